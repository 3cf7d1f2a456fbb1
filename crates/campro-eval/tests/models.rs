//! The shipped manifests and the model decoders on real images from `../shared` (skipped
//! with a message when it is absent; required under CI=true), and manifest errors.

use campro_testkit as shared;

use campro_eval::data::{coco_person, read_rgb8};
use campro_eval::face::{central_face, cosine, Embedder, FaceDetector};
use campro_eval::geometry::iou;
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use campro_eval::person::PersonDetector;
use campro_eval::EvalError;
use std::path::{Path, PathBuf};

fn manifest_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models").join(format!("{name}.json"))
}

fn load(name: &str, models: &Path) -> Model {
    Model::load(Manifest::load(&manifest_path(name), models).unwrap()).unwrap()
}

fn lfw(person: &str, n: usize) -> Option<PathBuf> {
    shared::shared(&format!("data/lfw/images_deepfunneled/{person}/{person}_{n:04}.jpg"))
}

#[test]
fn yunet_finds_the_lfw_face_with_landmarks_in_place() {
    let Some(models) = shared::shared("models/yunet_s_640_640.onnx").map(|p| p.parent().unwrap().to_path_buf()) else {
        return;
    };
    let det = FaceDetector::new(load("yunet", &models)).unwrap();
    for (person, n) in [("George_W_Bush", 1), ("Colin_Powell", 1), ("Donald_Rumsfeld", 1), ("Hugo_Chavez", 2)] {
        let Some(path) = lfw(person, n) else { return };
        let img = read_rgb8(&path).unwrap();
        let faces = det.detect(&img).unwrap();
        let f =
            central_face(&faces, img.width(), img.height()).unwrap_or_else(|| panic!("no face in {}", path.display()));
        // Deep-funneled LFW centres the face in the 250x250 frame.
        let (cx, cy) = ((f.bbox[0] + f.bbox[2]) / 2.0, (f.bbox[1] + f.bbox[3]) / 2.0);
        assert!((cx - 125.0).abs() < 25.0 && (cy - 125.0).abs() < 35.0, "{person}: box {:?}", f.bbox);
        assert!(f.score > 0.8, "{person}: score {}", f.score);
        let [re, le, nose, rm, lm] = f.landmarks;
        let eyes = le[0] - re[0];
        assert!((25.0..80.0).contains(&eyes), "{person}: eye distance {eyes}");
        assert!((le[1] - re[1]).abs() < 0.3 * eyes, "{person}: eyes not level");
        assert!(nose[0] > re[0] && nose[0] < le[0], "{person}: nose between the eyes");
        assert!(nose[1] > re[1].max(le[1]) && nose[1] < rm[1].min(lm[1]), "{person}: eyes, nose, mouth top to bottom");
        assert!(rm[0] < lm[0], "{person}: mouth corners in order");
        for p in f.landmarks {
            assert!(
                p[0] >= f.bbox[0] && p[0] <= f.bbox[2] && p[1] >= f.bbox[1] && p[1] <= f.bbox[3],
                "{person}: landmark outside the box"
            );
        }
    }
    // A flat grey frame holds no face; a large frame is scaled down and the face still found.
    assert!(det.detect(&image::RgbImage::from_pixel(300, 200, image::Rgb([128; 3]))).unwrap().is_empty());
    let Some(path) = lfw("George_W_Bush", 1) else { return };
    let big = image::imageops::resize(&read_rgb8(&path).unwrap(), 1000, 1000, image::imageops::FilterType::Triangle);
    let f = central_face(&det.detect(&big).unwrap(), 1000, 1000).expect("face in the 4x frame");
    assert!(((f.bbox[0] + f.bbox[2]) / 2.0 - 500.0).abs() < 100.0);
}

#[test]
fn embeddings_put_the_same_person_closer_than_others() {
    let Some(models) = shared::shared("models/yunet_s_640_640.onnx").map(|p| p.parent().unwrap().to_path_buf()) else {
        return;
    };
    let det = FaceDetector::new(load("yunet", &models)).unwrap();
    let photos = [
        ("George_W_Bush", 1),
        ("George_W_Bush", 2),
        ("Colin_Powell", 1),
        ("Colin_Powell", 2),
        ("Donald_Rumsfeld", 1),
        ("Hugo_Chavez", 2),
    ];
    let mut faces = Vec::new();
    for (person, n) in photos {
        let Some(path) = lfw(person, n) else { return };
        let img = read_rgb8(&path).unwrap();
        let f = central_face(&det.detect(&img).unwrap(), 250, 250).unwrap();
        faces.push((person, img, f));
    }
    for name in ["faceplugin", "mobilefacenet_casia"] {
        let emb = Embedder::new(load(name, &models)).unwrap();
        let e: Vec<Vec<f32>> =
            faces.iter().map(|(_, img, f)| emb.embed(&emb.align(img, &f.landmarks)).unwrap()).collect();
        for v in &e {
            let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            assert!((norm - 1.0).abs() < 1e-4, "{name}: norm {norm}");
        }
        let (mut same, mut other) = (f32::INFINITY, f32::NEG_INFINITY);
        for i in 0..e.len() {
            for j in i + 1..e.len() {
                let c = cosine(&e[i], &e[j]);
                if faces[i].0 == faces[j].0 {
                    same = same.min(c)
                } else {
                    other = other.max(c)
                }
            }
        }
        assert!(same > other + 0.1, "{name}: same person {same} vs others {other}");
        // A photo against itself mirrored is still the same person.
        let (_, img, _) = &faces[0];
        let flip = image::imageops::flip_horizontal(img);
        let ff = central_face(&det.detect(&flip).unwrap(), 250, 250).unwrap();
        let c = cosine(&e[0], &emb.embed(&emb.align(&flip, &ff.landmarks)).unwrap());
        assert!(c > other, "{name}: mirrored {c} vs others {other}");
    }
}

