//! Running an ONNX model with tract, fed as its manifest says.

use crate::error::{EvalError, Result};
use crate::manifest::{Channels, Manifest};
use crate::plans::Plans;
use image::RgbImage;
use std::path::Path;
use std::sync::Arc;
use tract_onnx::prelude::*;

/// Largest model file read (bytes): the bundled manifests' models are at most 5 MB.
pub const MAX_FILE: u64 = 64 << 20;

/// A loaded, optimised model plus its manifest. Cheap to share across threads (`run` takes
/// `&self`).
pub struct Model {
    pub manifest: Manifest,
    plan: Arc<TypedSimplePlan>,
    outputs: Vec<String>,
    /// The graph without its recorded intermediate shapes, planned for the manifest's size
    /// and again for other input sizes by [`Model::run_sized`] (fully convolutional models).
    source: InferenceModel,
    /// Plans by input (height, width) other than the manifest's.
    sized: Plans<(usize, usize)>,
}

impl Model {
    /// Loads (at most [`MAX_FILE`] bytes, a regular file) and optimises the model for its
    /// manifest's input size (batch 1).
    pub fn load(manifest: Manifest) -> Result<Self> {
        let path = manifest.file.clone();
        if !path.is_file() {
            return Err(EvalError::Model { path: path.clone(), message: "file not found".into() });
        }
        let bytes = campro::file::read_capped(&path, MAX_FILE, "a model (ONNX)")
            .map_err(|e| EvalError::Model { path: path.clone(), message: e.reason() })?;
        Self::from_bytes(manifest, &bytes)
    }

    /// [`Model::load`] of a model already in memory (one built into the binary);
    /// `manifest.file` only names it in errors.
    pub fn from_bytes(manifest: Manifest, bytes: &[u8]) -> Result<Self> {
        let path = manifest.file.clone();
        let err = |e: TractError| EvalError::Model { path: path.clone(), message: format!("{e:#}") };
        let onnx = tract_onnx::onnx();
        let mut proto = onnx.proto_model_for_read(&mut &bytes[..]).map_err(err)?;
        // The recorded shapes of intermediate values and outputs hold one input size; without
        // them tract infers every shape from the input given, so one graph serves every size.
        if let Some(g) = proto.graph.as_mut() {
            g.value_info.clear();
            for o in &mut g.output {
                o.r#type = None;
            }
        }
        let (source, outputs) = guarded(&path, || {
            let model = onnx.model_for_proto_model(&proto)?;
            let outputs = model
                .output_outlets()?
                .iter()
                .map(|o| model.outlet_label(*o).map(str::to_string).unwrap_or_else(|| model.node(o.node).name.clone()))
                .collect::<Vec<_>>();
            Ok((model, outputs))
        })?;
        let plan = plan_at(&path, source.clone(), manifest.input.height, manifest.input.width)?;
        Ok(Self { manifest, plan, outputs, source, sized: Plans::default() })
    }

    /// The input tensor for an image of exactly the manifest's size.
    pub fn tensor(&self, img: &RgbImage) -> Tensor {
        let i = &self.manifest.input;
        assert_eq!(
            (img.width() as usize, img.height() as usize),
            (i.width, i.height),
            "image not resized for the model"
        );
        self.region_tensor(img, [0, 0, img.width(), img.height()], (i.width, i.height))
    }

