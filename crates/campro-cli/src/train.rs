//! `campro train` and `campro finetune-detector`: the optimiser's CLI (crate campro-train).

use crate::{eval, load_params, write_atomic};
use anyhow::{bail, Result};
use campro_train::yolox::Yolox;
use std::path::{Path, PathBuf};

pub fn train(
    config: &Path,
    output: &Path,
    log: Option<&Path>,
    checkpoints: Option<PathBuf>,
    resume: Option<PathBuf>,
    init: Option<&Path>,
    force: bool,
) -> Result<()> {
    let cfg = campro_train::config::Config::load(config)?;
    let init = match init {
        Some(p) => Some(campro_train::train::Initial::from_params(&load_params(p)?, &p.display().to_string())?),
        None => None,
    };
    // A checkpoint folder that holds an earlier run is written into only when resuming
    // from it, or with --force.
    if let Some(c) = &checkpoints {
        if resume.as_deref() != Some(c.as_path()) {
            crate::check_output_folder(c, force, "--checkpoints")?;
        }
    }
    let opts = &campro_train::train::RunOptions { checkpoints, resume, init };
    for p in std::iter::once(output).chain(log) {
        if p.exists() && !force {
            bail!("{} exists (use --force to replace it)", p.display());
        }
    }
    let pb = indicatif::ProgressBar::new(cfg.budget.rounds as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template("train [{bar:30}] round {pos}/{len} {elapsed_precise} eta {eta} {msg}")
            .unwrap()
            .progress_chars("=> "),
    );
    let out = campro_train::train::run(&cfg, opts, |r| {
        pb.set_position(r.round as u64);
        pb.set_message(format!(
            "L_ns {:.4} L_det {:.3} attacker acc {:.2}",
            r.privacy_loss, r.detection_loss, r.attacker_accuracy
        ));
        if let Some(c) = r.check_accuracy {
            let line = format!(
                "round {}: check accuracy {:.3} (attacker CE {:.3}, L_ns {:.4}, L_det {:.3}, {:.0} s)",
                r.round, c, r.attacker_ce, r.privacy_loss, r.detection_loss, r.seconds
            );
            // A hidden bar (not a terminal: logs, CI) prints nothing: the line goes to stderr.
            if pb.is_hidden() {
                eprintln!("{line}");
            } else {
                pb.println(line);
            }
        }
    })?;
    pb.finish_and_clear();
    if let Some(l) = log {
        let csv = campro_train::log::log_csv(&out.log);
        write_atomic(l, csv.as_bytes(), force)?;
        let (losses, acc) = campro_train::log::plot_log(&out.log);
        let stem = l.with_extension("");
        write_atomic(&PathBuf::from(format!("{}-losses.svg", stem.display())), losses.as_bytes(), true)?;
        write_atomic(&PathBuf::from(format!("{}-accuracy.svg", stem.display())), acc.as_bytes(), true)?;
    }
    let name = output.file_stem().map_or("campro-trained".into(), |s| s.to_string_lossy().into_owned());
    let mut params = out.params(&cfg, &name, &config.display().to_string())?;
    if let Some(det) = &out.detector {
        let entry = write_detector(det, output, &params.name, force)?;
        params.provenance.insert("detector".into(), entry);
    }
    write_atomic(output, params.to_json().as_bytes(), force)?;
    eprintln!(
        "trained {} rounds on {} classes ({} faces, {} aside) in {:.0} s -> {}",
        out.log.last().map_or(0, |r| r.round),
        out.classes,
        out.train_faces,
        out.check_faces,
        out.seconds,
        output.display()
    );
    Ok(())
}

/// Writes a fine-tuned detector beside the parameter file `params_path` (`.detector.onnx`)
/// with a manifest `eval utility --person-detector` reads (the bundled one naming the new
/// file, `.detector.json`); returns the provenance entry naming both.
fn write_detector(det: &Yolox, params_path: &Path, name: &str, force: bool) -> Result<serde_json::Value> {
    let onnx = params_path.with_extension("detector.onnx");
    let manifest_path = params_path.with_extension("detector.json");
    for p in [&onnx, &manifest_path] {
        if p.exists() && !force {
            bail!("{} exists (use --force to replace it)", p.display());
        }
    }
    det.save_onnx(&onnx)?;
    let mut m: serde_json::Value = serde_json::from_str(eval::YOLOX_MANIFEST)?;
    let file = onnx.file_name().expect("a file name").to_string_lossy().into_owned();
    m["name"] = format!("yolox-nano fine-tuned ({name})").into();
    m["file"] = file.clone().into();
    write_atomic(&manifest_path, (serde_json::to_string_pretty(&m)? + "\n").as_bytes(), force)?;
    Ok(
        serde_json::json!({ "onnx": file, "manifest": manifest_path.file_name().map(|f| f.to_string_lossy().into_owned()),
                           "held_out_images": format!("COCO id % {} == 0 (never trained on)", campro_eval::data::HOLDOUT_EVERY) }),
    )
}

