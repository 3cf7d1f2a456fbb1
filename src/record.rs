//! The record beside a protected file (`NAME.EXT.campro.json`): which preset (name and
//! SHA-256), which campro, which path and its stated error bound, the SHA-256 of the output
//! and, where there is one, of the raw input; on a phone, the values the camera was sent.
//!
//! One format for every writer: `campro simulate --record` (desktop, with the raw input) and
//! the Android library's stills and recordings (through `libcampro_jni.so`, no raw input: the
//! sensor's data never leaves the camera). `campro check --record` reads it.

use serde::{Deserialize, Serialize};

/// The record format's version.
pub const RECORD_VERSION: u32 = 1;

/// A record file's largest size, bytes: it is a few hundred.
pub const MAX_RECORD_BYTES: u64 = 64 << 10;

/// [`Record::path`] of a desktop run without the enhancer.
pub const PATH_CAMERA: &str = "camera";
/// [`Record::path`] of a desktop run with the preset's enhancer.
pub const PATH_CAMERA_ENHANCER: &str = "camera+enhancer";
/// [`Record::path`] of a phone's Camera2 capture (values verified per frame).
pub const PATH_CAMERA2: &str = "camera2";

/// What a record says of the preset.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PresetRecord {
    /// The parameter set's own name.
    pub name: String,
    /// What named it (a bundled preset's name, or a file).
    pub given: String,
    /// SHA-256 of the parameter file's bytes (a bundled preset: its JSON as built in).
    pub sha256: String,
    /// The training round kept, where the set was trained.
    pub best_round: Option<u64>,
}

/// A file a record names.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FileRecord {
    /// Its file name (no folder: the record lies beside the output).
    pub name: String,
    /// SHA-256 of its bytes, lowercase hex.
    pub sha256: String,
    /// Its size, bytes.
    pub bytes: u64,
}

/// What a phone's camera was sent for the recorded output (path [`PATH_CAMERA2`]).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DeviceRecord {
    /// The Camera2 camera id.
    pub camera_id: String,
    /// `COLOR_CORRECTION_TRANSFORM` sent: nine (numerator, denominator) pairs, row-major.
    pub transform: Vec<i32>,
    /// `COLOR_CORRECTION_GAINS` sent: R, G_even, G_odd, B.
    pub gains: Vec<f32>,
    /// (Pin, Pout) points of the `TONEMAP_CURVE` sent (the same on the three channels).
    pub curve_points: u32,
    /// Largest deviation of what the camera's results reported from what was sent, 8-bit LSB
    /// (every delivered frame's result was within the guard's bound).
    pub worst_reported_deviation_lsb: f64,
}

/// One protected output's record.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Record {
    /// [`RECORD_VERSION`].
    pub campro_record: u32,
    /// The campro that wrote it.
    pub campro_version: String,
    /// The preset that made the output.
    pub preset: PresetRecord,
    /// [`PATH_CAMERA`], [`PATH_CAMERA_ENHANCER`] or [`PATH_CAMERA2`].
    pub path: String,
    /// Output bits per channel.
    pub bit_depth: u8,
    /// The path's stated bound, LSB of `bit_depth`. Desktop: rounding to the output code
    /// against the f64 reference (docs/accuracy-and-speed.md). Camera2: the conversion's
    /// bound plus the largest reported deviation the guard accepts, on the settings the
    /// device says it applied (its own demosaicing and noise reduction are not bounded).
    pub bound_lsb: f64,
    /// The enhancer, a network, has no bound: its SHA-256 names it.
    pub enhancer_sha256: Option<String>,
    /// JPEG quality (1..=100) where the output is a JPEG.
    pub jpeg_quality: Option<u8>,
    /// What the output kept of the input's metadata (`strip`, `keep-safe`, `keep`; a phone's
    /// still: `orientation`, its only tag; a phone's recording: `orientation+summary`).
    pub metadata: String,
    /// The raw input; `None` for a phone's capture (the raw never leaves the camera).
    #[serde(default)]
    pub input: Option<FileRecord>,
    /// The protected file.
    pub output: FileRecord,
    /// The values a phone's camera was sent (path [`PATH_CAMERA2`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<DeviceRecord>,
}

