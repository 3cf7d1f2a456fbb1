//! Model manifests: a small JSON file that says how to feed a model and read its output, so
//! a user can plug in their own face-recognition or detection model without code changes.
//!
//! ```json
//! { "name": "faceplugin", "file": "faceplugin_fr_feature.onnx",
//!   "input": { "width": 112, "height": 112, "channels": "rgb",
//!              "mean": [127, 127, 127], "std": [128, 128, 128] },
//!   "task": { "kind": "face_embedder", "output": "output",
//!             "template": [[38.2946, 51.6963], [73.5318, 51.5014], [56.0252, 71.7366],
//!                          [41.5493, 92.3655], [70.7299, 92.2041]] } }
//! ```
//! The network input is `(pixel − mean) / std` per channel (pixels 0..255), NCHW, batch 1.

use crate::error::{EvalError, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Channel order of the network input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Channels {
    Rgb,
    Bgr,
}

/// The input tensor: `1 x 3 x height x width`, `(pixel − mean[c]) / std[c]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Input {
    pub width: usize,
    pub height: usize,
    pub channels: Channels,
    #[serde(default)]
    pub mean: [f32; 3],
    #[serde(default = "ones")]
    pub std: [f32; 3],
}

fn ones() -> [f32; 3] {
    [1.0; 3]
}

/// What the model does and how its outputs are decoded.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Task {
    /// A face detector with 5 landmarks; `head` says how its outputs are decoded (YuNet's
    /// per-stride heads by default). The image is scaled down to fit (never up) and padded at
    /// the bottom/right with 0; a fully convolutional one also runs at other sizes, each
    /// side a multiple of its largest stride.
    FaceDetector {
        strides: Vec<usize>,
        #[serde(default)]
        head: Head,
        /// The face width (pixels, at the scale it is shown) from which it finds faces
        /// reliably; the face guard's pyramid enlarges its smallest face to it (2..=256).
        #[serde(default = "native_min_face")]
        min_face: f64,
        /// The score from which the face guard hides a find (0..1; default: half of
        /// `score_threshold`): a miss there shows a face, a false alarm pixelates a patch.
        #[serde(default)]
        guard_threshold: Option<f32>,
        /// Faces with `sqrt(cls·obj)` below this are dropped (0..1).
        score_threshold: f32,
        /// Greedy NMS IoU (0..1).
        nms_iou: f32,
    },
    /// YOLOX-style detector: one output `[1, N, 5 + classes]` per anchor
    /// (x, y, log w, log h, objectness, class probabilities), grids of `strides`, row-major.
    /// The image is letterboxed to the top-left, padded with `pad_value`.
    PersonDetector {
        output: String,
        strides: Vec<usize>,
        /// Index of the person class among the class probabilities.
        class_index: usize,
        /// Detections with `objectness · p(person)` below this are dropped (0..1).
        score_threshold: f32,
        nms_iou: f32,
        max_detections: usize,
        #[serde(default = "pad114")]
        pad_value: u8,
    },
    /// Face embedder: the face is aligned by a similarity transform from 5 landmarks
    /// (right eye, left eye, nose, right and left mouth corner of the person, i.e. image-left
    /// first) onto `template` (pixels of the input crop); the embedding is L2-normalised.
    FaceEmbedder {
        output: String,
        template: [[f32; 2]; 5],
        /// Verification thresholds calibrated on LFW (`campro eval thresholds`); `campro
        /// check` needs them.
        #[serde(default)]
        thresholds: Option<Thresholds>,
    },
}

/// A face model's verification thresholds: two faces are linked when the cosine similarity
/// of their embeddings is **above** the threshold of the false-accept rate (FAR) chosen.
/// Calibrated once on LFW by `campro eval thresholds` (every pair of different people among
/// the images of `pairs.txt`'s first folds); a test recomputes them.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Thresholds {
    /// At most 1 in 1,000 pairs of different people scores above this (cosine, -1..1).
    #[serde(rename = "far_1e-3")]
    pub far_1e3: f32,
    /// At most 1 in 100 (cosine, -1..1).
    #[serde(rename = "far_1e-2")]
    pub far_1e2: f32,
    /// Pairs of different people the thresholds were set on.
    pub impostor_pairs: usize,
    /// LFW `pairs.txt` folds whose images were used (1..=10).
    pub folds: usize,
}

/// How a face detector's outputs are decoded.
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Head {
    /// YuNet: `cls_s`, `obj_s` (N x 1), `bbox_s` (N x 4), `kps_s` (N x 10) per stride `s`.
    #[default]
    Yunet,
    /// CenterFace: four maps at a quarter of the input's size, named by the model: the face
    /// centre `heatmap` (1 channel, 0..1), the log box `scale` (height, width), the centre's
    /// sub-cell `offset` (y, x) and the 5 `landmarks` (y, x each, in box units from its
    /// top-left corner).
    Centerface { heatmap: String, scale: String, offset: String, landmarks: String },
}

impl Head {
    /// Bytes a detector of this head holds a pixel of its input while it runs (tract, one
    /// run): YuNet's 2048 x 1152 input peaked at 236 MB resident (100 a pixel); CenterFace's
    /// guard over a 50-megapixel photo, two 2048 x 720 tiles at once, added 736 MB to
    /// YuNet's run of the same (250 a pixel).
    pub fn bytes_per_pixel(&self) -> u64 {
        match self {
            Head::Yunet => 100,
            Head::Centerface { .. } => 250,
        }
    }
}

