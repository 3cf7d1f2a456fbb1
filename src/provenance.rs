//! What other code reads from a parameter set's `provenance`, typed and read in one place.
//!
//! The provenance object stays the file's free-form record (optimiser config, checkpoint,
//! seeds, figures: `Params::provenance`, written back byte for byte); the fields below are
//! the contract between the crates that write them (`campro train`, `train-enhancer`,
//! `finetune-detector`, the grey rating) and those that read them (`simulate --enhance`,
//! `eval`, `check`, records). Every key is named here once. A field that is present but of
//! the wrong shape is an error naming it; an absent one is `None`.

use serde_json::{Map, Value};

/// `provenance.enhancer`: the image enhancer shown to people (`{"onnx": FILE, ...}`).
pub const ENHANCER: &str = "enhancer";
/// `provenance.restorer`: the attacker's restoration network trained against the set.
pub const RESTORER: &str = "restorer";
/// `provenance.detector`: the person detector fine-tuned behind the set's camera
/// (`{"onnx": FILE, "manifest": FILE, ...}`).
pub const DETECTOR: &str = "detector";
/// `provenance.data`: what training read; its `validation_identities` are the LFW identities
/// held out of training.
pub const DATA: &str = "data";
/// `provenance.data.validation_identities`.
pub const VALIDATION_IDENTITIES: &str = "validation_identities";
/// `provenance.validation`: the held-out validation of training; its `best_round` is the
/// round whose parameters were kept.
pub const VALIDATION: &str = "validation";
/// `provenance.validation.best_round`.
pub const BEST_ROUND: &str = "best_round";
/// `provenance.grey`: the set's rating for grey input (`{"rated": true, ...}`).
pub const GREY: &str = "grey";
/// `provenance.protection`: the set's measured protection against face recognition
/// (`{"worst_top1": 0.11, "attacks": "...", "measured": "..."}`), written with the figures
/// that rate it. A set without it is not called protective anywhere (a privacy camera fails
/// closed): hand-made sets, sets in training, an app's own JSON.
pub const PROTECTION: &str = "protection";
/// `provenance.protection.worst_top1`: the worst face-recognition top-1 accuracy measured
/// over every attack on the set's output, 0..=1 (1% is chance among 100 identities).
pub const WORST_TOP1: &str = "worst_top1";
/// The largest worst-case top-1 at which a set is called protective (15%, inclusive):
/// every bundled preset below it was measured under the paper's protocol and the adaptive
/// attacks of its Sec. VII (trained/README.md); `campro-omega-1` (19%) and
/// `campro-omega-5` (39%) are above it.
pub const PROTECTIVE_TOP1: f64 = 0.15;
/// `provenance.protection.device_grids`: the grids a phone's HAL may put the values on with
/// the set's protection measured to hold there (`{"held": ["q10", "lut64"], "refused":
/// [...], "measured": "..."}`): `qB`, matrix entries rounded to B fractional bits (1..=24);
/// `lutN`, each curve resampled to N evenly spaced points (2..=4096). Measured by
/// `campro check` on held-out faces as that HAL applies the values (docs/android.md, "Grids");
/// the Android guard accepts a device on one of the `held` grids, and no other deviation
/// beyond half an LSB.
pub const DEVICE_GRIDS: &str = "device_grids";
/// `provenance.protection.device_grids.held`.
pub const HELD: &str = "held";

/// One grid of [`DEVICE_GRIDS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum DeviceGrid {
    /// Matrix entries rounded to this many fractional bits.
    MatrixBits(u8),
    /// Each curve resampled to this many evenly spaced points.
    CurvePoints(u16),
}

impl DeviceGrid {
    /// Reads `qB` or `lutN`; `None` for anything else or out of range.
    pub fn parse(s: &str) -> Option<Self> {
        if let Some(b) = s.strip_prefix('q') {
            let b: u8 = b.parse().ok()?;
            (1..=24).contains(&b).then_some(Self::MatrixBits(b))
        } else if let Some(n) = s.strip_prefix("lut") {
            let n: u16 = n.parse().ok()?;
            (2..=4096).contains(&n).then_some(Self::CurvePoints(n))
        } else {
            None
        }
    }
}

