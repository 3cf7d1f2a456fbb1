//! Colour-temperature (CT) dependent colour matrices.
//!
//! Two schemes exist in real cameras:
//! - ISPs such as Rockchip's and libcamera's hold calibrated CCMs at several CTs and
//!   interpolate linearly in CT between the two nearest (paper appendix), clamping at
//!   the ends: [`interpolate`].
//! - Android (and DNG) describe a sensor by two illuminants and interpolate their
//!   matrices linearly in *inverse* CT (mired), clamped at the ends: [`interpolate_dng`].
//!
//! Deploying CamPro on either: the device matrix `M(ct)` becomes `CCM_opt · M(ct)`.
//! Because both interpolations are linear in the matrices, replacing every calibrated
//! matrix by `CCM_opt · M_i` ([`compose_calibration`]) and composing at run time give
//! the same matrix (up to float rounding, tested).

use crate::ccm::{self, Mat3};
use crate::error::{check_matrix, check_range, ValidationError};

/// Accepted calibration colour temperatures, kelvin.
pub const CT_RANGE: (f64, f64) = (1000.0, 40000.0);

/// One calibrated CCM: sensor RGB -> linear sRGB at colour temperature `ct_kelvin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CtCcm {
    /// Correlated colour temperature, kelvin.
    pub ct_kelvin: f64,
    /// The calibrated matrix at that temperature (`out = ccm · in`).
    pub ccm: Mat3,
}

/// Rules: CTs finite, in [`CT_RANGE`], strictly increasing; matrices finite
/// and inside ±[`ccm::CCM_LIMIT`]. An empty list is valid (no calibration).
pub fn validate_calibration(cal: &[CtCcm]) -> Result<(), ValidationError> {
    let (lo, hi) = CT_RANGE;
    for (i, c) in cal.iter().enumerate() {
        check_range(|| format!("[{i}].ct_kelvin"), c.ct_kelvin, lo, hi)?;
        check_matrix(&format!("[{i}].ccm"), &c.ccm, ccm::CCM_LIMIT)?;
        if i > 0 && c.ct_kelvin <= cal[i - 1].ct_kelvin {
            return Err(ValidationError::NotIncreasing {
                field: "[].ct_kelvin".into(),
                index: i,
                prev: cal[i - 1].ct_kelvin,
                value: c.ct_kelvin,
            });
        }
    }
    Ok(())
}

/// The matrix at `ct` by linear interpolation in CT between the two nearest calibrated
/// matrices, clamped to the first/last outside their range (paper appendix).
/// `cal` must be validated and non-empty; a non-finite `ct` is an error.
pub fn interpolate(cal: &[CtCcm], ct: f64) -> Result<Mat3, ValidationError> {
    if !ct.is_finite() {
        return Err(ValidationError::NonFinite { field: "ct_kelvin".into(), value: ct });
    }
    let (first, last) = match (cal.first(), cal.last()) {
        (Some(f), Some(l)) => (f, l),
        _ => {
            return Err(ValidationError::WrongLength {
                field: "ct_calibration".into(),
                expected: "at least 1".into(),
                got: 0,
            })
        }
    };
    if ct <= first.ct_kelvin {
        return Ok(first.ccm);
    }
    if ct >= last.ct_kelvin {
        return Ok(last.ccm);
    }
    let i = cal.partition_point(|c| c.ct_kelvin <= ct) - 1;
    let (a, b) = (&cal[i], &cal[i + 1]);
    let t = (ct - a.ct_kelvin) / (b.ct_kelvin - a.ct_kelvin);
    Ok(ccm::lerp(&a.ccm, &b.ccm, t))
}

/// Every calibrated matrix composed with CamPro's: `M_i -> ccm_opt · M_i`.
pub fn compose_calibration(cal: &[CtCcm], ccm_opt: &Mat3) -> Vec<CtCcm> {
    cal.iter().map(|c| CtCcm { ct_kelvin: c.ct_kelvin, ccm: ccm::mul(ccm_opt, &c.ccm) }).collect()
}

