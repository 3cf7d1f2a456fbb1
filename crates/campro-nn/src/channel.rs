//! Per-channel ops on (B, C, ...) tensors as candle custom ops: a convolution's bias and
//! evaluation-mode batch norm (`x · scale + shift`), each one pass each way on the CPU; on
//! another device, the same from candle's broadcasts ([`channel_bias_generic`],
//! [`channel_affine_generic`]).

use crate::storage::{per_channel, plane, slice};
use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

/// (channels, plane size) of a (B, C, H, W) operand.
fn planes(l: &Layout) -> Result<(usize, usize)> {
    match l.dims() {
        &[_, c, h, w] => Ok((c, h * w)),
        d => candle_core::bail!("channel affine: expected (B, C, H, W), got {d:?}"),
    }
}

/// `x + b_c` per channel of (B, C, ...) (`b` of shape (C,)): a convolution's bias, one pass
/// forward; backward passes the gradient through and sums it per channel for `b`.
struct ChannelBias;

impl CustomOp2 for ChannelBias {
    fn name(&self) -> &'static str {
        "campro-channel-bias"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (x, b) = (slice(s1, l1, "bias")?, slice(s2, l2, "bias")?);
        let (c, n) = plane(l1.dims(), b.len())?;
        let mut y = crate::kernels::zeros(x.len());
        y.par_chunks_mut(n).zip(x.par_chunks(n)).enumerate().for_each(|(p, (yp, xp))| {
            crate::kernels::affine(yp, xp, 1.0, b[p % c]);
        });
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, b: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let dx = if x.track_op() { Some(grad.clone()) } else { None };
        let db = if b.track_op() {
            let c = b.elem_count();
            Some(grad.contiguous()?.apply_op1_no_bwd(&ChannelSum { c })?)
        } else {
            None
        };
        Ok((dx, db))
    }
}

/// Per channel sums of a (B, C, ...) tensor: (C,), accumulated in f64.
struct ChannelSum {
    c: usize,
}

impl candle_core::CustomOp1 for ChannelSum {
    fn name(&self) -> &'static str {
        "campro-channel-sum"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let g = slice(s, l, "bias")?;
        let (c, n) = plane(l.dims(), self.c)?;
        let per: Vec<f64> = g.par_chunks(n).map(|p| p.iter().map(|&v| v as f64).sum()).collect();
        let out: Vec<f32> = per_channel(per, c).into_iter().map(|v| v as f32).collect();
        Ok((CpuStorage::F32(out), Shape::from(c)))
    }
}

/// `x + b` per channel: `x` (B, C, ...), `b` (C,); differentiable in both.
pub fn channel_bias(x: &Tensor, b: &Tensor) -> Result<Tensor> {
    if !x.device().is_cpu() {
        return channel_bias_generic(x, b);
    }
    x.contiguous()?.apply_op2(&b.contiguous()?, ChannelBias)
}

/// y = x · scale_c + shift_c per channel c of (B, C, H, W): evaluation-mode batch norm with
/// folded statistics, one pass each way. From generic ops its two broadcasts and their
/// gradients (strided reductions over batch and pixels) cost more than the convolution.
struct ChannelAffine;

impl ChannelAffine {
    /// Per channel (Σ dy·x, Σ dy) over batch and pixels, in f64.
    fn sums(x: &[f32], g: &[f32], c: usize, n: usize) -> Vec<(f64, f64)> {
        let planes = x.len() / n;
        let per: Vec<(f64, f64)> = (0..planes)
            .into_par_iter()
            .map(|p| {
                let (s, sx) =
                    crate::kernels::sum_and_centred_dot(&g[p * n..(p + 1) * n], &x[p * n..(p + 1) * n], 0.0, 1.0);
                (sx as f64, s as f64)
            })
            .collect();
        let sx = per_channel(per.iter().map(|p| p.0), c);
        let s = per_channel(per.iter().map(|p| p.1), c);
        sx.into_iter().zip(s).collect()
    }
}

