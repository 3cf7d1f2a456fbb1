//! CamPro's image enhancer at inference (paper Sec. IV-D): the ONNX U-Net written by
//! `campro train-enhancer`, run by tract on whole 8-bit images of any size.
//!
//! The file is self-describing: input [`INPUT`] and output [`OUTPUT`], both (1, 3, H, W) RGB
//! in [0, 1]; H and W must be multiples of the metadata entry [`MULTIPLE_KEY`], so an image
//! is padded on the right and bottom by repeating its last column and row, and the result
//! is cropped back. The output is rounded to 8 bits (clamped to 0..=255).

use crate::error::{EvalError, Result};
use crate::plans::{Plan, Plans};
use image::RgbImage;
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::{bail, format_err};

mod names;
mod planes;
mod table;
mod threads;
pub use names::*;
use planes::*;
pub use planes::{cropped_rgb8, padded_chw};
use table::RestoreTable;
use threads::on_threads;

/// Bytes a pixel of a strip the reduced path holds at once (at [`Scale`] factors above 1):
/// three f32 planes for the ungated result and three for the gate's target, a gate plane,
/// and a little for the parallel rows' scratch.
pub const STRIP_BYTES_PER_PIXEL: u64 = 32;

/// Bytes the network holds a pixel it runs on (padded, at its working resolution): a
/// 960 x 540 and a 1920 x 1080 frame at `--enhance-scale 1` peaked at 209 and 471 MB
/// resident, 168 bytes a pixel between them. So 3840 x 2160 at full resolution (1.4 GB)
/// is refused; at [`Scale::Auto`] (a quarter) it needs 0.5 GB.
pub const NET_BYTES_PER_PIXEL: u64 = 170;
/// Largest enhancer file read (bytes): the recommended ones are at most 2 MB.
pub const MAX_FILE: u64 = 64 << 20;

/// A loaded enhancer; `enhance` takes `&self`, so one can serve several threads. tract
/// cannot prove that the U-Net's strided and upsampled shapes agree for a symbolic size, so
/// the graph is optimised once per padded image size, the most recent few kept
/// ([`crate::plans`]: a video or LFW has one size; a photo folder may have hundreds).
pub struct Enhancer {
    model: InferenceModel,
    plans: Plans<(usize, usize, Outputs)>,
    multiple: usize,
    path: PathBuf,
    parts: Parts,
    /// The network from its own input (the restoration, when there is a table) to the
    /// ungated output and the gate: what runs at reduced resolution.
    unet: Option<InferenceModel>,
    scale: Scale,
}

/// The resolution the U-Net runs at, against the image's.
///
/// At a reduced factor `f` the network runs on the image averaged down `f` times a side,
/// and its contribution over the per-pixel restoration (its residual, `ungated − restored`)
/// is upsampled bilinearly and added to the restoration computed at full resolution; the
/// face gate's map is upsampled the same way and its blend (toward the result pixelated in
/// the file's own blocks, at full resolution) is applied at full resolution. So the colours
/// stay per-pixel exact and only the network's spatial correction is coarser; the cost
/// falls about `f²` times. Measured quality and speed: `docs/enhancer.md`, "Speed".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scale {
    /// Full resolution below 1280 x 720 pixels, half from there, a quarter from 2560 x 1440,
    /// an eighth from 5120 x 2880 (so the network runs on at most about 1.3 megapixels
    /// below 10240 x 5760, where a sixteenth holds it there).
    #[default]
    Auto,
    /// The network at 1/f of the image's width and height (1: full resolution; 2, 4, 8).
    Factor(usize),
}

impl Scale {
    /// The factor for a `w` x `h` image.
    pub fn factor(self, w: usize, h: usize) -> usize {
        match self {
            Scale::Factor(f) => f.max(1),
            Scale::Auto if w * h >= 10240 * 5760 => 16,
            Scale::Auto if w * h >= 5120 * 2880 => 8,
            Scale::Auto if w * h >= 2560 * 1440 => 4,
            Scale::Auto if w * h >= 1280 * 720 => 2,
            Scale::Auto => 1,
        }
    }
}

