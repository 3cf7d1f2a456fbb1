//! The CamPro parameter set and its JSON format.
//!
//! ```json
//! { "format": "campro-params", "version": 1,
//!   "name": "identity", "description": "...",
//!   "ccm": [[1,0,0],[0,1,0],[0,0,1]],
//!   "tone_curve": { "y": [0.0, ..., 1.0] },          // x optional: evenly spaced
//!   // or, version 2, a curve per output channel:
//!   // "tone_curves": { "red": { "y": [...] }, "green": { ... }, "blue": { ... } },
//!   "degamma": 2.2,                                   // optional, default 2.2
//!   "ct_calibration": [ { "ct_kelvin": 2856, "ccm": [[...]] }, ... ],  // optional
//!   "provenance": { ... free-form ... } }
//! ```
//! Unknown fields are rejected; every rule broken is reported with its field path:
//! - `format` is `campro-params` and `version` is 1 (one `tone_curve`) or 2 (`tone_curves`,
//!   one per channel); a set whose three curves are equal is written as version 1, so
//!   every file written before per-channel curves existed reads and writes unchanged;
//! - every number is finite;
//! - `ccm` is 3 rows of 3, entries within ±[`CCM_LIMIT`] (32), row-major, acting on
//!   column vectors of linear RGB (`out = ccm · in`);
//! - `tone_curve.y` (each of `tone_curves.red`, `.green`, `.blue`) has 2 to 4096 outputs in [0, 1]; `x`, when given, has as many inputs
//!   strictly increasing from 0 to 1 (evenly spaced otherwise);
//! - `degamma` is in [0.2, 5] (the desktop pipeline's `clamp(x^γ, 0, 1)`);
//! - `ct_calibration` CTs are strictly increasing in [1000, 40000] K
//!   ([`crate::color_temp::CT_RANGE`]), each with a 3x3 matrix within ±32;
//! - the file is at most [`MAX_JSON_BYTES`] (4 MiB), read as a regular file.

use crate::ccm::{Mat3, CCM_LIMIT};
use crate::color_temp::CtCcm;
use crate::error::{check_matrix, check_range, ValidationError};
use crate::tone_curve::{ToneCurve, ToneCurves, CHANNELS};
use serde::{Deserialize, Serialize};

/// The `format` tag of a parameter file.
pub const FORMAT: &str = "campro-params";
/// The format version of a set with one shared tone curve.
pub const VERSION: u32 = 1;
/// The format version of a set with a tone curve per channel (`tone_curves`).
pub const VERSION_PER_CHANNEL: u32 = 2;
/// Accepted degamma exponents.
pub const DEGAMMA_RANGE: (f64, f64) = (0.2, 5.0);
/// Largest parameter file read (bytes); a real one is a few KiB.
pub const MAX_JSON_BYTES: usize = 4 << 20;

/// A validated CamPro parameter set.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// Short name, e.g. `identity`.
    pub name: String,
    /// What it is and where it came from, for people.
    pub description: String,
    /// The optimised colour correction matrix, `out = ccm · in` on linear RGB.
    pub ccm: Mat3,
    /// The optimised tone curves applied after the clipped CCM: one shared, or one per
    /// output channel.
    pub tone_curves: ToneCurves,
    /// Exponent of the desktop pipeline's degamma `clamp(x^γ, 0, 1)` (paper: 2.2).
    pub degamma: f64,
    /// The target device's calibrated CCMs by colour temperature (ascending), if the
    /// deployment interpolates them (paper appendix); empty otherwise.
    pub ct_calibration: Vec<CtCcm>,
    /// Free-form provenance (optimiser config, checkpoint, seed, ...).
    pub provenance: serde_json::Map<String, serde_json::Value>,
}

