//! What one training step costs, from a configuration's fields together: its peak memory
//! and its time. Every training entry point ([`crate::train::run`],
//! [`crate::finetune::run`], [`crate::enhancer::run`]) checks its step against
//! `budget.memory` ([`check`]) before it reads data or allocates a tensor, and refuses with
//! one line naming the fields and the figure.
//!
//! Each field may be within its own rule while their product is not (`detector.size =
//! 1024` with `detector.batch = 256`); the model multiplies them. Its coefficients were
//! measured on this project's CPU build (peak resident memory, `/usr/bin/time -f %M`, of
//! `campro bench train --only …` and `campro bench enhancer` at two sizes each, and of one
//! round of `campro train`; 2 threads) and are rounded up: the estimate is meant to be
//! at or above the real peak of a step (docs/optimiser.md gives the table).

use crate::config::{Config, ConfigError, DetectorConfig, EnhancerConfig};

const MIB: f64 = 1024.0 * 1024.0;

/// The process, the networks and their optimiser state. The data a run holds comes on top:
/// the face crops (`campro train`: added once the face set is read, before any network)
/// and the decoded scenes (`train-enhancer`: from the files' headers, before decoding).
pub const BASE: f64 = 160.0 * MIB;
/// One face through MobileFaceNet (112 x 96) forward and backward with its backbone
/// trained, the attacker's step: 52.3 MiB measured (8 → 32 faces: 447 → 1,701 MiB).
pub const ATTACKER_PER_FACE: f64 = 56.0 * MIB;
/// One face through the camera and the frozen MobileFaceNet, forward and backward (the
/// protector's privacy term): 37 MiB measured (8 → 32 faces: 302 → 1,189 MiB).
pub const PRIVACY_PER_FACE: f64 = 40.0 * MIB;
/// One input pixel through YOLOX-Nano forward and backward: 1,350 bytes measured (a 320²
/// image 132 MiB; 640² four times that).
pub const DETECTOR_PER_PIXEL: f64 = 1_400.0;
/// One hidden unit of the detector's colour adapter at one pixel: its pre-activation,
/// activation and gradient in f32 (the adapter is a per-pixel MLP).
pub const ADAPTER_PER_UNIT_PIXEL: f64 = 12.0;
/// One U-Net channel at one full-resolution pixel (a level of half the side counts a
/// quarter), forward, loss and backward: 74–79 bytes measured (widths 8..64 and 16..128).
pub const UNET_PER_CHANNEL_PIXEL: f64 = 84.0;
/// Seconds per face of the attacker's step (2 threads; 107 ms measured).
pub const ATTACKER_SECONDS_PER_FACE: f64 = 0.11;
/// Seconds per face of the protector's privacy term (2 threads; 79 ms measured).
pub const PRIVACY_SECONDS_PER_FACE: f64 = 0.08;
/// Seconds per input pixel of YOLOX-Nano's step (2 threads; 1.5 s for 4 x 320²).
pub const DETECTOR_SECONDS_PER_PIXEL: f64 = 3.8e-6;
/// Seconds per multiply-accumulate of the U-Net's step, forward and backward (2 threads;
/// 1.0 s for 8 x 128² at 7,728 MACs a pixel).
pub const UNET_SECONDS_PER_MAC: f64 = 1.0e-9;

/// One step's estimated peak memory and time, and what they come from.
#[derive(Debug, Clone, PartialEq)]
pub struct StepCost {
    /// Peak resident memory, bytes.
    pub bytes: f64,
    /// Seconds of one step on two threads.
    pub seconds: f64,
    /// The fields that make the cost, as they read (`data.batch 8`, `detector.size 320`).
    pub fields: Vec<String>,
}

impl StepCost {
    /// The cost in MiB, rounded up.
    pub fn mib(&self) -> u64 {
        (self.bytes / MIB).ceil() as u64
    }
}

