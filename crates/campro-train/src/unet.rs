//! The image enhancer R of CamPro (paper Sec. IV-D): a small U-Net from a captured
//! (protected) image back to the raw scene, built as an ONNX graph and trained through
//! [`OnnxNet`], so the file tract runs is the network that was trained.
//!
//! Shape, for widths `w₀ … w_L` (one level per width, each level below the first at half
//! the resolution of the one above), after an optional per-pixel stem (two 1x1
//! convolutions with ReLU: room for the camera's folded colour map):
//! - encoder: level 0 is two 3x3 convolutions (3 → w₀ → w₀); level l is a stride-2 3x3
//!   convolution (w_{l−1} → w_l) and a 3x3 convolution (w_l → w_l); ReLU after each;
//! - decoder, from the bottom up: a 3x3 convolution (w_{l+1} → w_l, ReLU) at the lower
//!   resolution, nearest 2x upsampling, concatenation with the encoder's level l, a 3x3
//!   convolution (2·w_l → w_l, ReLU);
//! - output: a 1x1 convolution (w₀ → 3) added to the input (a residual, zero at start, so an
//!   untrained enhancer returns the captured image unchanged);
//! - with a face gate ([`UnetConfig::face_gate`]), a branch at the deepest level (two 3x3
//!   convolutions w_L → 16 → 16 with ReLU and a 1x1 convolution to one logit, upsampled
//!   nearest to full resolution: the widest view the network has) plus a 1x1 convolution of
//!   the last decoder level (w₀ → 1, the edges), then a sigmoid, give each pixel the
//!   probability `g` that it is a face (about 0.02 at start), and the enhanced pixel is
//!   `out + g · (captured − out)`, or with [`UnetConfig::gate_blocks`] = N
//!   `out + g · (P(out) − out)`, `P` the output pixelated in N x N blocks (each block's
//!   mean). Trained as [`GATE`] beside the output; the ONNX file carries the blend
//!   ([`Unet::onnx_bytes`]).
//!
//! Input and output: (B, 3, H, W) RGB in [0, 1] (the output is not clamped; callers clamp
//! when they quantise), H and W multiples of [`Unet::multiple`]. No normalisation layers:
//! inference is one pass with no batch statistics.

use crate::config::{FaceTarget, PixelLoss, UnetConfig};
pub use campro_eval::enhance::GATE;
pub use campro_eval::enhance::{INPUT, MULTIPLE_KEY, OUTPUT};
// The node names the reader parses (campro_eval::enhance), from where it defines them.
use campro_eval::enhance::{GATE_BLEND, GATE_PIX, RESTORED, RESTORE_BINS, RESTORE_TABLE, UNGATED};
use campro_nn::onnx_net::{conv_attrs, f32_tensor, ints_attr, node, string_attr, GraphError, OnnxNet};
/// The face gate's logit at start: sigmoid(−4) ≈ 0.018, nearly off.
const GATE_BIAS: f32 = -4.0;
/// Channels of the face gate's deep branch.
const GATE_WIDTH: usize = 16;
use campro_eval::restore::{Table, SIDE};
use candle_core::{Result, Tensor, Var};
use rand::SeedableRng;
use rand_distr::Distribution;
use tract_onnx::pb;

/// The enhancer network.
pub struct Unet {
    net: OnnxNet,
    widths: Vec<usize>,
    gate: bool,
    /// Side of the pixelation blocks the gate blends toward; 0: toward the captured image.
    blocks: usize,
    /// [`UnetConfig::multiple`] of its shape.
    multiple: usize,
}

