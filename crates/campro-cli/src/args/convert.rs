//! Arguments of `convert` and `compare`: the camera stack, the device's own transform and
//! white balance, the conversion options and the file targets' options (shared by both).

use super::{Report, PARAMS_HELP};
use campro::targets::camera2;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// `campro convert`.
#[derive(Args)]
pub struct ConvertArgs {
    #[arg(help = PARAMS_HELP)]
    pub params: PathBuf,
    /// The camera stack: camera2 (JSON or Kotlin values), or a file for another stack
    /// (rpi-*, rkaiq-*, cube, hald; campro convert --help lists them).
    #[arg(long, default_value = "camera2", value_parser = target_names())]
    pub target: String,
    #[command(flatten)]
    pub device: DeviceArgs,
    #[command(flatten)]
    pub files: FileTargetArgs,
    /// Camera2 values as JSON, or as Kotlin statements for a CaptureRequest.Builder.
    #[arg(long, value_enum, default_value_t = Format::Json)]
    pub format: Format,
    /// Write to this file instead of standard output.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub force: bool,
}

/// `campro compare`.
#[derive(Args)]
pub struct CompareArgs {
    #[arg(help = PARAMS_HELP)]
    pub params: PathBuf,
    /// The camera stack to emulate (camera2, rpi-*, rkaiq-*, cube, hald).
    #[arg(long, default_value = "camera2", value_parser = target_names())]
    pub target: String,
    #[command(flatten)]
    pub files: FileTargetArgs,
    #[command(flatten)]
    pub device: DeviceArgs,
    /// Emulate a HAL that rounds matrix entries to this many fractional bits (0 to 52).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=52))]
    pub matrix_frac_bits: Option<u32>,
    /// Emulate a device LUT of this many evenly spaced entries (2 to 65536).
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..=65536))]
    pub lut_size: Option<u32>,
    /// Random pixels to test (1 to 10,000,000).
    #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    pub random: u32,
    /// Seed of the random pixels.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A text report, or one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}

/// The device's own colour transform and white balance, and the Camera2 conversion options.
#[derive(Args, Clone)]
pub struct DeviceArgs {
    /// The device's colour transform, nine numbers row-major (A11 A12 A13 A21 ... A33).
    #[arg(long, num_args = 9, allow_negative_numbers = true, value_name = "A", conflicts_with = "capture_result")]
    pub device_ccm: Option<Vec<f64>>,
    /// A saved capture result (JSON with colorCorrectionTransform) giving the device transform.
    #[arg(long)]
    pub capture_result: Option<PathBuf>,
    /// The device's white-balance gains metered with its transform (R G_EVEN G_ODD B, each in
    /// (0, 64]): printed into the Kotlin statements and the JSON (a capture result's
    /// colorCorrectionGains give them too).
    #[arg(long, num_args = 4, value_name = "G", conflicts_with = "capture_result", value_parser = parse_gain)]
    pub device_gains: Option<Vec<f32>>,
    /// Colour temperature (K, 1000 to 40000) at which to interpolate the parameter file's ct_calibration.
    #[arg(long, allow_negative_numbers = true, conflicts_with_all = ["device_ccm", "capture_result"], value_parser = parse_ct)]
    pub ct: Option<f64>,
    /// The device's TONEMAP_MAX_CURVE_POINTS (2 to 65536).
    #[arg(long, default_value_t = camera2::DEFAULT_MAX_CURVE_POINTS as u32, value_parser = clap::value_parser!(u32).range(2..=65536))]
    pub max_curve_points: u32,
    /// Rationals: best approximation with denominators up to this.
    #[arg(long, default_value_t = camera2::DEFAULT_MAX_DENOMINATOR, conflicts_with = "fixed_denominator")]
    pub max_denominator: u32,
    /// Rationals: every entry over this fixed denominator (e.g. 1024) instead.
    #[arg(long)]
    pub fixed_denominator: Option<u32>,
}

/// Options of the file-based targets.
#[derive(Args, Clone)]
pub struct FileTargetArgs {
    /// The stack's own tuning / IQ file to patch (Raspberry Pi, Rockchip).
    #[arg(long)]
    pub base: Option<PathBuf>,
    /// Points per axis of a .cube LUT.
    #[arg(long, default_value_t = 33)]
    pub cube_size: usize,
    /// Hald CLUT level L (an L^3 x L^3 image, L^2 points per axis).
    #[arg(long, default_value_t = 8)]
    pub hald_level: usize,
    /// Clamp values the stack cannot hold (saying which) instead of refusing them.
    #[arg(long)]
    pub clamp: bool,
}

/// `convert --format`.
#[derive(Clone, Copy, ValueEnum)]
pub enum Format {
    Json,
    Kotlin,
}

/// `--device-gains`: a white-balance gain in (0, 64].
fn parse_gain(s: &str) -> Result<f32, String> {
    camera2::gain(s.parse().ok())
        .ok_or_else(|| format!("must be a gain in (0, {}], got {}", camera2::MAX_GAIN, super::shown_arg(s)))
}

/// `--ct`: a finite colour temperature in the calibration range.
fn parse_ct(s: &str) -> Result<f64, String> {
    let (lo, hi) = campro::color_temp::CT_RANGE;
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        _ => Err(format!("must be a colour temperature in [{lo}, {hi}] K, got {}", super::shown_arg(s))),
    }
}

/// The registered stack names, for `--target` (`campro convert --help` lists them).
fn target_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        campro::targets::REGISTRY.iter().map(|e| clap::builder::PossibleValue::new(e.name).help(e.about)),
    )
}
