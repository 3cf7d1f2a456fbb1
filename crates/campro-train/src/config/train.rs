//! `campro train`'s configuration: the camera, the players, the data, the budget and the
//! validation-driven stop.

use super::{first_broken, load, parse, ConfigError, Rules, DEFAULT_MEMORY_MIB, MAX_ROUNDS, MEMORY_MIB};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Seed of every random choice (data order, splits, initialisation).
    pub seed: u64,
    pub camera: CameraConfig,
    pub attacker: AttackerConfig,
    pub protector: ProtectorConfig,
    pub data: DataConfig,
    pub detector: DetectorConfig,
    pub budget: BudgetConfig,
    pub validation: ValidationConfig,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Tone-curve knots k (paper: 32).
    pub knots: usize,
    /// A curve per output channel (Camera2's `TONEMAP_CURVE` takes three) instead of one
    /// for the three (the paper's camera).
    pub per_channel: bool,
    /// Degamma exponent (2.2).
    pub gamma: f64,
    /// Adam learning rate for the CCM and curve (paper: 1e-3).
    pub lr: f64,
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Head {
    /// Linear layer + softmax cross-entropy.
    Softmax,
    /// Additive angular margin (ArcFace, s = 64, m = 0.5) on normalised features.
    Arcface,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct AttackerConfig {
    /// PyTorch checkpoint of the white-box backbone F (MobileFaceNet).
    pub checkpoint: PathBuf,
    pub head: Head,
    /// SGD learning rate of the proxy head H (paper: 0.1 for the attacker).
    pub lr: f64,
    /// SGD learning rate of the pretrained backbone F. The paper's 0.1 destroyed
    /// MobileFaceNet's features within two rounds at batch 16 here (cross-entropy to chance,
    /// then NaN), so the default is 0.01.
    pub backbone_lr: f64,
    /// Head pretraining on raw faces stops at this training accuracy (0..1) ...
    pub pretrain_accuracy: f64,
    /// ... or after this many steps.
    pub pretrain_steps: usize,
    /// Attacker steps per round (m); 0 with `protector_only`.
    pub steps_per_round: usize,
    /// Update the batch-norm statistics in attacker steps (else they stay frozen).
    pub train_batch_norm: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ProtectorConfig {
    /// Protector steps per round (n).
    pub steps_per_round: usize,
    /// Weight ω of the detection loss (paper: 0.2).
    pub omega: f64,
    /// The paper's ablation: no attacker steps after pretraining.
    pub protector_only: bool,
    /// Weight (0..=10) of the grey term: each face batch is also made grey (BT.601 luma,
    /// [`crate::faces::grey`]) and its privacy loss, times this weight, joins the colour
    /// one; the attacker trains on both. 0 (the default) leaves the grey axis to chance.
    pub grey: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DataConfig {
    /// LFW folder (identities as sub-folders of `images_deepfunneled/`).
    pub lfw: PathBuf,
    /// Models folder (YuNet for alignment).
    pub models: PathBuf,
    /// Identities with at least this many photos form the proxy head's classes.
    pub min_images: usize,
    /// Fraction of those identities held out for validation (never trained on).
    pub validation_identities: f64,
    /// Use at most this many identities (tiny runs, CI).
    pub max_identities: Option<usize>,
    /// Faces per batch.
    pub batch: usize,
    /// Aligned crops are cached here (one file per configuration of the face set).
    pub cache: PathBuf,
}

/// The utility player P (used when `protector.omega > 0`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DetectorConfig {
    /// YOLOX ONNX file (batch-norm folded), fine-tuned from here.
    pub model: PathBuf,
    /// COCO person folder (`instances_person.json`, `images/`).
    pub data: PathBuf,
    /// Training canvas side in pixels (multiple of 32; the evaluation runs at 416).
    pub size: usize,
    /// Images per protector step.
    pub batch: usize,
    /// Adam learning rate of the detector (the issue: SGD 1e-4 diverged, Adam 1e-5 trained);
    /// 0 keeps it frozen.
    pub lr: f64,
    /// Use at most this many images (first by COCO id).
    pub max_images: Option<usize>,
    /// Weight of the distillation term ([`crate::detection::distill_loss`]: `model` as
    /// loaded, frozen, on the unprotected image as the teacher) added to the detection loss,
    /// in the joint training and in `finetune-detector` alike; 0 (the default) leaves it out.
    pub distill: f64,
    /// Hidden units of a per-pixel colour adapter in front of the detector
    /// ([`campro_nn::yolox::Yolox::with_adapter`]: 1x1 convolutions, starting as the identity,
    /// written into the fine-tuned ONNX file); 0 (the default) adds none. A detector
    /// fine-tuned at `lr` = 1e-5 barely moves its first layer (Adam moves a weight by about
    /// `lr` a step), so it cannot undo even a colour inversion, which that layer could absorb
    /// exactly, and a larger `lr` everywhere breaks the deeper layers (README, detector
    /// section). The adapter learns the colour map at its own rate instead and, in
    /// `campro train`, takes one fitting step ([`crate::detection::AdapterFit`]) per
    /// protector step to follow the camera.
    pub adapter: usize,
    /// Adam learning rate of the adapter (its share of the detection loss, and its fitting
    /// steps in `campro train`).
    pub adapter_lr: f64,
    /// `finetune-detector` first fits the adapter alone for this many steps (Adam at
    /// [`crate::finetune::FIT_LR`], a person batch each) to undo the camera pixel by pixel,
    /// `adapter(C(x)) ≈ x` in squared error, which needs no detector pass. 0 skips it.
    pub adapter_fit: usize,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct BudgetConfig {
    /// Rounds of (m attacker + n protector) steps.
    pub rounds: usize,
    /// Stop after this many seconds of training in this invocation (a resumed run gets the
    /// whole budget again; checkpoint written).
    pub seconds: f64,
    /// Write a checkpoint every this many rounds.
    pub checkpoint_every: usize,
    /// Peak memory one step may take, MiB (64..=1048576; default 1024): the step's cost
    /// ([`crate::cost::train_step`]) is checked against it before anything is allocated.
    pub memory: u64,
}

/// The validation-driven stop ([`crate::validation`]): every `every` rounds the current
/// camera is scored on data training never draws (never the evaluation's held-out
/// identities or images), the best camera so far is kept, and the run stops once `patience`
/// validations in a row bring no better one; the parameter set written is the best one.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ValidationConfig {
    /// Validate every this many rounds; 0 (the default) never validates, and the run ends at
    /// its budget with its last camera.
    pub every: usize,
    /// COCO training images set aside for the utility score (the last of the training images
    /// by id; never drawn for training). Used when `protector.omega > 0`.
    pub images: usize,
    /// The privacy bound (0..1): a camera whose validation top-1 is above it is only better
    /// than another above it by being more private; below it, by person AP.
    pub max_top1: f64,
    /// Stop after this many validations in a row without a better camera; 0 runs the whole
    /// budget (still writing the best camera).
    pub patience: usize,
}

impl Default for ValidationConfig {
    fn default() -> Self {
        Self { every: 0, images: 64, max_top1: 0.02, patience: 0 }
    }
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self { knots: 32, per_channel: false, gamma: 2.2, lr: 1e-3 }
    }
}
impl Default for AttackerConfig {
    fn default() -> Self {
        Self {
            checkpoint: "../shared/models/mobilefacenet_casia_068.ckpt".into(),
            head: Head::Softmax,
            lr: 0.1,
            backbone_lr: 0.01,
            pretrain_accuracy: 0.9,
            pretrain_steps: 500,
            steps_per_round: 1,
            train_batch_norm: false,
        }
    }
}
impl Default for ProtectorConfig {
    fn default() -> Self {
        Self { steps_per_round: 1, omega: 0.2, protector_only: false, grey: 0.0 }
    }
}
impl Default for DataConfig {
    fn default() -> Self {
        Self {
            lfw: "../shared/data/lfw".into(),
            models: "../shared/models".into(),
            min_images: 5,
            validation_identities: 0.2,
            max_identities: None,
            batch: 16,
            cache: "target/campro-train-cache".into(),
        }
    }
}
impl Default for DetectorConfig {
    fn default() -> Self {
        Self {
            model: "../shared/models/yolox_nano.onnx".into(),
            data: "../shared/data/coco-person".into(),
            size: 320,
            batch: 4,
            lr: 1e-5,
            max_images: None,
            distill: 0.0,
            adapter: 0,
            adapter_lr: 1e-3,
            adapter_fit: 0,
        }
    }
}

impl Default for BudgetConfig {
    fn default() -> Self {
        Self { rounds: 2000, seconds: 4.0 * 3600.0, checkpoint_every: 100, memory: DEFAULT_MEMORY_MIB }
    }
}

impl Config {
    /// The files and folders a training reads, by key: LFW, the models folder and the face
    /// model, and the detector and COCO when the utility player plays (`protector.omega`
    /// above 0). Relative paths are relative to the folder campro runs in.
    pub fn inputs(&self) -> Vec<(&'static str, &Path)> {
        let mut v = vec![
            ("data.lfw", self.data.lfw.as_path()),
            ("data.models", self.data.models.as_path()),
            ("attacker.checkpoint", self.attacker.checkpoint.as_path()),
        ];
        if self.protector.omega > 0.0 {
            v.extend([
                ("detector.model", self.detector.model.as_path()),
                ("detector.data", self.detector.data.as_path()),
            ]);
        }
        v
    }

    /// Reads and checks a TOML file (missing keys take the paper's defaults).
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        load(path)
    }

    pub fn parse(text: &str, origin: &str) -> Result<Self, ConfigError> {
        parse(text, origin)
    }
}

