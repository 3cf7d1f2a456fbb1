//! Training the image enhancer R (paper Sec. IV-D): AdamW on the face-masked L1 loss
//! `mean(s ⊙ |R(C(x)) − x|)` over random crops of the training scenes ([`crate::scenes`]);
//! by default the face boxes are also held to the captured image
//! ([`crate::config::FaceTarget`]). Checkpoints, resume, a log, and a validation on scenes
//! never trained on.
//!
//! With `data.faces = "restore"` the same run trains a plain restoration network: the
//! adaptive attacker's (Sec. VII), which is trained to restore faces too.

use crate::config::{EnhancerConfig, FaceTarget};
use crate::error::TrainError;
use crate::face_privacy::{FacePrivacy, FaceSource};
use crate::scenes::{chw_tensor, Scene, SceneBatch, SceneSet};
use crate::unet::{enhancer_loss, face_l1, gate_loss, loss_target, masked_l1, pixelate, Unet};
use candle_core::{Device, Tensor};
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use rand::SeedableRng;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Steps per log row (the row's loss is their mean).
pub const LOG_EVERY: usize = 10;

/// One line of the enhancer's log.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnhancerRow {
    pub step: usize,
    /// Training time over all resumed parts (s).
    pub seconds: f64,
    /// The pixel loss ([`crate::unet::enhancer_loss`], without the face-privacy term) on the
    /// crops, mean of the steps since the previous row (0..1; NaN at step 0).
    #[serde(deserialize_with = "crate::log::nan_if_null")]
    pub loss: f64,
    /// With the face-privacy term: the fraction of the same steps' enhanced faces that the
    /// nearest class mean identified (0..1).
    #[serde(default)]
    pub face_top1: Option<f64>,
    /// At checkpoints: the validation scenes, whole.
    pub validation: Option<Validation>,
}

/// The enhancer on the validation scenes (whole images, 8-bit output), means over scenes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    /// Masked L1 (0..1).
    #[serde(deserialize_with = "crate::log::nan_if_null")]
    pub masked_l1: f64,
    /// Mean |R(C(x)) − x| inside the face boxes (0..1); None without faces. Stays high
    /// when faces are not restored.
    pub face_l1: Option<f64>,
    /// The same for the U-Net's input (the captured image or its per-pixel restoration).
    pub face_l1_input: Option<f64>,
    /// PSNR against raw (dB) of the enhanced image, of the U-Net's input and of the captured
    /// image (infinite for identical images: null in a checkpoint, read back as NaN).
    #[serde(deserialize_with = "crate::log::nan_if_null")]
    pub psnr: f64,
    #[serde(deserialize_with = "crate::log::nan_if_null")]
    pub psnr_input: f64,
    #[serde(deserialize_with = "crate::log::nan_if_null")]
    pub psnr_captured: f64,
    /// With the face-privacy term: the nearest class mean's top-1 (0..1) on the enhanced
    /// check faces and on the U-Net's input ([`crate::face_privacy::FacePrivacy::validate`]).
    #[serde(default)]
    pub face_top1: Option<f64>,
    #[serde(default)]
    pub face_top1_input: Option<f64>,
    /// With a face gate: its mean probability (0..1) inside the face boxes and elsewhere.
    #[serde(default)]
    pub gate_faces: Option<f64>,
    #[serde(default)]
    pub gate_scene: Option<f64>,
    /// SSIM against raw of the enhanced image ([`campro_eval::quality::ssim`]); None in logs
    /// written before it was measured.
    #[serde(default)]
    pub ssim: Option<f64>,
}

/// A checkpoint's state (beside the network's tensors).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EnhancerState {
    pub step: usize,
    pub seed: u64,
    pub model: crate::config::UnetConfig,
    pub log: Vec<EnhancerRow>,
    /// Where the run started (`--init`: checkpoint, its step, the fresh tensors), kept
    /// through resumes for the provenance.
    #[serde(default)]
    pub init: Option<serde_json::Value>,
}

