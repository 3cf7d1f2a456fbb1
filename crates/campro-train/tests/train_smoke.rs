//! A seconds-long run of the optimiser on a few LFW identities (skipped without ../shared,
//! required under CI=true): the protector's loss must fall and the frozen attacker's
//! accuracy through the camera must drop, and the result must be a valid camera.

use campro_testkit as shared;

use campro_train::config::Config;
use std::path::Path;

/// Five LFW identities (four classes, one held out), batch 8, no utility player, caching in
/// `cache`; None (skipped) without ../shared.
/// A checkpoint this test wrote, read back whole for inspection (the run itself reads it
/// through `checkpoint::load`, against its expected tensors).
fn read_checkpoint(
    dir: &Path,
) -> (std::collections::HashMap<String, candle_core::Tensor>, campro_train::checkpoint::State) {
    let t = candle_core::safetensors::load(dir.join("tensors.safetensors"), &candle_core::Device::Cpu).unwrap();
    let s = serde_json::from_slice(&std::fs::read(dir.join("state.json")).unwrap()).unwrap();
    (t, s)
}

fn tiny(cache: &Path) -> Option<Config> {
    let ckpt = shared::shared("models/mobilefacenet_casia_068.ckpt")?;
    let lfw = shared::shared("data/lfw/pairs.txt")?;
    let mut c = Config::default();
    c.attacker.checkpoint = ckpt.clone();
    c.protector.omega = 0.0;
    c.data.lfw = lfw.parent().unwrap().to_path_buf();
    c.data.models = ckpt.parent().unwrap().to_path_buf();
    c.data.max_identities = Some(5);
    c.data.batch = 8;
    c.data.cache = cache.to_path_buf();
    Some(c)
}

/// `tiny` with the privacy player alone (the paper's protector-only ablation), seed 1, the
/// camera at Adam `lr`.
fn protector_only(cache: &Path, lr: f64) -> Option<Config> {
    let mut c = tiny(cache)?;
    c.seed = 1;
    c.camera.lr = lr;
    c.attacker.pretrain_steps = 3;
    c.protector.protector_only = true;
    Some(c)
}

/// `tiny` with the utility player: ω = 1, YOLOX-Nano at 128 px on the first `images` COCO
/// person training images, two a step; None (skipped) without ../shared.
fn with_people(cache: &Path, images: usize) -> Option<Config> {
    let mut c = tiny(cache)?;
    let coco = shared::shared("data/coco-person/instances_person.json")?;
    c.detector.model = c.data.models.join("yolox_nano.onnx");
    c.detector.data = coco.parent().unwrap().to_path_buf();
    c.detector.size = 128;
    c.detector.batch = 2;
    c.detector.max_images = Some(images);
    c.protector.omega = 1.0;
    c.attacker.pretrain_steps = 2;
    Some(c)
}

