//! Faces: detection with 5 landmarks (YuNet's and CenterFace's heads), similarity alignment onto an embedder's
//! template, and L2-normalised embeddings compared by cosine similarity.

use crate::error::{EvalError, Result};
use crate::geometry::{self, letterbox, nms, similarity, warp_affine};
pub use crate::manifest::CENTERFACE_STRIDE;
use crate::manifest::{Head, Task};
use crate::model::Model;
use image::RgbImage;

/// A detected face in image pixels: box `[x0, y0, x1, y1]`, score in [0, 1], landmarks in
/// the order right eye, left eye, nose tip, right and left mouth corner of the person
/// (image-left first).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Face {
    pub bbox: [f32; 4],
    pub score: f32,
    pub landmarks: [[f32; 2]; 5],
}

impl Face {
    /// The same face with every point (box corners, landmarks) mapped by `f`.
    pub fn mapped(self, f: impl Fn([f32; 2]) -> [f32; 2]) -> Face {
        let ([x0, y0], [x1, y1]) = (f([self.bbox[0], self.bbox[1]]), f([self.bbox[2], self.bbox[3]]));
        Face { bbox: [x0, y0, x1, y1], score: self.score, landmarks: self.landmarks.map(&f) }
    }
}

/// Decodes one stride of a YuNet head (`n = cols · rows` anchors, row-major) into `out`:
/// score = sqrt(clamp(cls)·clamp(obj)); centre = (col + dx, row + dy)·s; size = exp(dw, dh)·s;
/// landmark k = (col + kx, row + ky)·s.
pub fn decode_yunet_stride(
    stride: usize,
    cols: usize,
    cls: &[f32],
    obj: &[f32],
    bbox: &[f32],
    kps: &[f32],
    threshold: f32,
    out: &mut Vec<Face>,
) {
    let s = stride as f32;
    for i in 0..cls.len() {
        let score = (cls[i].clamp(0.0, 1.0) * obj[i].clamp(0.0, 1.0)).sqrt();
        if score < threshold || !score.is_finite() {
            continue;
        }
        let (col, row) = ((i % cols) as f32, (i / cols) as f32);
        let b = &bbox[4 * i..4 * i + 4];
        let (cx, cy) = ((col + b[0]) * s, (row + b[1]) * s);
        let (w, h) = (b[2].exp() * s, b[3].exp() * s);
        let k = &kps[10 * i..10 * i + 10];
        let landmarks = std::array::from_fn(|j| [(col + k[2 * j]) * s, (row + k[2 * j + 1]) * s]);
        out.push(Face { bbox: [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0], score, landmarks });
    }
}

/// Decodes CenterFace's maps (`cols` x `rows` cells, each [`CENTERFACE_STRIDE`] input
/// pixels; `scale`, `offset` two planes, `landmarks` ten) into `out`: a cell scoring at
/// least `threshold` is a face of height exp(scale₀)·4 and width exp(scale₁)·4 centred at
/// ((col + offset₁ + ½)·4, (row + offset₀ + ½)·4); landmark k is (landmarks₂ₖ₊₁ · width,
/// landmarks₂ₖ · height) from the box's top-left corner.
pub fn decode_centerface(
    cols: usize,
    heatmap: &[f32],
    scale: &[f32],
    offset: &[f32],
    landmarks: &[f32],
    threshold: f32,
    out: &mut Vec<Face>,
) {
    let n = heatmap.len();
    let s = CENTERFACE_STRIDE as f32;
    for (i, &score) in heatmap.iter().enumerate() {
        if score < threshold || !score.is_finite() {
            continue;
        }
        let (col, row) = ((i % cols) as f32, (i / cols) as f32);
        let (h, w) = (scale[i].exp() * s, scale[n + i].exp() * s);
        let (cx, cy) = ((col + offset[n + i] + 0.5) * s, (row + offset[i] + 0.5) * s);
        let (x0, y0) = (cx - w / 2.0, cy - h / 2.0);
        let lm = std::array::from_fn(|k| [x0 + landmarks[(2 * k + 1) * n + i] * w, y0 + landmarks[2 * k * n + i] * h]);
        let face = Face { bbox: [x0, y0, x0 + w, y0 + h], score: score.min(1.0), landmarks: lm };
        if face.bbox.iter().chain(face.landmarks.iter().flatten()).all(|v| v.is_finite()) {
            out.push(face);
        }
    }
}

/// A face detector (manifest task `face_detector`).
pub struct FaceDetector {
    model: Model,
    strides: Vec<usize>,
    head: Head,
    min_face: f64,
    guard_threshold: Option<f32>,
    threshold: f32,
    nms_iou: f32,
}

impl FaceDetector {
    pub fn new(model: Model) -> Result<Self> {
        match &model.manifest.task {
            Task::FaceDetector { strides, score_threshold, nms_iou, head, min_face, guard_threshold } => Ok(Self {
                guard_threshold: *guard_threshold,
                strides: strides.clone(),
                head: head.clone(),
                min_face: *min_face,
                threshold: *score_threshold,
                nms_iou: *nms_iou,
                model,
            }),
            _ => Err(EvalError::Invalid(format!("model {} is not a face_detector", model.manifest.name))),
        }
    }

