//! The re-training attack of the paper's Sec. VII (its Table VI, "Finetune, Softmax"): a
//! face-recognition model fine-tuned on protected faces of identities the attacker labelled
//! itself, then used to identify others. The model is read from its ONNX file into an
//! [`OnnxNet`] (every convolution and PReLU trainable; the shared models have batch norm
//! folded), a linear Softmax head over the embedding learns the training identities, and
//! SGD with momentum and weight decay takes the steps, with the paper's schedule: rate
//! `lr` for the first three quarters of the epochs, `lr / 10` after. The head is dropped
//! and the network written back as ONNX, so the evaluation runs the fine-tuned file.

use crate::error::{Result, TrainError};
use crate::onnx_net::OnnxNet;
use campro_eval::manifest::{Channels, Input};
use candle_core::{DType, Device, Tensor, Var, D};
use image::RgbImage;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_distr::Distribution;
use std::path::Path;

/// How to fine-tune.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RetrainConfig {
    /// Passes over the training faces (the paper: 20).
    pub epochs: usize,
    /// Faces per step.
    pub batch: usize,
    /// SGD rate of the first three quarters of the epochs (the paper: 0.1), then a tenth.
    pub lr: f64,
    pub momentum: f64,
    /// L2 weight decay added to each gradient (the paper: 5e-4).
    pub weight_decay: f64,
    /// Seed of the head's initial weights and of the face order.
    pub seed: u64,
}

impl Default for RetrainConfig {
    fn default() -> Self {
        Self { epochs: 20, batch: 32, lr: 0.1, momentum: 0.9, weight_decay: 5e-4, seed: 0 }
    }
}

/// A training face: a crop of the model's input size, and its identity (class index).
pub struct Sample {
    pub crop: RgbImage,
    pub label: usize,
}

/// What the fine-tuning did, per epoch.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RetrainLog {
    pub faces: usize,
    pub classes: usize,
    pub steps: usize,
    pub seconds: f64,
    /// Mean cross-entropy of each epoch's steps (before each step).
    pub epoch_loss: Vec<f64>,
    /// Share of each epoch's faces the head classified right (before each step).
    pub epoch_accuracy: Vec<f64>,
}

/// A batch of crops as the model's input tensor (B, 3, H, W): channels as the manifest
/// says, `(pixel − mean) / std`.
pub fn input_tensor(crops: &[&RgbImage], input: &Input, dev: &Device) -> Result<Tensor> {
    let (h, w) = (input.height, input.width);
    let mut v = Vec::with_capacity(crops.len() * 3 * h * w);
    for crop in crops {
        if (crop.width() as usize, crop.height() as usize) != (w, h) {
            return Err(TrainError::Unsupported(format!(
                "a {}x{} crop for a {w}x{h} model input",
                crop.width(),
                crop.height()
            )));
        }
        for c in 0..3 {
            let src = match input.channels {
                Channels::Rgb => c,
                Channels::Bgr => 2 - c,
            };
            v.extend(crop.pixels().map(|p| (p.0[src] as f32 - input.mean[c]) / input.std[c]));
        }
    }
    Ok(Tensor::from_vec(v, (crops.len(), 3, h, w), dev)?)
}

/// Fine-tunes the ONNX model at `model` (input as `input` says) to tell the `classes`
/// identities of `samples` apart. Returns the network (without the head) and its log.
pub fn fine_tune(
    model: &Path,
    input: &Input,
    samples: &[Sample],
    classes: usize,
    cfg: &RetrainConfig,
    dev: &Device,
) -> Result<(OnnxNet, RetrainLog)> {
    if samples.is_empty() || classes < 2 || cfg.batch == 0 || cfg.epochs == 0 {
        return Err(TrainError::Unsupported(format!(
            "re-training needs faces of at least 2 identities, a batch and an epoch ({} faces, {classes} identities)",
            samples.len()
        )));
    }
    if let Some(s) = samples.iter().find(|s| s.label >= classes) {
        return Err(TrainError::Unsupported(format!("a face of identity {} of {classes}", s.label)));
    }
    let start = std::time::Instant::now();
    let net = OnnxNet::load(model, dev)?;
    let dim = net.forward(&input_tensor(&[&samples[0].crop], input, dev)?)?.flatten_from(1)?.dim(1)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
    // The head starts small (N(0, 0.01²)), so the first steps do not wreck the backbone.
    let normal = rand_distr::Normal::new(0.0f32, 0.01).expect("valid");
    let init: Vec<f32> = (0..classes * dim).map(|_| normal.sample(&mut rng)).collect();
    let head_w = Var::from_vec(init, (classes, dim), dev)?;
    let head_b = Var::zeros(classes, DType::F32, dev)?;
    let mut vars = net.vars();
    vars.push(head_w.clone());
    vars.push(head_b.clone());
    let mut velocity: Vec<Tensor> =
        vars.iter().map(|v| v.as_tensor().zeros_like()).collect::<candle_core::Result<_>>()?;
    let mut order: Vec<usize> = (0..samples.len()).collect();
    let decay_at = (cfg.epochs * 3).div_ceil(4);
    let mut log = RetrainLog {
        faces: samples.len(),
        classes,
        steps: 0,
        seconds: 0.0,
        epoch_loss: Vec::new(),
        epoch_accuracy: Vec::new(),
    };
    for epoch in 0..cfg.epochs {
        let lr = if epoch < decay_at { cfg.lr } else { cfg.lr / 10.0 };
        order.shuffle(&mut rng);
        let (mut loss_sum, mut right, mut steps) = (0f64, 0usize, 0usize);
        for chunk in order.chunks(cfg.batch) {
            let crops: Vec<&RgbImage> = chunk.iter().map(|&i| &samples[i].crop).collect();
            let labels: Vec<u32> = chunk.iter().map(|&i| samples[i].label as u32).collect();
            let x = input_tensor(&crops, input, dev)?;
            let emb = net.forward(&x)?.flatten_from(1)?;
            let logits = emb.matmul(&head_w.as_tensor().t()?)?.broadcast_add(head_b.as_tensor())?;
            let target = Tensor::from_vec(labels.clone(), labels.len(), dev)?;
            let loss = candle_nn::loss::cross_entropy(&logits, &target)?;
            let l = loss.to_scalar::<f32>()? as f64;
            if !l.is_finite() {
                return Err(TrainError::Diverged(format!("re-training loss {l} at epoch {}", epoch + 1)));
            }
            let pred: Vec<u32> = logits.argmax(D::Minus1)?.to_vec1()?;
            right += pred.iter().zip(&labels).filter(|(a, b)| a == b).count();
            let grads = loss.backward()?;
            for (v, buf) in vars.iter().zip(velocity.iter_mut()) {
                let Some(g) = grads.get(v) else { continue };
                let g = (g + (v.as_tensor() * cfg.weight_decay)?)?;
                *buf = ((&*buf * cfg.momentum)? + g)?;
                v.set(&(v.as_tensor() - (&*buf * lr)?)?)?;
            }
            loss_sum += l;
            steps += 1;
        }
        log.steps += steps;
        log.epoch_loss.push(loss_sum / steps as f64);
        log.epoch_accuracy.push(right as f64 / samples.len() as f64);
        eprintln!(
            "re-training epoch {}/{}: loss {:.3}, training accuracy {:.3} ({:.0} s)",
            epoch + 1,
            cfg.epochs,
            loss_sum / steps as f64,
            right as f64 / samples.len() as f64,
            start.elapsed().as_secs_f64()
        );
    }
    log.seconds = start.elapsed().as_secs_f64();
    Ok((net, log))
}
