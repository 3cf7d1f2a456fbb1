//! The whole pipeline baked into a 3D LUT over gamma-encoded RGB (what `.cube` files,
//! ffmpeg's `lut3d`, OBS and GStreamer apply), with trilinear and tetrahedral
//! interpolation.
//!
//! Error: inside a cell the interpolant is a convex combination of node values, and each
//! node is within `h` (the grid step) of the input in every coordinate, so
//! `|lut - reference| <= K · h` with `K = γ · L · max_c Σ_j |CCM_cj|` (degamma's slope on
//! [0, 1] is at most γ for γ >= 1, the curve's is `L`, clipping is 1-Lipschitz), plus the
//! f32 storage rounding. The bound is loose; [`Lut3d::error_bound`] states it and tests
//! measure the real error over every 8-bit code triple.

use crate::params::Params;
use crate::pipeline::process_f64;

/// Interpolation inside a LUT cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interp {
    /// Between the 8 corners of the cell (what most video tools do).
    Trilinear,
    /// Between the 4 corners of the tetrahedron holding the point (ffmpeg `lut3d` default).
    Tetrahedral,
}

/// An `n`^3 LUT of output RGB, red index fastest (the `.cube` order).
#[derive(Debug, Clone, PartialEq)]
pub struct Lut3d {
    n: usize,
    data: Vec<[f32; 3]>,
    bound: f64,
}

impl Lut3d {
    /// Samples the reference pipeline on an `n`^3 grid (2 <= n <= 256).
    pub fn bake(params: &Params, n: usize) -> Self {
        assert!((2..=256).contains(&n), "LUT size must be in 2..=256, got {n}");
        let step = 1.0 / (n - 1) as f64;
        let mut data = Vec::with_capacity(n * n * n);
        for b in 0..n {
            for g in 0..n {
                for r in 0..n {
                    let v = process_f64(params, [r as f64 * step, g as f64 * step, b as f64 * step]);
                    data.push(v.map(|x| x as f32));
                }
            }
        }
        let s = crate::ccm::norm_inf(&params.ccm);
        let bound = params.degamma.max(1.0) * params.tone_curves.max_slope() * s * step + 1e-7;
        Self { n, data, bound }
    }

    /// A LUT from node values read from a file (red fastest), with no a-priori bound
    /// (`error_bound` is infinite): its error is what a comparison measures.
    pub fn from_data(n: usize, data: Vec<[f32; 3]>) -> Result<Self, crate::error::ValidationError> {
        use crate::error::ValidationError;
        if !(2..=256).contains(&n) {
            return Err(ValidationError::OutOfRange {
                field: "LUT_3D_SIZE".into(),
                value: n as f64,
                min: 2.0,
                max: 256.0,
            });
        }
        if data.len() != n * n * n {
            return Err(ValidationError::WrongLength {
                field: "LUT entries".into(),
                expected: format!("{n}^3 = {}", n * n * n),
                got: data.len(),
            });
        }
        if let Some(v) = data.iter().flatten().find(|v| !v.is_finite()) {
            return Err(ValidationError::NonFinite { field: "LUT entry".into(), value: *v as f64 });
        }
        Ok(Self { n, data, bound: f64::INFINITY })
    }

    /// Points per axis.
    pub fn size(&self) -> usize {
        self.n
    }

    /// Node values, red fastest.
    pub fn data(&self) -> &[[f32; 3]] {
        &self.data
    }

    /// A priori bound on |LUT - reference| for any input in [0, 1]^3, output units.
    pub fn error_bound(&self) -> f64 {
        self.bound
    }

    #[inline(always)]
    fn at(&self, r: usize, g: usize, b: usize) -> [f32; 3] {
        self.data[(b * self.n + g) * self.n + r]
    }