impl std::fmt::Display for DeviceGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::MatrixBits(b) => write!(f, "q{b}"),
            Self::CurvePoints(n) => write!(f, "lut{n}"),
        }
    }
}

/// A network's or detector's file field (a bare file name beside the parameter file).
pub const ONNX: &str = "onnx";
/// A fine-tuned detector's manifest field (a bare file name beside the parameter file).
pub const MANIFEST: &str = "manifest";

/// A file a provenance field names: a file name meant to lie beside the parameter file
/// (the caller resolves and checks it).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Named {
    /// The network's ONNX file.
    pub onnx: String,
    /// The model manifest beside it (fine-tuned detectors).
    pub manifest: Option<String>,
}

/// The typed fields of a provenance; everything else stays in `Params::provenance`.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Provenance {
    /// [`ENHANCER`].
    pub enhancer: Option<Named>,
    /// [`RESTORER`].
    pub restorer: Option<Named>,
    /// [`DETECTOR`].
    pub detector: Option<Named>,
    /// LFW identities held out of training.
    pub validation_identities: Option<Vec<String>>,
    /// The training round whose parameters were kept.
    pub best_round: Option<u64>,
    /// Rated for grey input.
    pub grey_rated: bool,
    /// [`WORST_TOP1`] of the set's protection rating, when it has one.
    pub worst_top1: Option<f64>,
    /// The `held` grids of [`DEVICE_GRIDS`] (empty: none measured).
    pub device_grids: Vec<DeviceGrid>,
}

/// A provenance field of the wrong shape: the field's path and the rule.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BadField {
    /// The field's path below `provenance`.
    pub field: String,
    /// What it must be.
    pub rule: &'static str,
}

impl std::fmt::Display for BadField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "provenance.{}: {}", self.field, self.rule)
    }
}

impl std::error::Error for BadField {}

fn bad<T>(field: impl Into<String>, rule: &'static str) -> Result<T, BadField> {
    Err(BadField { field: field.into(), rule })
}

/// The object at `key` (`None`: absent or null).
fn object<'a>(m: &'a Map<String, Value>, key: &str, path: &str) -> Result<Option<&'a Map<String, Value>>, BadField> {
    match m.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(Value::Object(o)) => Ok(Some(o)),
        Some(_) => bad(path, "must be an object"),
    }
}

fn named(m: &Map<String, Value>, key: &str) -> Result<Option<Named>, BadField> {
    let Some(o) = object(m, key, key)? else { return Ok(None) };
    let string = |f: &str| match o.get(f) {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(s)) => Ok(Some(s.clone())),
        Some(_) => bad(format!("{key}.{f}"), "must be a string"),
    };
    // An entry without its file (a record of a run that wrote none) names nothing.
    let Some(onnx) = string(ONNX)? else { return Ok(None) };
    Ok(Some(Named { onnx, manifest: string(MANIFEST)? }))
}

