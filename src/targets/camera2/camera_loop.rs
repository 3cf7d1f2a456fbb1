//! The state a camera app keeps per camera: a parameter set loaded once, the last
//! Camera2 values, and the rule that decides when the scene changed enough to send new
//! ones ("skip what a scene doesn't need").
//!
//! Each frame the app has the device's current colour transform `M_dev` (from an
//! auto-mode `CaptureResult`, or from a colour temperature through the calibration).
//! Values computed for an older `M_old` and sent unchanged still satisfy the Camera2
//! bound, evaluated against the new ideal matrix `CCM · M_dev / s`:
//! `stale = E_curve + L' · max_i Σ_j |R_ij - (CCM · M_dev)_ij / s|` (the range fold is
//! exact for any `s >= 1`, so the old `s` stays valid). [`Camera2Loop::update`] keeps the
//! old values while `stale <= fresh + tolerance`, where `fresh` is the bound the last
//! recompute achieved: skipping never costs more than `tolerance` (output units) over
//! what recomputing would have given for the old scene, and the bound actually achieved
//! is always returned. The check is a 3x3 product, no allocation.

use super::{check_options, convert_with, Camera2Values, ConvertError, CurvePart, Options};
use crate::ccm::{self, Mat3};
use crate::color_temp::{self, DngCalibration};
use crate::emulate::error_bound;
use crate::error::{check_matrix, check_range, ValidationError};
use crate::params::Params;

/// Default skip tolerance: a quarter of an 8-bit LSB.
pub const DEFAULT_TOLERANCE: f64 = 0.25 / 255.0;

/// Where the device transform for a colour temperature comes from.
#[derive(Debug, Clone, PartialEq)]
enum CtSource {
    /// The parameter set's `ct_calibration` (linear in CT, paper appendix).
    Params,
    /// Android's two-illuminant calibration (linear in inverse CT).
    Dng(DngCalibration),
}

/// What one update produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Update<'a> {
    /// The values to send: new ones when `recomputed`, else those sent before.
    pub values: &'a Camera2Values,
    /// Whether the values changed since the last update (the request must be rebuilt).
    pub recomputed: bool,
    /// Guaranteed bound on |device - desktop| for this update's device transform, output
    /// units (1 = full scale), including any staleness.
    pub bound: f64,
}

/// Counters since creation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LoopStats {
    /// Updates asked for.
    pub updates: u64,
    /// Updates that computed new values (the others kept the old ones).
    pub recomputes: u64,
    /// Times the curve half was fitted again (a new range scale or point budget).
    pub curve_fits: u64,
}

/// A parameter set deployed on one Camera2 camera. Not `Sync`-shared by itself: wrap it
/// in a mutex to use it from several threads (the JNI bridge does).
#[derive(Debug, Clone)]
pub struct Camera2Loop {
    params: Params,
    opts: Options,
    tolerance: f64,
    ct_source: CtSource,
    curve: Option<CurvePart>,
    current: Option<(Mat3, Camera2Values)>,
    stats: LoopStats,
}

impl Camera2Loop {
    /// `tolerance`: extra error (output units, in [0, 1]) a skipped update may cost; 0
    /// recomputes on any change of the device transform.
    pub fn new(params: Params, opts: Options, tolerance: f64) -> Result<Self, ValidationError> {
        params.validate()?;
        check_options(&opts)?;
        check_range(|| "skip_tolerance".into(), tolerance, 0.0, 1.0)?;
        Ok(Self {
            params,
            opts,
            tolerance,
            ct_source: CtSource::Params,
            curve: None,
            current: None,
            stats: LoopStats::default(),
        })
    }

    /// The parameter set.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// The conversion options.
    pub fn options(&self) -> &Options {
        &self.opts
    }

    /// What the loop has done so far.
    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// The values last returned, if any.
    pub fn current(&self) -> Option<&Camera2Values> {
        self.current.as_ref().map(|(_, v)| v)
    }

    /// Changes the device's `TONEMAP_MAX_CURVE_POINTS`; the next update recomputes.
    pub fn set_max_curve_points(&mut self, n: usize) -> Result<(), ValidationError> {
        let opts = Options { max_curve_points: n, ..self.opts };
        check_options(&opts)?;
        if opts != self.opts {
            self.opts = opts;
            self.current = None;
        }
        Ok(())
    }

    /// Uses Android's two-illuminant calibration for [`Camera2Loop::update_ct`].
    pub fn set_dng_calibration(&mut self, cal: DngCalibration) -> Result<(), ValidationError> {
        cal.validate()?;
        self.ct_source = CtSource::Dng(cal);
        Ok(())
    }

    /// The device transform at colour temperature `ct` (kelvin) from the DNG
    /// calibration if one was set, else from the parameter set's `ct_calibration`.
    pub fn device_at(&self, ct: f64) -> Result<Mat3, ConvertError> {
        match &self.ct_source {
            CtSource::Dng(cal) => Ok(cal.device_transform(ct)?),
            CtSource::Params => color_temp::interpolate(&self.params.ct_calibration, ct).map_err(|e| match e {
                ValidationError::WrongLength { .. } => ConvertError::NoCalibration,
                e => e.into(),
            }),
        }
    }

    /// Bound the current values would achieve for `device`, if there are any.
    pub fn stale_bound(&self, device: &Mat3) -> Option<f64> {
        let (_, v) = self.current.as_ref()?;
        let ideal = ccm::scale(&ccm::mul(&self.params.ccm, device), 1.0 / v.scale);
        let sent = v.matrix();
        Some(error_bound(v.report.channel_max_abs, v.report.channel_lipschitz, &sent, &ideal, [1.0; 3]))
    }

    /// One frame's update from the device transform (sensor RGB -> linear sRGB).
    pub fn update(&mut self, device: &Mat3) -> Result<Update<'_>, ConvertError> {
        check_matrix("device_ccm", device, ccm::CCM_LIMIT)?;
        self.stats.updates += 1;
        let keep = match (self.stale_bound(device), &self.current) {
            (Some(stale), Some((_, v))) if stale <= v.report.bound + self.tolerance => Some(stale),
            _ => None,
        };
        if let Some(bound) = keep {
            let values = &self.current.as_ref().expect("kept values exist").1;
            return Ok(Update { values, recomputed: false, bound });
        }
        let key = |c: &Option<CurvePart>| c.as_ref().map(|c| (c.scale, c.max_points));
        let before = key(&self.curve);
        let values = convert_with(&self.params, device, &self.opts, &mut self.curve)?;
        if key(&self.curve) != before {
            self.stats.curve_fits += 1;
        }
        self.stats.recomputes += 1;
        let bound = values.report.bound;
        let (_, v) = self.current.insert((*device, values));
        Ok(Update { values: v, recomputed: true, bound })
    }

    /// One frame's update from a colour temperature (kelvin), see [`Camera2Loop::device_at`].
    pub fn update_ct(&mut self, ct: f64) -> Result<Update<'_>, ConvertError> {
        let device = self.device_at(ct)?;
        self.update(&device)
    }

    /// Forgets the current values: the next update recomputes.
    pub fn invalidate(&mut self) {
        self.current = None;
    }
}