#[test]
fn protector_defeats_a_frozen_attacker_on_a_tiny_set() {
    let cache = tempfile::tempdir().unwrap();
    let Some(mut c) = protector_only(cache.path(), 0.05) else { return };
    c.budget.rounds = 10;
    c.budget.checkpoint_every = 10;
    let ckpts = cache.path().join("ckpt");
    let opts = campro_train::train::RunOptions {
        checkpoints: Some(ckpts.clone()),
        resume: None,
        init: None,
        ..Default::default()
    };
    let out = campro_train::train::run(&c, &opts, |_| {}).unwrap();
    let rows = &out.log;
    assert_eq!(rows.len(), 11, "pretraining row + 10 rounds");
    let first: f64 = rows[1..4].iter().map(|r| r.privacy_loss).sum::<f64>() / 3.0;
    let last: f64 = rows[8..].iter().map(|r| r.privacy_loss).sum::<f64>() / 3.0;
    assert!(last < 0.5 * first, "L_ns {first} -> {last}");
    let (before, after) = (rows[0].check_accuracy.unwrap(), rows[10].check_accuracy.unwrap());
    assert!(after < before, "attacker check accuracy {before} -> {after}");
    assert!(
        out.ccm.iter().flatten().all(|v| v.abs() <= 5.0)
            && out.curves.iter().flatten().all(|v| (0.0..=1.0).contains(v))
    );
    assert_eq!((out.curves.len(), out.curves[0].len()), (1, 32));
    assert_eq!(out.provenance["config"]["seed"], 1);
    // The face set was cached: a second build reads it back identically.
    let sel = campro_train::faces::Selection {
        lfw: c.data.lfw.clone(),
        min_images: 5,
        validation_identities: 0.2,
        max_identities: Some(5),
        seed: 1,
        exclude: Vec::new(),
    };
    let a = campro_train::faces::FaceSet::load_or_build(&sel, &c.data.models, cache.path()).unwrap();
    // One face file and one class-means file (the means of the raw embeddings, keyed by
    // faces and checkpoint), nothing rebuilt beside them.
    let mut cached: Vec<String> = std::fs::read_dir(cache.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| p.file_name().unwrap().to_string_lossy().split('-').next().unwrap().to_string())
        .collect();
    cached.sort();
    assert_eq!(cached, ["faces", "means"]);
    // Resuming from the last checkpoint (round 10) for two more rounds starts where it ended:
    // same camera, so the same held-aside accuracy.
    // The checkpoint kept the log: the resumed run's log is the whole run's, rounds 0..=12,
    // its first 11 rows the first part's (NaN-valued fields included), seconds rising.
    c.budget.rounds = 12;
    let mut seen = Vec::new();
    let resumed = campro_train::train::run(
        &c,
        &campro_train::train::RunOptions {
            checkpoints: None,
            resume: Some(ckpts.clone()),
            init: None,
            ..Default::default()
        },
        |r| seen.push(r.clone()),
    )
    .unwrap();
    assert_eq!((seen[0].round, seen[0].check_accuracy), (10, Some(after)));
    assert_eq!(resumed.log.iter().map(|r| r.round).collect::<Vec<_>>(), (0..=12).collect::<Vec<_>>());
    let same = |a: f64, b: f64| a == b || (a.is_nan() && b.is_nan());
    for (a, b) in rows.iter().zip(&resumed.log) {
        assert!(
            same(a.seconds, b.seconds)
                && same(a.privacy_loss, b.privacy_loss)
                && same(a.detection_loss, b.detection_loss)
                && a.check_accuracy == b.check_accuracy,
            "{a:?} != {b:?}"
        );
    }
    assert!(resumed.log.windows(2).all(|w| w[1].seconds >= w[0].seconds));
    assert!(resumed.seconds >= out.seconds && resumed.provenance["rounds"] == 12);
    // A checkpoint of another seed is refused.
    let seed0 = c.seed;
    c.seed = seed0 + 1;
    let err = campro_train::train::run(
        &c,
        &campro_train::train::RunOptions {
            checkpoints: None,
            resume: Some(ckpts.clone()),
            init: None,
            ..Default::default()
        },
        |_| {},
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("another face set or seed"), "{err}");
    c.seed = seed0;
    let resume_err = |dir: &Path| {
        campro_train::train::run(
            &c,
            &campro_train::train::RunOptions { resume: Some(dir.to_path_buf()), ..Default::default() },
            |_| {},
        )
        .err()
        .unwrap()
        .to_string()
    };
    // Hostile checkpoints (issue 59, classes B and I), each a copy of the good one with one
    // change: a round counter at u64::MAX (it once wrapped to round 0 and restarted), and
    // a tensor file with one tensor more than the run has (it was read whole and accepted).
    let copy = |name: &str| {
        let d = cache.path().join(name);
        std::fs::create_dir_all(&d).unwrap();
        for f in ["state.json", "tensors.safetensors"] {
            std::fs::copy(ckpts.join(f), d.join(f)).unwrap();
        }
        d
    };
    let wrapped = copy("wrapped");
    let mut state: serde_json::Value =
        serde_json::from_slice(&std::fs::read(wrapped.join("state.json")).unwrap()).unwrap();
    state["round"] = serde_json::json!(u64::MAX);
    std::fs::write(wrapped.join("state.json"), serde_json::to_vec(&state).unwrap()).unwrap();
    let err = resume_err(&wrapped);
    assert!(err.contains("round 18446744073709551615, past budget.rounds 12"), "{err}");
    let extra = copy("extra");
    let mut tensors =
        candle_core::safetensors::load(extra.join("tensors.safetensors"), &candle_core::Device::Cpu).unwrap();
    tensors.insert(
        "smuggled".into(),
        candle_core::Tensor::zeros(1000, candle_core::DType::F32, &candle_core::Device::Cpu).unwrap(),
    );
    candle_core::safetensors::save(&tensors, extra.join("tensors.safetensors")).unwrap();
    let err = resume_err(&extra);
    assert!(err.contains("\"smuggled\" is not one this file may hold"), "{err}");
    let (losses, acc) = campro_train::log::plot_log(&out.log);
    assert!(losses.starts_with("<svg") && losses.contains("privacy") && acc.contains("held-aside"));
    assert_eq!((a.classes.len(), a.validation.len()), (4, 1));
    assert_eq!(a.len(), out.train_faces + out.check_faces);
}

