//! Android Camera2: CamPro as `COLOR_CORRECTION_TRANSFORM` and `TONEMAP_CURVE`.
//!
//! On a phone the sensor's (white-balanced) RGB goes through the device's colour
//! transform `M_dev` (sensor -> linear sRGB, what the device reports in auto mode),
//! then the tone curve. The desktop pipeline applies `CCM` to linear sRGB, so the
//! request carries `M = CCM · M_dev` (column vectors; the paper's appendix writes the
//! same product for row vectors as `CCM_ori · CCM_opt`).
//!
//! Camera2 only promises unclipped matrix entries in [-1.5, 3.0]. When `M` leaves that
//! range it is divided by `s` and `s` is folded into the curve, `curve'(t) =
//! curve(min(1, s·t))`, which is exact because the device clips to [0, 1] before the
//! curve: `clip(M/s·v)` is `clip(M·v)/s` wherever `M·v < 1` and is 1 (mapped to
//! `curve(1)`) wherever `M·v >= 1`.
//!
//! Errors, in output units (1 = full scale; 8-bit LSB = 1/255), over sensor RGB in [0,1]^3:
//! `|device - desktop| <= E_curve + L' · max_i Σ_j |ΔM_ij|`, where `ΔM` is the rational
//! rounding of `M/s`, `L'` the largest slope of the sent curve and `E_curve` the exact
//! maximum difference between the sent (f32, possibly simplified) curve and `curve'`.

mod camera_loop;
mod device;
mod readback;
mod wire;

pub use camera_loop::{Camera2Loop, LoopStats, Update, DEFAULT_TOLERANCE};
pub use device::{device, Camera2};
pub use readback::{readback, readback_channel, Readback};
pub use wire::{device_transform_from_capture_result, gain, gains_from_capture_result, values_from_json, MAX_GAIN};

use crate::ccm::{self, Mat3};
use crate::emulate::error_bound;
use crate::error::{check_matrix, ValidationError};
use crate::params::Params;
use crate::rational::{self, Rational, RationalError};
use crate::tone_curve::{ToneCurve, ToneCurves};

/// Camera2 guarantees matrix entries in this range are not clipped.
pub const MATRIX_RANGE: (f64, f64) = (-1.5, 3.0);
/// Default denominator bound for the rationals (2^16, like a Q16 register). The
/// rounding error per entry is then at most 7.6e-6.
pub const DEFAULT_MAX_DENOMINATOR: u32 = 1 << 16;
/// Android guarantees `TONEMAP_MAX_CURVE_POINTS >= 64` where CONTRAST_CURVE exists.
pub const DEFAULT_MAX_CURVE_POINTS: usize = 64;

/// How matrix entries become rationals.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RationalMode {
    /// Closest fraction with a denominator up to the bound.
    Best {
        /// Largest denominator allowed (1 to `i32::MAX`).
        max_denominator: u32,
    },
    /// Every entry over this one denominator, like a fixed-point ISP.
    Fixed {
        /// The denominator (1 to `i32::MAX`).
        denominator: u32,
    },
}

/// Conversion settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// The device's `TONEMAP_MAX_CURVE_POINTS` (>= 2).
    pub max_curve_points: usize,
    /// Rational approximation of the matrix.
    pub rational: RationalMode,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            max_curve_points: DEFAULT_MAX_CURVE_POINTS,
            rational: RationalMode::Best { max_denominator: DEFAULT_MAX_DENOMINATOR },
        }
    }
}

/// `TonemapCurve`: per channel a flat array of (Pin, Pout) pairs, Pin ascending from 0 to 1.
#[derive(Debug, Clone, PartialEq)]
pub struct TonemapCurve {
    /// Red channel pairs.
    pub red: Vec<f32>,
    /// Green channel pairs (the same as red and blue for a set with one shared curve).
    pub green: Vec<f32>,
    /// Blue channel pairs.
    pub blue: Vec<f32>,
}