    /// The input tensor of a `cw` x `ch` canvas holding the `[x, y, w, h]` region of `img` at
    /// its top-left (clipped to the canvas), black (0 before normalisation) elsewhere.
    pub fn region_tensor(&self, img: &RgbImage, [x, y, w, h]: [u32; 4], (cw, ch): (usize, usize)) -> Tensor {
        let i = &self.manifest.input;
        let order = match i.channels {
            Channels::Rgb => [0, 1, 2],
            Channels::Bgr => [2, 1, 0],
        };
        let w = (w.min(img.width().saturating_sub(x)) as usize).min(cw);
        let h = (h.min(img.height().saturating_sub(y)) as usize).min(ch);
        let (stride, raw) = (img.width() as usize * 3, img.as_raw());
        let mut data = vec![0f32; 3 * cw * ch];
        for (c, &src) in order.iter().enumerate() {
            let (m, s) = (i.mean[c], i.std[c]);
            let plane = &mut data[c * cw * ch..(c + 1) * cw * ch];
            plane.fill((0.0 - m) / s);
            for row in 0..h {
                let from = &raw[(y as usize + row) * stride + x as usize * 3..][..w * 3];
                for (d, p) in plane[row * cw..row * cw + w].iter_mut().zip(from.chunks_exact(3)) {
                    *d = (p[src] as f32 - m) / s;
                }
            }
        }
        Tensor::from_shape(&[1, 3, ch, cw], &data).expect("shape matches data")
    }

    /// Runs the model on a ready image; outputs by name.
    pub fn run(&self, img: &RgbImage) -> Result<Outputs> {
        self.run_sized(self.tensor(img))
    }

    /// Runs the model on a `1 x 3 x h x w` input of any size its graph accepts (a fully
    /// convolutional detector: sides multiples of its largest stride), planned once a size
    /// and kept ([`crate::plans::KEPT`]); the manifest's size uses the plan made at loading.
    pub fn run_sized(&self, input: Tensor) -> Result<Outputs> {
        let path = &self.manifest.file;
        let shape = input.shape().to_vec();
        let [1, 3, h, w] = shape[..] else {
            return Err(EvalError::Model {
                path: path.clone(),
                message: format!("input of shape {shape:?}, not 1x3xHxW"),
            });
        };
        let plan = if (h, w) == (self.manifest.input.height, self.manifest.input.width) {
            self.plan.clone()
        } else {
            self.sized.get_or_make((h, w), || plan_at(path, self.source.clone(), h, w))?
        };
        let out = guarded(path, || plan.run(tvec!(input.into())))?;
        release_freed_memory();
        Ok(Outputs {
            names: self.outputs.clone(),
            values: out.into_iter().map(|t| t.into_tensor()).collect(),
            path: path.clone(),
        })
    }
}

/// `model` typed and optimised for a `1 x 3 x h x w` input.
fn plan_at(path: &Path, model: InferenceModel, h: usize, w: usize) -> Result<Arc<TypedSimplePlan>> {
    guarded(path, || model.with_input_fact(0, f32::fact([1, 3, h, w]).into())?.into_optimized()?.into_runnable())
        .map_err(|e| match e {
            EvalError::Model { path, message } => {
                EvalError::Model { path, message: format!("cannot be run at input 1x3x{h}x{w}: {message}") }
            }
            e => e,
        })
}

