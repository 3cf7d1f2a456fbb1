//! Presets by name, from any folder (issue 45): the bundled presets are in the binary.

mod common;

use common::{bundled, campro, fails_with};

fn photo(dir: &std::path::Path) -> std::path::PathBuf {
    let p = dir.join("photo.png");
    image::RgbImage::from_fn(24, 16, |x, y| image::Rgb([(x * 10) as u8, (y * 15) as u8, 90]))
        .save_with_format(&p, image::ImageFormat::Png)
        .unwrap();
    p
}

#[test]
fn a_bundled_preset_works_by_name_from_an_empty_folder() {
    let dir = tempfile::tempdir().unwrap();
    let input = photo(dir.path());
    let run = |args: &[&str], out: &str| {
        campro().current_dir(dir.path()).arg("simulate").args(args).arg(&input).arg("-o").arg(out).assert().success();
        image::open(dir.path().join(out).join("photo.png")).unwrap().to_rgb8()
    };
    let by_name = run(&["campro-omega-0.5"], "a");
    let by_json_name = run(&["campro-omega-0.5.json"], "b");
    let by_file = run(&[bundled("campro-omega-0.5.json").to_str().unwrap()], "c");
    assert_eq!(by_name, by_file);
    assert_eq!(by_json_name, by_file);
    // --enhance finds the bundled preset's enhancer, and gives what the file beside it gives
    // (its face guard's detector is in the shared models).
    let Some(models) = campro_testkit::shared("models/yunet_s_640_640.onnx") else { return };
    let models = models.parent().unwrap().to_str().unwrap();
    let enhanced = run(&["campro-omega-0.5", "--enhance", "--models", models], "d");
    let enhanced_file =
        run(&[bundled("campro-omega-0.5.json").to_str().unwrap(), "--enhance", "--models", models], "e");
    assert_eq!(enhanced, enhanced_file);
    assert_ne!(enhanced, by_name);
}

#[test]
fn a_copied_preset_with_its_enhancer_beside_it_still_works_and_a_local_file_wins() {
    let dir = tempfile::tempdir().unwrap();
    let input = photo(dir.path());
    std::fs::copy(bundled("campro-omega-0.5.json"), dir.path().join("mine.json")).unwrap();
    std::fs::copy(bundled("campro-omega-0.5.enhancer.onnx"), dir.path().join("campro-omega-0.5.enhancer.onnx"))
        .unwrap();
    let Some(models) = campro_testkit::shared("models/yunet_s_640_640.onnx") else { return };
    campro()
        .current_dir(dir.path())
        .args(["simulate", "mine.json", "--enhance", "--models"])
        .arg(models.parent().unwrap())
        .arg(&input)
        .args(["-o", "o"])
        .assert()
        .success();
    // A file named like a preset in the working folder is the file, not the preset.
    std::fs::copy(bundled("identity.json"), dir.path().join("campro-omega-1")).unwrap();
    campro()
        .current_dir(dir.path())
        .args(["simulate", "campro-omega-1"])
        .arg(&input)
        .args(["-o", "p"])
        .assert()
        .success();
    campro()
        .current_dir(dir.path())
        .arg("simulate")
        .arg(bundled("identity.json"))
        .arg(&input)
        .args(["-o", "q"])
        .assert()
        .success();
    let read = |d: &str| image::open(dir.path().join(d).join("photo.png")).unwrap().to_rgb8();
    assert_eq!(read("p"), read("q"), "the local identity file was used, not the preset");
}

