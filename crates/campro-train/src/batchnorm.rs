//! Training-mode batch normalisation over (B, C, H, W) as one candle custom op with a fused
//! backward (the textbook formulas, per channel, channels in parallel). Built from generic
//! candle ops, the batch statistics and their gradients cost several full passes and
//! strided reductions each: most of an attacker step on the CPU.

use candle_core::{CpuStorage, CustomOp1, CustomOp3, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

fn slice<'a>(s: &'a CpuStorage, l: &Layout) -> Result<&'a [f32]> {
    crate::conv::slice(s, l, "batch norm")
}

fn dims(l: &Layout) -> Result<(usize, usize, usize)> {
    match l.dims() {
        &[b, c, h, w] => Ok((b, c, h * w)),
        d => candle_core::bail!("batch norm: expected (B, C, H, W), got {d:?}"),
    }
}

/// Per channel (mean, biased variance), computed in f64: a (2, C) tensor.
struct Stats;

impl CustomOp1 for Stats {
    fn name(&self) -> &'static str {
        "batch-norm-stats"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, c, n) = dims(l)?;
        let x = slice(s, l)?;
        let per: Vec<(f32, f32)> = (0..c)
            .into_par_iter()
            .map(|ch| {
                let (mut s1, mut s2) = (0f64, 0f64);
                for bi in 0..b {
                    for &v in &x[(bi * c + ch) * n..(bi * c + ch + 1) * n] {
                        s1 += v as f64;
                        s2 += (v as f64) * (v as f64);
                    }
                }
                let m = s1 / (b * n) as f64;
                (m as f32, (s2 / (b * n) as f64 - m * m).max(0.0) as f32)
            })
            .collect();
        let mut out: Vec<f32> = per.iter().map(|p| p.0).collect();
        out.extend(per.iter().map(|p| p.1));
        Ok((CpuStorage::F32(out), Shape::from((2, c))))
    }
}

/// y = γ (x − μ) / sqrt(σ² + eps) + β with the given batch statistics.
struct Normalise {
    eps: f64,
}

impl Normalise {
    /// Per channel (mean, 1 / sqrt(var + eps), γ, β).
    fn coefs(&self, affine: &[f32], stats: &[f32], c: usize) -> Vec<[f32; 4]> {
        (0..c)
            .map(|ch| [stats[ch], (1.0 / (stats[c + ch] as f64 + self.eps).sqrt()) as f32, affine[ch], affine[c + ch]])
            .collect()
    }
}

impl CustomOp3 for Normalise {
    fn name(&self) -> &'static str {
        "batch-norm-train"
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
        let (_, c, n) = dims(l1)?;
        let (x, affine, stats) = (slice(s1, l1)?, slice(s2, l2)?, slice(s3, l3)?);
        if affine.len() != 2 * c || stats.len() != 2 * c {
            candle_core::bail!("batch norm: affine and stats must be (2, {c})");
        }
        let k = self.coefs(affine, stats, c);
        let mut y = crate::kernels::zeros(x.len());
        y.par_chunks_mut(n).zip(x.par_chunks(n)).enumerate().for_each(|(p, (yp, xp))| {
            let [m, r, g, b] = k[p % c];
            crate::kernels::affine(yp, xp, r * g, b - m * r * g);
        });
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        affine: &Tensor,
        stats: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        // One op reads x and dy where they lie and writes dx and (dγ, dβ) into one buffer,
        // returned as two views of it (no copies of the activations).
        let (_, c, _, _) = x.dims4()?;
        let coefs = Tensor::cat(&[affine.flatten_all()?, stats.flatten_all()?], 0)?;
        let both = x.apply_op3_no_bwd(&grad.contiguous()?, &coefs, &NormaliseGrad { eps: self.eps })?;
        let n = x.elem_count();
        let dx = both.narrow(0, 0, n)?.reshape(x.shape())?;
        let da = both.narrow(0, n, 2 * c)?.reshape((2, c))?;
        Ok((Some(dx), Some(da), None))
    }
}

/// The backward of [`Normalise`] from (x, dy, [γ, β, μ, σ²]): dx (as x) then dγ, dβ (C each),
/// flat in one buffer.
struct NormaliseGrad {
    eps: f64,
}

impl CustomOp3 for NormaliseGrad {
    fn name(&self) -> &'static str {
        "batch-norm-train-grad"
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
        let (b, c, n) = dims(l1)?;
        let (xv, gv, coefs) = (slice(s1, l1)?, slice(s2, l2)?, slice(s3, l3)?);
        if gv.len() != xv.len() || coefs.len() != 4 * c {
            candle_core::bail!("batch norm grad: operands do not match");
        }
        let k = Normalise { eps: self.eps }.coefs(&coefs[..2 * c], &coefs[2 * c..], c);
        let total = (b * n) as f32;
        // Per channel: Σ dy and Σ dy·x̂ (per plane in f32 lanes, over the batch in f64).
        let sums: Vec<(f32, f32)> = (0..c)
            .into_par_iter()
            .map(|ch| {
                let [m, r, _, _] = k[ch];
                let (mut sd, mut sdx) = (0f64, 0f64);
                for bi in 0..b {
                    let o = (bi * c + ch) * n;
                    let (a, bb) = crate::kernels::sum_and_centred_dot(&gv[o..o + n], &xv[o..o + n], m, r);
                    sd += a as f64;
                    sdx += bb as f64;
                }
                (sd as f32, sdx as f32)
            })
            .collect();
        // dx = γ r / N · (N dy − Σdy − x̂ Σ(dy x̂)).
        let mut out = crate::kernels::zeros(xv.len() + 2 * c);
        let (dx, da) = out.split_at_mut(xv.len());
        dx.par_chunks_mut(n).enumerate().for_each(|(p, d)| {
            let ch = p % c;
            let [m, r, g, _] = k[ch];
            let (sd, sdx) = sums[ch];
            let o = p * n;
            crate::kernels::batch_norm_grad(d, &xv[o..o + n], &gv[o..o + n], [m, r, g * r / total, total, sd, sdx]);
        });
        for (ch, (sd, sdx)) in sums.iter().enumerate() {
            da[ch] = *sdx; // dγ = Σ dy·x̂
            da[c + ch] = *sd; // dβ = Σ dy
        }
        let len = out.len();
        Ok((CpuStorage::F32(out), Shape::from(len)))
    }
}

/// Training-mode batch norm: returns the output and the batch (mean, biased variance) as a
/// (2, C) tensor (for the running statistics). Differentiable in `x`, `weight` and `bias`.
pub fn batch_norm_train(x: &Tensor, weight: &Tensor, bias: &Tensor, eps: f64) -> Result<(Tensor, Tensor)> {
    let x = x.contiguous()?;
    let stats = x.apply_op1_no_bwd(&Stats)?;
    let affine = Tensor::stack(&[weight, bias], 0)?;
    let y = x.apply_op3(&affine, &stats, Normalise { eps })?;
    Ok((y, stats))
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
        let sx = crate::conv::per_channel(per.iter().map(|p| p.0), c);
        let s = crate::conv::per_channel(per.iter().map(|p| p.1), c);
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
        let (_, c, n) = dims(l1)?;
        let (x, scale, shift) = (slice(s1, l1)?, slice(s2, l2)?, slice(s3, l3)?);
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
        let (_, c, n) = dims(l1)?;
        let (xv, gv, a) = (slice(s1, l1)?, slice(s2, l2)?, slice(s3, l3)?);
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
    x.contiguous()?.apply_op3(&scale.contiguous()?, &shift.contiguous()?, ChannelAffine)
}