/// What the conversion achieved, in output units (1 = full scale) unless named otherwise.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorReport {
    /// Largest |rational - wanted| over the nine (scaled) matrix entries.
    pub matrix_max_abs: f64,
    /// Exact max |sent curve - folded curve| over [0, 1] (simplification and f32 rounding),
    /// the largest of the channels'.
    pub curve_max_abs: f64,
    /// The most points of any channel's sent curve.
    pub curve_points: usize,
    /// Whether a curve had to lose knots to fit `max_curve_points`.
    pub curve_simplified: bool,
    /// Largest slope of the sent curves (how much matrix error grows).
    pub curve_lipschitz: f64,
    /// [`ErrorReport::curve_max_abs`] of each channel (red, green, blue).
    pub channel_max_abs: [f64; 3],
    /// [`ErrorReport::curve_lipschitz`] of each channel.
    pub channel_lipschitz: [f64; 3],
    /// Guaranteed bound on |device - desktop| for sensor RGB in [0, 1]^3.
    pub bound: f64,
}

impl ErrorReport {
    /// [`ErrorReport::bound`] in 8-bit LSB.
    pub fn bound_lsb(&self) -> f64 {
        self.bound * 255.0
    }
}

/// The values for a `CaptureRequest`, plus what they cost in accuracy.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera2Values {
    /// `COLOR_CORRECTION_TRANSFORM` as `ColorSpaceTransform(int[])` takes it: nine
    /// (numerator, denominator) pairs, row-major.
    pub color_correction_transform: [i32; 18],
    /// `TONEMAP_CURVE`.
    pub tonemap_curve: TonemapCurve,
    /// The matrix divided by this (>= 1) and folded into the curve.
    pub scale: f64,
    /// `CCM · M_dev` before scaling and rounding.
    pub composed: Mat3,
    /// Achieved accuracy.
    pub report: ErrorReport,
}

impl Camera2Values {
    /// The transform the device receives, as f64.
    pub fn matrix(&self) -> Mat3 {
        matrix_from_rationals(&self.color_correction_transform).expect("denominators are positive")
    }

    /// The curves the device receives, as f64.
    pub fn curves(&self) -> ToneCurves {
        let t = &self.tonemap_curve;
        ToneCurves::per_channel(
            [&t.red, &t.green, &t.blue].map(|p| curve_from_pairs(p).expect("sent curves are valid")),
        )
    }
}

/// Why a conversion failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConvertError {
    /// An input broke a rule.
    #[error("{0}")]
    Invalid(#[from] ValidationError),
    /// A matrix entry has no 32-bit rational within the bound.
    #[error("colorCorrectionTransform[{row}][{col}]: {source}")]
    Rational {
        /// Matrix row.
        row: usize,
        /// Matrix column.
        col: usize,
        /// Why the entry has no rational.
        source: RationalError,
    },
    /// A colour temperature was given but no calibration maps it to a device transform.
    #[error("ct_calibration: a colour temperature needs a calibration: set a DNG calibration or give the parameter set ct_calibration")]
    NoCalibration,
}

/// A 3x3 matrix from `ColorSpaceTransform`'s 18 integers (row-major num/den pairs).
pub fn matrix_from_rationals(v: &[i32; 18]) -> Result<Mat3, ValidationError> {
    let mut m = [[0.0; 3]; 3];
    for i in 0..9 {
        let (num, den) = (v[2 * i], v[2 * i + 1]);
        if den == 0 {
            return Err(ValidationError::Rule {
                field: format!("colorCorrectionTransform[{}]", 2 * i + 1),
                rule: "denominator must not be 0".into(),
            });
        }
        m[i / 3][i % 3] = num as f64 / den as f64;
    }
    Ok(m)
}

/// A curve from a flat (Pin, Pout) array as `TonemapCurve` holds it.
pub fn curve_from_pairs(pairs: &[f32]) -> Result<ToneCurve, ValidationError> {
    curve_from_pairs_named(pairs, "tonemapCurve")
}

/// [`curve_from_pairs`] with errors naming `field` (`tonemapCurve.green`).
pub fn curve_from_pairs_named(pairs: &[f32], field: &str) -> Result<ToneCurve, ValidationError> {
    if !pairs.len().is_multiple_of(2) {
        return Err(ValidationError::WrongLength {
            field: field.into(),
            expected: "an even number (Pin, Pout pairs)".into(),
            got: pairs.len(),
        });
    }
    let x = pairs.iter().step_by(2).map(|&v| v as f64).collect();
    let y = pairs.iter().skip(1).step_by(2).map(|&v| v as f64).collect();
    ToneCurve::new(x, y).map_err(|e| e.within(field))
}

