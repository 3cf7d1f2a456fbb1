//! Times one attacker step and one protector step of the face player on this machine:
//! `cargo run --release -p campro-train --example step_time -- CKPT [BATCH]`.

use campro_train::camera::Camera;
use campro_train::mobilefacenet::{l2_normalise, normalise_unit, MobileFaceNet, EMBEDDING};
use candle_core::{DType, Device, Module, Tensor};
use candle_nn::{loss, linear, AdamW, Optimizer, ParamsAdamW, VarBuilder, VarMap, SGD};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let ckpt = args.next().expect("checkpoint path");
    let batch: usize = args.next().map(|b| b.parse().unwrap()).unwrap_or(32);
    let dev = Device::Cpu;
    let (net, vm) = MobileFaceNet::from_checkpoint(ckpt.as_ref(), &dev)?;
    let head_vm = VarMap::new();
    let head = linear(EMBEDDING, 500, VarBuilder::from_varmap(&head_vm, DType::F32, &dev).pp("head"))?;
    let cam = Camera::identity(32, 2.2, &dev)?;
    let x = Tensor::rand(0f32, 1f32, (batch, 3, 112, 96), &dev)?;
    let lin = cam.degamma(&x)?;
    let y = Tensor::arange(0u32, batch as u32, &dev)?;
    let mut all = vm.all_vars();
    all.extend(head_vm.all_vars());
    let mut sgd = SGD::new(all, 0.1)?;
    let mut adam = AdamW::new(cam.vars(), ParamsAdamW { lr: 1e-3, weight_decay: 0.0, ..Default::default() })?;
    let t = std::time::Instant::now();
    let _ = net.forward_t(&normalise_unit(&x)?, false)?;
    println!("forward only (no variables touched by grad): {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
    let xd = normalise_unit(&x)?;
    for (name, f) in [("dense 1x1 64->128 at 56x48", 0), ("depthwise 3x3 128 at 56x48", 1)] {
        let a = Tensor::rand(0f32, 1f32, (batch, if f == 0 { 64 } else { 128 }, 56, 48), &dev)?;
        let t = std::time::Instant::now();
        let _ = if f == 0 { campro_train::mobilefacenet::dense(&a, &Tensor::rand(0f32, 1f32, (128, 64, 1, 1), &dev)?, 1, 0)? } else { campro_train::mobilefacenet::depthwise(&a, &Tensor::rand(0f32, 1f32, (128, 1, 3, 3), &dev)?, 1, 1)? };
        println!("{name}: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    }
    let _ = xd;
    {
        let a = Tensor::rand(0f32, 1f32, (batch, 128, 56, 48), &dev)?;
        let m = Tensor::rand(0f32, 1f32, (1, 128, 1, 1), &dev)?;
        let t = std::time::Instant::now();
        let _ = a.broadcast_mul(&m)?;
        println!("broadcast_mul (B,128,56,48)x(1,128,1,1): {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
        let t = std::time::Instant::now();
        let _ = a.relu()?;
        println!("relu: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
        let t = std::time::Instant::now();
        let _ = (&a + &a)?;
        println!("add: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    }
    for step in 0..4 {
        let t = std::time::Instant::now();
        // Attacker: cross-entropy on C(x), camera frozen.
        let img = cam.forward_linear(&lin)?.detach();
        let logits = head.forward(&l2_normalise(&net.forward_t(&normalise_unit(&img)?, true)?)?)?;
        let l = loss::cross_entropy(&logits, &y)?;
        let tf = t.elapsed();
        let g = l.backward()?;
        let tb = t.elapsed();
        sgd.step(&g)?;
        let ta = t.elapsed();
        println!("  attacker: forward {:.0} ms, backward {:.0} ms, SGD {:.0} ms", tf.as_secs_f64() * 1e3, (tb - tf).as_secs_f64() * 1e3, (ta - tb).as_secs_f64() * 1e3);
        // Protector: non-saturating privacy loss through the frozen attacker into the camera.
        let t = std::time::Instant::now();
        let img = cam.forward_linear(&lin)?;
        let logits = head.forward(&l2_normalise(&net.forward_t(&normalise_unit(&img)?, false)?)?)?;
        let lns = campro_train::train::non_saturating_loss(&logits, &y)?;
        let g = lns.backward()?;
        adam.step(&g)?;
        cam.project()?;
        println!("step {step}: batch {batch}: attacker {:.0} ms, protector {:.0} ms (CE {:.3}, L_ns {:.4})", ta.as_secs_f64() * 1e3, t.elapsed().as_secs_f64() * 1e3, l.to_scalar::<f32>()?, lns.to_scalar::<f32>()?);
    }
    Ok(())
}
