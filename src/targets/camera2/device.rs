//! Camera2 as a [`Target`]: the request values as JSON, read back and applied by an
//! emulated device, so Camera2 is compared with the desktop pipeline on the same path as
//! every other stack ([`crate::compare::deployment_vs_desktop`]).

use super::{convert, values_from_json, Camera2Values, Options, MATRIX_RANGE};
use crate::ccm::{self, Mat3};
use crate::emulate::{DeviceModel, Isp};
use crate::params::Params;
use crate::targets::target::{
    Condition, CurveFormat, Feed, Format, MatrixBy, MatrixFormat, StageOrder, Target, TargetError,
};

/// The ISP a Camera2 device runs with the request's matrix and curves, as `model` says
/// its HAL treats them: matrix entries rounded to `matrix_frac_bits` fractional bits,
/// each channel's curve resampled to a `lut_size`-entry LUT.
pub fn device(matrix: Mat3, curves: crate::ToneCurves, model: &DeviceModel) -> Isp {
    let mut matrix = matrix;
    if let Some(bits) = model.matrix_frac_bits {
        let q = (2.0f64).powi(bits.min(52) as i32);
        matrix = matrix.map(|r| r.map(|v| (v * q).round() / q));
    }
    let curves = match model.lut_size {
        Some(n) => curves.map(|c| c.resample_uniform(n.max(2))),
        None => curves,
    };
    Isp { matrix, curves }
}

/// A Camera2 device: its own colour transform (sensor RGB to linear sRGB), the
/// conversion options and how its HAL treats the values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera2 {
    /// The device's transform `M_dev` (identity when it reports none).
    pub device: Mat3,
    /// Point budget and rational mode.
    pub options: Options,
    /// The emulated HAL's rounding.
    pub model: DeviceModel,
}

impl Default for Camera2 {
    /// A device reporting the identity transform, default options, an exact HAL.
    fn default() -> Self {
        Self { device: ccm::IDENTITY, options: Options::default(), model: DeviceModel::default() }
    }
}

impl Camera2 {
    /// A device whose own transform is `device`, converted with `options`.
    pub fn new(device: Mat3, options: Options, model: DeviceModel) -> Self {
        Self { device, options, model }
    }

    /// The request values for `params`.
    pub fn values(&self, params: &Params) -> Result<Camera2Values, TargetError> {
        Ok(convert(params, &self.device, &self.options)?)
    }
}

impl Target for Camera2 {
    fn name(&self) -> &'static str {
        "camera2"
    }

    fn format(&self) -> Format {
        Format {
            matrix: Some(MatrixFormat {
                min: MATRIX_RANGE.0,
                max: MATRIX_RANGE.1,
                step: 2.0 * super::rational_error_bound(self.options.rational),
            }),
            curve: CurveFormat { grid: Vec::new(), y_step: f32::EPSILON as f64 / 2.0, monotonic: false },
            matrix_by: MatrixBy::PerFrame,
            order: StageOrder::MatrixClipCurve { clip_bits: None },
        }
    }

    fn export(&self, params: &Params, _base: Option<&str>) -> Result<Vec<u8>, TargetError> {
        let v = self.values(params)?;
        Ok((serde_json::to_string(&v.to_json()).expect("values serialise") + "\n").into_bytes())
    }

    fn emulate(&self, params: &Params, exported: &[u8], _base: Option<&str>) -> Result<Vec<Condition>, TargetError> {
        let (matrix, curves, scale) = values_from_json(exported)?;
        let isp = device(matrix, curves, &self.model);
        // The ideal the device should reach: CCM · M_dev / s, then the folded curve, for
        // the sensor RGB that sRGB test pixels in [0, 1]^3 synthesise through M_dev^-1.
        let bound = ccm::inverse(&self.device).map(|inv| {
            let range = inv.map(|row| row.iter().map(|v| v.abs()).sum::<f64>());
            let ideal = ccm::scale(&ccm::mul(&params.ccm, &self.device), 1.0 / scale);
            isp.error_bound(&ideal, &params.tone_curves.map(|c| c.fold_scale(scale)), range)
        });
        Ok(vec![Condition { label: "camera2".into(), feed: Feed::Sensor(self.device), emulator: Box::new(isp), bound }])
    }
}
