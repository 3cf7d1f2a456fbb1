//! Read-back: how far what a device reports in its `CaptureResult` is from what was
//! requested, and how far that moves the output (the check a fail-closed app makes on
//! every frame).

use super::{curve_from_pairs_named, matrix_from_rationals};
use crate::ccm;
use crate::emulate::error_bound;
use crate::error::ValidationError;
use crate::tone_curve::CHANNELS;

/// How far what a device reports in its `CaptureResult` is from what was requested.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Readback {
    /// Largest |reported - requested| over the nine matrix entries.
    pub matrix_max_abs: f64,
    /// Exact max |reported curve - requested curve| over [0, 1] and the three channels.
    pub curve_max_abs: f64,
    /// Bound on how far the device's output moves because of both (output units), for
    /// sensor RGB in [0, 1]^3: [`crate::emulate::error_bound`] with each channel's reported
    /// curve's slope.
    pub bound: f64,
}

/// Compares a request's `COLOR_CORRECTION_TRANSFORM` and `TONEMAP_CURVE` (red, green,
/// blue, each flat pairs) with those the `CaptureResult` reports: the worst of
/// [`readback_channel`] over the three channels.
pub fn readback(
    requested_cst: &[i32; 18],
    requested_curves: [&[f32]; 3],
    reported_cst: &[i32; 18],
    reported_curves: [&[f32]; 3],
) -> Result<Readback, ValidationError> {
    let mut worst = readback_channel(0, requested_cst, requested_curves[0], reported_cst, reported_curves[0])?;
    for c in 1..3 {
        let r = readback_channel(c, requested_cst, requested_curves[c], reported_cst, reported_curves[c])?;
        worst.curve_max_abs = worst.curve_max_abs.max(r.curve_max_abs);
        worst.bound = worst.bound.max(r.bound);
    }
    Ok(worst)
}

/// [`readback`] of one output channel `channel` (0 red, 1 green, 2 blue): its requested
/// and reported curves (flat pairs), and the bound on that channel's output (`E_c + L_c ·
/// Σ_j |ΔM_cj|`, [`crate::emulate::error_bound`] on row c).
pub fn readback_channel(
    channel: usize,
    requested_cst: &[i32; 18],
    requested_curve: &[f32],
    reported_cst: &[i32; 18],
    reported_curve: &[f32],
) -> Result<Readback, ValidationError> {
    let requested = |e: ValidationError| e.within("requested");
    let reported = |e: ValidationError| e.within("reported");
    let name = CHANNELS.get(channel).ok_or_else(|| ValidationError::Rule {
        field: "channel".into(),
        rule: format!("must be 0 (red), 1 (green) or 2 (blue), got {channel}"),
    })?;
    let want = matrix_from_rationals(requested_cst).map_err(requested)?;
    let got = matrix_from_rationals(reported_cst).map_err(reported)?;
    let field = format!("tonemapCurve.{name}");
    let want_c = curve_from_pairs_named(requested_curve, &field).map_err(requested)?;
    let got_c = curve_from_pairs_named(reported_curve, &field).map_err(reported)?;
    let curve_max_abs = got_c.max_abs_diff(&want_c);
    // Only this channel's curve is compared: the other channels' terms are 0.
    let (mut e, mut l) = ([0.0; 3], [0.0; 3]);
    (e[channel], l[channel]) = (curve_max_abs, got_c.max_slope());
    Ok(Readback {
        matrix_max_abs: ccm::max_abs_diff(&got, &want),
        curve_max_abs,
        bound: error_bound(e, l, &got, &want, [1.0; 3]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readback_by_hand() {
        let id = [1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1];
        let mut got = id;
        got[0] = 1023; // 1023/1024 instead of 1
        got[1] = 1024;
        got[2] = 1; // 1/1024 instead of 0
        got[3] = 1024;
        let line = [0.0, 0.0, 1.0, 1.0];
        // Reported curve: (0,0) (0.5,0.55) (1,1): 0.05 off at 0.5, slope 1.1.
        let bent = [0.0, 0.0, 0.5, 0.55, 1.0, 1.0];
        let r = readback(&id, [&line; 3], &got, [&line, &bent, &line]).unwrap();
        assert!((r.matrix_max_abs - 1.0 / 1024.0).abs() < 1e-15);
        assert!((r.curve_max_abs - 0.05).abs() < 1e-7);
        // Row 0 moves by 2/1024 in total through the straight red curve; green's row is
        // exact, so its bent curve adds only its own 0.05: max(2/1024, 0.05).
        assert!((r.bound - 0.05).abs() < 1e-7, "{r:?}");
        // The bent curve on red: 0.05 plus slope 1.1 times red's row error.
        let r = readback(&id, [&line; 3], &got, [&bent, &line, &line]).unwrap();
        assert!((r.bound - (0.05 + 1.1 * 2.0 / 1024.0)).abs() < 1e-7, "{r:?}");
        // Channel by channel: red carries its row's error through its bent curve, green
        // (an exact row, a straight curve) none.
        let red = readback_channel(0, &id, &line, &got, &bent).unwrap();
        assert!((red.bound - (0.05 + 1.1 * 2.0 / 1024.0)).abs() < 1e-7, "{red:?}");
        assert_eq!(readback_channel(1, &id, &line, &got, &line).unwrap().bound, 0.0);
        assert!(readback_channel(3, &id, &line, &got, &line).unwrap_err().to_string().contains("channel"));
        let e = readback(&id, [&line; 3], &id, [&line, &line, &[0.0, 0.0, 1.0]]).unwrap_err();
        assert!(e.to_string().contains("reported.tonemapCurve.blue"), "{e}");
        let mut bad = id;
        bad[3] = 0;
        assert!(readback(&id, [&line; 3], &bad, [&line; 3]).unwrap_err().to_string().contains("reported"));
    }
}