    /// The LUT at gamma-encoded `rgb` in [0, 1]^3 (clamped).
    #[inline]
    pub fn eval(&self, rgb: [f32; 3], interp: Interp) -> [f32; 3] {
        let top = (self.n - 1) as f32;
        let mut i = [0usize; 3];
        let mut f = [0f32; 3];
        for k in 0..3 {
            let x = rgb[k].clamp(0.0, 1.0) * top;
            let j = (x as usize).min(self.n - 2);
            i[k] = j;
            f[k] = x - j as f32;
        }
        let c = |dr: usize, dg: usize, db: usize| self.at(i[0] + dr, i[1] + dg, i[2] + db);
        let mut out = [0f32; 3];
        match interp {
            Interp::Trilinear => {
                let (c000, c100, c010, c110) = (c(0, 0, 0), c(1, 0, 0), c(0, 1, 0), c(1, 1, 0));
                let (c001, c101, c011, c111) = (c(0, 0, 1), c(1, 0, 1), c(0, 1, 1), c(1, 1, 1));
                for k in 0..3 {
                    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
                    let x00 = lerp(c000[k], c100[k], f[0]);
                    let x10 = lerp(c010[k], c110[k], f[0]);
                    let x01 = lerp(c001[k], c101[k], f[0]);
                    let x11 = lerp(c011[k], c111[k], f[0]);
                    out[k] = lerp(lerp(x00, x10, f[1]), lerp(x01, x11, f[1]), f[2]);
                }
            }
            Interp::Tetrahedral => {
                let (fr, fg, fb) = (f[0], f[1], f[2]);
                let c000 = c(0, 0, 0);
                let c111 = c(1, 1, 1);
                // The tetrahedron holding the point, by the order of the fractions.
                let (w, a, b) = if fr > fg {
                    if fg > fb {
                        ([1.0 - fr, fr - fg, fg - fb, fb], c(1, 0, 0), c(1, 1, 0))
                    } else if fr > fb {
                        ([1.0 - fr, fr - fb, fb - fg, fg], c(1, 0, 0), c(1, 0, 1))
                    } else {
                        ([1.0 - fb, fb - fr, fr - fg, fg], c(0, 0, 1), c(1, 0, 1))
                    }
                } else if fb > fg {
                    ([1.0 - fb, fb - fg, fg - fr, fr], c(0, 0, 1), c(0, 1, 1))
                } else if fb > fr {
                    ([1.0 - fg, fg - fb, fb - fr, fr], c(0, 1, 0), c(0, 1, 1))
                } else {
                    ([1.0 - fg, fg - fr, fr - fb, fb], c(0, 1, 0), c(1, 1, 0))
                };
                for k in 0..3 {
                    out[k] = w[0] * c000[k] + w[1] * a[k] + w[2] * b[k] + w[3] * c111[k];
                }
            }
        }
        out
    }

    /// Interleaved RGB8 in and out.
    #[inline]
    pub fn run(&self, src: &[u8], dst: &mut [u8], interp: Interp) {
        assert_eq!(src.len(), dst.len(), "source and destination sample counts differ");
        for (s, d) in src.chunks_exact(3).zip(dst.chunks_exact_mut(3)) {
            let v = self.eval([s[0] as f32 / 255.0, s[1] as f32 / 255.0, s[2] as f32 / 255.0], interp);
            for k in 0..3 {
                d[k] = (v[k] * 255.0 + 0.5) as u8;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tone_curve::ToneCurve;

    #[test]
    fn nodes_are_exact_and_both_interpolations_agree_on_them() {
        let p = Params::new(
            [[0.9, 0.2, -0.1], [0.1, 0.8, 0.1], [-0.2, 0.1, 1.1]],
            ToneCurve::from_fn(32, |t| 1.0 - t),
            2.2,
        )
        .unwrap();
        let lut = Lut3d::bake(&p, 5);
        for (r, g, b) in [(0, 0, 0), (1, 2, 3), (4, 4, 4), (4, 0, 2)] {
            let x = [r as f32 / 4.0, g as f32 / 4.0, b as f32 / 4.0];
            let want = process_f64(&p, x.map(f64::from));
            for interp in [Interp::Trilinear, Interp::Tetrahedral] {
                let got = lut.eval(x, interp);
                for k in 0..3 {
                    assert!((got[k] as f64 - want[k]).abs() < 1e-6, "{interp:?} {x:?}");
                }
            }
        }
    }

    #[test]
    fn affine_functions_are_reproduced_inside_cells() {
        // Identity CCM, degamma 1, identity curve: the pipeline is the identity on
        // [0, 1]^3, which both interpolations reproduce exactly.
        let p = Params::new(crate::ccm::IDENTITY, ToneCurve::identity(2), 1.0).unwrap();
        let lut = Lut3d::bake(&p, 3);
        for x in [[0.1f32, 0.7, 0.3], [0.9, 0.2, 0.55], [0.5, 0.5, 0.5]] {
            for interp in [Interp::Trilinear, Interp::Tetrahedral] {
                let got = lut.eval(x, interp);
                for k in 0..3 {
                    assert!((got[k] - x[k]).abs() < 1e-6, "{interp:?} {x:?} -> {got:?}");
                }
            }
        }
    }
}
