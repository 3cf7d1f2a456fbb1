//! The desktop (reference) pipeline of the paper, on sRGB input in [0, 1]:
//!
//! 1. degamma: `clamp(x^γ, 0, 1)` per channel (γ = 2.2),
//! 2. CCM: `clamp(CCM · rgb, 0, 1)`,
//! 3. tone curve: piecewise-linear interpolation of the knots.
//!
//! [`process_f64`] is the reference. [`process_f32_campro`] repeats CamPro's float32
//! PyTorch arithmetic (its `Gamma.forward` indexing included) to reproduce its outputs.
//! [`Prepared`] is the image path: the degamma becomes an exact table over every input
//! code, the rest runs in f64, so its only error against the reference is the final
//! rounding to the output code (at most 0.5 LSB of the output depth).

use crate::ccm;
use crate::params::Params;

pub mod fast;

/// `clamp(x^γ, 0, 1)`; NaN maps to 0.
#[inline]
pub fn degamma(x: f64, gamma: f64) -> f64 {
    let v = x.max(0.0).powf(gamma);
    if v.is_nan() {
        0.0
    } else {
        v.min(1.0)
    }
}

/// `clamp(v, 0, 1)` per channel (NaN to 0).
#[inline]
pub fn clip01(v: [f64; 3]) -> [f64; 3] {
    v.map(|c| if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) })
}

/// The stages after degamma: `curve_c(clamp(CCM · lin)_c)` per output channel c, on linear RGB.
#[inline]
pub fn from_linear(p: &Params, lin: [f64; 3]) -> [f64; 3] {
    let t = clip01(ccm::apply(&p.ccm, lin));
    [0, 1, 2].map(|c| p.tone_curves.channel(c).eval(t[c]))
}

/// The reference pipeline on one sRGB pixel in [0, 1], in f64.
#[inline]
pub fn process_f64(p: &Params, rgb: [f64; 3]) -> [f64; 3] {
    from_linear(p, rgb.map(|c| degamma(c, p.degamma)))
}

/// CamPro's float32 arithmetic on one 8-bit pixel: `x / 255` -> `clamp(x^2.2)` ->
/// `clamp(torch.mm(ccm, x))` -> `Gamma.forward` (which clamps the index input to
/// [1e-6, 1 - 1e-6] but interpolates with the unclamped value). Only for uniform knots.
///
/// It matches PyTorch bit for bit except where PyTorch's vectorised `pow` is one ulp
/// off the correctly rounded `powf` used here (about 2% of 8-bit codes); see
/// [`campro_f32_after_degamma`] and the fixture tests.
pub fn process_f32_campro(ccm32: &[[f32; 3]; 3], keypoints: &[f32], gamma: f32, rgb8: [u8; 3]) -> [f32; 3] {
    let d = rgb8.map(|c| (c as f32 / 255.0).powf(gamma).clamp(0.0, 1.0));
    campro_f32_after_degamma(ccm32, keypoints, d)
}

/// CamPro's float32 CCM (`torch.mm`, products summed left to right) and `Gamma.forward`
/// on already degamma'd values.
pub fn campro_f32_after_degamma(ccm32: &[[f32; 3]; 3], keypoints: &[f32], d: [f32; 3]) -> [f32; 3] {
    let n_space = (keypoints.len() - 1) as f32;
    let mut out = [0.0f32; 3];
    for (i, o) in out.iter_mut().enumerate() {
        let r = ccm32[i];
        let lin = (r[0] * d[0] + r[1] * d[1] + r[2] * d[2]).clamp(0.0, 1.0);
        let eps = 1e-6f32;
        let xc = lin.clamp(eps, 1.0 - eps);
        let idx = (xc * n_space).floor() as usize;
        let alpha = lin * n_space - idx as f32;
        *o = keypoints[idx] * (1.0 - alpha) + keypoints[idx + 1] * alpha;
    }
    out
}

/// Bit depth of integer image samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Depth {
    /// 0..=255
    Eight,
    /// 0..=65535
    Sixteen,
}

