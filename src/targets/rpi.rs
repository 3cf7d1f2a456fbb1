//! libcamera on Raspberry Pi: a patched tuning file (`rpi_vc4_*.json`, `rpi_pisp_*.json`).
//!
//! Export: every `rpi.ccm` entry becomes `CCM_opt · M(ct)` (the CT list is kept, and
//! must be strictly increasing), `rpi.contrast.gamma_curve` becomes the CamPro curve on
//! 0..65535 (its knots, rounded to integers) with `ce_enable: 0` so the adaptive contrast
//! enhancement leaves it alone. Everything else is untouched.
//!
//! What the ISP then does (the emulators):
//! - VC4: the curve is sampled at 33 fixed inputs (0..15360 step 1024, 16384..30720
//!   step 2048, 32768..61440 step 4096, 65535), truncated to integers, and the last point
//!   is forced to (65535, 65535): a curve with y(1) != 1 cannot be held there, and the
//!   error near white says how much that costs. CCM entries are held to 1/1000 in [-8, 8).
//! - PiSP: a 64-entry LUT at 0..15872 step 512, 16384..31744 step 1024, 32768..63488 step
//!   2048, values truncated, each slope (rise per segment) capped at 2^14 - 1, and the
//!   last entry flat to 65535. A decreasing curve is refused by libcamera ("Malformed PWL
//!   for Gamma, disabling!"), so gamma is then off: the emulator applies the identity and
//!   the error shows it. CCM entries are held with 10 fractional bits in [-8, 8).
//!
//! Between calibrated CTs libcamera interpolates the matrices linearly, which commutes
//! with the composition, so the check runs at each calibrated CT.

use super::target::{
    curve_from_points, shared_curve, Condition, CurveFormat, Feed, Format, MatrixBy, MatrixFormat, StageOrder, Target,
    TargetError,
};
use crate::ccm::{self, Mat3};
use crate::emulate::Isp;
use crate::params::Params;
use crate::tone_curve::ToneCurve;
use serde_json::Value;

/// Full scale of the tuning file's curve.
const FULL: f64 = 65535.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
/// A Raspberry Pi ISP.
pub enum Rpi {
    /// Pi 4 and earlier (VideoCore IV ISP).
    Vc4,
    /// Pi 5 (PiSP back end).
    Pisp,
}

impl Rpi {
    /// The hardware curve inputs, 0..65535.
    pub fn grid(self) -> Vec<f64> {
        match self {
            Rpi::Vc4 => (0..16)
                .map(|i| i as f64 * 1024.0)
                .chain((0..8).map(|i| 16384.0 + i as f64 * 2048.0))
                .chain((0..8).map(|i| 32768.0 + i as f64 * 4096.0))
                .chain([FULL])
                .collect(),
            Rpi::Pisp => (0..32)
                .map(|i| i as f64 * 512.0)
                .chain((0..16).map(|i| 16384.0 + i as f64 * 1024.0))
                .chain((0..16).map(|i| 32768.0 + i as f64 * 2048.0))
                .collect(),
        }
    }

    fn matrix_format(self) -> MatrixFormat {
        let step = match self {
            Rpi::Vc4 => 1e-3,
            Rpi::Pisp => 1.0 / 1024.0,
        };
        MatrixFormat { min: -8.0, max: 8.0 - step, step }
    }

