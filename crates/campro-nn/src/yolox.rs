//! The utility player P: YOLOX-Nano run by candle straight from its (batch-norm folded)
//! ONNX graph, so it can be fine-tuned and written back as ONNX for the evaluation.
//!
//! The graph is interpreted by [`OnnxNet`]; every Conv weight and bias becomes a trainable
//! [`Var`]. Input: (B, 3, H, W) **BGR** in 0..255, H and W multiples of
//! 32 (the network is fully convolutional; the ONNX file's fixed 416 only appears in its
//! final reshapes, which are read as "flatten the grid"). Output: (B, N, 85), per anchor the
//! raw (x, y, log w, log h), objectness and 80 class probabilities, anchors of strides 8,
//! 16, 32 in row-major grid order, as in the ONNX file.

use crate::onnx_net::{conv_attrs, f32_tensor, node, GraphError, OnnxNet};
use candle_core::{Result, Tensor, Var, D};
use std::path::Path;

/// The colour adapter's output tensor ([`Yolox::with_adapter`]).
const ADAPTED: &str = "adapter.y";

/// Strides of the three output grids.
pub const STRIDES: [usize; 3] = [8, 16, 32];

/// YOLOX-Nano with trainable convolutions (an [`OnnxNet`]).
pub struct Yolox {
    net: OnnxNet,
}

impl Yolox {
    /// Reads the ONNX file; any operator or attribute outside what YOLOX uses is an error
    /// naming the node.
    pub fn load(path: &Path, dev: &candle_core::Device) -> std::result::Result<Self, GraphError> {
        Ok(Self { net: OnnxNet::load(path, dev)? })
    }

    /// Every trainable tensor (conv weights and biases).
    pub fn vars(&self) -> Vec<Var> {
        self.net.vars()
    }

    /// Every trainable tensor with its ONNX initializer name.
    pub fn named_vars(&self) -> Vec<(String, Var)> {
        self.net.named_vars()
    }

    /// Writes the model with the current weights as ONNX (temporary file, then rename).
    pub fn save_onnx(&self, path: &Path) -> std::result::Result<(), GraphError> {
        self.net.save_onnx(path)
    }

    /// [`Self::save_onnx`] with the weights at half precision
    /// ([`crate::onnx_net::half_precision`]): what ships beside a parameter set.
    pub fn save_onnx_half(&self, path: &Path) -> std::result::Result<(), GraphError> {
        self.net.save_onnx_half(path)
    }

