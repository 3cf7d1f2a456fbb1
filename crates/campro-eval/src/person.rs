//! Person detection: letterbox, YOLOX decoding, NMS.

use crate::error::{EvalError, Result};
use crate::geometry::{letterbox, nms};
use crate::manifest::Task;
use crate::model::Model;
use image::RgbImage;

/// A detection in image pixels: box `[x0, y0, x1, y1]` and score in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    pub bbox: [f32; 4],
    pub score: f32,
}

/// Decodes a YOLOX head `[n, 5 + classes]` over grids of `strides` (row-major, strides in
/// order) for input `width x height`: centre = (x + col, y + row)·s, size = exp(log w, log h)·s,
/// score = objectness · p(class). Keeps scores ≥ `threshold`; coordinates in input pixels.
pub fn decode_yolox(
    head: &[f32],
    width: usize,
    height: usize,
    strides: &[usize],
    class: usize,
    threshold: f32,
) -> Result<Vec<Detection>> {
    let n: usize = strides.iter().map(|s| (width / s) * (height / s)).sum();
    if n == 0 || !head.len().is_multiple_of(n) || head.len() / n <= 5 + class {
        return Err(EvalError::Invalid(format!(
            "YOLOX output has {} values, which is not {n} anchors x (5 + classes > {class})",
            head.len()
        )));
    }
    let stride_len = head.len() / n;
    let mut out = Vec::new();
    let mut a = 0;
    for &s in strides {
        let cols = width / s;
        for i in 0..(width / s) * (height / s) {
            let r = &head[a * stride_len..(a + 1) * stride_len];
            a += 1;
            let score = r[4] * r[5 + class];
            // A NaN score is below any threshold.
            if score.is_nan() || score < threshold {
                continue;
            }
            let (col, row, s) = ((i % cols) as f32, (i / cols) as f32, s as f32);
            let (cx, cy) = ((r[0] + col) * s, (r[1] + row) * s);
            let (w, h) = (r[2].exp() * s, r[3].exp() * s);
            out.push(Detection { bbox: [cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0], score });
        }
    }
    Ok(out)
}

/// What a person detector reports from one YOLOX head on a `width` x `height` input:
/// [`decode_yolox`], then greedy NMS at `nms_iou`, at most `max` detections, best first, in
/// input pixels. `PersonDetector::detect` and the optimiser's validation share it.
#[allow(clippy::too_many_arguments)]
pub fn detections(
    head: &[f32],
    width: usize,
    height: usize,
    strides: &[usize],
    class: usize,
    threshold: f32,
    nms_iou: f32,
    max: usize,
) -> Result<Vec<Detection>> {
    let dets = decode_yolox(head, width, height, strides, class, threshold)?;
    let boxes: Vec<[f32; 4]> = dets.iter().map(|d| d.bbox).collect();
    let scores: Vec<f32> = dets.iter().map(|d| d.score).collect();
    Ok(nms(&boxes, &scores, nms_iou).into_iter().take(max).map(|i| dets[i]).collect())
}

/// A person detector (manifest task `person_detector`).
pub struct PersonDetector {
    model: Model,
}

impl PersonDetector {
    pub fn new(model: Model) -> Result<Self> {
        match &model.manifest.task {
            Task::PersonDetector { .. } => Ok(Self { model }),
            _ => Err(EvalError::Invalid(format!("model {} is not a person_detector", model.manifest.name))),
        }
    }

    /// People in `img` (image pixels, clipped to the image), best first, after NMS.
    pub fn detect(&self, img: &RgbImage) -> Result<Vec<Detection>> {
        let Task::PersonDetector { output, strides, class_index, score_threshold, nms_iou, max_detections, pad_value } =
            &self.model.manifest.task
        else {
            unreachable!("checked in new")
        };
        let (iw, ih) = (self.model.manifest.input.width, self.model.manifest.input.height);
        let scale = (iw as f64 / img.width() as f64).min(ih as f64 / img.height() as f64);
        let canvas = letterbox(img, iw as u32, ih as u32, scale, *pad_value);
        let out = self.model.run(&canvas)?;
        let dets =
            detections(out.any(output)?, iw, ih, strides, *class_index, *score_threshold, *nms_iou, *max_detections)?;
        let (w, h, inv) = (img.width() as f32, img.height() as f32, (1.0 / scale) as f32);
        Ok(dets
            .into_iter()
            .map(|d| {
                let b = d.bbox;
                let bbox = [
                    (b[0] * inv).clamp(0.0, w),
                    (b[1] * inv).clamp(0.0, h),
                    (b[2] * inv).clamp(0.0, w),
                    (b[3] * inv).clamp(0.0, h),
                ];
                Detection { bbox, score: d.score }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yolox_decoding_by_hand() {
        // Input 16x16, strides 8 (2x2 grid) and 16 (1x1): 5 anchors, 1 class.
        let mut head = vec![0f32; 5 * 6];
        // anchor 1 = stride 8, col 1, row 0: centre (8 + 0.5·8, 0.5·8) = (12, 4), size 8x16.
        head[6..12].copy_from_slice(&[0.5, 0.5, 0.0, 2f32.ln(), 0.9, 0.5]);
        // anchor 4 = stride 16, col 0, row 0: centre (8, 8), size 16x16, score 0.0009 < threshold.
        head[24..30].copy_from_slice(&[0.5, 0.5, 0.0, 0.0, 0.03, 0.03]);
        let d = decode_yolox(&head, 16, 16, &[8, 16], 0, 0.001).unwrap();
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].bbox, [8.0, -4.0, 16.0, 12.0]);
        assert!((d[0].score - 0.45).abs() < 1e-7);
        assert!(decode_yolox(&head[..29], 16, 16, &[8, 16], 0, 0.001).is_err());
    }
}