/// Parameters of a U-Net of this shape (weights and biases).
pub fn parameter_count(shape: &UnetConfig) -> usize {
    let (widths, stem) = (&shape.widths[..], shape.stem);
    let conv = |i: usize, o: usize, k: usize| i * o * k * k + o;
    let first = if stem > 0 { stem } else { 3 };
    let mut n = conv(first, widths[0], 3) + conv(widths[0], widths[0], 3);
    if stem > 0 {
        n += conv(3, stem, 1) + conv(stem, stem, 1);
    }
    for l in 1..widths.len() {
        n += conv(widths[l - 1], widths[l], 3) + conv(widths[l], widths[l], 3);
        n += conv(widths[l], widths[l - 1], 3) + conv(2 * widths[l - 1], widths[l - 1], 3);
    }
    n + conv(widths[0], 3, 1) + if shape.face_gate { gate_parameters(widths) } else { 0 }
}

/// The face gate's parameters: the deep branch and the fine 1x1 convolution.
fn gate_parameters(widths: &[usize]) -> usize {
    let conv = |i: usize, o: usize, k: usize| i * o * k * k + o;
    let deep = widths[widths.len() - 1];
    conv(deep, GATE_WIDTH, 3) + conv(GATE_WIDTH, GATE_WIDTH, 3) + conv(GATE_WIDTH, 1, 1) + conv(widths[0], 1, 1)
}

/// Multiply-accumulates per input pixel of one forward pass (a level l convolution runs on
/// 4^−l of the pixels).
pub fn macs_per_pixel(shape: &UnetConfig) -> f64 {
    let (widths, stem) = (&shape.widths[..], shape.stem);
    let area = |l: usize| 0.25f64.powi(l as i32);
    let conv = |i: usize, o: usize, k: usize, l: usize| (i * o * k * k) as f64 * area(l);
    let first = if stem > 0 { stem } else { 3 };
    let last = widths.len() - 1;
    let gate = if shape.face_gate {
        conv(widths[last], GATE_WIDTH, 3, last)
            + conv(GATE_WIDTH, GATE_WIDTH, 3, last)
            + conv(GATE_WIDTH, 1, 1, last)
            + conv(widths[0], 1, 1, 0)
    } else {
        0.0
    };
    let mut m = conv(first, widths[0], 3, 0) + conv(widths[0], widths[0], 3, 0) + conv(widths[0], 3, 1, 0) + gate;
    if stem > 0 {
        m += conv(3, stem, 1, 0) + conv(stem, stem, 1, 0);
    }
    for l in 1..widths.len() {
        m += conv(widths[l - 1], widths[l], 3, l) + conv(widths[l], widths[l], 3, l);
        m += conv(widths[l], widths[l - 1], 3, l) + conv(2 * widths[l - 1], widths[l - 1], 3, l - 1);
    }
    m
}

impl Unet {
    /// A fresh network: He-normal weights drawn from `seed`, zero biases, a zero output
    /// convolution (the identity map at start). Widths: 1 to 6 levels, each 1..=512; stem
    /// at most 256.
    pub fn new(shape: &UnetConfig, seed: u64, dev: &candle_core::Device) -> std::result::Result<Self, GraphError> {
        let widths = &shape.widths[..];
        if widths.is_empty() || widths.len() > 6 || widths.iter().any(|w| !(1..=512).contains(w)) || shape.stem > 256 {
            return Err(GraphError::Graph {
                path: "unet".into(),
                message: format!(
                    "widths {widths:?}, stem {}: 1 to 6 levels of 1..=512 channels, a stem of at most 256",
                    shape.stem
                ),
            });
        }
        let blocks = if shape.face_gate { shape.gate_blocks } else { 0 };
        if blocks != 0 && !(blocks.is_power_of_two() && (2..=64).contains(&blocks)) {
            return Err(GraphError::Graph {
                path: "unet".into(),
                message: format!("gate_blocks {blocks}: a power of two in 2..=64 (0 for the captured image)"),
            });
        }
        let multiple = UnetConfig { gate_blocks: blocks, ..shape.clone() }.multiple();
        let model = graph(widths, shape.stem, shape.face_gate, multiple, seed);
        Ok(Self {
            net: OnnxNet::from_model(model, "unet".into(), dev)?,
            widths: widths.to_vec(),
            gate: shape.face_gate,
            blocks,
            multiple,
        })
    }

    pub fn widths(&self) -> &[usize] {
        &self.widths
    }

