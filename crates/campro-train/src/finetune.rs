//! Fine-tunes the person detector for one fixed camera: the paper's utility protocol (its
//! App. B: "we finetune the person detector ... for each method"), run after `campro train`
//! or for any parameter set. YOLOX-Nano starts from its ONNX file and takes Adam steps on
//! the detection loss ([`crate::detection::utility_loss`]: YOLOX's, plus `distill` times a
//! distillation term from the unchanged detector on the raw images) over the training part of the COCO
//! person set, epoch by epoch; the held-out images
//! ([`campro_eval::data::detector_held_out`]) are never seen, so `eval utility
//! --own-detector` scores on them alone.

use crate::camera::Camera;
use crate::config::DetectorConfig;
use crate::detection::utility_loss;
use crate::error::TrainError;
use crate::persons::PersonSet;
use crate::train::draw;
use campro_nn::yolox::Yolox;
use rand::SeedableRng;

/// Adam's rate for the adapter's fit before fine-tuning (`detector.adapter_fit`).
pub const FIT_LR: f64 = 1e-2;

/// The camera a detector is fine-tuned behind.
#[derive(Debug, Clone)]
pub enum Imaging {
    /// Unprocessed sRGB (the images as stored).
    Raw,
    /// campro's desktop pipeline with these values: CCM, curve outputs at evenly spaced
    /// knots (one row, or three: red, green, blue), degamma exponent.
    Camera { ccm: [[f64; 3]; 3], curves: Vec<Vec<f64>>, gamma: f64 },
}

/// How long to fine-tune, and where.
#[derive(Debug, Clone)]
pub struct FinetuneOptions {
    /// Detector steps (each `batch` images).
    pub steps: usize,
    /// Stop after this many seconds even if steps remain.
    pub seconds: f64,
    /// Seed of the image order.
    pub seed: u64,
    /// Where it computes (default: the CPU).
    pub ctx: campro_nn::Context,
    /// Peak memory one step may take, MiB (`budget.memory`).
    pub memory: u64,
}

impl Default for FinetuneOptions {
    fn default() -> Self {
        Self {
            steps: 0,
            seconds: f64::INFINITY,
            seed: 0,
            ctx: Default::default(),
            memory: crate::config::DEFAULT_MEMORY_MIB,
        }
    }
}

/// One step of the log.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct StepRow {
    pub step: usize,
    pub seconds: f64,
    /// `5·L_iou + L_obj + L_cls + distill·L_kd` of the batch, before the step.
    pub loss: f64,
    pub iou: f64,
    pub obj: f64,
    pub cls: f64,
    pub positives: usize,
    /// The distillation term L_kd before its weight (0 when `distill` is 0).
    pub kd: f64,
}

/// The fine-tuned detector and its log.
pub struct Finetuned {
    pub detector: Yolox,
    pub log: Vec<StepRow>,
    /// Training images available (the held-out ones excluded).
    pub images: usize,
    /// The adapter fit's squared error per step (`detector.adapter_fit`; empty without).
    pub adapter_fit: Vec<f64>,
}

/// Fine-tunes `cfg.model` behind `imaging` with `cfg`'s data, size, batch and learning rate.
pub fn run(
    imaging: &Imaging,
    cfg: &DetectorConfig,
    o: &FinetuneOptions,
    mut on_step: impl FnMut(&StepRow),
) -> Result<Finetuned, TrainError> {
    if cfg.lr <= 0.0 {
        return Err(TrainError::Unsupported("detector.lr: must be > 0 to fine-tune".into()));
    }
    crate::cost::check(&crate::cost::detector_step(cfg), o.memory)?;
    let dev = o.ctx.device.clone();
    let set = PersonSet::open(&cfg.data, cfg.size, cfg.max_images)?;
    if set.is_empty() {
        return Err(TrainError::Unsupported(format!(
            "{}: no person images outside the held-out part",
            cfg.data.display()
        )));
    }
    let camera = match imaging {
        Imaging::Raw => None,
        Imaging::Camera { ccm, curves, gamma } => Some(Camera::from_values(*ccm, curves, *gamma, &dev)?),
    };
    let det = crate::detection::student(cfg, o.seed, &dev)?;
    let teacher = crate::detection::teacher(cfg, &dev)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(o.seed);
    let pool: Vec<usize> = (0..set.len()).collect();
    let mut order = Vec::new();
    // The camera is fixed: its output is data here.
    let through = |x: &candle_core::Tensor| -> candle_core::Result<candle_core::Tensor> {
        match &camera {
            Some(c) => Ok(c.forward(x)?.detach()),
            None => Ok(x.clone()),
        }
    };
    // The time budget counts from here: the adapter's fit spends it too.
    let start = std::time::Instant::now();
    let mut fit = Vec::new();
    let fitter = if cfg.adapter_fit > 0 { crate::detection::AdapterFit::new(&det, FIT_LR)? } else { None };
    if let Some(mut fitter) = fitter {
        for _ in 0..cfg.adapter_fit {
            if start.elapsed().as_secs_f64() >= o.seconds {
                break;
            }
            let b = set.batch(&draw(&mut order, &pool, cfg.batch, &mut rng), &dev)?;
            fit.push(fitter.step(&det, &through(&b.x)?, &b)?);
        }
    }
    let mut adam = crate::detection::DetectorAdam::new(&det, cfg)?;
    // The log grows as the steps run (a step is ~0.5 s): never reserved from the flag.
    let mut log = Vec::new();
    for step in 1..=o.steps {
        if start.elapsed().as_secs_f64() >= o.seconds {
            break;
        }
        let b = set.batch(&draw(&mut order, &pool, cfg.batch, &mut rng), &dev)?;
        let x = through(&b.x)?;
        let (loss, parts) = utility_loss(&det, teacher.as_ref(), cfg, &x, &b)?;
        let l = loss.to_scalar::<f32>()? as f64;
        if !l.is_finite() {
            return Err(TrainError::Diverged(format!("detection loss is {l} at step {step}: lower detector.lr")));
        }
        adam.step(&loss.backward()?)?;
        let row = StepRow {
            step,
            seconds: start.elapsed().as_secs_f64(),
            loss: l,
            iou: parts.iou,
            obj: parts.obj,
            cls: parts.cls,
            positives: parts.positives,
            kd: parts.kd,
        };
        on_step(&row);
        log.push(row);
    }
    Ok(Finetuned { detector: det, log, images: set.len(), adapter_fit: fit })
}
