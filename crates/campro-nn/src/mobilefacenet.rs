//! MobileFaceNet (Chen et al. 2018) as in Xiaoccer/MobileFaceNet_Pytorch, the white-box
//! attacker backbone: 112x96 RGB input `(x − 127.5) / 128`, 128-d embedding. Weights and
//! batch-norm statistics come from its PyTorch checkpoint, names unchanged, into a
//! [`VarMap`] so the attacker can be trained.
//!
//! Convolutions and PReLU are campro's own ops with their own backward
//! ([`crate::conv::conv2d`], [`depthwise`], batch norm with PReLU fused in
//! [`crate::batch_norm::batch_norm_train`]): candle runs a grouped
//! convolution as one convolution per group (hundreds of tiny kernels per layer here), its
//! CPU convolution backward is a naive loop, and PReLU from generic ops is five passes.

use crate::conv::conv2d;
pub use crate::depthwise::depthwise;
use crate::torch_legacy::{read_state_dict, TorchError};
use candle_core::{DType, Device, Result, Tensor, Var, D};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;

/// Bottleneck settings (expansion t, output channels c, repeats n, first stride s).
const SETTINGS: [(usize, usize, usize, usize); 5] =
    [(2, 64, 5, 2), (4, 128, 1, 2), (2, 128, 6, 1), (4, 128, 1, 2), (2, 128, 2, 1)];

/// Input size (height, width).
pub const INPUT: (usize, usize) = (112, 96);
/// Embedding size.
pub const EMBEDDING: usize = 128;

/// Batch norm over (B, C, H, W), PyTorch's semantics (eps 1e-5, momentum 0.1, running
/// variance unbiased). Training normalises by the batch statistics and updates the running
/// ones; evaluation is one per-channel scale and shift.
#[derive(Clone)]
struct BatchNorm {
    weight: Tensor,
    bias: Tensor,
    running_mean: Var,
    running_var: Var,
}

impl BatchNorm {
    const EPS: f64 = 1e-5;
    const MOMENTUM: f64 = 0.1;

    fn new(vb: VarBuilder, c: usize) -> Result<Self> {
        Ok(Self {
            weight: vb.get_with_hints(c, "weight", candle_nn::Init::Const(1.0))?,
            bias: vb.get_with_hints(c, "bias", candle_nn::Init::Const(0.0))?,
            running_mean: Var::from_tensor(&vb.get_with_hints(c, "running_mean", candle_nn::Init::Const(0.0))?)?,
            running_var: Var::from_tensor(&vb.get_with_hints(c, "running_var", candle_nn::Init::Const(1.0))?)?,
        })
    }

    /// The normalised `x`, then PReLU with slopes `prelu` if given (fused in training).
    fn forward(&self, x: &Tensor, train: bool, prelu: Option<&Tensor>) -> Result<Tensor> {
        let c = self.weight.dim(0)?;
        if !train {
            // The running statistics are state, not parameters: no gradient reaches them.
            let scale = (self.weight.as_ref() / (self.running_var.as_tensor().detach() + Self::EPS)?.sqrt()?)?;
            let shift = (&self.bias - self.running_mean.as_tensor().detach().mul(&scale)?)?;
            let y = crate::channel::channel_affine(x, &scale, &shift)?;
            return match prelu {
                Some(a) => crate::activation::prelu(&y, a),
                None => Ok(y),
            };
        }
        let n = (x.elem_count() / c) as f64;
        let (y, stats) = crate::batch_norm::batch_norm_train(x, &self.weight, &self.bias, Self::EPS, prelu)?;
        let (mean, var) = (stats.get(0)?, stats.get(1)?);
        let m = Self::MOMENTUM;
        self.running_mean.set(&((self.running_mean.as_tensor() * (1.0 - m))? + (mean * m)?)?)?;
        self.running_var
            .set(&((self.running_var.as_tensor() * (1.0 - m))? + (var * (m * n / (n - 1.0).max(1.0)))?)?)?;
        Ok(y)
    }
}

