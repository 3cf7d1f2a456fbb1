//! The parameter JSON format: round trips, bundled files, and one test per rule.

use campro::params::{Params, ParamsError};
use campro::ValidationError;

fn base() -> serde_json::Value {
    serde_json::json!({
        "format": "campro-params", "version": 1, "name": "t",
        "ccm": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        "tone_curve": {"y": [0.0, 0.5, 1.0]}
    })
}

fn parse(v: &serde_json::Value) -> Result<Params, ParamsError> {
    Params::from_json(&v.to_string())
}

/// The error message for `v` with `edit` applied; panics if it parses.
fn err(edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let mut v = base();
    edit(&mut v);
    match parse(&v) {
        Ok(_) => panic!("accepted: {v}"),
        Err(e) => e.to_string(),
    }
}

fn invalid(edit: impl FnOnce(&mut serde_json::Value)) -> ValidationError {
    let mut v = base();
    edit(&mut v);
    match parse(&v) {
        Err(ParamsError::Invalid(e)) => e,
        other => panic!("expected a validation error, got {other:?}"),
    }
}

#[test]
fn minimal_file_gets_defaults() {
    let p = parse(&base()).unwrap();
    assert_eq!(p.degamma, 2.2);
    assert!(p.tone_curves.channel(0).is_uniform());
    assert_eq!(p.tone_curves.channel(0).x(), &[0.0, 0.5, 1.0]);
    assert!(p.ct_calibration.is_empty());
}

/// A version 2 file: a curve per channel.
fn per_channel() -> serde_json::Value {
    let mut v = base();
    v["version"] = 2.into();
    v.as_object_mut().unwrap().remove("tone_curve");
    v["tone_curves"] = serde_json::json!({
        "red": {"y": [1.0, 0.0]},
        "green": {"y": [0.0, 0.25, 1.0]},
        "blue": {"x": [0.0, 0.3, 1.0], "y": [0.0, 0.9, 1.0]}
    });
    v
}

#[test]
fn a_curve_per_channel_reads_and_writes_as_version_2() {
    let p = parse(&per_channel()).unwrap();
    let c = &p.tone_curves;
    assert!(c.shared().is_none());
    // Each channel's own curve: red inverts, green bends at 0.5, blue at 0.3.
    assert_eq!([c.channel(0).eval(0.25), c.channel(1).eval(0.25), c.channel(2).eval(0.15)], [0.75, 0.125, 0.45]);
    assert_eq!(campro::pipeline::from_linear(&p, [0.25, 0.25, 0.15]), [0.75, 0.125, 0.45]);
    let text = p.to_json();
    assert!(text.contains("\"version\": 2") && text.contains("\"tone_curves\"") && !text.contains("\"tone_curve\""));
    assert_eq!(Params::from_json(&text).unwrap(), p);
    // Three equal curves are one shared curve, written as version 1.
    let mut same = per_channel();
    for c in ["red", "green", "blue"] {
        same["tone_curves"][c] = serde_json::json!({"y": [0.0, 0.5, 1.0]});
    }
    let shared = parse(&same).unwrap();
    assert_eq!(shared, parse(&base()).unwrap());
    assert!(shared.to_json().contains("\"version\": 1"));
    // Rules name the channel; a missing channel and an unknown one are refused.
    let mut bad = per_channel();
    bad["tone_curves"]["green"]["y"][1] = 1.5.into();
    let e = parse(&bad).map(|_| ()).unwrap_err().to_string();
    assert!(e.contains("tone_curves.green.y[1]"), "{e}");
    let mut missing = per_channel();
    missing["tone_curves"].as_object_mut().unwrap().remove("blue");
    assert!(parse(&missing).map(|_| ()).unwrap_err().to_string().contains("blue"));
    let mut extra = per_channel();
    extra["tone_curves"]["alpha"] = serde_json::json!({"y": [0.0, 1.0]});
    assert!(parse(&extra).map(|_| ()).unwrap_err().to_string().contains("alpha"));
}

