//! The element-wise inner loops of campro's training ops, compiled for AVX-512 and AVX2 as
//! well as the baseline and chosen at run time (`multiversion`): a Rust build targets plain
//! x86-64 (SSE2), which leaves most of a wide CPU's lanes unused. Plain multiplies and adds
//! (no fused multiply-add), so every version returns the same values; sums run in 16 lanes,
//! so a sum's rounding differs from a sequential one (both are f32 sums of the same terms).

use multiversion::multiversion;

/// `n` zeros, written: for the outputs of campro's ops. `vec![0.0; n]` is `calloc`, whose
/// fresh pages the kernel maps to its one read-only zero page until they are written; an op
/// that reads an element before writing it (an accumulation) then takes a copy-on-write
/// fault per page, and each one's TLB flush interrupts every other core (a fifth of a
/// two-thread MobileFaceNet step went there). Writing the zeros maps the pages writable.
pub fn zeros(n: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(n);
    v.resize(n, 0.0);
    v
}

/// `e^x` in a form LLVM vectorises (libm's `expf` is a call per element): Cephes' expf,
/// `2^n · p(r)` with `n = round(x · log2 e)` and a degree-7 polynomial on
/// `|r| ≤ ln 2 / 2`. Relative error below 4e-7 (about 3 ulp) for `x` in [−87, 88] (tested
/// against f64); `x` outside is clamped there, so the result stays normal and finite
/// (`e^−87` ≈ 1.6e−38, `e^88` ≈ 1.65e38), and NaN stays NaN.
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5·2^23
    let x = x.clamp(-87.0, 88.0);
    // Round to nearest by adding 1.5·2^23: `t`'s low mantissa bits then hold n as an
    // integer, read with integer arithmetic (`as i32` saturates, which LLVM does per lane).
    let t = x * std::f32::consts::LOG2_E + MAGIC;
    let n = t - MAGIC;
    let scale = f32::from_bits(t.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(127) << 23);
    let r = x - n * 0.693_359_4 + n * 2.121_944_4e-4;
    let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r + 1.666_666_5e-1)
        * r
        + 0.5;
    let p = p * r * r + r + 1.0;
    p * scale
}

/// SiLU forward: `y[i] = x[i] · σ(x[i])`, with [`exp`].
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn silu(y: &mut [f32], x: &[f32]) {
    for (o, &v) in y.iter_mut().zip(x) {
        *o = v / (1.0 + exp(-v));
    }
}

/// SiLU backward: `dx[i] = dy[i] · σ(x)·(1 + x·(1 − σ(x)))`, with [`exp`].
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn silu_grad(dx: &mut [f32], x: &[f32], g: &[f32]) {
    for ((o, &v), &gv) in dx.iter_mut().zip(x).zip(g) {
        let s = 1.0 / (1.0 + exp(-v));
        *o = gv * (s * (1.0 + v * (1.0 - s)));
    }
}

/// `y[i] += a · x[i]`.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn axpy(y: &mut [f32], a: f32, x: &[f32]) {
    for (o, &v) in y.iter_mut().zip(x) {
        *o += a * v;
    }
}

/// `Σ x[i] · y[i]`, in 16 lanes.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn dot(x: &[f32], y: &[f32]) -> f32 {
    let n = x.len().min(y.len());
    let ((xc, xr), (yc, yr)) = (x[..n].as_chunks::<16>(), y[..n].as_chunks::<16>());
    let mut lanes = [0f32; 16];
    for (a, b) in xc.iter().zip(yc) {
        for k in 0..16 {
            lanes[k] += a[k] * b[k];
        }
    }
    let mut s: f32 = lanes.iter().sum();
    for (a, b) in xr.iter().zip(yr) {
        s += a * b;
    }
    s
}

/// `y[i] = x[i] · a + b`.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn affine(y: &mut [f32], x: &[f32], a: f32, b: f32) {
    for (o, &v) in y.iter_mut().zip(x) {
        *o = v * a + b;
    }
}

/// PReLU forward: `y[i] = x[i]` where positive, else `s · x[i]`.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn prelu(y: &mut [f32], x: &[f32], s: f32) {
    for (o, &v) in y.iter_mut().zip(x) {
        *o = if v > 0.0 { v } else { s * v };
    }
}

