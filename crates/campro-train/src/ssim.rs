//! SSIM as a differentiable candle loss: the same definition `campro eval quality` scores
//! ([`campro_eval::quality::ssim`]: Wang et al. 2004, 11 x 11 Gaussian window with σ = 1.5,
//! K1 = 0.01, K2 = 0.03, "valid" filtering, mean over the map, the channels and the batch),
//! on images in 0..1, so a training run can ask for the structure the evaluation measures
//! rather than only the squared error. f32 throughout: agrees with the f64 evaluation within
//! 1e-4 on 8-bit images (`tests/enhancer.rs`); the variance E[x²] − μ² cancels in f32 to
//! about 3e-8, which against C2 = 9e-4 is the 1e-4.
//!
//! The Gaussian filter is two matrix products with banded matrices (W x (W − 10) and
//! H x (H − 10)), whose gradients candle already has.

use candle_core::{DType, Device, Result, Tensor};

/// Window taps, as the evaluation's ([`campro_eval::quality::gaussian_window`]).
const TAPS: usize = 11;
/// Stabilisers for a dynamic range of 1.
const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

/// `n` x (n − 10) band: column j holds the normalised Gaussian at rows j..j+11, so
/// `x · band` filters the last dimension of `x` ("valid").
fn band(n: usize, dev: &Device) -> Result<Tensor> {
    let g = campro_eval::quality::gaussian_window();
    let m = n - (TAPS - 1);
    let mut v = vec![0f32; n * m];
    for j in 0..m {
        for (k, gk) in g.iter().enumerate() {
            v[(j + k) * m + j] = *gk as f32;
        }
    }
    Tensor::from_vec(v, (n, m), dev)
}

/// Mean SSIM of `a` against `b`, both (B, C, H, W) in 0..1 with H, W ≥ 11: a scalar
/// tensor (−1..1, 1 for identical images) that carries gradients to both.
pub fn ssim(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let (n, c, h, w) = a.dims4()?;
    if h < TAPS || w < TAPS {
        candle_core::bail!("SSIM needs images of at least {TAPS} x {TAPS} pixels, not {w} x {h}");
    }
    let dev = a.device();
    let k = 5 * n * c;
    // The five maps the window averages, stacked so that both products run once; filtered
    // along the rows, transposed, filtered along the columns (the maps stay transposed:
    // everything after is per pixel and then averaged).
    let maps = Tensor::cat(&[a, b, &a.sqr()?, &b.sqr()?, &(a * b)?], 0)?.to_dtype(DType::F32)?;
    let rows = maps.reshape((k * h, w))?.matmul(&band(w, dev)?)?.reshape((k, h, w - 10))?;
    let cols = rows.transpose(1, 2)?.contiguous()?.reshape((k * (w - 10), h))?;
    let f = cols.matmul(&band(h, dev)?)?.reshape((k, w - 10, h - 10))?;
    let part = |i: usize| f.narrow(0, i * n * c, n * c);
    let (mu_a, mu_b) = (part(0)?, part(1)?);
    let (mu_aa, mu_bb, mu_ab) = ((&mu_a * &mu_a)?, (&mu_b * &mu_b)?, (&mu_a * &mu_b)?);
    let var_a = (part(2)? - &mu_aa)?;
    let var_b = (part(3)? - &mu_bb)?;
    let cov = (part(4)? - &mu_ab)?;
    let num = ((mu_ab * 2.0)? + C1)?.mul(&((cov * 2.0)? + C2)?)?;
    let den = ((mu_aa + mu_bb)? + C1)?.mul(&((var_a + var_b)? + C2)?)?;
    (num / den)?.mean_all()
}
