//! CamPro's image enhancer at inference (paper Sec. IV-D): the ONNX U-Net written by
//! `campro train-enhancer`, run by tract on whole 8-bit images of any size.
//!
//! The file is self-describing: input [`INPUT`] and output [`OUTPUT`], both (1, 3, H, W) RGB
//! in [0, 1]; H and W must be multiples of the metadata entry [`MULTIPLE_KEY`], so an image
//! is padded on the right and bottom by repeating its last column and row, and the result
//! is cropped back. The output is rounded to 8 bits (clamped to 0..=255).

use crate::error::{EvalError, Result};
use image::RgbImage;
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::{bail, format_err};

/// Name of the enhancer's input (captured RGB in [0, 1]).
pub const INPUT: &str = "captured";
/// Name of the enhancer's output (enhanced RGB, about [0, 1]).
pub const OUTPUT: &str = "enhanced";
/// ONNX metadata key: height and width must be multiples of its value (a power of two).
pub const MULTIPLE_KEY: &str = "campro.multiple";
/// Largest enhancer file read (bytes): the recommended ones are at most 2 MB.
pub const MAX_FILE: u64 = 64 << 20;

/// A loaded enhancer; `enhance` takes `&self`, so one can serve several threads.
pub struct Enhancer {
    plan: std::sync::Arc<TypedSimplePlan>,
    multiple: usize,
    path: PathBuf,
}

impl Enhancer {
    /// Reads and optimises the ONNX file at `path` (at most [`MAX_FILE`] bytes).
    pub fn load(path: &Path) -> Result<Self> {
        let bad = |m: String| EvalError::Model { path: path.to_path_buf(), message: m };
        let bytes = campro::file::read_capped(path, MAX_FILE, "an enhancer (ONNX)")?;
        let built = std::panic::catch_unwind(|| -> TractResult<(usize, std::sync::Arc<TypedSimplePlan>)> {
            let onnx = tract_onnx::onnx();
            let proto = onnx.proto_model_for_read(&mut bytes.as_slice())?;
            let multiple = proto
                .metadata_props
                .iter()
                .find(|p| p.key == MULTIPLE_KEY)
                .and_then(|p| p.value.parse::<usize>().ok())
                .filter(|m| m.is_power_of_two() && *m <= 64)
                .ok_or_else(|| format_err!("no {MULTIPLE_KEY} entry (a power of two up to 64): not a campro enhancer"))?;
            let graph = proto.graph.as_ref().ok_or_else(|| format_err!("no graph"))?;
            let names = (graph.input.first().map(|i| i.name.as_str()), graph.output.first().map(|o| o.name.as_str()));
            if names != (Some(INPUT), Some(OUTPUT)) {
                bail!("input {:?} and output {:?}, expected {INPUT:?} and {OUTPUT:?}", names.0, names.1);
            }
            let mut model = onnx.model_for_proto_model(&proto)?;
            let (h, w) = (model.symbols.sym("H"), model.symbols.sym("W"));
            model.set_input_fact(0, f32::fact([1.to_dim(), 3.to_dim(), h.into(), w.into()]).into())?;
            Ok((multiple, model.into_optimized()?.into_runnable()?))
        });
        match built {
            Ok(Ok((multiple, plan))) => Ok(Self { plan, multiple, path: path.to_path_buf() }),
            Ok(Err(e)) => Err(bad(format!("{e:#}"))),
            Err(_) => Err(bad("tract could not build it (malformed graph)".into())),
        }
    }

    /// Height and width multiple the network needs (images are padded to it).
    pub fn multiple(&self) -> usize {
        self.multiple
    }

    /// The enhanced image of a captured 8-bit image (same size).
    pub fn enhance(&self, img: &RgbImage) -> Result<RgbImage> {
        let (w, h) = (img.width() as usize, img.height() as usize);
        let m = self.multiple;
        let (pw, ph) = (w.div_ceil(m) * m, h.div_ceil(m) * m);
        let mut data = vec![0f32; 3 * pw * ph];
        for y in 0..ph {
            for x in 0..pw {
                let p = img.get_pixel(x.min(w - 1) as u32, y.min(h - 1) as u32).0;
                for c in 0..3 {
                    data[c * pw * ph + y * pw + x] = p[c] as f32 / 255.0;
                }
            }
        }
        let input = Tensor::from_shape(&[1, 3, ph, pw], &data).expect("shape matches data");
        let out = self
            .plan
            .run(tvec!(input.into()))
            .map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e:#}") })?;
        let v = out[0]
            .try_as_plain_ram()
            .and_then(|t| t.as_slice::<f32>())
            .map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e}") })?;
        if v.len() != 3 * pw * ph {
            return Err(EvalError::Model {
                path: self.path.clone(),
                message: format!("output has {} values, expected {}", v.len(), 3 * pw * ph),
            });
        }
        let q = |f: f32| (f * 255.0).round().clamp(0.0, 255.0) as u8;
        Ok(RgbImage::from_fn(w as u32, h as u32, |x, y| {
            let i = y as usize * pw + x as usize;
            image::Rgb([q(v[i]), q(v[pw * ph + i]), q(v[2 * pw * ph + i])])
        }))
    }
}
