//! Read-back: how far what a device reports in its `CaptureResult` is from what was
//! requested, and how far that moves the output (the check a fail-closed app makes on
//! every frame).

use super::{curve_from_pairs, matrix_from_rationals};
use crate::ccm;
use crate::emulate::error_bound;
use crate::error::ValidationError;

/// How far what a device reports in its `CaptureResult` is from what was requested.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Readback {
    /// Largest |reported - requested| over the nine matrix entries.
    pub matrix_max_abs: f64,
    /// Exact max |reported curve - requested curve| over [0, 1].
    pub curve_max_abs: f64,
    /// Bound on how far the device's output moves because of both (output units), for
    /// sensor RGB in [0, 1]^3: [`crate::emulate::error_bound`] with the reported curve's slope.
    pub bound: f64,
}

/// Compares a request's `COLOR_CORRECTION_TRANSFORM` and `TONEMAP_CURVE` (one channel,
/// flat pairs) with those the `CaptureResult` reports.
pub fn readback(
    requested_cst: &[i32; 18],
    requested_curve: &[f32],
    reported_cst: &[i32; 18],
    reported_curve: &[f32],
) -> Result<Readback, ValidationError> {
    let requested = |e: ValidationError| e.within("requested");
    let reported = |e: ValidationError| e.within("reported");
    let want = matrix_from_rationals(requested_cst).map_err(requested)?;
    let got = matrix_from_rationals(reported_cst).map_err(reported)?;
    let want_c = curve_from_pairs(requested_curve).map_err(requested)?;
    let got_c = curve_from_pairs(reported_curve).map_err(reported)?;
    let curve_max_abs = got_c.max_abs_diff(&want_c);
    Ok(Readback {
        matrix_max_abs: ccm::max_abs_diff(&got, &want),
        curve_max_abs,
        bound: error_bound(curve_max_abs, got_c.max_slope(), &got, &want, [1.0; 3]),
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
        let r = readback(&id, &line, &got, &bent).unwrap();
        assert!((r.matrix_max_abs - 1.0 / 1024.0).abs() < 1e-15);
        assert!((r.curve_max_abs - 0.05).abs() < 1e-7);
        // Row 0 moves by 2/1024 in total.
        assert!((r.bound - (r.curve_max_abs + 1.1 * 2.0 / 1024.0)).abs() < 1e-7, "{r:?}");
        let mut bad = id;
        bad[3] = 0;
        assert!(readback(&id, &line, &bad, &line).unwrap_err().to_string().contains("reported"));
    }
}