impl Provenance {
    /// Reads the typed fields of `m` (a parameter set's provenance).
    pub fn read(m: &Map<String, Value>) -> Result<Self, BadField> {
        let validation_identities = match object(m, DATA, DATA)?.and_then(|d| d.get(VALIDATION_IDENTITIES)) {
            None | Some(Value::Null) => None,
            Some(Value::Array(a)) => Some(
                a.iter()
                    .map(|v| v.as_str().map(str::to_string))
                    .collect::<Option<Vec<_>>>()
                    .map_or_else(|| bad("data.validation_identities", "must be an array of names"), Ok)?,
            ),
            Some(_) => return bad("data.validation_identities", "must be an array of names"),
        };
        let best_round = match object(m, VALIDATION, VALIDATION)?.and_then(|v| v.get(BEST_ROUND)) {
            None | Some(Value::Null) => None,
            Some(v) => Some(v.as_u64().map_or_else(|| bad("validation.best_round", "must be a whole number"), Ok)?),
        };
        let grey_rated = match object(m, GREY, GREY)?.and_then(|g| g.get("rated")) {
            None | Some(Value::Null) => false,
            Some(Value::Bool(b)) => *b,
            Some(_) => return bad("grey.rated", "must be true or false"),
        };
        let worst_top1 = match object(m, PROTECTION, PROTECTION)?.map(|o| o.get(WORST_TOP1)) {
            None => None,
            Some(Some(Value::Number(n))) if n.as_f64().is_some_and(|t| (0.0..=1.0).contains(&t)) => n.as_f64(),
            Some(_) => return bad("protection.worst_top1", "must be a number in 0..=1"),
        };
        const GRIDS_RULE: &str = "must be an array of at most 16 grid names: qB (B 1..=24) or lutN (N 2..=4096)";
        let grids = object(m, PROTECTION, PROTECTION)?
            .map(|o| object(o, DEVICE_GRIDS, "protection.device_grids"))
            .transpose()?
            .flatten();
        let device_grids = match grids.and_then(|g| g.get(HELD)) {
            None | Some(Value::Null) => Vec::new(),
            Some(Value::Array(a)) if a.len() <= 16 => a
                .iter()
                .map(|v| v.as_str().and_then(DeviceGrid::parse))
                .collect::<Option<Vec<_>>>()
                .map_or_else(|| bad("protection.device_grids.held", GRIDS_RULE), Ok)?,
            Some(_) => return bad("protection.device_grids.held", GRIDS_RULE),
        };
        Ok(Self {
            enhancer: named(m, ENHANCER)?,
            restorer: named(m, RESTORER)?,
            detector: named(m, DETECTOR)?,
            validation_identities,
            best_round,
            grey_rated,
            worst_top1,
            device_grids,
        })
    }

