//! Dense 2-D convolution as candle custom ops with their own backward, on the
//! `gemm` crate that candle's own matrix products use.
//!
//! Per image, a convolution is one matrix product: `Y = W · col(X)`, with `W` the
//! `(Cout, Cin·kh·kw)` weights and `col(X)` the `(Cin·kh·kw, OH·OW)` patches (im2col; a 1x1
//! convolution of stride 1 uses `X` itself). The backward is two more products, each computed
//! only when candle tracks that operand: `dW = Σ_b dY_b · col(X_b)ᵀ` and
//! `dX_b = col⁻¹(Wᵀ · dY_b)` (col2im adds overlapping patches). The stride is applied when
//! gathering patches, so a stride-2 layer does a quarter of the stride-1 work. Built from
//! candle's generic ops instead (one product per kernel tap on shifted copies, then
//! subsampling), the convolutions and their accumulations were most of a training step.
//!
//! Numerics: f32 throughout, as candle's `conv2d`; `tests/networks.rs` checks both directions
//! against candle's `conv2d` and finite differences.

use crate::storage::slice;
use candle_core::{CpuStorage, CustomOp2, Layout, Result, Shape, Tensor};
use rayon::prelude::*;

/// Row-major `dst (m×n) = [dst +] a · b` where `a` is `m×k` (or its transpose stored
/// `k×m`, `ta`) and `b` is `k×n` (or `n×k`, `tb`). Bounds are checked before the call.
#[allow(clippy::too_many_arguments)]
fn matmul(
    dst: &mut [f32],
    accumulate: bool,
    a: &[f32],
    ta: bool,
    b: &[f32],
    tb: bool,
    (m, n, k): (usize, usize, usize),
    threads: usize,
) {
    assert!(dst.len() >= m * n && a.len() >= m * k && b.len() >= k * n, "matmul operands too short");
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst[..m * n].fill(0.0);
        }
        return;
    }
    // (column stride, row stride) of each operand as stored.
    let (a_cs, a_rs) = if ta { (m as isize, 1) } else { (1, k as isize) };
    let (b_cs, b_rs) = if tb { (k as isize, 1) } else { (1, n as isize) };
    let par = if threads > 1 { gemm::Parallelism::Rayon(threads) } else { gemm::Parallelism::None };
    // SAFETY: every operand holds at least the elements its strides address (checked above:
    // m·k, k·n and m·n), `dst` is exclusively borrowed and does not alias `a` or `b`.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.as_ptr(),
            a_cs,
            a_rs,
            b.as_ptr(),
            b_cs,
            b_rs,
            if accumulate { 1.0 } else { 0.0 },
            1.0,
            false,
            false,
            false,
            par,
        )
    }
}

/// Geometry of one convolution.
#[derive(Clone, Copy, Debug)]
struct Geo {
    b: usize,
    cin: usize,
    h: usize,
    w: usize,
    cout: usize,
    kh: usize,
    kw: usize,
    stride: usize,
    pad: usize,
    oh: usize,
    ow: usize,
}

impl Geo {
    fn new(x: &[usize], w: &[usize], stride: usize, pad: usize) -> Result<Self> {
        let (&[b, cin, h, wd], &[cout, wc, kh, kw]) = (x, w) else {
            candle_core::bail!("conv2d: x {x:?} must be (B, C, H, W) and w {w:?} (Cout, Cin, kh, kw)")
        };
        if wc != cin || stride == 0 || h + 2 * pad < kh || wd + 2 * pad < kw || kh == 0 || kw == 0 {
            candle_core::bail!("conv2d: x {x:?}, w {w:?}, stride {stride}, pad {pad} do not fit");
        }
        let (oh, ow) = ((h + 2 * pad - kh) / stride + 1, (wd + 2 * pad - kw) / stride + 1);
        Ok(Self { b, cin, h, w: wd, cout, kh, kw, stride, pad, oh, ow })
    }

    /// Patch rows (Cin·kh·kw).
    fn k(&self) -> usize {
        self.cin * self.kh * self.kw
    }

