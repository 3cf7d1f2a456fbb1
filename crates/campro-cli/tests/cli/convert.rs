//! `validate`, `convert` (Camera2, the other targets, capture results) and `compare`.

use super::*;

#[test]
fn validate_bundled_and_bad_files() {
    campro().arg("validate").arg(bundled("identity.json")).arg(bundled("color-inversion.json")).assert().success();
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        r#"{"format":"campro-params","version":1,"ccm":[[1,0,0],[0,1,0],[0,0,1]],"tone_curve":{"y":[0,2]}}"#,
    )
    .unwrap();
    fails_with(campro().arg("validate").arg(&bad), "tone_curve.y[1]");
    std::fs::write(&bad, "{ not json").unwrap();
    fails_with(campro().arg("validate").arg(&bad), "invalid JSON");
    fails_with(campro().arg("validate").arg(dir.path().join("missing.json")), "missing.json");
}

#[test]
fn convert_json_has_camera2_keys() {
    let out = campro()
        .args([
            "convert",
            "--target",
            "camera2",
            "--device-ccm",
            "1.78",
            "-0.62",
            "-0.16",
            "-0.28",
            "1.62",
            "-0.34",
            "0.02",
            "-0.71",
            "1.69",
        ])
        .arg(bundled("color-inversion.json"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let cst: Vec<i64> = v["colorCorrectionTransform"].as_array().unwrap().iter().map(|x| x.as_i64().unwrap()).collect();
    assert_eq!(cst.len(), 18);
    // Identity CCM: the device matrix itself, exactly representable.
    assert_eq!(cst[0] as f64 / cst[1] as f64, 1.78);
    assert_eq!(cst[14] as f64 / cst[15] as f64, -0.71);
    for ch in ["red", "green", "blue"] {
        let c: Vec<f64> = v["tonemapCurve"][ch].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        assert_eq!(c.len(), 64);
        assert_eq!((c[0], c[1], c[62], c[63]), (0.0, 1.0, 1.0, 0.0));
    }
    let kt = campro().args(["convert", "--format", "kotlin"]).arg(bundled("identity.json")).output().unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(
        kt.contains("ColorSpaceTransform(intArrayOf(1, 1, 0, 1,")
            && kt.contains("TonemapCurve(campro, campro, campro)")
    );
}

#[test]
fn convert_sends_a_curve_per_channel() {
    // A version 2 set: red inverted, green a ramp to 0.5, blue the identity (2 knots each).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("three.json");
    std::fs::write(
        &path,
        r#"{"format":"campro-params","version":2,"ccm":[[1,0,0],[0,1,0],[0,0,1]],
            "tone_curves":{"red":{"y":[1,0]},"green":{"y":[0,0.5]},"blue":{"y":[0,1]}}}"#,
    )
    .unwrap();
    let out = campro().args(["convert", "--target", "camera2"]).arg(&path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let curve = |ch: &str| -> Vec<f64> {
        v["tonemapCurve"][ch].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
    };
    assert_eq!(curve("red"), vec![0.0, 1.0, 1.0, 0.0]);
    assert_eq!(curve("green"), vec![0.0, 0.0, 1.0, 0.5]);
    assert_eq!(curve("blue"), vec![0.0, 0.0, 1.0, 1.0]);
    let kt = campro().args(["convert", "--format", "kotlin"]).arg(&path).output().unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(
        kt.contains("val green = floatArrayOf(0.0f, 0.0f, 1.0f, 0.5f)")
            && kt.contains("TonemapCurve(red, green, blue)"),
        "{kt}"
    );
    // A stack with one gamma curve refuses it by name; the 3D LUT holds it.
    if let Some(base) = campro_testkit::shared("fixtures/targets/rpi_pisp_imx219.json") {
        fails_with(
            campro().args(["convert"]).arg(&path).args(["--target", "rpi-pisp", "--base"]).arg(base),
            "a curve per channel",
        );
    }
    let lut = campro().args(["convert"]).arg(&path).args(["--target", "cube", "--cube-size", "2"]).output().unwrap();
    assert!(lut.status.success(), "{}", String::from_utf8_lossy(&lut.stderr));
    // The LUT's (1, 0, 0) node: red through the inverted curve, green and blue at 0.
    assert!(String::from_utf8(lut.stdout).unwrap().lines().any(|l| l == "0.000000 0.000000 0.000000"));
}

#[test]
fn convert_capture_result_and_bad_device_input() {
    let dir = tempfile::tempdir().unwrap();
    let cr = dir.path().join("cr.json");
    std::fs::write(&cr, r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1]}"#).unwrap();
    let out = campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["colorCorrectionTransform"][0], 2);
    assert!(v["colorCorrectionGains"].is_null(), "no gains in the result, none invented");

    // The gains metered with the transform travel into the JSON and the Kotlin statements.
    std::fs::write(
        &cr,
        r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1], "colorCorrectionGains": [2.25, 1, 1, 1.5]}"#,
    )
    .unwrap();
    let convert = |format: &str| {
        let out = campro()
            .arg("convert")
            .arg(bundled("identity.json"))
            .arg("--capture-result")
            .arg(&cr)
            .args(["--format", format])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    let v: serde_json::Value = serde_json::from_str(&convert("json")).unwrap();
    assert_eq!(v["colorCorrectionGains"], serde_json::json!([2.25, 1.0, 1.0, 1.5]));
    let kt = convert("kotlin");
    assert!(kt.contains("COLOR_CORRECTION_GAINS, RggbChannelVector(2.25f, 1.0f, 1.0f, 1.5f))"), "{kt}");
    let kt = campro()
        .args(["convert", "identity", "--format", "kotlin", "--device-gains", "1.9", "1", "1", "2.5"])
        .output()
        .unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(kt.contains("RggbChannelVector(1.9f, 1.0f, 1.0f, 2.5f)"), "{kt}");
    let kt = campro().args(["convert", "identity", "--format", "kotlin"]).output().unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(
        kt.contains("meteringResult.get(CaptureResult.COLOR_CORRECTION_GAINS)"),
        "unknown gains are read back: {kt}"
    );
    std::fs::write(
        &cr,
        r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1], "colorCorrectionGains": [2, 1, 1]}"#,
    )
    .unwrap();
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr),
        "colorCorrectionGains: must have 4 entries, got 3",
    );
    std::fs::write(&cr, r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1], "colorCorrectionGains": [2, 1, 1, -1]}"#).unwrap();
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr),
        "colorCorrectionGains[3]",
    );
    fails_with(campro().args(["convert", "identity", "--device-gains", "1", "1", "1", "0"]), "--device-gains");

    std::fs::write(&cr, r#"{"colorCorrectionTransform": [1,0]}"#).unwrap();
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr),
        "colorCorrectionTransform",
    );
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).args([
            "--device-ccm",
            "1",
            "0",
            "0",
            "0",
            "1",
            "0",
            "0",
            "0",
            "NaN",
        ]),
        "--device-ccm[2][2]",
    );
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).args(["--max-curve-points", "1"]),
        "--max-curve-points",
    );
    fails_with(campro().arg("convert").arg(bundled("identity.json")).args(["--ct", "5000"]), "ct_calibration");
}