/// The smallest `s >= 1` that brings every entry of `m` into [`MATRIX_RANGE`].
pub fn range_scale(m: &Mat3) -> f64 {
    range_scale_within(m, 0.0)
}

/// The smallest `s >= 1` that brings every entry of `m` into [`MATRIX_RANGE`] shrunk by
/// `margin` at both ends, so that rounding each entry by up to `margin` stays in range.
pub fn range_scale_within(m: &Mat3, margin: f64) -> f64 {
    let (lo, hi) = ccm::min_max(m);
    1.0f64.max(hi / (MATRIX_RANGE.1 - margin)).max(lo / (MATRIX_RANGE.0 + margin))
}

/// Largest rounding error of one matrix entry under `mode`: half a unit of the
/// (largest) denominator; the best approximation is never worse than the fixed one.
pub fn rational_error_bound(mode: RationalMode) -> f64 {
    match mode {
        RationalMode::Best { max_denominator: d } | RationalMode::Fixed { denominator: d } => 0.5 / d.max(1) as f64,
    }
}

/// Maps CamPro parameters onto Camera2 for a device whose own colour transform is
/// `device` (sensor RGB -> linear sRGB; identity when the device reports none).
pub fn convert(params: &Params, device: &Mat3, opts: &Options) -> Result<Camera2Values, ConvertError> {
    check_options(opts)?;
    convert_with(params, device, opts, &mut None)
}

/// `opts` broken rules, by field.
pub fn check_options(opts: &Options) -> Result<(), ValidationError> {
    if opts.max_curve_points < 2 {
        return Err(ValidationError::OutOfRange {
            field: "max_curve_points".into(),
            value: opts.max_curve_points as f64,
            min: 2.0,
            max: f64::INFINITY,
        });
    }
    let d = match opts.rational {
        RationalMode::Best { max_denominator } => ("max_denominator", max_denominator),
        RationalMode::Fixed { denominator } => ("denominator", denominator),
    };
    if d.1 == 0 || d.1 > i32::MAX as u32 {
        return Err(ValidationError::OutOfRange {
            field: d.0.into(),
            value: d.1 as f64,
            min: 1.0,
            max: i32::MAX as f64,
        });
    }
    Ok(())
}

/// The tone-curve half of a conversion. It depends only on the parameters, the range
/// scale and the point budget, so a camera loop keeps it while the device matrix moves.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvePart {
    /// Range scale folded into the curves.
    pub scale: f64,
    /// The point budget they were fitted to.
    pub max_points: usize,
    /// Each channel's sent curve (red, green, blue; one fit shared by the three when the
    /// parameters' curve is).
    pub channels: [SentCurve; 3],
}

/// One channel's curve as sent, and what sending it costs.
#[derive(Debug, Clone, PartialEq)]
pub struct SentCurve {
    /// Flat f32 (Pin, Pout) pairs as sent.
    pub pairs: Vec<f32>,
    /// Exact max |sent - folded| over [0, 1].
    pub max_abs: f64,
    /// Whether knots were dropped to fit the budget.
    pub simplified: bool,
    /// Largest slope of the sent curve.
    pub lipschitz: f64,
}

/// Folds `scale` into each of the parameters' curves, fits it to `max_points` (optimal
/// knot subset when it has more) and rounds it to f32 pairs, measuring what that costs.
pub fn curve_part(params: &Params, scale: f64, max_points: usize) -> CurvePart {
    let fit = |c: &ToneCurve| {
        let folded = c.fold_scale(scale);
        let (fitted, simplified) =
            if folded.len() > max_points { (folded.simplify(max_points).0, true) } else { (folded.clone(), false) };
        let pairs = to_f32_pairs(&fitted);
        let sent = curve_from_pairs(&pairs).expect("rounded pairs stay valid");
        SentCurve { max_abs: folded.max_abs_diff(&sent), simplified, lipschitz: sent.max_slope(), pairs }
    };
    let channels = match &params.tone_curves {
        ToneCurves::Shared(c) => {
            let one = fit(c);
            [one.clone(), one.clone(), one]
        }
        ToneCurves::PerChannel(c) => [fit(&c[0]), fit(&c[1]), fit(&c[2])],
    };
    CurvePart { scale, max_points, channels }
}

