//! Fine-tunes YOLOX-Nano alone on raw COCO people (no camera) and writes it as ONNX, to
//! check the detection loss and learning rate: `cargo run --release -p campro-train --example
//! detector_finetune -- SHARED OUT.onnx [STEPS] [LR] [IMAGES] [SIZE]`. Evaluate the result
//! on the held-out images with `campro eval utility params/identity.json --person-detector
//! MANIFEST --held-out`.

use campro_train::config::DetectorConfig;
use campro_train::finetune::{run, FinetuneOptions, Imaging};
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let mut a = std::env::args().skip(1);
    let shared = PathBuf::from(a.next().unwrap_or_else(|| "../shared".into()));
    let out = PathBuf::from(a.next().unwrap_or_else(|| "finetuned.onnx".into()));
    let steps: usize = a.next().map_or(Ok(40), |s| s.parse())?;
    let lr: f64 = a.next().map_or(Ok(1e-5), |s| s.parse())?;
    let images: usize = a.next().map_or(Ok(300), |s| s.parse())?;
    let size: usize = a.next().map_or(Ok(416), |s| s.parse())?;
    let cfg = DetectorConfig {
        model: shared.join("models/yolox_nano.onnx"),
        data: shared.join("data/coco-person"),
        size,
        batch: 4,
        lr,
        max_images: Some(images),
        ..DetectorConfig::default()
    };
    let done = run(
        &Imaging::Raw,
        &cfg,
        &FinetuneOptions { steps, seconds: f64::INFINITY, seed: 0, ..Default::default() },
        |r| {
            println!(
                "step {}: L_det {:.3} (iou {:.3} obj {:.3} cls {:.3}, {} positives)",
                r.step, r.loss, r.iou, r.obj, r.cls, r.positives
            )
        },
    )?;
    done.detector.save_onnx(&out)?;
    Ok(())
}