/// Convolution (no bias) + batch norm (+ PReLU).
#[derive(Clone)]
struct ConvBlock {
    w: Tensor,
    stride: usize,
    pad: usize,
    depthwise: bool,
    bn: BatchNorm,
    prelu: Option<Tensor>,
}

impl ConvBlock {
    #[allow(clippy::too_many_arguments)]
    fn new(
        vb: &VarBuilder,
        cin: usize,
        cout: usize,
        k: (usize, usize),
        stride: usize,
        pad: usize,
        depthwise: bool,
        linear: bool,
        names: (&str, &str, &str),
    ) -> Result<Self> {
        let w = if depthwise { vb.get((cout, 1, k.0, k.1), names.0)? } else { vb.get((cout, cin, k.0, k.1), names.0)? };
        let bn = BatchNorm::new(vb.pp(names.1), cout)?;
        let prelu = if linear { None } else { Some(vb.get(cout, names.2)?) };
        Ok(Self { w, stride, pad, depthwise, bn, prelu })
    }

    fn forward(&self, x: &Tensor, train: bool) -> Result<Tensor> {
        let y = if self.depthwise {
            depthwise(x, &self.w, self.stride, self.pad)?
        } else {
            conv2d(x, &self.w, self.stride, self.pad)?
        };
        self.bn.forward(&y, train, self.prelu.as_ref())
    }
}

#[derive(Clone)]
struct Bottleneck {
    expand: ConvBlock,
    dw: ConvBlock,
    project: ConvBlock,
    residual: bool,
}

/// The network; its parameters live in the [`VarMap`] it was built from.
#[derive(Clone)]
pub struct MobileFaceNet {
    conv1: ConvBlock,
    dw_conv1: ConvBlock,
    blocks: Vec<Bottleneck>,
    conv2: ConvBlock,
    linear7: ConvBlock,
    linear1: ConvBlock,
}

impl MobileFaceNet {
    /// Builds the network over `vb` (fresh variables, or ones already loaded).
    pub fn new(vb: VarBuilder) -> Result<Self> {
        let std = ("conv.weight", "bn", "prelu.weight");
        let conv1 = ConvBlock::new(&vb.pp("conv1"), 3, 64, (3, 3), 2, 1, false, false, std)?;
        let dw_conv1 = ConvBlock::new(&vb.pp("dw_conv1"), 64, 64, (3, 3), 1, 1, true, false, std)?;
        let mut blocks = Vec::new();
        let mut cin = 64;
        for (t, c, n, s) in SETTINGS {
            for i in 0..n {
                let stride = if i == 0 { s } else { 1 };
                let vb = vb.pp(format!("blocks.{}.conv", blocks.len()));
                let hid = cin * t;
                blocks.push(Bottleneck {
                    expand: ConvBlock::new(&vb, cin, hid, (1, 1), 1, 0, false, false, ("0.weight", "1", "2.weight"))?,
                    dw: ConvBlock::new(&vb, hid, hid, (3, 3), stride, 1, true, false, ("3.weight", "4", "5.weight"))?,
                    project: ConvBlock::new(&vb, hid, c, (1, 1), 1, 0, false, true, ("6.weight", "7", ""))?,
                    residual: stride == 1 && cin == c,
                });
                cin = c;
            }
        }
        let conv2 = ConvBlock::new(&vb.pp("conv2"), 128, 512, (1, 1), 1, 0, false, false, std)?;
        let linear7 = ConvBlock::new(&vb.pp("linear7"), 512, 512, (7, 6), 1, 0, true, true, std)?;
        let linear1 = ConvBlock::new(&vb.pp("linear1"), 512, 128, (1, 1), 1, 0, false, true, std)?;
        Ok(Self { conv1, dw_conv1, blocks, conv2, linear7, linear1 })
    }