/// Which graph a plan runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Outputs {
    /// The whole file: captured in, enhanced out.
    Enhanced,
    /// The network alone: its input (the restoration, or the captured image) in, the
    /// ungated output and the gate out (or the output, without a gate).
    Network,
}

/// What a file's graph holds besides its input and output, for the reduced path.
#[derive(Debug, Clone, Default)]
struct Parts {
    /// The restoration stage's table, when the file has campro's: run here, at full
    /// resolution, in front of the network.
    table: Option<RestoreTable>,
    /// A face gate ([`UNGATED`] and [`GATE`]) and the side of its pixelation blocks (0: it
    /// blends toward the captured image).
    gate: Option<usize>,
}

impl Enhancer {
    /// Reads and optimises the ONNX file at `path` (at most [`MAX_FILE`] bytes).
    pub fn load(path: &Path) -> Result<Self> {
        Self::from_bytes(&campro::file::read_capped(path, MAX_FILE, "an enhancer (ONNX)")?, path)
    }

    /// Reads an enhancer from the bytes of its ONNX file; `path` names it in errors.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self> {
        let bad = |m: String| EvalError::Model { path: path.to_path_buf(), message: m };
        #[allow(clippy::type_complexity)]
        let built = std::panic::catch_unwind(
            || -> TractResult<(usize, Parts, InferenceModel, Option<InferenceModel>)> {
                let onnx = tract_onnx::onnx();
                let proto = onnx.proto_model_for_read(&mut &bytes[..])?;
                let multiple = proto
                    .metadata_props
                    .iter()
                    .find(|p| p.key == MULTIPLE_KEY)
                    .and_then(|p| p.value.parse::<usize>().ok())
                    .filter(|m| m.is_power_of_two() && *m <= 64)
                    .ok_or_else(|| {
                        format_err!("no {MULTIPLE_KEY} entry (a power of two up to 64): not a campro enhancer")
                    })?;
                let graph = proto.graph.as_ref().ok_or_else(|| format_err!("no graph"))?;
                let names =
                    (graph.input.first().map(|i| i.name.as_str()), graph.output.first().map(|o| o.name.as_str()));
                if names != (Some(INPUT), Some(OUTPUT)) {
                    bail!("input {:?} and output {:?}, expected {INPUT:?} and {OUTPUT:?}", names.0, names.1);
                }
                // Every node must compute from the input: tract folds constant-only nodes while
                // it reads the graph, so a few bytes of Tile, Expand or broadcasting on constants
                // could ask for gigabytes before any size check runs. A campro enhancer has none.
                let mut live: std::collections::HashSet<&str> = [INPUT].into_iter().collect();
                for n in &graph.node {
                    if !n.input.iter().any(|i| live.contains(i.as_str())) {
                        bail!(
                        "node {:?} ({}) computes from constants only; a campro enhancer computes every node from its input",
                        n.name.chars().take(64).collect::<String>(),
                        n.op_type.chars().take(32).collect::<String>()
                    );
                    }
                    live.extend(n.output.iter().map(String::as_str));
                }
                let made = |name: &str| graph.node.iter().any(|n| n.output.iter().any(|o| o == name));
                let blocks = graph
                    .node
                    .iter()
                    .find(|n| n.op_type == "AveragePool" && n.input.first().is_some_and(|i| i == UNGATED))
                    .and_then(|n| n.attribute.iter().find(|a| a.name == "kernel_shape"))
                    .and_then(|a| a.ints.first().copied())
                    .map_or(0, |k| k.clamp(0, 1024) as usize);
                let parts = Parts {
                    table: made(RESTORED).then(|| RestoreTable::from_graph(graph)).flatten(),
                    gate: (made(UNGATED) && made(GATE)).then_some(blocks),
                };
                // The network alone, for the reduced path: a graph without a readable table
                // (another restoration stage) has none and always runs whole.
                let unet = match (made(RESTORED), &parts.table) {
                    (false, _) => Some(onnx.model_for_proto_model(&proto)?),
                    (true, Some(_)) => Some(onnx.model_for_proto_model(&network_only(&proto, parts.gate.is_some()))?),
                    (true, None) => None,
                };
                Ok((multiple, parts, onnx.model_for_proto_model(&proto)?, unet))
            },
        );
        let e = match built {
            Ok(Ok((multiple, parts, model, unet))) => Self {
                model,
                plans: Default::default(),
                multiple,
                path: path.to_path_buf(),
                parts,
                unet,
                scale: Scale::Auto,
            },
            Ok(Err(e)) => return Err(bad(format!("{e:#}"))),
            Err(_) => return Err(bad("tract could not read it (malformed graph)".into())),
        };
        // Built once at the smallest size, so a graph that cannot run fails here.
        e.plan(e.multiple, e.multiple, Outputs::Enhanced)?;
        Ok(e)
    }

    /// The same enhancer at `scale` ([`Scale::Auto`] unless set).
    pub fn with_scale(mut self, scale: Scale) -> Self {
        self.scale = scale;
        self
    }

    /// The plan for a padded `w` x `h` input (built on first use).
    fn plan(&self, w: usize, h: usize, outputs: Outputs) -> Result<Plan> {
        self.plans.get_or_make((w, h, outputs), || self.make_plan(w, h, outputs))
    }

    fn make_plan(&self, w: usize, h: usize, outputs: Outputs) -> Result<Plan> {
        let mut model = match (outputs, &self.unet) {
            (Outputs::Enhanced, _) => self.model.clone(),
            (Outputs::Network, Some(u)) => u.clone(),
            (Outputs::Network, None) => {
                return Err(EvalError::Model { path: self.path.clone(), message: "has no separable network".into() })
            }
        };
        if outputs == Outputs::Network {
            let names: &[&str] = if self.parts.gate.is_some() { &[UNGATED, GATE] } else { &[OUTPUT] };
            model
                .select_outputs_by_name(names)
                .map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e:#}") })?;
        }
        let limit = tensor_limit(w, h);
        // The model is a fresh copy, dropped on a panic. Its shapes are checked before
        // tract optimises it (constant folding would compute every constant tensor).
        let built = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> TractResult<Plan> {
            let typed = model.with_input_fact(0, f32::fact([1, 3, h, w]).into())?.into_typed()?;
            if let Some((name, bytes)) = largest_tensor(&typed).filter(|&(_, b)| b > limit) {
                bail!(
                    "its tensor {name:?} would take {} MiB at input 1x3x{h}x{w}; an enhancer may use {} MiB a tensor",
                    bytes >> 20,
                    limit >> 20
                );
            }
            typed.into_optimized()?.into_runnable()
        }));
        match built {
            Ok(r) => r.map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e:#}") }),
            Err(_) => Err(EvalError::Model {
                path: self.path.clone(),
                message: format!("cannot be run at input 1x3x{h}x{w} (tract refused the shapes)"),
            }),
        }
    }

    /// Runs `plan` on a (1, 3, `ph`, `pw`) input, returning its outputs as float vectors.
    fn run(&self, plan: &Plan, data: &[f32], (pw, ph): (usize, usize), threads: usize) -> Result<Vec<Vec<f32>>> {
        let input = Tensor::from_shape(&[1, 3, ph, pw], data).expect("shape matches data");
        let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            on_threads(threads, || plan.run(tvec!(input.into())))
        }))
        .map_err(|_| EvalError::Model { path: self.path.clone(), message: "tract failed while running it".into() })?
        .map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e:#}") })?;
        out.iter()
            .map(|t| {
                let v = t
                    .try_as_plain_ram()
                    .and_then(|t| t.as_slice::<f32>())
                    .map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e}") })?;
                if v.len() != 3 * pw * ph && v.len() != pw * ph {
                    return Err(EvalError::Model {
                        path: self.path.clone(),
                        message: format!("an output has {} values, expected {} or {}", v.len(), 3 * pw * ph, pw * ph),
                    });
                }
                Ok(v.to_vec())
            })
            .collect()
    }

    /// Height and width multiple the network needs (images are padded to it).
    pub fn multiple(&self) -> usize {
        self.multiple
    }

    /// Pixels of a `w` x `h` image padded to the network's multiple (saturating).
    pub fn padded_pixels(&self, w: usize, h: usize) -> u64 {
        let m = self.multiple as u64;
        (w as u64).div_ceil(m).saturating_mul(m).saturating_mul((h as u64).div_ceil(m).saturating_mul(m))
    }

    /// Bytes [`Self::enhance`] holds for a `w` x `h` image besides the image itself and
    /// the enhanced image: the network's pixels (padded to the multiple, at its working
    /// scale) at [`NET_BYTES_PER_PIXEL`], and at a reduced scale one strip's planes
    /// ([`STRIP_BYTES_PER_PIXEL`]). Saturating.
    pub fn work_bytes(&self, w: u32, h: u32) -> u64 {
        let (w, h) = (w as usize, h as usize);
        let f = self.scale.factor(w, h);
        if f > 1 && w >= f * self.multiple && h >= f * self.multiple && self.unet.is_some() {
            let strip = self.padded_pixels(w, self.strip_rows(f)).saturating_mul(STRIP_BYTES_PER_PIXEL);
            self.padded_pixels(w.div_ceil(f), h.div_ceil(f)).saturating_mul(NET_BYTES_PER_PIXEL).saturating_add(strip)
        } else {
            self.padded_pixels(w, h).saturating_mul(NET_BYTES_PER_PIXEL)
        }
    }

    /// Rows of a strip of the reduced path at factor `f`: [`STRIP_ROWS`] rounded up to a
    /// multiple of `f` (its low rows are whole) and of the gate's blocks (its pixelation
    /// bands are the whole image's).
    fn strip_rows(&self, f: usize) -> usize {
        let unit = lcm(f, self.parts.gate.unwrap_or(0).max(1));
        STRIP_ROWS.div_ceil(unit) * unit
    }

    /// The enhanced image of a captured 8-bit image (same size), on the calling thread.
    pub fn enhance(&self, img: &RgbImage) -> Result<RgbImage> {
        self.enhance_on(img, 1)
    }

    /// [`Enhancer::enhance`] with the network's kernels spread over `threads` threads: for
    /// one frame at a time (video); images processed in parallel are better at one each.
    pub fn enhance_on(&self, img: &RgbImage, threads: usize) -> Result<RgbImage> {
        let (w, h) = (img.width() as usize, img.height() as usize);
        let f = self.scale.factor(w, h);
        if f > 1 && w >= f * self.multiple && h >= f * self.multiple && self.unet.is_some() {
            return self.enhance_reduced(img, f, threads);
        }
        let (data, pw, ph) = padded_chw(img, self.multiple);
        let plan = self.plan(pw, ph, Outputs::Enhanced)?;
        let out = self.run(&plan, &data, (pw, ph), threads)?;
        if out[0].len() != 3 * pw * ph {
            return Err(EvalError::Model { path: self.path.clone(), message: "the output is not an RGB image".into() });
        }
        Ok(cropped_rgb8(&out[0], pw, ph, w as u32, h as u32))
    }

    /// [`Self::enhance`] with the network at 1/`f` of the resolution ([`Scale`]): its
    /// input (the restoration, or the captured image) at full resolution, averaged down;
    /// the network's residual over that input upsampled and added back; the gate's map
    /// upsampled and its blend made at full resolution. Everything at full resolution is
    /// made a strip of [`STRIP_ROWS`] rows at a time (twice: once to average down, once to
    /// finish), so what this holds beside the input and the output is the network's at
    /// 1/`f` and a strip's planes, whatever the image's height.
    fn enhance_reduced(&self, img: &RgbImage, f: usize, threads: usize) -> Result<RgbImage> {
        use rayon::prelude::*;
        let (w, h) = (img.width() as usize, img.height() as usize);
        let (pw, ph) = (w.div_ceil(self.multiple) * self.multiple, h.div_ceil(self.multiple) * self.multiple);
        let (sw, sh) = (w.div_ceil(f), h.div_ceil(f));
        let (lpw, lph) = (sw.div_ceil(self.multiple) * self.multiple, sh.div_ceil(self.multiple) * self.multiple);
        let rows = self.strip_rows(f);
        let input = |r: std::ops::Range<usize>| match &self.parts.table {
            Some(t) => t.restore_rows(img, pw, r),
            None => chw_rows(img, pw, r),
        };
        let mut low = vec![0f32; 3 * lpw * lph];
        for y0 in (0..h).step_by(rows) {
            let n = rows.min(ph - y0);
            average_strip_into(&input(y0..y0 + n), pw, (y0, n), (w, h), f, (lpw, lph), &mut low);
        }
        padded_low(&mut low, (lpw, lph), (sw, sh));
        let mut out = self.run(&self.plan(lpw, lph, Outputs::Network)?, &low, (lpw, lph), threads)?.into_iter();
        let (Some(ungated_low), gate_low) = (out.next(), out.next()) else {
            return Err(EvalError::Model { path: self.path.clone(), message: "the network gave no output".into() });
        };
        // The network's output as a local linear function of its input (a guided filter
        // fitted at low resolution, He et al.), applied to the full-resolution input: the
        // edges the input has at full resolution stay sharp.
        let (gain, offset) = guided_coefficients(&low, &ungated_low, (sw, sh), lpw, lph);
        drop(low);
        let (cols, taps_y) = (taps(pw, sw, f), taps(ph, sh, f));
        let gated = self.parts.gate.zip(gate_low);
        let mut enhanced = RgbImage::new(w as u32, h as u32);
        for (k, rows_out) in enhanced.chunks_mut(3 * w * rows).enumerate() {
            let y0 = k * rows;
            let n = rows.min(ph - y0);
            let mut ungated = input(y0..y0 + n);
            let scratch = || (vec![0f32; pw], vec![0f32; pw]);
            ungated.par_chunks_mut(pw).enumerate().for_each_init(scratch, |(g, o), (row, line)| {
                let (c, y) = (row / n, y0 + row % n);
                let at = c * lpw * lph..(c + 1) * lpw * lph;
                upsample_row(&gain[at.clone()], lpw, taps_y[y], &cols, g, |v, x| *v = x);
                upsample_row(&offset[at], lpw, taps_y[y], &cols, o, |v, x| *v = x);
                for ((v, g), o) in line.iter_mut().zip(g.iter()).zip(o.iter()) {
                    *v = g * *v + o;
                }
            });
            let done = match &gated {
                None => ungated,
                Some((blocks, gate_low)) => {
                    // The gate's blend at full resolution, toward the pixelated result (or
                    // the capture).
                    let toward =
                        if *blocks > 0 { pixelated(&ungated, pw, n, *blocks) } else { chw_rows(img, pw, y0..y0 + n) };
                    let mut gate = vec![0f32; pw * n];
                    gate.par_chunks_mut(pw).enumerate().for_each(|(r, line)| {
                        upsample_row(gate_low, lpw, taps_y[y0 + r], &cols, line, |v, g| *v = g.clamp(0.0, 1.0));
                    });
                    blended(ungated, &gate, &toward, pw * n)
                }
            };
            put_rgb8_rows(&done, pw, n, w, rows_out);
        }
        Ok(enhanced)
    }
}