/// Runs `f`, a tract call, with its error and any panic as a model error: tract can panic
/// on a graph whose shapes disagree with the input given, and that must not escape.
fn guarded<T>(path: &Path, f: impl FnOnce() -> TractResult<T>) -> Result<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(|e| EvalError::Model { path: path.to_path_buf(), message: format!("{e:#}") }),
        Err(_) => Err(EvalError::Model {
            path: path.to_path_buf(),
            message: "tract failed on it (the shapes disagree)".into(),
        }),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plans::KEPT;
    use tract_onnx::pb;

    /// A one-`Relu` graph whose recorded shapes (input, an intermediate value, output) all
    /// say 1 x 3 x 4 x 4, as a file exported at one size records them.
    fn relu_onnx() -> Vec<u8> {
        use prost::Message;
        let info = |name: &str| pb::ValueInfoProto {
            name: name.into(),
            r#type: Some(pb::TypeProto {
                value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                    elem_type: 1,
                    shape: Some(pb::TensorShapeProto {
                        dim: [1, 3, 4, 4]
                            .map(|d| pb::tensor_shape_proto::Dimension {
                                value: Some(pb::tensor_shape_proto::dimension::Value::DimValue(d)),
                                ..Default::default()
                            })
                            .to_vec(),
                    }),
                })),
                ..Default::default()
            }),
            ..Default::default()
        };
        let node = |op: &str, i: &str, o: &str| pb::NodeProto {
            op_type: op.into(),
            input: vec![i.into()],
            output: vec![o.into()],
            ..Default::default()
        };
        pb::ModelProto {
            ir_version: 7,
            opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 13 }],
            graph: Some(pb::GraphProto {
                node: vec![node("Relu", "x", "r"), node("Identity", "r", "y")],
                input: vec![info("x")],
                output: vec![info("y")],
                value_info: vec![info("r")],
                ..Default::default()
            }),
            ..Default::default()
        }
        .encode_to_vec()
    }

    fn model() -> Model {
        let text = r#"{"name": "relu", "file": "relu.onnx", "input": {"width": 4, "height": 4, "channels": "rgb"},
                       "task": {"kind": "face_detector", "strides": [1], "score_threshold": 0.5, "nms_iou": 0.3}}"#;
        let manifest = Manifest::parse(text, Path::new("relu.json"), Path::new(".")).unwrap();
        Model::from_bytes(manifest, &relu_onnx()).unwrap()
    }

    #[test]
    fn a_model_runs_at_sizes_other_than_its_manifest_s_with_plans_kept() {
        let m = model();
        let input = |h: usize, w: usize| {
            let v: Vec<f32> = (0..3 * h * w).map(|i| i as f32 - (3 * h * w / 2) as f32).collect();
            Tensor::from_shape(&[1, 3, h, w], &v).unwrap()
        };
        // At another size the graph's recorded 4 x 4 shapes do not get in the way, and the
        // output is the Relu of the input.
        let out = m.run_sized(input(6, 10)).unwrap();
        let y = out.any("y").unwrap();
        assert_eq!(y.len(), 180);
        for (i, &v) in y.iter().enumerate() {
            assert_eq!(v, (i as f32 - 90.0).max(0.0));
        }
        // The manifest's size uses the plan made at loading; the others are kept, the
        // least recently used dropped beyond KEPT.
        m.run_sized(input(4, 4)).unwrap();
        assert_eq!(m.sized.keys(), [(6, 10)]);
        for w in 1..=KEPT + 3 {
            m.run_sized(input(2, w)).unwrap();
        }
        assert_eq!(m.sized.keys(), (4..=KEPT + 3).map(|w| (2, w)).collect::<Vec<_>>());
        // A size used again is kept over one used less recently.
        m.run_sized(input(2, 4)).unwrap();
        m.run_sized(input(2, 100)).unwrap();
        let kept = m.sized.keys();
        assert_eq!((kept.len(), kept[0], kept[KEPT - 2..].to_vec()), (KEPT, (2, 6), vec![(2, 4), (2, 100)]));
        // A tensor of another rank is refused by name, not a panic.
        let bad = m.run_sized(Tensor::from_shape(&[3, 4, 4], &[0f32; 48]).unwrap()).err().unwrap();
        assert!(bad.to_string().contains("not 1x3xHxW"), "{bad}");
    }

    #[test]
    fn a_region_tensor_is_the_region_then_black() {
        let m = model();
        let img = RgbImage::from_fn(5, 3, |x, y| image::Rgb([(10 * x + y) as u8, 100, 200]));
        // The 2 x 2 region at (3, 1) on a 4 x 3 canvas: copied top-left, 0 elsewhere
        // (mean 0, std 1 by default), clipped where the region leaves the image.
        let t = m.region_tensor(&img, [3, 1, 4, 4], (4, 3));
        let v = t.try_as_plain_ram().and_then(|v| v.as_slice::<f32>()).unwrap();
        let at = |c: usize, y: usize, x: usize| v[c * 12 + y * 4 + x];
        assert_eq!((at(0, 0, 0), at(0, 0, 1), at(0, 1, 0), at(0, 1, 1)), (31.0, 41.0, 32.0, 42.0));
        assert_eq!((at(1, 0, 0), at(2, 1, 1)), (100.0, 200.0));
        assert_eq!((at(0, 0, 2), at(0, 2, 0), at(2, 2, 3)), (0.0, 0.0, 0.0));
    }
}