#[test]
fn presets_are_listed_with_their_line_and_unknown_names_list_them() {
    let out = campro().arg("presets").output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for name in
        ["campro-omega-0.5 (with enhancer)", "campro-omega-0.5-hour (with enhancer)", "identity", "color-inversion"]
    {
        assert!(text.contains(name), "{name} missing from {text}");
    }
    let json = campro().args(["presets", "--format", "json"]).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    // One a parameter file of the repository's params/.
    let files = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../../params"))
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "json"))
        .count();
    assert_eq!((v.as_array().unwrap().len(), files), (9, 9));
    assert!(v[0]["description"].as_str().is_some_and(|d| !d.is_empty()));
    // No bundled preset is rated for grey input yet, and each says so.
    assert!(v.as_array().unwrap().iter().all(|p| p["ratedForGrey"] == false), "{v}");
    assert_eq!(text.matches("Not rated for grey input").count(), 9, "{text}");
    // Each says in plain words what to pick it for, the unprotected ones that they protect nothing.
    assert!(text.contains("campro-omega-0.5 (with enhancer)\n    Pick this for everyday use"), "{text}");
    assert_eq!(text.matches("\n    No protection:").count(), 3, "{text}");
    // Protective: the four rated within the threshold; the other five say they are not.
    let protective: Vec<&str> =
        v.as_array().unwrap().iter().filter(|p| p["protective"] == true).map(|p| p["name"].as_str().unwrap()).collect();
    assert_eq!(
        protective,
        ["campro-omega-0.5", "campro-omega-0.5-distill", "campro-omega-0.5-hour", "campro-omega-1-shared-continued"]
    );
    assert_eq!(text.matches("\n    Not protective:").count(), 5, "{text}");
    assert!(v.as_array().unwrap().iter().all(|p| p["pick"].as_str().is_some_and(|s| s.len() > 20)), "{v}");
    fails_with(
        campro().args(["validate", "no-such-preset"]),
        "not a bundled preset (campro presets lists them: campro-omega-0.5",
    );
    // A slip in a name (a dot counts as an ending, case, a missing dash): the nearest name.
    for typed in ["campro-omega0.5", "Campro-Omega-0.5-Hour", "campro-omega-05.json"] {
        let want = if typed.contains("Hour") {
            "did you mean campro-omega-0.5-hour?"
        } else {
            "did you mean campro-omega-0.5?"
        };
        fails_with(campro().args(["validate", typed]), want);
    }
    // Arguments swapped: the folder of photos where the preset goes.
    let dir = tempfile::tempdir().unwrap();
    fails_with(
        campro().arg("simulate").arg(dir.path()).arg("campro-omega-0.5").arg("-o").arg(dir.path().join("o")),
        "is a folder; the parameter set (a preset from campro presets, or a .json file) comes first",
    );
    fails_with(
        campro().args(["simulate", "identity", "x.png", "-o", "o", "--enhance"]),
        "identity: this bundled preset has no enhancer",
    );
}