/// Full-resolution rows the reduced path makes at once (rounded up to a multiple of its
/// factor and of the gate's blocks): a strip's planes are about 60 bytes a pixel of it, so
/// 2 MB a 1,000 pixels of width.
pub const STRIP_ROWS: usize = 128;

/// Least common multiple.
fn lcm(a: usize, b: usize) -> usize {
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    a / gcd(a, b) * b
}

/// Widest activation an enhancer may hold at full resolution, channels: a campro U-Net's
/// largest is its first decoder's concatenation (twice the first width, at most 64).
pub const MAX_FULL_RES_CHANNELS: usize = 128;

/// Largest tensor an enhancer may hold for a padded `w` x `h` input, bytes
/// ([`MAX_FULL_RES_CHANNELS`] f32 channels at full resolution, at least 64 MiB).
pub fn tensor_limit(w: usize, h: usize) -> usize {
    (MAX_FULL_RES_CHANNELS * 4).saturating_mul(w).saturating_mul(h).max(64 << 20)
}

/// The node output (name, bytes) with the most bytes, among those of known shape.
fn largest_tensor(model: &TypedModel) -> Option<(String, usize)> {
    model
        .nodes
        .iter()
        .flat_map(|n| n.outputs.iter().map(move |o| (n, o)))
        .filter_map(|(n, o)| {
            let dims = o.fact.shape.as_concrete()?;
            let count = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).unwrap_or(usize::MAX);
            Some((n.name.clone(), count.saturating_mul(o.fact.datum_type.size_of())))
        })
        .max_by_key(|&(_, b)| b)
}

