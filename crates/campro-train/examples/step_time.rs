//! Times the players' training steps on this machine (median of 5 after one warm-up):
//! `cargo run --release -p campro-train --example step_time -- MODELS_DIR [FACE_BATCH] [PERSON_BATCH] [SIZE]`.
//!
//! - attacker: MobileFaceNet + head forward/backward and an SGD step on C(x);
//! - privacy: the protector's L_ns through the frozen attacker into the camera;
//! - detector: C(people) through YOLOX-Nano, L_det (SimOTA), backward into camera and P;
//! - each network alone at the shapes `tools/framework-step` times in burn.

use campro_train::camera::Camera;
use campro_train::detection::yolox_loss;
use campro_train::mobilefacenet::{l2_normalise, normalise_unit, MobileFaceNet, EMBEDDING};
use campro_train::persons::detector_input;
use campro_train::yolox::Yolox;
use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{linear, loss, AdamW, Optimizer, ParamsAdamW, VarBuilder, VarMap, SGD};
use std::path::PathBuf;

fn median(mut f: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<f64> {
    f()?;
    let mut t: Vec<f64> = (0..5)
        .map(|_| {
            let s = std::time::Instant::now();
            f().map(|_| s.elapsed().as_secs_f64())
        })
        .collect::<anyhow::Result<_>>()?;
    t.sort_by(f64::total_cmp);
    Ok(t[2])
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let models = PathBuf::from(args.next().unwrap_or_else(|| "../shared/models".into()));
    let fb: usize = args.next().map_or(Ok(16), |b| b.parse())?;
    let pb: usize = args.next().map_or(Ok(4), |b| b.parse())?;
    let size: usize = args.next().map_or(Ok(320), |b| b.parse())?;
    let dev = Device::Cpu;
    let (net, vm) = MobileFaceNet::from_checkpoint(&models.join("mobilefacenet_casia_068.ckpt"), &dev)?;
    let head_vm = VarMap::new();
    let head = linear(EMBEDDING, 250, VarBuilder::from_varmap(&head_vm, DType::F32, &dev).pp("head"))?;
    let cam = Camera::identity(32, 2.2, &dev)?;
    let x = Tensor::rand(0f32, 1f32, (fb, 3, 112, 96), &dev)?;
    let y = Tensor::arange(0u32, fb as u32, &dev)?;
    let mut all = MobileFaceNet::trainable(&vm);
    all.extend(head_vm.all_vars());
    let mut sgd = SGD::new(all, 0.01)?;
    let mut adam = AdamW::new(cam.vars(), ParamsAdamW { lr: 1e-3, weight_decay: 0.0, ..Default::default() })?;
    let attacker = median(|| {
        let e = l2_normalise(&net.forward_t(&normalise_unit(&cam.forward(&x)?.detach())?, false)?)?;
        sgd.step(&loss::cross_entropy(&head.forward(&e)?, &y)?.backward()?)?;
        Ok(())
    })?;
    let privacy = median(|| {
        let e = l2_normalise(&net.forward_t(&normalise_unit(&cam.forward(&x)?)?, false)?)?;
        adam.step(&campro_train::train::non_saturating_loss(&head.forward(&e)?, &y)?.backward()?)?;
        Ok(())
    })?;
    let det = Yolox::load(&models.join("yolox_nano.onnx"), &dev)?;
    let mut adam_det = AdamW::new(det.vars(), ParamsAdamW { lr: 1e-5, weight_decay: 0.0, ..Default::default() })?;
    let people = Tensor::rand(0f32, 1f32, (pb, 3, size, size), &dev)?;
    let mask = Tensor::ones((pb, 1, size, size), DType::F32, &dev)?;
    let s = size as f32;
    let boxes: Vec<Vec<[f32; 4]>> = (0..pb)
        .map(|i| vec![[s * 0.5, s * 0.5, s * 0.3, s * 0.6], [s * 0.2, s * 0.3, s * 0.1, s * (0.2 + 0.05 * i as f32)]])
        .collect();
    let detector = median(|| {
        let head = det.forward(&detector_input(&cam.forward(&people)?, &mask)?)?;
        let (l, _) = yolox_loss(&head, size, size, &boxes)?;
        let g = l.backward()?;
        adam.step(&g)?;
        adam_det.step(&g)?;
        Ok(())
    })?;
    // The shapes of tools/framework-step (burn): sum of the output, backward, no update.
    let x416 = Tensor::rand(0f32, 255f32, (1, 3, 416, 416), &dev)?;
    let yolox_416 = median(|| {
        let _ = det.forward(&x416)?.sum_all()?.backward()?;
        Ok(())
    })?;
    let mfn_8 = Tensor::rand(0f32, 1f32, (8, 3, 112, 96), &dev)?;
    let mfn_step = median(|| {
        let _ = net.forward_t(&normalise_unit(&mfn_8)?, false)?.sum_all()?.backward()?;
        Ok(())
    })?;
    println!("threads {}", rayon::current_num_threads());
    println!("YOLOX-Nano 1x416x416 forward + backward of the output sum: {:.0} ms", yolox_416 * 1e3);
    println!("MobileFaceNet 8x112x96 forward + backward of the output sum: {:.0} ms", mfn_step * 1e3);
    println!("attacker step, {fb} faces: {:.0} ms", attacker * 1e3);
    println!("privacy step, {fb} faces: {:.0} ms", privacy * 1e3);
    println!("detector step, {pb} people at {size}: {:.0} ms", detector * 1e3);
    Ok(())
}
