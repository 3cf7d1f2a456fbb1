//! Fine-tunes YOLOX-Nano alone on raw COCO people (no camera) and writes it as ONNX, to
//! check the detection loss and learning rate: `cargo run --release -p campro-train --example
//! detector_finetune -- SHARED OUT.onnx [STEPS] [LR] [IMAGES] [SIZE]`. Evaluate the result
//! with `campro eval utility params/identity.json --person-detector MANIFEST --limit IMAGES`.

use campro_train::detection::yolox_loss;
use campro_train::persons::{detector_input, PersonSet};
use campro_train::yolox::Yolox;
use candle_core::Device;
use candle_nn::{AdamW, Optimizer, ParamsAdamW};
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut a = std::env::args().skip(1);
    let shared = PathBuf::from(a.next().unwrap_or_else(|| "../shared".into()));
    let out = PathBuf::from(a.next().unwrap_or_else(|| "finetuned.onnx".into()));
    let steps: usize = a.next().map_or(Ok(40), |s| s.parse())?;
    let lr: f64 = a.next().map_or(Ok(1e-5), |s| s.parse())?;
    let images: usize = a.next().map_or(Ok(300), |s| s.parse())?;
    let size: usize = a.next().map_or(Ok(416), |s| s.parse())?;
    let dev = Device::Cpu;
    let set = PersonSet::open(&shared.join("data/coco-person"), size, Some(images))?;
    let det = Yolox::load(&shared.join("models/yolox_nano.onnx"), &dev)?;
    let mut adam = AdamW::new(det.vars(), ParamsAdamW { lr, weight_decay: 0.0, ..Default::default() })?;
    for step in 0..steps {
        let idx: Vec<usize> = (0..4).map(|k| (step * 4 + k) % set.len()).collect();
        let b = set.batch(&idx, &dev)?;
        let (l, parts) = yolox_loss(&det.forward(&detector_input(&b.x, &b.mask)?)?, size, size, &b.boxes)?;
        adam.step(&l.backward()?)?;
        println!("step {step}: L_det {:.3} (iou {:.3} obj {:.3} cls {:.3}, {} positives)", l.to_scalar::<f32>()?, parts.iou, parts.obj, parts.cls, parts.positives);
    }
    det.save_onnx(&out)?;
    Ok(())
}