#[test]
fn convert_output_file_is_not_overwritten_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("v.json");
    std::fs::write(&o, "keep").unwrap();
    fails_with(campro().arg("convert").arg(bundled("identity.json")).arg("-o").arg(&o), "exists");
    assert_eq!(std::fs::read_to_string(&o).unwrap(), "keep");
    campro().arg("convert").arg(bundled("identity.json")).arg("-o").arg(&o).arg("--force").assert().success();
    assert!(std::fs::read_to_string(&o).unwrap().contains("colorCorrectionTransform"));
    assert_eq!(files_in(dir.path()), vec!["v.json"], "no temporary files left");
}

#[test]
fn compare_reports_within_bound() {
    let out = campro()
        .arg("compare")
        .arg(bundled("color-inversion.json"))
        .args(["--format", "json", "--random", "2000", "--lut-size", "256", "--matrix-frac-bits", "10"])
        .args(["--device-ccm", "1.78", "-0.62", "-0.16", "-0.28", "1.62", "-0.34", "0.02", "-0.71", "1.69"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = v["comparison"].as_array().unwrap();
    assert_eq!(rows.len(), 4);
    for r in rows {
        assert!(r["maxLsb"].as_f64().unwrap() <= r["boundLsb"].as_f64().unwrap() + 1e-9, "{r}");
        assert!(r["maxLsb"].as_f64().unwrap() > 0.0, "a 256-entry LUT and Q10 matrix cost something");
    }
    assert!(v["verdict"].as_str().unwrap().starts_with("every condition within its stated bound"), "{v}");
    campro()
        .arg("compare")
        .arg(bundled("identity.json"))
        .assert()
        .success()
        .stdout(predicates::str::contains("every grey level"))
        .stdout(predicates::str::contains(
            "verdict: every condition within its stated bound; this stack holds the preset (at most",
        ));
    // A 4-entry device LUT cannot hold a learnt curve: the verdict says so.
    let out = campro()
        .arg("compare")
        .arg(bundled("campro-omega-0.5.json"))
        .args(["--format", "json", "--random", "2000", "--lut-size", "4"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["holds"], false, "{v}");
    assert!(v["verdict"].as_str().unwrap().contains("this stack cannot hold the preset (up to"), "{v}");
}

#[test]
fn file_targets_convert_compare_and_refuse() {
    let dir = tempfile::tempdir().unwrap();
    let cube = dir.path().join("campro.cube");
    campro()
        .args(["convert"])
        .arg(bundled("srgb-passthrough.json"))
        .args(["--target", "cube", "--cube-size", "9", "-o"])
        .arg(&cube)
        .assert()
        .success();
    let text = std::fs::read_to_string(&cube).unwrap();
    assert_eq!(campro::targets::cube::parse_cube(&text).unwrap().size(), 9);
    let out = campro()
        .args(["compare"])
        .arg(bundled("srgb-passthrough.json"))
        .args(["--target", "cube", "--random", "500", "--format", "json"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["target"], "cube");
    assert_eq!(
        v["comparison"].as_array().unwrap().len(),
        8,
        "2 interpolations x 4 pixel sets (every grey level first)"
    );
    fails_with(campro().args(["convert"]).arg(bundled("identity.json")).args(["--target", "rkisp1"]), "--target cube");
    fails_with(campro().args(["convert"]).arg(bundled("identity.json")).args(["--target", "rpi-vc4"]), "--base");
    fails_with(campro().args(["convert"]).arg(bundled("identity.json")).args(["--target", "hald"]), "binary");
    // Nothing half-written on a refusal.
    fails_with(
        campro()
            .args(["convert"])
            .arg(bundled("identity.json"))
            .args(["--target", "uvc", "-o"])
            .arg(dir.path().join("x.json")),
        "scalar gamma",
    );
    assert!(!dir.path().join("x.json").exists());
}
