//! Training-step timings (`campro bench train`): the two network steps that
//! `../shared/anchors/torch_step.py` times in PyTorch (forward, sum of the output, backward,
//! batch norm in training mode) and the three players' steps of a round at a
//! configuration's shapes. Medians after one warm-up; inputs are seeded noise.

use crate::camera::Camera;
use crate::config::Config;
use crate::detection::yolox_loss;
use crate::persons::detector_input;
use campro_nn::mobilefacenet::{normalise_unit, MobileFaceNet, EMBEDDING};
use campro_nn::yolox::Yolox;
use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{linear, loss, AdamW, Optimizer, ParamsAdamW, VarBuilder, VarMap, SGD};
use std::path::Path;

/// Which steps to time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// MobileFaceNet, 8x3x112x96, forward + sum + backward (the anchor's shape).
    MobileFaceNet,
    /// YOLOX-Nano, 1x3x416x416, forward + sum + backward (the anchor's shape).
    Yolox,
    /// The attacker's step: C(x) detached, backbone + head, cross-entropy, SGD.
    Attacker,
    /// The protector's privacy step: L_ns through the frozen attacker into the camera, AdamW.
    Privacy,
    /// The protector's detector step: C(people) through YOLOX-Nano, L_det, backward, AdamW.
    Detector,
}

impl Step {
    /// Every step, in report order.
    pub const ALL: [Step; 5] = [Step::MobileFaceNet, Step::Yolox, Step::Attacker, Step::Privacy, Step::Detector];

    /// The JSON key of its median, in milliseconds.
    pub fn key(self) -> &'static str {
        match self {
            Step::MobileFaceNet => "mobilefacenet_8x112x96_ms",
            Step::Yolox => "yolox_nano_1x416_ms",
            Step::Attacker => "attacker_step_ms",
            Step::Privacy => "privacy_step_ms",
            Step::Detector => "detector_step_ms",
        }
    }
}

/// Median seconds of `runs` calls of `f` after one warm-up call.
pub fn median_secs(runs: usize, mut f: impl FnMut() -> crate::Result<()>) -> crate::Result<f64> {
    f()?;
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs.max(1) {
        let s = std::time::Instant::now();
        f()?;
        t.push(s.elapsed().as_secs_f64());
    }
    t.sort_by(f64::total_cmp);
    Ok(t[t.len() / 2])
}

