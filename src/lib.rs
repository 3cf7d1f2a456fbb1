//! campro: CamPro (NDSS 2024, "Camera-based Anti-Facial Recognition") for real cameras.
//!
//! CamPro tunes two stages every camera ISP already has, the 3x3 colour correction
//! matrix and the tone (gamma) curve, so that the camera's own output defeats face
//! recognition while person detection still works. This crate holds the parameter
//! model ([`params`]), the paper's desktop pipeline ([`pipeline`]), the mapping to
//! Android Camera2 ([`targets::camera2`]), an emulator of what a device does with the
//! exported values ([`emulate`]) and the comparison of the two ([`compare`]).
//!
//! The default build has no desktop-only dependencies beyond the `cli` feature; with
//! `--no-default-features` it is the Android core.

pub mod camera_loop;
pub mod ccm;
pub mod chart;
pub mod color_temp;
pub mod compare;
pub mod emulate;
pub mod error;
pub mod lut3d;
pub mod params;
pub mod pipeline;
pub mod rational;
pub mod stress;
pub mod targets;
pub mod tone_curve;


#[cfg(feature = "pt")]
pub mod import_pt;

pub use ccm::Mat3;
pub use error::ValidationError;
pub use params::Params;
pub use tone_curve::ToneCurve;

/// Any error of this crate's operations.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Params(#[from] params::ParamsError),
    #[error(transparent)]
    Invalid(#[from] ValidationError),
    #[error(transparent)]
    Convert(#[from] targets::camera2::ConvertError),
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[cfg(feature = "pt")]
    #[error(transparent)]
    Checkpoint(#[from] import_pt::CheckpointError),
}

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Self::Io { path: path.display().to_string(), source }
    }
}