#[test]
fn usage_errors_say_what_is_missing_and_what_was_meant() {
    let out = campro().args(["simulate", "identity", "photos"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2));
    assert!(err.contains("--output"), "the missing -o is named: {err}");
    assert!(err.contains("Usage: campro simulate"), "{err}");
    let out = campro().output().unwrap();
    let all = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    for cmd in ["simulate", "convert", "presets", "demo"] {
        assert!(all.contains(cmd), "a bare campro lists {cmd}: {all}");
    }
    let out = campro().args(["simulat"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("tip: a similar subcommand exists: 'simulate'"), "{err}");
    let out = campro().args(["convert", "identity", "--target", "rpi"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("rpi-pisp") && err.contains("camera2"), "valid targets listed: {err}");
    assert!(!err.contains('\u{1b}'), "{err:?}");
}

#[test]
fn convert_says_what_a_target_costs_and_refuses_kotlin_where_there_is_none() {
    let dir = tempfile::tempdir().unwrap();
    let out = campro()
        .args(["convert", "campro-omega-0.5", "--target", "cube", "--cube-size", "33", "-o"])
        .arg(dir.path().join("a.cube"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("measured against the desktop pipeline: up to"), "{err}");
    // A 2-point cube cannot hold the curve: said as a warning with the size of the error.
    let out = campro()
        .args(["convert", "campro-omega-0.5", "--target", "cube", "--cube-size", "2", "-o"])
        .arg(dir.path().join("b.cube"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("warning: --target cube errs by up to"), "{err}");
    fails_with(
        campro().args(["convert", "identity", "--target", "cube", "--format", "kotlin"]),
        "--format kotlin: only --target camera2 has a Kotlin form",
    );
    // Camera2 without a device transform: the assumption is said, with how to give a phone's.
    let out = campro().args(["convert", "campro-omega-0.5"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("no device transform given, so the identity was assumed"), "{err}");
    assert!(err.contains("--capture-result result.json"), "{err}");
    let out = campro()
        .args([
            "convert",
            "campro-omega-0.5",
            "--device-ccm",
            "1.6",
            "-0.4",
            "-0.2",
            "-0.2",
            "1.5",
            "-0.3",
            "0",
            "-0.5",
            "1.5",
        ])
        .output()
        .unwrap();
    assert!(out.status.success() && !String::from_utf8_lossy(&out.stderr).contains("identity was assumed"));
}

#[test]
fn inspect_says_where_its_models_come_from() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("look");
    fails_with(
        campro()
            .env("CAMPRO_SHARED", dir.path().join("nowhere"))
            .args(["inspect", "campro-omega-0.5", "photo.png", "-o"])
            .arg(&out),
        "`campro models fetch` installs the models a registry has",
    );
}

#[test]
fn re_runs_skip_what_is_there_and_json_says_what_happened() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir(&inp).unwrap();
    photo(&inp);
    std::fs::copy(inp.join("photo.png"), inp.join("second.png")).unwrap();
    std::fs::write(inp.join("broken.png"), b"not a png").unwrap();
    let out = dir.path().join("out");
    let run = |extra: &[&str]| {
        let o = campro().arg("simulate").arg("identity").arg(&inp).arg("-o").arg(&out).args(extra).output().unwrap();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or(serde_json::Value::Null);
        (o.status.success(), v, String::from_utf8_lossy(&o.stderr).to_string())
    };
    let (ok, v, _) = run(&["--format", "json"]);
    assert!(!ok, "the broken file fails the run");
    assert_eq!(
        (v["written"].as_u64(), v["skipped"].as_u64(), v["failed"].as_u64()),
        (Some(2), Some(0), Some(1)),
        "{v}"
    );
    let files = v["files"].as_array().unwrap();
    assert_eq!(files.len(), 3);
    let broken = files.iter().find(|f| f["input"].as_str().unwrap().ends_with("broken.png")).unwrap();
    assert_eq!(broken["status"], "failed");
    assert!(broken["error"].as_str().unwrap().contains("broken.png"));
    assert!(files.iter().all(|f| f["ms"].as_f64().is_some_and(|ms| ms >= 0.0)));
    // A plain re-run refuses the existing outputs; --skip-existing leaves them and redoes nothing.
    let before = std::fs::metadata(out.join("photo.png")).unwrap().modified().unwrap();
    let (ok, _, err) = run(&[]);
    assert!(!ok && err.contains("--skip-existing"), "{err}");
    // One line for the run, not one a file.
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("exists, and 2 of 3 outputs in all") && err.contains("nothing was written"), "{err}");
    std::fs::remove_file(inp.join("broken.png")).unwrap();
    let (ok, v, err) = run(&["--skip-existing", "--format", "json"]);
    assert!(ok, "{err}");
    assert_eq!((v["written"].as_u64(), v["skipped"].as_u64()), (Some(0), Some(2)), "{v}");
    assert!(err.contains("2 skipped: already there"), "{err}");
    assert_eq!(std::fs::metadata(out.join("photo.png")).unwrap().modified().unwrap(), before);
    fails_with(
        campro().arg("simulate").arg("identity").arg(&inp).arg("-o").arg(&out).args(["--skip-existing", "--force"]),
        "cannot be used with",
    );
}

/// A preset's name works as `--identities` too (its held-out validation identities), from
/// a folder outside the repository, exactly as the file does.
#[test]
fn a_presets_name_gives_its_held_out_identities() {
    let Some(lfw) = campro_testkit::shared("data/lfw/pairs.txt") else { return };
    let shared = lfw.parent().unwrap().parent().unwrap().parent().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut reports = Vec::new();
    for (k, identities) in [bundled("campro-omega-0.5.json"), "campro-omega-0.5".into()].iter().enumerate() {
        let out = dir.path().join(format!("p{k}"));
        campro()
            .current_dir(dir.path())
            .args(["eval", "privacy", "campro-omega-0.5", "--identities"])
            .arg(identities)
            .args(["--condition", "colour", "--limit", "3", "--runs", "1", "--no-verification", "--shared"])
            .arg(shared)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("privacy.json")).unwrap()).unwrap();
        assert!(!v["identification"].is_null(), "{v}");
        reports.push(v["identification"].clone());
    }
    assert_eq!(reports[0], reports[1], "the name and the file give the same evaluation");
    fails_with(
        campro()
            .current_dir(dir.path())
            .args(["eval", "privacy", "campro-omega-0.5", "--identities", "no-such-list", "--shared"])
            .arg(shared),
        "no-such-list",
    );
}