/// The file's network alone: the restoration stage's nodes removed and the graph's input
/// renamed to what they made ([`RESTORED`]); with a gate, the blend removed and the output
/// renamed [`UNGATED`] (the gate map is read by name).
fn network_only(proto: &tract_onnx::pb::ModelProto, gated: bool) -> tract_onnx::pb::ModelProto {
    let mut m = proto.clone();
    if let Some(g) = m.graph.as_mut() {
        let front = |o: &str| o == RESTORED || o.starts_with(RESTORE_PREFIX);
        let blend = |o: &str| gated && (o == OUTPUT || o.starts_with(GATE_PIX) || GATE_BLEND.contains(&o));
        g.node.retain(|n| !n.output.iter().any(|o| front(o) || blend(o)));
        g.initializer.retain(|t| !t.name.starts_with(RESTORE_PREFIX));
        if let Some(i) = g.input.first_mut() {
            i.name = RESTORED.into();
        }
        if gated {
            if let Some(o) = g.output.first_mut() {
                o.name = UNGATED.into();
            }
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;
    use tract_onnx::pb;

    fn node(op: &str, inputs: &[&str], output: &str) -> pb::NodeProto {
        pb::NodeProto {
            op_type: op.into(),
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![output.into()],
            name: output.into(),
            ..Default::default()
        }
    }

    fn value_info(name: &str) -> pb::ValueInfoProto {
        let dim = |v: i64| pb::tensor_shape_proto::Dimension {
            value: Some(pb::tensor_shape_proto::dimension::Value::DimValue(v)),
            ..Default::default()
        };
        pb::ValueInfoProto {
            name: name.into(),
            r#type: Some(pb::TypeProto {
                value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                    elem_type: 1,
                    shape: Some(pb::TensorShapeProto { dim: vec![dim(1), dim(3), dim(8), dim(8)] }),
                })),
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    /// An "enhancer" that adds to its input the sum of `tiled` tiled `repeats` times (`tiled`
    /// is the constant "c" or the input itself): a few hundred bytes that ask for
    /// `4 * product(repeats)` bytes or more.
    fn tile_bomb(tiled: &str, repeats: [i64; 4]) -> Vec<u8> {
        let inits = vec![
            pb::TensorProto {
                name: "c".into(),
                dims: vec![1, 1, 1, 1],
                data_type: 1,
                float_data: vec![1.0],
                ..Default::default()
            },
            pb::TensorProto {
                name: "r".into(),
                dims: vec![4],
                data_type: 7,
                int64_data: repeats.to_vec(),
                ..Default::default()
            },
        ];
        let model = pb::ModelProto {
            ir_version: 8,
            opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 13 }],
            metadata_props: vec![pb::StringStringEntryProto { key: MULTIPLE_KEY.into(), value: "8".into() }],
            graph: Some(pb::GraphProto {
                node: vec![
                    node("Tile", &[tiled, "r"], "t"),
                    node("ReduceSum", &["t"], "s"),
                    node("Add", &[INPUT, "s"], OUTPUT),
                ],
                initializer: inits,
                input: vec![value_info(INPUT)],
                output: vec![value_info(OUTPUT)],
                ..Default::default()
            }),
            ..Default::default()
        };
        model.encode_to_vec()
    }

    #[test]
    fn a_small_graph_that_asks_for_gigabytes_is_refused_before_it_runs() {
        // 60000 x 60000 floats (13 GiB) from a constant: refused before tract folds it.
        let bytes = tile_bomb("c", [1, 1, 60000, 60000]);
        assert!(bytes.len() < 400, "{}", bytes.len());
        let e = Enhancer::from_bytes(&bytes, Path::new("bomb.onnx")).err().expect("refused").to_string();
        assert!(e.starts_with("model bomb.onnx: ") && e.contains("constants only"), "{e}");
        // The same from the input: refused by its size at the smallest input (8 x 8 x 7500²).
        let e = Enhancer::from_bytes(&tile_bomb(INPUT, [1, 1, 7500, 7500]), Path::new("big.onnx"))
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("MiB a tensor"), "{e}");
        // A small honest graph of the same shape runs.
        let ok = Enhancer::from_bytes(&tile_bomb(INPUT, [1, 1, 1, 1]), Path::new("ok.onnx")).unwrap();
        let img = image::RgbImage::from_pixel(8, 8, image::Rgb([10, 20, 30]));
        let out = ok.enhance(&img).unwrap();
        // Each pixel plus the sum of all 192 input values (clamped to 255).
        assert_eq!(out.get_pixel(0, 0).0, [255, 255, 255]);
    }

    /// The shipped recommended enhancer (table, U-Net, face gate pixelating 16 x 16).
    fn shipped() -> (Vec<u8>, Enhancer) {
        let path = campro_testkit::workspace_root().join("params/campro-omega-0.5.enhancer.onnx");
        let bytes = std::fs::read(&path).unwrap();
        let e = Enhancer::from_bytes(&bytes, &path).unwrap();
        (bytes, e)
    }

    /// A textured test picture: gradients, a disc and stripes.
    fn picture(w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            let (fx, fy) = (x as f32 / w as f32, y as f32 / h as f32);
            let disc = ((fx - 0.5).powi(2) + (fy - 0.5).powi(2)) < 0.06;
            let stripe = (x / 3) % 2 == 0;
            image::Rgb([
                (255.0 * fx) as u8,
                if disc { 230 } else { (200.0 * fy) as u8 },
                if stripe { 40 } else { 180 } ^ (y as u8 & 0x1f),
            ])
        })
    }

    #[test]
    fn plans_are_kept_for_the_most_recent_sizes_only() {
        let ok = Enhancer::from_bytes(&tile_bomb(INPUT, [1, 1, 1, 1]), Path::new("ok.onnx")).unwrap();
        let m = ok.multiple();
        // The smallest size, planned at loading, then KEPT + 3 more: the oldest go.
        for k in 1..=crate::plans::KEPT + 3 {
            let out =
                ok.enhance(&image::RgbImage::from_pixel((k * m) as u32, m as u32, image::Rgb([1, 0, 0]))).unwrap();
            assert_eq!(out.dimensions(), ((k * m) as u32, m as u32));
        }
        let widths: Vec<usize> = ok.plans.keys().iter().map(|&(w, _, _)| w).collect();
        assert_eq!(widths, (4..=crate::plans::KEPT + 3).map(|k| k * m).collect::<Vec<_>>());
    }

    #[test]
    fn the_restoration_here_is_the_files_bit_for_bit() {
        let (bytes, e) = shipped();
        assert!(e.parts.table.is_some() && e.parts.gate == Some(16), "{:?}", e.parts.gate);
        let (w, h) = (2 * e.multiple, e.multiple);
        let img = picture(w as u32, h as u32);
        let (data, pw, ph) = padded_chw(&img, e.multiple);
        let model = tract_onnx::onnx()
            .model_for_read(&mut &bytes[..])
            .unwrap()
            .with_outputs_by_name([RESTORED])
            .unwrap()
            .with_input_fact(0, f32::fact([1, 3, ph, pw]).into())
            .unwrap()
            .into_optimized()
            .unwrap()
            .into_runnable()
            .unwrap();
        let input = Tensor::from_shape(&[1, 3, ph, pw], &data).unwrap();
        let out = model.run(tvec!(input.into())).unwrap();
        let want = out[0].try_as_plain_ram().unwrap().as_slice::<f32>().unwrap().to_vec();
        let got = e.parts.table.as_ref().unwrap().restore(&img, pw, ph);
        assert!(got == want, "the table read from the file differs from tract's run of it");
    }

    #[test]
    fn the_network_alone_and_the_blend_here_make_the_whole_file() {
        let (_, e) = shipped();
        let e = e.with_scale(Scale::Factor(1));
        let (w, h) = (3 * e.multiple as u32 + 5, 2 * e.multiple as u32 + 3);
        let img = picture(w, h);
        let whole = e.enhance(&img).unwrap();
        // Restoration here, the network cut out of the file, the gate's blend here.
        let (pw, ph) = ((w as usize).div_ceil(e.multiple) * e.multiple, (h as usize).div_ceil(e.multiple) * e.multiple);
        let restored = e.parts.table.as_ref().unwrap().restore(&img, pw, ph);
        let out = e.run(&e.plan(pw, ph, Outputs::Network).unwrap(), &restored, (pw, ph), 1).unwrap();
        let (ungated, gate) = (out[0].clone(), &out[1]);
        let toward = pixelated(&ungated, pw, ph, 16);
        let parts = cropped_rgb8(&blended(ungated, gate, &toward, pw * ph), pw, ph, w, h);
        let worst = whole.as_raw().iter().zip(parts.as_raw()).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        assert!(worst <= 1, "the parts differ from the whole file by {worst} LSB");
    }

    #[test]
    fn the_guided_upsampling_keeps_what_is_linear_in_the_input() {
        let (w, h) = (40usize, 24usize);
        let img = picture(w as u32, h as u32);
        let (input, pw, ph) = padded_chw(&img, 8);
        // An output that is 0.8 · input + 0.1 everywhere: gain 0.8 and offset 0.1 wherever
        // the window has texture (the regulariser pulls flat windows toward their mean).
        let output: Vec<f32> = input.iter().map(|v| 0.8 * v + 0.1).collect();
        let (gain, offset) = guided_coefficients(&input, &output, (w, h), pw, ph);
        let errors: Vec<f32> = (0..input.len()).map(|k| (gain[k] * input[k] + offset[k] - output[k]).abs()).collect();
        let (mean, worst) =
            (errors.iter().sum::<f32>() / errors.len() as f32, errors.iter().fold(0f32, |m, &e| m.max(e)));
        // In a window of variance v the gain is 0.8 · v / (v + eps): off by at most
        // 0.8 · eps / v times the pixel's distance to the window's mean.
        assert!(mean < 1e-3 && worst < 1e-2, "mean {mean}, worst {worst}");
        // A constant output is a zero gain and that constant.
        let flat = vec![0.25f32; input.len()];
        let (gain, offset) = guided_coefficients(&input, &flat, (w, h), pw, ph);
        assert!(gain.iter().all(|g| g.abs() < 1e-4) && offset.iter().all(|o| (o - 0.25).abs() < 1e-4));
    }

    #[test]
    fn the_reduced_network_follows_the_full_one_and_auto_picks_by_size() {
        assert_eq!(Scale::Auto.factor(640, 480), 1);
        assert_eq!(Scale::Auto.factor(1280, 720), 2);
        assert_eq!(Scale::Auto.factor(3840, 2160), 4);
        assert_eq!(Scale::Auto.factor(4032, 3024), 4);
        assert_eq!(Scale::Auto.factor(8160, 6120), 8);
        assert_eq!(Scale::Auto.factor(12000, 9000), 16);
        assert_eq!(Scale::Factor(1).factor(3840, 2160), 1);
        let (_, e) = shipped();
        let img = picture(256, 160);
        let full = e.with_scale(Scale::Factor(1)).enhance(&img).unwrap();
        let (_, e) = shipped();
        let half = e.with_scale(Scale::Factor(2)).enhance(&img).unwrap();
        assert_eq!(half.dimensions(), img.dimensions());
        let mse = full.as_raw().iter().zip(half.as_raw()).map(|(a, b)| (*a as f64 - *b as f64).powi(2)).sum::<f64>()
            / full.as_raw().len() as f64;
        let psnr = 10.0 * (255.0f64 * 255.0 / mse).log10();
        assert!(psnr > 25.0 && full != half, "half against full resolution: {psnr:.1} dB");
    }

    #[test]
    fn the_tensor_limit_follows_the_image() {
        assert_eq!(tensor_limit(8, 8), 64 << 20);
        assert_eq!(tensor_limit(1280, 720), 512 * 1280 * 720);
    }
}
