//! Training-mode batch normalisation over (B, C, H, W) as one candle custom op with a fused
//! backward (the textbook formulas, per channel, channels in parallel). Built from generic
//! candle ops, the batch statistics and their gradients cost several full passes and
//! strided reductions each: most of an attacker step on the CPU.

use candle_core::{CpuStorage, CustomOp1, CustomOp3, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

fn slice<'a>(s: &'a CpuStorage, l: &Layout) -> Result<&'a [f32]> {
    crate::storage::slice(s, l, "batch norm")
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
                    let (a, q) = crate::kernels::sum_and_squares(&x[(bi * c + ch) * n..(bi * c + ch + 1) * n]);
                    s1 += a;
                    s2 += q;
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

/// y = γ (x − μ) / sqrt(σ² + eps) + β with the given batch statistics, then PReLU with one
/// slope per channel where `prelu`: the affine operand is then (γ, β, a) instead of (γ, β).
/// Fused, the PReLU's input is never stored: the backward recomputes it from x.
struct Normalise {
    eps: f64,
    prelu: bool,
}

impl Normalise {
    /// Rows of the affine operand: γ, β (and the slope a).
    fn rows(&self) -> usize {
        if self.prelu {
            3
        } else {
            2
        }
    }

    /// Per channel (mean, 1 / sqrt(var + eps), γ, β, a); a = 1 (the identity) without PReLU.
    fn coefs(&self, affine: &[f32], stats: &[f32], c: usize) -> Vec<[f32; 5]> {
        (0..c)
            .map(|ch| {
                let r = (1.0 / (stats[c + ch] as f64 + self.eps).sqrt()) as f32;
                let a = if self.prelu { affine[2 * c + ch] } else { 1.0 };
                [stats[ch], r, affine[ch], affine[c + ch], a]
            })
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
        if affine.len() != self.rows() * c || stats.len() != 2 * c {
            candle_core::bail!("batch norm: affine must be ({}, {c}) and stats (2, {c})", self.rows());
        }
        let k = self.coefs(affine, stats, c);
        let mut y = crate::kernels::zeros(x.len());
        y.par_chunks_mut(n).zip(x.par_chunks(n)).enumerate().for_each(|(p, (yp, xp))| {
            let [m, r, g, b, a] = k[p % c];
            if self.prelu {
                crate::kernels::affine_prelu(yp, xp, r * g, b - m * r * g, a);
            } else {
                crate::kernels::affine(yp, xp, r * g, b - m * r * g);
            }
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
        // One op reads x and dy where they lie and writes dx and (dγ, dβ[, da]) into one
        // buffer, returned as two views of it (no copies of the activations).
        let (_, c, _, _) = x.dims4()?;
        let rows = self.rows();
        let coefs = Tensor::cat(&[affine.flatten_all()?, stats.flatten_all()?], 0)?;
        let grad_op = NormaliseGrad { eps: self.eps, prelu: self.prelu };
        let both = x.apply_op3_no_bwd(&grad.contiguous()?, &coefs, &grad_op)?;
        let n = x.elem_count();
        let dx = both.narrow(0, 0, n)?.reshape(x.shape())?;
        let da = both.narrow(0, n, rows * c)?.reshape((rows, c))?;
        Ok((Some(dx), Some(da), None))
    }
}

/// The backward of [`Normalise`] from (x, dy, [γ, β, (a,) μ, σ²]): dx (as x) then dγ, dβ
/// (and da), C each, flat in one buffer. Channels run in parallel; with PReLU each keeps
/// its `dz` (the gradient at the PReLU's input) in scratch, never in a tensor.
struct NormaliseGrad {
    eps: f64,
    prelu: bool,
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
        let norm = Normalise { eps: self.eps, prelu: self.prelu };
        let rows = norm.rows();
        if gv.len() != xv.len() || coefs.len() != (rows + 2) * c {
            candle_core::bail!("batch norm grad: operands do not match");
        }
        let k = norm.coefs(&coefs[..rows * c], &coefs[rows * c..], c);
        let total = (b * n) as f32;
        let mut out = crate::kernels::zeros(xv.len() + rows * c);
        let (dx, da) = out.split_at_mut(xv.len());
        // The planes of each channel, to give every channel its own output planes.
        let mut planes: Vec<Vec<&mut [f32]>> = (0..c).map(|_| Vec::with_capacity(b)).collect();
        for (p, plane) in dx.chunks_mut(n).enumerate() {
            planes[p % c].push(plane);
        }
        // Per channel (Σ dz·x̂, Σ dz, Σ_{z ≤ 0} z·dy): dγ, dβ and da.
        let sums: Vec<[f32; 3]> = planes
            .into_par_iter()
            .enumerate()
            .map_init(Vec::new, |dz, (ch, mut dxs)| {
                let [m, r, g, beta, a] = k[ch];
                let (s, t) = (r * g, beta - m * r * g);
                if self.prelu {
                    dz.resize(b * n, 0.0);
                }
                let (mut sd, mut sdx, mut sa) = (0f64, 0f64, 0f64);
                for bi in 0..b {
                    let o = (bi * c + ch) * n;
                    let (xp, gp) = (&xv[o..o + n], &gv[o..o + n]);
                    let dzp: &[f32] = if self.prelu {
                        let d = &mut dz[bi * n..(bi + 1) * n];
                        sa += crate::kernels::affine_prelu_grad(d, xp, gp, [s, t, a]) as f64;
                        d
                    } else {
                        gp
                    };
                    let (a1, a2) = crate::kernels::sum_and_centred_dot(dzp, xp, m, r);
                    sd += a1 as f64;
                    sdx += a2 as f64;
                }
                // dx = γ r / N · (N dz − Σdz − x̂ Σ(dz x̂)).
                let coef = [m, r, g * r / total, total, sd as f32, sdx as f32];
                for (bi, d) in dxs.iter_mut().enumerate() {
                    let o = (bi * c + ch) * n;
                    let dzp = if self.prelu { &dz[bi * n..(bi + 1) * n] } else { &gv[o..o + n] };
                    crate::kernels::batch_norm_grad(d, &xv[o..o + n], dzp, coef);
                }
                [sdx as f32, sd as f32, sa as f32]
            })
            .collect();
        for (ch, [sdx, sd, sa]) in sums.into_iter().enumerate() {
            da[ch] = sdx; // dγ = Σ dz·x̂
            da[c + ch] = sd; // dβ = Σ dz
            if self.prelu {
                da[2 * c + ch] = sa; // da = Σ_{z ≤ 0} z·dy
            }
        }
        let len = out.len();
        Ok((CpuStorage::F32(out), Shape::from(len)))
    }
}

/// Training-mode batch norm, then PReLU with slopes `prelu` (C,) if given: returns the
/// output and the batch (mean, biased variance) as a (2, C) tensor (for the running
/// statistics). Differentiable in `x`, `weight`, `bias` and the slopes. On the CPU one
/// fused op each way; on another device [`batch_norm_train_generic`].
pub fn batch_norm_train(
    x: &Tensor,
    weight: &Tensor,
    bias: &Tensor,
    eps: f64,
    prelu: Option<&Tensor>,
) -> Result<(Tensor, Tensor)> {
    if !x.device().is_cpu() {
        return batch_norm_train_generic(x, weight, bias, eps, prelu);
    }
    let x = x.contiguous()?;
    let stats = x.apply_op1_no_bwd(&Stats)?;
    let affine = match prelu {
        Some(a) => Tensor::stack(&[weight, bias, a], 0)?,
        None => Tensor::stack(&[weight, bias], 0)?,
    };
    let y = x.apply_op3(&affine, &stats, Normalise { eps, prelu: prelu.is_some() })?;
    Ok((y, stats))
}

/// The same as [`batch_norm_train`] in candle's generic ops, the textbook expression
/// `(x − mean) / sqrt(var + eps) · weight + bias`, then PReLU as `max(z, 0) + a · min(z, 0)`:
/// the path on other devices, and the second implementation the tests check the fused op
/// against.
pub fn batch_norm_train_generic(
    x: &Tensor,
    weight: &Tensor,
    bias: &Tensor,
    eps: f64,
    prelu: Option<&Tensor>,
) -> Result<(Tensor, Tensor)> {
    let c = x.dim(1)?;
    let per = |t: &Tensor| t.reshape((1, c, 1, 1));
    let mean = x.mean_keepdim((0, 2, 3))?;
    let centred = x.broadcast_sub(&mean)?;
    let var = centred.sqr()?.mean_keepdim((0, 2, 3))?;
    let z = centred.broadcast_div(&(&var + eps)?.sqrt()?)?.broadcast_mul(&per(weight)?)?.broadcast_add(&per(bias)?)?;
    let y = match prelu {
        Some(a) => (z.relu()? + z.minimum(0f32)?.broadcast_mul(&per(a)?)?)?,
        None => z,
    };
    let stats = Tensor::stack(&[mean.flatten_all()?, var.flatten_all()?], 0)?.detach();
    Ok((y, stats))
}
