//! The [`Target`] trait and what every target describes: how it holds the matrix and
//! the curve ([`Format`]), and the conditions it is checked under ([`Condition`]).

use crate::ccm::Mat3;
use crate::emulate::Emulator;
use crate::error::ValidationError;
use crate::params::Params;
use crate::tone_curve::ToneCurve;

/// How a target holds the colour correction matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatrixFormat {
    /// Smallest representable entry (entries clamp to it).
    pub min: f64,
    /// Largest representable entry.
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

/// How a target's matrix follows the scene illuminant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum MatrixBy {
    /// The app sends a new matrix with each capture request (Camera2: `CCM · M_dev`
    /// for the device transform the last result reported).
    PerFrame,
    /// One matrix per calibrated colour temperature, interpolated linearly in CT
    /// (libcamera on Raspberry Pi).
    CtInterpolated,
    /// One matrix per illuminant and saturation, blended by the AWB gains (rkaiq).
    IlluminantBlend,
    /// Baked into one 3D LUT for the scene it was made for.
    Baked,
}

/// The order of the stages and where values clip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum StageOrder {
    /// White-balanced sensor RGB, the matrix, a clip to [0, 1] at `clip_bits` of
    /// precision (`None`: floating point), then the curve.
    MatrixClipCurve {
        /// Bits the clipped value is held in before the curve.
        clip_bits: Option<u32>,
    },
    /// Gamma-encoded RGB through one 3D LUT (degamma, matrix, clip and curve baked in).
    EncodedLut,
}

/// What a target does, stage by stage.
#[derive(Debug, Clone, PartialEq)]
pub struct Format {
    /// `None` where the target has no separate matrix (a 3D LUT bakes everything).
    pub matrix: Option<MatrixFormat>,
    /// How the curve is held.
    pub curve: CurveFormat,
    /// How the matrix follows the scene illuminant.
    pub matrix_by: MatrixBy,
    /// Stage order and where values clip.
    pub order: StageOrder,
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
    /// The target's a priori bound on |deployment - desktop| for every 8-bit sRGB input
    /// under this condition (output units), where it states one.
    pub bound: Option<f64>,
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
#[non_exhaustive]
pub enum TargetError {
    /// The file is not of its format.
    #[error("{file}: not valid {format}: {message}")]
    Parse {
        /// Which file (`base`, `exported`).
        file: String,
        /// The format expected.
        format: &'static str,
        /// What the parser said.
        message: String,
    },
    /// A field of the file breaks the stack's rule.
    #[error("{file}: {field}: {rule}")]
    Field {
        /// Which file.
        file: String,
        /// The field's path in it.
        field: String,
        /// The rule broken.
        rule: String,
    },
    /// The target patches a tuning file and none was given.
    #[error("{target} needs its tuning file to patch (pass --base FILE)")]
    NeedsBase {
        /// The target's name.
        target: &'static str,
    },
    /// The stack cannot hold what CamPro needs.
    #[error("{target} cannot hold a CamPro tone curve: {why}")]
    Unsupported {
        /// The target's name.
        target: &'static str,
        /// Why.
        why: String,
    },
    /// A value breaks a rule.
    #[error(transparent)]
    Invalid(#[from] ValidationError),
    /// The Camera2 conversion failed.
    #[error(transparent)]
    Convert(#[from] crate::targets::camera2::ConvertError),
}

/// A camera stack CamPro parameters can be deployed to.
pub trait Target {
    /// Name on the command line (`rpi-vc4`, `rkaiq-isp3x`, `cube`, ...).
    fn name(&self) -> &'static str;
    /// How the stack holds the two stages.
    fn format(&self) -> Format;
    /// The exported file's contents. `base` is the stack's own tuning file where the
    /// export patches one (everything not CamPro's is kept).
    fn export(&self, params: &Params, base: Option<&str>) -> Result<Vec<u8>, TargetError>;
    /// [`Target::export`], clamping values the stack cannot hold instead of refusing
    /// them; returns the file and one line per value clamped. Targets that never clamp
    /// export as usual.
    fn export_clamped(&self, params: &Params, base: Option<&str>) -> Result<(Vec<u8>, Vec<String>), TargetError> {
        self.export(params, base).map(|bytes| (bytes, Vec::new()))
    }
    /// Reads `exported` back with the target's parser and returns what the ISP applies
    /// under each condition it is calibrated for. `params` is what was exported (for the
    /// stated bounds), `base` the unpatched tuning file (the device matrices before
    /// composition).
    fn emulate(&self, params: &Params, exported: &[u8], base: Option<&str>) -> Result<Vec<Condition>, TargetError>;
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

/// The one tone curve of `params` for a stack whose ISP has a single gamma curve for the
/// three channels; a set with a curve per channel is refused (Camera2 and 3D LUTs hold
/// it).
pub fn shared_curve<'a>(target: &'static str, params: &'a Params) -> Result<&'a ToneCurve, TargetError> {
    params.tone_curves.shared().ok_or_else(|| TargetError::Unsupported {
        target,
        why: "its ISP has one gamma curve for the three channels and this set has a curve per channel (the camera2 and cube targets hold it)".into(),
    })
}
