//! The optimiser's configuration: one TOML file holds every hyper-parameter (paper
//! defaults), so a run is reproducible from its file and seed. Unknown keys are refused;
//! each rule names its key.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: {key}: {rule}")]
    Rule { path: String, key: String, rule: String },
    /// The fields together cost more than the budget ([`crate::cost`]).
    #[error("{key}: {rule}")]
    Budget { key: &'static str, rule: String },
}

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

/// The most rounds (camera training) or steps (the enhancer) a budget may ask: far beyond
/// any run (a round takes seconds), so that a counter can never wrap.
pub const MAX_ROUNDS: usize = 10_000_000;

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

/// The first of `checks` (holds, key, rule) that does not hold, as (key, rule).
fn first_broken(checks: &[(bool, &'static str, &'static str)]) -> Result<(), (&'static str, &'static str)> {
    match checks.iter().find(|c| !c.0) {
        Some(&(_, key, rule)) => Err((key, rule)),
        None => Ok(()),
    }
}

/// `budget.memory` when a configuration leaves it out: 1 GiB, MiB.
pub const DEFAULT_MEMORY_MIB: u64 = 1024;

/// The range of `budget.memory`, MiB.
const MEMORY_MIB: std::ops::RangeInclusive<u64> = 64..=1 << 20;

/// A configuration file's rules: the first broken one as (key, rule).
pub trait Rules {
    fn check(&self) -> Result<(), (&'static str, &'static str)>;
}

/// Reads and checks a TOML configuration (missing keys take their defaults): a regular
/// file of at most 1 MiB.
pub fn load<T: serde::de::DeserializeOwned + Rules>(path: &Path) -> Result<T, ConfigError> {
    let p = path.display().to_string();
    let text = campro::file::read_text_capped(path, 1 << 20, "a configuration")
        .map_err(|e| ConfigError::Parse { path: p.clone(), message: e.reason() })?;
    parse(&text, &p)
}

/// Parses and checks a TOML configuration; `origin` names it in errors.
pub fn parse<T: serde::de::DeserializeOwned + Rules>(text: &str, origin: &str) -> Result<T, ConfigError> {
    let c: T = toml::from_str(text).map_err(|e| ConfigError::Parse {
        path: origin.into(),
        message: e.message().to_string() + &span(text, e.span()),
    })?;
    c.check().map_err(|(key, rule)| ConfigError::Rule { path: origin.into(), key: key.into(), rule: rule.into() })?;
    Ok(c)
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

fn span(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    match span {
        Some(r) => {
            let line = text[..r.start.min(text.len())].lines().count().max(1);
            format!(" (line {line})")
        }
        None => String::new(),
    }
}

/// `campro train-enhancer`'s configuration: the enhancer's U-Net (paper Sec. IV-D), its data
/// and its optimiser. Every key is optional; unknown keys are refused.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct EnhancerConfig {
    /// Seed of every random choice (initial weights, data order, crops, validation split).
    pub seed: u64,
    pub model: UnetConfig,
    pub data: SceneConfig,
    pub optimiser: AdamWConfig,
    pub budget: StepBudget,
    /// The per-pixel distance the loss averages ([`PixelLoss`]).
    pub loss: PixelLoss,
    /// The face-privacy term ([`FacePrivacyConfig`]; off by default).
    pub privacy: FacePrivacyConfig,
    /// Weight of the face gate's cross-entropy against the face boxes beside the pixel loss
    /// (`model.face_gate`), 0..=100.
    pub gate_weight: f64,
    /// Weight of the cross-entropy's background pixels against its face pixels (0.01..=100):
    /// above 1 the gate opens only where it is sure, which keeps textures that merely look
    /// like the captured faces restored.
    pub gate_background: f64,
    /// Weight of `1 − SSIM` ([`crate::ssim`], the evaluation's SSIM) beside the pixel loss,
    /// against the same target, 0..=100 (0: off). The squared error alone gives blurred
    /// structure; SSIM asks for the local contrast and correlation the evaluation scores.
    pub ssim_weight: f64,
}

