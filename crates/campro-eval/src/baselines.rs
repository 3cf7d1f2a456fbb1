//! The paper's hardware baselines (its Appendix "Baselines"): a low-resolution camera (area
//! downsampling by `s`, bilinear upsampling back) and a defocused camera (normalised
//! Gaussian blur with zero padding, as a `conv2d` with `padding = k / 2`).

use crate::geometry::resize_bilinear;
use image::{Rgb, RgbImage};
use std::fmt;
use std::str::FromStr;

/// A baseline protection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Baseline {
    /// Downsample by this factor (≥ 1) with area averaging, upsample bilinearly.
    LowRes(u32),
    /// Gaussian blur: odd kernel size and σ (px).
    Defocus { kernel: u32, sigma: f64 },
}

impl Baseline {
    /// The paper's settings: low resolution 4/8/16, defocus 9/3, 13/5, 15/7 and 25/7.
    pub fn paper() -> Vec<Baseline> {
        vec![
            Baseline::LowRes(4),
            Baseline::LowRes(8),
            Baseline::LowRes(16),
            Baseline::Defocus { kernel: 9, sigma: 3.0 },
            Baseline::Defocus { kernel: 13, sigma: 5.0 },
            Baseline::Defocus { kernel: 15, sigma: 7.0 },
            Baseline::Defocus { kernel: 25, sigma: 7.0 },
        ]
    }

    pub fn apply(&self, img: &RgbImage) -> RgbImage {
        match *self {
            Baseline::LowRes(s) => low_res(img, s),
            Baseline::Defocus { kernel, sigma } => defocus(img, kernel, sigma),
        }
    }
}

impl fmt::Display for Baseline {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Baseline::LowRes(s) => write!(f, "lowres-{s}"),
            Baseline::Defocus { kernel, sigma } => write!(f, "defocus-{kernel}-{sigma}"),
        }
    }
}

impl FromStr for Baseline {
    type Err = String;
    /// `lowres-S` or `defocus-K-SIGMA`, as printed.
    fn from_str(s: &str) -> Result<Self, String> {
        let parts: Vec<&str> = s.split('-').collect();
        let bad =
            || format!("baseline {s:?}: expected lowres-S (S ≥ 1) or defocus-K-SIGMA (odd K in 1..=101, SIGMA > 0)");
        match parts.as_slice() {
            ["lowres", f] => match f.parse::<u32>() {
                Ok(f) if (1..=256).contains(&f) => Ok(Baseline::LowRes(f)),
                _ => Err(bad()),
            },
            ["defocus", k, sg] => match (k.parse::<u32>(), sg.parse::<f64>()) {
                (Ok(k), Ok(sg)) if k % 2 == 1 && k <= 101 && sg.is_finite() && sg > 0.0 => {
                    Ok(Baseline::Defocus { kernel: k, sigma: sg })
                }
                _ => Err(bad()),
            },
            _ => Err(bad()),
        }
    }
}

/// Area resampling to `w x h` (each output pixel is the mean of the input area it covers,
/// fractional pixels weighted by coverage; OpenCV's INTER_AREA for shrinking).
pub fn resize_area(img: &RgbImage, w: u32, h: u32) -> RgbImage {
    let weights = |n_in: u32, n_out: u32| -> Vec<Vec<(usize, f64)>> {
        let s = n_in as f64 / n_out as f64;
        (0..n_out)
            .map(|o| {
                let (a, b) = (o as f64 * s, (o + 1) as f64 * s);
                (a.floor() as usize..(b.ceil() as usize).min(n_in as usize))
                    .map(|i| (i, ((i + 1) as f64).min(b) - (i as f64).max(a)))
                    .filter(|&(_, c)| c > 0.0)
                    .map(|(i, c)| (i, c / s))
                    .collect()
            })
            .collect()
    };
    let (wx, wy) = (weights(img.width(), w), weights(img.height(), h));
    RgbImage::from_fn(w, h, |x, y| {
        let mut acc = [0.0f64; 3];
        for &(iy, cy) in &wy[y as usize] {
            for &(ix, cx) in &wx[x as usize] {
                let p = img.get_pixel(ix as u32, iy as u32).0;
                for k in 0..3 {
                    acc[k] += cx * cy * p[k] as f64;
                }
            }
        }
        Rgb(acc.map(|v| v.round().clamp(0.0, 255.0) as u8))
    })
}