    /// Output pixels per image.
    fn p(&self) -> usize {
        self.oh * self.ow
    }

    /// Whether an image is its own patch matrix (1x1, stride 1, no padding).
    fn direct(&self) -> bool {
        self.kh == 1 && self.kw == 1 && self.stride == 1 && self.pad == 0
    }

    /// Input index of output coordinate `o` and tap `t` along an axis of length `n`.
    #[inline]
    fn src(&self, o: usize, t: usize, n: usize) -> Option<usize> {
        (o * self.stride + t).checked_sub(self.pad).filter(|&i| i < n)
    }

    /// im2col of one image `x` (Cin, H, W) into `col` (K, P); zeros outside.
    fn im2col(&self, x: &[f32], col: &mut [f32]) {
        let p = self.p();
        for c in 0..self.cin {
            for ky in 0..self.kh {
                for kx in 0..self.kw {
                    let row = &mut col[((c * self.kh + ky) * self.kw + kx) * p..][..p];
                    for oy in 0..self.oh {
                        let out = &mut row[oy * self.ow..(oy + 1) * self.ow];
                        let Some(iy) = self.src(oy, ky, self.h) else {
                            out.fill(0.0);
                            continue;
                        };
                        let line = &x[(c * self.h + iy) * self.w..][..self.w];
                        for (ox, v) in out.iter_mut().enumerate() {
                            *v = self.src(ox, kx, self.w).map_or(0.0, |ix| line[ix]);
                        }
                    }
                }
            }
        }
    }

