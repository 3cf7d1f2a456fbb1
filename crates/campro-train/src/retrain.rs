//! The re-training attack of the paper's Sec. VII (its Table VI, "Finetune, Softmax"): a
//! face-recognition model fine-tuned on protected faces of identities the attacker labelled
//! itself, then used to identify others. The model is read from its ONNX file into an
//! [`OnnxNet`] (every convolution and PReLU trainable; the shared models have batch norm
//! folded). A Softmax head over the embedding, imprinted with the identities' mean
//! embeddings, learns the training identities; SGD with momentum, weight decay and a
//! clipped gradient norm takes the steps, with the paper's schedule (rate `lr` for the
//! first three quarters of the epochs, `lr / 10` after). The head is dropped and the
//! network written back as ONNX, so the evaluation runs the fine-tuned file.

use crate::error::{Result, TrainError};
use campro_eval::manifest::{Channels, Input};
use campro_nn::onnx_net::OnnxNet;
use candle_core::{DType, Device, Tensor, Var, D};
use image::RgbImage;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::path::Path;

/// How to fine-tune.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RetrainConfig {
    /// Passes over the training faces (the paper: 20).
    pub epochs: usize,
    /// Faces per step.
    pub batch: usize,
    /// SGD rate of the first three quarters of the epochs, then a tenth. The paper's 0.1
    /// diverged here (the shared models have batch norm folded: loss 4.7, 14.8, 107 over
    /// the first three epochs of MobileFaceNet on 100 identities), and 0.01 did within an
    /// epoch for faceplugin on 1,177 identities; hence 0.003.
    pub lr: f64,
    pub momentum: f64,
    /// L2 weight decay added to each gradient (the paper: 5e-4).
    pub weight_decay: f64,
    /// The gradient's global L2 norm is scaled down to at most this. The shared models have
    /// batch norm folded into their convolutions, so nothing holds the activations' scale:
    /// unclipped, ArcFace's scaled logits blew MobileFaceNet up within an epoch at 0.01.
    pub clip: f64,
    /// Seed of the head's initial weights and of the face order.
    pub seed: u64,
    pub loss: Loss,
}

/// The classification loss of the head (the paper re-trains with both).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Loss {
    /// A linear classifier (weights and biases) over the raw embedding, cross-entropy.
    Softmax,
    /// ArcFace (Deng et al. 2019): embeddings and class weights L2-normalised, the target
    /// class's angle widened by `margin` radians, logits scaled by `scale` (64 and 0.5 as
    /// there), cross-entropy.
    ArcFace { scale: f64, margin: f64 },
}

impl Loss {
    /// ArcFace with its paper's scale 64 and margin 0.5.
    pub const ARCFACE: Loss = Loss::ArcFace { scale: 64.0, margin: 0.5 };
}

