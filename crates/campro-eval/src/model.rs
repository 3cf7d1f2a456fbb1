//! Running an ONNX model with tract, fed as its manifest says.

use crate::error::{EvalError, Result};
use crate::manifest::{Channels, Manifest};
use image::RgbImage;
use tract_onnx::prelude::*;

/// A loaded, optimised model plus its manifest. Cheap to share across threads (`run` takes
/// `&self`).
pub struct Model {
    pub manifest: Manifest,
    plan: std::sync::Arc<TypedSimplePlan>,
    outputs: Vec<String>,
}

impl Model {
    /// Loads and optimises the model for its manifest's input size (batch 1).
    pub fn load(manifest: Manifest) -> Result<Self> {
        let path = manifest.file.clone();
        let err = |e: TractError| EvalError::Model { path: path.clone(), message: format!("{e:#}") };
        if !path.is_file() {
            return Err(EvalError::Model { path: path.clone(), message: "file not found".into() });
        }
        let shape = [1, 3, manifest.input.height, manifest.input.width];
        // tract can panic on a model whose fixed reshapes disagree with the input size:
        // keep that from escaping as a panic.
        let built = std::panic::catch_unwind(|| -> TractResult<(std::sync::Arc<TypedSimplePlan>, Vec<String>)> {
            let model = tract_onnx::onnx().model_for_path(&manifest.file)?;
            let outputs = model
                .output_outlets()?
                .iter()
                .map(|o| model.outlet_label(*o).map(str::to_string).unwrap_or_else(|| model.node(o.node).name.clone()))
                .collect();
            let plan = model.with_input_fact(0, f32::fact(shape).into())?.into_optimized()?.into_runnable()?;
            Ok((plan, outputs))
        });
        let (plan, outputs) = match built {
            Ok(r) => r.map_err(err)?,
            Err(_) => {
                return Err(EvalError::Model {
                    path,
                    message: format!("cannot be run at input 1x3x{}x{} (tract refused the shapes)", shape[2], shape[3]),
                })
            }
        };
        Ok(Self { manifest, plan, outputs })
    }

    /// The input tensor for an image of exactly the manifest's size.
    pub fn tensor(&self, img: &RgbImage) -> Tensor {
        let i = &self.manifest.input;
        assert_eq!(
            (img.width() as usize, img.height() as usize),
            (i.width, i.height),
            "image not resized for the model"
        );
        let order = match i.channels {
            Channels::Rgb => [0, 1, 2],
            Channels::Bgr => [2, 1, 0],
        };
        let (w, h) = (i.width, i.height);
        let mut data = vec![0f32; 3 * w * h];
        for (c, &src) in order.iter().enumerate() {
            let (m, s) = (i.mean[c], i.std[c]);
            let plane = &mut data[c * w * h..(c + 1) * w * h];
            for (d, p) in plane.iter_mut().zip(img.pixels()) {
                *d = (p.0[src] as f32 - m) / s;
            }
        }
        Tensor::from_shape(&[1, 3, h, w], &data).expect("shape matches data")
    }

    /// Runs the model on a ready image; outputs by name.
    pub fn run(&self, img: &RgbImage) -> Result<Outputs> {
        let out = self
            .plan
            .run(tvec!(self.tensor(img).into()))
            .map_err(|e| EvalError::Model { path: self.manifest.file.clone(), message: format!("{e:#}") })?;
        release_freed_memory();
        Ok(Outputs {
            names: self.outputs.clone(),
            values: out.into_iter().map(|t| t.into_tensor()).collect(),
            path: self.manifest.file.clone(),
        })
    }
}

/// Hands the memory freed by a model run back to the system. tract allocates every
/// intermediate tensor anew (sizes from kilobytes to megabytes, on several threads), and
/// glibc's malloc keeps what it frees: `eval privacy` over 1,239 identities grew to 9.9 GB
/// resident for 52 MB of live heap. `malloc_trim` returns the free pages; another
/// allocator would too, but made candle's training steps 35–80% slower here.
/// Trimming after every run cost 40% of `eval privacy`'s time; every 64th run costs little
/// and bounds what accumulates.
fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static RUNS: AtomicUsize = AtomicUsize::new(0);
        if RUNS.fetch_add(1, Ordering::Relaxed) % 64 == 63 {
            // SAFETY: malloc_trim only releases free memory of the process's own allocator.
            unsafe {
                libc::malloc_trim(0);
            }
        }
    }
}

/// Named output tensors of one run.
pub struct Outputs {
    names: Vec<String>,
    values: Vec<Tensor>,
    path: std::path::PathBuf,
}

impl Outputs {
    /// The output `name` as a flat f32 slice, checked to hold `len` values.
    pub fn get(&self, name: &str, len: usize) -> Result<&[f32]> {
        let i = self.names.iter().position(|n| n == name).ok_or_else(|| EvalError::Model {
            path: self.path.clone(),
            message: format!("no output named {name:?} (outputs: {:?})", self.names),
        })?;
        let s = self.values[i]
            .try_as_plain_ram()
            .and_then(|v| v.as_slice::<f32>())
            .map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e}") })?;
        if s.len() != len {
            return Err(EvalError::Model {
                path: self.path.clone(),
                message: format!("output {name:?} has {} values, expected {len}", s.len()),
            });
        }
        Ok(s)
    }

    /// The output `name` whatever its length.
    pub fn any(&self, name: &str) -> Result<&[f32]> {
        let i = self.names.iter().position(|n| n == name).ok_or_else(|| EvalError::Model {
            path: self.path.clone(),
            message: format!("no output named {name:?} (outputs: {:?})", self.names),
        })?;
        self.values[i]
            .try_as_plain_ram()
            .and_then(|v| v.as_slice::<f32>())
            .map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e}") })
    }
}
