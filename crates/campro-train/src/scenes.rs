//! The enhancer's data (paper Sec. IV-D): raw scenes, what the camera captures of them (the
//! exact 8-bit pipeline, the same bytes `campro simulate` writes) and where their faces are.
//!
//! Scenes are the COCO person training images (never the held-out ones, see
//! [`campro_eval::data::detector_held_out`]) plus LFW photos of identities the preset did not
//! hold out. Faces are found by YuNet on the raw image; each box is enlarged to cover the
//! head and hair ([`crate::config::SceneConfig::face_margin`]) and masked out of the loss.

use crate::config::SceneConfig;
use campro::pipeline::fast::Exact8;
use campro_eval::data::{coco_person, detector_held_out, read_rgb8, Lfw};
use campro_eval::face::FaceDetector;
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use candle_core::{Device, Tensor};
use image::RgbImage;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use std::path::Path;

const YUNET: &str = include_str!("../../campro-eval/models/yunet.json");

/// One training scene.
pub struct Scene {
    pub raw: RgbImage,
    /// The camera's 8-bit output of `raw`.
    pub captured: RgbImage,
    /// `captured` through the restoration table, when there is one.
    pub restored: Option<RgbImage>,
    /// Enlarged face boxes `[x0, y0, x1, y1]` in pixels (clipped to the image).
    pub faces: Vec<[u32; 4]>,
}

impl Scene {
    /// What the U-Net reads: the restored image, or the captured one.
    pub fn input(&self) -> &RgbImage {
        self.restored.as_ref().unwrap_or(&self.captured)
    }

    /// 1 where the loss restores the image, 0 inside a face box; row-major, `w` x `h` from
    /// (`x0`, `y0`).
    pub fn keep(&self, x0: u32, y0: u32, w: u32, h: u32) -> Vec<f32> {
        let mut m = vec![1f32; (w * h) as usize];
        for f in &self.faces {
            for y in f[1].max(y0)..f[3].min(y0 + h) {
                for x in f[0].max(x0)..f[2].min(x0 + w) {
                    m[((y - y0) * w + (x - x0)) as usize] = 0.0;
                }
            }
        }
        m
    }
}

/// Training and validation scenes.
pub struct SceneSet {
    pub train: Vec<Scene>,
    pub validation: Vec<Scene>,
    /// The restoration table fitted on the training scenes (with `restorer`).
    pub table: Option<campro_eval::restore::Table>,
    /// COCO and LFW images read.
    pub coco: usize,
    pub lfw: usize,
    /// Images left out for being smaller than a crop.
    pub too_small: usize,
    /// Face boxes masked, in all.
    pub faces: usize,
}

/// One training batch.
pub struct SceneBatch {
    /// What the U-Net reads ([`Scene::input`]), (B, 3, S, S) in [0, 1].
    pub input: Tensor,
    /// The captured crops (B, 3, S, S) in [0, 1] (the same as `input` without a restoration
    /// stage).
    pub captured: Tensor,
    /// The raw crops (B, 3, S, S) in [0, 1].
    pub raw: Tensor,
    /// (B, 1, S, S): 0 on faces, 1 elsewhere (all ones when faces are restored too).
    pub keep: Tensor,
}

/// `img` as (3, H, W) floats in [0, 1], appended to `out`.
pub fn push_chw(img: &RgbImage, out: &mut Vec<f32>) {
    for c in 0..3 {
        out.extend(img.pixels().map(|p| p.0[c] as f32 / 255.0));
    }
}

/// `img` as a (1, 3, H, W) tensor in [0, 1].
pub fn chw_tensor(img: &RgbImage, dev: &Device) -> candle_core::Result<Tensor> {
    let mut v = Vec::with_capacity(3 * img.as_raw().len());
    push_chw(img, &mut v);
    Tensor::from_vec(v, (1, 3, img.height() as usize, img.width() as usize), dev)
}