/// The enhancer's face-privacy term ([`crate::face_privacy`]): aligned LFW faces of the
/// preset's training identities go through the camera and the enhancer, and the term is
/// `weight · mean(max(0, cos_y − max_{c ≠ y} cos_c + margin))` over the white-box face
/// model's cosines to the raw class means. It asks what the face mask only leaves unasked:
/// that the enhanced face does not point back at its identity.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct FacePrivacyConfig {
    /// Weight beside the pixel loss, 0..=1000; 0: off (no faces read).
    pub weight: f64,
    /// Aligned faces per step, 1..=256.
    pub faces: usize,
    /// How far (cosine, 0..=2) below the best other identity a face's own must rank before it
    /// costs nothing.
    pub margin: f64,
    /// The white-box face model: MobileFaceNet's PyTorch checkpoint.
    pub checkpoint: PathBuf,
    /// LFW identities with at least this many photos (2..=100) give faces; the preset's
    /// held-out identities never do.
    pub min_images: usize,
    /// At most this many of them (a seeded choice); None: all.
    pub max_identities: Option<usize>,
    /// Check faces (each training identity's last photo, never drawn for the term) scored
    /// at every checkpoint.
    pub validation_faces: usize,
}

impl Default for FacePrivacyConfig {
    fn default() -> Self {
        Self {
            weight: 0.0,
            faces: 8,
            margin: 0.1,
            checkpoint: "../shared/models/mobilefacenet_casia_068.ckpt".into(),
            min_images: 5,
            max_identities: None,
            validation_faces: 64,
        }
    }
}

/// The distance between the enhanced and the target pixel that the enhancer's loss averages.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PixelLoss {
    /// `|R(C(x)) − x|`, the paper's. Its gradient is a sign: behind the per-pixel
    /// restoration table, whose per-pixel error is already minimal on average, a fresh U-Net
    /// found nothing in it to follow (docs/enhancer.md).
    #[default]
    L1,
    /// `(R(C(x)) − x)²`, what PSNR measures.
    L2,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct UnetConfig {
    /// Channels per level, full resolution first; each further level halves the resolution
    /// ([`crate::unet`]). 1 to 6 levels of 1..=512.
    pub widths: Vec<usize>,
    /// Hidden units of a per-pixel stem (two 1x1 convolutions with ReLU) in front of the
    /// first level, 0..=256; 0: none.
    pub stem: usize,
    /// Put the camera's per-pixel restoration in front of the U-Net: each captured colour
    /// replaced by the mean raw colour producing it in the training scenes
    /// ([`campro_eval::restore`], a 786 KB table in the ONNX file), so the U-Net starts from
    /// the best per-pixel inverse and learns what context adds.
    pub restorer: bool,
    /// A face gate: a second head (a branch at the deepest level plus a 1x1 convolution of
    /// the last decoder level, then a sigmoid; [`crate::unet`]) gives each pixel the
    /// probability `g` that it is a face, and the enhanced
    /// pixel is `g · captured + (1 − g) · restored`, so a face the gate finds leaves the
    /// enhancer as the camera captured it. Trained on YuNet's (enlarged) boxes of the raw
    /// scenes with `data.faces = "captured"` and the cross-entropy weighted by
    /// `gate_weight`. In the ONNX file too (four operators after the U-Net).
    pub face_gate: bool,
    /// With the face gate: 0 (default), a gated pixel becomes the captured one; N (a power of
    /// two in 2..=64), it becomes the enhanced image's mean over its N x N block
    /// (pixelation), trained with `data.faces = "pixelated"`. The picture keeps a face's
    /// place and colour but not its features, and where the gate opens by mistake on
    /// scenery the cost is a blur rather than the captured image's contour bands.
    pub gate_blocks: usize,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    /// COCO person folder: its training part only (never the held-out images).
    pub coco: PathBuf,
    /// LFW folder: photos of training identities only (never the preset's held-out ones).
    pub lfw: PathBuf,
    /// Models folder (YuNet, for the face masks).
    pub models: PathBuf,
    /// Use at most this many COCO training images (first by id); None: all.
    pub max_images: Option<usize>,
    /// LFW photos of training identities to add (seeded choice); 0: none.
    pub lfw_images: usize,
    /// Training images kept aside (seeded) to validate on; never trained on.
    pub validation_images: usize,
    /// Side of the square training crops (pixels, a multiple of the U-Net's multiple).
    pub crop: usize,
    /// Crops per step.
    pub batch: usize,
    /// Each YuNet face box grows by this fraction of its width left and right and of its
    /// height below, and by twice that above (hair), before it is masked.
    pub face_margin: f64,
    /// What the loss asks of the face boxes ([`FaceTarget`]).
    pub faces: FaceTarget,
    /// YuNet's face boxes are cached here (one file per image list and model folder).
    pub cache: PathBuf,
}

