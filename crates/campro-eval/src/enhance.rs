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

/// A loaded enhancer; `enhance` takes `&self`, so one can serve several threads. tract
/// cannot prove that the U-Net's strided and upsampled shapes agree for a symbolic size, so
/// the graph is optimised once per padded image size and kept (a video or LFW has one
/// size; COCO has a few dozen).
pub struct Enhancer {
    model: InferenceModel,
    plans: std::sync::Mutex<std::collections::HashMap<(usize, usize), std::sync::Arc<TypedSimplePlan>>>,
    multiple: usize,
    path: PathBuf,
}

impl Enhancer {
    /// Reads and optimises the ONNX file at `path` (at most [`MAX_FILE`] bytes).
    pub fn load(path: &Path) -> Result<Self> {
        Self::from_bytes(&campro::file::read_capped(path, MAX_FILE, "an enhancer (ONNX)")?, path)
    }

    /// Reads an enhancer from the bytes of its ONNX file; `path` names it in errors.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self> {
        let bad = |m: String| EvalError::Model { path: path.to_path_buf(), message: m };
        let built = std::panic::catch_unwind(|| -> TractResult<(usize, InferenceModel)> {
            let onnx = tract_onnx::onnx();
            let proto = onnx.proto_model_for_read(&mut &bytes[..])?;
            let multiple = proto
                .metadata_props
                .iter()
                .find(|p| p.key == MULTIPLE_KEY)
                .and_then(|p| p.value.parse::<usize>().ok())
                .filter(|m| m.is_power_of_two() && *m <= 64)
                .ok_or_else(|| {
                    format_err!("no {MULTIPLE_KEY} entry (a power of two up to 64): not a campro enhancer")
                })?;
            let graph = proto.graph.as_ref().ok_or_else(|| format_err!("no graph"))?;
            let names = (graph.input.first().map(|i| i.name.as_str()), graph.output.first().map(|o| o.name.as_str()));
            if names != (Some(INPUT), Some(OUTPUT)) {
                bail!("input {:?} and output {:?}, expected {INPUT:?} and {OUTPUT:?}", names.0, names.1);
            }
            // Every node must compute from the input: tract folds constant-only nodes while
            // it reads the graph, so a few bytes of Tile, Expand or broadcasting on constants
            // could ask for gigabytes before any size check runs. A campro enhancer has none.
            let mut live: std::collections::HashSet<&str> = [INPUT].into_iter().collect();
            for n in &graph.node {
                if !n.input.iter().any(|i| live.contains(i.as_str())) {
                    bail!(
                        "node {:?} ({}) computes from constants only; a campro enhancer computes every node from its input",
                        n.name.chars().take(64).collect::<String>(),
                        n.op_type.chars().take(32).collect::<String>()
                    );
                }
                live.extend(n.output.iter().map(String::as_str));
            }
            Ok((multiple, onnx.model_for_proto_model(&proto)?))
        });
        let e = match built {
            Ok(Ok((multiple, model))) => Self { model, plans: Default::default(), multiple, path: path.to_path_buf() },
            Ok(Err(e)) => return Err(bad(format!("{e:#}"))),
            Err(_) => return Err(bad("tract could not read it (malformed graph)".into())),
        };
        // Built once at the smallest size, so a graph that cannot run fails here.
        e.plan(e.multiple, e.multiple)?;
        Ok(e)
    }

    /// The plan for a padded `w` x `h` input (built on first use).
    fn plan(&self, w: usize, h: usize) -> Result<std::sync::Arc<TypedSimplePlan>> {
        let mut plans = self.plans.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(p) = plans.get(&(w, h)) {
            return Ok(p.clone());
        }
        let model = self.model.clone();
        let limit = tensor_limit(w, h);
        // The model is a fresh copy, dropped on a panic. Its shapes are checked before
        // tract optimises it (constant folding would compute every constant tensor).
        let built = std::panic::catch_unwind(std::panic::AssertUnwindSafe(
            || -> TractResult<std::sync::Arc<TypedSimplePlan>> {
                let typed = model.with_input_fact(0, f32::fact([1, 3, h, w]).into())?.into_typed()?;
                if let Some((name, bytes)) = largest_tensor(&typed).filter(|&(_, b)| b > limit) {
                    bail!(
                        "its tensor {name:?} would take {} MiB at input 1x3x{h}x{w}; an enhancer may use {} MiB a tensor",
                        bytes >> 20,
                        limit >> 20
                    );
                }
                typed.into_optimized()?.into_runnable()
            },
        ));
        let plan = match built {
            Ok(r) => r.map_err(|e| EvalError::Model { path: self.path.clone(), message: format!("{e:#}") })?,
            Err(_) => {
                return Err(EvalError::Model {
                    path: self.path.clone(),
                    message: format!("cannot be run at input 1x3x{h}x{w} (tract refused the shapes)"),
                })
            }
        };
        plans.insert((w, h), plan.clone());
        Ok(plan)
    }

    /// Height and width multiple the network needs (images are padded to it).
    pub fn multiple(&self) -> usize {
        self.multiple
    }

    /// The enhanced image of a captured 8-bit image (same size).
    pub fn enhance(&self, img: &RgbImage) -> Result<RgbImage> {
        let (w, h) = (img.width() as usize, img.height() as usize);
        let (data, pw, ph) = padded_chw(img, self.multiple);
        let input = Tensor::from_shape(&[1, 3, ph, pw], &data).expect("shape matches data");
        let plan = self.plan(pw, ph)?;
        let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| plan.run(tvec!(input.into()))))
            .map_err(|_| EvalError::Model { path: self.path.clone(), message: "tract failed while running it".into() })?
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
        Ok(cropped_rgb8(v, pw, ph, w as u32, h as u32))
    }
}

