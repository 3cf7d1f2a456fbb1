//! The re-training attack's pieces: both shared face models read into candle from their
//! ONNX files embed as tract does, a fine-tune on a few identities learns them, and the
//! written ONNX file is the fine-tuned network (tract agrees with candle after training).

use campro_testkit as shared;

use campro_eval::face::{central_face, Embedder, FaceDetector};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use campro_nn::onnx_net::OnnxNet;
use campro_train::retrain::{fine_tune, input_tensor, RetrainConfig, Sample};
use candle_core::Device;
use image::RgbImage;
use std::path::{Path, PathBuf};

fn manifest(name: &str, models: &Path) -> Manifest {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../campro-eval/models");
    Manifest::load(&dir.join(name), models).unwrap()
}

/// Aligned crops of the first `per` photos of each named LFW identity, for `emb`.
fn crops(lfw: &Path, names: &[&str], per: usize, det: &FaceDetector, emb: &Embedder) -> Vec<Sample> {
    let mut out = Vec::new();
    for (label, name) in names.iter().enumerate() {
        for k in 1..=per {
            let path = lfw.join(format!("images_deepfunneled/{name}/{name}_{k:04}.jpg"));
            let img = campro_eval::data::read_rgb8(&path).unwrap();
            let f = central_face(&det.detect(&img).unwrap(), img.width(), img.height()).unwrap();
            out.push(Sample { crop: emb.align(&img, &f.landmarks), label });
        }
    }
    out
}

fn l2(v: &[f32]) -> Vec<f32> {
    let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    v.iter().map(|x| x / n).collect()
}

/// The candle network's L2-normalised embedding of one crop.
fn candle_embedding(net: &OnnxNet, crop: &RgbImage, m: &Manifest) -> Vec<f32> {
    let x = input_tensor(&[crop], &m.input, &Device::Cpu).unwrap();
    l2(&net.forward(&x).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap())
}

#[test]
fn both_face_models_run_in_candle_as_in_tract_and_fine_tune() {
    let Some(models) = shared::shared("models/faceplugin_fr_feature.onnx") else { return };
    let Some(lfw) = shared::shared("data/lfw") else { return };
    let models: PathBuf = models.parent().unwrap().into();
    let det = FaceDetector::new(Model::load(manifest("yunet.json", &models)).unwrap()).unwrap();
    for name in ["faceplugin.json", "mobilefacenet_casia.json"] {
        let m = manifest(name, &models);
        let emb = Embedder::new(Model::load(m.clone()).unwrap()).unwrap();
        let people = ["Colin_Powell", "George_W_Bush", "Gerhard_Schroeder", "Donald_Rumsfeld"];
        let samples = crops(&lfw, &people, 4, &det, &emb);
        // Read from ONNX into candle: the same embedding as tract's, to float rounding.
        let net = OnnxNet::load(&m.file, &Device::Cpu).unwrap();
        for s in samples.iter().step_by(5) {
            let (got, want) = (candle_embedding(&net, &s.crop, &m), emb.embed(&s.crop).unwrap());
            let cos: f32 = got.iter().zip(&want).map(|(a, b)| a * b).sum();
            assert!(cos > 0.9999, "{name}: cosine {cos} between candle and tract");
        }
        // A short fine-tune on 16 faces of 4 people: the loss falls and the training faces
        // stay classified.
        let cfg = RetrainConfig { epochs: 8, batch: 8, lr: 0.01, ..Default::default() };
        let (tuned, log) = fine_tune(&m.file, &m.input, &samples, people.len(), &cfg, &Device::Cpu).unwrap();
        assert_eq!((log.faces, log.classes, log.steps), (16, 4, 16));
        // The imprinted head (class means of the unchanged network's embeddings) tells
        // these raw faces apart before any step.
        assert!(log.epoch_accuracy[0] >= 0.75, "{name}: first epoch {:?}", log.epoch_accuracy);
        let (first, last) = (log.epoch_loss[0], *log.epoch_loss.last().unwrap());
        assert!(last < 0.5 * first, "{name}: loss {first} -> {last}");
        assert!(*log.epoch_accuracy.last().unwrap() >= 0.75, "{name}: {:?}", log.epoch_accuracy);
        // The written file is the tuned network: tract on it agrees with candle, and the
        // weights moved (the embedding differs from the original model's).
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("tuned.onnx");
        tuned.save_onnx(&file).unwrap();
        let tuned_emb = Embedder::new(Model::load(Manifest { file, ..m.clone() }).unwrap()).unwrap();
        let s = &samples[0];
        let (got, want) = (candle_embedding(&tuned, &s.crop, &m), tuned_emb.embed(&s.crop).unwrap());
        let cos: f32 = got.iter().zip(&want).map(|(a, b)| a * b).sum();
        assert!(cos > 0.9999, "{name}: tuned cosine {cos}");
        let before = emb.embed(&s.crop).unwrap();
        let moved: f32 = want.iter().zip(&before).map(|(a, b)| a * b).sum();
        assert!(moved < 0.9999, "{name}: fine-tuning left the embedding as it was ({moved})");
    }
}

#[test]
fn bad_retraining_input_is_refused_by_name() {
    let Some(model) = shared::shared("models/faceplugin_fr_feature.onnx") else { return };
    let m = manifest("faceplugin.json", model.parent().unwrap());
    let one = vec![Sample { crop: RgbImage::new(112, 112), label: 0 }];
    let err = |s: &[Sample], classes| {
        fine_tune(&m.file, &m.input, s, classes, &RetrainConfig::default(), &Device::Cpu).err().unwrap().to_string()
    };
    assert!(err(&one, 1).contains("at least 2 identities"), "{}", err(&one, 1));
    let wrong = vec![Sample { crop: RgbImage::new(112, 112), label: 5 }];
    assert!(err(&wrong, 2).contains("identity 5 of 2"), "{}", err(&wrong, 2));
    let small =
        vec![Sample { crop: RgbImage::new(96, 112), label: 0 }, Sample { crop: RgbImage::new(96, 112), label: 1 }];
    assert!(err(&small, 2).contains("96x112 crop for a 112x112"), "{}", err(&small, 2));
}
