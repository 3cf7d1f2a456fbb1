//! Full-reference image quality on 8-bit RGB (values 0..255): RMSE, PSNR, SSIM and MS-SSIM.
//!
//! SSIM is Wang et al. 2004 with an 11x11 Gaussian window (σ = 1.5), K1 = 0.01, K2 = 0.03,
//! L = 255, "valid" filtering (no padding), averaged over the valid map and then over the
//! three channels. MS-SSIM is Wang et al. 2003: five scales with weights
//! (0.0448, 0.2856, 0.3001, 0.2363, 0.1333), the contrast-structure term at scales 1-4 and
//! the full SSIM at scale 5, each scale halved by 2x2 averaging (an odd last row or column
//! is dropped); per channel, then averaged. It needs both sides ≥ 176 px (11 px at the fifth scale).
//!
//! Colour fidelity is CIEDE2000 ([`crate::colour`]) per pixel, outside the faces a caller
//! names (the enhanced view pixelates faces on purpose): its mean, 95th percentile and the
//! share of pixels above 5, each averaged over the images.

use crate::data::read_rgb8;
use crate::error::{EvalError, Result};
use crate::Condition;
use image::RgbImage;
use std::path::PathBuf;

pub const MS_SSIM_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];
/// Smallest side MS-SSIM accepts: the 11-px window must fit at the fifth scale (÷16).
pub const MS_SSIM_MIN_SIDE: u32 = 176;

/// The four metrics of one image pair.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Quality {
    pub rmse: f64,
    /// dB; infinite for identical images.
    pub psnr: f64,
    pub ssim: f64,
    /// None when the image is smaller than [`MS_SSIM_MIN_SIDE`].
    pub ms_ssim: Option<f64>,
    /// ΔE00 outside the faces; None when faces cover every pixel.
    pub colour: Option<crate::colour::Fidelity>,
}

/// The face regions (`[x0, y0, x1, y1)` pixels) of a raw image that colour fidelity leaves
/// out.
pub type FacesFn<'a> = dyn Fn(&RgbImage) -> Result<Vec<[u32; 4]>> + Sync + 'a;

/// A single-channel image in f64.
#[derive(Clone)]
struct Plane {
    w: usize,
    h: usize,
    v: Vec<f64>,
}

fn planes(img: &RgbImage) -> [Plane; 3] {
    let (w, h) = (img.width() as usize, img.height() as usize);
    std::array::from_fn(|c| Plane { w, h, v: img.pixels().map(|p| p.0[c] as f64).collect() })
}

/// RMSE over all pixels and channels (0..255 scale).
pub fn rmse(a: &RgbImage, b: &RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let n = a.as_raw().len() as f64;
    (a.as_raw().iter().zip(b.as_raw()).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum::<f64>() / n).sqrt()
}

/// PSNR in dB for peak 255.
pub fn psnr(a: &RgbImage, b: &RgbImage) -> f64 {
    20.0 * (255.0 / rmse(a, b)).log10()
}

/// SSIM's window: 11 taps of a Gaussian with σ = 1.5 px, normalised to sum 1.
pub fn gaussian_window() -> [f64; 11] {
    let mut g: [f64; 11] = std::array::from_fn(|i| (-((i as f64 - 5.0).powi(2)) / (2.0 * 1.5 * 1.5)).exp());
    let s: f64 = g.iter().sum();
    g.iter_mut().for_each(|x| *x /= s);
    g
}

/// Separable valid filtering by the 11-tap Gaussian: output (w − 10) x (h − 10).
fn filter_valid(p: &Plane, g: &[f64; 11]) -> Plane {
    let (w, h) = (p.w - 10, p.h - 10);
    let mut tmp = vec![0.0; w * p.h];
    for y in 0..p.h {
        let row = &p.v[y * p.w..(y + 1) * p.w];
        for x in 0..w {
            tmp[y * w + x] = (0..11).map(|k| g[k] * row[x + k]).sum();
        }
    }
    let mut v = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            v[y * w + x] = (0..11).map(|k| g[k] * tmp[(y + k) * w + x]).sum();
        }
    }
    Plane { w, h, v }
}

