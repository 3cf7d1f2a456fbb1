//! The attacker's face set: LFW identities with enough photos, each photo detected by YuNet
//! and aligned onto MobileFaceNet's 112x96 template (the evaluation's own code), cached as
//! raw bytes so later runs skip detection. Identities are split, seeded, into the proxy
//! head's classes and held-out validation identities; each class keeps its last photo aside
//! to measure the attacker's accuracy.

pub use crate::error::FacesError;
use campro_eval::data::{read_rgb8, Lfw};
use campro_eval::face::{central_face, FaceDetector};
use campro_eval::geometry::{similarity, warp_affine};
use campro_eval::manifest::{Manifest, Task};
use campro_eval::model::Model;
use campro_nn::mobilefacenet::EMBEDDING;
use candle_core::{Device, Tensor};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Crop size (height, width) of MobileFaceNet.
pub const CROP: (usize, usize) = (112, 96);

/// The most bytes a face cache may hold: a crop of every LFW photo (13,233) and 64 MiB of
/// index.
const MAX_CACHE_BYTES: u64 = 13_233 * (CROP.0 * CROP.1 * 3) as u64 + (64 << 20);

/// The BT.601 luma weights of [`campro::chroma::luma`], in its integer form over 256.
const LUMA: [f32; 3] = [77.0 / 256.0, 150.0 / 256.0, 29.0 / 256.0];

/// A batch of faces `x` (B, 3, H, W) in [0, 1] as a black-and-white camera sees them: each
/// pixel's luma in all three channels. The float form of [`campro::chroma::luma`] (the
/// evaluation's grey scene), which floors to 8 bits; the two differ by under 1/255.
pub fn grey(x: &Tensor) -> candle_core::Result<Tensor> {
    let w = Tensor::new(&LUMA, x.device())?.reshape((1, 3, 1, 1))?;
    x.broadcast_mul(&w)?.sum_keepdim(1)?.repeat((1, 3, 1, 1))
}
const YUNET: &str = include_str!("../../campro-eval/models/yunet.json");
const MOBILEFACENET: &str = include_str!("../../campro-eval/models/mobilefacenet_casia.json");

/// Which faces to use (the data part of the configuration).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Selection {
    pub lfw: PathBuf,
    pub min_images: usize,
    pub validation_identities: f64,
    pub max_identities: Option<usize>,
    pub seed: u64,
    /// Identities never read (a preset's held-out ones), left out before anything else.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exclude: Vec<String>,
}

#[derive(Serialize, Deserialize)]
struct Index {
    selection: Selection,
    classes: Vec<String>,
    validation: Vec<String>,
    labels: Vec<u32>,
    check: Vec<bool>,
    skipped: usize,
}

/// Aligned crops (RGB, HWC, u8) with their class labels.
pub struct FaceSet {
    pub classes: Vec<String>,
    /// Held-out identities (never trained on): for evaluating transfer.
    pub validation: Vec<String>,
    pub labels: Vec<u32>,
    /// Per crop: kept aside to check the attacker (the last photo of each class).
    pub check: Vec<bool>,
    pub crops: Vec<u8>,
    /// Photos left out because YuNet found no face.
    pub skipped: usize,
}

impl FaceSet {
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// Indices of the training crops and of the check crops.
    pub fn split(&self) -> (Vec<usize>, Vec<usize>) {
        (0..self.len()).partition(|&i| !self.check[i])
    }

    /// Crops `idx` as (B, 3, 112, 96) sRGB in [0, 1], and their labels (B,).
    pub fn batch(&self, idx: &[usize], device: &Device) -> candle_core::Result<(Tensor, Tensor)> {
        let (h, w) = CROP;
        let n = h * w * 3;
        let mut data = Vec::with_capacity(idx.len() * n);
        for &i in idx {
            data.extend(self.crops[i * n..(i + 1) * n].iter().map(|&v| v as f32 / 255.0));
        }
        let x = Tensor::from_vec(data, (idx.len(), h, w, 3), device)?.permute((0, 3, 1, 2))?.contiguous()?;
        let y = Tensor::from_vec(idx.iter().map(|&i| self.labels[i]).collect::<Vec<u32>>(), idx.len(), device)?;
        Ok((x, y))
    }