/// Widest activation an enhancer may hold at full resolution, channels: a campro U-Net's
/// largest is its first decoder's concatenation (twice the first width, at most 64).
pub const MAX_FULL_RES_CHANNELS: usize = 128;

/// Largest tensor an enhancer may hold for a padded `w` x `h` input, bytes
/// ([`MAX_FULL_RES_CHANNELS`] f32 channels at full resolution, at least 64 MiB).
pub fn tensor_limit(w: usize, h: usize) -> usize {
    (MAX_FULL_RES_CHANNELS * 4).saturating_mul(w).saturating_mul(h).max(64 << 20)
}

/// The node output (name, bytes) with the most bytes, among those of known shape.
fn largest_tensor(model: &TypedModel) -> Option<(String, usize)> {
    model
        .nodes
        .iter()
        .flat_map(|n| n.outputs.iter().map(move |o| (n, o)))
        .filter_map(|(n, o)| {
            let dims = o.fact.shape.as_concrete()?;
            let count = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).unwrap_or(usize::MAX);
            Some((n.name.clone(), count.saturating_mul(o.fact.datum_type.size_of())))
        })
        .max_by_key(|&(_, b)| b)
}

/// The top-left `w` x `h` of a (3, `ph`, `pw`) float image in [0, 1] (the enhancer's
/// output on [`padded_chw`]'s input), rounded to 8 bits and clamped.
pub fn cropped_rgb8(v: &[f32], pw: usize, ph: usize, w: u32, h: u32) -> RgbImage {
    let q = |f: f32| (f * 255.0).round().clamp(0.0, 255.0) as u8;
    RgbImage::from_fn(w, h, |x, y| {
        let i = y as usize * pw + x as usize;
        image::Rgb([q(v[i]), q(v[pw * ph + i]), q(v[2 * pw * ph + i])])
    })
}