/// The three players on tiny data: two COCO images at 128 px with the detector at Adam 1e-3
/// and ω = 1. Fed the same two images every round, the detection loss must fall (the
/// detector and camera fit them) while the privacy loss still runs; the fine-tuned detector
/// comes back and checkpoints hold it.
#[test]
fn the_utility_player_fits_its_images_beside_the_privacy_player() {
    let cache = tempfile::tempdir().unwrap();
    let Some(mut c) = with_people(cache.path(), 2) else { return };
    c.detector.lr = 1e-3;
    c.budget.rounds = 8;
    c.budget.checkpoint_every = 8;
    let ckpts = cache.path().join("ckpt");
    let out = campro_train::train::run(
        &c,
        &campro_train::train::RunOptions {
            checkpoints: Some(ckpts.clone()),
            resume: None,
            init: None,
            ..Default::default()
        },
        |_| {},
    )
    .unwrap();
    let det: Vec<f64> = out.log[1..].iter().map(|r| r.detection_loss).collect();
    assert!(det.iter().all(|v| v.is_finite() && *v > 0.0), "{det:?}");
    let (first, last) = ((det[0] + det[1]) / 2.0, (det[6] + det[7]) / 2.0);
    assert!(last < 0.8 * first, "L_det {first} -> {last}: {det:?}");
    assert!(out.log[1..].iter().all(|r| r.privacy_loss.is_finite()));
    assert!(out.log[0].detection_loss.is_nan(), "no detection loss before round 1");
    assert_eq!(out.provenance["data"]["person_images"], 2);
    let detector = out.detector.expect("the fine-tuned detector");
    let (tensors, _) = read_checkpoint(&ckpts);
    let stored = tensors.keys().filter(|k| k.starts_with("detector.")).count();
    assert_eq!(stored, detector.vars().len());
    // With a colour adapter in P: it trains and follows the camera (its output layer leaves
    // zero, where it starts) and the checkpoint holds it with the rest.
    let mut a = c.clone();
    a.detector.adapter = 4;
    let ckpts_a = cache.path().join("ckpt-a");
    let out = campro_train::train::run(
        &a,
        &campro_train::train::RunOptions {
            checkpoints: Some(ckpts_a.clone()),
            resume: None,
            init: None,
            ..Default::default()
        },
        |_| {},
    )
    .unwrap();
    let detector = out.detector.expect("the fine-tuned detector");
    let (adapter, _) = detector.adapter_and_rest();
    assert_eq!(adapter.len(), 4);
    let w2: Vec<f32> = adapter[2].as_tensor().flatten_all().unwrap().to_vec1().unwrap();
    assert!(w2.iter().any(|v| v.abs() > 1e-3), "{w2:?}");
    let (tensors, _) = read_checkpoint(&ckpts_a);
    assert_eq!(tensors.keys().filter(|k| k.starts_with("detector.")).count(), detector.vars().len());
    assert!(tensors.contains_key("detector.adapter.w2"));
    // Without a detector weight the detector is never loaded.
    c.protector.omega = 0.0;
    c.detector.model = "/nonexistent.onnx".into();
    c.budget.rounds = 1;
    assert!(campro_train::train::run(&c, &Default::default(), |_| {}).unwrap().detector.is_none());
    // --init: the camera starts at the given set (at a learning rate too small to move it in
    // one round, it ends there) and the provenance names it; a set of other knots is refused.
    let ccm = [[0.5, -1.0, 0.25], [2.0, 1.0, -0.5], [0.0, 0.125, 1.5]];
    let curve: Vec<f64> = (0..32).map(|i| ((i * 7) % 32) as f64 / 31.0).collect();
    let init = |curves: Vec<Vec<f64>>| campro_train::train::RunOptions {
        init: Some(campro_train::train::Initial { ccm, curves, gamma: 2.2, origin: "start.json".into() }),
        ..Default::default()
    };
    c.camera.lr = 1e-12;
    let out = campro_train::train::run(&c, &init(vec![curve.clone()]), |_| {}).unwrap();
    assert!(out.ccm.iter().flatten().zip(ccm.iter().flatten()).all(|(a, b)| (a - b).abs() < 1e-6), "{:?}", out.ccm);
    assert!(out.curves[0].iter().zip(&curve).all(|(a, b)| (a - b).abs() < 1e-6), "{:?}", out.curves);
    assert_eq!(out.provenance["init"], "start.json");
    let err = campro_train::train::run(&c, &init(vec![vec![0.0, 1.0, 0.5]]), |_| {}).err().unwrap().to_string();
    assert!(err.contains("3 curve knots") && err.contains("camera.knots is 32"), "{err}");
    // A curve per channel: a shared start continues as three equal curves, which learn
    // apart; three curves do not start a shared camera.
    c.camera.per_channel = true;
    c.camera.lr = 1e-2;
    let out = campro_train::train::run(&c, &init(vec![curve.clone()]), |_| {}).unwrap();
    assert_eq!(out.curves.len(), 3);
    assert!(out.curves.iter().all(|row| row.len() == 32 && row.iter().all(|v| (0.0..=1.0).contains(v))));
    assert!(out.curves[0] != out.curves[1] || out.curves[1] != out.curves[2], "the channels' curves moved apart");
    let p = out.params(&c, "per-channel", "tiny.toml").unwrap();
    assert!(p.tone_curves.shared().is_none());
    let back = campro::Params::from_json(&p.to_json()).unwrap();
    assert_eq!(back.tone_curves, p.tone_curves);
    c.camera.per_channel = false;
    let err = campro_train::train::run(&c, &init(out.curves.clone()), |_| {}).err().unwrap().to_string();
    assert!(err.contains("camera.per_channel is false"), "{err}");
}