    /// Sums of the unit embeddings (`embed`: (B, 3, 112, 96) in [0, 1] to MobileFaceNet's
    /// (B, 128)) of crops `idx` by class, (classes, 128): the raw class means up to scale. Cached in `cache`, keyed
    /// by the selection `sel` this set was built for and the face model's `checkpoint` file
    /// (path and length): one backbone pass over every face otherwise.
    pub fn class_means(
        &self,
        idx: &[usize],
        sel: &Selection,
        checkpoint: &Path,
        cache: &Path,
        embed: impl Fn(&Tensor) -> candle_core::Result<Tensor>,
        device: &Device,
    ) -> candle_core::Result<Tensor> {
        let classes = self.classes.len();
        let ckpt_len = std::fs::metadata(checkpoint).map_or(0, |m| m.len());
        let key = fnv(&format!(
            "{}|{}|{ckpt_len}",
            serde_json::to_string(sel).expect("selection serialises"),
            checkpoint.display()
        ));
        let name = format!("means-{key:016x}.safetensors");
        let expected = [("means".to_string(), vec![classes, EMBEDDING])].into();
        let cached = crate::checkpoint::read_tensors(&cache.join(&name), &expected, device)
            .ok()
            .and_then(|mut t| t.remove("means"));
        if let Some(m) = cached {
            return Ok(m);
        }
        let mut sums = vec![vec![0f32; EMBEDDING]; classes];
        for chunk in idx.chunks(64) {
            let (x, _) = self.batch(chunk, device)?;
            let e: Vec<Vec<f32>> = embed(&x)?.to_vec2()?;
            for (&i, v) in chunk.iter().zip(e) {
                sums[self.labels[i] as usize].iter_mut().zip(v).for_each(|(s, x)| *s += x);
            }
        }
        let m = Tensor::from_vec(sums.concat(), (classes, EMBEDDING), device)?;
        // A cache that cannot be written only costs the next run this pass.
        let _ = crate::checkpoint::write_tensors(cache, &name, &[("means".to_string(), m.clone())].into());
        Ok(m)
    }

    /// Loads the set from `cache` if it was built for the same selection, else builds it
    /// (YuNet from `models`) and writes the cache (temporary file + rename).
    pub fn load_or_build(sel: &Selection, models: &Path, cache: &Path) -> Result<Self, FacesError> {
        let key = fnv(&serde_json::to_string(sel).expect("selection serialises"));
        let file = cache.join(format!("faces-{key:016x}.bin"));
        // A regular file of at most every LFW photo's crop and its index; anything else
        // (a FIFO, a link to a device, a sparse giant) is not read and the set is rebuilt.
        if let Ok(bytes) = campro::file::read_capped(&file, MAX_CACHE_BYTES, "a face cache") {
            if let Some(set) = Self::decode(&bytes, sel) {
                return Ok(set);
            }
        }
        let set = Self::build(sel, models)?;
        campro::file::atomic::write(&file, &set.encode(sel), true)
            .map_err(|e| FacesError::Cache { path: file.clone(), message: e.to_string() })?;
        Ok(set)
    }

    fn encode(&self, sel: &Selection) -> Vec<u8> {
        let idx = Index {
            selection: sel.clone(),
            classes: self.classes.clone(),
            validation: self.validation.clone(),
            labels: self.labels.clone(),
            check: self.check.clone(),
            skipped: self.skipped,
        };
        let json = serde_json::to_vec(&idx).expect("index serialises");
        let mut out = (json.len() as u64).to_le_bytes().to_vec();
        out.extend(json);
        out.extend(&self.crops);
        out
    }

