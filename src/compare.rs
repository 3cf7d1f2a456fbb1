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
use crate::targets::{Condition, Feed};

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

/// One measured cell of a comparison: a deployment condition on one pixel set.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// The condition's label (`ct 4650`, `33^3 tetrahedral`, ...).
    pub condition: String,
    /// The pixel set's name (`every grey level`, `RGB cube, step 5`, ...).
    pub pixels: String,
    /// The measured error.
    pub stats: Stats,
    /// The condition's stated bound (output units), where the target states one.
    pub bound: Option<f64>,
}

/// The test pixels every comparison uses, named: every grey level, the RGB cube in steps of
/// 5, `random` seeded random pixels and the built-in chart.
pub fn pixel_sets(random: usize, seed: u64) -> Vec<(String, Vec<[u8; 3]>)> {
    let chart: Vec<[u8; 3]> = crate::chart::render().chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    vec![
        ("every grey level".to_string(), grey_levels()),
        ("RGB cube, step 5".to_string(), code_cube(5)),
        (format!("{random} random pixels"), random_pixels(random, seed)),
        ("built-in chart".to_string(), chart),
    ]
}

/// Every condition on every pixel set of [`pixel_sets`], conditions outermost: what
/// `campro compare` reports and `campro convert` checks before it writes a file target.
pub fn comparison(
    params: &Params,
    conditions: &[Condition],
    random: usize,
    seed: u64,
) -> Result<Vec<Row>, ValidationError> {
    let sets = pixel_sets(random, seed);
    let mut rows = Vec::with_capacity(conditions.len() * sets.len());
    for c in conditions {
        for (name, px) in &sets {
            let stats = deployment_vs_desktop(params, &c.feed, c.emulator.as_ref(), px)?;
            rows.push(Row { condition: c.label.clone(), pixels: name.clone(), stats, bound: c.bound });
        }
    }
    Ok(rows)
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
    fn comparison_is_every_condition_on_every_set_in_order() {
        let p = Params::identity_curve(9);
        // Two conditions: the exact ISP, and one whose matrix is off by 1% on the diagonal.
        let conditions: Vec<Condition> = [1.0, 1.01]
            .into_iter()
            .map(|g| Condition {
                label: format!("gain {g}"),
                feed: Feed::Sensor(ccm::IDENTITY),
                emulator: Box::new(crate::emulate::Isp {
                    matrix: ccm::scale(&p.ccm, g),
                    curves: p.tone_curves.clone(),
                }),
                bound: Some(0.5),
            })
            .collect();
        let rows = comparison(&p, &conditions, 50, 3).unwrap();
        let sets = super::pixel_sets(50, 3);
        assert_eq!(rows.len(), 2 * 4);
        for (i, r) in rows.iter().enumerate() {
            let (c, (name, px)) = (&conditions[i / 4], &sets[i % 4]);
            assert_eq!((&r.condition, &r.pixels, r.bound), (&c.label, name, Some(0.5)));
            assert_eq!(r.stats, deployment_vs_desktop(&p, &c.feed, c.emulator.as_ref(), px).unwrap());
            assert_eq!(r.stats.count, 3 * px.len());
        }
        assert_eq!(rows[0].stats.max_abs, 0.0, "the exact ISP on grey levels");
        assert!(rows[4].stats.max_abs > 0.0);
        assert_eq!(sets.iter().map(|s| s.1.len()).collect::<Vec<_>>(), [256, 52 * 52 * 52, 50, sets[3].1.len()]);
        assert_eq!(sets[3].1.len(), (crate::chart::WIDTH * crate::chart::HEIGHT) as usize);
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
