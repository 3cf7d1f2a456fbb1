//! The utility player's data: COCO people (the evaluation's `instances_person.json`),
//! letterboxed to the detector's training size the way the evaluation feeds YOLOX (scaled to
//! fit, top-left, padding 114), with their boxes in canvas pixels.

use campro_eval::data::{coco_person, detector_held_out, read_rgb8, CocoImage};
use campro_eval::geometry::{letterbox, letterbox_size};
use candle_core::{Device, Tensor};
use rayon::prelude::*;
use std::path::Path;

/// YOLOX's letterbox padding value (0..255).
pub const PAD: u8 = 114;

/// One batch: sRGB canvases, where the image lies in them, and the person boxes.
pub struct PersonBatch {
    /// (B, 3, S, S) RGB in [0, 1], padding included.
    pub x: Tensor,
    /// (B, 1, S, S): 1 on image pixels, 0 on padding (the camera never sees padding).
    pub mask: Tensor,
    /// Per image, non-crowd person boxes (cx, cy, w, h) in canvas pixels.
    pub boxes: Vec<Vec<[f32; 4]>>,
}

pub struct PersonSet {
    pub images: Vec<CocoImage>,
    /// Canvas side S (a multiple of 32).
    pub size: usize,
}

impl PersonSet {
    /// Opens the training part of `root` (the COCO person folder): every image but those
    /// held out for evaluation ([`detector_held_out`]); `limit` keeps the first by id.
    pub fn open(root: &Path, size: usize, limit: Option<usize>) -> campro_eval::Result<Self> {
        let mut images = coco_person(root)?;
        images.retain(|im| !detector_held_out(im.id));
        images.truncate(limit.unwrap_or(usize::MAX));
        Ok(Self { images, size })
    }

    pub fn len(&self) -> usize {
        self.images.len()
    }

    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }

    /// Decodes and letterboxes the images `idx` (in parallel).
    pub fn batch(&self, idx: &[usize], dev: &Device) -> Result<PersonBatch, crate::error::TrainError> {
        let s = self.size;
        // Per image: letterboxed pixels (CHW), the mask of the image inside the letterbox, boxes (cx, cy, w, h).
        type Item = (Vec<f32>, Vec<f32>, Vec<[f32; 4]>);
        let items: Vec<Item> = idx
            .par_iter()
            .map(|&i| -> campro_eval::Result<_> {
                let im = &self.images[i];
                let img = read_rgb8(&im.path)?;
                let scale = (s as f64 / img.width() as f64).min(s as f64 / img.height() as f64);
                let canvas = letterbox(&img, s as u32, s as u32, scale, PAD);
                let (sw, sh) = letterbox_size(img.dimensions(), s as u32, s as u32, scale);
                let (sw, sh) = (sw as usize, sh as usize);
                let mut x = vec![0f32; 3 * s * s];
                for (k, p) in canvas.pixels().enumerate() {
                    for c in 0..3 {
                        x[c * s * s + k] = p.0[c] as f32 / 255.0;
                    }
                }
                let mask: Vec<f32> = (0..s * s).map(|k| if k % s < sw && k / s < sh { 1.0 } else { 0.0 }).collect();
                let f = scale as f32;
                let boxes = im
                    .gts
                    .iter()
                    .filter(|g| !g.crowd && g.bbox[2] * f >= 1.0 && g.bbox[3] * f >= 1.0)
                    .map(|g| {
                        [
                            (g.bbox[0] + g.bbox[2] / 2.0) * f,
                            (g.bbox[1] + g.bbox[3] / 2.0) * f,
                            g.bbox[2] * f,
                            g.bbox[3] * f,
                        ]
                    })
                    .collect();
                Ok((x, mask, boxes))
            })
            .collect::<campro_eval::Result<_>>()?;
        let b = idx.len();
        let (mut xs, mut ms, mut boxes) =
            (Vec::with_capacity(b * 3 * s * s), Vec::with_capacity(b * s * s), Vec::with_capacity(b));
        for (x, m, bx) in items {
            xs.extend(x);
            ms.extend(m);
            boxes.push(bx);
        }
        Ok(PersonBatch {
            x: Tensor::from_vec(xs, (b, 3, s, s), dev)?,
            mask: Tensor::from_vec(ms, (b, 1, s, s), dev)?,
            boxes,
        })
    }
}

/// The detector's input from the camera's output: padding restored to 114, RGB [0, 1] to
/// BGR 0..255 (YOLOX's convention).
pub fn detector_input(camera_out: &Tensor, mask: &Tensor) -> candle_core::Result<Tensor> {
    let pad = PAD as f64 / 255.0;
    let inside = camera_out.broadcast_mul(mask)?;
    let outside = ((1.0 - mask)? * pad)?;
    let rgb = inside.broadcast_add(&outside)?;
    let bgr = Tensor::cat(&[rgb.narrow(1, 2, 1)?, rgb.narrow(1, 1, 1)?, rgb.narrow(1, 0, 1)?], 1)?;
    bgr * 255.0
}