/// The optimiser's camera values of `params` (read from `path`): CCM rows, curve outputs,
/// degamma exponent; its curve must have evenly spaced knots.
/// Fine-tunes YOLOX-Nano behind the camera of `params_path` and records it in that file.
pub fn finetune_detector(
    params_path: &Path,
    config: Option<&Path>,
    steps: usize,
    seconds: f64,
    log: Option<&Path>,
    force: bool,
) -> Result<()> {
    if steps == 0 {
        bail!("--steps: must be at least 1");
    }
    if seconds.is_nan() || seconds <= 0.0 {
        bail!("--seconds: must be > 0 (inf for no limit), got {seconds}");
    }
    let cfg = match config {
        Some(c) => campro_train::config::Config::load(c)?,
        None => campro_train::config::Config::default(),
    };
    if let Some(l) = log {
        if l.exists() && !force {
            bail!("{} exists (use --force to replace it)", l.display());
        }
    }
    let mut params = load_params(params_path)?;
    let campro_train::train::Initial { ccm, curve, gamma, .. } =
        campro_train::train::Initial::from_params(&params, &params_path.display().to_string())?;
    let imaging = campro_train::finetune::Imaging::Camera { ccm, curve, gamma };
    let opts = campro_train::finetune::FinetuneOptions { steps, seconds, seed: cfg.seed };
    let pb = indicatif::ProgressBar::new(steps as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "finetune-detector [{bar:30}] step {pos}/{len} {elapsed_precise} eta {eta} {msg}",
        )
        .unwrap()
        .progress_chars("=> "),
    );
    let every = (steps / 20).max(1);
    let done = campro_train::finetune::run(&imaging, &cfg.detector, &opts, |r| {
        pb.set_position(r.step as u64);
        pb.set_message(format!("L_det {:.3}", r.loss));
        if pb.is_hidden() && r.step % every == 0 {
            eprintln!("step {}: L_det {:.3} ({:.0} s)", r.step, r.loss, r.seconds);
        }
    })?;
    pb.finish_and_clear();
    let fit = done.adapter_fit.first().zip(done.adapter_fit.last()).map(|(a, b)| [*a, *b]);
    if let Some([a, b]) = fit {
        eprintln!("adapter fit: squared error {a:.5} -> {b:.5} in {} steps", done.adapter_fit.len());
    }
    if let Some(l) = log {
        let mut csv = String::from("step,seconds,loss,iou,obj,cls,positives,kd\n");
        for r in &done.log {
            csv += &format!(
                "{},{:.3},{:.6},{:.6},{:.6},{:.6},{},{:.6}\n",
                r.step, r.seconds, r.loss, r.iou, r.obj, r.cls, r.positives, r.kd
            );
        }
        write_atomic(l, csv.as_bytes(), force)?;
    }
    let mut entry = write_detector(&done.detector, params_path, &params.name, force)?;
    let tail = &done.log[done.log.len().saturating_sub(50)..];
    entry["finetune"] = serde_json::json!({
        "steps": done.log.len(), "seconds": done.log.last().map_or(0.0, |r| r.seconds), "images": done.images,
        "detector": cfg.detector, "seed": cfg.seed, "adapter_fit_error": fit,
        "mean_loss_last_50": tail.iter().map(|r| r.loss).sum::<f64>() / tail.len().max(1) as f64,
    });
    params.provenance.insert("detector".into(), entry);
    write_atomic(params_path, params.to_json().as_bytes(), true)?;
    eprintln!(
        "fine-tuned the detector {} steps on {} images in {:.0} s -> {}",
        done.log.len(),
        done.images,
        done.log.last().map_or(0.0, |r| r.seconds),
        params_path.with_extension("detector.json").display()
    );
    Ok(())
}