/// Low-resolution camera: area-downsample to `⌊w/s⌋ x ⌊h/s⌋` (at least 1), bilinear back.
pub fn low_res(img: &RgbImage, s: u32) -> RgbImage {
    let (w, h) = ((img.width() / s).max(1), (img.height() / s).max(1));
    resize_bilinear(&resize_area(img, w, h), img.width(), img.height())
}

/// Normalised 1-D Gaussian of `kernel` taps (odd), σ in px.
pub fn gaussian_kernel(kernel: u32, sigma: f64) -> Vec<f64> {
    let r = (kernel / 2) as f64;
    let g: Vec<f64> = (0..kernel).map(|i| (-((i as f64 - r).powi(2)) / (2.0 * sigma * sigma)).exp()).collect();
    let s: f64 = g.iter().sum();
    g.into_iter().map(|v| v / s).collect()
}

/// Defocused camera: separable normalised Gaussian blur, zero padding (edges darken, as a
/// zero-padded `conv2d`).
pub fn defocus(img: &RgbImage, kernel: u32, sigma: f64) -> RgbImage {
    let g = gaussian_kernel(kernel, sigma);
    let r = (kernel / 2) as i64;
    let (w, h) = (img.width() as i64, img.height() as i64);
    let src: Vec<f64> = img.as_raw().iter().map(|&v| v as f64).collect();
    let mut tmp = vec![0.0; src.len()];
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let mut a = 0.0;
                for (k, gk) in g.iter().enumerate() {
                    let xx = x + k as i64 - r;
                    if (0..w).contains(&xx) {
                        a += gk * src[((y * w + xx) * 3 + c) as usize];
                    }
                }
                tmp[((y * w + x) * 3 + c) as usize] = a;
            }
        }
    }
    let mut out = RgbImage::new(img.width(), img.height());
    for y in 0..h {
        for x in 0..w {
            let mut px = [0u8; 3];
            for (c, p) in px.iter_mut().enumerate() {
                let mut a = 0.0;
                for (k, gk) in g.iter().enumerate() {
                    let yy = y + k as i64 - r;
                    if (0..h).contains(&yy) {
                        a += gk * tmp[((yy * w + x) * 3 + c as i64) as usize];
                    }
                }
                *p = a.round().clamp(0.0, 255.0) as u8;
            }
            out.put_pixel(x as u32, y as u32, Rgb(px));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_refused() {
        for b in Baseline::paper() {
            assert_eq!(b.to_string().parse::<Baseline>().unwrap(), b);
        }
        for bad in ["lowres-0", "defocus-4-2", "defocus-9-nan", "blur-3", "defocus-9--1"] {
            assert!(bad.parse::<Baseline>().is_err(), "{bad}");
        }
    }

    #[test]
    fn area_downsample_averages_blocks() {
        // A 4x2 image of values 0, 10, 20, 30 / 40, 50, 60, 70 halved: block means 25 and 45.
        let img = RgbImage::from_fn(4, 2, |x, y| Rgb([(x * 10 + y * 40) as u8; 3]));
        let d = resize_area(&img, 2, 1);
        assert_eq!(d.get_pixel(0, 0).0[0], 25);
        assert_eq!(d.get_pixel(1, 0).0[0], 45);
        // A fractional case: 3 px -> 2 px, each output covers 1.5 inputs.
        let img = RgbImage::from_fn(3, 1, |x, _| Rgb([[0, 30, 90][x as usize]; 3]));
        let d = resize_area(&img, 2, 1);
        assert_eq!(d.get_pixel(0, 0).0[0], 10); // (0 + 0.5·30) / 1.5
        assert_eq!(d.get_pixel(1, 0).0[0], 70); // (0.5·30 + 90) / 1.5
    }

    #[test]
    fn defocus_keeps_flat_interiors_and_darkens_edges() {
        let img = RgbImage::from_pixel(40, 40, Rgb([200; 3]));
        let b = defocus(&img, 9, 3.0);
        assert_eq!(b.get_pixel(20, 20).0, [200; 3]);
        // At a corner, a quarter-plane-ish share of the kernel falls outside: darker.
        let g = gaussian_kernel(9, 3.0);
        let inside: f64 = g[4..].iter().sum();
        assert_eq!(b.get_pixel(0, 0).0[0], (200.0 * inside * inside).round() as u8);
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn low_res_of_a_flat_image_is_flat() {
        let img = RgbImage::from_pixel(50, 30, Rgb([77, 88, 99]));
        let l = low_res(&img, 16);
        assert_eq!(l.dimensions(), (50, 30));
        assert!(l.pixels().all(|p| p.0 == [77, 88, 99]));
    }
}