/// Where checkpoints go, and which one to resume from.
#[derive(Debug, Clone, Default)]
pub struct EnhancerOptions {
    pub checkpoints: Option<PathBuf>,
    pub resume: Option<PathBuf>,
    /// Start from another run's checkpoint folder or enhancer file (`PARAMS.enhancer.onnx`):
    /// every tensor of the same name and shape is copied, the face gate's start fresh if it
    /// has none (any other tensor missing is an error); step 1, a new log.
    pub init: Option<PathBuf>,
    /// Where it computes (default: the CPU).
    pub ctx: campro_nn::Context,
}

/// An enhancer: the optional per-pixel restoration table, then the U-Net.
pub struct EnhancerNet {
    pub unet: Unet,
    /// [`campro_eval::restore::Restorer::table`] of the camera, fitted on the training scenes.
    pub table: Option<campro_eval::restore::Table>,
}

impl EnhancerNet {
    /// The enhanced image of a captured 8-bit image (candle; tract runs the ONNX file).
    pub fn enhance(&self, captured: &image::RgbImage, dev: &Device) -> Result<image::RgbImage, TrainError> {
        match &self.table {
            Some(t) => enhance(&self.unet, &t.apply(captured), captured, dev),
            None => enhance(&self.unet, captured, captured, dev),
        }
    }

    /// The whole enhancer as an ONNX file (input: the captured image).
    pub fn onnx_bytes(&self) -> Result<Vec<u8>, TrainError> {
        Ok(match &self.table {
            Some(t) => self.unet.onnx_bytes_with_table(t)?,
            None => self.unet.onnx_bytes()?,
        })
    }

    /// Writes [`Self::onnx_bytes`] to `path` (temporary file, then rename; replaces).
    pub fn save_onnx(&self, path: &std::path::Path) -> Result<(), TrainError> {
        let bytes = self.onnx_bytes()?;
        campro::file::atomic::write(path, &bytes, true).map_err(|e| {
            TrainError::Checkpoint(crate::error::CheckpointError::Io { path: path.into(), message: e.to_string() })
        })
    }
}

/// The trained enhancer and how it was trained.
pub struct EnhancerOutcome {
    pub enhancer: EnhancerNet,
    pub log: Vec<EnhancerRow>,
    pub seconds: f64,
    pub provenance: serde_json::Map<String, serde_json::Value>,
}

