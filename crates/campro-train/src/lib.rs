//! campro-train: campro's training loops on candle, kept out of the Android core; the ops
//! and networks they train are `campro-nn`'s, and a [`campro_nn::Context`] in each run's
//! options says where they compute.
//!
//! - [`train`]: CamPro's adversarial optimiser (the paper's Sec. IV-C, Algorithm 1);
//! - [`finetune`]: the person detector behind a camera; [`enhancer`] and [`unet`]: the image
//!   enhancer (Sec. IV-D); [`retrain`]: the model re-training attack (Sec. VII);
//! - [`camera`]: the differentiable camera (degamma, CCM, tone curve), the same maths as
//!   campro's desktop pipeline; the losses ([`detection`], [`face_privacy`], [`ssim`]), the
//!   data ([`faces`], [`persons`], [`scenes`]), [`checkpoint`]s, [`log`]s and [`validation`].

pub mod bench;
pub mod camera;
pub mod checkpoint;
pub mod config;
pub mod cost;
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