/// (mean SSIM, mean contrast-structure) of one channel.
fn ssim_cs(a: &Plane, b: &Plane) -> (f64, f64) {
    let g = gaussian_window();
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let prod =
        |f: fn(f64, f64) -> f64| Plane { w: a.w, h: a.h, v: a.v.iter().zip(&b.v).map(|(&x, &y)| f(x, y)).collect() };
    let mu_a = filter_valid(a, &g);
    let mu_b = filter_valid(b, &g);
    let aa = filter_valid(&prod(|x, _| x * x), &g);
    let bb = filter_valid(&prod(|_, y| y * y), &g);
    let ab = filter_valid(&prod(|x, y| x * y), &g);
    let n = mu_a.v.len() as f64;
    let (mut s, mut c) = (0.0, 0.0);
    for i in 0..mu_a.v.len() {
        let (ma, mb) = (mu_a.v[i], mu_b.v[i]);
        let (va, vb, cov) = (aa.v[i] - ma * ma, bb.v[i] - mb * mb, ab.v[i] - ma * mb);
        let cs = (2.0 * cov + c2) / (va + vb + c2);
        c += cs;
        s += (2.0 * ma * mb + c1) / (ma * ma + mb * mb + c1) * cs;
    }
    (s / n, c / n)
}

fn halve(p: &Plane) -> Plane {
    let (w, h) = (p.w / 2, p.h / 2);
    let v = (0..h)
        .flat_map(|y| (0..w).map(move |x| (y, x)))
        .map(|(y, x)| {
            (p.v[2 * y * p.w + 2 * x]
                + p.v[2 * y * p.w + 2 * x + 1]
                + p.v[(2 * y + 1) * p.w + 2 * x]
                + p.v[(2 * y + 1) * p.w + 2 * x + 1])
                / 4.0
        })
        .collect();
    Plane { w, h, v }
}

/// The least side of an image [`ssim`] and [`quality`] measure: SSIM's Gaussian window.
pub const MIN_SIDE: u32 = 11;

/// SSIM (mean over channels). Both sides must be ≥ [`MIN_SIDE`] px (callers check; smaller
/// panics).
pub fn ssim(a: &RgbImage, b: &RgbImage) -> f64 {
    ssim_and_ms_ssim(a, b).0
}

/// MS-SSIM (mean over channels), or None below [`MS_SSIM_MIN_SIDE`]. Negative
/// contrast-structure terms are clamped at 0 (as pytorch-msssim and TensorFlow) so the power
/// is defined.
pub fn ms_ssim(a: &RgbImage, b: &RgbImage) -> Option<f64> {
    ssim_and_ms_ssim(a, b).1
}

/// Both, sharing the first scale (the full-resolution SSIM is MS-SSIM's scale 1).
fn ssim_and_ms_ssim(a: &RgbImage, b: &RgbImage) -> (f64, Option<f64>) {
    assert_eq!(a.dimensions(), b.dimensions());
    assert!(a.width() >= 11 && a.height() >= 11, "SSIM needs at least 11x11");
    let multi = a.width().min(a.height()) >= MS_SSIM_MIN_SIDE;
    let (pa, pb) = (planes(a), planes(b));
    let (mut ssim, mut ms) = (0.0, 0.0);
    for c in 0..3 {
        let (mut x, mut y) = (pa[c].clone(), pb[c].clone());
        let mut v = 1.0;
        for (k, w) in MS_SSIM_WEIGHTS.iter().enumerate() {
            let (s, cs) = ssim_cs(&x, &y);
            if k == 0 {
                ssim += s;
                if !multi {
                    break;
                }
            }
            v *= if k == 4 { s.max(0.0).powf(*w) } else { cs.max(0.0).powf(*w) };
            if k < 4 {
                x = halve(&x);
                y = halve(&y);
            }
        }
        ms += v;
    }
    (ssim / 3.0, multi.then_some(ms / 3.0))
}

/// All four metrics, and colour fidelity over every pixel.
pub fn quality(a: &RgbImage, b: &RgbImage) -> Quality {
    quality_outside(a, b, &[])
}

/// [`quality`] with colour fidelity outside the `faces` regions (`[x0, y0, x1, y1)`).
pub fn quality_outside(a: &RgbImage, b: &RgbImage, faces: &[[u32; 4]]) -> Quality {
    let (ssim, ms_ssim) = ssim_and_ms_ssim(a, b);
    let outside = |x: u32, y: u32| !faces.iter().any(|r| (r[0]..r[2]).contains(&x) && (r[1]..r[3]).contains(&y));
    Quality { rmse: rmse(a, b), psnr: psnr(a, b), ssim, ms_ssim, colour: crate::colour::compare(a, b, outside) }
}