/// Why a record was refused: the field and the rule.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {rule}")]
pub struct BadRecord {
    /// The field, as a path (`device.transform`).
    pub field: String,
    /// The rule it broke.
    pub rule: String,
}

fn bad(field: &str, rule: impl Into<String>) -> BadRecord {
    BadRecord { field: field.into(), rule: rule.into() }
}

fn is_sha256(h: &str) -> bool {
    h.len() == 64 && h.bytes().all(|b| b.is_ascii_hexdigit())
}

impl Record {
    /// Parses and checks a record's text (at most [`MAX_RECORD_BYTES`]).
    pub fn from_json(text: &str) -> Result<Self, BadRecord> {
        if text.len() as u64 > MAX_RECORD_BYTES {
            return Err(bad("(record)", format!("must be at most {MAX_RECORD_BYTES} bytes, got {}", text.len())));
        }
        let de = &mut serde_json::Deserializer::from_str(text);
        let r: Record =
            serde_path_to_error::deserialize(de).map_err(|e| bad(&e.path().to_string(), e.inner().to_string()))?;
        r.check()?;
        Ok(r)
    }

    /// The record's rules beyond its shape.
    pub fn check(&self) -> Result<(), BadRecord> {
        if self.campro_record != RECORD_VERSION {
            return Err(bad("campro_record", format!("must be {RECORD_VERSION}, got {}", self.campro_record)));
        }
        let hashes = [("preset.sha256", Some(&self.preset.sha256)), ("output.sha256", Some(&self.output.sha256))];
        let input = [("input.sha256", self.input.as_ref().map(|i| &i.sha256))];
        for (field, h) in hashes.iter().chain(&input) {
            if let Some(h) = h {
                if !is_sha256(h) {
                    return Err(bad(field, "must be 64 hex digits"));
                }
            }
        }
        match (self.path.as_str(), &self.device, &self.input) {
            (PATH_CAMERA | PATH_CAMERA_ENHANCER, None, Some(_)) => {}
            (PATH_CAMERA | PATH_CAMERA_ENHANCER, _, _) => {
                return Err(bad("input", "a desktop record names its raw input and no device"))
            }
            (PATH_CAMERA2, Some(d), None) => {
                if d.transform.len() != 18 || d.transform.chunks(2).any(|p| p[1] <= 0) {
                    return Err(bad("device.transform", "must hold 9 (numerator, denominator > 0) pairs"));
                }
                if d.gains.len() != 4 || d.gains.iter().any(|g| !(g.is_finite() && *g > 0.0)) {
                    return Err(bad("device.gains", "must hold 4 finite gains > 0"));
                }
            }
            (PATH_CAMERA2, _, _) => return Err(bad("device", "a camera2 record names its device values and no input")),
            (other, _, _) => {
                return Err(bad(
                    "path",
                    format!("must be {PATH_CAMERA}, {PATH_CAMERA_ENHANCER} or {PATH_CAMERA2}, got {other:?}"),
                ))
            }
        }
        if !(self.bound_lsb.is_finite() && self.bound_lsb >= 0.0) {
            return Err(bad("bound_lsb", "must be finite and >= 0"));
        }
        self.check_fields()
    }