/// DNG / Android two-illuminant interpolation: weight `g = (1/ct - 1/ct2) / (1/ct1 - 1/ct2)`
/// clamped to [0, 1], result `g · m1 + (1 - g) · m2`. `ct1 != ct2`, both positive.
pub fn interpolate_dng(ct: f64, (ct1, m1): (f64, &Mat3), (ct2, m2): (f64, &Mat3)) -> Result<Mat3, ValidationError> {
    check_range(|| "ct_kelvin".into(), ct, 1.0, 1e6)?;
    check_range(|| "illuminant1_ct".into(), ct1, 1.0, 1e6)?;
    check_range(|| "illuminant2_ct".into(), ct2, 1.0, 1e6)?;
    if ct1 == ct2 {
        return Ok(*m1);
    }
    let g = ((1.0 / ct - 1.0 / ct2) / (1.0 / ct1 - 1.0 / ct2)).clamp(0.0, 1.0);
    Ok(ccm::lerp(m2, m1, g))
}

/// Colour temperature of an Android `SENSOR_REFERENCE_ILLUMINANT1/2` value (the EXIF
/// LightSource codes), as the DNG SDK assigns them; `None` for unknown codes.
pub fn illuminant_ct(code: u8) -> Option<f64> {
    Some(match code {
        17 | 3 => 2850.0,              // STANDARD_A, TUNGSTEN
        24 => 3200.0,                  // ISO_STUDIO_TUNGSTEN
        23 => 5000.0,                  // D50
        20 | 1 | 9 | 4 | 18 => 5500.0, // D55, DAYLIGHT, FINE_WEATHER, FLASH, STANDARD_B
        21 | 19 | 10 => 6500.0,        // D65, STANDARD_C, CLOUDY_WEATHER
        22 | 11 => 7500.0,             // D75, SHADE
        12 => 6400.0,                  // DAYLIGHT_FLUORESCENT (5700-7100 K)
        13 => 5050.0,                  // DAY_WHITE_FLUORESCENT (4600-5500 K)
        14 | 2 => 4150.0,              // COOL_WHITE_FLUORESCENT, FLUORESCENT (3800-4500 K)
        15 => 3525.0,                  // WHITE_FLUORESCENT (3250-3800 K)
        16 => 2925.0,                  // WARM_WHITE_FLUORESCENT (2600-3250 K)
        _ => return None,
    })
}

/// CIE XYZ (D50, the DNG/Android profile connection space) -> linear sRGB (D65),
/// with Bradford chromatic adaptation (Lindbloom's table).
pub const XYZ_D50_TO_SRGB: Mat3 =
    [[3.1338561, -1.6168667, -0.4906146], [-0.9787684, 1.9161415, 0.0334540], [0.0719453, -0.2289914, 1.4052427]];

/// An Android device's two-illuminant calibration: `SENSOR_REFERENCE_ILLUMINANT1/2`
/// and `SENSOR_FORWARD_MATRIX1/2` (white-balanced sensor RGB -> XYZ D50).
#[derive(Debug, Clone, PartialEq)]
pub struct DngCalibration {
    /// `SENSOR_REFERENCE_ILLUMINANT1` (an EXIF LightSource code, e.g. 17 = Standard A).
    pub illuminant1: u8,
    /// `SENSOR_FORWARD_MATRIX1`: white-balanced sensor RGB to XYZ D50 under illuminant 1.
    pub forward_matrix1: Mat3,
    /// `SENSOR_REFERENCE_ILLUMINANT2` (e.g. 21 = D65).
    pub illuminant2: u8,
    /// `SENSOR_FORWARD_MATRIX2`: the same under illuminant 2.
    pub forward_matrix2: Mat3,
}

