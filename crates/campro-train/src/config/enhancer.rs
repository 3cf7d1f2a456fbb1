//! `campro train-enhancer`'s configuration.

use super::{first_broken, Rules, DEFAULT_MEMORY_MIB, MAX_ROUNDS, MEMORY_MIB};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

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
