//! Errors of a deployment against the desktop pipeline.
//!
//! The device is simulated on an sRGB test pixel as: degamma -> inverse device matrix
//! (giving the sensor RGB the device would have seen) -> emulator. The desktop
//! pipeline runs on the same pixel in f64. Errors are in output units (1 = full scale)
//! and reported in 8-bit LSB (x255) and PSNR.

use crate::ccm;
use crate::emulate::Emulator;
use crate::error::ValidationError;
use crate::params::Params;
use crate::pipeline::{degamma, process_f64};
use crate::targets::Feed;

/// Running error statistics over pixel channels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stats {
    /// Largest absolute channel difference.
    pub max_abs: f64,
    sum_abs: f64,
    sum_sq: f64,
    /// Channels compared.
    pub count: usize,
}

impl Stats {
    /// Adds one pixel pair.
    #[inline]
    pub fn add(&mut self, a: [f64; 3], b: [f64; 3]) {
        for k in 0..3 {
            let d = (a[k] - b[k]).abs();
            self.max_abs = self.max_abs.max(d);
            self.sum_abs += d;
            self.sum_sq += d * d;
        }
        self.count += 3;
    }
    /// Mean absolute difference.
    pub fn mean_abs(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_abs / self.count as f64
        }
    }
    /// Max in 8-bit LSB.
    pub fn max_lsb(&self) -> f64 {
        self.max_abs * 255.0
    }
    /// Mean in 8-bit LSB.
    pub fn mean_lsb(&self) -> f64 {
        self.mean_abs() * 255.0
    }
    /// PSNR in dB for a peak of 1 (infinite when identical).
    pub fn psnr(&self) -> f64 {
        let mse = if self.count == 0 { 0.0 } else { self.sum_sq / self.count as f64 };
        10.0 * (1.0 / mse).log10()
    }
}

/// Every 8-bit grey level, black to white.
pub fn grey_levels() -> Vec<[u8; 3]> {
    (0..=255u8).map(|v| [v; 3]).collect()
}

/// `n` random 8-bit pixels from a seeded SplitMix64 stream (reproducible everywhere).
pub fn random_pixels(n: usize, seed: u64) -> Vec<[u8; 3]> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            [z as u8, (z >> 8) as u8, (z >> 16) as u8]
        })
        .collect()
}

/// The 8-bit RGB cube sampled every `step` codes per axis (255 always included).
pub fn code_cube(step: usize) -> Vec<[u8; 3]> {
    let mut axis: Vec<u8> = (0..=255u32).step_by(step.max(1)).map(|v| v as u8).collect();
    if *axis.last().unwrap() != 255 {
        axis.push(255);
    }
    let mut out = Vec::with_capacity(axis.len().pow(3));
    for &r in &axis {
        for &g in &axis {
            for &b in &axis {
                out.push([r, g, b]);
            }
        }
    }
    out
}

/// Any deployment against the desktop pipeline on sRGB `pixels`. With
/// [`Feed::Sensor`]`(device)` each pixel becomes the sensor RGB that device would have
/// seen (`device^-1 · degamma(pixel)`); with [`Feed::Encoded`] the emulator gets the
/// pixel itself in [0, 1]. Outputs are compared with [`process_f64`]. Fails if the
/// device is singular.
pub fn deployment_vs_desktop(
    params: &Params,
    feed: &Feed,
    emulator: &dyn Emulator,
    pixels: &[[u8; 3]],
) -> Result<Stats, ValidationError> {
    let inv = match feed {
        Feed::Sensor(device) => Some(ccm::inverse(device).ok_or_else(|| ValidationError::Rule {
            field: "device_ccm".into(),
            rule: "must be invertible to synthesise sensor RGB from sRGB test images".into(),
        })?),
        Feed::Encoded => None,
    };
    let table: Vec<f64> = (0..=255).map(|c| degamma(c as f64 / 255.0, params.degamma)).collect();
    let mut stats = Stats::default();
    for px in pixels {
        let input = match &inv {
            Some(inv) => ccm::apply(inv, px.map(|c| table[c as usize])),
            None => px.map(|c| c as f64 / 255.0),
        };
        let want = process_f64(params, px.map(|c| c as f64 / 255.0));
        stats.add(emulator.sensor_to_output(input), want);
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_by_hand() {
        let mut s = Stats::default();
        s.add([0.0, 0.5, 1.0], [0.0, 0.25, 1.0]);
        assert_eq!(s.max_abs, 0.25);
        assert!((s.mean_abs() - 0.25 / 3.0).abs() < 1e-15);
        // mse = 0.0625 / 3 -> psnr = 10 log10(48)
        assert!((s.psnr() - 10.0 * 48f64.log10()).abs() < 1e-12);
    }

    #[test]
    fn pixel_sets() {
        assert_eq!(grey_levels().len(), 256);
        assert_eq!(code_cube(51).len(), 6 * 6 * 6);
        assert_eq!(code_cube(100).len(), 4 * 4 * 4);
        assert_eq!(random_pixels(10, 1), random_pixels(10, 1));
        assert_ne!(random_pixels(10, 1), random_pixels(10, 2));
    }
}
