//! campro-eval: what CamPro is for, measured with real models.
//!
//! - **privacy**: closed-set face identification and LFW verification against real face
//!   recognition models (YuNet detection + 5-point alignment + embedding);
//! - **utility**: person detection (YOLOX) on COCO, COCO AP;
//! - **quality**: RMSE, PSNR, SSIM, MS-SSIM between raw and protected images.
//!
//! Models are ONNX files run on the CPU by tract, each described by a JSON manifest
//! ([`manifest`]). This crate knows nothing of CamPro parameters: a protection is any
//! function from an 8-bit RGB image to another ([`Condition`]), so the CamPro pipeline, the
//! paper's baselines and a user's own filter are evaluated the same way.

pub mod ap;
pub mod baselines;
pub mod check;
pub mod colour;
pub mod data;
pub mod enhance;
pub mod error;
pub mod face;
pub mod frontier;
pub mod geometry;
pub mod guard;
pub mod heif;
pub mod hvcc;
pub mod image_file;
pub mod linear;
pub mod manifest;
pub mod model;
pub mod person;
pub mod place;
pub mod plans;
pub mod plot;
pub mod privacy;
pub mod quality;
pub mod report;
pub mod restore;
pub mod scene;
pub mod table;
pub mod utility;

pub use error::{EvalError, Result};

use image::RgbImage;
use std::borrow::Cow;
use std::sync::Arc;

/// Maps `f` over `items` in parallel (rayon) behind a progress bar named `label`; the first
/// error stops the map.
pub fn par_map_progress<I: Sync, T: Send>(
    items: &[I],
    label: &str,
    f: impl Fn(&I) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    use rayon::prelude::*;
    let pb = indicatif::ProgressBar::new(items.len() as u64);
    let style = format!("{label} [{{bar:30}}] {{pos}}/{{len}} {{elapsed_precise}} eta {{eta}}");
    pb.set_style(indicatif::ProgressStyle::with_template(&style).expect("valid template").progress_chars("=> "));
    let out = items
        .par_iter()
        .map(|i| {
            let r = f(i);
            pb.inc(1);
            r
        })
        .collect::<Result<Vec<T>>>();
    pb.finish_and_clear();
    out
}

/// A protection applied to whole 8-bit RGB images (same size out).
pub type ProtectFn = dyn Fn(&RgbImage) -> RgbImage + Send + Sync;

/// One image type of an evaluation: raw (no protection) or a named protection.
#[derive(Clone)]
pub struct Condition {
    pub name: String,
    pub protect: Option<Arc<ProtectFn>>,
}

impl Condition {
    pub fn raw() -> Self {
        Self { name: "raw".into(), protect: None }
    }

    pub fn new(name: impl Into<String>, f: impl Fn(&RgbImage) -> RgbImage + Send + Sync + 'static) -> Self {
        Self { name: name.into(), protect: Some(Arc::new(f)) }
    }

    /// A paper baseline as a condition.
    pub fn baseline(b: baselines::Baseline) -> Self {
        Self::new(b.to_string(), move |img| b.apply(img))
    }

    /// The image under this condition.
    pub fn apply<'a>(&self, img: &'a RgbImage) -> Cow<'a, RgbImage> {
        match &self.protect {
            None => Cow::Borrowed(img),
            Some(f) => Cow::Owned(f(img)),
        }
    }
}
