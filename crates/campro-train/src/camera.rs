//! The differentiable camera C of CamPro (paper Sec. IV-B), the same maths as campro's desktop
//! pipeline: `degamma(x) = clamp(x^γ, 0, 1)`, `y = clamp(CCM · rgb, 0, 1)`, then the tone
//! curve (k evenly spaced knots, linear interpolation), one for the three channels (the
//! paper's camera) or one per output channel (Camera2's `TONEMAP_CURVE` takes three). The
//! CCM (9 values, kept in [−5, 5]) and the curve outputs (k or 3k values, kept in [0, 1])
//! are trainable [`Var`]s.

use candle_core::{DType, Device, Result, Tensor, Var};

/// Bound on the CCM entries the optimiser keeps (paper: clamped to [−5, 5]).
pub const CCM_LIMIT: f64 = 5.0;

pub struct Camera {
    /// (3, 3), row-major, `out = ccm · in` on linear RGB.
    pub ccm: Var,
    /// (k,) for a shared curve or (3, k) for one per channel (red, green, blue): the curve
    /// outputs at `i / (k − 1)`.
    pub curve: Var,
    /// Degamma exponent (2.2).
    pub gamma: f64,
}

impl Camera {
    /// The paper's initialisation: identity CCM, identity curve with `k` knots (on each
    /// channel when `per_channel`).
    pub fn identity(k: usize, per_channel: bool, gamma: f64, device: &Device) -> Result<Self> {
        let line: Vec<f64> = (0..k).map(|i| i as f64 / (k - 1) as f64).collect();
        let curves = if per_channel { vec![line.clone(), line.clone(), line] } else { vec![line] };
        Self::from_values(campro::ccm::IDENTITY, &curves, gamma, device)
    }

    /// From explicit values (`ccm` row-major; `curves` one row of knot outputs for a shared
    /// curve, or three of equal length, red first).
    pub fn from_values(ccm: [[f64; 3]; 3], curves: &[Vec<f64>], gamma: f64, device: &Device) -> Result<Self> {
        let k = curves.first().map_or(0, Vec::len);
        if !(curves.len() == 1 || curves.len() == 3) || k < 2 || curves.iter().any(|c| c.len() != k) {
            candle_core::bail!("the camera takes 1 or 3 curves of the same length (at least 2 knots)");
        }
        let c: Vec<f32> = ccm.iter().flatten().map(|&v| v as f32).collect();
        let v: Vec<f32> = curves.iter().flatten().map(|&v| v as f32).collect();
        let curve = Tensor::from_vec(v, k * curves.len(), device)?;
        let curve = if curves.len() == 3 { curve.reshape((3, k))? } else { curve };
        Ok(Self {
            ccm: Var::from_tensor(&Tensor::from_vec(c, (3, 3), device)?)?,
            curve: Var::from_tensor(&curve)?,
            gamma,
        })
    }

    /// Knots of each curve.
    pub fn knots(&self) -> usize {
        *self.curve.dims().last().expect("curve has a dimension")
    }

    /// Whether each channel has its own curve.
    pub fn per_channel(&self) -> bool {
        self.curve.rank() == 2
    }

    /// `clamp(x^γ, 0, 1)` of sRGB values in [0, 1] (no parameters: apply once and cache).
    pub fn degamma(&self, srgb: &Tensor) -> Result<Tensor> {
        srgb.clamp(0f32, 1f32)?.powf(self.gamma)?.clamp(0f32, 1f32)
    }

    /// The camera on linear-light images (B, 3, H, W): CCM, clip, tone curve. Differentiable
    /// in the CCM, the curve and the input.
    pub fn forward_linear(&self, lin: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = lin.dims4()?;
        let x = lin.reshape((b, c, h * w))?;
        let y = self.ccm.as_tensor().broadcast_matmul(&x)?.clamp(0f32, 1f32)?;
        let k = self.knots();
        let t = y.affine((k - 1) as f64, 0.0)?;
        // Knot index i = min(floor(t), k − 2): t = 1 falls in the last segment with frac 1.
        let i = t.floor()?.clamp(0f32, (k - 2) as f32)?.detach();
        let frac = (&t - &i)?;
        // A curve per channel: channel c's knots start at c · k in the flattened (3k) table.
        let i = if self.per_channel() {
            let start = Tensor::from_vec(vec![0f32, k as f32, 2.0 * k as f32], (1, 3, 1), lin.device())?;
            i.broadcast_add(&start)?
        } else {
            i
        };
        let idx = i.to_dtype(DType::U32)?.flatten_all()?;
        let curve = self.curve.as_tensor().flatten_all()?;
        let lo = curve.index_select(&idx, 0)?.reshape(t.shape())?;
        let hi = curve.index_select(&(&idx + 1.0)?, 0)?.reshape(t.shape())?;
        let out = (&lo + (hi - &lo)?.mul(&frac)?)?;
        out.reshape((b, c, h, w))
    }

    /// The whole camera on sRGB images in [0, 1].
    pub fn forward(&self, srgb: &Tensor) -> Result<Tensor> {
        self.forward_linear(&self.degamma(srgb)?)
    }

    /// Projects the parameters back into their ranges after an optimiser step.
    pub fn project(&self) -> Result<()> {
        self.ccm.set(&self.ccm.as_tensor().clamp(-CCM_LIMIT as f32, CCM_LIMIT as f32)?)?;
        self.curve.set(&self.curve.as_tensor().clamp(0f32, 1f32)?)
    }

    /// The CCM as f64 rows.
    pub fn ccm_values(&self) -> Result<[[f64; 3]; 3]> {
        let v: Vec<Vec<f32>> = self.ccm.as_tensor().to_vec2()?;
        Ok(std::array::from_fn(|i| std::array::from_fn(|j| v[i][j] as f64)))
    }

    /// The curve outputs as f64: one row, or three (red, green, blue).
    pub fn curve_values(&self) -> Result<Vec<Vec<f64>>> {
        let rows = self.curve.as_tensor().reshape(((), self.knots()))?.to_vec2::<f32>()?;
        Ok(rows.into_iter().map(|r| r.into_iter().map(f64::from).collect()).collect())
    }

    /// The trainable variables (for an optimiser).
    pub fn vars(&self) -> Vec<Var> {
        vec![self.ccm.clone(), self.curve.clone()]
    }
}