/// One scene's validation terms: masked L1, face L1 of the enhanced image and of the
/// U-Net's input (None without faces), PSNR against raw of the enhanced image, the input and
/// the captured image, the face gate's mean inside the faces and elsewhere, SSIM against raw.
fn validate_scene(unet: &Unet, sc: &Scene, dev: &Device) -> Result<[Option<f64>; 9], TrainError> {
    let (out, gate) = enhance_gated(unet, sc.input(), &sc.captured, dev)?;
    let (w, h) = sc.raw.dimensions();
    let k = sc.keep(0, 0, w, h);
    let gate_mean = |face: bool| {
        let v: Vec<f64> =
            gate.iter().flatten().zip(&k).filter(|(_, &k)| (k == 0.0) == face).map(|(&g, _)| g as f64).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    let gates = [gate_mean(true), gate_mean(false)];
    let keep = Tensor::from_vec(k, (1, 1, h as usize, w as usize), dev)?;
    let (o, i, r) = (chw_tensor(&out, dev)?, chw_tensor(sc.input(), dev)?, chw_tensor(&sc.raw, dev)?);
    Ok([
        Some(masked_l1(&o, &r, &keep)?.to_scalar::<f32>()? as f64),
        face_l1(&o, &r, &keep)?,
        face_l1(&i, &r, &keep)?,
        Some(campro_eval::quality::psnr(&out, &sc.raw)),
        Some(campro_eval::quality::psnr(sc.input(), &sc.raw)),
        Some(campro_eval::quality::psnr(&sc.captured, &sc.raw)),
        gates[0],
        gates[1],
        Some(campro_eval::quality::ssim(&out, &sc.raw)),
    ])
}

/// The enhancer on a whole 8-bit image: the U-Net's `input` (the captured image or its
/// per-pixel restoration) and the `captured` image of the same size (padded to the multiple,
/// cropped back, rounded).
pub fn enhance(
    unet: &Unet,
    input: &image::RgbImage,
    captured: &image::RgbImage,
    dev: &Device,
) -> Result<image::RgbImage, TrainError> {
    enhance_gated(unet, input, captured, dev).map(|(img, _)| img)
}

/// [`enhance`], and the face gate's map (row-major, the image's size) when there is one.
pub fn enhance_gated(
    unet: &Unet,
    input: &image::RgbImage,
    captured: &image::RgbImage,
    dev: &Device,
) -> Result<(image::RgbImage, Option<Vec<f32>>), TrainError> {
    let (w, h) = input.dimensions();
    if captured.dimensions() != (w, h) {
        return Err(TrainError::Unsupported(format!(
            "enhancer: input {w}x{h}, captured {}x{}",
            captured.width(),
            captured.height()
        )));
    }
    let m = unet.multiple();
    let tensor = |img: &image::RgbImage| -> Result<Tensor, TrainError> {
        let (data, pw, ph) = campro_eval::enhance::padded_chw(img, m);
        Ok(Tensor::from_vec(data, (1, 3, ph, pw), dev)?)
    };
    // Without a restoration stage the U-Net reads the captured image itself: pad it once.
    let x = tensor(input)?;
    let c = if std::ptr::eq(input, captured) { x.clone() } else { tensor(captured)? };
    let (_, _, ph, pw) = x.dims4()?;
    let (y, g) = unet.forward_gated(&x, &c)?;
    let v: Vec<f32> = y.flatten_all()?.to_vec1()?;
    let gate = match g {
        Some(g) => {
            let g: Vec<f32> = g.flatten_all()?.to_vec1()?;
            Some((0..h as usize).flat_map(|r| g[r * pw..r * pw + w as usize].to_vec()).collect())
        }
        None => None,
    };
    Ok((campro_eval::enhance::cropped_rgb8(&v, pw, ph, w, h), gate))
}

/// Means of the validation terms over `scenes`, and the check faces' cosines with the
/// face-privacy term.
pub fn validate(
    unet: &Unet,
    scenes: &[Scene],
    privacy: Option<&FacePrivacy>,
    dev: &Device,
) -> Result<Option<Validation>, TrainError> {
    if scenes.is_empty() {
        return Ok(None);
    }
    let top1 = match privacy {
        Some(p) => p.validate(unet, dev)?,
        None => None,
    };
    let rows = scenes.iter().map(|sc| validate_scene(unet, sc, dev)).collect::<Result<Vec<_>, _>>()?;
    // The mean of term k over the scenes that have it.
    let mean = |k: usize| {
        let v: Vec<f64> = rows.iter().filter_map(|r| r[k]).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    Ok(Some(Validation {
        masked_l1: mean(0).unwrap_or(f64::NAN),
        face_l1: mean(1),
        face_l1_input: mean(2),
        psnr: mean(3).unwrap_or(f64::NAN),
        psnr_input: mean(4).unwrap_or(f64::NAN),
        psnr_captured: mean(5).unwrap_or(f64::NAN),
        face_top1: top1.map(|c| c.0),
        face_top1_input: top1.map(|c| c.1),
        gate_faces: mean(6),
        gate_scene: mean(7),
        ssim: mean(8),
    }))
}

/// Trains the enhancer of the camera `params` (`held_out`: LFW identities never read);
/// `on_row` sees every log line as it happens.
pub fn run(
    cfg: &EnhancerConfig,
    params: &campro::Params,
    held_out: &[String],
    opts: &EnhancerOptions,
    mut on_row: impl FnMut(&EnhancerRow),
) -> Result<EnhancerOutcome, TrainError> {
    let step = crate::cost::enhancer_step(cfg);
    crate::cost::check(&step, cfg.budget.memory)?;
    let start = std::time::Instant::now();
    let dev = opts.ctx.device.clone();
    let room = (cfg.budget.memory << 20).saturating_sub(step.bytes as u64);
    let scenes = SceneSet::load(&cfg.data, params, held_out, cfg.model.restorer, cfg.seed, room)?;
    if scenes.train.is_empty() {
        return Err(TrainError::Unsupported(format!(
            "no training scene of at least {0}x{0} pixels (data.crop)",
            cfg.data.crop
        )));
    }
    let unet = Unet::new(&cfg.model, cfg.seed, &dev)?;
    let privacy = if cfg.privacy.weight > 0.0 {
        let src = FaceSource {
            lfw: &cfg.data.lfw,
            models: &cfg.data.models,
            cache: &cfg.data.cache,
            held_out,
            seed: cfg.seed,
        };
        Some(FacePrivacy::load(&cfg.privacy, &src, params, scenes.table.clone(), &dev)?)
    } else {
        None
    };
    let privacy = privacy.as_ref();
    let (mut first, mut log, mut earlier) = (1, Vec::new(), 0.0);
    let mut init = None;
    // What a checkpoint of this U-Net may hold (its variables, by name and shape).
    let expected: crate::checkpoint::Expected =
        unet.named_vars().into_iter().map(|(n, v)| (n, v.dims().to_vec())).collect();
    if let Some(from) = &opts.init {
        let (tensors, step) = if from.is_dir() {
            let (tensors, state) = crate::checkpoint::load::<EnhancerState>(from, &expected, &dev)?;
            if state.model.widths != cfg.model.widths || state.model.stem != cfg.model.stem {
                return Err(TrainError::Unsupported(format!(
                    "--init {}: widths {:?} and stem {}, but model.widths is {:?} and model.stem {}",
                    from.display(),
                    state.model.widths,
                    state.model.stem,
                    cfg.model.widths,
                    cfg.model.stem
                )));
            }
            (tensors, Some(state.step))
        } else {
            (campro_nn::onnx_net::f32_initializers(from, &dev)?, None)
        };
        let fresh = load_vars(&unet, &tensors)?;
        // Only a head the other run did not have may start fresh: anything else means
        // another shape (an enhancer file carries no configuration to compare).
        if let Some(name) = fresh.iter().find(|n| !n.starts_with("gate.")) {
            return Err(TrainError::Unsupported(format!(
                "--init {}: {name} missing or of another shape (model.widths and model.stem must match)",
                from.display()
            )));
        }
        init = Some(serde_json::json!({ "checkpoint": from.display().to_string(), "step": step, "fresh": fresh }));
    }
    if let Some(dir) = &opts.resume {
        let (tensors, state) = crate::checkpoint::load::<EnhancerState>(dir, &expected, &dev)?;
        crate::checkpoint::within_budget(dir, ("step", state.step), ("budget.steps", cfg.budget.steps))?;
        if state.seed != cfg.seed || state.model != cfg.model {
            return Err(TrainError::Unsupported(format!(
                "{}: checkpoint of another seed or [model]: resume with its own configuration",
                dir.display()
            )));
        }
        if let Some(name) = load_vars(&unet, &tensors)?.first() {
            return Err(TrainError::Unsupported(format!("{}: {name} missing from the checkpoint", dir.display())));
        }
        first = state.step + 1;
        init = state.init;
        earlier = state.log.last().map_or(0.0, |r| r.seconds);
        log = state.log;
    }
    let seconds = || earlier + start.elapsed().as_secs_f64();
    let save = |step: usize, log: &[EnhancerRow]| -> Result<(), TrainError> {
        let Some(dir) = &opts.checkpoints else { return Ok(()) };
        let tensors = unet.named_vars().into_iter().map(|(k, v)| (k, v.as_tensor().clone())).collect();
        let state =
            EnhancerState { step, seed: cfg.seed, model: cfg.model.clone(), log: log.to_vec(), init: init.clone() };
        Ok(crate::checkpoint::save(dir, &tensors, &state)?)
    };
    let mut adam = AdamW::new(
        unet.vars(),
        ParamsAdamW { lr: cfg.optimiser.lr, weight_decay: cfg.optimiser.weight_decay, ..Default::default() },
    )?;
    // Reseeded from the step on resume (see `checkpoint`).
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ ((first as u64 - 1) << 32) ^ 0xe4a);
    let pool: Vec<usize> = (0..scenes.train.len()).collect();
    let (mut order, mut face_order) = (Vec::new(), Vec::new());
    let (mut sum, mut count, mut hit_sum) = (0.0, 0usize, 0.0);
    if first == 1 {
        let row = EnhancerRow {
            step: 0,
            seconds: seconds(),
            loss: f64::NAN,
            face_top1: None,
            validation: validate(&unet, &scenes.validation, privacy, &dev)?,
        };
        on_row(&row);
        log.push(row);
    }
    for step in first..=cfg.budget.steps.max(first - 1) {
        let idx = crate::train::draw(&mut order, &pool, cfg.data.batch, &mut rng);
        let b = scenes.batch(&idx, cfg.data.crop, cfg.data.faces != FaceTarget::Restore, &mut rng, &dev)?;
        let (mut loss, v) = step_loss(&unet, cfg, &b)?;
        if let Some(p) = privacy {
            let t = p.term(&unet, &mut face_order, &mut rng, &dev)?;
            hit_sum += t.top1;
            loss = (loss + t.loss)?;
        }
        let total = loss.to_scalar::<f32>()? as f64;
        if !total.is_finite() {
            return Err(TrainError::Diverged(format!("enhancer loss is {total}: lower optimiser.lr")));
        }
        adam.step(&loss.backward()?)?;
        (sum, count) = (sum + v, count + 1);
        let last = step == cfg.budget.steps || start.elapsed().as_secs_f64() >= cfg.budget.seconds;
        let checkpoint = step % cfg.budget.checkpoint_every == 0 || last;
        if step % LOG_EVERY == 0 || checkpoint {
            let validation = if checkpoint { validate(&unet, &scenes.validation, privacy, &dev)? } else { None };
            let face_top1 = privacy.map(|_| hit_sum / count as f64);
            let row = EnhancerRow { step, seconds: seconds(), loss: sum / count as f64, face_top1, validation };
            (sum, count, hit_sum) = (0.0, 0, 0.0);
            on_row(&row);
            log.push(row);
        }
        if checkpoint {
            save(step, &log)?;
        }
        if last {
            break;
        }
    }
    let prov = serde_json::json!({
        "trainer": "campro train-enhancer",
        "config": cfg,
        "camera": params.name,
        "parameters": crate::unet::parameter_count(&cfg.model),
        "init": init,
        "privacy_faces": privacy.map(|p| serde_json::json!({ "identities": p.identities(), "train_faces": p.train_faces() })),
        "data": { "coco_images": scenes.coco, "lfw_images": scenes.lfw, "too_small": scenes.too_small,
                  "face_boxes": scenes.faces, "train_scenes": scenes.train.len(), "validation_scenes": scenes.validation.len(),
                  "coco_held_out": format!("COCO id % {} == 0 (never trained on)", campro_eval::data::HOLDOUT_EVERY),
                  "lfw_held_out_identities": held_out.len() },
        "steps": log.last().map_or(0, |r| r.step),
        "final": log.iter().rev().find(|r| r.validation.is_some()),
        "seconds": seconds(),
    });
    let serde_json::Value::Object(provenance) = prov else { unreachable!("a JSON object") };
    Ok(EnhancerOutcome { enhancer: EnhancerNet { unet, table: scenes.table }, log, seconds: seconds(), provenance })
}

/// One training step's loss on a batch, without the face-privacy term: the pixel loss
/// ([`enhancer_loss`], faces held to what `data.faces` says), plus `ssim_weight` ·
/// (1 − SSIM) against the same target ([`crate::ssim`]), plus the face gate's cross-entropy
/// (`gate_weight`). Returns the total and the pixel loss alone (what the log's loss column
/// reports).
pub fn step_loss(unet: &Unet, cfg: &EnhancerConfig, b: &SceneBatch) -> candle_core::Result<(Tensor, f64)> {
    let (pred, gate) = unet.forward_gated(&b.input, &b.captured)?;
    let held = match cfg.data.faces {
        FaceTarget::Captured => b.captured.clone(),
        FaceTarget::Pixelated => pixelate(&b.raw, cfg.model.gate_blocks)?,
        _ => b.input.clone(),
    };
    let pixel = enhancer_loss(&pred, &b.raw, &held, &b.keep, cfg.data.faces, cfg.loss)?;
    let v = pixel.to_scalar::<f32>()? as f64;
    let mut loss = pixel;
    if cfg.ssim_weight > 0.0 {
        // The config refuses "free" faces here: SSIM's windows cannot leave pixels out.
        let target = loss_target(&b.raw, &held, &b.keep, cfg.data.faces)?;
        loss = (loss + ((1.0 - crate::ssim::ssim(&pred, &target)?)? * cfg.ssim_weight)?)?;
    }
    if let Some(g) = &gate {
        loss = (loss + (gate_loss(g, &b.keep, cfg.gate_background)? * cfg.gate_weight)?)?;
    }
    Ok((loss, v))
}

/// Sets every tensor of `unet` that `tensors` holds under its name and shape; returns the
/// names of those it does not (they keep their values).
fn load_vars(unet: &Unet, tensors: &std::collections::HashMap<String, Tensor>) -> Result<Vec<String>, TrainError> {
    let mut missing = Vec::new();
    for (name, var) in unet.named_vars() {
        match tensors.get(&name).filter(|t| t.dims() == var.dims()) {
            Some(t) => var.set(t)?,
            None => missing.push(name),
        }
    }
    Ok(missing)
}

/// The log as CSV: step, seconds, loss, then the validation columns (empty between
/// checkpoints).
pub fn log_csv(log: &[EnhancerRow]) -> String {
    let mut csv = String::from(
        "step,seconds,loss,face_top1,val_masked_l1,val_face_l1,val_face_l1_input,val_psnr,val_psnr_input,val_psnr_captured,val_face_top1,val_face_top1_input,val_gate_faces,val_gate_scene,val_ssim\n",
    );
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6}"));
    for r in log {
        let v = r.validation.as_ref();
        csv += &format!(
            "{},{:.3},{:.6},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            r.step,
            r.seconds,
            r.loss,
            opt(r.face_top1),
            opt(v.map(|v| v.masked_l1)),
            opt(v.and_then(|v| v.face_l1)),
            opt(v.and_then(|v| v.face_l1_input)),
            opt(v.map(|v| v.psnr)),
            opt(v.map(|v| v.psnr_input)),
            opt(v.map(|v| v.psnr_captured)),
            opt(v.and_then(|v| v.face_top1)),
            opt(v.and_then(|v| v.face_top1_input)),
            opt(v.and_then(|v| v.gate_faces)),
            opt(v.and_then(|v| v.gate_scene)),
            opt(v.and_then(|v| v.ssim)),
        );
    }
    csv
}