/// [`convert`] reusing `cache` when its scale and point budget still apply (and
/// refilling it when not). `opts` must have passed [`check_options`].
pub(crate) fn convert_with(
    params: &Params,
    device: &Mat3,
    opts: &Options,
    cache: &mut Option<CurvePart>,
) -> Result<Camera2Values, ConvertError> {
    check_matrix("device_ccm", device, ccm::CCM_LIMIT)?;
    let composed = ccm::mul(&params.ccm, device);
    // Leave room for the rounding: coarse denominators (say 1/2) could otherwise round an
    // in-range entry out of Camera2's range.
    let scale = range_scale_within(&composed, rational_error_bound(opts.rational));
    let wanted = ccm::scale(&composed, 1.0 / scale);

    let mut cst = [0i32; 18];
    let mut matrix_err: f64 = 0.0;
    let mut sent = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let x = wanted[i][j];
            let r: Rational = match opts.rational {
                RationalMode::Best { max_denominator } => rational::best(x, max_denominator as u64),
                RationalMode::Fixed { denominator } => rational::fixed(x, denominator as u64),
            }
            .map_err(|source| ConvertError::Rational { row: i, col: j, source })?;
            cst[2 * (3 * i + j)] = r.num;
            cst[2 * (3 * i + j) + 1] = r.den;
            sent[i][j] = r.to_f64();
            matrix_err = matrix_err.max((sent[i][j] - x).abs());
        }
    }

    let curve = match cache {
        Some(c) if c.scale == scale && c.max_points == opts.max_curve_points => c,
        _ => cache.insert(curve_part(params, scale, opts.max_curve_points)),
    };
    let [red, green, blue] = &curve.channels;
    let max_abs = curve.channels.each_ref().map(|c| c.max_abs);
    let lipschitz = curve.channels.each_ref().map(|c| c.lipschitz);
    Ok(Camera2Values {
        color_correction_transform: cst,
        tonemap_curve: TonemapCurve { red: red.pairs.clone(), green: green.pairs.clone(), blue: blue.pairs.clone() },
        scale,
        composed,
        report: ErrorReport {
            matrix_max_abs: matrix_err,
            curve_max_abs: max_abs.into_iter().fold(0.0, f64::max),
            curve_points: curve.channels.iter().map(|c| c.pairs.len() / 2).max().unwrap_or(0),
            curve_simplified: curve.channels.iter().any(|c| c.simplified),
            curve_lipschitz: lipschitz.into_iter().fold(0.0, f64::max),
            channel_max_abs: max_abs,
            channel_lipschitz: lipschitz,
            // The device applying exactly what it received, over sensor RGB in [0, 1]^3.
            bound: error_bound(max_abs, lipschitz, &sent, &wanted, [1.0; 3]),
        },
    })
}