/// A face detector's default `min_face`: YuNet's (the face guard's `NATIVE_MIN_FACE`).
pub const DEFAULT_MIN_FACE: f64 = 16.0;

/// The stride of CenterFace's maps: a quarter of the input's size.
pub const CENTERFACE_STRIDE: usize = 4;

fn native_min_face() -> f64 {
    DEFAULT_MIN_FACE
}

fn pad114() -> u8 {
    114
}

/// A parsed, validated manifest; `file` is resolved against the models folder.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    pub name: String,
    pub file: PathBuf,
    pub input: Input,
    pub task: Task,
}

impl Manifest {
    /// Reads `path`; a relative `file` is looked up beside the manifest first (a model
    /// written with its manifest, e.g. a fine-tuned detector), then in `models_dir`.
    pub fn load(path: &Path, models_dir: &Path) -> Result<Self> {
        let text = campro::file::read_text_capped(path, 1 << 20, "a model manifest")?;
        let beside = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        match Self::parse(&text, path, beside) {
            Ok(m) if m.file.is_file() => Ok(m),
            _ => Self::parse(&text, path, models_dir),
        }
    }

    /// Parses manifest text (`origin` only names it in errors).
    pub fn parse(text: &str, origin: &Path, models_dir: &Path) -> Result<Self> {
        let de = &mut serde_json::Deserializer::from_str(text);
        let mut m: Manifest = serde_path_to_error::deserialize(de).map_err(|e| EvalError::Manifest {
            path: origin.into(),
            field: e.path().to_string(),
            rule: e.inner().to_string(),
        })?;
        if m.file.is_relative() {
            m.file = models_dir.join(&m.file);
        }
        m.validate().map_err(|(field, rule)| EvalError::Manifest { path: origin.into(), field, rule })?;
        Ok(m)
    }

    fn validate(&self) -> std::result::Result<(), (String, String)> {
        let bad = |f: &str, r: &str| Err((f.to_string(), r.to_string()));
        if self.name.is_empty() {
            return bad("name", "must not be empty");
        }
        let i = &self.input;
        if !(1..=8192).contains(&i.width) || !(1..=8192).contains(&i.height) {
            return bad("input", "width and height must be in 1..=8192");
        }
        if i.mean.iter().any(|v| !v.is_finite()) {
            return bad("input.mean", "must be finite");
        }
        if i.std.iter().any(|v| !v.is_finite() || *v <= 0.0) {
            return bad("input.std", "must be finite and > 0");
        }
        let unit = |v: f32| (0.0..=1.0).contains(&v);
        match &self.task {
            Task::FaceDetector { strides, score_threshold, nms_iou, head, min_face, guard_threshold } => {
                check_strides(strides, i)?;
                if guard_threshold.is_some_and(|t| !unit(t)) {
                    return bad("task.guard_threshold", "must be in [0, 1]");
                }
                if !(2.0..=256.0).contains(min_face) {
                    return bad("task.min_face", "must be in 2..=256 pixels");
                }
                if matches!(head, Head::Centerface { .. }) && strides.iter().any(|s| s % CENTERFACE_STRIDE != 0) {
                    return bad(
                        "task.strides",
                        "a centerface head's strides must be multiples of 4 (its maps are a quarter of the input)",
                    );
                }
                if !unit(*score_threshold) || !unit(*nms_iou) {
                    return bad("task", "score_threshold and nms_iou must be in [0, 1]");
                }
            }
            Task::PersonDetector { strides, score_threshold, nms_iou, max_detections, .. } => {
                check_strides(strides, i)?;
                if !unit(*score_threshold) || !unit(*nms_iou) {
                    return bad("task", "score_threshold and nms_iou must be in [0, 1]");
                }
                if *max_detections == 0 {
                    return bad("task.max_detections", "must be at least 1");
                }
            }
            Task::FaceEmbedder { template, thresholds, .. } => {
                if template.iter().flatten().any(|v| !v.is_finite()) {
                    return bad("task.template", "must be finite");
                }
                if let Some(t) = thresholds {
                    let cos = |v: f32| (-1.0..=1.0).contains(&v);
                    if !cos(t.far_1e3) || !cos(t.far_1e2) || t.far_1e3 < t.far_1e2 {
                        return bad(
                            "task.thresholds",
                            "far_1e-3 and far_1e-2 must be cosines in [-1, 1], far_1e-3 >= far_1e-2",
                        );
                    }
                    if !(1..=10).contains(&t.folds) || t.impostor_pairs == 0 {
                        return bad("task.thresholds", "folds must be in 1..=10 and impostor_pairs at least 1");
                    }
                }
            }
        }
        Ok(())
    }
}

fn check_strides(strides: &[usize], i: &Input) -> std::result::Result<(), (String, String)> {
    if strides.is_empty()
        || strides.iter().any(|&s| s == 0 || !i.width.is_multiple_of(s) || !i.height.is_multiple_of(s))
    {
        return Err(("task.strides".into(), "must be non-empty and divide the input width and height".into()));
    }
    Ok(())
}
