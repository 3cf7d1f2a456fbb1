//! The enhancer's face-privacy term ([`crate::config::FacePrivacyConfig`]).
//!
//! The paper's masked loss only leaves the faces unasked; a U-Net that cannot tell a face
//! from the rest of a scene then restores faces with everything else (docs/enhancer.md: the
//! squared-error enhancer's faces scored above the per-pixel restoration). This term asks it
//! outright: aligned LFW faces of identities the preset trained on go through the camera
//! (the paper's order: aligned, then captured), the restoration table and the U-Net, and
//! each costs `max(0, cos(e, m_y) − max_{c ≠ y} cos(e, m_c) + margin)`: `e` the white-box
//! MobileFaceNet's unit embedding of the enhanced face (frozen, batch norm in evaluation
//! mode), `m_c` the raw faces' class means over every training identity, `y` its own. That is
//! the evaluation's gallery attacker (nearest class mean by cosine), asked to rank the face's
//! own identity below another by `margin`; a face already that far below costs nothing.
//! Away-from-raw alone would not do: the captured faces' cosine to their raw ones is already
//! about 0.02 on average, yet they are identified above chance, and the camera optimiser's
//! `−log(1 − p_y)` is flat there (p_y ≈ 1/classes). The preset's held-out identities are left
//! out before any photo //! is read.

use crate::config::FacePrivacyConfig;
use crate::error::TrainError;
use crate::faces::{FaceSet, Selection, CROP};
use crate::unet::Unet;
use campro::pipeline::fast::Exact8;
use campro_nn::mobilefacenet::{l2_normalise, MobileFaceNet};
use candle_core::{Device, Tensor};
use image::RgbImage;
use rand::Rng;
use std::path::Path;

/// Where the faces come from: the enhancer's LFW folder and caches.
pub struct FaceSource<'p> {
    pub lfw: &'p Path,
    pub models: &'p Path,
    pub cache: &'p Path,
    /// LFW identities never read (the preset's held-out ones).
    pub held_out: &'p [String],
    pub seed: u64,
}

/// The faces, the camera and the frozen face model the term needs.
pub struct FacePrivacy<'a> {
    cfg: FacePrivacyConfig,
    faces: FaceSet,
    train: Vec<usize>,
    check: Vec<usize>,
    net: MobileFaceNet,
    /// Unit class means of the raw training faces' embeddings (classes, 128).
    means: Tensor,
    camera: Exact8<'a>,
    table: Option<campro_eval::restore::Table>,
}

/// One step's term and how many of its faces the nearest class mean identified.
pub struct Term {
    /// `weight · mean(max(0, cos_y − max_{c ≠ y} cos_c + margin))`, differentiable in the
    /// U-Net's weights.
    pub loss: Tensor,
    /// Fraction of the step's enhanced faces whose nearest class mean is their own (0..1).
    pub top1: f64,
}

impl<'a> FacePrivacy<'a> {
    /// Aligns (or reads from the cache) every photo of the identities with at least
    /// `cfg.min_images` photos outside `src.held_out`; `table`: the enhancer's restoration
    /// stage, if any.
    pub fn load(
        cfg: &FacePrivacyConfig,
        src: &FaceSource,
        params: &'a campro::Params,
        table: Option<campro_eval::restore::Table>,
        dev: &Device,
    ) -> Result<Self, TrainError> {
        let sel = Selection {
            lfw: src.lfw.to_path_buf(),
            min_images: cfg.min_images,
            validation_identities: 0.0,
            max_identities: cfg.max_identities,
            seed: src.seed,
            exclude: src.held_out.to_vec(),
        };
        let faces = FaceSet::load_or_build(&sel, src.models, src.cache)?;
        if let Some(name) = faces.classes.iter().find(|c| src.held_out.contains(c)) {
            return Err(TrainError::Unsupported(format!(
                "privacy: {name} is a held-out identity (a stale face cache?)"
            )));
        }
        let (train, mut check) = faces.split();
        check.truncate(cfg.validation_faces);
        let (net, _) = MobileFaceNet::from_checkpoint(&cfg.checkpoint, dev)?;
        let net = net.frozen();
        let means = l2_normalise(&faces.class_means(
            &train,
            &sel,
            &cfg.checkpoint,
            src.cache,
            |x| net.embed(x, false),
            dev,
        )?)?;
        Ok(Self { cfg: cfg.clone(), faces, train, check, net, means, camera: Exact8::new(params), table })
    }

    /// Training faces (each identity's photos but its last).
    pub fn train_faces(&self) -> usize {
        self.train.len()
    }

    /// Identities the faces come from.
    pub fn identities(&self) -> usize {
        self.faces.classes.len()
    }

    /// The U-Net's input (camera, then the restoration table) of crops `idx` (flipped
    /// left-right where `flip` says), (B, 3, 112, 96) in [0, 1].
    /// The U-Net's inputs and the captured faces of crops `idx`, each flipped or not.
    fn inputs(&self, idx: &[usize], flip: &[bool], dev: &Device) -> Result<(Tensor, Tensor), TrainError> {
        let (h, w) = CROP;
        let n = h * w * 3;
        let (mut inp, mut cap) = (Vec::with_capacity(idx.len() * n), Vec::with_capacity(idx.len() * n));
        for (&i, &f) in idx.iter().zip(flip) {
            let bytes = self.faces.crops[i * n..(i + 1) * n].to_vec();
            let mut x = RgbImage::from_raw(w as u32, h as u32, bytes).expect("a whole crop");
            if f {
                image::imageops::flip_horizontal_in_place(&mut x);
            }
            let mut captured = RgbImage::new(w as u32, h as u32);
            self.camera.run(x.as_raw(), &mut captured);
            if let Some(t) = &self.table {
                crate::scenes::push_chw(&t.apply(&captured), &mut inp);
            }
            crate::scenes::push_chw(&captured, &mut cap);
        }
        let cap = Tensor::from_vec(cap, (idx.len(), 3, h, w), dev)?;
        let inp = if self.table.is_some() { Tensor::from_vec(inp, (idx.len(), 3, h, w), dev)? } else { cap.clone() };
        Ok((inp, cap))
    }