#[test]
fn round_trip_is_exact() {
    let mut v = base();
    v["tone_curve"] = serde_json::json!({"x": [0.0, 0.1, 0.7, 1.0], "y": [0.3, 0.0, 0.9, 0.2]});
    v["ccm"] = serde_json::json!([[1.0 / 3.0, -4.9, 0.1], [2.0, 0.5, 0.25], [-1.0e-9, 0.0, 5.0]]);
    v["degamma"] = serde_json::json!(2.4);
    v["ct_calibration"] = serde_json::json!([{"ct_kelvin": 2856, "ccm": [[1,0,0],[0,1,0],[0,0,1]]}, {"ct_kelvin": 6504, "ccm": [[2,0,0],[0,1,0],[0,0,1]]}]);
    v["provenance"] = serde_json::json!({"seed": 7, "note": "x"});
    let p = parse(&v).unwrap();
    let again = Params::from_json(&p.to_json()).unwrap();
    assert_eq!(p, again);
    let uniform = parse(&base()).unwrap();
    assert!(!uniform.to_json().contains("\"x\""), "evenly spaced x is left out");
    assert_eq!(Params::from_json(&uniform.to_json()).unwrap(), uniform);
}

#[test]
fn bundled_parameter_sets_are_valid_and_match_their_formulas() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("params");
    let inv = Params::from_file(&dir.join("color-inversion.json")).unwrap();
    assert_eq!(inv.ccm, campro::ccm::IDENTITY);
    for (x, y) in inv.tone_curves.channel(0).x().iter().zip(inv.tone_curves.channel(0).y()) {
        assert!((y - (1.0 - x.powf(1.0 / 2.2))).abs() < 1e-15);
    }
    let id = Params::from_file(&dir.join("identity.json")).unwrap();
    assert!(id.tone_curves.channel(0).is_identity(1e-15) && id.tone_curves.channel(0).len() == 32);
    let pass = Params::from_file(&dir.join("srgb-passthrough.json")).unwrap();
    assert!(pass
        .tone_curves
        .channel(0)
        .y()
        .iter()
        .zip(pass.tone_curves.channel(0).x())
        .all(|(y, x)| (y - x.powf(1.0 / 2.2)).abs() < 1e-15));
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|x| x == "onnx") {
            continue; // an enhancer beside its preset
        }
        let p = Params::from_file(&path).unwrap();
        assert!(!p.description.is_empty() && !p.name.is_empty());
    }
}

#[test]
fn malformed_json_names_the_position() {
    let e = Params::from_json("{\"format\": \"campro-params\", ").unwrap_err();
    assert!(matches!(e, ParamsError::Json { .. }), "{e}");
    assert!(Params::from_json("").is_err());
    assert!(Params::from_json("[1, 2]").is_err());
}

#[test]
fn unknown_fields_are_rejected_by_name() {
    assert!(err(|v| v["colour"] = 1.into()).contains("colour"));
    assert!(err(|v| v["tone_curve"]["z"] = 1.into()).contains("tone_curve"));
}

#[test]
fn wrong_type_names_the_field() {
    let e = err(|v| v["ccm"][1][2] = "x".into());
    assert!(e.contains("ccm[1][2]"), "{e}");
}

#[test]
fn non_finite_numbers_are_rejected() {
    // JSON has no NaN or Infinity; an overflowing literal is the way to smuggle one in.
    let text = base().to_string().replace("\"y\":[0.0,0.5,1.0]", "\"y\":[0.0,1e999,1.0]");
    let e = Params::from_json(&text).unwrap_err().to_string();
    assert!(e.contains("tone_curve.y"), "{e}");
    assert!(matches!(
        Params::from_json(&base().to_string().replace("1.0,0.0,0.0]", "NaN,0.0,0.0]")),
        Err(ParamsError::Json { .. })
    ));
}

#[test]
fn format_and_version() {
    assert_eq!(invalid(|v| v["format"] = "other".into()).field(), "format");
    assert_eq!(invalid(|v| v["version"] = 3.into()).field(), "version");
    assert_eq!(invalid(|v| v["version"] = 0.into()).field(), "version");
    // Version 2 holds tone_curves, version 1 tone_curve.
    assert_eq!(invalid(|v| v["version"] = 2.into()).field(), "tone_curves");
    let mut three = per_channel();
    three["version"] = 1.into();
    let e = parse(&three).map(|_| ()).unwrap_err().to_string();
    assert!(e.ends_with("tone_curve: version 1 holds one tone_curve (tone_curves needs version 2)"), "{e}");
    assert!(err(|v| v.as_object_mut().unwrap().remove("format").map(|_| ()).unwrap()).contains("format"));
}