impl Rules for Config {
    /// Every rule, first broken one reported.
    fn check(&self) -> Result<(), (&'static str, &'static str)> {
        let finite_pos = |v: f64| v.is_finite() && v > 0.0;
        let checks: [(bool, &str, &str); 27] = [
            ((2..=1024).contains(&self.camera.knots), "camera.knots", "must be in 2..=1024"),
            (MEMORY_MIB.contains(&self.budget.memory), "budget.memory", "must be in 64..=1048576 (MiB)"),
            (
                self.camera.gamma.is_finite() && (0.2..=5.0).contains(&self.camera.gamma),
                "camera.gamma",
                "must be in [0.2, 5]",
            ),
            (finite_pos(self.camera.lr), "camera.lr", "must be finite and > 0"),
            (finite_pos(self.attacker.lr), "attacker.lr", "must be finite and > 0"),
            (
                self.attacker.backbone_lr.is_finite() && self.attacker.backbone_lr >= 0.0,
                "attacker.backbone_lr",
                "must be finite and ≥ 0 (0 freezes F)",
            ),
            ((0.0..=1.0).contains(&self.attacker.pretrain_accuracy), "attacker.pretrain_accuracy", "must be in [0, 1]"),
            (self.protector.steps_per_round >= 1, "protector.steps_per_round", "must be ≥ 1"),
            (
                self.protector.omega.is_finite() && self.protector.omega >= 0.0,
                "protector.omega",
                "must be finite and ≥ 0",
            ),
            ((0.0..=10.0).contains(&self.protector.grey), "protector.grey", "must be in [0, 10]"),
            (
                self.protector.protector_only || self.attacker.steps_per_round >= 1,
                "attacker.steps_per_round",
                "must be ≥ 1 unless protector.protector_only",
            ),
            (self.data.min_images >= 2, "data.min_images", "must be ≥ 2 (one photo to train on, one to check)"),
            ((0.0..1.0).contains(&self.data.validation_identities), "data.validation_identities", "must be in [0, 1)"),
            ((1..=4096).contains(&self.data.batch), "data.batch", "must be in 1..=4096"),
            (
                self.detector.size.is_multiple_of(32) && (64..=1024).contains(&self.detector.size),
                "detector.size",
                "must be a multiple of 32 in 64..=1024",
            ),
            ((1..=256).contains(&self.detector.batch), "detector.batch", "must be in 1..=256"),
            (
                self.detector.lr.is_finite() && self.detector.lr >= 0.0,
                "detector.lr",
                "must be finite and ≥ 0 (0 freezes P)",
            ),
            (
                self.detector.distill.is_finite() && self.detector.distill >= 0.0,
                "detector.distill",
                "must be finite and ≥ 0 (0 leaves it out)",
            ),
            (self.detector.adapter <= 4096, "detector.adapter", "must be at most 4096 hidden units (0 for none)"),
            (
                self.detector.adapter_fit == 0 || self.detector.adapter > 0,
                "detector.adapter_fit",
                "needs detector.adapter > 0 (there is no adapter to fit)",
            ),
            (
                self.detector.adapter_lr.is_finite() && self.detector.adapter_lr >= 0.0,
                "detector.adapter_lr",
                "must be finite and ≥ 0 (0 freezes the adapter)",
            ),
            (self.budget.seconds.is_finite() && self.budget.seconds > 0.0, "budget.seconds", "must be finite and > 0"),
            ((1..=MAX_ROUNDS).contains(&self.budget.rounds), "budget.rounds", "must be in 1..=10000000"),
            (self.budget.checkpoint_every >= 1, "budget.checkpoint_every", "must be ≥ 1"),
            (
                self.validation.every == 0 || (1..=100_000).contains(&self.validation.images),
                "validation.images",
                "must be in 1..=100000",
            ),
            (
                self.validation.max_top1.is_finite() && (0.0..=1.0).contains(&self.validation.max_top1),
                "validation.max_top1",
                "must be in [0, 1]",
            ),
            (
                self.validation.patience == 0 || self.validation.every > 0,
                "validation.patience",
                "needs validation.every > 0 (nothing is validated)",
            ),
        ];
        first_broken(&checks)
    }
}
