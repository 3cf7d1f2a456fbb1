//! Depthwise 2-D convolution as a candle custom op with its own backward, for the CPU:
//! candle would run it as one convolution per channel group (hundreds of tiny kernels), and
//! as shifted broadcast multiplies it spends its time in strided indexing. Planes (b, c)
//! run in parallel with rayon; f32, contiguous operands.
//!
//! Each plane is first split into `stride²` zero-padded phase planes, `P_ab[i][j] =
//! x_pad[i·s + a][j·s + b]`, all `PW` wide. Then every tap `(ky, kx)` reads one phase plane
//! at one offset for every output pixel at once, so the output, computed `PW` wide (the
//! columns past the output's width are discarded), is `kh·kw` multiply-adds over one
//! contiguous run each: whole vectors, no bounds test per pixel, at any stride. The two
//! gradients use the same layout: the input gradient adds each tap's run into the phase
//! planes (then gathers the input pixels back), the weight gradient is one dot product per
//! tap. The output gradient is laid out `PW` wide with zeros in the extra columns, so
//! they add nothing. Per output pixel the taps are summed in the same order as a direct
//! loop (`ky` then `kx`).

use candle_core::{CpuStorage, CustomOp2, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

/// Geometry shared by the forward and both gradients.
#[derive(Clone, Copy, Debug)]
struct Geo {
    b: usize,
    c: usize,
    h: usize,
    w: usize,
    kh: usize,
    kw: usize,
    stride: usize,
    pad: usize,
    oh: usize,
    ow: usize,
    /// Phase-plane rows (one more than any tap reads, so the last run stays inside).
    ph: usize,
    /// Phase-plane width, also the row length of the wide output.
    pw: usize,
}

impl Geo {
    fn new(x: &[usize], k: &[usize], stride: usize, pad: usize) -> Result<Self> {
        let (&[b, c, h, w], &[kc, 1, kh, kw]) = (x, k) else {
            candle_core::bail!("depthwise: x {x:?} must be (B, C, H, W) and w {k:?} (C, 1, kh, kw)")
        };
        if kc != c || h + 2 * pad < kh || w + 2 * pad < kw || stride == 0 || kh == 0 || kw == 0 {
            candle_core::bail!("depthwise: x {x:?}, w {k:?}, stride {stride}, pad {pad} do not fit");
        }
        let (oh, ow) = ((h + 2 * pad - kh) / stride + 1, (w + 2 * pad - kw) / stride + 1);
        // Tap (ky, kx) of output (y, x) is phase-plane pixel (y + ky/s, x + kx/s):
        // rows up to oh − 1 + (kh − 1)/s, columns up to ow − 1 + (kw − 1)/s.
        let (ph, pw) = (oh + (kh - 1) / stride + 1, ow + (kw - 1) / stride);
        Ok(Self { b, c, h, w, kh, kw, stride, pad, oh, ow, ph, pw })
    }

    fn phase_len(&self) -> usize {
        self.ph * self.pw
    }

    /// The wide output's length: `oh` rows of `pw`.
    fn wide_len(&self) -> usize {
        self.oh * self.pw
    }

    /// Every tap `(ky, kx)` as (its index in the kernel, where its run of `wide_len` starts
    /// in the phase planes).
    fn runs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let s = self.stride;
        (0..self.kh).flat_map(move |ky| {
            (0..self.kw).map(move |kx| {
                let (q, off) = ((ky % s) * s + kx % s, (ky / s) * self.pw + kx / s);
                (ky * self.kw + kx, q * self.phase_len() + off)
            })
        })
    }

    /// Input pixel `(iy, ix)` as (phase index, offset): the inverse of the split.
    fn place(&self, iy: usize, ix: usize) -> (usize, usize) {
        let (s, (py, px)) = (self.stride, (iy + self.pad, ix + self.pad));
        ((py % s) * s + px % s, (py / s) * self.pw + px / s)
    }

    /// Splits one input plane (H, W) into the phase planes (`phases`, zeroed first).
    fn split(&self, x: &[f32], phases: &mut [f32]) {
        phases.fill(0.0);
        let n = self.phase_len();
        for iy in 0..self.h {
            let row = &x[iy * self.w..(iy + 1) * self.w];
            if self.stride == 1 {
                let o = (iy + self.pad) * self.pw + self.pad;
                phases[o..o + self.w].copy_from_slice(row);
                continue;
            }
            for (ix, &v) in row.iter().enumerate() {
                let (q, o) = self.place(iy, ix);
                // Past `pw`: a column no tap reads (the padding beyond the last window).
                if (ix + self.pad) / self.stride < self.pw && (iy + self.pad) / self.stride < self.ph {
                    phases[q * n + o] = v;
                }
            }
        }
    }

    /// One output-gradient plane (OH, OW) laid out `pw` wide, zeros in the extra columns.
    fn widen(&self, dy: &[f32], wide: &mut [f32]) {
        wide.fill(0.0);
        for y in 0..self.oh {
            wide[y * self.pw..y * self.pw + self.ow].copy_from_slice(&dy[y * self.ow..(y + 1) * self.ow]);
        }
    }
}