/// What the enhancer's loss asks of the pixels inside the (enlarged) face boxes.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum FaceTarget {
    /// Keep them as the U-Net's input has them: L1 to that input there, to the raw image
    /// elsewhere. The input is the captured image or, with `model.restorer`, its per-pixel
    /// restoration, which anyone who knows the camera can compute; so the enhanced face
    /// carries no more of the face than that.
    Input,
    /// The paper's loss as written, `mean(s ⊙ |R(C(x)) − x|)`: nothing asked of faces, so
    /// they come out however the network generalises (partly restored, measured).
    Free,
    /// No mask: restore faces too. The restoration attacker's network (Sec. VII), not an
    /// enhancer to ship.
    Restore,
    /// Inside the boxes the target is the captured image itself, what the camera already
    /// gives every app; needs `model.face_gate`, which learns where they are.
    Captured,
    /// Inside the boxes the target is the raw image pixelated in `model.gate_blocks`
    /// blocks; needs the face gate with those blocks.
    Pixelated,
}

/// AdamW (the paper's enhancer: lr 3e-4, weight decay 1e-2).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct AdamWConfig {
    pub lr: f64,
    pub weight_decay: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StepBudget {
    /// Optimiser steps in all (a resumed run continues the count); 0 writes the untrained
    /// network (behind the restoration table with no gate: the table alone).
    pub steps: usize,
    /// Stop after this many seconds in this invocation (checkpoint written).
    pub seconds: f64,
    /// Checkpoint and validate every this many steps.
    pub checkpoint_every: usize,
    /// Peak memory one step may take, MiB (64..=1048576; default 1024): the step's cost
    /// ([`crate::cost::enhancer_step`]) is checked against it before anything is allocated.
    pub memory: u64,
}

impl UnetConfig {
    /// Height and width of the network's input must be multiples of this: 2^(levels − 1)
    /// (levels clamped to 1..=6), or the gate's pixelation blocks when larger.
    pub fn multiple(&self) -> usize {
        (1usize << self.widths.len().clamp(1, 6).saturating_sub(1)).max(self.gate_blocks)
    }
}

impl Default for UnetConfig {
    fn default() -> Self {
        Self { widths: vec![8, 16, 32, 64], stem: 0, restorer: true, face_gate: false, gate_blocks: 0 }
    }
}
impl Default for EnhancerConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            model: UnetConfig::default(),
            data: SceneConfig::default(),
            optimiser: AdamWConfig::default(),
            budget: StepBudget::default(),
            loss: PixelLoss::default(),
            privacy: FacePrivacyConfig::default(),
            gate_weight: 1.0,
            gate_background: 1.0,
            ssim_weight: 0.0,
        }
    }
}
impl Default for SceneConfig {
    fn default() -> Self {
        Self {
            coco: "../shared/data/coco-person".into(),
            lfw: "../shared/data/lfw".into(),
            models: "../shared/models".into(),
            max_images: None,
            lfw_images: 1000,
            validation_images: 32,
            crop: 128,
            batch: 8,
            face_margin: 0.3,
            faces: FaceTarget::Input,
            cache: "target/campro-train-cache".into(),
        }
    }
}
impl Default for AdamWConfig {
    fn default() -> Self {
        Self { lr: 3e-4, weight_decay: 1e-2 }
    }
}
impl Default for StepBudget {
    fn default() -> Self {
        Self { steps: 20_000, seconds: 4.0 * 3600.0, checkpoint_every: 500, memory: DEFAULT_MEMORY_MIB }
    }
}