impl Default for RetrainConfig {
    fn default() -> Self {
        Self {
            epochs: 20,
            batch: 32,
            lr: 0.01,
            momentum: 0.9,
            weight_decay: 5e-4,
            clip: 5.0,
            seed: 0,
            loss: Loss::Softmax,
        }
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
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
    let head_w = Var::from_tensor(&imprint(&net, input, samples, classes, cfg, dev)?)?;
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
            // A non-finite embedding is divergence even where a clamp hides it from the loss.
            let e = emb.sqr()?.sum_all()?.to_scalar::<f32>()?;
            if !e.is_finite() {
                return Err(TrainError::Diverged(format!("re-training embedding {e} at epoch {}", epoch + 1)));
            }
            let logits = head_logits(&emb, &head_w, &head_b, &labels, cfg.loss)?;
            let target = Tensor::from_vec(labels.clone(), labels.len(), dev)?;
            let loss = candle_nn::loss::cross_entropy(&logits, &target)?;
            let l = loss.to_scalar::<f32>()? as f64;
            if !l.is_finite() {
                return Err(TrainError::Diverged(format!("re-training loss {l} at epoch {}", epoch + 1)));
            }
            let pred: Vec<u32> = logits.argmax(D::Minus1)?.to_vec1()?;
            right += pred.iter().zip(&labels).filter(|(a, b)| a == b).count();
            let grads = loss.backward()?;
            let mut norm2 = 0f64;
            for v in &vars {
                if let Some(g) = grads.get(v) {
                    norm2 += g.sqr()?.sum_all()?.to_scalar::<f32>()? as f64;
                }
            }
            let shrink = (cfg.clip / norm2.sqrt()).min(1.0);
            for (v, buf) in vars.iter().zip(velocity.iter_mut()) {
                let Some(g) = grads.get(v) else { continue };
                let g = ((g * shrink)? + (v.as_tensor() * cfg.weight_decay)?)?;
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

/// The head's starting weights, imprinted (Qi et al. 2018): each class's row is the mean
/// of its faces' unit embeddings by the unchanged network, normalised, so the head
/// classifies from the first step and its gradient does not have to drag the backbone
/// through a random start. For Softmax the rows are scaled so that a face's logit for its
/// own class is about 10 times its cosine to the class mean (`10 / mean |embedding|`).
fn imprint(
    net: &OnnxNet,
    input: &Input,
    samples: &[Sample],
    classes: usize,
    cfg: &RetrainConfig,
    dev: &Device,
) -> Result<Tensor> {
    let (mut sums, mut norm_sum): (Option<Vec<f32>>, f64) = (None, 0.0);
    for chunk in samples.chunks(cfg.batch) {
        let crops: Vec<&RgbImage> = chunk.iter().map(|s| &s.crop).collect();
        let emb: Vec<Vec<f32>> = net.forward(&input_tensor(&crops, input, dev)?)?.flatten_from(1)?.to_vec2()?;
        for (e, s) in emb.iter().zip(chunk) {
            let n = e.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
            norm_sum += n as f64;
            let dim = e.len();
            let acc = sums.get_or_insert_with(|| vec![0f32; classes * dim]);
            for (a, v) in acc[s.label * dim..(s.label + 1) * dim].iter_mut().zip(e) {
                *a += v / n;
            }
        }
    }
    let mut w = sums.unwrap_or_default();
    let dim = w.len() / classes;
    let scale = match cfg.loss {
        Loss::Softmax => (10.0 / (norm_sum / samples.len() as f64)) as f32,
        Loss::ArcFace { .. } => 1.0,
    };
    for row in w.chunks_mut(dim) {
        let n = row.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
        row.iter_mut().for_each(|v| *v *= scale / n);
    }
    Ok(Tensor::from_vec(w, (classes, dim), dev)?)
}

/// The head's logits (B, classes) for embeddings `emb` (B, D) under `loss`; ArcFace needs
/// the batch's `labels` (its margin applies to the target class only).
fn head_logits(emb: &Tensor, w: &Var, b: &Var, labels: &[u32], loss: Loss) -> Result<Tensor> {
    match loss {
        Loss::Softmax => Ok(emb.matmul(&w.as_tensor().t()?)?.broadcast_add(b.as_tensor())?),
        Loss::ArcFace { scale, margin } => {
            let unit = |x: &Tensor| -> candle_core::Result<Tensor> {
                x.broadcast_div(&x.sqr()?.sum_keepdim(D::Minus1)?.sqrt()?.clamp(1e-12, f64::INFINITY)?)
            };
            let cos = unit(emb)?.matmul(&unit(w.as_tensor())?.t()?)?.clamp(-1.0, 1.0)?;
            let sin = (1.0 - cos.sqr()?)?.clamp(0.0, 1.0)?.sqrt()?;
            // cos(θ + m); past θ = π − m, where that stops decreasing, cos θ − m·sin m
            // (InsightFace's fallback, keeping the target logit monotone in θ).
            let (cm, sm) = (margin.cos(), margin.sin());
            let widened = ((&cos * cm)? - (&sin * sm)?)?;
            let fallback = (&cos - margin * sm)?;
            let past = cos.le((std::f64::consts::PI - margin).cos())?;
            let phi = past.where_cond(&fallback, &widened)?;
            let classes = cos.dim(1)?;
            let mut hot = vec![0u8; labels.len() * classes];
            for (i, &l) in labels.iter().enumerate() {
                hot[i * classes + l as usize] = 1;
            }
            let hot = Tensor::from_vec(hot, cos.shape(), cos.device())?;
            Ok((hot.where_cond(&phi, &cos)? * scale)?)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arcface_logits_by_hand() {
        let dev = Device::Cpu;
        // Embeddings along x and y (any length), classes along x and y.
        let emb = Tensor::from_vec(vec![3f32, 0.0, 0.0, 0.5], (2, 2), &dev).unwrap();
        let w = Var::from_vec(vec![2f32, 0.0, 0.0, 1.0], (2, 2), &dev).unwrap();
        let b = Var::zeros(2, DType::F32, &dev).unwrap();
        let logits = |labels: &[u32]| -> Vec<Vec<f32>> {
            head_logits(&emb, &w, &b, labels, Loss::ARCFACE).unwrap().to_vec2().unwrap()
        };
        let s = 64f32;
        // Face 0 of class 0 (θ = 0): its logit is s·cos 0.5; class 1 (θ = π/2): s·0.
        // Face 1 labelled class 0 (θ = π/2 from class 0): s·cos(π/2 + 0.5) = −s·sin 0.5.
        let got = logits(&[0, 0]);
        let want = [[s * 0.5f32.cos(), 0.0], [-s * 0.5f32.sin(), s]];
        for (g, w) in got.iter().flatten().zip(want.iter().flatten()) {
            assert!((g - w).abs() < 1e-4, "{got:?} against {want:?}");
        }
        // An embedding opposite its class (θ = π > π − m): the fallback cos θ − m·sin m.
        let emb = Tensor::from_vec(vec![-1f32, 0.0], (1, 2), &dev).unwrap();
        let got: Vec<Vec<f32>> = head_logits(&emb, &w, &b, &[0], Loss::ARCFACE).unwrap().to_vec2().unwrap();
        assert!((got[0][0] - s * (-1.0 - 0.5 * 0.5f32.sin())).abs() < 1e-3, "{got:?}");
        // Softmax is the linear classifier with its bias.
        let b = Var::from_vec(vec![1f32, -1.0], 2, &dev).unwrap();
        let got: Vec<Vec<f32>> = head_logits(&emb, &w, &b, &[0], Loss::Softmax).unwrap().to_vec2().unwrap();
        assert_eq!(got, vec![vec![-2.0 + 1.0, -1.0]]);
    }
}