    /// col2im: adds `col` (K, P) back onto one image's gradient `dx` (Cin, H, W).
    fn col2im(&self, col: &[f32], dx: &mut [f32]) {
        let p = self.p();
        for c in 0..self.cin {
            for ky in 0..self.kh {
                for kx in 0..self.kw {
                    let row = &col[((c * self.kh + ky) * self.kw + kx) * p..][..p];
                    for oy in 0..self.oh {
                        let Some(iy) = self.src(oy, ky, self.h) else { continue };
                        let line = &mut dx[(c * self.h + iy) * self.w..][..self.w];
                        for (ox, &v) in row[oy * self.ow..(oy + 1) * self.ow].iter().enumerate() {
                            if let Some(ix) = self.src(ox, kx, self.w) {
                                line[ix] += v;
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Whether to run images in parallel (each product single-threaded) rather than one after
/// another with every thread inside each product: when there are at least as many images as
/// threads.
fn images_in_parallel(b: usize) -> (bool, usize) {
    let threads = rayon::current_num_threads();
    (b >= threads || threads == 1, threads)
}

/// `f(image index, thread budget)` for every image of the batch, results in order.
fn over_batch<T: Send>(b: usize, f: impl Fn(usize, usize) -> T + Sync) -> Vec<T> {
    match images_in_parallel(b) {
        (true, _) => (0..b).into_par_iter().map(|i| f(i, 1)).collect(),
        (false, threads) => (0..b).map(|i| f(i, threads)).collect(),
    }
}

/// `f(image index, its chunk of out, thread budget)` for every image, `out` cut in `b` chunks.
fn over_batch_into(out: &mut [f32], b: usize, f: impl Fn(usize, &mut [f32], usize) + Sync) {
    let chunk = out.len() / b.max(1);
    if chunk == 0 {
        return;
    }
    match images_in_parallel(b) {
        (true, _) => out.par_chunks_mut(chunk).enumerate().for_each(|(i, o)| f(i, o, 1)),
        (false, threads) => out.chunks_mut(chunk).enumerate().for_each(|(i, o)| f(i, o, threads)),
    }
}

/// The forward op (x, w) → y.
struct Conv {
    stride: usize,
    pad: usize,
}

impl CustomOp2 for Conv {
    fn name(&self) -> &'static str {
        "campro-conv2d"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let g = Geo::new(l1.dims(), l2.dims(), self.stride, self.pad)?;
        let (x, w) = (slice(s1, l1, "conv2d")?, slice(s2, l2, "conv2d")?);
        let (k, p, img) = (g.k(), g.p(), g.cin * g.h * g.w);
        let mut y = crate::kernels::zeros(g.b * g.cout * p);
        over_batch_into(&mut y, g.b, |i, yi, threads| {
            let xi = &x[i * img..(i + 1) * img];
            if g.direct() {
                matmul(yi, false, w, false, xi, false, (g.cout, p, k), threads);
            } else {
                let mut col = crate::kernels::zeros(k * p);
                g.im2col(xi, &mut col);
                matmul(yi, false, w, false, &col, false, (g.cout, p, k), threads);
            }
        });
        Ok((CpuStorage::F32(y), Shape::from((g.b, g.cout, g.oh, g.ow))))
    }

    fn bwd(&self, x: &Tensor, w: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        // Both gradients read the operands where they lie (no copies), each only if tracked.
        let grad = grad.contiguous()?;
        let (stride, pad) = (self.stride, self.pad);
        let dw = if w.track_op() {
            let (_, _, kh, kw) = w.dims4()?;
            Some(x.apply_op2_no_bwd(&grad, &ConvGradWeight { stride, pad, cout: w.dim(0)?, kh, kw })?)
        } else {
            None
        };
        let dx = if x.track_op() {
            Some(grad.apply_op2_no_bwd(w, &ConvGradInput { stride, pad, h: x.dim(2)?, w: x.dim(3)? })?)
        } else {
            None
        };
        Ok((dx, dw))
    }
}

/// `dW = Σ_b dY_b (Cout×P) · col(X_b)ᵀ (P×K)` from (x, dy).
struct ConvGradWeight {
    stride: usize,
    pad: usize,
    cout: usize,
    kh: usize,
    kw: usize,
}

impl CustomOp2 for ConvGradWeight {
    fn name(&self) -> &'static str {
        "campro-conv2d-grad-weight"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let xd = l1.dims();
        let cin = xd.get(1).copied().unwrap_or(0);
        let g = Geo::new(xd, &[self.cout, cin, self.kh, self.kw], self.stride, self.pad)?;
        let (x, dy) = (slice(s1, l1, "conv2d grad")?, slice(s2, l2, "conv2d grad")?);
        if l2.dims() != [g.b, g.cout, g.oh, g.ow] {
            candle_core::bail!("conv2d grad: output gradient {:?} does not match", l2.dims());
        }
        let (k, p, img) = (g.k(), g.p(), g.cin * g.h * g.w);
        let parts = over_batch(g.b, |i, threads| {
            let dyi = &dy[i * g.cout * p..(i + 1) * g.cout * p];
            let xi = &x[i * img..(i + 1) * img];
            let mut part = crate::kernels::zeros(g.cout * k);
            if g.direct() {
                matmul(&mut part, false, dyi, false, xi, true, (g.cout, k, p), threads);
            } else {
                let mut col = crate::kernels::zeros(k * p);
                g.im2col(xi, &mut col);
                matmul(&mut part, false, dyi, false, &col, true, (g.cout, k, p), threads);
            }
            part
        });
        let mut parts = parts.into_iter();
        let mut sum = parts.next().unwrap_or_else(|| crate::kernels::zeros(g.cout * k));
        for part in parts {
            sum.iter_mut().zip(part).for_each(|(s, v)| *s += v);
        }
        Ok((CpuStorage::F32(sum), Shape::from((g.cout, g.cin, g.kh, g.kw))))
    }
}

/// `dX_b = col⁻¹(Wᵀ (K×Cout) · dY_b (Cout×P))` from (dy, w).
struct ConvGradInput {
    stride: usize,
    pad: usize,
    h: usize,
    w: usize,
}

impl CustomOp2 for ConvGradInput {
    fn name(&self) -> &'static str {
        "campro-conv2d-grad-input"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (dd, wd) = (l1.dims(), l2.dims());
        let (Some(&b), Some(&cin)) = (dd.first(), wd.get(1)) else {
            candle_core::bail!("conv2d grad: output gradient {dd:?} and weights {wd:?} do not fit")
        };
        let g = Geo::new(&[b, cin, self.h, self.w], wd, self.stride, self.pad)?;
        if dd != [g.b, g.cout, g.oh, g.ow] {
            candle_core::bail!("conv2d grad: output gradient {dd:?} does not match");
        }
        let (dy, w) = (slice(s1, l1, "conv2d grad")?, slice(s2, l2, "conv2d grad")?);
        let (k, p, img) = (g.k(), g.p(), g.cin * g.h * g.w);
        let mut dx = crate::kernels::zeros(g.b * img);
        over_batch_into(&mut dx, g.b, |i, dxi, threads| {
            let dyi = &dy[i * g.cout * p..(i + 1) * g.cout * p];
            if g.direct() {
                matmul(dxi, false, w, true, dyi, false, (k, p, g.cout), threads);
            } else {
                let mut col = crate::kernels::zeros(k * p);
                matmul(&mut col, false, w, true, dyi, false, (k, p, g.cout), threads);
                g.col2im(&col, dxi);
            }
        });
        Ok((CpuStorage::F32(dx), Shape::from((g.b, g.cin, g.h, g.w))))
    }
}

/// Dense convolution: `x` (B, Cin, H, W), `w` (Cout, Cin, kh, kw), zero padding `pad` on
/// every side, stride `stride`; differentiable in both (gradients only for tracked operands).
/// On the CPU the custom op; on another device [`conv2d_generic`].
pub fn conv2d(x: &Tensor, w: &Tensor, stride: usize, pad: usize) -> Result<Tensor> {
    if !x.device().is_cpu() {
        return conv2d_generic(x, w, stride, pad);
    }
    x.contiguous()?.apply_op2(&w.contiguous()?, Conv { stride, pad })
}

/// The same convolution as [`conv2d`] built from candle's generic ops (one matrix product per
/// kernel tap on shifted copies, then subsampling): the second implementation the tests check
/// [`conv2d`] against, several times slower on the CPU, and the path on other devices.
pub fn conv2d_generic(x: &Tensor, w: &Tensor, stride: usize, pad: usize) -> Result<Tensor> {
    let (b, cin, h, wd) = x.dims4()?;
    let (cout, _, kh, kw) = w.dims4()?;
    let xp = if pad > 0 { x.pad_with_zeros(2, pad, pad)?.pad_with_zeros(3, pad, pad)? } else { x.clone() };
    let (oh, ow) = (h + 2 * pad - kh + 1, wd + 2 * pad - kw + 1);
    let mut acc: Option<Tensor> = None;
    for ky in 0..kh {
        for kx in 0..kw {
            let tap = w.narrow(2, ky, 1)?.narrow(3, kx, 1)?.reshape((cout, cin))?;
            let win =
                if kh == 1 && kw == 1 { xp.clone() } else { xp.narrow(2, ky, oh)?.narrow(3, kx, ow)?.contiguous()? };
            let term = tap.broadcast_matmul(&win.reshape((b, cin, oh * ow))?)?;
            acc = Some(match acc {
                None => term,
                Some(a) => (a + term)?,
            });
        }
    }
    let full = acc.expect("kernel is at least 1x1").reshape((b, cout, oh, ow))?;
    if stride == 1 {
        return Ok(full);
    }
    subsample(&subsample(&full, 2, stride)?, 3, stride)
}

/// Every `s`-th element along `dim`, from 0.
pub fn subsample(x: &Tensor, dim: usize, s: usize) -> Result<Tensor> {
    if s == 1 {
        return Ok(x.clone());
    }
    let n = x.dim(dim)?;
    let m = n.div_ceil(s);
    let x = if m * s > n { x.pad_with_zeros(dim, 0, m * s - n)? } else { x.clone() };
    let mut dims = x.dims().to_vec();
    dims[dim] = m;
    dims.insert(dim + 1, s);
    x.reshape(dims)?.narrow(dim + 1, 0, 1)?.squeeze(dim + 1)
}