impl SceneSet {
    /// Reads the scenes `cfg` names, captures them through `params` and finds their faces.
    /// `held_out`: LFW identities never to read (the preset's held-out ones).
    /// With `restorer`, fits the restoration table on the training scenes and gives every
    /// scene its restored `input`. `room`: the bytes the decoded scenes may hold (the
    /// memory budget less one step), checked from the files' headers before decoding.
    pub fn load(
        cfg: &SceneConfig,
        params: &campro::Params,
        held_out: &[String],
        restorer: bool,
        seed: u64,
        room: u64,
    ) -> Result<Self, crate::TrainError> {
        let mut paths = Vec::new();
        let mut coco = coco_person(&cfg.coco)?;
        coco.retain(|im| !detector_held_out(im.id));
        coco.truncate(cfg.max_images.unwrap_or(usize::MAX));
        let n_coco = coco.len();
        paths.extend(coco.into_iter().map(|im| im.path));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut n_lfw = 0;
        if cfg.lfw_images > 0 {
            let lfw = Lfw::open(&cfg.lfw)?;
            let mut photos: Vec<_> = lfw
                .people
                .iter()
                .filter(|(name, _)| !held_out.contains(name))
                .flat_map(|(_, ps)| ps.iter().cloned())
                .collect();
            photos.shuffle(&mut rng);
            photos.truncate(cfg.lfw_images);
            n_lfw = photos.len();
            paths.extend(photos);
        }
        if paths.is_empty() {
            return Err(crate::TrainError::Unsupported(format!(
                "{}: no training images (data.max_images, data.lfw_images)",
                cfg.coco.display()
            )));
        }
        // What the decoded scenes will hold (raw, captured and restored planes), from the
        // files' headers, before any is decoded.
        let planes = if restorer { 3 } else { 2 };
        let held: u64 = paths
            .par_iter()
            .map(|p| campro_eval::image_file::dimensions(p).map(|(w, h)| u64::from(w) * u64::from(h) * 3 * planes))
            .sum::<campro_eval::Result<u64>>()?;
        if held > room {
            return Err(crate::config::ConfigError::Budget {
                key: "budget.memory",
                rule: format!(
                    "the {} scenes (data.max_images {}, data.lfw_images {}) hold {} MiB decoded, over the {} MiB budget.memory leaves beside one step: lower those fields or raise budget.memory",
                    paths.len(),
                    cfg.max_images.map_or("all".to_string(), |m| m.to_string()),
                    cfg.lfw_images,
                    held.div_ceil(1 << 20),
                    room >> 20
                ),
            }
            .into());
        }
        let boxes = face_boxes(&paths, &cfg.models, &cfg.cache)?;
        let camera = Exact8::new(params);
        let margin = cfg.face_margin as f32;
        let scenes: Vec<Option<Scene>> = paths
            .par_iter()
            .zip(&boxes)
            .map(|(p, found)| -> campro_eval::Result<Option<Scene>> {
                let raw = read_rgb8(p)?;
                if raw.width() < cfg.crop as u32 || raw.height() < cfg.crop as u32 {
                    return Ok(None);
                }
                let mut captured = RgbImage::new(raw.width(), raw.height());
                camera.run(raw.as_raw(), &mut captured);
                // Found in every mode: a restoration network is measured on the faces too.
                let faces = found.iter().map(|&b| enlarge(b, margin, raw.width(), raw.height())).collect();
                Ok(Some(Scene { raw, captured, restored: None, faces }))
            })
            .collect::<campro_eval::Result<_>>()?;
        let too_small = scenes.iter().filter(|s| s.is_none()).count();
        let mut scenes: Vec<Scene> = scenes.into_iter().flatten().collect();
        // The validation scenes: a seeded choice, never trained on.
        let mut order: Vec<usize> = (0..scenes.len()).collect();
        order.shuffle(&mut rng);
        let n_val = cfg.validation_images.min(scenes.len().saturating_sub(1));
        let mut val_idx: Vec<usize> = order[..n_val].to_vec();
        val_idx.sort_unstable_by(|a, b| b.cmp(a));
        let mut validation: Vec<Scene> = val_idx.iter().map(|&i| scenes.swap_remove(i)).collect();
        validation.reverse();
        let faces = scenes.iter().chain(&validation).map(|s| s.faces.len()).sum();
        // The per-pixel restoration, fitted on the training scenes only.
        let table = if restorer {
            let protect = |img: &RgbImage| {
                let mut out = RgbImage::new(img.width(), img.height());
                camera.run(img.as_raw(), &mut out);
                out
            };
            let t = campro_eval::restore::Restorer::fit(protect, scenes.iter().map(|s| &s.raw))?.table().clone();
            for s in scenes.iter_mut().chain(validation.iter_mut()) {
                s.restored = Some(t.apply(&s.captured));
            }
            Some(t)
        } else {
            None
        };
        Ok(Self { train: scenes, validation, table, coco: n_coco, lfw: n_lfw, too_small, faces })
    }

    /// Random `size` x `size` crops of the training scenes `idx`, each flipped left-right
    /// with probability 1/2; `mask_faces` false gives a `keep` of all ones.
    pub fn batch(
        &self,
        idx: &[usize],
        size: usize,
        mask_faces: bool,
        rng: &mut rand_chacha::ChaCha8Rng,
        dev: &Device,
    ) -> candle_core::Result<SceneBatch> {
        let s = size as u32;
        let (mut inp, mut cap, mut raw, mut keep) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for &i in idx {
            let sc = &self.train[i];
            let x0 = rng.random_range(0..=sc.raw.width() - s);
            let y0 = rng.random_range(0..=sc.raw.height() - s);
            let flip = rng.random_bool(0.5);
            let crop = |img: &RgbImage| {
                let c = image::imageops::crop_imm(img, x0, y0, s, s).to_image();
                if flip {
                    image::imageops::flip_horizontal(&c)
                } else {
                    c
                }
            };
            push_chw(&crop(sc.input()), &mut inp);
            push_chw(&crop(&sc.captured), &mut cap);
            push_chw(&crop(&sc.raw), &mut raw);
            let mut k = if mask_faces { sc.keep(x0, y0, s, s) } else { vec![1.0; size * size] };
            if flip {
                k.chunks_mut(size).for_each(|row| row.reverse());
            }
            keep.extend(k);
        }
        let b = idx.len();
        Ok(SceneBatch {
            input: Tensor::from_vec(inp, (b, 3, size, size), dev)?,
            captured: Tensor::from_vec(cap, (b, 3, size, size), dev)?,
            raw: Tensor::from_vec(raw, (b, 3, size, size), dev)?,
            keep: Tensor::from_vec(keep, (b, 1, size, size), dev)?,
        })
    }
}