fn slice<'a>(s: &'a CpuStorage, l: &Layout) -> Result<&'a [f32]> {
    crate::storage::slice(s, l, "depthwise")
}

/// Per-thread scratch: phase planes and one wide plane.
#[derive(Default)]
struct Scratch {
    phases: Vec<f32>,
    wide: Vec<f32>,
}

impl Scratch {
    fn sized(&mut self, g: &Geo) -> (&mut [f32], &mut [f32]) {
        self.phases.resize(g.stride * g.stride * g.phase_len(), 0.0);
        self.wide.resize(g.wide_len(), 0.0);
        (&mut self.phases, &mut self.wide)
    }
}

/// out = depthwise(x, w).
struct Forward {
    stride: usize,
    pad: usize,
}

impl CustomOp2 for Forward {
    fn name(&self) -> &'static str {
        "depthwise-conv2d"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let g = Geo::new(l1.dims(), l2.dims(), self.stride, self.pad)?;
        let (x, k) = (slice(s1, l1)?, slice(s2, l2)?);
        let m = g.wide_len();
        let mut out = crate::kernels::zeros(g.b * g.c * g.oh * g.ow);
        out.par_chunks_mut(g.oh * g.ow).enumerate().for_each_init(Scratch::default, |scratch, (p, o)| {
            let c = p % g.c;
            let kp = &k[c * g.kh * g.kw..(c + 1) * g.kh * g.kw];
            let (phases, wide) = scratch.sized(&g);
            g.split(&x[p * g.h * g.w..(p + 1) * g.h * g.w], phases);
            wide.fill(0.0);
            for (t, s) in g.runs() {
                crate::kernels::axpy(wide, kp[t], &phases[s..s + m]);
            }
            for y in 0..g.oh {
                o[y * g.ow..(y + 1) * g.ow].copy_from_slice(&wide[y * g.pw..y * g.pw + g.ow]);
            }
        });
        Ok((CpuStorage::F32(out), Shape::from((g.b, g.c, g.oh, g.ow))))
    }

    fn bwd(&self, x: &Tensor, w: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        // Only the gradients candle tracks: a frozen network's weights need none.
        let grad = grad.contiguous()?;
        let gx =
            if x.track_op() {
                Some(grad.apply_op2_no_bwd(
                    w,
                    &GradInput { stride: self.stride, pad: self.pad, h: x.dim(2)?, w: x.dim(3)? },
                )?)
            } else {
                None
            };
        let gw = if w.track_op() {
            Some(x.apply_op2_no_bwd(
                &grad,
                &GradWeight { stride: self.stride, pad: self.pad, kh: w.dim(2)?, kw: w.dim(3)? },
            )?)
        } else {
            None
        };
        Ok((gx, gw))
    }
}

/// d loss / d x from the output gradient and the weights.
struct GradInput {
    stride: usize,
    pad: usize,
    h: usize,
    w: usize,
}

