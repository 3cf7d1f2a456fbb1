//! The privacy evaluation's small, group and pose conditions on real photos and models
//! (`../shared`; skipped with a message when it is absent, required under CI=true).
//!
//! The raw condition of a placed scene takes its own path (the picture unprotected); a
//! camera that copies its input takes the protection path. The two must agree to the last
//! digit, and the placed faces must be recognisable raw (so the landmarks follow the face
//! into the scene) and gone when the camera blanks the picture.

use campro_eval::face::{Embedder, FaceDetector};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use campro_eval::privacy::{self, FaceModels, Order, PrivacyOptions, PrivacyReport};
use campro_eval::scene::Scene;
use campro_eval::Condition;
use image::RgbImage;
use std::path::Path;

fn load(name: &str, models: &Path) -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("models").join(format!("{name}.json"));
    Model::load(Manifest::load(&path, models).unwrap()).unwrap()
}

fn run(shared: &Path, scene: Scene) -> PrivacyReport {
    let models = shared.join("models");
    let fm = FaceModels {
        detector: FaceDetector::new(load("yunet", &models)).unwrap(),
        embedders: vec![Embedder::new(load("faceplugin", &models)).unwrap()],
    };
    let lfw = campro_eval::data::Lfw::open(&shared.join("data/lfw")).unwrap();
    let conds = [
        Condition::raw(),
        Condition::new("copy", |i: &RgbImage| i.clone()),
        Condition::new("black", |i: &RgbImage| RgbImage::new(i.width(), i.height())),
    ];
    let o = PrivacyOptions {
        runs: 2,
        limit: Some(12),
        verification: false,
        scene,
        backdrops: Some(shared.join("data/coco-person")),
        ..Default::default()
    };
    privacy::evaluate(&lfw, &fm, &conds, &o).unwrap()
}

fn rows<'a>(r: &'a PrivacyReport, cond: &'a str) -> impl Iterator<Item = &'a privacy::IdentRow> + 'a {
    r.identification.iter().filter(move |x| x.condition == cond)
}

#[test]
fn placed_and_posed_probes_are_recognisable_raw_and_a_copying_camera_changes_nothing() {
    let Some(shared) = campro_testkit::shared_root(&[
        "models/yunet_s_640_640.onnx",
        "models/faceplugin_fr_feature.onnx",
        "data/lfw/pairs.txt",
        "data/coco-person/instances_person.json",
    ]) else {
        return;
    };
    for scene in [Scene::Small, Scene::Group, Scene::Pose] {
        let r = run(&shared, scene);
        let chance = 1.0 / r.gallery as f64;
        // The copying camera takes the protection path; raw its own. Same numbers.
        for (a, b) in rows(&r, "raw").zip(rows(&r, "copy")) {
            assert_eq!((a.order, &a.model, a.classifier), (b.order, &b.model, b.classifier));
            assert_eq!(a.top1_mean, b.top1_mean, "{}: {:?} {}", scene.name(), a.order, a.classifier);
            assert_eq!(a.detection_rate, b.detection_rate, "{}", scene.name());
        }
        // Raw, with the face where the landmarks say: well above chance.
        for x in rows(&r, "raw").filter(|x| x.order == Order::Paper) {
            assert!(x.top1_mean >= 3.0 * chance, "{} raw {}: {}", scene.name(), x.classifier, x.top1_mean);
        }
        // A black picture has no face to find.
        for x in rows(&r, "black").filter(|x| x.order == Order::EndToEnd) {
            assert_eq!(x.detection_rate, Some(0.0), "{}", scene.name());
            assert_eq!(x.top1_mean, 0.0);
        }
        match scene {
            // LFW's most turned faces: every probe turns by at least a fifth of the eye
            // distance (the median LFW photo by 0.10).
            Scene::Pose => assert!(r.probe_turn.unwrap() >= privacy::MIN_TURN as f64, "{:?}", r.probe_turn),
            _ => assert_eq!(r.probe_turn, None),
        }
    }
}