/// PReLU backward for one plane of slope `s`: writes `dx` and returns `Σ_{x ≤ 0} x · dy`
/// (the slope's gradient), in 16 lanes; one pass.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn prelu_grad(dx: &mut [f32], x: &[f32], g: &[f32], s: f32) -> f32 {
    let n = dx.len().min(x.len()).min(g.len());
    let (dc, dr) = dx[..n].as_chunks_mut::<16>();
    let ((xc, xr), (gc, gr)) = (x[..n].as_chunks::<16>(), g[..n].as_chunks::<16>());
    let mut lanes = [0f32; 16];
    for ((o, a), b) in dc.iter_mut().zip(xc).zip(gc) {
        for k in 0..16 {
            let pos = a[k] > 0.0;
            o[k] = if pos { b[k] } else { s * b[k] };
            lanes[k] += if pos { 0.0 } else { a[k] * b[k] };
        }
    }
    let mut sum: f32 = lanes.iter().sum();
    for ((o, &a), &b) in dr.iter_mut().zip(xr).zip(gr) {
        let pos = a > 0.0;
        *o = if pos { b } else { s * b };
        sum += if pos { 0.0 } else { a * b };
    }
    sum
}

/// Batch norm's affine then PReLU, forward: `z = x·s + t`, `y = z` where `z > 0`, else
/// `a·z`.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn affine_prelu(y: &mut [f32], x: &[f32], s: f32, t: f32, a: f32) {
    for (o, &v) in y.iter_mut().zip(x) {
        let z = v * s + t;
        *o = if z > 0.0 { z } else { a * z };
    }
}

/// The PReLU part of [`affine_prelu`]'s backward for one plane: writes `dz = dy` where
/// `z = x·s + t > 0`, else `a·dy`, and returns `Σ_{z ≤ 0} z · dy` (the slope's gradient),
/// in 16 lanes.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn affine_prelu_grad(dz: &mut [f32], x: &[f32], g: &[f32], [s, t, a]: [f32; 3]) -> f32 {
    let n = dz.len().min(x.len()).min(g.len());
    let (dc, dr) = dz[..n].as_chunks_mut::<16>();
    let ((xc, xr), (gc, gr)) = (x[..n].as_chunks::<16>(), g[..n].as_chunks::<16>());
    let mut lanes = [0f32; 16];
    for ((o, xv), gv) in dc.iter_mut().zip(xc).zip(gc) {
        for k in 0..16 {
            let z = xv[k] * s + t;
            let pos = z > 0.0;
            o[k] = if pos { gv[k] } else { a * gv[k] };
            lanes[k] += if pos { 0.0 } else { z * gv[k] };
        }
    }
    let mut sum: f32 = lanes.iter().sum();
    for ((o, &xv), &gv) in dr.iter_mut().zip(xr).zip(gr) {
        let z = xv * s + t;
        let pos = z > 0.0;
        *o = if pos { gv } else { a * gv };
        sum += if pos { 0.0 } else { z * gv };
    }
    sum
}

/// `(Σ x, Σ x²)` over one plane in f64 (8 lanes each): batch statistics whose variance
/// `E[x²] − E[x]²` must not cancel in f32.
pub fn sum_and_squares(x: &[f32]) -> (f64, f64) {
    (sum_f64(x), squares_f64(x))
}

/// `Σ x[i]` in f64, 8 lanes.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
fn sum_f64(x: &[f32]) -> f64 {
    let (xc, xr) = x.as_chunks::<8>();
    let mut lanes = [0f64; 8];
    for a in xc {
        for k in 0..8 {
            lanes[k] += a[k] as f64;
        }
    }
    lanes.iter().sum::<f64>() + xr.iter().map(|&v| v as f64).sum::<f64>()
}

/// `Σ x[i]²` in f64, 8 lanes.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
fn squares_f64(x: &[f32]) -> f64 {
    let (xc, xr) = x.as_chunks::<8>();
    let mut lanes = [0f64; 8];
    for a in xc {
        for k in 0..8 {
            let v = a[k] as f64;
            lanes[k] += v * v;
        }
    }
    lanes.iter().sum::<f64>() + xr.iter().map(|&v| (v as f64) * (v as f64)).sum::<f64>()
}

/// `(Σ dy, Σ dy · (x − m) · r)` over one plane, in 16 lanes: two passes over `dy` (one
/// plane fits in the L1 cache), because LLVM vectorises two sums in one loop as pairs of
/// scalars.
pub fn sum_and_centred_dot(g: &[f32], x: &[f32], m: f32, r: f32) -> (f32, f32) {
    (sum(g), centred_dot(g, x, m) * r)
}

/// `Σ x[i]`, in 16 lanes.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn sum(x: &[f32]) -> f32 {
    let (xc, xr) = x.as_chunks::<16>();
    let mut lanes = [0f32; 16];
    for a in xc {
        for k in 0..16 {
            lanes[k] += a[k];
        }
    }
    lanes.iter().sum::<f32>() + xr.iter().sum::<f32>()
}

