//! `train` and `finetune-detector` on tiny data, and the bundled presets' own detectors.

use super::*;

/// `train` with all three players on tiny data writes a parameter set, the fine-tuned
/// detector (ONNX + manifest) beside it and the log; `eval utility` runs that detector and
/// `eval privacy --identities` scores only the identities the run held out.
#[test]
fn train_writes_params_and_detector_that_eval_reads() {
    let Some(models) = campro_testkit::shared("models/yolox_nano.onnx") else { return };
    let Some(lfw) = campro_testkit::shared("data/lfw/pairs.txt") else { return };
    let Some(coco) = campro_testkit::shared("data/coco-person/instances_person.json") else { return };
    let shared = models.parent().unwrap().parent().unwrap().to_path_buf();
    let dir = tempfile::tempdir().unwrap();
    let q = |p: &std::path::Path| format!("{:?}", p.to_str().unwrap());
    let cfg = format!(
        "[attacker]\ncheckpoint = {}\npretrain_steps = 2\n[protector]\nomega = 1.0\n[data]\nlfw = {}\nmodels = {}\nmax_identities = 5\nbatch = 8\ncache = {}\n[detector]\nmodel = {}\ndata = {}\nsize = 128\nbatch = 2\nmax_images = 2\n[budget]\nrounds = 2\n",
        q(&models.with_file_name("mobilefacenet_casia_068.ckpt")),
        q(lfw.parent().unwrap()),
        q(models.parent().unwrap()),
        q(&dir.path().join("cache")),
        q(&models),
        q(coco.parent().unwrap())
    );
    std::fs::write(dir.path().join("tiny.toml"), cfg).unwrap();
    let p = dir.path().join("p.json");
    campro()
        .arg("train")
        .arg(dir.path().join("tiny.toml"))
        .arg("-o")
        .arg(&p)
        .arg("--log")
        .arg(dir.path().join("log.csv"))
        .assert()
        .success();
    campro().arg("validate").arg(&p).assert().success();
    let log = std::fs::read_to_string(dir.path().join("log.csv")).unwrap();
    assert!(
        log.starts_with(
            "round,seconds,attacker_ce,attacker_accuracy,privacy_loss,detection_loss,check_accuracy,validation_top1,validation_ap\n"
        )
            && log.lines().count() == 4,
        "{log}"
    );
    let manifest = dir.path().join("p.detector.json");
    assert!(dir.path().join("p.detector.onnx").is_file() && manifest.is_file());
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    assert_eq!(v["provenance"]["detector"]["onnx"], "p.detector.onnx");
    let held_out = v["provenance"]["data"]["validation_identities"].as_array().unwrap().len();
    assert_eq!(held_out, 1);
    // Run from another folder: the manifest finds its ONNX beside itself.
    let out = dir.path().join("ev");
    campro()
        .current_dir("/")
        .args(["eval", "utility"])
        .arg(&p)
        .arg("--person-detector")
        .arg(&manifest)
        .args(["--limit", "2", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    assert!(std::fs::read_to_string(out.join("utility.md")).unwrap().contains("fine-tuned (p)"));
    // --own-detector: raw with the bundled detector, p with its own, rows in order.
    let md = own_detector_utility(&p, &shared, &out);
    assert!(md.contains("yolox-nano; p each with its own fine-tuned detector"), "{md}");
    assert!(md.contains("2 images (those held out of detector fine-tuning: COCO id % 5 == 0)"), "{md}");
    let scored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("utility.json")).unwrap()).unwrap();
    assert_eq!(scored["options"]["held_out"], true);
    let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| raw") || l.starts_with("| p ")).collect();
    assert_eq!(rows.len(), 2, "{md}");
    assert!(rows[0].starts_with("| raw"));
    campro()
        .args(["eval", "privacy"])
        .args(["--condition", "colour"])
        .arg(&p)
        .arg("--identities")
        .arg(&p)
        .args(["--runs", "1", "--no-verification", "--force", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    assert!(std::fs::read_to_string(out.join("privacy.md")).unwrap().contains("Closed set: 1 identities"));
    let names = dir.path().join("names.txt");
    std::fs::write(&names, "# two people\nNo_Such_Person\n").unwrap();
    fails_with(
        campro()
            .args(["eval", "privacy"])
            .arg(&p)
            .arg("--identities")
            .arg(&names)
            .args(["--force", "--shared"])
            .arg(&shared)
            .arg("-o")
            .arg(&out),
        "\"No_Such_Person\" is not in LFW",
    );
}

/// The bundled presets' own detectors: by name from any folder (built into the binary),
/// and from the repository's parameter file (the ONNX file beside it, no manifest).
#[test]
fn a_bundled_preset_s_own_detector_is_built_in() {
    let Some(models) = campro_testkit::shared("models/yolox_nano.onnx") else { return };
    let shared = models.parent().unwrap().parent().unwrap().to_path_buf();
    let dir = tempfile::tempdir().unwrap();
    let file = campro_testkit::workspace_root().join("params/campro-omega-0.5.json");
    for (k, preset) in [std::ffi::OsStr::new("campro-omega-0.5"), file.as_os_str()].into_iter().enumerate() {
        let out = dir.path().join(format!("ev{k}"));
        let run = campro()
            .current_dir(dir.path())
            .args(["eval", "utility"])
            .arg(preset)
            .args(["--own-detector", "--limit", "2", "--shared"])
            .arg(&shared)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        let err = String::from_utf8_lossy(&run.get_output().stderr).into_owned();
        let said = if k == 0 { "(built in)" } else { "campro-omega-0.5.detector.onnx" };
        assert!(err.contains("loading yolox-nano fine-tuned (campro-omega-0.5)") && err.contains(said), "{err}");
        let md = std::fs::read_to_string(out.join("utility.md")).unwrap();
        assert!(md.contains("campro-omega-0.5 each with its own fine-tuned detector"), "{md}");
    }
}

#[test]
fn finetune_detector_writes_a_detector_for_any_params_and_records_it() {
    let Some(models) = campro_testkit::shared("models/yolox_nano.onnx") else { return };
    let Some(coco) = campro_testkit::shared("data/coco-person/instances_person.json") else { return };
    let shared = models.parent().unwrap().parent().unwrap().to_path_buf();
    let dir = tempfile::tempdir().unwrap();
    let q = |p: &std::path::Path| format!("{:?}", p.to_str().unwrap());
    let cfg = format!(
        "seed = 3\n[detector]\nmodel = {}\ndata = {}\nsize = 128\nbatch = 2\nmax_images = 2\n",
        q(&models),
        q(coco.parent().unwrap())
    );
    std::fs::write(dir.path().join("ft.toml"), cfg).unwrap();
    let p = dir.path().join("inv.json");
    std::fs::copy(campro_testkit::workspace_root().join("params/campro-omega-1.json"), &p).unwrap();
    let before: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    let run = || {
        let mut c = campro();
        c.arg("finetune-detector")
            .arg(&p)
            .arg("--config")
            .arg(dir.path().join("ft.toml"))
            .args(["--steps", "2", "--log"])
            .arg(dir.path().join("ft.csv"));
        c
    };
    run().assert().success();
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    assert_eq!(v["ccm"], before["ccm"], "the camera is not touched");
    let d = &v["provenance"]["detector"];
    assert_eq!((d["onnx"].as_str(), d["manifest"].as_str()), (Some("inv.detector.onnx"), Some("inv.detector.json")));
    assert_eq!(
        (d["finetune"]["steps"].as_u64(), d["finetune"]["images"].as_u64(), d["finetune"]["seed"].as_u64()),
        (Some(2), Some(2), Some(3))
    );
    assert!(d["held_out_images"].as_str().unwrap().contains("% 5 == 0"));
    assert_eq!(std::fs::read_to_string(dir.path().join("ft.csv")).unwrap().lines().count(), 3);
    // Written at half precision: YOLOX-Nano's 3.66 MB of f32 weights in under 2 MB (the
    // repository's file limit, so presets ship theirs).
    let written = std::fs::metadata(dir.path().join("inv.detector.onnx")).unwrap().len();
    assert!(written < 2_000_000 && written > 1_700_000, "{written} bytes");
    // A written (half-precision) detector is a starting point for more fine-tuning.
    let again = dir.path().join("again.toml");
    let first = dir.path().join("first.detector.onnx");
    std::fs::copy(dir.path().join("inv.detector.onnx"), &first).unwrap();
    std::fs::write(
        &again,
        std::fs::read_to_string(dir.path().join("ft.toml")).unwrap().replace(&q(&models), &q(&first)),
    )
    .unwrap();
    let twice = dir.path().join("twice.json");
    std::fs::copy(&p, &twice).unwrap();
    campro().arg("finetune-detector").arg(&twice).arg("--config").arg(&again).args(["--steps", "1"]).assert().success();
    // Existing outputs are kept unless --force.
    fails_with(&mut run(), "exists (use --force");
    run().arg("--force").assert().success();
    let out = dir.path().join("ev");
    assert!(own_detector_utility(&p, &shared, &out).contains("inv each with its own fine-tuned detector"));
    fails_with(campro().arg("finetune-detector").arg(&p).args(["--steps", "0"]), "0 is not in 1..=10000000");
    fails_with(campro().arg("finetune-detector").arg(&p).args(["--seconds", "NaN"]), "--seconds: must be > 0");
    // A curve with uneven knots cannot drive the optimiser's camera.
    let uneven = dir.path().join("uneven.json");
    let mut u = before.clone();
    u["tone_curve"] = serde_json::json!({ "x": [0.0, 0.3, 1.0], "y": [0.0, 0.5, 1.0] });
    std::fs::write(&uneven, u.to_string()).unwrap();
    fails_with(
        campro()
            .arg("finetune-detector")
            .arg(&uneven)
            .arg("--config")
            .arg(dir.path().join("ft.toml"))
            .args(["--steps", "1"]),
        "tone_curve: the optimiser's camera needs evenly spaced knots",
    );
    // ... nor start it (train --init), which also excludes --resume; no output is written.
    let trained = dir.path().join("t.json");
    let train = |init: &Path| {
        let mut c = campro();
        c.arg("train").arg(dir.path().join("ft.toml")).arg("--init").arg(init).arg("-o").arg(&trained);
        c
    };
    fails_with(&mut train(&uneven), "tone_curve: the optimiser's camera needs evenly spaced knots");
    let both = train(&p).arg("--resume").arg(dir.path()).output().unwrap();
    assert!(
        !both.status.success()
            && String::from_utf8_lossy(&both.stderr)
                .contains("'--init <INIT>' cannot be used with '--resume <RESUME>'")
    );
    assert!(!trained.exists());
}

/// `eval utility PARAMS --own-detector` on two held-out images into `out` (replacing what is
/// there); its `utility.md`.
fn own_detector_utility(params: &Path, shared: &Path, out: &Path) -> String {
    campro()
        .args(["eval", "utility"])
        .arg(params)
        .args(["--own-detector", "--limit", "2", "--force", "--shared"])
        .arg(shared)
        .arg("-o")
        .arg(out)
        .assert()
        .success();
    std::fs::read_to_string(out.join("utility.md")).unwrap()
}
