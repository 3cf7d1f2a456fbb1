//! `campro eval privacy --attack retrain`: the paper's model re-training attack (Sec. VII,
//! Table VI). For each parameter set and face model, the model is fine-tuned
//! (campro_train::retrain) on that set's protected faces (the paper's order: aligned, then
//! through the camera) of identities the evaluation never probes, then the evaluation's
//! own protocol runs with the fine-tuned model on the same probes: rows "NAME retrained".
//!
//! How many photos the attacker labelled per identity sets its knowledge: a white-box
//! attacker (the parameters known) simulates the camera on any photo it likes (default 20
//! per identity); a gray-box one (the camera bought, the parameters unknown) photographs a
//! few people itself (`--retrain-photos 2`); a black-box one has no labels and cannot
//! re-train (the plain rows).

use crate::args::{LossArg, RetrainArgs};
use anyhow::{bail, Context, Result};
use campro_eval::data::Lfw;
use campro_eval::face::{central_face, Embedder, FaceDetector};
use campro_eval::privacy::{self, FaceModels, IdentRow, PrivacyOptions};
use campro_eval::Condition;
use campro_train::retrain::{fine_tune, Loss, RetrainConfig, Sample};
use image::RgbImage;
use rand::seq::{IndexedRandom, SliceRandom};
use rand::SeedableRng;
use std::path::{Path, PathBuf};

/// A training photo: its identity and the five landmarks of its face.
struct Photo {
    label: usize,
    image: RgbImage,
    landmarks: [[f32; 2]; 5],
}

/// The training photos: up to `photos` per identity with 2 or more photos that `probed`
/// does not name, at most `identities` identities (seeded), each with a face found raw;
/// and the identities' names, by label.
fn training_photos(
    lfw: &Lfw,
    probed: &[String],
    a: &RetrainArgs,
    seed: u64,
    det: &FaceDetector,
) -> Result<(Vec<Photo>, Vec<String>)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut ids: Vec<(&String, &Vec<PathBuf>)> =
        lfw.people.iter().filter(|(n, v)| v.len() >= 2 && !probed.contains(n)).collect();
    if let Some(n) = a.retrain_identities {
        ids.shuffle(&mut rng);
        ids.truncate(n as usize);
        ids.sort();
    }
    let (mut out, mut names) = (Vec::new(), Vec::new());
    let (mut label, mut missed) = (0, 0);
    for (name, paths) in ids {
        let chosen: Vec<&PathBuf> = paths.choose_multiple(&mut rng, a.retrain_photos as usize).collect();
        let mut found = Vec::new();
        for p in chosen {
            let image = campro_eval::data::read_rgb8(p)?;
            match central_face(&det.detect(&image)?, image.width(), image.height()) {
                Some(f) => found.push(Photo { label, image, landmarks: f.landmarks }),
                None => missed += 1,
            }
        }
        // An identity needs two faces to be learnt as one.
        if found.len() >= 2 {
            out.extend(found);
            names.push(name.clone());
            label += 1;
        }
    }
    if label < 2 {
        bail!(
            "--attack retrain: fewer than 2 training identities with 2 faces found (LFW minus the probed identities)"
        );
    }
    eprintln!("re-training data: {} faces of {label} identities ({missed} photos without a face)", out.len());
    Ok((out, names))
}

/// One fine-tuned model's record beside its ONNX file.
#[derive(serde::Serialize)]
struct Record<'a> {
    set: &'a str,
    model: &'a str,
    config: &'a RetrainConfig,
    log: &'a campro_train::retrain::RetrainLog,
    /// The training identities, by class index.
    identities: &'a [String],
}

/// Runs the attack for every parameter set among `conds` (those in `sets`) and every face
/// model in `manifests`; writes the fine-tuned models and their logs under
/// `output/retrain/` and returns the identification rows, condition "NAME retrained".
#[allow(clippy::too_many_arguments)]
pub fn attack(
    lfw: &Lfw,
    probed: &[String],
    conds: &[Condition],
    sets: &[String],
    manifests: &[campro_eval::manifest::Manifest],
    detector: impl Fn() -> Result<FaceDetector>,
    a: &RetrainArgs,
    o: &PrivacyOptions,
    output: &Path,
) -> Result<Vec<IdentRow>> {
    let det = detector()?;
    let (photos, names) = training_photos(lfw, probed, a, o.seed, &det)?;
    let classes = names.len();
    let dir = output.join("retrain");
    std::fs::create_dir_all(&dir).with_context(|| dir.display().to_string())?;
    let cfg = RetrainConfig {
        epochs: a.retrain_epochs as usize,
        batch: a.retrain_batch as usize,
        lr: a.retrain_lr,
        seed: o.seed,
        loss: match a.retrain_loss {
            LossArg::Softmax => Loss::Softmax,
            LossArg::Arcface => Loss::ARCFACE,
        },
        ..Default::default()
    };
    let mut rows = Vec::new();
    for cond in conds.iter().filter(|c| sets.contains(&c.name)) {
        let Some(protect) = &cond.protect else { continue };
        let mut tuned = Vec::new();
        for m in manifests {
            let base = Embedder::new(campro_eval::model::Model::load(m.clone())?)?;
            eprintln!("re-training {} on {} faces", m.name, cond.name);
            let samples: Vec<Sample> = photos
                .iter()
                .map(|p| Sample { crop: protect(&base.align(&p.image, &p.landmarks)), label: p.label })
                .collect();
            let (net, log) = fine_tune(&m.file, &m.input, &samples, classes, &cfg, &campro_nn::Context::cpu().device)
                .with_context(|| format!("re-training {} on {}", m.name, cond.name))?;
            let file = dir.join(format!("{}.{}.onnx", cond.name, m.name));
            net.save_onnx(&file)?;
            let record = Record { set: &cond.name, model: &m.name, config: &cfg, log: &log, identities: &names };
            let json = serde_json::to_vec_pretty(&record)?;
            campro::file::atomic::write(&file.with_extension("json"), &json, true)
                .with_context(|| file.display().to_string())?;
            tuned.push(Embedder::new(campro_eval::model::Model::load(campro_eval::manifest::Manifest {
                file,
                ..m.clone()
            })?)?);
        }
        // The evaluation's protocol and probes, with the fine-tuned models.
        let fm = FaceModels { detector: detector()?, embedders: tuned };
        let only = [Condition::raw(), cond.clone()];
        let r = privacy::evaluate(lfw, &fm, &only, &PrivacyOptions { verification: false, ..o.clone() })?;
        rows.extend(r.identification.into_iter().filter(|x| x.condition == cond.name).map(|mut x| {
            x.condition = format!("{} retrained", cond.name);
            x
        }));
    }
    Ok(rows)
}