/// The log as two SVG charts: the losses (training masked L1, validation masked and face
/// L1) and the validation PSNR, by step.
pub fn plot_log(log: &[EnhancerRow]) -> (String, String) {
    use campro_eval::plot::{chart, Series, Style};
    let series = |name: &str, f: &dyn Fn(&EnhancerRow) -> Option<f64>| Series {
        name: name.into(),
        points: log.iter().filter_map(|r| f(r).filter(|v| v.is_finite()).map(|v| (r.step as f64, v))).collect(),
    };
    let losses = chart(
        "campro train-enhancer: L1",
        "step",
        "mean |R(C(x)) − x|",
        &[
            series("training, masked", &|r| Some(r.loss)),
            series("validation, masked", &|r| r.validation.as_ref().map(|v| v.masked_l1)),
            series("validation, faces", &|r| r.validation.as_ref().and_then(|v| v.face_l1)),
        ],
        Style::Lines,
        None,
        None,
    );
    let psnr = chart(
        "campro train-enhancer: validation PSNR",
        "step",
        "dB",
        &[
            series("enhanced", &|r| r.validation.as_ref().map(|v| v.psnr)),
            series("U-Net input", &|r| r.validation.as_ref().map(|v| v.psnr_input)),
            series("captured", &|r| r.validation.as_ref().map(|v| v.psnr_captured)),
        ],
        Style::Lines,
        None,
        None,
    );
    (losses, psnr)
}
