//! Wire formats: the values as JSON (what `campro convert` prints and the JNI bridge
//! hands over), as Kotlin statements, and the device transform read from a saved
//! capture result.

use super::{matrix_from_rationals, Camera2Values};
use crate::ccm::Mat3;
use crate::error::{check_matrix, ValidationError};

impl Camera2Values {
    /// One JSON object: `colorCorrectionTransform` (18 integers), `tonemapCurve`
    /// (`red`, `green`, `blue` flat pair arrays), the request modes, and the report.
    pub fn to_json(&self) -> serde_json::Value {
        let r = &self.report;
        serde_json::json!({
            "target": "camera2",
            "colorCorrectionMode": "TRANSFORM_MATRIX",
            "tonemapMode": "CONTRAST_CURVE",
            "colorCorrectionTransform": self.color_correction_transform.to_vec(),
            "tonemapCurve": {
                "red": self.tonemap_curve.red,
                "green": self.tonemap_curve.green,
                "blue": self.tonemap_curve.blue,
            },
            "scale": self.scale,
            "composedMatrix": self.composed,
            "error": {
                "matrixMaxAbs": r.matrix_max_abs,
                "curveMaxAbs": r.curve_max_abs,
                "curvePoints": r.curve_points,
                "curveSimplified": r.curve_simplified,
                "curveLipschitz": r.curve_lipschitz,
                "bound": r.bound,
                "boundLsb8": r.bound_lsb(),
            }
        })
    }

    /// Kotlin statements setting these values on a `CaptureRequest.Builder` named `builder`.
    /// `gains` are the device's white-balance gains (R, G_even, G_odd, B) metered with the
    /// device transform; AWB is off while CamPro's transform is used, so the request must
    /// carry them. Unknown, the statement copies them from a `CaptureResult` named
    /// `meteringResult` (an AWB-converged result).
    pub fn to_kotlin(&self, gains: Option<[f32; 4]>) -> String {
        let ints = self.color_correction_transform.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", ");
        let floats = |v: &[f32]| v.iter().map(|f| format!("{f:?}f")).collect::<Vec<_>>().join(", ");
        let t = &self.tonemap_curve;
        // One array for a shared curve, as before; three for a curve per channel.
        let (curves, curve_args) = if t.red == t.green && t.green == t.blue {
            (format!("val campro = floatArrayOf({})\n", floats(&t.red)), "campro, campro, campro")
        } else {
            let arrays = format!(
                "val red = floatArrayOf({})\nval green = floatArrayOf({})\nval blue = floatArrayOf({})\n",
                floats(&t.red),
                floats(&t.green),
                floats(&t.blue)
            );
            (arrays, "red, green, blue")
        };
        let gains = match gains {
            Some(g) => format!(
                "// The device's white balance (R, G_even, G_odd, B), metered with the device transform.\n\
                 builder.set(CaptureRequest.COLOR_CORRECTION_GAINS, RggbChannelVector({}))\n",
                floats(&g)
            ),
            None => "// The device's white balance from an AWB-converged result (campro applies it unchanged;\n\
                     // campro convert --capture-result or --device-gains prints its values here).\n\
                     builder.set(CaptureRequest.COLOR_CORRECTION_GAINS, meteringResult.get(CaptureResult.COLOR_CORRECTION_GAINS))\n"
                .to_string(),
        };
        format!(
            "// CamPro via Camera2 (scale {scale}, bound {bound:.3} LSB). COLOR_CORRECTION_MODE is\n\
             // only honoured with CONTROL_AWB_MODE_OFF, which also needs COLOR_CORRECTION_GAINS.\n\
             {curves}\
             builder.set(CaptureRequest.CONTROL_AWB_MODE, CaptureRequest.CONTROL_AWB_MODE_OFF)\n\
             {gains}\
             builder.set(CaptureRequest.COLOR_CORRECTION_MODE, CaptureRequest.COLOR_CORRECTION_MODE_TRANSFORM_MATRIX)\n\
             builder.set(CaptureRequest.COLOR_CORRECTION_TRANSFORM, ColorSpaceTransform(intArrayOf({ints})))\n\
             builder.set(CaptureRequest.TONEMAP_MODE, CaptureRequest.TONEMAP_MODE_CONTRAST_CURVE)\n\
             builder.set(CaptureRequest.TONEMAP_CURVE, TonemapCurve({curve_args}))\n",
            scale = self.scale,
            bound = self.report.bound_lsb(),
        )
    }
}