    /// Whether the set is protective: its rating's worst-case top-1 is at most
    /// [`PROTECTIVE_TOP1`]. Unrated sets are not.
    pub fn protective(&self) -> bool {
        self.worst_top1.is_some_and(|t| t <= PROTECTIVE_TOP1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn read(v: Value) -> Result<Provenance, BadField> {
        Provenance::read(v.as_object().unwrap())
    }

    #[test]
    fn typed_fields_by_hand() {
        let p = read(json!({
            "enhancer": {"onnx": "p.enhancer.onnx", "steps": 60},
            "detector": {"onnx": "p.detector.onnx", "manifest": "p.detector.json"},
            "data": {"validation_identities": ["A_B", "C_D"], "person_images": 2},
            "validation": {"best_round": 12},
            "grey": {"rated": true},
            "config": {"seed": 1}
        }))
        .unwrap();
        assert_eq!(p.enhancer, Some(Named { onnx: "p.enhancer.onnx".into(), manifest: None }));
        assert_eq!(p.detector.unwrap().manifest.as_deref(), Some("p.detector.json"));
        assert_eq!(p.restorer, None);
        assert_eq!(p.validation_identities.unwrap(), ["A_B", "C_D"]);
        assert_eq!(p.best_round, Some(12));
        assert!(p.grey_rated);
        assert_eq!(read(json!({})).unwrap(), Provenance::default());
        assert_eq!(
            read(json!({"enhancer": {"steps": 3}, "validation": {"best_round": null}})).unwrap(),
            Provenance::default()
        );
    }

    #[test]
    fn device_grids_by_hand() {
        let p = read(json!({"protection": {"worst_top1": 0.11, "device_grids": {"held": ["q10", "q7", "lut64"], "refused": ["lut17"]}}})).unwrap();
        assert_eq!(
            p.device_grids,
            [DeviceGrid::MatrixBits(10), DeviceGrid::MatrixBits(7), DeviceGrid::CurvePoints(64)]
        );
        assert_eq!(p.device_grids.iter().map(ToString::to_string).collect::<Vec<_>>(), ["q10", "q7", "lut64"]);
        assert!(read(json!({"protection": {"worst_top1": 0.11}})).unwrap().device_grids.is_empty());
        for bad_grids in [
            json!(["q0"]),
            json!(["q25"]),
            json!(["lut1"]),
            json!(["lut4097"]),
            json!(["Q10"]),
            json!([10]),
            json!("q10"),
            json!(vec!["q10"; 17]),
        ] {
            let e = read(json!({"protection": {"worst_top1": 0.1, "device_grids": {"held": bad_grids}}})).unwrap_err();
            assert_eq!(e.field, "protection.device_grids.held");
        }
        let e = read(json!({"protection": {"worst_top1": 0.1, "device_grids": ["q10"]}})).unwrap_err();
        assert_eq!(e.field, "protection.device_grids");
    }

    #[test]
    fn a_field_of_the_wrong_shape_is_named() {
        let e = |v: Value| read(v).unwrap_err().to_string();
        assert_eq!(e(json!({"enhancer": "x.onnx"})), "provenance.enhancer: must be an object");
        assert_eq!(e(json!({"restorer": {"onnx": 3}})), "provenance.restorer.onnx: must be a string");
        assert_eq!(
            e(json!({"data": {"validation_identities": ["a", 1]}})),
            "provenance.data.validation_identities: must be an array of names"
        );
        assert_eq!(
            e(json!({"validation": {"best_round": -1}})),
            "provenance.validation.best_round: must be a whole number"
        );
        assert_eq!(e(json!({"grey": {"rated": "yes"}})), "provenance.grey.rated: must be true or false");
        for bad in [json!({}), json!({"worst_top1": "5%"}), json!({"worst_top1": 1.5}), json!({"worst_top1": -0.1})] {
            assert_eq!(e(json!({ "protection": bad })), "provenance.protection.worst_top1: must be a number in 0..=1");
        }
    }

    #[test]
    fn the_bundled_presets_that_protect_are_the_rated_ones_within_the_threshold() {
        let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/params"));
        let mut protective = Vec::new();
        for e in std::fs::read_dir(dir).unwrap() {
            let path = e.unwrap().path();
            if path.extension().is_some_and(|x| x == "json") {
                let p = crate::Params::from_file(&path).unwrap();
                let fields = p.provenance_fields().unwrap();
                // Every learnt set carries its rating; hand-made ones none.
                assert_eq!(fields.worst_top1.is_some(), p.provenance.contains_key("optimiser"), "{}", path.display());
                if p.protective() {
                    protective.push(path.file_stem().unwrap().to_string_lossy().into_owned());
                }
            }
        }
        protective.sort();
        assert_eq!(
            protective,
            [
                "campro-omega-0.5",
                "campro-omega-0.5-distill",
                "campro-omega-0.5-hour",
                "campro-omega-1-shared-continued"
            ]
        );
    }

    #[test]
    fn the_aars_threshold_is_the_cores() {
        // android/campro/build.gradle.kts picks the presets the AAR ships with the same rule.
        let gradle =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/android/campro/build.gradle.kts")).unwrap();
        let line = gradle.lines().find(|l| l.starts_with("val PROTECTIVE_TOP1 = ")).expect("the AAR's threshold");
        let v: f64 = line.trim_start_matches("val PROTECTIVE_TOP1 = ").trim().parse().unwrap();
        assert_eq!(v, PROTECTIVE_TOP1);
    }

    #[test]
    fn protective_only_with_a_rating_at_most_the_threshold() {
        let p = |v: Value| read(v).unwrap().protective();
        assert!(!p(json!({})), "unrated");
        assert!(!p(json!({"optimiser": "campro-train"})), "trained but unrated");
        assert!(p(json!({"protection": {"worst_top1": 0.0}})));
        assert!(p(json!({"protection": {"worst_top1": 0.15}})), "the threshold is inclusive");
        assert!(!p(json!({"protection": {"worst_top1": 0.1501}})));
        assert!(!p(json!({"protection": {"worst_top1": 0.39}})));
    }
}