    /// All faces above the threshold, after NMS, in image pixels, best first. The image is
    /// scaled down to fit the input (never up) and padded with black at the bottom/right.
    pub fn detect(&self, img: &RgbImage) -> Result<Vec<Face>> {
        let (iw, ih) = self.input_size();
        let scale = (iw as f64 / img.width() as f64).min(ih as f64 / img.height() as f64).min(1.0);
        let faces = self.detect_scaled(img, scale, self.threshold)?;
        Ok(self.suppressed(faces))
    }

    /// The model's name (its manifest's).
    pub fn name(&self) -> &str {
        &self.model.manifest.name
    }

    /// The model's input (width, height), pixels.
    pub fn input_size(&self) -> (usize, usize) {
        (self.model.manifest.input.width, self.model.manifest.input.height)
    }

    /// Bytes it holds a pixel of its input while it runs ([`Head::bytes_per_pixel`]).
    pub fn bytes_per_pixel(&self) -> u64 {
        self.head.bytes_per_pixel()
    }

    /// The face width (pixels at the scale shown) from which it finds faces reliably.
    pub fn min_face(&self) -> f64 {
        self.min_face
    }

    /// The score from which the face guard hides a find: the manifest's `guard_threshold`,
    /// else `share` of its score threshold.
    pub fn guard_threshold(&self, share: f32) -> f32 {
        self.guard_threshold.unwrap_or(self.threshold * share)
    }

    /// The manifest's score threshold.
    pub fn threshold(&self) -> f32 {
        self.threshold
    }

    /// Every face scoring at least `threshold` in `img` scaled by `scale` (which must fit
    /// the input: the scaled image is placed top-left, black below and right), in `img`'s
    /// pixels, before NMS.
    pub fn detect_scaled(&self, img: &RgbImage, scale: f64, threshold: f32) -> Result<Vec<Face>> {
        let (iw, ih) = self.input_size();
        let canvas = letterbox(img, iw as u32, ih as u32, scale, 0);
        let faces = self.decode(&self.model.run(&canvas)?, (iw, ih), threshold)?;
        let inv = (1.0 / scale) as f32;
        Ok(faces.into_iter().map(|f| f.mapped(|p| [p[0] * inv, p[1] * inv])).collect())
    }

    /// Every face scoring at least `threshold` in the `[x, y, w, h]` region of `img`, the
    /// network run at the region's size rounded up to a multiple of its largest stride
    /// (black beyond the region, as [`Self::detect_scaled`] pads), in `img`'s pixels,
    /// before NMS. The detector must be fully convolutional (YuNet is: its heads are
    /// reshaped to `-1` anchors); each size is planned once ([`Model::run_sized`]).
    pub fn detect_region(&self, img: &RgbImage, region: [u32; 4], threshold: f32) -> Result<Vec<Face>> {
        let [x, y, w, h] = region;
        let (cw, ch) = (self.canvas_side(w as usize), self.canvas_side(h as usize));
        let out = self.model.run_sized(self.model.region_tensor(img, region, (cw, ch)))?;
        let faces = self.decode(&out, (cw, ch), threshold)?;
        Ok(faces.into_iter().map(|f| f.mapped(|p| [p[0] + x as f32, p[1] + y as f32])).collect())
    }

    /// `len` pixels rounded up to a multiple of the largest stride (at least one stride).
    fn canvas_side(&self, len: usize) -> usize {
        let s = self.strides.iter().copied().max().unwrap_or(1).max(1);
        len.div_ceil(s).max(1) * s
    }

    /// The faces of one run on a `cw` x `ch` canvas, in its pixels.
    fn decode(&self, out: &crate::model::Outputs, (cw, ch): (usize, usize), threshold: f32) -> Result<Vec<Face>> {
        let mut faces = Vec::new();
        if let Head::Centerface { heatmap, scale, offset, landmarks } = &self.head {
            let (cols, rows) = (cw / CENTERFACE_STRIDE, ch / CENTERFACE_STRIDE);
            let n = cols * rows;
            decode_centerface(
                cols,
                out.get(heatmap, n)?,
                out.get(scale, 2 * n)?,
                out.get(offset, 2 * n)?,
                out.get(landmarks, 10 * n)?,
                threshold,
                &mut faces,
            );
            return Ok(faces);
        }
        for &s in &self.strides {
            let (cols, rows) = (cw / s, ch / s);
            let n = cols * rows;
            decode_yunet_stride(
                s,
                cols,
                out.get(&format!("cls_{s}"), n)?,
                out.get(&format!("obj_{s}"), n)?,
                out.get(&format!("bbox_{s}"), 4 * n)?,
                out.get(&format!("kps_{s}"), 10 * n)?,
                threshold,
                &mut faces,
            );
        }
        Ok(faces)
    }