    /// Height and width must be multiples of this: 2^(levels − 1), or the gate's
    /// pixelation blocks when larger.
    pub fn multiple(&self) -> usize {
        self.multiple
    }

    /// Every trainable tensor.
    pub fn vars(&self) -> Vec<Var> {
        self.net.vars()
    }

    /// Every trainable tensor by name (checkpoints).
    pub fn named_vars(&self) -> Vec<(String, Var)> {
        self.net.named_vars()
    }

    /// The U-Net's output (B, 3, H, W) for inputs `x` (B, 3, H, W) in [0, 1], before any face
    /// gate.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.check(x)?;
        // The graph's one output is OUTPUT.
        self.net.forward(x)
    }

    /// The enhanced image (B, 3, H, W) of inputs `x` whose camera output is `captured` (the
    /// same tensor without a restoration stage), and the face gate's map (B, 1, H, W) when
    /// there is one: `out + g · (captured − out)`, or `out + g · (P(out) − out)` with
    /// pixelation blocks ([`pixelate`]).
    pub fn forward_gated(&self, x: &Tensor, captured: &Tensor) -> Result<(Tensor, Option<Tensor>)> {
        self.check(x)?;
        if !self.gate {
            return self.net.forward(x).map(|y| (y, None));
        }
        let mut v = self.net.run(x, None)?;
        let (Some(out), Some(g)) = (v.remove(OUTPUT), v.remove(GATE)) else {
            candle_core::bail!("the gated U-Net computed no {OUTPUT} or {GATE}");
        };
        let toward = if self.blocks > 0 { pixelate(&out, self.blocks)? } else { captured.clone() };
        let y = (&out + (toward - &out)?.broadcast_mul(&g)?)?;
        Ok((y, Some(g)))
    }

    fn check(&self, x: &Tensor) -> Result<()> {
        let (_, _, h, w) = x.dims4()?;
        let m = self.multiple();
        if h % m != 0 || w % m != 0 {
            candle_core::bail!("enhancer input {h}x{w}: height and width must be multiples of {m}");
        }
        Ok(())
    }

    /// The network with its current weights, encoded as an ONNX file (input: the captured
    /// image; with a face gate, the blend included).
    pub fn onnx_bytes(&self) -> Result<Vec<u8>> {
        use prost::Message;
        let mut model = self.net.current()?;
        self.append_gate(&mut model);
        Ok(model.encode_to_vec())
    }

    /// With a face gate: the U-Net's output renamed [`UNGATED`] and the blend
    /// `OUTPUT = ungated + gate · (INPUT − ungated)` appended, INPUT being the graph's input
    /// (the captured image, also behind a restoration stage, which renames the U-Net's reads
    /// of it first); with pixelation blocks N, toward `P(ungated)` instead (AveragePool N x N,
    /// stride N, then nearest Resize by N).
    fn append_gate(&self, model: &mut pb::ModelProto) {
        if !self.gate {
            return;
        }
        let graph = model.graph.as_mut().expect("built with a graph");
        for n in graph.node.iter_mut().filter(|n| n.output.iter().any(|o| o == OUTPUT)) {
            n.output = vec![UNGATED.into()];
            n.name = format!("{}_{UNGATED}", n.op_type);
        }
        graph.initializer.push(f32_tensor("gate.minus1", vec![], &[-1.0]));
        let toward = if self.blocks > 0 {
            let n = self.blocks as i64;
            let f = self.blocks as f32;
            graph.initializer.push(f32_tensor("gate.pix.scales", vec![4], &[1.0, 1.0, f, f]));
            let pool = vec![ints_attr("kernel_shape", vec![n, n]), ints_attr("strides", vec![n, n])];
            graph.node.extend([
                node("AveragePool", &[UNGATED], "gate.pix.low", pool),
                node("Resize", &["gate.pix.low", "", "gate.pix.scales"], GATE_PIX, nearest()),
            ]);
            GATE_PIX
        } else {
            INPUT
        };
        graph.node.extend([
            node("Mul", &[UNGATED, "gate.minus1"], GATE_BLEND[0], vec![]),
            node("Add", &[toward, GATE_BLEND[0]], GATE_BLEND[1], vec![]),
            node("Mul", &[GATE, GATE_BLEND[1]], GATE_BLEND[2], vec![]),
            node("Add", &[UNGATED, GATE_BLEND[2]], OUTPUT, vec![]),
        ]);
    }

    /// The network with its current weights behind a per-pixel restoration stage: each
    /// captured pixel replaced by its bin's entry ([`campro_eval::restore::Table`]: 2^18
    /// entries, [`SIDE`] bins a channel), then the U-Net on that; encoded as an ONNX file
    /// whose input is still the captured image. The stage is ONNX operators: the 8-bit level
    /// (Mul, Round, Clip, Cast), each channel's bin already scaled by its place in the index
    /// (Add of the channel's offset, Gather from a 768-entry float table), the index (a 1x1
    /// Conv summing the three, Cast), the entry (Gather from a uint8 table), and back to
    /// (B, 3, H, W) in [0, 1] (Cast, Mul, Transpose, Squeeze): 786,432 bytes of table.
    /// Exact: the index sums three integers below 2^18 in f32.
    pub fn onnx_bytes_with_table(&self, table: &Table) -> std::result::Result<Vec<u8>, GraphError> {
        use prost::Message;
        let bad = |m: &str| GraphError::Graph { path: "unet".into(), message: m.into() };
        if table.entries.len() != SIDE * SIDE * SIDE {
            return Err(bad("a restoration table has 2^18 entries"));
        }
        let mut model = self.net.current()?;
        let graph = model.graph.as_mut().ok_or_else(|| bad("no graph"))?;
        for n in graph.node.iter_mut() {
            for i in n.input.iter_mut().filter(|i| *i == INPUT) {
                *i = RESTORED.into();
            }
        }
        let int_attr =
            |name: &str, i: i64| pb::AttributeProto { name: name.into(), r#type: 2, i, ..Default::default() };
        let int64 = |name: &str, dims: Vec<i64>, v: &[i64]| {
            let mut t = f32_tensor(name, dims, &[]);
            t.data_type = 7; // int64
            t.raw_data = v.iter().flat_map(|x| x.to_le_bytes()).collect();
            t
        };
        let mut lut = f32_tensor(RESTORE_TABLE, vec![SIDE.pow(3) as i64, 3], &[]);
        lut.data_type = 2; // uint8
        lut.raw_data = table.entries.iter().flatten().copied().collect();
        // Channel c's level v at c · 256 + v: its bin times SIDE^(2 − c).
        let place = [SIDE * SIDE, SIDE, 1];
        let bins: Vec<f32> = (0..3)
            .flat_map(|c| table.binning.levels()[c].iter().map(move |&q| (q as usize * place[c]) as f32))
            .collect();
        graph.initializer.extend([
            lut,
            int64("restore.axes", vec![1], &[4]),
            int64("restore.offset", vec![1, 3, 1, 1], &[0, 256, 512]),
            f32_tensor(RESTORE_BINS, vec![768], &bins),
            f32_tensor("restore.255", vec![], &[255.0]),
            f32_tensor("restore.0", vec![], &[0.0]),
            f32_tensor("restore.inv255", vec![], &[1.0 / 255.0]),
            f32_tensor("restore.sum", vec![1, 3, 1, 1], &[1.0, 1.0, 1.0]),
        ]);
        let mut perm = ints_attr("perm", vec![0, 4, 2, 3, 1]);
        perm.name = "perm".into();
        let front = vec![
            node("Mul", &[INPUT, "restore.255"], "restore.levels", vec![]),
            node("Round", &["restore.levels"], "restore.r", vec![]),
            node("Clip", &["restore.r", "restore.0", "restore.255"], "restore.v", vec![]),
            node("Cast", &["restore.v"], "restore.v64", vec![int_attr("to", 7)]),
            node("Add", &["restore.v64", "restore.offset"], "restore.at", vec![]),
            node("Gather", &["restore.bins", "restore.at"], "restore.q", vec![int_attr("axis", 0)]),
            node("Conv", &["restore.q", "restore.sum"], "restore.i", conv_attrs(1, 1, 0)),
            node("Cast", &["restore.i"], "restore.i64", vec![int_attr("to", 7)]),
            node("Gather", &["restore.table", "restore.i64"], "restore.g", vec![int_attr("axis", 0)]),
            node("Cast", &["restore.g"], "restore.f", vec![int_attr("to", 1)]),
            node("Mul", &["restore.f", "restore.inv255"], "restore.nhwc", vec![]),
            node("Transpose", &["restore.nhwc"], "restore.t", vec![perm]),
            node("Squeeze", &["restore.t", "restore.axes"], RESTORED, vec![]),
        ];
        graph.node.splice(0..0, front);
        self.append_gate(&mut model);
        Ok(model.encode_to_vec())
    }
}