/// Mean metrics of one condition over a set of images (PSNR: mean of per-image dB, identical
/// pairs left out; MS-SSIM over the images large enough).
#[derive(Debug, Clone, serde::Serialize)]
pub struct QualityRow {
    pub condition: String,
    pub rmse: f64,
    pub psnr: f64,
    pub ssim: f64,
    pub ms_ssim: f64,
    /// Mean ΔE00 outside faces, its 95th percentile and the share above 5 (each the mean
    /// over the images).
    pub delta_e: f64,
    pub delta_e_p95: f64,
    pub delta_e_over5: f64,
    pub images: usize,
    pub ms_ssim_images: usize,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct QualityReport {
    pub images: usize,
    pub rows: Vec<QualityRow>,
    pub seconds: f64,
}

/// Scores every protected condition (raw ones are skipped) against the raw images; colour
/// fidelity outside the regions `faces` finds in each raw image (every pixel without it).
pub fn evaluate(
    paths: &[PathBuf],
    conds: &[Condition],
    limit: Option<usize>,
    faces: Option<&FacesFn<'_>>,
) -> Result<QualityReport> {
    let start = std::time::Instant::now();
    let paths = &paths[..limit.unwrap_or(paths.len()).min(paths.len())];
    let conds: Vec<&Condition> = conds.iter().filter(|c| c.protect.is_some()).collect();
    let per: Vec<Vec<Quality>> = crate::par_map_progress(paths, "quality", |p| {
        let img = read_rgb8(p)?;
        if img.width() < MIN_SIDE || img.height() < MIN_SIDE {
            return Err(EvalError::Invalid(format!(
                "{}: {} x {} px; image quality needs at least {MIN_SIDE} x {MIN_SIDE} (SSIM's window)",
                campro::file::shown(p),
                img.width(),
                img.height()
            )));
        }
        let regions = faces.map(|f| f(&img)).transpose()?.unwrap_or_default();
        Ok(conds.iter().map(|c| quality_outside(&img, &c.apply(&img), &regions)).collect())
    })?;
    let rows = conds
        .iter()
        .enumerate()
        .map(|(c, cond)| {
            let n = per.len() as f64;
            let col = || per.iter().map(move |q| q[c]);
            let finite: Vec<f64> = col().map(|q| q.psnr).filter(|v| v.is_finite()).collect();
            let ms: Vec<f64> = col().filter_map(|q| q.ms_ssim).collect();
            let colour: Vec<crate::colour::Fidelity> = col().filter_map(|q| q.colour).collect();
            let mean_of =
                |f: fn(&crate::colour::Fidelity) -> f64| colour.iter().map(f).sum::<f64>() / colour.len().max(1) as f64;
            QualityRow {
                condition: cond.name.clone(),
                rmse: col().map(|q| q.rmse).sum::<f64>() / n,
                psnr: if finite.is_empty() { f64::INFINITY } else { finite.iter().sum::<f64>() / finite.len() as f64 },
                ssim: col().map(|q| q.ssim).sum::<f64>() / n,
                ms_ssim: ms.iter().sum::<f64>() / ms.len().max(1) as f64,
                delta_e: mean_of(|f| f.mean),
                delta_e_p95: mean_of(|f| f.p95),
                delta_e_over5: mean_of(|f| f.over5),
                images: per.len(),
                ms_ssim_images: ms.len(),
            }
        })
        .collect();
    Ok(QualityReport { images: paths.len(), rows, seconds: start.elapsed().as_secs_f64() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    #[test]
    fn identical_images_score_perfectly() {
        let a =
            RgbImage::from_fn(176, 180, |x, y| Rgb([(x * 3 % 256) as u8, (y * 5 % 256) as u8, ((x + y) % 256) as u8]));
        let q = quality(&a, &a);
        assert_eq!(q.rmse, 0.0);
        assert!(q.psnr.is_infinite());
        assert!((q.ssim - 1.0).abs() < 1e-12);
        assert!((q.ms_ssim.unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rmse_psnr_by_hand() {
        // Every value differs by 10: RMSE 10, PSNR 20·log10(25.5) = 28.1308 dB.
        let a = RgbImage::from_pixel(20, 20, Rgb([100, 100, 100]));
        let b = RgbImage::from_pixel(20, 20, Rgb([110, 90, 110]));
        assert!((rmse(&a, &b) - 10.0).abs() < 1e-12);
        assert!((psnr(&a, &b) - 28.130803608679102).abs() < 1e-9);
    }

    #[test]
    fn ssim_of_flat_images_by_hand() {
        // Flat images: σ = 0, so SSIM = (2·μa·μb + C1) / (μa² + μb² + C1).
        let a = RgbImage::from_pixel(30, 30, Rgb([100; 3]));
        let b = RgbImage::from_pixel(30, 30, Rgb([120; 3]));
        let c1 = (0.01f64 * 255.0).powi(2);
        let want = (2.0 * 100.0 * 120.0 + c1) / (100.0f64.powi(2) + 120.0f64.powi(2) + c1);
        assert!((ssim(&a, &b) - want).abs() < 1e-12);
    }
}