impl Rules for EnhancerConfig {
    fn check(&self) -> Result<(), (&'static str, &'static str)> {
        let w = &self.model.widths;
        let blocks = self.model.gate_blocks;
        let multiple = self.model.multiple();
        let p = &self.privacy;
        let gate = self.model.face_gate;
        let checks: [(bool, &str, &str); 27] = [
            (
                self.ssim_weight.is_finite() && (0.0..=100.0).contains(&self.ssim_weight),
                "ssim_weight",
                "must be in [0, 100] (0: off)",
            ),
            (
                self.ssim_weight == 0.0 || self.data.faces != FaceTarget::Free,
                "ssim_weight",
                "needs a target inside the faces (data.faces other than \"free\"): SSIM's windows cannot leave pixels out",
            ),
            (
                self.gate_background.is_finite() && (0.01..=100.0).contains(&self.gate_background),
                "gate_background",
                "must be in [0.01, 100]",
            ),
            (
                !gate || matches!(self.data.faces, FaceTarget::Captured | FaceTarget::Pixelated),
                "model.face_gate",
                "needs data.faces = \"captured\" or \"pixelated\" (the gate's target)",
            ),
            (
                gate || !matches!(self.data.faces, FaceTarget::Captured | FaceTarget::Pixelated),
                "data.faces",
                "\"captured\" and \"pixelated\" need model.face_gate = true (a U-Net alone cannot tell faces)",
            ),
            (
                blocks == 0 || (blocks.is_power_of_two() && (2..=64).contains(&blocks)),
                "model.gate_blocks",
                "must be 0 or a power of two in 2..=64",
            ),
            (
                (blocks > 0) == (self.data.faces == FaceTarget::Pixelated),
                "model.gate_blocks",
                "is set exactly when data.faces = \"pixelated\" (the blocks the faces become)",
            ),
            (
                self.gate_weight.is_finite() && (0.0..=100.0).contains(&self.gate_weight),
                "gate_weight",
                "must be in [0, 100]",
            ),
            (
                p.weight.is_finite() && (0.0..=1000.0).contains(&p.weight),
                "privacy.weight",
                "must be in [0, 1000] (0: off)",
            ),
            ((1..=256).contains(&p.faces), "privacy.faces", "must be in 1..=256"),
            (p.margin.is_finite() && (0.0..=2.0).contains(&p.margin), "privacy.margin", "must be in [0, 2]"),
            (p.validation_faces <= 4096, "privacy.validation_faces", "must be at most 4096"),
            ((2..=100).contains(&p.min_images), "privacy.min_images", "must be in 2..=100"),
            (
                p.max_identities.is_none_or(|m| m >= 2),
                "privacy.max_identities",
                "must be at least 2 (leave it out for all)",
            ),
            (
                (1..=6).contains(&w.len()) && w.iter().all(|c| (1..=512).contains(c)),
                "model.widths",
                "must hold 1 to 6 levels of 1..=512 channels",
            ),
            (self.model.stem <= 256, "model.stem", "must be at most 256 hidden units (0 for none)"),
            (
                (16..=1024).contains(&self.data.crop) && self.data.crop.is_multiple_of(multiple),
                "data.crop",
                "must be in 16..=1024 and a multiple of 2^(levels - 1) and of model.gate_blocks",
            ),
            ((1..=256).contains(&self.data.batch), "data.batch", "must be in 1..=256"),
            (
                self.data.face_margin.is_finite() && (0.0..=2.0).contains(&self.data.face_margin),
                "data.face_margin",
                "must be in [0, 2]",
            ),
            (self.data.max_images != Some(0), "data.max_images", "must be at least 1 (leave it out for all)"),
            (self.data.lfw_images <= 100_000, "data.lfw_images", "must be at most 100000"),
            (self.optimiser.lr.is_finite() && self.optimiser.lr > 0.0, "optimiser.lr", "must be finite and > 0"),
            (
                self.optimiser.weight_decay.is_finite() && self.optimiser.weight_decay >= 0.0,
                "optimiser.weight_decay",
                "must be finite and ≥ 0",
            ),
            (self.budget.seconds.is_finite() && self.budget.seconds > 0.0, "budget.seconds", "must be finite and > 0"),
            // 0: the restoration table alone (configs/enhancer-table.toml).
            (self.budget.steps <= MAX_ROUNDS, "budget.steps", "must be at most 10000000"),
            (self.budget.checkpoint_every >= 1, "budget.checkpoint_every", "must be ≥ 1"),
            (MEMORY_MIB.contains(&self.budget.memory), "budget.memory", "must be in 64..=1048576 (MiB)"),
        ];
        first_broken(&checks)
    }
}
