//! campro-train: CamPro's adversarial optimiser (the paper's Sec. IV-C, Algorithm 1) on
//! candle, kept out of the Android core.
//!
//! - [`camera`]: the differentiable camera (degamma, CCM, tone curve), the same maths as
//!   campro's desktop pipeline;
//! - [`mobilefacenet`]: the white-box attacker backbone, loaded from its PyTorch checkpoint
//!   ([`torch_legacy`]);

pub mod bench;
pub mod camera;
pub mod checkpoint;
pub mod config;
pub mod detection;
pub mod enhancer;
pub mod error;
pub mod face_privacy;
pub mod faces;
pub mod finetune;
pub mod log;
pub mod persons;
pub mod retrain;
pub mod scenes;
pub mod ssim;
pub mod train;
pub mod unet;
pub mod validation;

pub use candle_core::{Device, Tensor};
pub use error::{Result, TrainError};
pub use log::LogRow;