#[test]
fn yolox_finds_the_coco_people() {
    let Some(models) = shared::shared("models/yolox_nano.onnx").map(|p| p.parent().unwrap().to_path_buf()) else {
        return;
    };
    let Some(coco) = shared::shared("data/coco-person/instances_person.json") else { return };
    let det = PersonDetector::new(load("yolox_nano", &models)).unwrap();
    let images = coco_person(coco.parent().unwrap()).unwrap();
    let (mut large, mut found) = (0, 0);
    for im in images.iter().take(12) {
        let img = read_rgb8(&im.path).unwrap();
        let dets = det.detect(&img).unwrap();
        for d in &dets {
            assert!(d.bbox[0] <= d.bbox[2] && d.bbox[2] <= img.width() as f32 && d.bbox[3] <= img.height() as f32);
            assert!((0.0..=1.0).contains(&d.score));
        }
        for g in im.gts.iter().filter(|g| !g.crowd && g.bbox[2] * g.bbox[3] >= 96.0 * 96.0) {
            large += 1;
            let b = [g.bbox[0], g.bbox[1], g.bbox[0] + g.bbox[2], g.bbox[1] + g.bbox[3]];
            if dets.iter().any(|d| d.score >= 0.25 && iou(d.bbox, b) >= 0.5) {
                found += 1;
            }
        }
    }
    // Large people (COCO's "large" area) are the easy ones: YOLOX-Nano finds nearly all.
    assert!(large >= 5 && found as f64 >= 0.8 * large as f64, "found {found} of {large} large people");
}

fn manifest_error(text: &str) -> (String, String) {
    match Manifest::parse(text, Path::new("m.json"), Path::new("/models")) {
        Err(EvalError::Manifest { field, rule, .. }) => (field, rule),
        other => panic!("expected a manifest error, got {other:?}"),
    }
}

#[test]
fn bad_manifests_name_the_field_and_the_rule() {
    let good = std::fs::read_to_string(manifest_path("faceplugin")).unwrap();
    let m = Manifest::parse(&good, Path::new("m.json"), Path::new("/models")).unwrap();
    assert_eq!(m.file, Path::new("/models/faceplugin_fr_feature.onnx"));
    let (field, rule) = manifest_error(&good.replace("\"rgb\"", "\"rgba\""));
    assert_eq!(field, "input.channels");
    assert!(rule.contains("unknown variant"), "{rule}");
    let (field, rule) = manifest_error(&good.replace("\"std\": [128, 128, 128]", "\"std\": [128, 0, 128]"));
    assert_eq!((field.as_str(), rule.as_str()), ("input.std", "must be finite and > 0"));
    let (field, _) = manifest_error(&good.replace("\"face_embedder\"", "\"face_swapper\""));
    assert_eq!(field, "task.kind");
    let (field, rule) = manifest_error(
        r#"{"name": "x", "file": "x.onnx", "input": {"width": 0, "height": 5, "channels": "rgb"}, "task": {"kind": "face_detector", "strides": [8], "score_threshold": 0.5, "nms_iou": 0.3}}"#,
    );
    assert_eq!(field, "input", "{rule}");
    let (field, _) = manifest_error(
        r#"{"name": "x", "file": "x.onnx", "input": {"width": 64, "height": 64, "channels": "rgb"}, "task": {"kind": "face_detector", "strides": [8], "score_threshold": 1.5, "nms_iou": 0.3}}"#,
    );
    assert_eq!(field, "task");
    // serde buffers a tagged enum, so inside `task` the rule carries the detail.
    let (field, rule) = manifest_error(
        r#"{"name": "x", "file": "x.onnx", "input": {"width": 64, "height": 64, "channels": "rgb"}, "task": {"kind": "face_embedder", "output": "o", "template": [[1, 2]]}}"#,
    );
    assert!(field == "task" && rule.contains("length 1") && rule.contains("5"), "{field}: {rule}");
    let (field, _) = manifest_error("{\"name\": \"x\", \"fil\": 1}");
    assert_eq!(field, "fil");
    // A manifest whose model file is missing fails at load with the path, not a panic.
    let m = Manifest::parse(&good, Path::new("m.json"), Path::new("/nonexistent")).unwrap();
    let err = Model::load(m).err().unwrap().to_string();
    assert!(err.contains("/nonexistent/faceplugin_fr_feature.onnx"), "{err}");
}

#[test]
fn a_corrupt_model_file_is_an_error_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("faceplugin_fr_feature.onnx"), b"not an onnx file at all").unwrap();
    let good = std::fs::read_to_string(manifest_path("faceplugin")).unwrap();
    let m = Manifest::parse(&good, Path::new("m.json"), dir.path()).unwrap();
    assert!(matches!(Model::load(m), Err(EvalError::Model { .. })));
}