impl CustomOp3 for ChannelAffine {
    fn name(&self) -> &'static str {
        "channel-affine"
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
        let (c, n) = planes(l1)?;
        let (x, scale, shift) =
            (slice(s1, l1, "channel affine")?, slice(s2, l2, "channel affine")?, slice(s3, l3, "channel affine")?);
        if scale.len() != c || shift.len() != c {
            candle_core::bail!("channel affine: scale and shift must have {c} entries");
        }
        let mut y = crate::kernels::zeros(x.len());
        y.par_chunks_mut(n).zip(x.par_chunks(n)).enumerate().for_each(|(p, (yp, xp))| {
            crate::kernels::affine(yp, xp, scale[p % c], shift[p % c]);
        });
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        scale: &Tensor,
        shift: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        // One op reads x and dy in place and writes dx, then d(scale) and d(shift), into one
        // buffer (three views); the sums only when the scale or shift is tracked.
        let c = scale.elem_count();
        let sums = scale.track_op() || shift.track_op();
        let all = x.apply_op3_no_bwd(&grad.contiguous()?, &scale.contiguous()?, &ChannelAffineGrad { sums })?;
        let n = x.elem_count();
        let dx = if x.track_op() { Some(all.narrow(0, 0, n)?.reshape(x.shape())?) } else { None };
        let (ds, db) = if sums { (Some(all.narrow(0, n, c)?), Some(all.narrow(0, n + c, c)?)) } else { (None, None) };
        Ok((dx, ds, db))
    }
}

/// The backward of [`ChannelAffine`] from (x, dy, scale): dx, then Σ dy·x and Σ dy per
/// channel (zeros unless `sums`), flat in one buffer.
struct ChannelAffineGrad {
    sums: bool,
}

impl CustomOp3 for ChannelAffineGrad {
    fn name(&self) -> &'static str {
        "channel-affine-grad"
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
        let (c, n) = planes(l1)?;
        let (xv, gv, a) =
            (slice(s1, l1, "channel affine")?, slice(s2, l2, "channel affine")?, slice(s3, l3, "channel affine")?);
        if gv.len() != xv.len() || a.len() != c {
            candle_core::bail!("channel affine grad: operands do not match");
        }
        let mut out = crate::kernels::zeros(xv.len() + 2 * c);
        let (dx, rest) = out.split_at_mut(xv.len());
        dx.par_chunks_mut(n).zip(gv.par_chunks(n)).enumerate().for_each(|(p, (d, g))| {
            crate::kernels::affine(d, g, a[p % c], 0.0);
        });
        if self.sums {
            for (ch, (sx, s)) in ChannelAffine::sums(xv, gv, c, n).into_iter().enumerate() {
                rest[ch] = sx as f32;
                rest[c + ch] = s as f32;
            }
        }
        let len = out.len();
        Ok((CpuStorage::F32(out), Shape::from(len)))
    }
}

/// `x · scale + shift` per channel of (B, C, H, W) (`scale`, `shift` of shape (C,));
/// differentiable in all three.
pub fn channel_affine(x: &Tensor, scale: &Tensor, shift: &Tensor) -> Result<Tensor> {
    if !x.device().is_cpu() {
        return channel_affine_generic(x, scale, shift);
    }
    x.contiguous()?.apply_op3(&scale.contiguous()?, &shift.contiguous()?, ChannelAffine)
}

/// `v` (C,) shaped to broadcast over the channels of `x` (B, C, ...).
fn per_channel_view(x: &Tensor, v: &Tensor) -> Result<Tensor> {
    let mut shape = vec![1; x.rank()];
    shape[1] = v.elem_count();
    v.reshape(shape)
}

/// `x + b` per channel from candle's broadcasts.
pub fn channel_bias_generic(x: &Tensor, b: &Tensor) -> Result<Tensor> {
    x.broadcast_add(&per_channel_view(x, b)?)
}

/// `x · scale + shift` per channel from candle's broadcasts.
pub fn channel_affine_generic(x: &Tensor, scale: &Tensor, shift: &Tensor) -> Result<Tensor> {
    x.broadcast_mul(&per_channel_view(x, scale)?)?.broadcast_add(&per_channel_view(x, shift)?)
}
