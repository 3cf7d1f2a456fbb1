//! One training step (forward, sum of the output, backward) of each player's network in burn
//! (NdArray backend with Autodiff, f32, CPU), at the shapes campro-train's `step_time`
//! example times in candle: YOLOX-Nano 1x3x416x416 (its ONNX fixes batch 1) and
//! MobileFaceNet 8x3x112x96. Median of 5 after one warm-up.

mod yolox {
    include!(concat!(env!("OUT_DIR"), "/model/yolox_nano.rs"));
}
mod mfn {
    include!(concat!(env!("OUT_DIR"), "/model/mobilefacenet_casia.rs"));
}

use burn::backend::{Autodiff, NdArray};
use burn::tensor::{Distribution, Tensor};

type B = Autodiff<NdArray<f32>>;

fn median(mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..5)
        .map(|_| {
            let s = std::time::Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[2]
}

fn main() {
    let dev = Default::default();
    let y: yolox::Model<B> = yolox::Model::default();
    let x = Tensor::<B, 4>::random([1, 3, 416, 416], Distribution::Uniform(0.0, 255.0), &dev).require_grad();
    let yolox_step = median(|| {
        let _ = y.forward(x.clone()).sum().backward();
    });
    let m: mfn::Model<B> = mfn::Model::default();
    let f = Tensor::<B, 4>::random([8, 3, 112, 96], Distribution::Uniform(-1.0, 1.0), &dev).require_grad();
    let mfn_step = median(|| {
        let _ = m.forward(f.clone()).sum().backward();
    });
    println!("burn (ndarray + autodiff): YOLOX-Nano 1x416x416 forward + backward of the output sum: {:.0} ms", yolox_step * 1e3);
    println!("burn (ndarray + autodiff): MobileFaceNet 8x112x96 forward + backward of the output sum: {:.0} ms", mfn_step * 1e3);
}