    /// None when the cache is stale, truncated or not ours (it is then rebuilt).
    fn decode(bytes: &[u8], sel: &Selection) -> Option<Self> {
        let n = u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?) as usize;
        let idx: Index = serde_json::from_slice(bytes.get(8..8usize.checked_add(n)?)?).ok()?;
        let crops = bytes.get(8 + n..)?.to_vec();
        let ok = idx.selection == *sel
            && crops.len() == idx.labels.len() * CROP.0 * CROP.1 * 3
            && idx.check.len() == idx.labels.len()
            && idx.labels.iter().all(|&l| (l as usize) < idx.classes.len());
        ok.then_some(Self {
            classes: idx.classes,
            validation: idx.validation,
            labels: idx.labels,
            check: idx.check,
            crops,
            skipped: idx.skipped,
        })
    }

    fn build(sel: &Selection, models: &Path) -> Result<Self, FacesError> {
        let lfw = Lfw::open(&sel.lfw)?;
        let mut names: Vec<&String> = lfw
            .people
            .iter()
            .filter(|(k, v)| v.len() >= sel.min_images && !sel.exclude.contains(k))
            .map(|(k, _)| k)
            .collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(sel.seed);
        names.shuffle(&mut rng);
        if let Some(m) = sel.max_identities {
            names.truncate(m);
        }
        let n_val = (names.len() as f64 * sel.validation_identities).round() as usize;
        let validation: Vec<String> = names[..n_val].iter().map(|s| s.to_string()).collect();
        let mut classes: Vec<String> = names[n_val..].iter().map(|s| s.to_string()).collect();
        classes.sort();
        if classes.len() < 2 {
            return Err(FacesError::Data(format!(
                "{}: only {} identities with ≥ {} photos after the validation split",
                sel.lfw.display(),
                classes.len(),
                sel.min_images
            )));
        }
        let det = FaceDetector::new(Model::load(Manifest::parse(YUNET, Path::new("bundled yunet.json"), models)?)?)?;
        let Task::FaceEmbedder { template, .. } =
            Manifest::parse(MOBILEFACENET, Path::new("bundled mobilefacenet_casia.json"), models)?.task
        else {
            unreachable!("the bundled manifest is an embedder")
        };
        let template = template.map(|p| p.map(f64::from));
        let jobs: Vec<(u32, &PathBuf)> = classes
            .iter()
            .enumerate()
            .flat_map(|(c, name)| lfw.people[name].iter().map(move |p| (c as u32, p)))
            .collect();
        let crops: Vec<Option<(u32, Vec<u8>)>> = jobs
            .par_iter()
            .map(|&(c, p)| -> Result<Option<(u32, Vec<u8>)>, FacesError> {
                let img = read_rgb8(p)?;
                let Some(f) = central_face(&det.detect(&img)?, img.width(), img.height()) else { return Ok(None) };
                let m = similarity(&f.landmarks.map(|q| q.map(f64::from)), &template);
                Ok(warp_affine(&img, &m, CROP.1 as u32, CROP.0 as u32).map(|crop| (c, crop.into_raw())))
            })
            .collect::<Result<_, _>>()?;
        let skipped = crops.iter().filter(|c| c.is_none()).count();
        let kept: Vec<(u32, Vec<u8>)> = crops.into_iter().flatten().collect();
        // The last kept photo of each class is its check photo.
        let check: Vec<bool> =
            (0..kept.len()).map(|i| kept.get(i + 1).is_none_or(|next| next.0 != kept[i].0)).collect();
        Ok(Self {
            classes,
            validation,
            labels: kept.iter().map(|k| k.0).collect(),
            check,
            crops: kept.into_iter().flat_map(|k| k.1).collect(),
            skipped,
        })
    }
}

/// FNV-1a, 64 bits: names the cache file of a selection.
pub(crate) fn fnv(s: &str) -> u64 {
    s.bytes().fold(0xcbf29ce484222325, |h, b| (h ^ b as u64).wrapping_mul(0x100000001b3))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_is_the_evaluations_luma_before_flooring() {
        // Two pixels: pure red and (10, 20, 30); channels first.
        let px = [[255u8, 0, 0], [10, 20, 30]];
        let data: Vec<f32> = (0..3).flat_map(|c| px.iter().map(move |p| p[c] as f32 / 255.0)).collect();
        let x = Tensor::from_vec(data, (1, 3, 1, 2), &Device::Cpu).unwrap();
        let g = grey(&x).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        // By hand: 77·255/256 = 76.70 (the integer luma floors to 76); (770 + 3000 + 870)
        // / 256 = 18.125 (18). Every channel the same.
        let want = [76.699_22f32, 18.125];
        for c in 0..3 {
            for (k, w) in want.iter().enumerate() {
                assert!((g[c * 2 + k] * 255.0 - w).abs() < 1e-3, "channel {c}, pixel {k}: {}", g[c * 2 + k] * 255.0);
                assert_eq!((g[c * 2 + k] * 255.0 + 1e-3).floor() as u8, campro::chroma::luma(px[k]));
            }
        }
    }
}