/// The most face boxes kept for one image (the highest scored): a training scene of 256
/// pixels holds far fewer faces, and [`Scene::keep`]'s work is boxes x box area.
pub const MAX_BOXES: usize = 64;

/// Bytes a face-box cache may take for `n` images: [`MAX_BOXES`] boxes of four floats as
/// JSON (at most 96 characters a box) an image.
fn cache_cap(n: usize) -> u64 {
    64 + n as u64 * (MAX_BOXES as u64 * 96 + 8)
}

/// The face boxes cached in `file` for `n` images, if the file is a regular file within
/// [`cache_cap`] (so that even empty lists, 3 bytes each in JSON and 24 parsed, stay within
/// 8 times that) holding exactly `n` lists of at most [`MAX_BOXES`] finite boxes; None (and
/// the boxes are found again) otherwise.
fn cached_boxes(file: &Path, n: usize) -> Option<Vec<Vec<[f32; 4]>>> {
    let bytes = campro::file::read_capped(file, cache_cap(n), "a face-box cache").ok()?;
    let b: Vec<Vec<[f32; 4]>> = serde_json::from_slice(&bytes).ok()?;
    let sound = b.len() == n && b.iter().all(|v| v.len() <= MAX_BOXES && v.iter().flatten().all(|c| c.is_finite()));
    sound.then_some(b)
}

/// YuNet's face boxes `[x0, y0, x1, y1]` (pixels) on each image of `paths`, read from
/// `cache` when an earlier run found them for the same list and models, else found and
/// cached (temporary file + rename; a cache that cannot be written only costs the next run).
fn face_boxes(
    paths: &[std::path::PathBuf],
    models: &Path,
    cache: &Path,
) -> Result<Vec<Vec<[f32; 4]>>, crate::TrainError> {
    let list: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    let key = crate::faces::fnv(&format!("{}|{}|{YUNET}", list.join("\n"), models.display()));
    let file = cache.join(format!("face-boxes-{key:016x}.json"));
    if let Some(b) = cached_boxes(&file, paths.len()) {
        return Ok(b);
    }
    let det = FaceDetector::new(Model::load(Manifest::parse(YUNET, Path::new("bundled yunet.json"), models)?)?)?;
    let boxes: Vec<Vec<[f32; 4]>> = paths
        .par_iter()
        .map(|p| -> campro_eval::Result<Vec<[f32; 4]>> {
            Ok(det.detect(&read_rgb8(p)?)?.iter().take(MAX_BOXES).map(|f| f.bbox).collect())
        })
        .collect::<campro_eval::Result<_>>()?;
    let _ = campro::file::atomic::write(&file, &serde_json::to_vec(&boxes).expect("boxes serialise"), true);
    Ok(boxes)
}

/// A face box grown by `m` of its width left and right, of its height below and by twice
/// that above, clipped to the `w` x `h` image.
pub fn enlarge(b: [f32; 4], m: f32, w: u32, h: u32) -> [u32; 4] {
    let (bw, bh) = (b[2] - b[0], b[3] - b[1]);
    let clip = |v: f32, hi: u32| v.round().clamp(0.0, hi as f32) as u32;
    [clip(b[0] - m * bw, w), clip(b[1] - 2.0 * m * bh, h), clip(b[2] + m * bw, w), clip(b[3] + m * bh, h)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_face_box_cache_is_read_only_when_it_is_what_the_images_need() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("face-boxes.json");
        let write = |text: &str| std::fs::write(&file, text).unwrap();
        write("[[[1,2,3,4]],[]]");
        assert_eq!(cached_boxes(&file, 2), Some(vec![vec![[1.0, 2.0, 3.0, 4.0]], vec![]]));
        // Another count of images, a non-finite box (JSON cannot say NaN; a huge number
        // overflows f32 to infinity), too many boxes: found again.
        assert_eq!(cached_boxes(&file, 3), None);
        write("[[[1,2,3,1e39]],[]]");
        assert_eq!(cached_boxes(&file, 2), None);
        write(&format!("[[{}],[]]", vec!["[0,0,1,1]"; MAX_BOXES + 1].join(",")));
        assert_eq!(cached_boxes(&file, 2), None);
        // Empty lists amplify 8 times when parsed: past the cap for 2 images, not read.
        write(&format!("[{}[]]", "[],".repeat(cache_cap(2) as usize / 3)));
        assert_eq!(cached_boxes(&file, 2), None);
        assert_eq!(cache_cap(2), 64 + 2 * (64 * 96 + 8));
    }
}
