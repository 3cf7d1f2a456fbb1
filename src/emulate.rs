//! What a device does with exported values: the emulators.
//!
//! A device sees linear sensor RGB. The Camera2 emulator applies the received rational
//! matrix (optionally rounded to `n` fractional bits, as a fixed-point HAL would),
//! clips to [0, 1], and applies the received curve by linear interpolation (optionally
//! first resampled to an evenly spaced LUT of the device's size).

use crate::ccm::{self, Mat3};
use crate::pipeline::clip01;
use crate::targets::camera2::{self, Camera2Values};
use crate::tone_curve::ToneCurve;

/// Something that turns linear sensor RGB into output RGB in [0, 1].
pub trait Emulator {
    /// One pixel of sensor RGB (any real values) to output RGB in [0, 1].
    fn sensor_to_output(&self, sensor: [f64; 3]) -> [f64; 3];
}

/// How the emulated HAL / ISP treats the received values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DeviceModel {
    /// Round each matrix entry to this many fractional bits (e.g. 10 for Q.10); `None`
    /// keeps the rationals exact.
    pub matrix_frac_bits: Option<u32>,
    /// Resample the curve to an evenly spaced LUT of this many entries (e.g. 64, 256,
    /// 1024); `None` interpolates the received points directly.
    pub lut_size: Option<usize>,
}

/// A Camera2 device as emulated from the values of a `CaptureRequest`.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera2Device {
    /// The matrix the device applies.
    pub matrix: Mat3,
    /// The curve the device applies.
    pub curve: ToneCurve,
}

impl Camera2Device {
    /// The device that received `values` and treats them as `model` says.
    pub fn new(values: &Camera2Values, model: &DeviceModel) -> Self {
        let mut matrix = values.matrix();
        if let Some(bits) = model.matrix_frac_bits {
            let q = (2.0f64).powi(bits.min(52) as i32);
            matrix = matrix.map(|r| r.map(|v| (v * q).round() / q));
        }
        let mut curve = values.curve();
        if let Some(n) = model.lut_size {
            curve = curve.resample_uniform(n.max(2));
        }
        Self { matrix, curve }
    }

    /// Guaranteed bound on |device - ideal| where the ideal applies `ideal_matrix`, clip
    /// and `ideal_curve`, for sensor inputs with |sensor_j| <= `range[j]`:
    /// `|curve - ideal_curve|_inf + L(curve) · max_i Σ_j |ΔM_ij| · range_j`.
    pub fn error_bound(&self, ideal_matrix: &Mat3, ideal_curve: &ToneCurve, range: [f64; 3]) -> f64 {
        camera2::error_bound(self.curve.max_abs_diff(ideal_curve), self.curve.max_slope(), &self.matrix, ideal_matrix, range)
    }
}

impl Emulator for Camera2Device {
    #[inline]
    fn sensor_to_output(&self, sensor: [f64; 3]) -> [f64; 3] {
        clip01(ccm::apply(&self.matrix, sensor)).map(|c| self.curve.eval(c))
    }
}

/// A generic ISP: a matrix on sensor RGB, a clip to [0, 1], a curve. What every
/// file-based target (Raspberry Pi, Rockchip) applies once its values are read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Isp {
    pub matrix: Mat3,
    pub curve: ToneCurve,
}

impl Emulator for Isp {
    #[inline]
    fn sensor_to_output(&self, sensor: [f64; 3]) -> [f64; 3] {
        clip01(ccm::apply(&self.matrix, sensor)).map(|c| self.curve.eval(c))
    }
}