    /// Puts a per-pixel colour adapter with `hidden` units in front of the network:
    /// `x + 255·(W₂·SiLU(W₁·x/255 + b₁) + b₂)` on the BGR 0..255 input, as 1x1 convolutions
    /// in the graph itself (so the written ONNX file carries it). `W₁` is drawn from
    /// N(0, 1/3) by `seed`, the rest is zero, so the adapter starts as the identity and the
    /// detector's output is unchanged. The network keeps its current weights (new tensors,
    /// fresh optimiser state). Its tensors are named `adapter.*` ([`Self::adapter_and_rest`]).
    pub fn with_adapter(
        self,
        hidden: usize,
        seed: u64,
        dev: &candle_core::Device,
    ) -> std::result::Result<Self, GraphError> {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        let p = "adapter".to_string();
        if hidden == 0 {
            return Err(GraphError::Graph { path: p, message: "an adapter needs at least one hidden unit".into() });
        }
        let mut model = self.net.current()?;
        let graph = model.graph.as_mut().expect("checked in load");
        if graph.initializer.iter().any(|t| t.name.starts_with("adapter.")) {
            return Err(GraphError::Graph { path: p, message: "the model already has an adapter".into() });
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let normal = rand_distr::Normal::new(0.0f32, (1.0f32 / 3.0).sqrt()).expect("valid");
        let h = hidden as i64;
        graph.initializer.extend([
            f32_tensor("adapter.in", vec![], &[1.0 / 255.0]),
            f32_tensor(
                "adapter.w1",
                vec![h, 3, 1, 1],
                &(0..3 * hidden).map(|_| normal.sample(&mut rng)).collect::<Vec<_>>(),
            ),
            f32_tensor("adapter.b1", vec![h], &vec![0.0; hidden]),
            f32_tensor("adapter.w2", vec![3, h, 1, 1], &vec![0.0; 3 * hidden]),
            f32_tensor("adapter.b2", vec![3], &[0.0; 3]),
            f32_tensor("adapter.out", vec![], &[255.0]),
        ]);
        let input = self.net.input.clone();
        for n in graph.node.iter_mut() {
            for i in n.input.iter_mut().filter(|i| **i == input) {
                *i = ADAPTED.into();
            }
        }
        let front = vec![
            node("Mul", &[&input, "adapter.in"], "adapter.u", vec![]),
            node("Conv", &["adapter.u", "adapter.w1", "adapter.b1"], "adapter.z", conv_attrs(1, 1, 0)),
            node("Sigmoid", &["adapter.z"], "adapter.s", vec![]),
            node("Mul", &["adapter.z", "adapter.s"], "adapter.a", vec![]),
            node("Conv", &["adapter.a", "adapter.w2", "adapter.b2"], "adapter.r", conv_attrs(1, 1, 0)),
            node("Mul", &["adapter.r", "adapter.out"], "adapter.d", vec![]),
            node("Add", &[&input, "adapter.d"], ADAPTED, vec![]),
        ];
        graph.node.splice(0..0, front);
        Ok(Self { net: OnnxNet::from_model(model, p, dev)? })
    }

    /// The adapter's trainable tensors ([`Self::with_adapter`]; none without one) and every
    /// other trainable tensor.
    pub fn adapter_and_rest(&self) -> (Vec<Var>, Vec<Var>) {
        let (a, b): (Vec<_>, Vec<_>) = self.net.params.iter().partition(|(n, _)| n.starts_with("adapter."));
        (a.into_iter().map(|(_, v)| v.clone()).collect(), b.into_iter().map(|(_, v)| v.clone()).collect())
    }

    /// The raw head (B, N, 85) for `x` (B, 3, H, W), BGR 0..255.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (_, _, h, w) = x.dims4()?;
        if h % 32 != 0 || w % 32 != 0 {
            candle_core::bail!("YOLOX input {h}x{w}: height and width must be multiples of 32");
        }
        self.net.forward(x)
    }

    /// The colour adapter's output ([`Self::with_adapter`]) for `x` (B, 3, H, W), BGR
    /// 0..255, any H and W (it works pixel by pixel); an error without an adapter.
    pub fn adapt(&self, x: &Tensor) -> Result<Tensor> {
        if !self.net.index.contains_key("adapter.w1") {
            candle_core::bail!("the detector has no colour adapter");
        }
        let mut v = self.net.run(x, Some(ADAPTED))?;
        v.remove(ADAPTED).ok_or_else(|| candle_core::Error::Msg("the detector has no colour adapter".into()))
    }
}

/// Anchor centres and strides of the output grids for an `h` x `w` input: per anchor
/// (column, row, stride), in the head's order.
pub fn anchors(h: usize, w: usize) -> Vec<(f32, f32, f32)> {
    let mut out = Vec::new();
    for s in STRIDES {
        for row in 0..h / s {
            for col in 0..w / s {
                out.push((col as f32, row as f32, s as f32));
            }
        }
    }
    out
}

/// Raw head (B, N, 85) → boxes (B, N, 4) as (cx, cy, w, h) in input pixels, differentiable.
pub fn decode_boxes(head: &Tensor, h: usize, w: usize) -> Result<Tensor> {
    let a = anchors(h, w);
    let dev = head.device();
    let grid = Tensor::from_vec(a.iter().flat_map(|&(c, r, _)| [c, r]).collect::<Vec<_>>(), (1, a.len(), 2), dev)?;
    let stride = Tensor::from_vec(a.iter().map(|&(_, _, s)| s).collect::<Vec<_>>(), (1, a.len(), 1), dev)?;
    let xy = head.narrow(D::Minus1, 0, 2)?.broadcast_add(&grid)?.broadcast_mul(&stride)?;
    let wh = head.narrow(D::Minus1, 2, 2)?.exp()?.broadcast_mul(&stride)?;
    Tensor::cat(&[xy, wh], D::Minus1)
}