    /// Each field in its range and against the others: what a writer can have written.
    fn check_fields(&self) -> Result<(), BadRecord> {
        let text = |field: &str, v: &str, max: usize| {
            if v.is_empty() || v.len() > max || v.chars().any(char::is_control) {
                return Err(bad(field, format!("must be 1 to {max} bytes of text")));
            }
            Ok(())
        };
        text("campro_version", &self.campro_version, 64)?;
        text("preset.name", &self.preset.name, 128)?;
        text("preset.given", &self.preset.given, 4096)?;
        let files = [("output", Some(&self.output)), ("input", self.input.as_ref())];
        for (what, f) in files {
            let Some(f) = f else { continue };
            text(&format!("{what}.name"), &f.name, 255)?;
            if f.name.contains(['/', '\\']) || f.name == "." || f.name == ".." {
                return Err(bad(&format!("{what}.name"), "must be a file name, no folder"));
            }
            if f.bytes == 0 {
                return Err(bad(&format!("{what}.bytes"), "must be at least 1"));
            }
        }
        if self.bit_depth != 8 && self.bit_depth != 16 {
            return Err(bad("bit_depth", format!("must be 8 or 16, got {}", self.bit_depth)));
        }
        if self.bound_lsb > 1.0 * f64::from(1u32 << self.bit_depth) {
            return Err(bad("bound_lsb", "must be at most the output's range"));
        }
        let jpeg = {
            let n = self.output.name.to_ascii_lowercase();
            n.ends_with(".jpg") || n.ends_with(".jpeg")
        };
        match self.jpeg_quality {
            Some(q) if !(1..=100).contains(&q) => {
                return Err(bad("jpeg_quality", format!("must be in 1..=100, got {q}")))
            }
            Some(_) if !jpeg => return Err(bad("jpeg_quality", "only a JPEG output has a quality")),
            None if jpeg && self.path != PATH_CAMERA2 => {
                return Err(bad("jpeg_quality", "a JPEG output's record gives its quality"))
            }
            _ => {}
        }
        match (self.path.as_str(), &self.enhancer_sha256) {
            (PATH_CAMERA_ENHANCER, Some(h)) if is_sha256(h) => {}
            (PATH_CAMERA_ENHANCER, _) => {
                return Err(bad("enhancer_sha256", "a camera+enhancer record names its enhancer (64 hex digits)"))
            }
            (_, Some(_)) => {
                return Err(bad("enhancer_sha256", format!("only a {PATH_CAMERA_ENHANCER} record names an enhancer")))
            }
            _ => {}
        }
        let policies: &[&str] = if self.path == PATH_CAMERA2 {
            &["orientation", "orientation+summary"]
        } else {
            &["strip", "keep-safe", "keep"]
        };
        if !policies.contains(&self.metadata.as_str()) {
            return Err(bad("metadata", format!("must be {} for a {} record", policies.join(" or "), self.path)));
        }
        if let Some(d) = &self.device {
            text("device.camera_id", &d.camera_id, 64)?;
            if !(2..=4096).contains(&d.curve_points) {
                return Err(bad("device.curve_points", "must be in 2..=4096"));
            }
            let w = d.worst_reported_deviation_lsb;
            if !(w.is_finite() && w >= 0.0 && w <= self.bound_lsb) {
                return Err(bad("device.worst_reported_deviation_lsb", "must be finite, >= 0 and within bound_lsb"));
            }
        }
        Ok(())
    }

    /// The record as written: pretty JSON and a newline.
    pub fn to_json(&self) -> String {
        // Plain data with string keys: serialisation cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn phone() -> Record {
        Record {
            campro_record: RECORD_VERSION,
            campro_version: "0.1.0".into(),
            preset: PresetRecord {
                name: "campro-omega-0.5".into(),
                given: "campro-omega-0.5".into(),
                sha256: "ab".repeat(32),
                best_round: Some(7),
            },
            path: PATH_CAMERA2.into(),
            bit_depth: 8,
            bound_lsb: 0.5,
            enhancer_sha256: None,
            jpeg_quality: Some(95),
            metadata: "orientation".into(),
            input: None,
            output: FileRecord { name: "photo.jpg".into(), sha256: "cd".repeat(32), bytes: 1234 },
            device: Some(DeviceRecord {
                camera_id: "0".into(),
                transform: vec![178, 100, -62, 100, -16, 100, -28, 100, 162, 100, -34, 100, 2, 100, -71, 100, 169, 100],
                gains: vec![2.0, 1.0, 1.0, 1.6],
                curve_points: 64,
                worst_reported_deviation_lsb: 0.0,
            }),
        }
    }