/// Times `steps` with the models of `models` (the shared folder's `models/`) at `cfg`'s
/// face batch, person batch and size; (step, median milliseconds) in the order asked.
pub fn run(
    ctx: &campro_nn::Context,
    models: &Path,
    cfg: &Config,
    steps: &[Step],
    runs: usize,
) -> crate::Result<Vec<(Step, f64)>> {
    let dev = ctx.device.clone();
    let mut out = Vec::new();
    let needs_mfn = steps.iter().any(|s| matches!(s, Step::MobileFaceNet | Step::Attacker | Step::Privacy));
    let needs_yolox = steps.iter().any(|s| matches!(s, Step::Yolox | Step::Detector));
    let mfn = if needs_mfn {
        Some(MobileFaceNet::from_checkpoint(&models.join("mobilefacenet_casia_068.ckpt"), &dev)?)
    } else {
        None
    };
    let det = if needs_yolox { Some(Yolox::load(&models.join("yolox_nano.onnx"), &dev)?) } else { None };
    let cam = Camera::identity(cfg.camera.knots, cfg.camera.per_channel, cfg.camera.gamma, &dev)?;
    let fb = cfg.data.batch;
    for &step in steps {
        let ms = 1e3
            * match step {
                Step::MobileFaceNet => {
                    let (net, _) = mfn.as_ref().expect("loaded");
                    let x = seeded(&[8, 3, 112, 96], 1.0, 1, &dev)?;
                    median_secs(runs, || {
                        net.forward_t(&normalise_unit(&x)?, true)?.sum_all()?.backward()?;
                        Ok(())
                    })?
                }
                Step::Yolox => {
                    let det = det.as_ref().expect("loaded");
                    let x = seeded(&[1, 3, 416, 416], 255.0, 2, &dev)?;
                    median_secs(runs, || {
                        det.forward(&x)?.sum_all()?.backward()?;
                        Ok(())
                    })?
                }
                Step::Attacker | Step::Privacy => {
                    let (net, vm) = mfn.as_ref().expect("loaded");
                    let head_vm = VarMap::new();
                    let head = linear(EMBEDDING, 250, VarBuilder::from_varmap(&head_vm, DType::F32, &dev).pp("head"))?;
                    let x = seeded(&[fb, 3, 112, 96], 1.0, 3, &dev)?;
                    let y = Tensor::from_vec((0..fb as u32).map(|i| i % 250).collect::<Vec<u32>>(), fb, &dev)?;
                    if step == Step::Attacker {
                        let mut all = MobileFaceNet::trainable(vm);
                        all.extend(head_vm.all_vars());
                        let mut sgd = SGD::new(all, 1e-4)?;
                        median_secs(runs, || {
                            let e = net.embed(&cam.forward(&x)?.detach(), false)?;
                            sgd.step(&loss::cross_entropy(&head.forward(&e)?, &y)?.backward()?)?;
                            Ok(())
                        })?
                    } else {
                        let net = net.frozen();
                        let mut adam =
                            AdamW::new(cam.vars(), ParamsAdamW { lr: 1e-6, weight_decay: 0.0, ..Default::default() })?;
                        median_secs(runs, || {
                            let e = net.embed(&cam.forward(&x)?, false)?;
                            adam.step(&crate::train::non_saturating_loss(&head.forward(&e)?, &y)?.backward()?)?;
                            Ok(())
                        })?
                    }
                }
                Step::Detector => {
                    let det = det.as_ref().expect("loaded");
                    let (pb, size) = (cfg.detector.batch, cfg.detector.size);
                    let mut adam =
                        AdamW::new(cam.vars(), ParamsAdamW { lr: 1e-6, weight_decay: 0.0, ..Default::default() })?;
                    let mut adam_det =
                        AdamW::new(det.vars(), ParamsAdamW { lr: 1e-7, weight_decay: 0.0, ..Default::default() })?;
                    let people = seeded(&[pb, 3, size, size], 1.0, 4, &dev)?;
                    let mask = Tensor::ones((pb, 1, size, size), DType::F32, &dev)?;
                    let s = size as f32;
                    let boxes: Vec<Vec<[f32; 4]>> = (0..pb)
                        .map(|i| {
                            vec![
                                [s * 0.5, s * 0.5, s * 0.3, s * 0.6],
                                [s * 0.2, s * 0.3, s * 0.1, s * (0.2 + 0.05 * i as f32)],
                            ]
                        })
                        .collect();
                    median_secs(runs, || {
                        let head = det.forward(&detector_input(&cam.forward(&people)?, &mask)?)?;
                        let (l, _) = yolox_loss(&head, size, size, &boxes)?;
                        let g = l.backward()?;
                        adam.step(&g)?;
                        adam_det.step(&g)?;
                        Ok(())
                    })?
                }
            };
        out.push((step, ms));
    }
    Ok(out)
}

/// Uniform noise in [0, scale) from a fixed seed (the same inputs on every run).
fn seeded(shape: &[usize], scale: f32, seed: u64, dev: &Device) -> candle_core::Result<Tensor> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n: usize = shape.iter().product();
    let v: Vec<f32> = (0..n).map(|_| rng.random::<f32>() * scale).collect();
    Tensor::from_vec(v, shape, dev)
}

/// Median seconds of one enhancer training step (forward, [`crate::enhancer::step_loss`]
/// with `cfg`'s loss, gate and SSIM term, backward, AdamW) on `cfg.data.batch` seeded
/// `cfg.data.crop`-pixel crops, for a U-Net of `cfg.model`.
pub fn enhancer_step(ctx: &campro_nn::Context, cfg: &crate::config::EnhancerConfig, runs: usize) -> crate::Result<f64> {
    let dev = ctx.device.clone();
    let unet = crate::unet::Unet::new(&cfg.model, 1, &dev)?;
    let mut adam = AdamW::new(unet.vars(), ParamsAdamW { lr: 3e-4, weight_decay: 1e-2, ..Default::default() })?;
    let (batch, crop) = (cfg.data.batch, cfg.data.crop);
    let input = seeded(&[batch, 3, crop, crop], 1.0, 2, &dev)?;
    let b = crate::scenes::SceneBatch {
        captured: input.clone(),
        input,
        raw: seeded(&[batch, 3, crop, crop], 1.0, 3, &dev)?,
        keep: seeded(&[batch, 1, crop, crop], 1.0, 4, &dev)?.ge(0.1)?.to_dtype(DType::F32)?,
    };
    median_secs(runs, || {
        let (loss, _) = crate::enhancer::step_loss(&unet, cfg, &b)?;
        adam.step(&loss.backward()?)?;
        Ok(())
    })
}