/// Flat f32 (Pin, Pout) pairs; a knot whose Pin rounds onto the previous one is dropped
/// (its cost shows up in the measured curve error).
fn to_f32_pairs(c: &ToneCurve) -> Vec<f32> {
    let mut out: Vec<f32> = Vec::with_capacity(2 * c.len());
    let n = c.len();
    for (i, (&x, &y)) in c.x().iter().zip(c.y()).enumerate() {
        let (xf, yf) = (x as f32, y as f32);
        if let Some(&prev) = out.get(out.len().wrapping_sub(2)) {
            if xf <= prev {
                if i == n - 1 {
                    // Keep the end point at 1: replace the previous knot.
                    out.truncate(out.len() - 2);
                } else {
                    continue;
                }
            }
        }
        out.push(xf);
        out.push(yf);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(ccm: Mat3, y: Vec<f64>) -> Params {
        Params::new(ccm, ToneCurve::uniform(y).unwrap(), 2.2).unwrap()
    }

    #[test]
    fn identity_maps_to_unit_rationals_and_the_curve_itself() {
        let p = params(ccm::IDENTITY, vec![0.0, 0.25, 1.0]);
        let v = convert(&p, &ccm::IDENTITY, &Options::default()).unwrap();
        assert_eq!(v.color_correction_transform, [1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1]);
        assert_eq!(v.tonemap_curve.red, vec![0.0, 0.0, 0.5, 0.25, 1.0, 1.0]);
        assert_eq!(v.tonemap_curve.red, v.tonemap_curve.blue);
        assert_eq!(v.scale, 1.0);
        assert_eq!(v.report.bound, 0.0);
    }

    #[test]
    fn composes_ccm_after_device_matrix() {
        let ccm_opt = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let dev = [[1.5, -0.25, -0.25], [-0.125, 1.25, -0.125], [0.0, -0.5, 1.5]];
        let v = convert(&params(ccm_opt, vec![0.0, 1.0]), &dev, &Options::default()).unwrap();
        // Rows of dev swapped: CCM_opt · M_dev.
        assert_eq!(v.matrix(), [[-0.125, 1.25, -0.125], [1.5, -0.25, -0.25], [0.0, -0.5, 1.5]]);
    }

    #[test]
    fn out_of_range_matrix_is_scaled_and_folded() {
        let p = params([[4.5, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -2.0]], vec![0.0, 0.7, 0.2, 1.0]);
        let v = convert(&p, &ccm::IDENTITY, &Options::default()).unwrap();
        // 4.5 / 3 = 1.5, with room for half a unit of the 2^16 denominator.
        let s = 4.5 / (3.0 - 0.5 / 65536.0);
        assert_eq!(v.scale, s);
        let (lo, hi) = ccm::min_max(&v.matrix());
        assert!(lo >= MATRIX_RANGE.0 && hi <= MATRIX_RANGE.1);
        // Pin of each knot divided by s, then a flat tail to (1, 1).
        let x: Vec<f32> = v.tonemap_curve.red.iter().step_by(2).copied().collect();
        assert_eq!(x, vec![0.0, (1.0f64 / 3.0 / s) as f32, (2.0f64 / 3.0 / s) as f32, (1.0f64 / s) as f32, 1.0]);
    }

    #[test]
    fn fixed_denominator_mode() {
        let p = params([[0.3, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], vec![0.0, 1.0]);
        let o = Options { rational: RationalMode::Fixed { denominator: 1024 }, ..Options::default() };
        let v = convert(&p, &ccm::IDENTITY, &o).unwrap();
        assert_eq!(&v.color_correction_transform[..2], &[307, 1024]);
        assert!((v.report.matrix_max_abs - (0.3 - 307.0 / 1024.0f64).abs()).abs() < 1e-15);
    }

    #[test]
    fn too_many_knots_are_simplified_with_reported_error() {
        let p = Params::new(ccm::IDENTITY, ToneCurve::from_fn(100, |t| (9.0 * t).sin() * 0.5 + 0.5), 2.2).unwrap();
        let v = convert(&p, &ccm::IDENTITY, &Options { max_curve_points: 16, ..Options::default() }).unwrap();
        assert_eq!(v.report.curve_points, 16);
        assert!(v.report.curve_simplified);
        let exact = p.tone_curves.max_abs_diff(&v.curves());
        assert!((exact - v.report.curve_max_abs).abs() < 1e-12 && exact > 0.0);
    }

    #[test]
    fn bad_inputs_are_named() {
        let p = params(ccm::IDENTITY, vec![0.0, 1.0]);
        let mut dev = ccm::IDENTITY;
        dev[1][2] = f64::NAN;
        let e = convert(&p, &dev, &Options::default()).unwrap_err();
        assert!(e.to_string().contains("device_ccm[1][2]"), "{e}");
        let e = convert(&p, &ccm::IDENTITY, &Options { max_curve_points: 1, ..Options::default() }).unwrap_err();
        assert!(e.to_string().contains("max_curve_points"));
        assert!(matrix_from_rationals(&[1, 0, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1]).is_err());
    }
}