/// Errors reading or checking a parameter set.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ParamsError {
    /// Not JSON of the format, at this path inside the document.
    #[error("invalid JSON at {path}: {message}")]
    Json {
        /// Where in the document (`tone_curve.y[3]`, `.` for the top).
        path: String,
        /// What the parser said.
        message: String,
    },
    /// JSON of the format, but a value breaks a rule.
    #[error("invalid parameters: {0}")]
    Invalid(#[from] ValidationError),
    /// The text is larger than [`MAX_JSON_BYTES`].
    #[error("parameter file is {size} bytes; the limit is {limit}")]
    TooLarge {
        /// Its size, bytes.
        size: usize,
        /// The limit, bytes.
        limit: usize,
    },
    /// The file could not be read.
    #[error(transparent)]
    File(#[from] crate::file::FileError),
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CurveJson {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    x: Option<Vec<f64>>,
    y: Vec<f64>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParamsJson {
    format: String,
    version: u32,
    #[serde(default)]
    name: String,
    #[serde(default)]
    description: String,
    ccm: Vec<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tone_curve: Option<CurveJson>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    tone_curves: Option<ChannelCurvesJson>,
    #[serde(default = "default_degamma")]
    degamma: f64,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    ct_calibration: Vec<CtCcmJson>,
    #[serde(default, skip_serializing_if = "serde_json::Map::is_empty")]
    provenance: serde_json::Map<String, serde_json::Value>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ChannelCurvesJson {
    red: CurveJson,
    green: CurveJson,
    blue: CurveJson,
}

impl CurveJson {
    fn of(t: &ToneCurve) -> Self {
        Self { x: (!t.is_uniform()).then(|| t.x().to_vec()), y: t.y().to_vec() }
    }

    fn curve(self, field: &str) -> Result<ToneCurve, ValidationError> {
        match self.x {
            Some(x) => ToneCurve::new(x, self.y),
            None => ToneCurve::uniform(self.y),
        }
        .map_err(|e| e.within(field))
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CtCcmJson {
    ct_kelvin: f64,
    ccm: Vec<Vec<f64>>,
}

fn default_degamma() -> f64 {
    2.2
}

/// Converts nested JSON rows into a 3x3 matrix, naming `field` when the shape is wrong.
pub fn matrix_from_rows(field: &str, rows: &[Vec<f64>]) -> Result<Mat3, ValidationError> {
    if rows.len() != 3 {
        return Err(ValidationError::WrongLength { field: field.into(), expected: "3 rows".into(), got: rows.len() });
    }
    let mut m = [[0.0; 3]; 3];
    for (i, row) in rows.iter().enumerate() {
        if row.len() != 3 {
            return Err(ValidationError::WrongLength {
                field: format!("{field}[{i}]"),
                expected: "3".into(),
                got: row.len(),
            });
        }
        m[i].copy_from_slice(row);
    }
    Ok(m)
}

fn rows(m: &Mat3) -> Vec<Vec<f64>> {
    m.iter().map(|r| r.to_vec()).collect()
}

impl Params {
    /// Builds and validates a parameter set (name/description/provenance empty).
    pub fn new(ccm: Mat3, tone_curves: impl Into<ToneCurves>, degamma: f64) -> Result<Self, ValidationError> {
        let p = Self {
            name: String::new(),
            description: String::new(),
            ccm,
            tone_curves: tone_curves.into(),
            degamma,
            ct_calibration: Vec::new(),
            provenance: Default::default(),
        };
        p.validate()?;
        Ok(p)
    }

    /// The identity parameters: the pipeline returns `clamp(x^γ)` through the
    /// identity curve, i.e. linear light (k evenly spaced knots).
    pub fn identity_curve(k: usize) -> Self {
        Self::new(crate::ccm::IDENTITY, ToneCurve::identity(k), 2.2).expect("identity is valid")
    }

    /// Checks every rule; the error names the first field that breaks one.
    pub fn validate(&self) -> Result<(), ValidationError> {
        check_matrix("ccm", &self.ccm, CCM_LIMIT)?;
        check_range(|| "degamma".into(), self.degamma, DEGAMMA_RANGE.0, DEGAMMA_RANGE.1)?;
        crate::color_temp::validate_calibration(&self.ct_calibration).map_err(|e| e.within("ct_calibration"))?;
        Ok(())
    }

    /// Parses and validates the JSON format.
    pub fn from_json(text: &str) -> Result<Self, ParamsError> {
        if text.len() > MAX_JSON_BYTES {
            return Err(ParamsError::TooLarge { size: text.len(), limit: MAX_JSON_BYTES });
        }
        let de = &mut serde_json::Deserializer::from_str(text);
        let raw: ParamsJson = serde_path_to_error::deserialize(&mut *de)
            .map_err(|e| ParamsError::Json { path: e.path().to_string(), message: e.inner().to_string() })?;
        // One object and nothing after it (white space aside). serde_json bounds the
        // nesting depth (128) while parsing.
        de.end().map_err(|e| ParamsError::Json { path: ".".into(), message: format!("text after the object: {e}") })?;
        Ok(Self::from_raw(raw)?)
    }

    /// Reads a parameter file (size-limited) and parses it.
    pub fn from_file(path: &std::path::Path) -> Result<Self, ParamsError> {
        let text = crate::file::read_text_capped(path, MAX_JSON_BYTES as u64, "a parameter file")?;
        Self::from_json(&text)
    }

    fn from_raw(raw: ParamsJson) -> Result<Self, ValidationError> {
        if raw.format != FORMAT {
            return Err(ValidationError::Rule {
                field: "format".into(),
                rule: format!("must be \"{FORMAT}\", got \"{}\"", raw.format),
            });
        }
        let rule = |field: &str, rule: String| ValidationError::Rule { field: field.into(), rule };
        let tone_curves = match (raw.version, raw.tone_curve, raw.tone_curves) {
            (VERSION, Some(t), None) => ToneCurves::Shared(t.curve("tone_curve")?),
            (VERSION_PER_CHANNEL, None, Some(t)) => {
                let [red, green, blue] = CHANNELS.map(|c| format!("tone_curves.{c}"));
                ToneCurves::per_channel([t.red.curve(&red)?, t.green.curve(&green)?, t.blue.curve(&blue)?])
            }
            (VERSION, _, _) => {
                return Err(rule("tone_curve", "version 1 holds one tone_curve (tone_curves needs version 2)".into()))
            }
            (VERSION_PER_CHANNEL, _, _) => {
                return Err(rule(
                    "tone_curves",
                    "version 2 holds tone_curves (red, green, blue), not tone_curve".into(),
                ))
            }
            (v, _, _) => {
                return Err(rule(
                    "version",
                    format!(
                        "must be {VERSION} (one tone curve) or {VERSION_PER_CHANNEL} (a curve per channel), got {v}"
                    ),
                ))
            }
        };
        let ccm = matrix_from_rows("ccm", &raw.ccm)?;
        let mut ct_calibration = Vec::with_capacity(raw.ct_calibration.len());
        for (i, c) in raw.ct_calibration.iter().enumerate() {
            ct_calibration.push(CtCcm {
                ct_kelvin: c.ct_kelvin,
                ccm: matrix_from_rows(&format!("ct_calibration[{i}].ccm"), &c.ccm)?,
            });
        }
        let p = Self {
            name: raw.name,
            description: raw.description,
            ccm,
            tone_curves,
            degamma: raw.degamma,
            ct_calibration,
            provenance: raw.provenance,
        };
        p.validate()?;
        Ok(p)
    }

    /// The JSON format, pretty-printed: version 1 for a shared curve, 2 for a curve per
    /// channel. Evenly spaced knot inputs are left out.
    pub fn to_json(&self) -> String {
        let (version, tone_curve, tone_curves) = match &self.tone_curves {
            ToneCurves::Shared(t) => (VERSION, Some(CurveJson::of(t)), None),
            ToneCurves::PerChannel(t) => (
                VERSION_PER_CHANNEL,
                None,
                Some(ChannelCurvesJson {
                    red: CurveJson::of(&t[0]),
                    green: CurveJson::of(&t[1]),
                    blue: CurveJson::of(&t[2]),
                }),
            ),
        };
        let raw = ParamsJson {
            format: FORMAT.into(),
            version,
            name: self.name.clone(),
            description: self.description.clone(),
            ccm: rows(&self.ccm),
            tone_curve,
            tone_curves,
            degamma: self.degamma,
            ct_calibration: self
                .ct_calibration
                .iter()
                .map(|c| CtCcmJson { ct_kelvin: c.ct_kelvin, ccm: rows(&c.ccm) })
                .collect(),
            provenance: self.provenance.clone(),
        };
        let mut s = serde_json::to_string_pretty(&raw).expect("plain data serialises");
        s.push('\n');
        s
    }

    /// The typed fields of this set's provenance ([`crate::provenance::Provenance::read`]).
    pub fn provenance_fields(&self) -> Result<crate::provenance::Provenance, crate::provenance::BadField> {
        crate::provenance::Provenance::read(&self.provenance)
    }

    /// Whether the set is rated for grey input ([`crate::chroma`]): its provenance holds
    /// `"grey": {"rated": true, ...}` ([`GREY_RATING`]), written with the figures that rate
    /// it. Without it, tools do not call a grey image protected.
    pub fn rated_for_grey(&self) -> bool {
        self.provenance_fields().is_ok_and(|p| p.grey_rated)
    }

    /// Whether the set protects faces: its provenance holds a protection rating
    /// (`"protection": {"worst_top1": T, ...}`) with `T` at most
    /// [`crate::provenance::PROTECTIVE_TOP1`]. Hand-made sets, sets in training and JSON
    /// without the rating are not protective: a device does not call them "Protected".
    pub fn protective(&self) -> bool {
        self.provenance_fields().is_ok_and(|p| p.protective())
    }

    /// The grids a phone's HAL may put this set's values on with its protection measured to
    /// hold (`provenance.protection.device_grids.held`); none for a set that is not
    /// protective, or whose provenance does not read.
    pub fn device_grids(&self) -> Vec<crate::provenance::DeviceGrid> {
        self.provenance_fields().ok().filter(|p| p.protective()).map(|p| p.device_grids).unwrap_or_default()
    }
}

/// The provenance key of a set's rating for grey input ([`Params::rated_for_grey`]).
pub const GREY_RATING: &str = crate::provenance::GREY;