    /// `faces` after non-maximum suppression at the manifest's IoU, best first.
    pub fn suppressed(&self, faces: Vec<Face>) -> Vec<Face> {
        let boxes: Vec<[f32; 4]> = faces.iter().map(|f| f.bbox).collect();
        let scores: Vec<f32> = faces.iter().map(|f| f.score).collect();
        nms(&boxes, &scores, self.nms_iou).into_iter().map(|i| faces[i]).collect()
    }
}

/// The face whose box centre is nearest the image centre (LFW centres the named person).
pub fn central_face(faces: &[Face], width: u32, height: u32) -> Option<Face> {
    let (cx, cy) = (width as f32 / 2.0, height as f32 / 2.0);
    let d = |f: &Face| ((f.bbox[0] + f.bbox[2]) / 2.0 - cx).powi(2) + ((f.bbox[1] + f.bbox[3]) / 2.0 - cy).powi(2);
    faces.iter().copied().min_by(|a, b| d(a).total_cmp(&d(b)))
}

/// A face embedder (manifest task `face_embedder`).
pub struct Embedder {
    model: Model,
    output: String,
    template: [[f64; 2]; 5],
}

impl Embedder {
    pub fn new(model: Model) -> Result<Self> {
        match &model.manifest.task {
            Task::FaceEmbedder { output, template, .. } => {
                Ok(Self { output: output.clone(), template: template.map(|p| p.map(f64::from)), model })
            }
            _ => Err(EvalError::Invalid(format!("model {} is not a face_embedder", model.manifest.name))),
        }
    }

    pub fn name(&self) -> &str {
        &self.model.manifest.name
    }

    /// The verification thresholds of its manifest (`None`: not calibrated).
    pub fn thresholds(&self) -> Option<crate::manifest::Thresholds> {
        match &self.model.manifest.task {
            Task::FaceEmbedder { thresholds, .. } => *thresholds,
            _ => None,
        }
    }

    /// The crop this model expects: a similarity transform from `landmarks` onto the
    /// template, bilinear, black outside.
    pub fn align(&self, img: &RgbImage, landmarks: &[[f32; 2]; 5]) -> RgbImage {
        let src = landmarks.map(|p| p.map(f64::from));
        let m = similarity(&src, &self.template);
        let (w, h) = (self.model.manifest.input.width as u32, self.model.manifest.input.height as u32);
        warp_affine(img, &m, w, h).unwrap_or_else(|| RgbImage::new(w, h))
    }

    /// The L2-normalised embedding of an aligned crop (of the model's input size).
    pub fn embed(&self, crop: &RgbImage) -> Result<Vec<f32>> {
        let out = self.model.run(crop)?;
        let mut v = out.any(&self.output)?.to_vec();
        let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        if !(n > 0.0 && n.is_finite()) {
            return Err(EvalError::Model {
                path: self.model.manifest.file.clone(),
                message: "embedding has zero or non-finite norm".into(),
            });
        }
        v.iter_mut().for_each(|x| *x /= n);
        Ok(v)
    }
}

/// Cosine similarity of two L2-normalised embeddings.
pub fn cosine(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

pub use geometry::iou;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yunet_decoding_by_hand() {
        // Stride 8, a 2x2 grid; anchor 3 is (col 1, row 1).
        let cls = [0.0, 0.0, 0.0, 0.81];
        let obj = [1.0, 1.0, 1.0, 1.0];
        let mut bbox = [0.0f32; 16];
        bbox[12..16].copy_from_slice(&[0.5, 0.25, 0.0, 2f32.ln()]);
        let mut kps = [0.0f32; 40];
        kps[30..40].copy_from_slice(&[0.0, 0.0, 1.0, 0.0, 0.5, 0.5, 0.0, 1.0, 1.0, 1.0]);
        let mut faces = Vec::new();
        decode_yunet_stride(8, 2, &cls, &obj, &bbox, &kps, 0.5, &mut faces);
        assert_eq!(faces.len(), 1);
        let f = faces[0];
        assert!((f.score - 0.9).abs() < 1e-6); // sqrt(0.81 · 1)
                                               // centre (1.5·8, 1.25·8) = (12, 10); size (8, 16).
        assert_eq!(f.bbox, [8.0, 2.0, 16.0, 18.0]);
        assert_eq!(f.landmarks[0], [8.0, 8.0]);
        assert_eq!(f.landmarks[2], [12.0, 12.0]);
        assert_eq!(f.landmarks[4], [16.0, 16.0]);
    }

    #[test]
    fn central_face_picks_the_middle() {
        let f = |x: f32| Face { bbox: [x, 40.0, x + 20.0, 60.0], score: 0.9, landmarks: [[0.0; 2]; 5] };
        let faces = [f(0.0), f(45.0), f(80.0)];
        assert_eq!(central_face(&faces, 100, 100).unwrap().bbox[0], 45.0);
        assert!(central_face(&[], 100, 100).is_none());
    }
}
