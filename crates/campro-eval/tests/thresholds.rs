//! The verification thresholds recorded in the bundled face models' manifests are what
//! `campro eval thresholds` computes on this copy of LFW (same folds).

use campro_eval::check::calibrate;
use campro_eval::data::Lfw;
use campro_eval::face::{Embedder, FaceDetector};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;

#[test]
fn bundled_thresholds_are_recomputed() {
    let Some(shared) = campro_testkit::shared_root(&[
        "models/yunet_s_640_640.onnx",
        "models/faceplugin_fr_feature.onnx",
        "models/mobilefacenet_casia.onnx",
        "data/lfw/pairs.txt",
    ]) else {
        return;
    };
    let models = shared.join("models");
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let detector =
        FaceDetector::new(Model::load(Manifest::load(&here.join("yunet.json"), &models).unwrap()).unwrap()).unwrap();
    let lfw = Lfw::open(&shared.join("data/lfw")).unwrap();
    for file in ["faceplugin.json", "mobilefacenet_casia.json"] {
        let e = Embedder::new(Model::load(Manifest::load(&here.join(file), &models).unwrap()).unwrap()).unwrap();
        let recorded = e.thresholds().unwrap_or_else(|| panic!("{file}: no task.thresholds"));
        let c = calibrate(&lfw, &detector, &e, recorded.folds).unwrap();
        let t = c.thresholds;
        assert_eq!(t.impostor_pairs, recorded.impostor_pairs, "{file}");
        // Recorded with 6 decimals; the ONNX runtime's kernels may differ in the last float bits between CPUs.
        assert!(
            (t.far_1e3 - recorded.far_1e3).abs() < 1e-4,
            "{file}: far 1e-3 {} recorded {}",
            t.far_1e3,
            recorded.far_1e3
        );
        assert!(
            (t.far_1e2 - recorded.far_1e2).abs() < 1e-4,
            "{file}: far 1e-2 {} recorded {}",
            t.far_1e2,
            recorded.far_1e2
        );
        // The model still links the same person on most of the folds' same-person pairs.
        assert!(c.genuine_accept[0] > 0.9, "{file}: {:?}", c.genuine_accept);
    }
}