    /// Cosines (B, classes) to the class means of (B, 3, 112, 96) images in [0, 1] (clamped
    /// first, as 8-bit output is), and the crops' labels (B,).
    fn logits(&self, x: &Tensor, idx: &[usize], dev: &Device) -> candle_core::Result<(Tensor, Tensor)> {
        let e = self.net.embed(&x.clamp(0f32, 1f32)?, false)?;
        let y = Tensor::from_vec(idx.iter().map(|&i| self.faces.labels[i]).collect::<Vec<u32>>(), idx.len(), dev)?;
        Ok((e.matmul(&self.means.t()?)?, y))
    }

    /// The term on `self.cfg.faces` training faces drawn with `rng` (`order`: the draw's
    /// running permutation, see [`crate::train::draw`]).
    pub fn term(
        &self,
        unet: &Unet,
        order: &mut Vec<usize>,
        rng: &mut rand_chacha::ChaCha8Rng,
        dev: &Device,
    ) -> Result<Term, TrainError> {
        let idx = crate::train::draw(order, &self.train, self.cfg.faces, rng);
        let flip: Vec<bool> = idx.iter().map(|_| rng.random_bool(0.5)).collect();
        let (input, captured) = self.inputs(&idx, &flip, dev)?;
        let (logits, y) = self.logits(&unet.forward_gated(&input, &captured)?.0, &idx, dev)?;
        let top1 = hits(&logits, &y)? as f64 / idx.len() as f64;
        Ok(Term { loss: (rank_hinge(&logits, &y, self.cfg.margin)? * self.cfg.weight)?, top1 })
    }

    /// Top-1 of the nearest class mean (0..1) over the check faces (each training identity's
    /// last photo, never drawn for the term nor in the means) of the enhanced face and of the
    /// U-Net's input; None without check faces.
    pub fn validate(&self, unet: &Unet, dev: &Device) -> Result<Option<(f64, f64)>, TrainError> {
        if self.check.is_empty() {
            return Ok(None);
        }
        let (mut enhanced, mut input) = (0, 0);
        for chunk in self.check.chunks(32) {
            let (x, c) = self.inputs(chunk, &vec![false; chunk.len()], dev)?;
            let (l, y) = self.logits(&unet.forward_gated(&x, &c)?.0, chunk, dev)?;
            enhanced += hits(&l, &y)?;
            let (l, y) = self.logits(&x, chunk, dev)?;
            input += hits(&l, &y)?;
        }
        let n = self.check.len() as f64;
        Ok(Some((enhanced as f64 / n, input as f64 / n)))
    }
}

/// `mean(max(0, cos[i, y_i] − max_{c ≠ y_i} cos[i, c] + margin))` over the rows of `cos`
/// (B, classes), `y` (B,) the labels.
pub fn rank_hinge(cos: &Tensor, y: &Tensor, margin: f64) -> candle_core::Result<Tensor> {
    let onehot = candle_nn::encoding::one_hot(y.clone(), cos.dim(1)?, 1f32, 0f32)?;
    let own = (cos * &onehot)?.sum(1)?;
    // The label's own entry pushed below every cosine (≥ −1) before the maximum.
    let best_other = (cos - (onehot * 4.0)?)?.max(1)?;
    ((own - best_other)? + margin)?.relu()?.mean_all()
}

/// How many rows of `logits` (B, classes) are largest at their label `y` (B,).
fn hits(logits: &Tensor, y: &Tensor) -> candle_core::Result<usize> {
    let best: Vec<u32> = logits.argmax(1)?.to_vec1()?;
    let y: Vec<u32> = y.to_vec1()?;
    Ok(best.iter().zip(&y).filter(|(a, b)| a == b).count())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rank_hinge_by_hand() {
        let dev = Device::Cpu;
        let cos = candle_core::Var::from_vec(vec![0.5f32, 0.2, 0.1, 0.0, 0.3, 0.1], (2, 3), &dev).unwrap();
        let y = Tensor::new(&[0u32, 2], &dev).unwrap();
        // Row 0: 0.5 − 0.2 + 0.1 = 0.4; row 1: 0.1 − 0.3 + 0.1 < 0, free. Mean 0.2.
        let l = rank_hinge(cos.as_tensor(), &y, 0.1).unwrap();
        assert!((l.to_scalar::<f32>().unwrap() - 0.2).abs() < 1e-6);
        // The gradient lowers the own class and raises the best other, of row 0 only.
        let g: Vec<Vec<f32>> = l.backward().unwrap().get(&cos).unwrap().to_vec2().unwrap();
        assert_eq!(g, vec![vec![0.5, -0.5, 0.0], vec![0.0, 0.0, 0.0]]);
        // With no margin and the own class already below, nothing is asked.
        let l = rank_hinge(cos.as_tensor(), &Tensor::new(&[2u32, 0], &dev).unwrap(), 0.0).unwrap();
        assert_eq!(l.to_scalar::<f32>().unwrap(), 0.0);
    }
}