/// `img` as (3, H', W') floats in [0, 1], H' and W' rounded up to multiples of `multiple` by
/// repeating the last row and column; returns the data, W' and H'.
pub fn padded_chw(img: &RgbImage, multiple: usize) -> (Vec<f32>, usize, usize) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (pw, ph) = (w.div_ceil(multiple) * multiple, h.div_ceil(multiple) * multiple);
    let mut data = vec![0f32; 3 * pw * ph];
    for y in 0..ph {
        for x in 0..pw {
            let p = img.get_pixel(x.min(w - 1) as u32, y.min(h - 1) as u32).0;
            for c in 0..3 {
                data[c * pw * ph + y * pw + x] = p[c] as f32 / 255.0;
            }
        }
    }
    (data, pw, ph)
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;
    use tract_onnx::pb;

    fn node(op: &str, inputs: &[&str], output: &str) -> pb::NodeProto {
        pb::NodeProto {
            op_type: op.into(),
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![output.into()],
            name: output.into(),
            ..Default::default()
        }
    }

    fn value_info(name: &str) -> pb::ValueInfoProto {
        let dim = |v: i64| pb::tensor_shape_proto::Dimension {
            value: Some(pb::tensor_shape_proto::dimension::Value::DimValue(v)),
            ..Default::default()
        };
        pb::ValueInfoProto {
            name: name.into(),
            r#type: Some(pb::TypeProto {
                value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                    elem_type: 1,
                    shape: Some(pb::TensorShapeProto { dim: vec![dim(1), dim(3), dim(8), dim(8)] }),
                })),
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    /// An "enhancer" that adds to its input the sum of `tiled` tiled `repeats` times (`tiled`
    /// is the constant "c" or the input itself): a few hundred bytes that ask for
    /// `4 * product(repeats)` bytes or more.
    fn tile_bomb(tiled: &str, repeats: [i64; 4]) -> Vec<u8> {
        let inits = vec![
            pb::TensorProto {
                name: "c".into(),
                dims: vec![1, 1, 1, 1],
                data_type: 1,
                float_data: vec![1.0],
                ..Default::default()
            },
            pb::TensorProto {
                name: "r".into(),
                dims: vec![4],
                data_type: 7,
                int64_data: repeats.to_vec(),
                ..Default::default()
            },
        ];
        let model = pb::ModelProto {
            ir_version: 8,
            opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 13 }],
            metadata_props: vec![pb::StringStringEntryProto { key: MULTIPLE_KEY.into(), value: "8".into() }],
            graph: Some(pb::GraphProto {
                node: vec![
                    node("Tile", &[tiled, "r"], "t"),
                    node("ReduceSum", &["t"], "s"),
                    node("Add", &[INPUT, "s"], OUTPUT),
                ],
                initializer: inits,
                input: vec![value_info(INPUT)],
                output: vec![value_info(OUTPUT)],
                ..Default::default()
            }),
            ..Default::default()
        };
        model.encode_to_vec()
    }

    #[test]
    fn a_small_graph_that_asks_for_gigabytes_is_refused_before_it_runs() {
        // 60000 x 60000 floats (13 GiB) from a constant: refused before tract folds it.
        let bytes = tile_bomb("c", [1, 1, 60000, 60000]);
        assert!(bytes.len() < 400, "{}", bytes.len());
        let e = Enhancer::from_bytes(&bytes, Path::new("bomb.onnx")).err().expect("refused").to_string();
        assert!(e.starts_with("model bomb.onnx: ") && e.contains("constants only"), "{e}");
        // The same from the input: refused by its size at the smallest input (8 x 8 x 7500²).
        let e = Enhancer::from_bytes(&tile_bomb(INPUT, [1, 1, 7500, 7500]), Path::new("big.onnx"))
            .err()
            .expect("refused")
            .to_string();
        assert!(e.contains("MiB a tensor"), "{e}");
        // A small honest graph of the same shape runs.
        let ok = Enhancer::from_bytes(&tile_bomb(INPUT, [1, 1, 1, 1]), Path::new("ok.onnx")).unwrap();
        let img = image::RgbImage::from_pixel(8, 8, image::Rgb([10, 20, 30]));
        let out = ok.enhance(&img).unwrap();
        // Each pixel plus the sum of all 192 input values (clamped to 255).
        assert_eq!(out.get_pixel(0, 0).0, [255, 255, 255]);
    }

    #[test]
    fn the_tensor_limit_follows_the_image() {
        assert_eq!(tensor_limit(8, 8), 64 << 20);
        assert_eq!(tensor_limit(1280, 720), 512 * 1280 * 720);
    }
}