#[test]
fn ccm_shape_and_range() {
    assert!(matches!(
        invalid(|v| v["ccm"] = serde_json::json!([[1, 0, 0], [0, 1, 0]])),
        ValidationError::WrongLength { .. }
    ));
    assert_eq!(invalid(|v| v["ccm"][2] = serde_json::json!([0, 1])).field(), "ccm[2]");
    let e = invalid(|v| v["ccm"][0][1] = 40.0.into());
    assert!(matches!(e, ValidationError::OutOfRange { .. }) && e.field() == "ccm[0][1]");
}

#[test]
fn tone_curve_rules() {
    assert!(matches!(
        invalid(|v| v["tone_curve"]["y"] = serde_json::json!([0.5])),
        ValidationError::WrongLength { .. }
    ));
    assert_eq!(invalid(|v| v["tone_curve"]["y"][1] = 1.5.into()).field(), "tone_curve.y[1]");
    assert_eq!(invalid(|v| v["tone_curve"]["y"][0] = (-0.1).into()).field(), "tone_curve.y[0]");
    assert!(matches!(
        invalid(|v| v["tone_curve"]["x"] = serde_json::json!([0.0, 1.0])),
        ValidationError::WrongLength { .. }
    ));
    assert!(matches!(
        invalid(|v| v["tone_curve"]["x"] = serde_json::json!([0.0, 0.0, 1.0])),
        ValidationError::NotIncreasing { .. }
    ));
    assert!(matches!(
        invalid(|v| v["tone_curve"]["x"] = serde_json::json!([0.0, 0.7, 0.5])),
        ValidationError::WrongEndpoint { .. }
    ));
    assert_eq!(invalid(|v| v["tone_curve"]["x"] = serde_json::json!([0.1, 0.5, 1.0])).field(), "tone_curve.x[0]");
    assert!(matches!(
        invalid(|v| v["tone_curve"]["y"] = serde_json::json!(vec![0.5; 5000])),
        ValidationError::WrongLength { .. }
    ));
}

#[test]
fn degamma_range() {
    assert_eq!(invalid(|v| v["degamma"] = 0.0.into()).field(), "degamma");
    assert_eq!(invalid(|v| v["degamma"] = 9.0.into()).field(), "degamma");
}

#[test]
fn ct_calibration_rules() {
    let cal = |a: f64, b: f64| serde_json::json!([{"ct_kelvin": a, "ccm": [[1,0,0],[0,1,0],[0,0,1]]}, {"ct_kelvin": b, "ccm": [[1,0,0],[0,1,0],[0,0,1]]}]);
    assert!(matches!(invalid(|v| v["ct_calibration"] = cal(5000.0, 5000.0)), ValidationError::NotIncreasing { .. }));
    assert!(matches!(invalid(|v| v["ct_calibration"] = cal(6000.0, 3000.0)), ValidationError::NotIncreasing { .. }));
    assert_eq!(invalid(|v| v["ct_calibration"] = cal(10.0, 3000.0)).field(), "ct_calibration[0].ct_kelvin");
    assert_eq!(
        invalid(|v| v["ct_calibration"] = serde_json::json!([{"ct_kelvin": 3000, "ccm": [[1,0,0],[0,1,0]]}])).field(),
        "ct_calibration[0].ccm"
    );
    assert!(err(|v| v["ct_calibration"] = serde_json::json!([{"ct_kelvin": 3000}])).contains("ccm"));
}

#[test]
fn huge_input_is_refused_before_parsing() {
    let big = " ".repeat(campro::params::MAX_JSON_BYTES + 1);
    assert!(matches!(Params::from_json(&big), Err(ParamsError::TooLarge { .. })));
}

/// A file is one object: text after it is refused (as a capture result's is).
#[test]
fn text_after_the_object_is_refused() {
    let ok = std::fs::read_to_string(campro_testkit::workspace_root().join("params/identity.json")).unwrap();
    assert!(Params::from_json(&format!("{ok}\n\n")).is_ok());
    for tail in ["{}", "x", "]", "{\"format\": 1}"] {
        let e = Params::from_json(&format!("{ok}{tail}")).unwrap_err().to_string();
        assert!(e.contains("text after the object"), "{tail}: {e}");
    }
}