/// The paper's face-masked L1 loss `mean(s ⊙ |pred − target|)`: `pred` and `target`
/// (B, 3, H, W), `keep` (B, 1, H, W), 1 where the image is to be restored and 0 on faces.
/// With `keep` all ones it is the plain L1 loss (the restoration attack's).
pub fn masked_l1(pred: &Tensor, target: &Tensor, keep: &Tensor) -> Result<Tensor> {
    (pred - target)?.abs()?.broadcast_mul(keep)?.mean_all()
}

/// The enhancer's training loss for `faces` ([`FaceTarget`]): the mean masked distance
/// ([`PixelLoss`]) to `raw`, plus, with [`FaceTarget::Input`], [`FaceTarget::Captured`] and
/// [`FaceTarget::Pixelated`], the distance inside the faces to `held`: the network's input,
/// the captured image, or the raw image pixelated.
pub fn enhancer_loss(
    pred: &Tensor,
    raw: &Tensor,
    held: &Tensor,
    keep: &Tensor,
    faces: FaceTarget,
    loss: PixelLoss,
) -> Result<Tensor> {
    let diff = match faces {
        FaceTarget::Free | FaceTarget::Restore => (pred - raw)?.broadcast_mul(keep)?,
        FaceTarget::Input | FaceTarget::Captured | FaceTarget::Pixelated => {
            (pred - loss_target(raw, held, keep, faces)?)?
        }
    };
    match loss {
        PixelLoss::L1 => diff.abs()?.mean_all(),
        PixelLoss::L2 => diff.sqr()?.mean_all(),
    }
}