impl DngCalibration {
    /// Checks both illuminant codes are known and both matrices finite.
    pub fn validate(&self) -> Result<(f64, f64), ValidationError> {
        let ct = |field: &str, code: u8| {
            illuminant_ct(code).ok_or_else(|| ValidationError::Rule {
                field: field.into(),
                rule: format!("unknown reference illuminant code {code}"),
            })
        };
        let ct1 = ct("illuminant1", self.illuminant1)?;
        let ct2 = ct("illuminant2", self.illuminant2)?;
        check_matrix("forward_matrix1", &self.forward_matrix1, ccm::CCM_LIMIT)?;
        check_matrix("forward_matrix2", &self.forward_matrix2, ccm::CCM_LIMIT)?;
        Ok((ct1, ct2))
    }

    /// The device's sensor -> linear sRGB transform at `ct`: the forward matrices
    /// interpolated in inverse CT, followed by XYZ(D50) -> sRGB.
    pub fn device_transform(&self, ct: f64) -> Result<Mat3, ValidationError> {
        let (ct1, ct2) = self.validate()?;
        let fm = interpolate_dng(ct, (ct1, &self.forward_matrix1), (ct2, &self.forward_matrix2))?;
        Ok(ccm::mul(&XYZ_D50_TO_SRGB, &fm))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diag(v: f64) -> Mat3 {
        ccm::scale(&ccm::IDENTITY, v)
    }

    #[test]
    fn linear_in_ct_and_clamped() {
        let cal = [
            CtCcm { ct_kelvin: 2000.0, ccm: diag(1.0) },
            CtCcm { ct_kelvin: 4000.0, ccm: diag(2.0) },
            CtCcm { ct_kelvin: 6000.0, ccm: diag(4.0) },
        ];
        assert_eq!(interpolate(&cal, 3000.0).unwrap(), diag(1.5));
        assert_eq!(interpolate(&cal, 5500.0).unwrap(), diag(3.5));
        assert_eq!(interpolate(&cal, 4000.0).unwrap(), diag(2.0));
        assert_eq!(interpolate(&cal, 100.0).unwrap(), diag(1.0));
        assert_eq!(interpolate(&cal, 9e9).unwrap(), diag(4.0));
        assert!(interpolate(&cal, f64::NAN).is_err());
        assert!(interpolate(&[], 5000.0).is_err());
    }

    #[test]
    fn dng_weights_in_inverse_ct() {
        // Halfway in mired between 2850 K and 6500 K: 1/ct = (1/2850 + 1/6500)/2.
        let ct = 2.0 / (1.0 / 2850.0 + 1.0 / 6500.0);
        let m = interpolate_dng(ct, (2850.0, &diag(1.0)), (6500.0, &diag(3.0))).unwrap();
        assert!(ccm::max_abs_diff(&m, &diag(2.0)) < 1e-12);
        // Clamped beyond both ends.
        assert_eq!(interpolate_dng(2000.0, (2850.0, &diag(1.0)), (6500.0, &diag(3.0))).unwrap(), diag(1.0));
        assert_eq!(interpolate_dng(9000.0, (2850.0, &diag(1.0)), (6500.0, &diag(3.0))).unwrap(), diag(3.0));
    }

    #[test]
    fn xyz_d50_white_maps_to_srgb_white() {
        let w = ccm::apply(&XYZ_D50_TO_SRGB, [0.96422, 1.0, 0.82521]);
        for c in w {
            assert!((c - 1.0).abs() < 2e-4, "{w:?}");
        }
    }

    #[test]
    fn calibration_rules() {
        let ok = CtCcm { ct_kelvin: 3000.0, ccm: diag(1.0) };
        let dup = CtCcm { ct_kelvin: 3000.0, ccm: diag(1.0) };
        assert!(matches!(validate_calibration(&[ok, dup]), Err(ValidationError::NotIncreasing { .. })));
        let bad = CtCcm { ct_kelvin: 3000.0, ccm: [[f64::INFINITY, 0.0, 0.0], [0.0; 3], [0.0; 3]] };
        assert_eq!(validate_calibration(&[bad]).unwrap_err().field(), "[0].ccm[0][0]");
        assert!(validate_calibration(&[CtCcm { ct_kelvin: 50.0, ccm: diag(1.0) }]).is_err());
    }
}
