//! One training step (forward, sum of the output, backward) of each player's network in burn
//! (NdArray backend with Autodiff, f32, CPU), at the shapes `campro bench train`
//! times in candle: YOLOX-Nano 1x3x416x416 (its ONNX fixes batch 1) and
//! MobileFaceNet 8x3x112x96. Each phase (building the model from its weights, the forward
//! pass, the backward pass) is timed apart and printed as it ends, so a run cut short still
//! says where its time went; then the median of `REPS` (default 3) whole steps.

mod yolox {
    include!(concat!(env!("OUT_DIR"), "/model/yolox_nano.rs"));
}
mod mfn {
    include!(concat!(env!("OUT_DIR"), "/model/mobilefacenet_casia.rs"));
}

use burn::backend::{Autodiff, NdArray};
use burn::tensor::{Distribution, Tensor};
use std::time::Instant;

type B = Autodiff<NdArray<f32>>;

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Times one player: load, first forward, first backward, then the median whole step.
fn player(name: &str, reps: usize, load: impl FnOnce() -> Box<dyn Fn() -> Tensor<B, 1>>) {
    let t = Instant::now();
    let step = load();
    println!("burn {name}: model built in {:.0} ms", ms(t));
    let t = Instant::now();
    let loss = step();
    println!("burn {name}: first forward {:.0} ms", ms(t));
    let t = Instant::now();
    let _ = loss.backward();
    println!("burn {name}: first backward {:.0} ms", ms(t));
    let mut times: Vec<f64> = (0..reps)
        .map(|_| {
            let t = Instant::now();
            let _ = step().backward();
            ms(t)
        })
        .collect();
    times.sort_by(f64::total_cmp);
    println!("burn (ndarray + autodiff): {name} forward + backward of the output sum: {:.0} ms (median of {reps})", times[reps / 2]);
}

fn main() {
    let reps: usize = std::env::var("REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3)
        .max(1);
    let dev: burn::backend::ndarray::NdArrayDevice = Default::default();
    player("YOLOX-Nano 1x416x416", reps, || {
        let y: yolox::Model<B> = yolox::Model::default();
        let x = Tensor::<B, 4>::random([1, 3, 416, 416], Distribution::Uniform(0.0, 255.0), &dev)
            .require_grad();
        Box::new(move || y.forward(x.clone()).sum())
    });
    player("MobileFaceNet 8x112x96", reps, || {
        let m: mfn::Model<B> = mfn::Model::default();
        let f = Tensor::<B, 4>::random([8, 3, 112, 96], Distribution::Uniform(-1.0, 1.0), &dev)
            .require_grad();
        Box::new(move || m.forward(f.clone()).sum())
    });
}