#[test]
fn a_diverging_run_stops_with_a_named_error_and_no_parameters() {
    let cache = tempfile::tempdir().unwrap();
    let Some(mut c) = tiny(cache.path()) else { return };
    // Steps that overflow f32: weights reach inf, then inf − inf.
    c.attacker.lr = 1e36;
    c.attacker.backbone_lr = 1e36;
    c.attacker.pretrain_steps = 5;
    c.budget.rounds = 5;
    let err =
        campro_train::train::run(&c, &Default::default(), |_| {}).err().expect("a learning rate of 1e36 diverges");
    assert!(matches!(err, campro_train::TrainError::Diverged(_)), "{err}");
    assert!(err.to_string().contains("is NaN") || err.to_string().contains("is inf"), "{err}");
}

#[test]
fn attacker_and_protector_alternate_and_the_attacker_loses_ground() {
    let cache = tempfile::tempdir().unwrap();
    let Some(mut c) = tiny(cache.path()) else { return };
    c.seed = 1;
    c.camera.lr = 0.05;
    c.attacker.pretrain_steps = 5;
    c.budget.rounds = 8;
    c.budget.checkpoint_every = 8;
    let out = campro_train::train::run(&c, &Default::default(), |_| {}).unwrap();
    let rows = &out.log;
    assert!(rows[1..].iter().all(|r| r.attacker_ce.is_finite() && r.privacy_loss.is_finite()));
    // The attacker keeps training on C(x), yet the protector drives its loss up.
    let (first, last) = (rows[0].attacker_ce, rows[6..].iter().map(|r| r.attacker_ce).fold(0.0, f64::max));
    assert!(last > 10.0 * first.max(1e-4), "attacker CE {first} -> {last}");
    assert!(rows[8].privacy_loss < rows[1].privacy_loss);
}