/// What the enhancer is asked to output for `faces` ([`FaceTarget`]): `raw` outside the
/// faces (`keep` 1) and `held` inside them, or `raw` everywhere with [`FaceTarget::Free`]
/// (whose face pixels the loss leaves out) and [`FaceTarget::Restore`].
pub fn loss_target(raw: &Tensor, held: &Tensor, keep: &Tensor, faces: FaceTarget) -> Result<Tensor> {
    match faces {
        FaceTarget::Free | FaceTarget::Restore => Ok(raw.clone()),
        FaceTarget::Input | FaceTarget::Captured | FaceTarget::Pixelated => {
            raw.broadcast_mul(keep)? + held.broadcast_mul(&(1.0 - keep)?)?
        }
    }
}

/// `x` (B, C, H, W) pixelated in `n` x `n` blocks: each pixel replaced by its block's
/// mean (H and W multiples of `n`). What a gated face becomes with
/// [`UnetConfig::gate_blocks`], and its training target inside the faces (of the raw image).
pub fn pixelate(x: &Tensor, n: usize) -> Result<Tensor> {
    let (_, _, h, w) = x.dims4()?;
    x.avg_pool2d((n, n))?.upsample_nearest2d(h, w)
}

/// The face gate's mean binary cross-entropy against the face boxes: `gate` (B, 1, H, W)
/// probabilities, clamped to [1e-6, 1 − 1e-6] before the logarithm; the target is 1 where
/// `keep` is 0 (a face) and 0 elsewhere, the background's terms weighted by `background`.
pub fn gate_loss(gate: &Tensor, keep: &Tensor, background: f64) -> Result<Tensor> {
    let p = gate.clamp(1e-6f32, 1.0 - 1e-6f32)?;
    let face = (1.0 - keep)?;
    let on = (p.log()? * &face)?;
    let off = ((1.0 - &p)?.log()? * (keep * background)?)?;
    (on + off)?.mean_all()?.neg()
}

