//! Depthwise 2-D convolution as a candle custom op with its own backward, for the CPU:
//! candle would run it as one convolution per channel group (hundreds of tiny kernels), and
//! as shifted broadcast multiplies it spends its time in strided indexing. Planes (b, c)
//! run in parallel with rayon; f32, contiguous operands.

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
}

impl Geo {
    fn new(x: &[usize], k: &[usize], stride: usize, pad: usize) -> Result<Self> {
        let (&[b, c, h, w], &[kc, 1, kh, kw]) = (x, k) else {
            candle_core::bail!("depthwise: x {x:?} must be (B, C, H, W) and w {k:?} (C, 1, kh, kw)")
        };
        if kc != c || h + 2 * pad < kh || w + 2 * pad < kw || stride == 0 {
            candle_core::bail!("depthwise: x {x:?}, w {k:?}, stride {stride}, pad {pad} do not fit");
        }
        Ok(Self {
            b,
            c,
            h,
            w,
            kh,
            kw,
            stride,
            pad,
            oh: (h + 2 * pad - kh) / stride + 1,
            ow: (w + 2 * pad - kw) / stride + 1,
        })
    }

    /// Input coordinate of output `o` and tap `k`, if inside the image.
    #[inline]
    fn src(&self, o: usize, k: usize, n: usize) -> Option<usize> {
        (o * self.stride + k).checked_sub(self.pad).filter(|&i| i < n)
    }

    /// The outputs `lo..hi` (of `on`) whose tap `k` falls inside an input axis of length `n`:
    /// `o·stride + k − pad` in `0..n`. Looping over this range needs no bounds test per pixel.
    #[inline]
    fn valid(&self, k: usize, n: usize, on: usize) -> (usize, usize) {
        let lo = self.pad.saturating_sub(k).div_ceil(self.stride);
        let hi = if n + self.pad > k { ((n - 1 + self.pad - k) / self.stride + 1).min(on) } else { 0 };
        (lo, hi.max(lo))
    }
}

fn slice<'a>(s: &'a CpuStorage, l: &Layout) -> Result<&'a [f32]> {
    crate::conv::slice(s, l, "depthwise")
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
        let mut out = vec![0f32; g.b * g.c * g.oh * g.ow];
        out.par_chunks_mut(g.oh * g.ow).enumerate().for_each(|(p, o)| {
            let c = p % g.c;
            let xp = &x[p * g.h * g.w..(p + 1) * g.h * g.w];
            let kp = &k[c * g.kh * g.kw..(c + 1) * g.kh * g.kw];
            for oy in 0..g.oh {
                for ky in 0..g.kh {
                    let Some(iy) = g.src(oy, ky, g.h) else { continue };
                    let row = &xp[iy * g.w..(iy + 1) * g.w];
                    let orow = &mut o[oy * g.ow..(oy + 1) * g.ow];
                    for kx in 0..g.kw {
                        let wv = kp[ky * g.kw + kx];
                        let (lo, hi) = g.valid(kx, g.w, g.ow);
                        if lo == hi {
                            continue;
                        }
                        let first = lo * g.stride + kx - g.pad;
                        if g.stride == 1 {
                            crate::kernels::axpy(&mut orow[lo..hi], wv, &row[first..first + hi - lo]);
                        } else {
                            for (ov, &xv) in orow[lo..hi].iter_mut().zip(row[first..].iter().step_by(g.stride)) {
                                *ov += wv * xv;
                            }
                        }
                    }
                }
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
        let g = Geo::new(&[d[0], d[1], self.h, self.w], l2.dims(), self.stride, self.pad)?;
        if d[2] != g.oh || d[3] != g.ow {
            candle_core::bail!("depthwise grad: output gradient {d:?} does not match");
        }
        let (go, k) = (slice(s1, l1)?, slice(s2, l2)?);
        let mut gx = vec![0f32; g.b * g.c * g.h * g.w];
        gx.par_chunks_mut(g.h * g.w).enumerate().for_each(|(p, gxp)| {
            let c = p % g.c;
            let gop = &go[p * g.oh * g.ow..(p + 1) * g.oh * g.ow];
            let kp = &k[c * g.kh * g.kw..(c + 1) * g.kh * g.kw];
            for oy in 0..g.oh {
                for ky in 0..g.kh {
                    let Some(iy) = g.src(oy, ky, g.h) else { continue };
                    let grow = &gop[oy * g.ow..(oy + 1) * g.ow];
                    let xrow = &mut gxp[iy * g.w..(iy + 1) * g.w];
                    for kx in 0..g.kw {
                        let wv = kp[ky * g.kw + kx];
                        let (lo, hi) = g.valid(kx, g.w, g.ow);
                        if lo == hi {
                            continue;
                        }
                        let first = lo * g.stride + kx - g.pad;
                        if g.stride == 1 {
                            crate::kernels::axpy(&mut xrow[first..first + hi - lo], wv, &grow[lo..hi]);
                        } else {
                            for (xv, &gv) in xrow[first..].iter_mut().step_by(g.stride).zip(&grow[lo..hi]) {
                                *xv += wv * gv;
                            }
                        }
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
        let g = Geo::new(d, &[d[1], 1, self.kh, self.kw], self.stride, self.pad)?;
        let (x, go) = (slice(s1, l1)?, slice(s2, l2)?);
        if l2.dims() != [g.b, g.c, g.oh, g.ow] {
            candle_core::bail!("depthwise grad: output gradient {:?} does not match", l2.dims());
        }
        let taps = g.kh * g.kw;
        // Per plane, then summed over the batch.
        let per: Vec<Vec<f32>> = (0..g.b * g.c)
            .into_par_iter()
            .map(|p| {
                let xp = &x[p * g.h * g.w..(p + 1) * g.h * g.w];
                let gop = &go[p * g.oh * g.ow..(p + 1) * g.oh * g.ow];
                let mut acc = vec![0f32; taps];
                for ky in 0..g.kh {
                    for kx in 0..g.kw {
                        let mut s = 0f32;
                        let (lo, hi) = g.valid(kx, g.w, g.ow);
                        if lo < hi {
                            let first = lo * g.stride + kx - g.pad;
                            for oy in 0..g.oh {
                                let Some(iy) = g.src(oy, ky, g.h) else { continue };
                                let (xrow, grow) =
                                    (&xp[iy * g.w..(iy + 1) * g.w], &gop[oy * g.ow + lo..oy * g.ow + hi]);
                                if g.stride == 1 {
                                    s += crate::kernels::dot(&xrow[first..first + hi - lo], grow);
                                } else {
                                    s += xrow[first..]
                                        .iter()
                                        .step_by(g.stride)
                                        .zip(grow)
                                        .map(|(a, b)| a * b)
                                        .sum::<f32>();
                                }
                            }
                        }
                        acc[ky * g.kw + kx] = s;
                    }
                }
                acc
            })
            .collect();
        let mut gw = vec![0f32; g.c * taps];
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
pub fn depthwise(x: &Tensor, w: &Tensor, stride: usize, pad: usize) -> Result<Tensor> {
    x.contiguous()?.apply_op2(&w.contiguous()?, Forward { stride, pad })
}
