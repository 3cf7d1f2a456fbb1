//! Rockchip rkaiq IQ files (ISP2x "V10" XML converted to JSON, ISP3x JSON): the CCM
//! tables and the gamma curve.
//!
//! Export: every `matrixAll` entry's `ccMatrix` becomes `CCM_opt · M` (entries hold
//! [-8, 7.992], i.e. steps of 1/128), and the gamma curve (`curve_normal`, `curve_hdr`,
//! `curve_night`, `curve_user1/2` on ISP2x; `Gamma_curve` on ISP3x) becomes the CamPro
//! curve sampled at the fixed log-spaced inputs, 12-bit (0..4095). Everything else in
//! the file is untouched.
//!
//! Emulator: the ISP interpolates the 12-bit values linearly between the fixed inputs,
//! so the deployment error is the curve's resampling onto 45 (ISP2x) or 49 (ISP3x)
//! knots plus 12-bit rounding, and the matrix's 1/128 quantisation. The check runs at
//! every calibrated matrix (rkaiq blends them by illuminant and saturation; blending is
//! linear, which commutes with the composition).

use super::target::{
    resample_on_grid, shared_curve, Condition, CurveFormat, Feed, Format, MatrixBy, MatrixFormat, StageOrder, Target,
    TargetError,
};
use crate::ccm::{self, Mat3};
use crate::emulate::Isp;
use crate::params::Params;
use crate::tone_curve::ToneCurve;
use serde_json::Value;

const FULL: f64 = 4095.0;
const MATRIX: MatrixFormat = MatrixFormat { min: -8.0, max: 8.0 - 1.0 / 128.0, step: 1.0 / 128.0 };

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
/// A Rockchip ISP generation.
pub enum Rkaiq {
    /// RV1109/RV1126 (rkaiq V10 gamma, 45 knots).
    Isp20,
    /// RK3568/RK3588 class (agamma V30, 49 knots).
    Isp3x,
}

impl Rkaiq {
    /// The fixed curve inputs on 0..4095.
    pub fn grid(self) -> Vec<f64> {
        // 0..8, then four points per octave up to 2048.
        let mut x: Vec<f64> = (0..=8).map(f64::from).collect();
        let mut step = 2.0;
        while *x.last().expect("non-empty") < 2048.0 {
            for _ in 0..4 {
                let next = x.last().expect("non-empty") + step;
                x.push(next);
            }
            step *= 2.0;
        }
        match self {
            Rkaiq::Isp20 => x.extend([2560.0, 3072.0, 3584.0, 4095.0]),
            Rkaiq::Isp3x => x.extend([2304.0, 2560.0, 2816.0, 3072.0, 3328.0, 3584.0, 3840.0, 4095.0]),
        }
        x
    }

    fn curve_keys(self) -> &'static [&'static str] {
        match self {
            Rkaiq::Isp20 => &["curve_normal", "curve_hdr", "curve_night", "curve_user1", "curve_user2"],
            Rkaiq::Isp3x => &["Gamma_curve"],
        }
    }

    fn file(self) -> &'static str {
        match self {
            Rkaiq::Isp20 => "rkaiq-isp20 IQ file",
            Rkaiq::Isp3x => "rkaiq-isp3x IQ file",
        }
    }
}

/// The CamPro-relevant parts of an IQ file: JSON pointers and values.
#[derive(Debug, Clone, PartialEq)]
pub struct Iq {
    /// `(name, pointer, matrix)` of every `ccMatrix`.
    pub matrices: Vec<(String, String, Mat3)>,
    /// `(pointer, 12-bit values)` of every gamma curve.
    pub curves: Vec<(String, Vec<f64>)>,
}

fn field(file: &str, f: &str, rule: impl Into<String>) -> TargetError {
    TargetError::Field { file: file.into(), field: f.into(), rule: rule.into() }
}

/// Numbers of a value that is an array of numbers or a string like "[1 2\t3]".
fn numbers(v: &Value, file: &str, at: &str) -> Result<Vec<f64>, TargetError> {
    let out: Option<Vec<f64>> = match v {
        Value::Array(a) => a.iter().map(Value::as_f64).collect(),
        Value::String(s) => {
            s.trim().trim_start_matches('[').trim_end_matches(']').split_whitespace().map(|t| t.parse().ok()).collect()
        }
        _ => None,
    };
    let out = out.ok_or_else(|| field(file, at, "must be numbers (an array or a \"[a b c]\" string)"))?;
    if let Some(bad) = out.iter().find(|x| !x.is_finite()) {
        return Err(field(file, at, format!("must be finite, got {bad}")));
    }
    Ok(out)
}

/// Writes numbers back in the representation `like` had.
fn write_numbers(like: &Value, v: &[f64], decimals: usize) -> Value {
    match like {
        Value::String(_) => {
            let sep = if decimals == 0 { "\t" } else { " " };
            Value::String(format!("[{}]", v.iter().map(|x| format!("{x:.decimals$}")).collect::<Vec<_>>().join(sep)))
        }
        _ if decimals == 0 => Value::Array(v.iter().map(|&x| serde_json::json!(x as i64)).collect()),
        _ => Value::Array(v.iter().map(|&x| serde_json::json!(x)).collect()),
    }
}