/// The validation-driven stop on tiny data (privacy player only, so privacy alone ranks
/// cameras): validated every 2 rounds, patience 3. The camera kept is the first with the
/// lowest validation top-1 in the log, the run stops at the third validation after it that
/// is no better, and the parameters written are the kept camera's, not the last one's.
#[test]
fn the_run_keeps_its_best_validated_camera_and_stops_when_none_is_better() {
    let cache = tempfile::tempdir().unwrap();
    let Some(mut c) = protector_only(cache.path(), 0.1) else { return };
    c.budget.rounds = 100;
    c.budget.checkpoint_every = 1000;
    c.validation.every = 2;
    c.validation.patience = 3;
    let ckpts = cache.path().join("ckpt");
    let opts = campro_train::train::RunOptions {
        checkpoints: Some(ckpts.clone()),
        resume: None,
        init: None,
        ..Default::default()
    };
    let out = campro_train::train::run(&c, &opts, |_| {}).unwrap();
    let validated: Vec<(usize, f64)> = out.log.iter().filter_map(|r| r.validation_top1.map(|t| (r.round, t))).collect();
    // Rounds 0, 2, 4, ...: every validation is in the log, none with an AP (ω = 0).
    assert!(validated.iter().enumerate().all(|(i, &(r, _))| r == 2 * i), "{validated:?}");
    assert!(out.log.iter().all(|r| r.validation_ap.is_none()));
    let min = validated.iter().map(|v| v.1).fold(f64::INFINITY, f64::min);
    let best_round = validated.iter().find(|v| v.1 == min).unwrap().0;
    let v = &out.provenance["validation"];
    assert_eq!(v["best_round"], best_round, "{validated:?}");
    assert!(min < validated[0].1, "the camera became more private: {validated:?}");
    // Patience 3: the run ended at the third validation after the best one.
    let last = out.log.last().unwrap().round;
    assert_eq!(v["stopped_early"], true, "{validated:?}");
    assert_eq!(last, best_round + 6, "{validated:?}");
    // The written camera is the best one, which the checkpoint holds as best.*, beside the
    // last camera (which differs: the camera moved for six more rounds).
    let (t, state) = read_checkpoint(&ckpts);
    assert_eq!(state.round, last);
    assert_eq!(state.best.map(|b| (b.round, b.stale)), Some((best_round, 3)));
    let flat = |name: &str| -> Vec<f64> {
        t[name].flatten_all().unwrap().to_dtype(candle_core::DType::F64).unwrap().to_vec1().unwrap()
    };
    let written: Vec<f64> = out.ccm.iter().flatten().copied().collect();
    let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6);
    assert!(close(&written, &flat("best.camera.ccm")), "{written:?}");
    assert!(close(&out.curves.concat(), &flat("best.camera.curve")));
    assert!(!close(&written, &flat("camera.ccm")) || !close(&out.curves.concat(), &flat("camera.curve")));
    // A resumed run reads the best camera back and keeps it unless a later one is better.
    c.validation.patience = 0;
    c.budget.rounds = last + 2;
    let resumed = campro_train::train::run(
        &c,
        &campro_train::train::RunOptions { checkpoints: None, resume: Some(ckpts), init: None, ..Default::default() },
        |_| {},
    )
    .unwrap();
    let r = &resumed.provenance["validation"];
    let after = resumed.log.last().unwrap().validation_top1.unwrap();
    if after < min {
        assert_eq!(r["best_round"], last + 2);
    } else {
        assert_eq!(r["best_round"], best_round);
        assert!(close(&resumed.ccm.iter().flatten().copied().collect::<Vec<_>>(), &written));
    }
    assert_eq!(r["stopped_early"], false);
}

/// With a utility player, validation also scores person AP on training images set aside
/// from the draw: the last `validation.images` of them; asking for all of them is refused
/// with the key named.
#[test]
fn validation_sets_person_images_aside_and_scores_their_ap() {
    let cache = tempfile::tempdir().unwrap();
    let Some(mut c) = with_people(cache.path(), 4) else { return };
    c.budget.rounds = 4;
    c.validation.every = 2;
    c.validation.images = 2;
    let out = campro_train::train::run(&c, &Default::default(), |_| {}).unwrap();
    let aps: Vec<(usize, f64)> = out.log.iter().filter_map(|r| r.validation_ap.map(|a| (r.round, a))).collect();
    assert_eq!(aps.iter().map(|a| a.0).collect::<Vec<_>>(), [0, 2, 4]);
    assert!(aps.iter().all(|a| (0.0..=1.0).contains(&a.1)), "{aps:?}");
    // YOLOX-Nano finds people at 128 px on the unprotected start: its AP is not nil.
    assert!(aps[0].1 > 0.0, "{aps:?}");
    let v = &out.provenance["validation"];
    assert_eq!(
        (v["person_images_set_aside"].as_u64(), out.provenance["data"]["person_images"].as_u64()),
        (Some(2), Some(4))
    );
    c.validation.images = 4;
    let err = campro_train::train::run(&c, &Default::default(), |_| {}).err().unwrap().to_string();
    assert!(err.contains("validation.images") && err.contains("none to train on"), "{err}");
}
