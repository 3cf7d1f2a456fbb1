//! Activations as candle custom ops with their own backward: PReLU (one slope per
//! channel), SiLU and ReLU, each one pass forward and one backward on the CPU; on another
//! device, the same functions built from candle's generic ops ([`prelu_generic`],
//! [`silu_generic`], [`relu_generic`]), which the tests also check the CPU ops against.

use crate::storage::{per_channel, plane, slice};
use candle_core::{CpuStorage, CustomOp2, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

/// PReLU with one slope per channel: `y = x` where `x > 0`, else `a_c · x`.
struct Prelu;

impl CustomOp2 for Prelu {
    fn name(&self) -> &'static str {
        "campro-prelu"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (x, a) = (slice(s1, l1, "prelu")?, slice(s2, l2, "prelu")?);
        let (c, n) = plane(l1.dims(), a.len())?;
        let mut y = crate::kernels::zeros(x.len());
        y.par_chunks_mut(n).zip(x.par_chunks(n)).enumerate().for_each(|(pl, (yp, xp))| {
            crate::kernels::prelu(yp, xp, a[pl % c]);
        });
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, a: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        // One op reads x and dy in place and writes dx then da into one buffer (two views).
        let slopes = a.track_op();
        let both = x.apply_op3_no_bwd(&grad.contiguous()?, &a.contiguous()?, &PreluGrad { slopes })?;
        let n = x.elem_count();
        let dx = if x.track_op() { Some(both.narrow(0, 0, n)?.reshape(x.shape())?) } else { None };
        let da = if slopes { Some(both.narrow(0, n, a.elem_count())?.reshape(a.shape())?) } else { None };
        Ok((dx, da))
    }
}

/// The backward of [`Prelu`] from (x, dy, a): dx (as x), then da (C; zeros unless `slopes`).
struct PreluGrad {
    slopes: bool,
}

impl candle_core::CustomOp3 for PreluGrad {
    fn name(&self) -> &'static str {
        "campro-prelu-grad"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (xv, gv, av) = (slice(s1, l1, "prelu")?, slice(s2, l2, "prelu")?, slice(s3, l3, "prelu")?);
        let (c, n) = plane(l1.dims(), av.len())?;
        if gv.len() != xv.len() {
            candle_core::bail!("prelu: gradient of {} values for {} inputs", gv.len(), xv.len());
        }
        let mut out = crate::kernels::zeros(xv.len() + c);
        let (dx, da) = out.split_at_mut(xv.len());
        let per: Vec<f32> = dx
            .par_chunks_mut(n)
            .enumerate()
            .map(|(pl, d)| {
                let (xp, gp) = (&xv[pl * n..(pl + 1) * n], &gv[pl * n..(pl + 1) * n]);
                crate::kernels::prelu_grad(d, xp, gp, av[pl % c])
            })
            .collect();
        if self.slopes {
            let acc = per_channel(per.iter().map(|&v| v as f64), c);
            da.iter_mut().zip(acc).for_each(|(o, v)| *o = v as f32);
        }
        let len = out.len();
        Ok((CpuStorage::F32(out), Shape::from(len)))
    }
}

/// PReLU: `x` (B, C, ...), `a` (C,); differentiable in both.
pub fn prelu(x: &Tensor, a: &Tensor) -> Result<Tensor> {
    if !x.device().is_cpu() {
        return prelu_generic(x, a);
    }
    x.contiguous()?.apply_op2(&a.contiguous()?, Prelu)
}

/// PReLU from candle's generic ops: `relu(x) − a_c · relu(−x)`.
pub fn prelu_generic(x: &Tensor, a: &Tensor) -> Result<Tensor> {
    let mut shape = vec![1; x.rank()];
    shape[1] = a.elem_count();
    x.relu()? - x.neg()?.relu()?.broadcast_mul(&a.reshape(shape)?)?
}