fn escape(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

/// Walks the tree collecting `ccMatrix` and curve entries. A matrix's name is its
/// object's `name`, or (XML-converted files: lists of one-key objects) a sibling's.
fn walk(
    v: &Value,
    at: &str,
    keys: &[&str],
    sibling_name: Option<&str>,
    found: &mut (Vec<(String, String)>, Vec<String>),
) {
    match v {
        Value::Object(o) => {
            let name = o.get("name").and_then(Value::as_str).or(sibling_name);
            for (k, child) in o {
                let p = format!("{at}/{}", escape(k));
                if k == "ccMatrix" {
                    found.0.push((name.unwrap_or("?").to_string(), p));
                } else if keys.contains(&k.as_str()) {
                    found.1.push(p);
                } else {
                    walk(child, &p, keys, None, found);
                }
            }
        }
        Value::Array(a) => {
            let name = a.iter().find_map(|e| e.get("name").and_then(Value::as_str));
            for (i, child) in a.iter().enumerate() {
                walk(child, &format!("{at}/{i}"), keys, name, found);
            }
        }
        _ => {}
    }
}

impl Rkaiq {
    /// Parses an IQ file (or excerpt) of this ISP generation.
    pub fn parse(self, text: &str, file: &str) -> Result<(Value, Iq), TargetError> {
        let root: Value = serde_json::from_str(text).map_err(|e| TargetError::Parse {
            file: file.into(),
            format: "JSON",
            message: e.to_string(),
        })?;
        let mut found = (Vec::new(), Vec::new());
        walk(&root, "", self.curve_keys(), None, &mut found);
        let mut matrices = Vec::new();
        for (name, p) in found.0 {
            let v = numbers(root.pointer(&p).unwrap_or(&Value::Null), file, &p)?;
            if v.len() != 9 {
                return Err(field(file, &p, format!("must hold 9 numbers, got {}", v.len())));
            }
            matrices.push((name, p, [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]));
        }
        let n = self.grid().len();
        let mut curves = Vec::new();
        for p in found.1 {
            let v = numbers(root.pointer(&p).unwrap_or(&Value::Null), file, &p)?;
            if v.len() != n {
                return Err(field(file, &p, format!("must hold {n} values, got {}", v.len())));
            }
            if let Some(bad) = v.iter().find(|y| !(0.0..=FULL).contains(*y)) {
                return Err(field(file, &p, format!("values must be in 0..=4095, got {bad}")));
            }
            curves.push((p, v));
        }
        if matrices.is_empty() {
            return Err(field(file, "ccMatrix", "no CCM table found"));
        }
        if curves.is_empty() {
            return Err(field(file, self.curve_keys()[0], "no gamma curve found"));
        }
        Ok((root, Iq { matrices, curves }))
    }

    /// The ISP's curve for a CamPro curve: sampled at the grid, 12-bit.
    pub fn hardware_curve(self, curve: &ToneCurve) -> ToneCurve {
        resample_on_grid(curve, &self.grid().iter().map(|x| x / FULL).collect::<Vec<_>>(), 1.0 / FULL)
    }
}

impl Target for Rkaiq {
    fn name(&self) -> &'static str {
        match self {
            Rkaiq::Isp20 => "rkaiq-isp20",
            Rkaiq::Isp3x => "rkaiq-isp3x",
        }
    }

    fn format(&self) -> Format {
        Format {
            matrix: Some(MATRIX),
            curve: CurveFormat {
                grid: self.grid().iter().map(|x| x / FULL).collect(),
                y_step: 1.0 / FULL,
                monotonic: false,
            },
            matrix_by: MatrixBy::IlluminantBlend,
            order: StageOrder::MatrixClipCurve { clip_bits: None },
        }
    }

    fn export(&self, params: &Params, base: Option<&str>) -> Result<Vec<u8>, TargetError> {
        let base = base.ok_or(TargetError::NeedsBase { target: self.name() })?;
        let (mut root, iq) = self.parse(base, self.file())?;
        for (_, p, m) in &iq.matrices {
            let c = ccm::mul(&params.ccm, m);
            let slot = root.pointer_mut(p).expect("found by the parser");
            *slot = write_numbers(slot, &c.iter().flatten().copied().collect::<Vec<_>>(), 6);
        }
        let y: Vec<f64> =
            self.hardware_curve(shared_curve(self.name(), params)?).y().iter().map(|v| (v * FULL).round()).collect();
        for (p, _) in &iq.curves {
            let slot = root.pointer_mut(p).expect("found by the parser");
            *slot = write_numbers(slot, &y, 0);
        }
        let mut text = serde_json::to_string_pretty(&root).map_err(|e| TargetError::Parse {
            file: self.file().into(),
            format: "JSON",
            message: e.to_string(),
        })?;
        text.push('\n');
        Ok(text.into_bytes())
    }

    fn emulate(&self, _params: &Params, exported: &[u8], base: Option<&str>) -> Result<Vec<Condition>, TargetError> {
        let text = std::str::from_utf8(exported).map_err(|e| TargetError::Parse {
            file: "export".into(),
            format: "UTF-8",
            message: e.to_string(),
        })?;
        let (_, ours) = self.parse(text, "export")?;
        let base = base.ok_or(TargetError::NeedsBase { target: self.name() })?;
        let (_, theirs) = self.parse(base, self.file())?;
        if ours.matrices.len() != theirs.matrices.len() {
            return Err(field("export", "ccMatrix", "matrix count differs from the base IQ file's"));
        }
        // The normal-mode curve (the first found) is what a daytime stream uses.
        let grid: Vec<f64> = self.grid().iter().map(|x| x / FULL).collect();
        let curve = ToneCurve::new(grid, ours.curves[0].1.iter().map(|v| v / FULL).collect())?;
        Ok(ours
            .matrices
            .iter()
            .zip(&theirs.matrices)
            .map(|((name, _, m), (_, _, device))| Condition {
                bound: None,
                label: name.clone(),
                feed: Feed::Sensor(*device),
                emulator: Box::new(Isp { matrix: MATRIX.apply(m), curves: curve.clone().into() }),
            })
            .collect())
    }
}