    fn file(self) -> &'static str {
        match self {
            Rpi::Vc4 => "rpi-vc4 tuning file",
            Rpi::Pisp => "rpi-pisp tuning file",
        }
    }

    /// The curve the ISP applies given the tuning file's `gamma_curve`.
    pub fn hardware_curve(self, given: &ToneCurve) -> ToneCurve {
        let grid: Vec<f64> = self.grid().iter().map(|x| x / FULL).collect();
        // Integer truncation of the sampled values, as the IPA's int conversion does.
        let sample = |x: f64| (given.eval(x) * FULL).floor().clamp(0.0, FULL);
        match self {
            Rpi::Vc4 => {
                let mut y: Vec<f64> = grid.iter().map(|&x| sample(x) / FULL).collect();
                *y.last_mut().expect("33 points") = 1.0;
                ToneCurve::new(grid, y).expect("fixed grid")
            }
            Rpi::Pisp => {
                let mut ys: Vec<f64> = Vec::with_capacity(grid.len());
                for &x in &grid {
                    let mut y = sample(x);
                    if let Some(&last) = ys.last() {
                        if y < last {
                            // libcamera disables gamma: the ISP outputs its input.
                            return ToneCurve::identity(2);
                        }
                        y = y.min(last + 16383.0);
                    }
                    ys.push(y);
                }
                let last = *ys.last().expect("64 points");
                let mut x = grid;
                x.push(1.0);
                ys.push(last); // the last entry has no slope: flat to the end
                ToneCurve::new(x, ys.iter().map(|v| v / FULL).collect()).expect("fixed grid")
            }
        }
    }
}

/// The parts of a Raspberry Pi tuning file CamPro touches, read with one parser.
#[derive(Debug, Clone, PartialEq)]
pub struct Tuning {
    /// `(ct, ccm)` of `rpi.ccm`, CT strictly increasing.
    pub ccms: Vec<(f64, Mat3)>,
    /// `rpi.contrast.gamma_curve` as (x, y) points on 0..65535.
    pub gamma: Vec<(f64, f64)>,
    /// `rpi.contrast.ce_enable`.
    pub ce_enable: Option<i64>,
}

fn field(file: &str, f: &str, rule: impl Into<String>) -> TargetError {
    TargetError::Field { file: file.into(), field: f.into(), rule: rule.into() }
}

/// The algorithm block `name` of a parsed tuning file.
fn block<'a>(root: &'a mut Value, name: &str, file: &str) -> Result<&'a mut Value, TargetError> {
    let algs = root
        .get_mut("algorithms")
        .and_then(Value::as_array_mut)
        .ok_or_else(|| field(file, "algorithms", "must be an array of algorithm blocks"))?;
    algs.iter_mut().find_map(|a| a.get_mut(name)).ok_or_else(|| field(file, name, "block is missing"))
}

fn num(v: &Value, file: &str, f: &str) -> Result<f64, TargetError> {
    v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| field(file, f, format!("must be a finite number, got {v}")))
}

/// Parses a tuning file (any Raspberry Pi target) into [`Tuning`].
pub fn parse(text: &str, file: &str) -> Result<(Value, Tuning), TargetError> {
    let mut root: Value = serde_json::from_str(text).map_err(|e| TargetError::Parse {
        file: file.into(),
        format: "JSON",
        message: e.to_string(),
    })?;
    let ccm_block = block(&mut root, "rpi.ccm", file)?;
    let list = ccm_block
        .get("ccms")
        .and_then(Value::as_array)
        .ok_or_else(|| field(file, "rpi.ccm.ccms", "must be an array"))?;
    let mut ccms = Vec::with_capacity(list.len());
    for (i, e) in list.iter().enumerate() {
        let f = format!("rpi.ccm.ccms[{i}]");
        let ct = num(e.get("ct").unwrap_or(&Value::Null), file, &format!("{f}.ct"))?;
        let m = e
            .get("ccm")
            .and_then(Value::as_array)
            .filter(|a| a.len() == 9)
            .ok_or_else(|| field(file, &format!("{f}.ccm"), "must be 9 numbers (row-major 3x3)"))?;
        let v: Vec<f64> =
            m.iter().enumerate().map(|(j, x)| num(x, file, &format!("{f}.ccm[{j}]"))).collect::<Result<_, _>>()?;
        if let Some(&(prev, _)) = ccms.last() {
            if ct <= prev {
                return Err(field(
                    file,
                    &format!("{f}.ct"),
                    format!("must be strictly increasing ({ct} follows {prev})"),
                ));
            }
        }
        ccms.push((ct, [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]));
    }
    if ccms.is_empty() {
        return Err(field(file, "rpi.ccm.ccms", "must not be empty"));
    }
    let contrast = block(&mut root, "rpi.contrast", file)?;
    let g = contrast
        .get("gamma_curve")
        .and_then(Value::as_array)
        .ok_or_else(|| field(file, "rpi.contrast.gamma_curve", "must be an array"))?;
    if g.len() < 4 || g.len() % 2 != 0 {
        return Err(field(
            file,
            "rpi.contrast.gamma_curve",
            format!("must hold (x, y) pairs, at least two; got {} numbers", g.len()),
        ));
    }
    let mut gamma = Vec::with_capacity(g.len() / 2);
    for (i, pair) in g.chunks(2).enumerate() {
        let f = format!("rpi.contrast.gamma_curve[{}]", 2 * i);
        let (x, y) = (num(&pair[0], file, &f)?, num(&pair[1], file, &f)?);
        if !(0.0..=FULL).contains(&x) || !(0.0..=FULL).contains(&y) {
            return Err(field(file, &f, "points must lie in 0..=65535"));
        }
        if let Some(&(px, _)) = gamma.last() {
            if x <= px {
                return Err(field(file, &f, format!("x must be strictly increasing ({x} follows {px})")));
            }
        }
        gamma.push((x, y));
    }
    let ce_enable = contrast.get("ce_enable").and_then(Value::as_i64);
    Ok((root, Tuning { ccms, gamma, ce_enable }))
}