/// An element-wise activation with its own backward, one pass each way: forward
/// `y = f(x)`, backward `dx = dy · f'(x)` read from the saved input. Fused here because
/// candle's generic ops take several passes and saved tensors for each (SiLU from the ONNX
/// graph's Sigmoid and Mul: two ops, four passes; ReLU: a comparison, a cast and a product
/// backward). A type per activation, so its loops are compiled for the CPU's vector width.
trait Pointwise: Copy + Send + Sync + 'static {
    const NAME: &'static str;
    /// `y = f(x)` over one chunk.
    fn forward(y: &mut [f32], x: &[f32]);
    /// `dx = dy · f'(x)` over one chunk.
    fn backward(dx: &mut [f32], x: &[f32], g: &[f32]);
}

/// SiLU: `x · σ(x)`, `dy/dx = σ(x)·(1 + x·(1 − σ(x)))`, with [`crate::kernels::exp`]
/// (relative error below 4e-7).
#[derive(Clone, Copy)]
struct Silu;

impl Pointwise for Silu {
    const NAME: &'static str = "campro-silu";
    fn forward(y: &mut [f32], x: &[f32]) {
        crate::kernels::silu(y, x);
    }
    fn backward(dx: &mut [f32], x: &[f32], g: &[f32]) {
        crate::kernels::silu_grad(dx, x, g);
    }
}

/// ReLU: `max(x, 0)`, gradient 1 where `x > 0`, else 0 (as candle's).
#[derive(Clone, Copy)]
struct Relu;

impl Pointwise for Relu {
    const NAME: &'static str = "campro-relu";
    fn forward(y: &mut [f32], x: &[f32]) {
        y.iter_mut().zip(x).for_each(|(o, &v)| *o = v.max(0.0));
    }
    fn backward(dx: &mut [f32], x: &[f32], g: &[f32]) {
        for ((o, &v), &gv) in dx.iter_mut().zip(x).zip(g) {
            *o = if v > 0.0 { gv } else { 0.0 };
        }
    }
}

/// The forward op of a [`Pointwise`] activation.
struct Activation<A>(A);

impl<A: Pointwise> candle_core::CustomOp1 for Activation<A> {
    fn name(&self) -> &'static str {
        A::NAME
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = slice(s, l, A::NAME)?;
        let mut y = crate::kernels::zeros(x.len());
        y.par_chunks_mut(4096).zip(x.par_chunks(4096)).for_each(|(o, i)| A::forward(o, i));
        Ok((CpuStorage::F32(y), l.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(x.apply_op2_no_bwd(&grad.contiguous()?, &ActivationGrad(self.0))?))
    }
}

/// The input gradient of a [`Pointwise`] activation from (x, dy), reading both in place.
struct ActivationGrad<A>(A);

impl<A: Pointwise> CustomOp2 for ActivationGrad<A> {
    fn name(&self) -> &'static str {
        "campro-activation-grad"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (x, g) = (slice(s1, l1, A::NAME)?, slice(s2, l2, A::NAME)?);
        if x.len() != g.len() {
            candle_core::bail!("{}: gradient of {} values for {} inputs", A::NAME, g.len(), x.len());
        }
        let mut dx = crate::kernels::zeros(x.len());
        dx.par_chunks_mut(4096)
            .zip(x.par_chunks(4096).zip(g.par_chunks(4096)))
            .for_each(|(o, (xs, gs))| A::backward(o, xs, gs));
        Ok((CpuStorage::F32(dx), l1.shape().clone()))
    }
}

/// SiLU (`x · σ(x)`) of any tensor; differentiable.
pub fn silu(x: &Tensor) -> Result<Tensor> {
    if !x.device().is_cpu() {
        return silu_generic(x);
    }
    x.contiguous()?.apply_op1(Activation(Silu))
}

/// ReLU of any tensor; differentiable (the gradient at 0 is 0, as candle's).
pub fn relu(x: &Tensor) -> Result<Tensor> {
    if !x.device().is_cpu() {
        return relu_generic(x);
    }
    x.contiguous()?.apply_op1(Activation(Relu))
}

/// SiLU from candle's generic ops: `x · sigmoid(x)`, as the ONNX graph has it.
pub fn silu_generic(x: &Tensor) -> Result<Tensor> {
    x.mul(&candle_nn::ops::sigmoid(x)?)
}

/// ReLU from candle's generic ops.
pub fn relu_generic(x: &Tensor) -> Result<Tensor> {
    x.relu()
}