impl CustomOp2 for GradInput {
    fn name(&self) -> &'static str {
        "depthwise-conv2d-grad-input"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let d = l1.dims();
        let [b, c, dh, dw] = *d else { candle_core::bail!("depthwise grad: output gradient {d:?} is not 4-d") };
        let g = Geo::new(&[b, c, self.h, self.w], l2.dims(), self.stride, self.pad)?;
        if dh != g.oh || dw != g.ow {
            candle_core::bail!("depthwise grad: output gradient {d:?} does not match");
        }
        let (go, k) = (slice(s1, l1)?, slice(s2, l2)?);
        let (n, m) = (g.phase_len(), g.wide_len());
        let mut gx = crate::kernels::zeros(g.b * g.c * g.h * g.w);
        gx.par_chunks_mut(g.h * g.w).enumerate().for_each_init(Scratch::default, |scratch, (p, gxp)| {
            let c = p % g.c;
            let kp = &k[c * g.kh * g.kw..(c + 1) * g.kh * g.kw];
            let (phases, wide) = scratch.sized(&g);
            g.widen(&go[p * g.oh * g.ow..(p + 1) * g.oh * g.ow], wide);
            phases.fill(0.0);
            for (t, s) in g.runs() {
                crate::kernels::axpy(&mut phases[s..s + m], kp[t], wide);
            }
            for iy in 0..g.h {
                let row = &mut gxp[iy * g.w..(iy + 1) * g.w];
                if g.stride == 1 {
                    let o = (iy + g.pad) * g.pw + g.pad;
                    row.copy_from_slice(&phases[o..o + g.w]);
                    continue;
                }
                for (ix, v) in row.iter_mut().enumerate() {
                    // A pixel outside every window (past `pw` or `ph`) has no gradient.
                    if (ix + g.pad) / g.stride < g.pw && (iy + g.pad) / g.stride < g.ph {
                        let (q, o) = g.place(iy, ix);
                        *v = phases[q * n + o];
                    }
                }
            }
        });
        Ok((CpuStorage::F32(gx), Shape::from((g.b, g.c, g.h, g.w))))
    }
}

/// d loss / d w from the input and the output gradient (summed over the batch).
struct GradWeight {
    stride: usize,
    pad: usize,
    kh: usize,
    kw: usize,
}

impl CustomOp2 for GradWeight {
    fn name(&self) -> &'static str {
        "depthwise-conv2d-grad-weight"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let d = l1.dims();
        let Some(&c) = d.get(1) else { candle_core::bail!("depthwise grad: input {d:?} is not 4-d") };
        let g = Geo::new(d, &[c, 1, self.kh, self.kw], self.stride, self.pad)?;
        let (x, go) = (slice(s1, l1)?, slice(s2, l2)?);
        if l2.dims() != [g.b, g.c, g.oh, g.ow] {
            candle_core::bail!("depthwise grad: output gradient {:?} does not match", l2.dims());
        }
        let (taps, m) = (g.kh * g.kw, g.wide_len());
        // Per plane, then summed over the batch.
        let per: Vec<Vec<f32>> = (0..g.b * g.c)
            .into_par_iter()
            .map_init(Scratch::default, |scratch, p| {
                let (phases, wide) = scratch.sized(&g);
                g.split(&x[p * g.h * g.w..(p + 1) * g.h * g.w], phases);
                g.widen(&go[p * g.oh * g.ow..(p + 1) * g.oh * g.ow], wide);
                let mut acc = vec![0f32; taps];
                for (t, s) in g.runs() {
                    acc[t] = crate::kernels::dot(wide, &phases[s..s + m]);
                }
                acc
            })
            .collect();
        let mut gw = crate::kernels::zeros(g.c * taps);
        for (p, acc) in per.iter().enumerate() {
            let c = p % g.c;
            for t in 0..taps {
                gw[c * taps + t] += acc[t];
            }
        }
        Ok((CpuStorage::F32(gw), Shape::from((g.c, 1, g.kh, g.kw))))
    }
}

/// Depthwise convolution: `x` (B, C, H, W), `w` (C, 1, kh, kw), zero padding `pad`;
/// differentiable in both.
/// On the CPU the custom op; on another device [`depthwise_generic`].
pub fn depthwise(x: &Tensor, w: &Tensor, stride: usize, pad: usize) -> Result<Tensor> {
    if !x.device().is_cpu() {
        return depthwise_generic(x, w, stride, pad);
    }
    x.contiguous()?.apply_op2(&w.contiguous()?, Forward { stride, pad })
}

/// The same depthwise convolution as candle's grouped `conv2d` (one group per channel):
/// the path on other devices, and the second implementation the tests check [`depthwise`]
/// against.
pub fn depthwise_generic(x: &Tensor, w: &Tensor, stride: usize, pad: usize) -> Result<Tensor> {
    let c = x.dim(1)?;
    x.conv2d(w, pad, stride, 1, c)
}
