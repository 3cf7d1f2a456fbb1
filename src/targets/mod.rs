//! Deployment targets: how a parameter set becomes the values a camera stack takes.
//!
//! Every target answers the same questions, in [`Format`]: how the CCM is held (range,
//! quantisation step, how it follows the colour temperature), on what grid and with what
//! precision the tone curve is given, and in what order the stages run. A [`Target`]
//! exports a parameter set into the stack's own file and, from that file read back with
//! the same parser, emulates what the ISP then applies ([`Condition`]), so
//! [`crate::compare::deployment_vs_desktop`] can measure the deployment error.
//!
//! Camera2 ([`camera2`]) predates the trait and keeps its own richer API (rationals,
//! per-frame updates); the file-based stacks are [`rpi`], [`rkaiq`] and [`cube`].
//! [`refusal`] explains the stacks that cannot hold a CamPro curve at all.

pub mod camera2;
pub mod cube;
pub mod rkaiq;
pub mod rpi;

use crate::ccm::Mat3;
use crate::emulate::Emulator;
use crate::error::ValidationError;
use crate::params::Params;
use crate::tone_curve::ToneCurve;

/// How a target holds the colour correction matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatrixFormat {
    /// Smallest and largest representable entry (entries clamp to these).
    pub min: f64,
    pub max: f64,
    /// Quantisation step of an entry.
    pub step: f64,
}

impl MatrixFormat {
    /// An entry as the ISP holds it: rounded to the step, then clamped.
    pub fn quantize(&self, v: f64) -> f64 {
        ((v / self.step).round() * self.step).clamp(self.min, self.max)
    }

    /// Every entry of `m` quantised.
    pub fn apply(&self, m: &Mat3) -> Mat3 {
        m.map(|r| r.map(|v| self.quantize(v)))
    }
}

/// How a target holds the tone curve.
#[derive(Debug, Clone, PartialEq)]
pub struct CurveFormat {
    /// Input positions in [0, 1] the hardware interpolates between (fixed grids), or
    /// empty when the exported knots are used as given.
    pub grid: Vec<f64>,
    /// Output quantisation step (in [0, 1] units).
    pub y_step: f64,
    /// Whether the hardware needs a non-decreasing curve.
    pub monotonic: bool,
}

/// What a target does, stage by stage.
#[derive(Debug, Clone, PartialEq)]
pub struct Format {
    /// `None` where the target has no separate matrix (a 3D LUT bakes everything).
    pub matrix: Option<MatrixFormat>,
    pub curve: CurveFormat,
    /// How the matrix follows the scene illuminant.
    pub matrix_by: &'static str,
    /// Stage order and where values clip.
    pub order: &'static str,
}

/// One condition a deployment is checked under (a calibrated colour temperature, an
/// illuminant, or the single device-independent case).
pub struct Condition {
    /// E.g. `ct 4650`, `D65_100`, `33^3 tetrahedral`.
    pub label: String,
    /// What the emulator is fed.
    pub feed: Feed,
    /// What the ISP applies to sensor RGB.
    pub emulator: Box<dyn Emulator + Send + Sync>,
}

/// The input of a deployment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Feed {
    /// Sensor RGB of a device whose own sensor-to-linear-sRGB transform is this matrix
    /// (test pixels are turned into sensor RGB through its inverse).
    Sensor(Mat3),
    /// Gamma-encoded sRGB in [0, 1] (3D LUTs applied after capture).
    Encoded,
}