/// The device transform from a saved capture result: a JSON object whose
/// `colorCorrectionTransform` (or `android.colorCorrection.transform`) is 18 integers
/// (numerator/denominator pairs), 9 numbers, or 3 rows of 3.
pub fn device_transform_from_capture_result(text: &str) -> Result<Mat3, ValidationError> {
    let v: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| ValidationError::Rule { field: "<capture result>".into(), rule: format!("not JSON: {e}") })?;
    let (key, t) = ["colorCorrectionTransform", "android.colorCorrection.transform"]
        .iter()
        .find_map(|k| v.get(*k).map(|t| (*k, t)))
        .ok_or_else(|| ValidationError::Rule {
            field: "colorCorrectionTransform".into(),
            rule: "missing from the capture result".into(),
        })?;
    let flat: Vec<&serde_json::Value> = match t.as_array() {
        Some(a) if a.len() == 3 && a.iter().all(|r| r.is_array()) => {
            a.iter().flat_map(|r| r.as_array().unwrap().iter()).collect()
        }
        Some(a) => a.iter().collect(),
        None => return Err(ValidationError::Rule { field: key.into(), rule: "must be an array".into() }),
    };
    let num = |i: usize| {
        flat[i]
            .as_f64()
            .ok_or_else(|| ValidationError::Rule { field: format!("{key}[{i}]"), rule: "must be a number".into() })
    };
    match flat.len() {
        18 => {
            let mut ints = [0i32; 18];
            for (i, slot) in ints.iter_mut().enumerate() {
                *slot = flat[i].as_i64().and_then(|v| i32::try_from(v).ok()).ok_or_else(|| ValidationError::Rule {
                    field: format!("{key}[{i}]"),
                    rule: "must be a 32-bit integer".into(),
                })?;
            }
            matrix_from_rationals(&ints).map_err(|e| ValidationError::Rule { field: key.into(), rule: e.to_string() })
        }
        9 => {
            let mut m = [[0.0; 3]; 3];
            for i in 0..9 {
                m[i / 3][i % 3] = num(i)?;
            }
            check_matrix(key, &m, crate::ccm::CCM_LIMIT)?;
            Ok(m)
        }
        n => {
            Err(ValidationError::WrongLength { field: key.into(), expected: "18 integers or 9 numbers".into(), got: n })
        }
    }
}

/// Largest white-balance gain read (devices report about 1 to 8).
pub const MAX_GAIN: f64 = 64.0;

/// The white-balance gains of a saved capture result, when it has them:
/// `colorCorrectionGains` (or `android.colorCorrection.gains`), four finite numbers in
/// (0, [`MAX_GAIN`]]: R, G_even, G_odd, B.
pub fn gains_from_capture_result(text: &str) -> Result<Option<[f32; 4]>, ValidationError> {
    let v: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| ValidationError::Rule { field: "<capture result>".into(), rule: format!("not JSON: {e}") })?;
    let Some((key, g)) =
        ["colorCorrectionGains", "android.colorCorrection.gains"].iter().find_map(|k| v.get(*k).map(|g| (*k, g)))
    else {
        return Ok(None);
    };
    let a = g.as_array().ok_or_else(|| ValidationError::Rule { field: key.into(), rule: "must be an array".into() })?;
    if a.len() != 4 {
        return Err(ValidationError::WrongLength { field: key.into(), expected: "4".into(), got: a.len() });
    }
    let mut out = [0f32; 4];
    for (i, (slot, x)) in out.iter_mut().zip(a).enumerate() {
        *slot = gain(x.as_f64()).ok_or_else(|| ValidationError::Rule {
            field: format!("{key}[{i}]"),
            rule: format!("must be a number in (0, {MAX_GAIN}]"),
        })?;
    }
    Ok(Some(out))
}

/// A gain in (0, [`MAX_GAIN`]] as `f32`.
pub fn gain(x: Option<f64>) -> Option<f32> {
    x.filter(|g| g.is_finite() && *g > 0.0 && *g <= MAX_GAIN).map(|g| g as f32)
}

/// Reads back what [`Camera2Values::to_json`] wrote: the matrix the device receives (from
/// `colorCorrectionTransform`), its curves (`tonemapCurve.red`, `.green`, `.blue`) and the
/// range scale folded into the curves. Trailing content after the object is refused.
pub fn values_from_json(bytes: &[u8]) -> Result<(Mat3, crate::ToneCurves, f64), ValidationError> {
    let rule = |field: &str, rule: String| ValidationError::Rule { field: field.into(), rule };
    let v: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| rule("<camera2 values>", format!("not JSON: {e}")))?;
    let cst = v
        .get("colorCorrectionTransform")
        .and_then(|a| a.as_array())
        .filter(|a| a.len() == 18)
        .ok_or_else(|| rule("colorCorrectionTransform", "must be an array of 18 integers".into()))?;
    let mut ints = [0i32; 18];
    for (i, slot) in ints.iter_mut().enumerate() {
        *slot = cst[i]
            .as_i64()
            .and_then(|x| i32::try_from(x).ok())
            .ok_or_else(|| rule(&format!("colorCorrectionTransform[{i}]"), "must be a 32-bit integer".into()))?;
    }
    let curve = |channel: &str| {
        let field = format!("tonemapCurve.{channel}");
        let pairs = v
            .pointer(&format!("/tonemapCurve/{channel}"))
            .and_then(|a| a.as_array())
            .and_then(|a| a.iter().map(|x| x.as_f64().map(|f| f as f32)).collect::<Option<Vec<f32>>>())
            .ok_or_else(|| rule(&field, "must be an array of numbers".into()))?;
        super::curve_from_pairs_named(&pairs, &field)
    };
    let [red, green, blue] = crate::tone_curve::CHANNELS.map(curve);
    let curves = crate::ToneCurves::per_channel([red?, green?, blue?]);
    let scale = v.get("scale").and_then(|s| s.as_f64()).filter(|s| s.is_finite() && *s >= 1.0);
    let scale = scale.ok_or_else(|| rule("scale", "must be a finite number >= 1".into()))?;
    Ok((matrix_from_rationals(&ints)?, curves, scale))
}