    #[test]
    fn a_phone_record_round_trips() {
        let r = phone();
        assert_eq!(Record::from_json(&r.to_json()).unwrap(), r);
        assert!(r.to_json().contains("\"input\": null"));
    }

    #[test]
    fn a_desktop_record_without_device_reads() {
        let mut r = phone();
        r.path = PATH_CAMERA.into();
        r.device = None;
        r.metadata = "keep-safe".into();
        r.input = Some(FileRecord { name: "raw.png".into(), sha256: "ef".repeat(32), bytes: 9 });
        let text = r.to_json();
        assert!(!text.contains("device"), "a desktop record has no device key: {text}");
        assert_eq!(Record::from_json(&text).unwrap(), r);
    }

    #[test]
    fn bad_records_name_the_field() {
        let mut r = phone();
        r.device = None;
        assert_eq!(Record::from_json(&r.to_json()).unwrap_err().field, "device");
        let mut r = phone();
        r.output.sha256 = "xyz".into();
        assert_eq!(Record::from_json(&r.to_json()).unwrap_err().field, "output.sha256");
        let mut r = phone();
        r.device.as_mut().unwrap().transform[1] = 0;
        assert_eq!(Record::from_json(&r.to_json()).unwrap_err().field, "device.transform");
        let mut r = phone();
        r.path = "camera".into();
        assert_eq!(Record::from_json(&r.to_json()).unwrap_err().field, "input");
        let text = phone().to_json().replacen("\"bit_depth\"", "\"extra\": 1, \"bit_depth\"", 1);
        assert!(Record::from_json(&text).unwrap_err().rule.contains("unknown field"));
        assert_eq!(Record::from_json(&" ".repeat(70_000)).unwrap_err().field, "(record)");
    }

    /// Contradictory or out-of-range fields, each refused by name (what a hand-edited
    /// record tries).
    #[test]
    fn fields_out_of_range_or_contradicting_each_other_are_refused() {
        let desktop = || {
            let mut r = phone();
            r.path = PATH_CAMERA.into();
            r.device = None;
            r.metadata = "keep-safe".into();
            r.input = Some(FileRecord { name: "raw.jpg".into(), sha256: "ef".repeat(32), bytes: 9 });
            r
        };
        assert!(Record::from_json(&desktop().to_json()).is_ok());
        type Edit = fn(&mut Record);
        let cases: [(&str, Edit); 12] = [
            ("enhancer_sha256", |r| r.path = PATH_CAMERA_ENHANCER.into()),
            ("enhancer_sha256", |r| r.enhancer_sha256 = Some("ab".repeat(32))),
            ("bit_depth", |r| r.bit_depth = 3),
            ("jpeg_quality", |r| r.jpeg_quality = Some(0)),
            ("jpeg_quality", |r| r.jpeg_quality = None),
            ("jpeg_quality", |r| r.output.name = "photo.png".into()),
            ("output.bytes", |r| r.output.bytes = 0),
            ("preset.name", |r| r.preset.name = String::new()),
            ("output.name", |r| r.output.name = "../photo.jpg".into()),
            ("metadata", |r| r.metadata = "orientation".into()),
            ("bound_lsb", |r| r.bound_lsb = 1e9),
            ("campro_version", |r| r.campro_version = "x\u{7}".into()),
        ];
        for (field, edit) in cases {
            let mut r = desktop();
            edit(&mut r);
            assert_eq!(Record::from_json(&r.to_json()).unwrap_err().field, field, "{r:?}");
        }
        let mut r = phone();
        r.device.as_mut().unwrap().worst_reported_deviation_lsb = 2.0;
        assert_eq!(Record::from_json(&r.to_json()).unwrap_err().field, "device.worst_reported_deviation_lsb");
        let mut r = phone();
        r.metadata = "keep".into();
        assert_eq!(Record::from_json(&r.to_json()).unwrap_err().field, "metadata");
    }
}
