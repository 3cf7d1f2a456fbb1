//! The differentiable camera C of CamPro (paper Sec. IV-B), the same maths as campro's desktop
//! pipeline: `degamma(x) = clamp(x^γ, 0, 1)`, `y = clamp(CCM · rgb, 0, 1)`, then the tone
//! curve (k evenly spaced knots, linear interpolation). The CCM (9 values, kept in [−5, 5])
//! and the curve outputs (k values, kept in [0, 1]) are trainable [`Var`]s.

use candle_core::{DType, Device, Result, Tensor, Var};

/// Bound on the CCM entries the optimiser keeps (paper: clamped to [−5, 5]).
pub const CCM_LIMIT: f64 = 5.0;

pub struct Camera {
    /// (3, 3), row-major, `out = ccm · in` on linear RGB.
    pub ccm: Var,
    /// (k,), the curve outputs at `i / (k − 1)`.
    pub curve: Var,
    /// Degamma exponent (2.2).
    pub gamma: f64,
}

impl Camera {
    /// The paper's initialisation: identity CCM, identity curve with `k` knots.
    pub fn identity(k: usize, gamma: f64, device: &Device) -> Result<Self> {
        let ccm = Var::from_tensor(&Tensor::eye(3, DType::F32, device)?)?;
        let curve = Var::from_tensor(
            &Tensor::arange(0u32, k as u32, device)?.to_dtype(DType::F32)?.affine(1.0 / (k - 1) as f64, 0.0)?,
        )?;
        Ok(Self { ccm, curve, gamma })
    }

    /// From explicit values (`ccm` row-major, `curve` knot outputs).
    pub fn from_values(ccm: [[f64; 3]; 3], curve: &[f64], gamma: f64, device: &Device) -> Result<Self> {
        let c: Vec<f32> = ccm.iter().flatten().map(|&v| v as f32).collect();
        let k: Vec<f32> = curve.iter().map(|&v| v as f32).collect();
        Ok(Self {
            ccm: Var::from_tensor(&Tensor::from_vec(c, (3, 3), device)?)?,
            curve: Var::from_tensor(&Tensor::from_vec(k, curve.len(), device)?)?,
            gamma,
        })
    }

    pub fn knots(&self) -> usize {
        self.curve.dim(0).expect("curve is 1-d")
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
        let idx = i.to_dtype(DType::U32)?.flatten_all()?;
        let curve = self.curve.as_tensor();
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

    /// The curve outputs as f64.
    pub fn curve_values(&self) -> Result<Vec<f64>> {
        Ok(self.curve.as_tensor().to_vec1::<f32>()?.into_iter().map(f64::from).collect())
    }

    /// The trainable variables (for an optimiser).
    pub fn vars(&self) -> Vec<Var> {
        vec![self.ccm.clone(), self.curve.clone()]
    }
}
