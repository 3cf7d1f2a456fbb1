//! campro: CamPro (NDSS 2024, "Camera-based Anti-Facial Recognition") for real cameras.
//!
//! CamPro tunes two stages every camera ISP already has, the 3x3 colour correction
//! matrix and the tone (gamma) curve, so that the camera's own output defeats face
//! recognition while person detection still works. Because the protection happens
//! inside the camera, an app or a compromised OS never sees an unprotected face.
//!
//! This crate is the core (the library an Android app links through `jni-bridge`):
//! - [`Params`]: a parameter set and its JSON format (see [`params`] for the rules);
//! - [`pipeline`]: the paper's desktop pipeline and its exact fast paths;
//! - [`targets`]: one module per camera stack behind one [`targets::Target`] trait and
//!   one [`targets::REGISTRY`]: Android Camera2 ([`targets::camera2`]: rationals, tone
//!   curve points, read-back, the per-frame loop), Raspberry Pi, Rockchip, 3D LUTs;
//! - [`emulate`] and [`compare`]: what a device does with the exported values, measured
//!   against the desktop pipeline with a stated bound.
//!
//! The default build has no desktop-only dependency. The `pt` feature adds
//! [`import_pt`] (CamPro's PyTorch checkpoints, read by the bounded [`pickle`] reader
//! without executing anything). The `stress` feature adds [`stress`] (adversarial cases
//! and the invariants every path keeps) and [`bench`] (the benchmarks' inputs), which the
//! `campro stress` and `campro bench` commands and the property tests run.
//! Errors: each module returns its own error kind; all of them convert into [`Error`].
#![warn(missing_docs)]

pub mod ccm;
pub mod chart;
pub mod chroma;
pub mod color_temp;
pub mod compare;
pub mod emulate;
pub mod error;
pub mod file;
pub mod lut3d;
pub mod params;
pub mod pipeline;
pub mod provenance;
pub mod rational;
pub mod record;
pub mod targets;
pub mod tone_curve;

#[cfg(feature = "stress")]
pub mod bench;
#[cfg(feature = "pt")]
pub mod import_pt;
#[cfg(feature = "pt")]
pub mod pickle;
#[cfg(feature = "stress")]
pub mod stress;

pub use ccm::Mat3;
pub use error::ValidationError;
pub use params::Params;
pub use tone_curve::{ToneCurve, ToneCurves};

/// Any error of this crate's operations: one variant per kind, each naming the field or
/// file and the rule broken.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or parsing a parameter set.
    #[error(transparent)]
    Params(#[from] params::ParamsError),
    /// A value broke a rule.
    #[error(transparent)]
    Invalid(#[from] ValidationError),
    /// A Camera2 conversion failed.
    #[error(transparent)]
    Convert(#[from] targets::camera2::ConvertError),
    /// Exporting to or reading back a target's file failed.
    #[error(transparent)]
    Target(#[from] targets::TargetError),
    /// An input file could not be read.
    #[error(transparent)]
    File(#[from] file::FileError),
    /// A CamPro checkpoint could not be read.
    #[cfg(feature = "pt")]
    #[error(transparent)]
    Checkpoint(#[from] import_pt::CheckpointError),
}

/// `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