    /// Loads the checkpoint (`net_state_dict` of a legacy `torch.save`) into a new VarMap.
    pub fn from_checkpoint(path: &Path, device: &Device) -> std::result::Result<(Self, VarMap), TorchError> {
        let sd = read_state_dict(path, Some("net_state_dict"), device)?;
        let bad =
            |e: candle_core::Error| TorchError::Format { path: path.display().to_string(), message: e.to_string() };
        let vm = VarMap::new();
        let net = Self::new(VarBuilder::from_varmap(&vm, DType::F32, device)).map_err(bad)?;
        let vars = vm.data().lock().expect("var map lock");
        for (name, var) in vars.iter() {
            let t = sd.get(name).ok_or_else(|| TorchError::Format {
                path: path.display().to_string(),
                message: format!("{name} missing from the checkpoint"),
            })?;
            if t.dims() != var.dims() {
                return Err(TorchError::Format {
                    path: path.display().to_string(),
                    message: format!("{name}: shape {:?}, expected {:?}", t.dims(), var.dims()),
                });
            }
            var.set(&t.to_device(device).map_err(bad)?).map_err(bad)?;
        }
        drop(vars);
        Ok((net, vm))
    }

    /// The trainable variables of `vars` (the map `from_checkpoint` returned): everything but
    /// the batch-norm running statistics.
    pub fn trainable(vars: &VarMap) -> Vec<Var> {
        vars.data()
            .lock()
            .expect("var map lock")
            .iter()
            .filter(|(k, _)| !k.contains("running_"))
            .map(|(_, v)| v.clone())
            .collect()
    }

    /// The same network with its weights detached from the [`VarMap`]: they share storage
    /// (an optimiser step on the variables shows here too), but no gradient is computed for
    /// them. For the protector's steps, which need only the gradient into the camera.
    pub fn frozen(&self) -> Self {
        let mut f = self.clone();
        for b in f.blocks_mut() {
            b.w = b.w.detach();
            b.bn.weight = b.bn.weight.detach();
            b.bn.bias = b.bn.bias.detach();
            b.prelu = b.prelu.as_ref().map(Tensor::detach);
        }
        f
    }

    /// Every convolution block, in order.
    fn blocks_mut(&mut self) -> impl Iterator<Item = &mut ConvBlock> {
        let inner = self.blocks.iter_mut().flat_map(|b| [&mut b.expand, &mut b.dw, &mut b.project]);
        [&mut self.conv1, &mut self.dw_conv1].into_iter().chain(inner).chain([
            &mut self.conv2,
            &mut self.linear7,
            &mut self.linear1,
        ])
    }

    /// Embeddings (B, 128) of normalised faces (B, 3, 112, 96); `train` uses and updates
    /// the batch statistics.
    pub fn forward_t(&self, x: &Tensor, train: bool) -> Result<Tensor> {
        let mut x = self.conv1.forward(x, train)?;
        x = self.dw_conv1.forward(&x, train)?;
        for b in &self.blocks {
            let y = b.project.forward(&b.dw.forward(&b.expand.forward(&x, train)?, train)?, train)?;
            x = if b.residual { (x + y)? } else { y };
        }
        x = self.conv2.forward(&x, train)?;
        x = self.linear7.forward(&x, train)?;
        x = self.linear1.forward(&x, train)?;
        x.flatten_from(1)
    }

    /// Unit-length embeddings (B, 128) of sRGB faces (B, 3, 112, 96) in [0, 1]:
    /// [`normalise_unit`], [`MobileFaceNet::forward_t`], [`l2_normalise`].
    pub fn embed(&self, x: &Tensor, train: bool) -> Result<Tensor> {
        l2_normalise(&self.forward_t(&normalise_unit(x)?, train)?)
    }
}

/// `(x − 127.5) / 128` for x in 0..255, or `(255·x − 127.5) / 128` for x in [0, 1].
pub fn normalise_unit(x: &Tensor) -> Result<Tensor> {
    x.affine(255.0 / 128.0, -127.5 / 128.0)
}

/// L2-normalised rows.
pub fn l2_normalise(x: &Tensor) -> Result<Tensor> {
    let n = x.sqr()?.sum_keepdim(D::Minus1)?.sqrt()?.clamp(1e-12, f64::INFINITY)?;
    x.broadcast_div(&n)
}