/// Mean `|pred − target|` over the pixels where `keep` is 0 (the faces), or None when there
/// are none: how far the enhancer stays from restoring faces.
pub fn face_l1(pred: &Tensor, target: &Tensor, keep: &Tensor) -> Result<Option<f64>> {
    let face = (1.0 - keep)?;
    let pixels = face.sum_all()?.to_scalar::<f32>()? as f64;
    if pixels < 1.0 {
        return Ok(None);
    }
    let s = (pred - target)?.abs()?.broadcast_mul(&face)?.sum_all()?.to_scalar::<f32>()? as f64;
    Ok(Some(s / (3.0 * pixels)))
}

fn value_info(name: &str) -> pb::ValueInfoProto {
    use pb::tensor_shape_proto::{dimension::Value, Dimension};
    let dim = |v: Value| Dimension { value: Some(v), ..Default::default() };
    pb::ValueInfoProto {
        name: name.into(),
        r#type: Some(pb::TypeProto {
            value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                elem_type: 1,
                shape: Some(pb::TensorShapeProto {
                    dim: vec![
                        dim(Value::DimParam("N".into())),
                        dim(Value::DimValue(3)),
                        dim(Value::DimParam("H".into())),
                        dim(Value::DimParam("W".into())),
                    ],
                }),
            })),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// Initializers and nodes of a graph being built, weights drawn from `rng`.
struct Builder {
    inits: Vec<pb::TensorProto>,
    nodes: Vec<pb::NodeProto>,
    rng: rand_chacha::ChaCha8Rng,
}

impl Builder {
    /// A convolution `name` (i → o channels, k x k, padding k / 2) on `x`, He-normal weights
    /// and a ReLU, or zero weights and no ReLU; returns its output's name.
    fn conv(&mut self, name: &str, x: &str, (i, o): (usize, usize), k: usize, stride: i64, relu: bool) -> String {
        let n = o * i * k * k;
        let w: Vec<f32> = if relu {
            let normal = rand_distr::Normal::new(0.0f32, (2.0 / (i * k * k) as f32).sqrt()).expect("valid");
            (0..n).map(|_| normal.sample(&mut self.rng)).collect()
        } else {
            vec![0.0; n]
        };
        let (wn, bn, y) = (format!("{name}.w"), format!("{name}.b"), format!("{name}.y"));
        self.inits.push(f32_tensor(&wn, vec![o as i64, i as i64, k as i64, k as i64], &w));
        self.inits.push(f32_tensor(&bn, vec![o as i64], &vec![0.0; o]));
        self.nodes.push(node("Conv", &[x, &wn, &bn], &y, conv_attrs(k as i64, stride, (k / 2) as i64)));
        if !relu {
            return y;
        }
        let r = format!("{name}.r");
        self.nodes.push(node("Relu", &[&y], &r, vec![]));
        r
    }
}

/// Nearest-neighbour upsampling's Resize attributes.
fn nearest() -> Vec<pb::AttributeProto> {
    vec![
        string_attr("mode", "nearest"),
        string_attr("coordinate_transformation_mode", "asymmetric"),
        string_attr("nearest_mode", "floor"),
    ]
}

