//! `eval`: every report, the privacy attacks on tiny data, the frontier, bad arguments.

use super::*;

/// `eval all` on a few images and identities: every report is written, laid out as stated.
#[test]
fn eval_all_with_a_limit_writes_every_report() {
    let Some(shared) = campro_testkit::shared_root(&[
        "models/yunet_s_640_640.onnx",
        "data/lfw/pairs.txt",
        "data/coco-person/instances_person.json",
    ]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ev");
    campro()
        .args(["eval", "all"])
        .arg(bundled("identity.json"))
        .arg(bundled("color-inversion.json"))
        .args(["--baseline", "lowres-8", "--limit", "4", "--runs", "2", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    for f in [
        "privacy.csv",
        "privacy.md",
        "verification.csv",
        "cmc.svg",
        "utility.csv",
        "quality.csv",
        "report.md",
        "tradeoff.svg",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let csv = |name: &str| -> Vec<Vec<String>> {
        std::fs::read_to_string(out.join(name))
            .unwrap()
            .lines()
            .map(|l| l.split(',').map(String::from).collect())
            .collect()
    };
    // Table I layout: dataset, order, image type, classifier, one column per model, average.
    let p = csv("privacy.csv");
    assert_eq!(p[0].join(","), "dataset,order,image_type,classifier,faceplugin,mobilefacenet-casia,average");
    assert_eq!(p.len(), 1 + 2 * 4 * 2, "2 orders x 4 image types x 2 classifiers");
    for row in &p[1..] {
        let v: Vec<f64> = row[4..].iter().map(|x| x.parse().unwrap()).collect();
        assert!(v.iter().all(|x| (0.0..=100.0).contains(x)));
        assert!((v[2] - (v[0] + v[1]) / 2.0).abs() < 0.01, "average column: {row:?}");
        if row[2] == "raw" {
            assert!(v[2] >= 75.0, "raw faces of 4 identities are recognised: {row:?}");
        }
    }
    let u = csv("utility.csv");
    assert_eq!(u.len(), 1 + 4);
    assert_eq!(u[1][0], "raw");
    // Quality compares protected images with raw: no raw row.
    let q = csv("quality.csv");
    assert_eq!(
        q.iter().skip(1).map(|r| r[0].as_str()).collect::<Vec<_>>(),
        ["identity", "color-inversion", "lowres-8"]
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("tradeoff.svg") && report.contains("| lowres-8 |"));
}

/// `eval privacy --distractors`: the probed identities and their gallery and probe photos
/// stay the same while the gallery grows, so under the nearest classifier no probe's rank
/// can improve: every CMC point is at most the one without distractors.
#[test]
fn privacy_distractors_only_enlarge_the_gallery() {
    let Some(shared) = campro_testkit::shared_root(&["models/yunet_s_640_640.onnx", "data/lfw/pairs.txt"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], out: &str| -> serde_json::Value {
        let out = dir.path().join(out);
        campro()
            .args(["eval", "privacy"])
            .args(["--condition", "colour"])
            .arg(bundled("color-inversion.json"))
            .args(["--limit", "4", "--runs", "3", "--no-verification", "--shared"])
            .arg(&shared)
            .args(extra)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        privacy_json(&out)
    };
    let (a, b) = (run(&[], "plain"), run(&["--distractors", "6"], "more"));
    assert_eq!(a["identities"], b["identities"]);
    assert_eq!(a["gallery"], a["identities"]);
    let (n, g) = (b["identities"].as_u64().unwrap(), b["gallery"].as_u64().unwrap());
    assert!(g > n && g <= n + 6, "gallery {g} for {n} probed identities and 6 distractors");
    let md = std::fs::read_to_string(dir.path().join("more/privacy.md")).unwrap();
    assert!(md.contains(&format!("gallery of {g} identities, {} of them distractors", g - n)), "{md}");
    assert!(md.contains(&format!("(chance {:.2}%)", 100.0 / g as f64)), "{md}");
    let rows = |v: &serde_json::Value| v["identification"].as_array().unwrap().clone();
    let (ra, rb) = (rows(&a), rows(&b));
    assert_eq!(ra.len(), rb.len());
    let mut compared = 0;
    for (x, y) in ra.iter().zip(&rb) {
        assert_eq!(
            (&x["condition"], &x["order"], &x["model"], &x["classifier"]),
            (&y["condition"], &y["order"], &y["model"], &y["classifier"])
        );
        if x["classifier"] == "nearest" {
            for (p, q) in x["cmc"].as_array().unwrap().iter().zip(y["cmc"].as_array().unwrap()) {
                assert!(q.as_f64().unwrap() <= p.as_f64().unwrap() + 1e-12, "{x} vs {y}");
            }
            compared += 1;
        }
    }
    assert_eq!(compared, 2 * 2 * 2, "2 conditions x 2 orders x 2 models");
    let bad = campro().args(["eval", "privacy", "--distractors", "many"]).output().unwrap();
    assert!(
        !bad.status.success()
            && String::from_utf8_lossy(&bad.stderr).contains("expected a count or `all`, got \"many\"")
    );
}

/// `eval privacy --restore`: each parameter set gets a "NAME restored" row. Colour inversion
/// is a bijection, so restoring it gives most of the raw accuracy back; baselines get none.
#[test]
fn privacy_restore_undoes_a_bijective_camera() {
    let Some(shared) = campro_testkit::shared_root(&[
        "models/yunet_s_640_640.onnx",
        "data/lfw/pairs.txt",
        "data/coco-person/instances_person.json",
    ]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    campro()
        .args(["eval", "privacy"])
        .args(["--condition", "colour"])
        .arg(bundled("color-inversion.json"))
        .args(["--baseline", "lowres-8", "--restore", "--limit", "8", "--runs", "3", "--no-verification", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let v = privacy_json(&out);
    let top1 = |cond: &str| -> f64 {
        let rows: Vec<f64> = v["identification"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["condition"] == cond && r["order"] == "paper" && r["classifier"] == "nearest")
            .map(|r| 100.0 * r["top1_mean"].as_f64().unwrap())
            .collect();
        assert_eq!(rows.len(), 2, "{cond}: one row per model");
        rows.iter().sum::<f64>() / 2.0
    };
    let (inverted, restored, raw) = (top1("color-inversion"), top1("color-inversion restored"), top1("raw"));
    assert!(restored > inverted + 30.0 && restored > 0.6 * raw, "inverted {inverted}, restored {restored}, raw {raw}");
    let names: Vec<&str> =
        v["identification"].as_array().unwrap().iter().map(|r| r["condition"].as_str().unwrap()).collect();
    assert!(!names.contains(&"lowres-8 restored"), "only parameter sets are restored");
}

/// `eval privacy --enrol camera`: the attacker enrols its gallery through the same camera.
/// The raw condition's scores cannot change (its camera is the identity). A camera that
/// outputs one grey for every pixel makes every protected face the same, so the nearest
/// classifier's ties leave it at chance, 1 / gallery, exactly; enrolled raw, the same
/// camera sends every probe to one gallery face. Colour inversion keeps identities apart,
/// so matching inverted to inverted identifies more than matching it to raw faces.
#[test]
fn privacy_camera_enrolment_matches_protected_to_protected() {
    let Some(shared) = campro_testkit::shared_root(&["models/yunet_s_640_640.onnx", "data/lfw/pairs.txt"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut flat: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(bundled("color-inversion.json")).unwrap()).unwrap();
    flat["name"] = "flat-grey".into();
    flat["tone_curve"]["y"] = serde_json::json!(vec![0.5; 32]);
    let flat_path = dir.path().join("flat-grey.json");
    std::fs::write(&flat_path, serde_json::to_string(&flat).unwrap()).unwrap();
    let run = |enrol: &str| -> serde_json::Value {
        let out = dir.path().join(enrol);
        campro()
            .args(["eval", "privacy"])
            .args(["--condition", "colour"])
            .arg(bundled("color-inversion.json"))
            .arg(&flat_path)
            .args(["--limit", "8", "--runs", "3", "--no-verification", "--enrol", enrol, "--shared"])
            .arg(&shared)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        let md = std::fs::read_to_string(out.join("privacy.md")).unwrap();
        assert!(md.contains(if enrol == "camera" { "Enrolled through the camera" } else { "Enrolled raw" }), "{md}");
        privacy_json(&out)
    };
    let (raw, cam) = (run("raw"), run("camera"));
    assert_eq!(cam["options"]["enrolment"], "camera");
    let rows = |v: &serde_json::Value, cond: &str, cls: &str| -> Vec<f64> {
        let r: Vec<f64> = v["identification"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["condition"] == cond && r["order"] == "paper" && r["classifier"] == cls)
            .map(|r| r["top1_mean"].as_f64().unwrap())
            .collect();
        assert_eq!(r.len(), 2, "{cond} {cls}: one row per model");
        r
    };
    for cls in ["nearest", "linear"] {
        assert_eq!(rows(&raw, "raw", cls), rows(&cam, "raw", cls), "the raw condition is enrolled the same either way");
    }
    let gallery = cam["gallery"].as_f64().unwrap();
    for t in rows(&cam, "flat-grey", "nearest") {
        assert!(
            (t - 1.0 / gallery).abs() < 1e-12,
            "flat camera enrolled through itself: {t}, chance {}",
            1.0 / gallery
        );
    }
    for t in rows(&raw, "flat-grey", "nearest") {
        assert!(t <= 1.0 / gallery + 1e-12, "every probe goes to the same gallery face: {t}");
    }
    let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    let (as_raw, as_cam) =
        (mean(rows(&raw, "color-inversion", "nearest")), mean(rows(&cam, "color-inversion", "nearest")));
    assert!(as_cam > as_raw + 0.2, "colour inversion enrolled raw {as_raw}, through the camera {as_cam}");
    let bad = campro().args(["eval", "privacy", "--enrol", "sideways"]).output().unwrap();
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("sideways"));
}

/// `--attack retrain` on tiny data: each face model is fine-tuned on colour-inverted faces of
/// identities the evaluation never probes, written beside its log, and scored on the same
/// probes as the plain rows.
#[test]
fn privacy_retrain_attack_fine_tunes_each_model_on_unprobed_identities() {
    let Some(shared) = campro_testkit::shared_root(&["models/yunet_s_640_640.onnx", "data/lfw/pairs.txt"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let probed = ["Colin_Powell", "George_W_Bush", "Gerhard_Schroeder", "Donald_Rumsfeld", "Ariel_Sharon"];
    let list = dir.path().join("probed.txt");
    std::fs::write(&list, probed.join("\n")).unwrap();
    let out = dir.path().join("ev");
    campro()
        .args(["eval", "privacy"])
        .args(["--condition", "colour"])
        .arg(bundled("color-inversion.json"))
        .arg("--identities")
        .arg(&list)
        .args(["--runs", "1", "--no-verification", "--attack", "retrain", "--retrain-identities", "6"])
        .args(["--retrain-photos", "3", "--retrain-epochs", "2", "--retrain-batch", "8", "--retrain-lr", "0.01"])
        .arg("--shared")
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let v = privacy_json(&out);
    let rows: Vec<&serde_json::Value> = v["identification"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["condition"] == "color-inversion retrained" && r["order"] == "paper")
        .collect();
    // Two models, two classifiers, rates in [0, 1].
    assert_eq!(rows.len(), 4, "{rows:?}");
    assert!(rows.iter().all(|r| (0.0..=1.0).contains(&r["top1_mean"].as_f64().unwrap())));
    for model in ["faceplugin", "mobilefacenet-casia"] {
        let file = |ext: &str| out.join(format!("retrain/color-inversion.{model}.{ext}"));
        assert!(file("onnx").is_file(), "{model}: no fine-tuned model");
        let rec: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(file("json")).unwrap()).unwrap();
        let names: Vec<&str> = rec["identities"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
        assert!(names.len() >= 2 && names.len() <= 6, "{names:?}");
        assert!(names.iter().all(|n| !probed.contains(n)), "trained on a probed identity: {names:?}");
        assert_eq!(rec["log"]["classes"].as_u64().unwrap() as usize, names.len());
        assert_eq!(rec["log"]["epoch_loss"].as_array().unwrap().len(), 2);
    }
    fails_with(
        campro().args(["eval", "privacy", "--attack", "retrain", "--limit", "3"]).arg("-o").arg(dir.path().join("x")),
        "--attack retrain needs --identities",
    );
}

#[test]
fn eval_refuses_bad_arguments_clearly() {
    let out = campro().args(["eval", "quality", "--baseline", "lowres-0"]).output().unwrap();
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("expected lowres-S (S ≥ 1)"));
    fails_with(
        campro().args(["eval", "quality", "--shared", "/nonexistent-shared"]),
        "/nonexistent-shared/data/coco-person/images",
    );
    fails_with(
        campro().args(["eval", "utility", "--person-detector", "nosuchmodel", "--shared", "/nonexistent-shared"]),
        "reading the COCO person set",
    );
    let Some(_) = campro_testkit::shared("data/coco-person/instances_person.json") else { return };
    let shared = campro_testkit::shared("").unwrap();
    fails_with(
        campro().args(["eval", "utility", "--person-detector", "nosuchmodel", "--shared"]).arg(&shared),
        "neither a bundled model",
    );
}

/// The privacy report an `eval privacy -o OUT` wrote.
fn privacy_json(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("privacy.json")).unwrap()).unwrap()
}

/// `eval frontier`: the plot and table of measured points; a bad CSV, a folder as the CSV
/// and an earlier run's output are refused in one line.
#[test]
fn eval_frontier_plots_the_points_and_refuses_bad_ones() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("p.csv"),
        "set,hours,top1,top1_attacked,ap_ratio\nslow,2.4,0.48,13.23,34\nfast,1.0,0.48,2.74,59\nfixed,,5,100,74\n",
    )
    .unwrap();
    campro().args(["eval", "frontier"]).arg(d.join("p.csv")).arg("-o").arg(d.join("f")).assert().success();
    let md = std::fs::read_to_string(d.join("f/frontier.md")).unwrap();
    // "slow" is beaten on both axes by "fast"; the other two are on the frontier.
    assert!(md.contains("| slow | 2.4 h | 0.48 | 13.23 | 34 |  |"), "{md}");
    assert!(
        md.contains("| fast | 1.0 h | 0.48 | 2.74 | 59 | yes |")
            && md.contains("| fixed | — | 5.00 | 100.00 | 74 | yes |")
    );
    assert!(std::fs::read_to_string(d.join("f/frontier.svg")).unwrap().contains("fast (1.0 h)"));
    let frontier = |csv: &Path, out: &str| {
        let mut c = campro();
        c.args(["eval", "frontier"]).arg(csv).arg("-o").arg(d.join(out));
        c
    };
    fails_with(&mut frontier(&d.join("p.csv"), "f"), "already holds files");
    std::fs::write(d.join("bad.csv"), "set,hours,top1,top1_attacked,ap_ratio\na,1,0.5,inf,60\n").unwrap();
    fails_with(&mut frontier(&d.join("bad.csv"), "g"), "line 2: top1_attacked must be a number in [0, 100]");
    fails_with(&mut frontier(d, "h"), "is a directory; only regular files are read");
}