/// Errors exporting to or reading back a target's file.
#[derive(Debug, thiserror::Error)]
pub enum TargetError {
    #[error("{file}: not valid {format}: {message}")]
    Parse { file: String, format: &'static str, message: String },
    #[error("{file}: {field}: {rule}")]
    Field { file: String, field: String, rule: String },
    #[error("{target} needs its tuning file to patch (pass --base FILE)")]
    NeedsBase { target: &'static str },
    #[error("{target} cannot hold a CamPro tone curve: {why}")]
    Unsupported { target: &'static str, why: String },
    #[error(transparent)]
    Invalid(#[from] ValidationError),
}

/// A camera stack CamPro parameters can be deployed to through a file.
pub trait Target {
    /// Name on the command line (`rpi-vc4`, `rkaiq-isp3x`, `cube`, ...).
    fn name(&self) -> &'static str;
    /// How the stack holds the two stages.
    fn format(&self) -> Format;
    /// The exported file's contents. `base` is the stack's own tuning file where the
    /// export patches one (everything not CamPro's is kept).
    fn export(&self, params: &Params, base: Option<&str>) -> Result<Vec<u8>, TargetError>;
    /// Reads `exported` back with the target's parser and returns what the ISP applies
    /// under each condition it is calibrated for. `base` is the unpatched tuning file
    /// (the device matrices before composition).
    fn emulate(&self, exported: &[u8], base: Option<&str>) -> Result<Vec<Condition>, TargetError>;
}

/// Every target by name, for the CLI.
pub fn by_name(name: &str) -> Option<Box<dyn Target>> {
    Some(match name {
        "rpi-vc4" => Box::new(rpi::Rpi::Vc4),
        "rpi-pisp" => Box::new(rpi::Rpi::Pisp),
        "rkaiq-isp20" => Box::new(rkaiq::Rkaiq::Isp20),
        "rkaiq-isp3x" => Box::new(rkaiq::Rkaiq::Isp3x),
        "cube" => Box::new(cube::CubeFile::default()),
        "hald" => Box::new(cube::CubeFile::hald(8)),
        _ => return None,
    })
}

/// The names [`by_name`] knows.
pub const NAMES: [&str; 6] = ["rpi-vc4", "rpi-pisp", "rkaiq-isp20", "rkaiq-isp3x", "cube", "hald"];

/// Why a stack with only a scalar gamma cannot take CamPro, and what to do instead;
/// `None` for stacks that can.
pub fn refusal(name: &str) -> Option<String> {
    let why = match name {
        "rkisp1" => "libcamera's rkisp1 IPA drives the gamma-out block (GOC) from one scalar gamma (17 fixed knots, 10-bit) and its tuning files carry no curve",
        "simple" | "soft-isp" => "libcamera's simple (software) ISP builds its lookup table from one scalar gamma and a contrast value",
        "v4l2" | "uvc" => "plain V4L2 / UVC webcams expose only a scalar gamma control (V4L2_CID_GAMMA)",
        _ => return None,
    };
    Some(format!(
        "{name}: {why}, so the CamPro tone curve (arbitrary, often non-monotonic) cannot be deployed in the camera. \
         Use the 3D LUT route instead: `campro convert PARAMS --target cube` and apply the .cube right after capture \
         (ffmpeg lut3d, GStreamer, OBS), accepting that the unprotected frame then exists in software for a moment."
    ))
}

/// A curve given as integer points on `[0, full]` (x strictly increasing) as a
/// [`ToneCurve`] on [0, 1]. `field` names the source for errors.
pub(crate) fn curve_from_points(points: &[(f64, f64)], full: f64, field: &str) -> Result<ToneCurve, ValidationError> {
    let x: Vec<f64> = points.iter().map(|p| p.0 / full).collect();
    let y: Vec<f64> = points.iter().map(|p| (p.1 / full).clamp(0.0, 1.0)).collect();
    ToneCurve::new(x, y).map_err(|e| ValidationError::Rule { field: field.into(), rule: e.to_string() })
}

/// The ISP's curve after it resamples `given` on a fixed `grid` (values rounded to
/// `y_step`): linear interpolation between the grid points.
pub(crate) fn resample_on_grid(given: &ToneCurve, grid: &[f64], y_step: f64) -> ToneCurve {
    let y = grid.iter().map(|&x| ((given.eval(x) / y_step).round() * y_step).clamp(0.0, 1.0)).collect();
    ToneCurve::new(grid.to_vec(), y).expect("grid is strictly increasing and values are clamped")
}