/// The U-Net of `widths` as an ONNX model (opset 13), weights drawn from `seed`.
fn graph(widths: &[usize], stem: usize, gate: bool, multiple: usize, seed: u64) -> pb::ModelProto {
    let mut b = Builder { inits: Vec::new(), nodes: Vec::new(), rng: rand_chacha::ChaCha8Rng::seed_from_u64(seed) };
    let (mut x, mut first) = (INPUT.to_string(), 3);
    if stem > 0 {
        x = b.conv("stem.conv0", &x, (3, stem), 1, 1, true);
        x = b.conv("stem.conv1", &x, (stem, stem), 1, 1, true);
        first = stem;
    }
    x = b.conv("enc0.conv0", &x, (first, widths[0]), 3, 1, true);
    x = b.conv("enc0.conv1", &x, (widths[0], widths[0]), 3, 1, true);
    let mut skips = vec![x.clone()];
    for l in 1..widths.len() {
        x = b.conv(&format!("enc{l}.conv0"), &x, (widths[l - 1], widths[l]), 3, 2, true);
        x = b.conv(&format!("enc{l}.conv1"), &x, (widths[l], widths[l]), 3, 1, true);
        skips.push(x.clone());
    }
    let deep_gate = gate.then(|| {
        let g = b.conv("gate.c0", &x, (widths[widths.len() - 1], GATE_WIDTH), 3, 1, true);
        let g = b.conv("gate.c1", &g, (GATE_WIDTH, GATE_WIDTH), 3, 1, true);
        let low = b.conv("gate.low", &g, (GATE_WIDTH, 1), 1, 1, false);
        *b.inits.last_mut().expect("the gate's bias") = f32_tensor("gate.low.b", vec![1], &[GATE_BIAS]);
        let f = (1usize << (widths.len() - 1)) as f32;
        b.inits.push(f32_tensor("gate.scales", vec![4], &[1.0, 1.0, f, f]));
        b.nodes.push(node("Resize", &[&low, "", "gate.scales"], "gate.up", nearest()));
        "gate.up".to_string()
    });
    b.inits.push(f32_tensor("up.scales", vec![4], &[1.0, 1.0, 2.0, 2.0]));
    for l in (0..widths.len() - 1).rev() {
        let t = b.conv(&format!("dec{l}.conv0"), &x, (widths[l + 1], widths[l]), 3, 1, true);
        let (up, cat) = (format!("dec{l}.up"), format!("dec{l}.cat"));
        b.nodes.push(node("Resize", &[&t, "", "up.scales"], &up, nearest()));
        let mut concat = node("Concat", &[&up, &skips[l]], &cat, vec![]);
        concat.attribute.push(pb::AttributeProto { name: "axis".into(), r#type: 2, i: 1, ..Default::default() });
        b.nodes.push(concat);
        x = b.conv(&format!("dec{l}.conv1"), &cat, (2 * widths[l], widths[l]), 3, 1, true);
    }
    let r = b.conv("out", &x, (widths[0], 3), 1, 1, false);
    b.nodes.push(node("Add", &[INPUT, &r], OUTPUT, vec![]));
    if let Some(up) = deep_gate {
        let fine = b.conv("gate.fine", &x, (widths[0], 1), 1, 1, false);
        b.nodes.push(node("Add", &[&up, &fine], "gate.logit", vec![]));
        b.nodes.push(node("Sigmoid", &["gate.logit"], GATE, vec![]));
    }
    pb::ModelProto {
        ir_version: 8,
        opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 13 }],
        producer_name: "campro".into(),
        producer_version: env!("CARGO_PKG_VERSION").into(),
        doc_string: format!(
            "CamPro image enhancer: U-Net, widths {widths:?}, stem {stem}{}",
            if gate { ", face gate" } else { "" }
        ),
        metadata_props: vec![pb::StringStringEntryProto { key: MULTIPLE_KEY.into(), value: multiple.to_string() }],
        graph: Some(pb::GraphProto {
            name: "campro-enhancer".into(),
            node: b.nodes,
            initializer: b.inits,
            input: vec![value_info(INPUT)],
            output: vec![value_info(OUTPUT)],
            ..Default::default()
        }),
        ..Default::default()
    }
}