impl Depth {
    /// Largest code value.
    pub fn max(self) -> u32 {
        match self {
            Depth::Eight => 255,
            Depth::Sixteen => 65535,
        }
    }
}

/// The pipeline prepared for integer input of one depth: an exact degamma table.
#[derive(Debug, Clone)]
pub struct Prepared<'a> {
    params: &'a Params,
    degamma: Vec<f64>,
}

impl<'a> Prepared<'a> {
    /// Tabulates the degamma over every code of `input` depth (256 or 65536 entries).
    pub fn new(params: &'a Params, input: Depth) -> Self {
        let max = input.max();
        let degamma = (0..=max).map(|c| degamma(c as f64 / max as f64, params.degamma)).collect();
        Self { params, degamma }
    }

    /// The parameters this was prepared for.
    pub fn params(&self) -> &'a Params {
        self.params
    }

    /// One pixel given as integer codes, output in [0, 1] (f64, no rounding).
    #[inline]
    pub fn pixel(&self, rgb: [u16; 3]) -> [f64; 3] {
        from_linear(self.params, rgb.map(|c| self.degamma[c as usize]))
    }

    /// Interleaved RGB codes in, interleaved RGB codes of `out` depth out (rounded to
    /// nearest). `src.len()` must equal `dst.len()` and be a multiple of 3; codes above
    /// the input depth's maximum are clamped to it.
    pub fn run(&self, src: &[u16], dst: &mut [u16], out: Depth) {
        assert_eq!(src.len(), dst.len(), "source and destination sample counts differ");
        let top = (self.degamma.len() - 1) as u16;
        let scale = out.max() as f64;
        for (s, d) in src.chunks_exact(3).zip(dst.chunks_exact_mut(3)) {
            let v = self.pixel([s[0].min(top), s[1].min(top), s[2].min(top)]);
            for k in 0..3 {
                d[k] = (v[k] * scale + 0.5) as u16;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tone_curve::ToneCurve;

    #[test]
    fn hand_computed_pixel() {
        // CCM swaps R and B and halves G; curve y = 1 - x (two knots).
        let ccm = [[0.0, 0.0, 1.0], [0.0, 0.5, 0.0], [1.0, 0.0, 0.0]];
        let p = Params::new(ccm, ToneCurve::uniform(vec![1.0, 0.0]).unwrap(), 2.0).unwrap();
        let out = process_f64(&p, [0.5, 1.0, 0.0]);
        // degamma (γ=2): [0.25, 1, 0]; CCM: [0, 0.5, 0.25]; curve: [1, 0.5, 0.75].
        assert_eq!(out, [1.0, 0.5, 0.75]);
    }

    #[test]
    fn ccm_output_is_clipped_before_the_curve() {
        let ccm = [[2.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]];
        let p = Params::new(ccm, ToneCurve::identity(2), 1.0).unwrap();
        assert_eq!(process_f64(&p, [0.8, 0.8, 0.3]), [1.0, 0.0, 0.3]);
    }

    #[test]
    fn prepared_matches_reference_within_half_lsb() {
        let p = Params::new(
            [[1.2, -0.3, 0.1], [0.2, 0.9, -0.1], [-0.4, 0.3, 1.1]],
            ToneCurve::from_fn(32, |t| (6.0 * t).sin().abs()),
            2.2,
        )
        .unwrap();
        let prep = Prepared::new(&p, Depth::Eight);
        let mut src = Vec::new();
        for r in (0..256).step_by(5) {
            for g in (0..256).step_by(7) {
                for b in (0..256).step_by(3) {
                    src.extend([r as u16, g as u16, b as u16]);
                }
            }
        }
        let mut dst = vec![0; src.len()];
        prep.run(&src, &mut dst, Depth::Sixteen);
        for (s, d) in src.chunks(3).zip(dst.chunks(3)) {
            let want = process_f64(&p, [s[0] as f64 / 255.0, s[1] as f64 / 255.0, s[2] as f64 / 255.0]);
            for k in 0..3 {
                assert!((d[k] as f64 - want[k] * 65535.0).abs() <= 0.5 + 1e-9);
            }
        }
    }
}
