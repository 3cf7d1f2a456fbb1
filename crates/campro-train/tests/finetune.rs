//! The detector's own split of the COCO person set and the post-hoc fine-tune behind a fixed
//! camera (skipped without ../shared, required under CI=true).

use campro_testkit as shared;

use campro_eval::data::{coco_person, detector_held_out};
use campro_train::config::DetectorConfig;
use campro_train::finetune::{run, FinetuneOptions, Imaging};
use campro_train::persons::PersonSet;

#[test]
fn training_never_sees_the_held_out_images() {
    let Some(coco) = shared::shared("data/coco-person/instances_person.json") else { return };
    let root = coco.parent().unwrap();
    let all = coco_person(root).unwrap();
    let set = PersonSet::open(root, 320, None).unwrap();
    assert!(set.images.iter().all(|im| im.id % 5 != 0));
    let held = all.iter().filter(|im| im.id % 5 == 0).count();
    assert_eq!(set.len() + held, all.len());
    assert!(held * 6 > all.len() && held * 4 < all.len(), "about a fifth held out: {held} of {}", all.len());
    assert!(detector_held_out(10) && !detector_held_out(11) && detector_held_out(0));
    // `limit` counts training images only.
    let some = PersonSet::open(root, 320, Some(7)).unwrap();
    assert_eq!(some.len(), 7);
    assert!(some.images.iter().zip(&set.images).all(|(a, b)| a.id == b.id));
}

#[test]
fn fine_tuning_behind_a_camera_fits_its_images_and_stops_on_time() {
    let Some(model) = shared::shared("models/yolox_nano.onnx") else { return };
    let Some(coco) = shared::shared("data/coco-person/instances_person.json") else { return };
    let cfg = DetectorConfig {
        model,
        data: coco.parent().unwrap().to_path_buf(),
        size: 128,
        batch: 2,
        lr: 1e-3,
        max_images: Some(2),
        ..DetectorConfig::default()
    };
    // A strong camera (colour inversion through the curve): the detector must adapt to it.
    let imaging = Imaging::Camera {
        ccm: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        curves: vec![(0..32).map(|i| 1.0 - i as f64 / 31.0).collect()],
        gamma: 2.2,
    };
    let done = run(
        &imaging,
        &cfg,
        &FinetuneOptions { steps: 8, seconds: f64::INFINITY, seed: 0, ..Default::default() },
        |_| {},
    )
    .unwrap();
    assert_eq!((done.log.len(), done.images), (8, 2));
    let l: Vec<f64> = done.log.iter().map(|r| r.loss).collect();
    assert!(l.iter().all(|v| v.is_finite() && *v > 0.0), "{l:?}");
    assert!(done.log.iter().all(|r| r.positives > 0));
    let (first, last) = ((l[0] + l[1]) / 2.0, (l[6] + l[7]) / 2.0);
    assert!(last < 0.8 * first, "L_det {first} -> {last}: {l:?}");
    // The time budget stops it before the first step; a zero learning rate is refused.
    assert!(run(
        &Imaging::Raw,
        &cfg,
        &FinetuneOptions { steps: 8, seconds: 0.0, seed: 0, ..Default::default() },
        |_| {}
    )
    .unwrap()
    .log
    .is_empty());
    // Distillation: behind no camera the student starts as its teacher (L_kd = 0 at the
    // first step, not after it); behind the inverting camera it does not, and the logged
    // loss is the detection parts plus L_kd.
    let kd = DetectorConfig { distill: 1.0, ..cfg.clone() };
    let two = FinetuneOptions { steps: 2, seconds: f64::INFINITY, seed: 0, ..Default::default() };
    let raw = run(&Imaging::Raw, &kd, &two, |_| {}).unwrap();
    assert!(raw.log[0].kd.abs() < 1e-6 && raw.log[1].kd > 1e-6, "{:?}", raw.log);
    let inv = run(&imaging, &kd, &two, |_| {}).unwrap();
    let r = inv.log[0];
    assert!(r.kd > 0.1, "{r:?}");
    assert!((r.loss - (5.0 * r.iou + r.obj + r.cls + r.kd)).abs() < 1e-3 * r.loss, "{r:?}");
    // A colour adapter fitted to the inverting camera: its pixel error falls well below where
    // it starts (the identity map), and the written detector carries it.
    let adapted = DetectorConfig { adapter: 8, adapter_fit: 60, ..cfg.clone() };
    let fit = run(&imaging, &adapted, &two, |_| {}).unwrap();
    let e = &fit.adapter_fit;
    assert_eq!(e.len(), 60);
    assert!(e[0] > 0.05 && e[59] < 0.3 * e[0], "adapter fit {} -> {}", e[0], e[59]);
    assert_eq!(fit.detector.adapter_and_rest().0.len(), 4);
    assert!(done.adapter_fit.is_empty());
    let frozen = DetectorConfig { lr: 0.0, ..cfg };
    assert!(run(
        &Imaging::Raw,
        &frozen,
        &FinetuneOptions { steps: 1, seconds: 1.0, seed: 0, ..Default::default() },
        |_| {}
    )
    .is_err());
}
