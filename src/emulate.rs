//! What a device does with exported values: the emulators.
//!
//! A device sees linear sensor RGB. Every ISP stage CamPro uses is a matrix, a clip to
//! [0, 1] and a curve applied by linear interpolation ([`Isp`]); each target builds one
//! from the values it read back (Camera2 in [`crate::targets::camera2::device`], with the
//! HAL's rounding from a [`DeviceModel`]). 3D LUTs bring their own [`Emulator`].

use crate::ccm::{self, Mat3};
use crate::pipeline::clip01;
use crate::tone_curve::ToneCurves;

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

/// A generic ISP: a matrix on sensor RGB, a clip to [0, 1], a curve. What every
/// camera target (Camera2, Raspberry Pi, Rockchip) applies once its values are read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Isp {
    /// The matrix the ISP applies to sensor RGB.
    pub matrix: Mat3,
    /// The curves it applies after clipping to [0, 1], output channel by channel.
    pub curves: ToneCurves,
}

impl Isp {
    /// Guaranteed bound on |this - ideal| where the ideal applies `ideal_matrix`, clip
    /// and `ideal_curves`, for sensor inputs with |sensor_j| <= `range[j]`: the largest over
    /// output channels i of `|curve_i - ideal_curve_i|_inf + L(curve_i) · Σ_j |ΔM_ij| ·
    /// range_j` (clipping is 1-Lipschitz, so a row error of δ moves channel i's curve input
    /// by at most δ).
    pub fn error_bound(&self, ideal_matrix: &Mat3, ideal_curves: &ToneCurves, range: [f64; 3]) -> f64 {
        let c = |i: usize| (self.curves.channel(i), ideal_curves.channel(i));
        let e = [0, 1, 2].map(|i| c(i).0.max_abs_diff(c(i).1));
        error_bound(e, [0, 1, 2].map(|i| c(i).0.max_slope()), &self.matrix, ideal_matrix, range)
    }
}

/// The bound every matrix-clip-curve deployment states: the largest over output channels
/// i of `E_i + L_i · Σ_j |sent_ij - ideal_ij| · range_j` for sensor inputs with
/// |sensor_j| <= `range[j]`, where `E_i` (`curve_max_abs[i]`) is the largest difference
/// between channel i's applied curve and its ideal one and `L_i` (`lipschitz[i]`) the
/// applied curve's largest slope. The ISP clips to [0, 1] before the curve (clipping is
/// 1-Lipschitz), so a row error of δ moves the curve's input by at most δ and its output
/// by at most `L_i · δ`. A shared curve passes the same value three times.
pub fn error_bound(curve_max_abs: [f64; 3], lipschitz: [f64; 3], sent: &Mat3, ideal: &Mat3, range: [f64; 3]) -> f64 {
    (0..3)
        .map(|i| {
            let row: f64 = (0..3).map(|j| (sent[i][j] - ideal[i][j]).abs() * range[j]).sum();
            curve_max_abs[i] + lipschitz[i] * row
        })
        .fold(0.0, f64::max)
}

impl Emulator for Isp {
    #[inline]
    fn sensor_to_output(&self, sensor: [f64; 3]) -> [f64; 3] {
        let t = clip01(ccm::apply(&self.matrix, sensor));
        [0, 1, 2].map(|c| self.curves.channel(c).eval(t[c]))
    }
}