impl Target for Rpi {
    fn name(&self) -> &'static str {
        match self {
            Rpi::Vc4 => "rpi-vc4",
            Rpi::Pisp => "rpi-pisp",
        }
    }

    fn format(&self) -> Format {
        Format {
            matrix: Some(self.matrix_format()),
            curve: CurveFormat {
                grid: self.grid().iter().map(|x| x / FULL).collect(),
                y_step: 1.0 / FULL,
                monotonic: *self == Rpi::Pisp,
            },
            matrix_by: MatrixBy::CtInterpolated,
            order: StageOrder::MatrixClipCurve { clip_bits: Some(16) },
        }
    }

    fn export(&self, params: &Params, base: Option<&str>) -> Result<Vec<u8>, TargetError> {
        self.export_with(params, base, false).map(|(bytes, _)| bytes)
    }

    fn export_clamped(&self, params: &Params, base: Option<&str>) -> Result<(Vec<u8>, Vec<String>), TargetError> {
        self.export_with(params, base, true)
    }

    fn emulate(&self, _params: &Params, exported: &[u8], base: Option<&str>) -> Result<Vec<Condition>, TargetError> {
        self.emulate_file(exported, base)
    }
}

impl Rpi {
    /// The `target` a tuning file for this ISP names.
    fn tuning_target(self) -> &'static str {
        match self {
            Rpi::Vc4 => "bcm2835",
            Rpi::Pisp => "pisp",
        }
    }

    /// The export; matrix entries outside the ISP's range are refused, or clamped (and
    /// listed) with `clamp`.
    fn export_with(
        &self,
        params: &Params,
        base: Option<&str>,
        clamp: bool,
    ) -> Result<(Vec<u8>, Vec<String>), TargetError> {
        let base = base.ok_or(TargetError::NeedsBase { target: self.name() })?;
        let (mut root, tuning) = parse(base, self.file())?;
        match root.get("target").and_then(Value::as_str) {
            Some(t) if t != self.tuning_target() => {
                return Err(field(
                    "base",
                    "target",
                    format!("is \"{t}\": --target {} needs a \"{}\" tuning file", self.name(), self.tuning_target()),
                ))
            }
            _ => {}
        }
        let fmt = self.matrix_format();
        let mut clamped = Vec::new();
        let mut composed: Vec<Value> = Vec::with_capacity(tuning.ccms.len());
        for (i, (ct, m)) in tuning.ccms.iter().enumerate() {
            let mut c: Vec<f64> = ccm::mul(&params.ccm, m).iter().flatten().copied().collect();
            for (k, v) in c.iter_mut().enumerate() {
                if !(fmt.min..=fmt.max).contains(v) {
                    let f = format!("rpi.ccm.ccms[{i}].ccm[{k}]");
                    let rule = format!("{v:.4} is outside the ISP's range [{}, {}]", fmt.min, fmt.max);
                    if !clamp {
                        return Err(field(
                            "exported",
                            &f,
                            format!("{rule} (--clamp clamps it; compare then shows the error)"),
                        ));
                    }
                    clamped.push(format!("{f}: {rule}, clamped"));
                    *v = v.clamp(fmt.min, fmt.max);
                }
            }
            composed.push(serde_json::json!({ "ct": ct, "ccm": c }));
        }
        block(&mut root, "rpi.ccm", self.file())?["ccms"] = Value::Array(composed);
        let c = shared_curve(self.name(), params)?;
        let mut points: Vec<Value> = Vec::with_capacity(2 * c.len());
        let mut last_x = -1.0;
        for (&x, &y) in c.x().iter().zip(c.y()) {
            let xi = (x * FULL).round();
            if xi <= last_x {
                return Err(TargetError::Unsupported {
                    target: self.name(),
                    why: format!("two knots fall on the same 16-bit input {xi}"),
                });
            }
            last_x = xi;
            points.push(serde_json::json!(xi as u32));
            points.push(serde_json::json!((y * FULL).round() as u32));
        }
        let contrast = block(&mut root, "rpi.contrast", self.file())?;
        contrast["gamma_curve"] = Value::Array(points);
        contrast["ce_enable"] = serde_json::json!(0);
        let mut text = serde_json::to_string_pretty(&root).map_err(|e| TargetError::Parse {
            file: self.file().into(),
            format: "JSON",
            message: e.to_string(),
        })?;
        text.push('\n');
        Ok((text.into_bytes(), clamped))
    }

    fn emulate_file(&self, exported: &[u8], base: Option<&str>) -> Result<Vec<Condition>, TargetError> {
        let text = std::str::from_utf8(exported).map_err(|e| TargetError::Parse {
            file: "export".into(),
            format: "UTF-8",
            message: e.to_string(),
        })?;
        let (_, ours) = parse(text, "export")?;
        let base = base.ok_or(TargetError::NeedsBase { target: self.name() })?;
        let (_, theirs) = parse(base, self.file())?;
        if ours.ccms.len() != theirs.ccms.len() || ours.ccms.iter().zip(&theirs.ccms).any(|(a, b)| a.0 != b.0) {
            return Err(field("export", "rpi.ccm.ccms", "CT list differs from the base tuning file's"));
        }
        let given = curve_from_points(&ours.gamma, FULL, "rpi.contrast.gamma_curve")?;
        if ours.ce_enable.unwrap_or(1) != 0 {
            return Err(field(
                "export",
                "rpi.contrast.ce_enable",
                "must be 0: adaptive contrast enhancement would rewrite the curve per frame",
            ));
        }
        let curve = self.hardware_curve(&given);
        let fmt = self.matrix_format();
        Ok(ours
            .ccms
            .iter()
            .zip(&theirs.ccms)
            .map(|((ct, m), (_, device))| Condition {
                bound: None,
                label: format!("ct {ct}"),
                feed: Feed::Sensor(*device),
                emulator: Box::new(Isp { matrix: fmt.apply(m), curves: curve.clone().into() }),
            })
            .collect())
    }
}

/// The ISP curve of a CamPro curve exported to `target`, against the CamPro curve:
/// the largest difference (output units) on a fine grid and at every knot.
pub fn curve_error(target: Rpi, curve: &ToneCurve) -> f64 {
    let pts: Vec<(f64, f64)> =
        curve.x().iter().zip(curve.y()).map(|(x, y)| ((x * FULL).round(), (y * FULL).round())).collect();
    let given = curve_from_points(&pts, FULL, "curve").expect("a valid curve stays valid on 16 bits");
    let hw = target.hardware_curve(&given);
    (0..=4096)
        .map(|i| i as f64 / 4096.0)
        .chain(curve.x().iter().copied())
        .map(|t| (hw.eval(t) - curve.eval(t)).abs())
        .fold(0.0, f64::max)
}