/// The costliest step of a `campro train` / `finetune-detector` configuration: the
/// attacker's (its face batch), the protector's (the privacy term, twice with the grey term,
/// and the detector's batch with its adapter, all in one graph), or the adapter's fit.
pub fn train_step(c: &Config) -> StepCost {
    let faces = c.data.batch as f64;
    let pixels = (c.detector.batch * c.detector.size * c.detector.size) as f64;
    let adapter = c.detector.adapter as f64;
    let grey = if c.protector.grey > 0.0 { 2.0 } else { 1.0 };
    let attacker = if c.protector.protector_only { 0.0 } else { faces * ATTACKER_PER_FACE };
    let detector = pixels * (DETECTOR_PER_PIXEL + adapter * ADAPTER_PER_UNIT_PIXEL);
    let protector = grey * faces * PRIVACY_PER_FACE + if c.protector.omega > 0.0 { detector } else { 0.0 };
    let bytes = BASE + attacker.max(protector).max(detector);
    let seconds = if c.protector.protector_only { 0.0 } else { faces * ATTACKER_SECONDS_PER_FACE }
        + grey * faces * PRIVACY_SECONDS_PER_FACE
        + pixels * DETECTOR_SECONDS_PER_PIXEL;
    let mut fields = vec![
        format!("data.batch {}", c.data.batch),
        format!("detector.batch {}", c.detector.batch),
        format!("detector.size {}", c.detector.size),
    ];
    if c.detector.adapter > 0 {
        fields.push(format!("detector.adapter {}", c.detector.adapter));
    }
    if c.protector.grey > 0.0 {
        fields.push("protector.grey (the faces twice)".into());
    }
    StepCost { bytes, seconds, fields }
}

/// A `campro train-enhancer` step: the U-Net on `data.batch` crops of `data.crop`² (each
/// level's channels at its resolution, the per-pixel stem at full resolution), and the face
/// privacy term's `privacy.faces` through MobileFaceNet when it is on.
pub fn enhancer_step(c: &EnhancerConfig) -> StepCost {
    let pixels = (c.data.batch * c.data.crop * c.data.crop) as f64;
    let channels: f64 = c.model.widths.iter().enumerate().map(|(i, &w)| w as f64 / 4f64.powi(i as i32)).sum::<f64>()
        + c.model.stem as f64;
    let privacy = if c.privacy.weight > 0.0 { c.privacy.faces as f64 } else { 0.0 };
    let bytes = BASE + pixels * channels * UNET_PER_CHANNEL_PIXEL + privacy * PRIVACY_PER_FACE;
    let seconds =
        pixels * crate::unet::macs_per_pixel(&c.model) * UNET_SECONDS_PER_MAC + privacy * PRIVACY_SECONDS_PER_FACE;
    let mut fields = vec![
        format!("data.batch {}", c.data.batch),
        format!("data.crop {}", c.data.crop),
        format!("model.widths {:?}", c.model.widths),
    ];
    if c.model.stem > 0 {
        fields.push(format!("model.stem {}", c.model.stem));
    }
    if privacy > 0.0 {
        fields.push(format!("privacy.faces {}", c.privacy.faces));
    }
    StepCost { bytes, seconds, fields }
}

/// A `campro finetune-detector` step: YOLOX-Nano (and its adapter) on `batch` people at
/// `size`². A distilling teacher's forward is not counted: it keeps no graph, so each of
/// its activations is freed once the next layer has read it.
pub fn detector_step(c: &DetectorConfig) -> StepCost {
    let pixels = (c.batch * c.size * c.size) as f64;
    let bytes = BASE + pixels * (DETECTOR_PER_PIXEL + c.adapter as f64 * ADAPTER_PER_UNIT_PIXEL);
    let mut fields = vec![format!("detector.batch {}", c.batch), format!("detector.size {}", c.size)];
    if c.adapter > 0 {
        fields.push(format!("detector.adapter {}", c.adapter));
    }
    StepCost { bytes, seconds: pixels * DETECTOR_SECONDS_PER_PIXEL, fields }
}

/// Refuses `cost` over `memory_mib` MiB (`budget.memory`) with one line naming the fields
/// and the figures.
pub fn check(cost: &StepCost, memory_mib: u64) -> Result<(), ConfigError> {
    if cost.mib() <= memory_mib {
        return Ok(());
    }
    Err(ConfigError::Budget {
        key: "budget.memory",
        rule: format!(
            "one step needs about {} MiB and {:.1} s on two cores ({}), over budget.memory = {memory_mib} MiB: lower those fields or raise budget.memory",
            cost.mib(),
            cost.seconds,
            cost.fields.join(", ")
        ),
    })
}