/// `Σ g[i] · (x[i] − m)`, in 16 lanes.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn centred_dot(g: &[f32], x: &[f32], m: f32) -> f32 {
    let n = g.len().min(x.len());
    let ((gc, gr), (xc, xr)) = (g[..n].as_chunks::<16>(), x[..n].as_chunks::<16>());
    let mut lanes = [0f32; 16];
    for (a, b) in gc.iter().zip(xc) {
        for k in 0..16 {
            lanes[k] += a[k] * (b[k] - m);
        }
    }
    let mut s: f32 = lanes.iter().sum();
    for (&a, &b) in gr.iter().zip(xr) {
        s += a * (b - m);
    }
    s
}

/// Batch-norm input gradient over one plane: `dx = k · (N·dy − Σdy − x̂·Σ(dy x̂))` with
/// `x̂ = (x − m)·r` and `k = γ r / N`.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx512dq+avx512bw", "x86_64+avx2+fma"))]
pub fn batch_norm_grad(dx: &mut [f32], x: &[f32], g: &[f32], [m, r, k, total, sd, sdx]: [f32; 6]) {
    for ((o, &xv), &gv) in dx.iter_mut().zip(x).zip(g) {
        let xh = (xv - m) * r;
        *o = k * (total * gv - sd - xh * sdx);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_within_its_bound_against_f64() {
        let mut worst = 0f64;
        for i in 0..=1_750_000 {
            let x = -87.0 + i as f32 * 1e-4;
            let want = (x as f64).exp();
            worst = worst.max(((exp(x) as f64) - want).abs() / want);
        }
        assert!(worst < 4e-7, "relative error {worst:e}");
        // Clamped outside [−87, 88], never infinite or zero; NaN stays NaN.
        assert_eq!((exp(-200.0), exp(200.0)), (exp(-87.0), exp(88.0)));
        assert!(exp(88.0).is_finite() && exp(-87.0) > 0.0 && exp(f32::NAN).is_nan());
        assert_eq!(exp(0.0), 1.0);
    }

    #[test]
    fn kernels_by_hand() {
        let x: Vec<f32> = (0..37).map(|i| i as f32 - 18.0).collect();
        let g: Vec<f32> = (0..37).map(|i| 0.5 + i as f32 * 0.25).collect();
        let mut y = vec![1.0f32; 37];
        axpy(&mut y, 2.0, &x);
        assert_eq!(y[0], 1.0 - 36.0);
        assert_eq!(dot(&x, &g), x.iter().zip(&g).map(|(a, b)| a * b).sum::<f32>());
        affine(&mut y, &x, 3.0, 1.0);
        assert_eq!(y[36], 18.0 * 3.0 + 1.0);
        prelu(&mut y, &x, 0.25);
        assert_eq!((y[0], y[18], y[36]), (-4.5, 0.0, 18.0));
        let mut dx = vec![0f32; 37];
        let ds = prelu_grad(&mut dx, &x, &g, 0.25);
        assert_eq!((dx[0], dx[36]), (0.125, g[36]));
        let want: f32 = x.iter().zip(&g).filter(|(a, _)| **a <= 0.0).map(|(a, b)| a * b).sum();
        assert!((ds - want).abs() <= 1e-4 * want.abs());
        affine_prelu(&mut y, &x, 2.0, 1.0, 0.25);
        assert_eq!((y[0], y[18], y[36]), ((-36.0 + 1.0) * 0.25, 1.0, 37.0));
        let ds = affine_prelu_grad(&mut dx, &x, &g, [2.0, 1.0, 0.25]);
        assert_eq!((dx[0], dx[17], dx[36]), (0.125, g[17] * 0.25, g[36]));
        let want: f32 =
            x.iter().zip(&g).map(|(a, b)| (a * 2.0 + 1.0, b)).filter(|(z, _)| *z <= 0.0).map(|(z, b)| z * b).sum();
        assert!((ds - want).abs() <= 1e-4 * want.abs());
        let (s, q) = sum_and_squares(&x);
        assert_eq!((s, q), (0.0, (1..=18).map(|i| 2.0 * (i * i) as f64).sum::<f64>()));
        let (s1, s2) = sum_and_centred_dot(&g, &x, 1.0, 0.5);
        assert!((s1 - g.iter().sum::<f32>()).abs() < 1e-4);
        let w2: f32 = g.iter().zip(&x).map(|(a, b)| a * (b - 1.0)).sum::<f32>() * 0.5;
        assert!((s2 - w2).abs() <= 1e-4 * w2.abs());
    }
}
