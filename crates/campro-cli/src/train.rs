//! `campro train`, `campro finetune-detector`, `campro train-enhancer` and the training
//! benchmarks: the optimiser's CLI (crate campro-train).

use crate::args::{
    BenchEnhancerArgs, BenchTrainArgs, FinetuneDetectorArgs, RunFiles, StepArg, TrainArgs, TrainEnhancerArgs,
};
use crate::output::file_key;
use crate::{load_params, write_atomic};
use anyhow::{bail, Result};
use campro_eval::table::{Cell, Column, Table};
use campro_nn::yolox::Yolox;
use std::path::{Path, PathBuf};

impl RunFiles {
    /// Refuses to start a run whose files collide ([`check_run_files`]), or that would write
    /// into a checkpoint folder holding an earlier run (unless resuming from it).
    fn check(&self, inputs: &[&Path], outputs: &[(&str, &Path)], charts: &[&str]) -> Result<()> {
        check_run_files(inputs, outputs, self.log.as_deref(), charts, self.force)?;
        if let Some(c) = &self.checkpoints {
            if self.resume.as_deref() != Some(c.as_path()) {
                crate::check_output_folder(c, self.force, "--checkpoints")?;
            }
        }
        Ok(())
    }
}

/// The chart `name` of the log `log`: `LOG-NAME.svg` beside it.
fn chart_path(log: &Path, name: &str) -> PathBuf {
    let mut stem = log.with_extension("").into_os_string();
    stem.push(format!("-{name}.svg"));
    PathBuf::from(stem)
}

/// Checks every file a training run will write before round one, so that no work is lost
/// at its end: the `outputs` (each with the flag that names it), the log and its `charts`.
/// None may be one of the `inputs` (--force or not), no two may be one file, and none may
/// exist unless `force`.
fn check_run_files(
    inputs: &[&Path],
    outputs: &[(&str, &Path)],
    log: Option<&Path>,
    charts: &[&str],
    force: bool,
) -> Result<()> {
    let mut all: Vec<(String, PathBuf)> = outputs.iter().map(|(f, p)| (f.to_string(), p.to_path_buf())).collect();
    if let Some(l) = log {
        all.push(("--log".into(), l.to_path_buf()));
        all.extend(charts.iter().map(|c| (format!("--log's {c} chart"), chart_path(l, c))));
    }
    for (i, (flag, p)) in all.iter().enumerate() {
        crate::output::not_an_input(flag, p, inputs)?;
        if let Some((other, _)) = all[..i].iter().find(|(_, q)| file_key(q) == file_key(p)) {
            bail!("{flag} {}: is also where {other} goes; give each its own file", crate::shown(p));
        }
        if p.exists() && !force {
            bail!("{} exists (use --force to replace it)", crate::shown(p));
        }
    }
    Ok(())
}

/// A parameter argument of a command that writes beside the parameter file and into it:
/// it must be a file, not a bundled preset's name (whose outputs would land, mangled, in
/// the working folder).
fn writable_params(flag: &str, p: &Path) -> Result<()> {
    if let Some(preset) = crate::presets::named(p) {
        bail!(
            "{flag} {}: is a bundled preset, and this command writes its results beside the parameter file and into it; copy the preset to a file of yours first (its JSON is params/{}.json in campro's source)",
            crate::shown(p),
            preset.name
        );
    }
    Ok(())
}

pub fn train(a: &TrainArgs) -> Result<()> {
    let (config, output, files) = (a.config.as_path(), a.output.as_path(), &a.files);
    if !config.exists() {
        bail!(
            "CONFIG {}: no such file (the repository's configurations are in crates/campro-train/configs, with paths relative to its root: run from there)",
            crate::shown(config)
        );
    }
    let cfg = campro_train::config::Config::load(config)?;
    let init = match &a.init {
        Some(p) => Some(campro_train::train::Initial::from_params(&load_params(p)?, &p.display().to_string())?),
        None => None,
    };
    // The detector's files are written when the utility player plays.
    let (onnx, manifest) = (output.with_extension("detector.onnx"), output.with_extension("detector.json"));
    let mut outputs = vec![("-o", output)];
    if cfg.protector.omega > 0.0 {
        outputs.extend([("-o's detector", onnx.as_path()), ("-o's detector manifest", manifest.as_path())]);
    }
    let inputs: Vec<&Path> = [Some(config), a.init.as_deref()].into_iter().flatten().collect();
    files.check(&inputs, &outputs, &["losses", "accuracy"])?;
    let opts = &campro_train::train::RunOptions {
        checkpoints: files.checkpoints.clone(),
        resume: files.resume.clone(),
        init,
        ctx: campro_nn::Context::cpu().on(device_of(&a.device)?),
    };
    let pb = training_bar("train", "round", cfg.budget.rounds);
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
            checkpoint_line(&pb, line);
        }
        if let Some(t) = r.validation_top1 {
            let ap = r.validation_ap.map_or(String::new(), |a| format!(", person AP {a:.3}"));
            checkpoint_line(&pb, format!("round {}: validation top-1 {t:.3}{ap}", r.round));
        }
    })?;
    pb.finish_and_clear();
    if let Some(v) = out.provenance.get("validation").filter(|v| !v.is_null()) {
        eprintln!(
            "validation: best camera at round {}{}",
            v["best_round"],
            if v["stopped_early"] == true { " (stopped early: no better camera within the patience)" } else { "" }
        );
    }
    let force = files.force;
    if let Some(l) = &files.log {
        let (losses, acc) = campro_train::log::plot_log(&out.log);
        write_log(l, &campro_train::log::log_csv(&out.log), [("losses", losses), ("accuracy", acc)], force)?;
    }
    let name = output.file_stem().map_or("campro-trained".into(), |s| s.to_string_lossy().into_owned());
    let mut params = out.params(&cfg, &name, &config.display().to_string())?;
    if let Some(det) = &out.detector {
        let entry = write_detector(det, output, &params.name, force)?;
        params.provenance.insert(campro::provenance::DETECTOR.into(), entry);
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

/// The progress bar of a training run: `what [bar] UNIT pos/len ...`.
fn training_bar(what: &str, unit: &str, len: usize) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(len as u64);
    let template = format!("{what} [{{bar:30}}] {unit} {{pos}}/{{len}} {{elapsed_precise}} eta {{eta}} {{msg}}");
    pb.set_style(indicatif::ProgressStyle::with_template(&template).expect("a valid template").progress_chars("=> "));
    pb
}

/// A checkpoint's line, above the bar; a hidden bar (not a terminal: logs, CI) prints
/// nothing, so the line goes to stderr.
fn checkpoint_line(pb: &indicatif::ProgressBar, line: String) {
    if pb.is_hidden() {
        eprintln!("{line}");
    } else {
        pb.println(line);
    }
}

/// Writes a training log `l` and its charts beside it ([`chart_path`]), each replaced only
/// with `force`.
fn write_log<const N: usize>(l: &Path, csv: &str, charts: [(&str, String); N], force: bool) -> Result<()> {
    write_atomic(l, csv.as_bytes(), force)?;
    for (name, svg) in charts {
        write_atomic(&chart_path(l, name), svg.as_bytes(), force)?;
    }
    Ok(())
}

/// Writes a fine-tuned detector beside the parameter file `params_path` (`.detector.onnx`,
/// weights at half precision: 1.8 MB, under the repository's file limit, so presets ship it)
/// with a manifest `eval utility --person-detector` reads (the bundled one naming the new
/// file, `.detector.json`); returns the provenance entry naming both.
fn write_detector(det: &Yolox, params_path: &Path, name: &str, force: bool) -> Result<serde_json::Value> {
    let onnx = params_path.with_extension("detector.onnx");
    let manifest_path = params_path.with_extension("detector.json");
    for p in [&onnx, &manifest_path] {
        if p.exists() && !force {
            bail!("{} exists (use --force to replace it)", crate::shown(p));
        }
    }
    det.save_onnx_half(&onnx)?;
    let mut m: serde_json::Value = serde_json::from_str(crate::models::YOLOX_MANIFEST)?;
    let file = onnx.file_name().expect("a file name").to_string_lossy().into_owned();
    m["name"] = crate::models::fine_tuned_name(name).into();
    m["file"] = file.clone().into();
    write_atomic(&manifest_path, (serde_json::to_string_pretty(&m)? + "\n").as_bytes(), force)?;
    Ok(
        serde_json::json!({ "onnx": file, "manifest": manifest_path.file_name().map(|f| f.to_string_lossy().into_owned()),
                           "held_out_images": format!("COCO id % {} == 0 (never trained on)", campro_eval::data::HOLDOUT_EVERY) }),
    )
}

/// Fine-tunes YOLOX-Nano behind the camera of `params_path` and records it in that file.
pub fn finetune_detector(a: &FinetuneDetectorArgs) -> Result<()> {
    let (params_path, steps, seconds, log, force) =
        (a.params.as_path(), a.steps as usize, a.seconds, a.log.as_deref(), a.force);
    if seconds.is_nan() || seconds <= 0.0 {
        bail!("--seconds: must be > 0 (inf for no limit), got {seconds}");
    }
    let cfg = match &a.config {
        Some(c) => campro_train::config::Config::load(c)?,
        None => campro_train::config::Config::default(),
    };
    writable_params("PARAMS", params_path)?;
    let (onnx, manifest) = (params_path.with_extension("detector.onnx"), params_path.with_extension("detector.json"));
    let inputs: Vec<&Path> = [Some(params_path), a.config.as_deref()].into_iter().flatten().collect();
    check_run_files(
        &inputs,
        &[("PARAMS's detector", &onnx), ("PARAMS's detector manifest", &manifest)],
        log,
        &[],
        force,
    )?;
    let mut params = load_params(params_path)?;
    let campro_train::train::Initial { ccm, curves, gamma, .. } =
        campro_train::train::Initial::from_params(&params, &params_path.display().to_string())?;
    let imaging = campro_train::finetune::Imaging::Camera { ccm, curves, gamma };
    let opts = campro_train::finetune::FinetuneOptions {
        steps,
        seconds,
        seed: cfg.seed,
        memory: cfg.budget.memory,
        ..Default::default()
    };
    let pb = training_bar("finetune-detector", "step", steps);
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
    params.provenance.insert(campro::provenance::DETECTOR.into(), entry);
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
/// LFW identities a trained parameter set held out (`provenance.data.validation_identities`).
fn held_out_identities(params: &campro::Params) -> Option<Vec<String>> {
    params.provenance_fields().ok()?.validation_identities
}

pub fn train_enhancer(a: &TrainEnhancerArgs) -> Result<()> {
    let cfg: campro_train::config::EnhancerConfig = match &a.config {
        Some(c) => campro_train::config::load(c)?,
        None => Default::default(),
    };
    writable_params("PARAMS", &a.params)?;
    let mut params = load_params(&a.params)?;
    let held_out = match held_out_identities(&params) {
        Some(h) => h,
        None if cfg.data.lfw_images == 0 => Vec::new(),
        None => bail!(
            "{}: provenance.data.validation_identities: missing, so LFW's held-out identities are unknown (train from a preset of campro train, or set data.lfw_images = 0)",
            a.params.display()
        ),
    };
    // A network trained to restore faces too is an attacker's, never the preset's enhancer.
    let which = if cfg.data.faces == campro_train::config::FaceTarget::Restore {
        crate::capture::Network::Restorer
    } else {
        crate::capture::Network::Enhancer
    };
    let key = which.key();
    let onnx = a.params.with_extension(format!("{key}.onnx"));
    let manifest = a.params.with_extension(format!("{key}.json"));
    let inputs: Vec<&Path> =
        [Some(a.params.as_path()), a.config.as_deref(), a.init.as_deref()].into_iter().flatten().collect();
    a.files.check(
        &inputs,
        &[("PARAMS's network", &onnx), ("PARAMS's network manifest", &manifest)],
        &["losses", "psnr"],
    )?;
    let opts = campro_train::enhancer::EnhancerOptions {
        checkpoints: a.files.checkpoints.clone(),
        resume: a.files.resume.clone(),
        init: a.init.clone(),
        ctx: campro_nn::Context::cpu(),
    };
    let pb = indicatif::ProgressBar::new(cfg.budget.steps as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "train-enhancer [{bar:30}] step {pos}/{len} {elapsed_precise} eta {eta} {msg}",
        )
        .unwrap()
        .progress_chars("=> "),
    );
    let out = campro_train::enhancer::run(&cfg, &params, &held_out, &opts, |r| {
        pb.set_position(r.step as u64);
        pb.set_message(format!("L1 {:.4}", r.loss));
        if let Some(v) = &r.validation {
            let line = format!(
                "step {}: validation PSNR {:.2} dB (input {:.2}, captured {:.2}){}, masked L1 {:.4}, face L1 {} (input {}){}{} ({:.0} s)",
                r.step,
                v.psnr,
                v.psnr_input,
                v.psnr_captured,
                v.ssim.map_or(String::new(), |s| format!(", SSIM {s:.3}")),
                v.masked_l1,
                v.face_l1.map_or("-".into(), |f| format!("{f:.4}")),
                v.face_l1_input.map_or("-".into(), |f| format!("{f:.4}")),
                match (v.face_top1, v.face_top1_input) {
                    (Some(e), Some(i)) => format!(", face top-1 {:.1}% (input {:.1}%)", 100.0 * e, 100.0 * i),
                    _ => String::new(),
                },
                match (v.gate_faces, v.gate_scene) {
                    (Some(f), Some(s)) => format!(", face gate {f:.2} on faces, {s:.3} elsewhere"),
                    (None, Some(s)) => format!(", face gate {s:.3}"),
                    _ => String::new(),
                },
                r.seconds
            );
            checkpoint_line(&pb, line);
        }
    })?;
    pb.finish_and_clear();
    if let Some(l) = &a.files.log {
        let (losses, psnr) = campro_train::enhancer::plot_log(&out.log);
        write_log(l, &campro_train::enhancer::log_csv(&out.log), [("losses", losses), ("psnr", psnr)], a.files.force)?;
    }
    out.enhancer.save_onnx(&onnx)?;
    let file = |p: &Path| p.file_name().expect("a file name").to_string_lossy().into_owned();
    let m = serde_json::json!({
        "name": format!("campro {key} ({})", params.name),
        "kind": if which == crate::capture::Network::Enhancer { "image_enhancer" } else { "restoration_network" },
        "file": file(&onnx),
        "widths": out.enhancer.unet.widths(),
        "multiple": out.enhancer.unet.multiple(),
        "restoration_table": out.enhancer.table.is_some(),
        "provenance": out.provenance,
    });
    write_atomic(&manifest, (serde_json::to_string_pretty(&m)? + "\n").as_bytes(), a.files.force)?;
    let last = out.log.iter().rev().find_map(|r| r.validation.clone());
    params.provenance.insert(
        key.into(),
        serde_json::json!({ "onnx": file(&onnx), "manifest": file(&manifest), "steps": out.log.last().map_or(0, |r| r.step),
                            "seconds": out.seconds, "validation": last }),
    );
    write_atomic(&a.params, params.to_json().as_bytes(), true)?;
    eprintln!(
        "trained the {key} {} steps in {:.0} s -> {}",
        out.log.last().map_or(0, |r| r.step),
        out.seconds,
        onnx.display()
    );
    Ok(())
}

pub fn bench_train(a: &BenchTrainArgs) -> Result<()> {
    use campro_train::bench::Step;
    let threads = a.timing.threads();
    // candle's matrix products read RAYON_NUM_THREADS on every call; rayon reads it once.
    std::env::set_var("RAYON_NUM_THREADS", threads.to_string());
    let cfg = match &a.config {
        Some(p) => campro_train::config::Config::load(p)?,
        None => campro_train::config::Config::default(),
    };
    let steps: Vec<Step> = if a.only.is_empty() {
        Step::ALL.to_vec()
    } else {
        a.only
            .iter()
            .map(|s| match s {
                StepArg::Mobilefacenet => Step::MobileFaceNet,
                StepArg::Yolox => Step::Yolox,
                StepArg::Attacker => Step::Attacker,
                StepArg::Privacy => Step::Privacy,
                StepArg::Detector => Step::Detector,
            })
            .collect()
    };
    let shared = crate::args::shared_dir(a.shared.as_deref());
    let models = shared.join("models");
    let ctx = campro_nn::Context::cpu().with_threads(threads).on(device_of(&a.device)?);
    let times = ctx.install(|| campro_train::bench::run(&ctx, &models, &cfg, &steps, a.timing.runs as usize))?;
    let torch = match &a.anchor {
        Some(py) => Some(run_anchor(py, &shared, threads)?),
        None => None,
    };
    // Each step's key, its time and PyTorch's (when the anchor ran and timed it), in ms.
    let rows: Vec<(&str, f64, Option<f64>)> = times
        .iter()
        .map(|(s, ms)| (s.key(), *ms, torch.as_ref().and_then(|t| t.get(s.key())).and_then(|v| v.as_f64())))
        .collect();
    match a.format {
        // PyTorch's anchor's own shape (`anchors/torch_step.py --json`), with the ratios.
        crate::args::Report::Json => {
            let mut json = serde_json::Map::new();
            json.insert("threads".into(), threads.into());
            json.insert("face_batch".into(), cfg.data.batch.into());
            json.insert("person_batch".into(), cfg.detector.batch.into());
            json.insert("person_size".into(), cfg.detector.size.into());
            for &(key, ms, base) in &rows {
                json.insert(key.into(), ms.into());
                if let Some(b) = base {
                    json.insert(key.replace("_ms", "_ratio"), (ms / b).into());
                }
            }
            if let Some(t) = torch {
                json.insert("torch".into(), t);
            }
            crate::say!("{}", serde_json::Value::Object(json))
        }
        crate::args::Report::Text => {
            let mut t = Table::new([
                Column::new(format!("step ({threads} threads)"), "step", 0),
                Column::new("campro-train (ms)", "ms", 0),
                Column::new("PyTorch (ms)", "torch_ms", 0),
                Column::new("ratio", "ratio", 2),
            ]);
            for &(key, ms, base) in &rows {
                t.push(vec![key.into(), ms.into(), Cell::opt(base), Cell::opt(base.map(|b| ms / b))]);
            }
            crate::say!("{}", t.markdown().trim_end());
        }
    }
    Ok(())
}

/// PyTorch's anchor as JSON: `PYTHON SHARED/anchors/torch_step.py MODELS THREADS --json`.
fn run_anchor(python: &Path, shared: &Path, threads: usize) -> Result<serde_json::Value> {
    let script = shared.join("anchors/torch_step.py");
    if !script.is_file() {
        bail!("--anchor: {} not found", crate::shown(&script));
    }
    let out = std::process::Command::new(python)
        .arg(&script)
        .arg(shared.join("models"))
        .arg(threads.to_string())
        .arg("--json")
        .stdin(std::process::Stdio::null())
        .output()
        .map_err(|e| anyhow::anyhow!("--anchor {}: {e}", crate::shown(python)))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        bail!("--anchor: the anchor failed: {}", err.lines().last().unwrap_or("no message"));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let last = text.lines().last().unwrap_or("");
    serde_json::from_str(last).map_err(|e| anyhow::anyhow!("--anchor: the anchor printed no JSON ({e})"))
}

pub fn bench_enhancer(a: &BenchEnhancerArgs) -> Result<()> {
    let threads = a.timing.threads();
    std::env::set_var("RAYON_NUM_THREADS", threads.to_string());
    let cfg: campro_train::config::EnhancerConfig = match &a.config {
        Some(c) => campro_train::config::load(c)?,
        None => Default::default(),
    };
    let mut sizes: Vec<Vec<usize>> = Vec::new();
    for s in &a.sizes {
        let w: Vec<usize> = s
            .split(',')
            .map(|v| v.trim().parse::<usize>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("--size {s}: {e}"))?;
        sizes.push(w);
    }
    if sizes.is_empty() {
        sizes.push(if a.widths.is_empty() { cfg.model.widths.clone() } else { a.widths.clone() });
    }
    let frame = image::RgbImage::from_fn(640, 480, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, ((x + y) % 256) as u8])
    });
    let ctx = campro_nn::Context::cpu().with_threads(threads);
    let stems = if a.stems.is_empty() { vec![cfg.model.stem] } else { a.stems.clone() };
    let shapes: Vec<campro_train::config::UnetConfig> = sizes
        .iter()
        .flat_map(|w| {
            stems.iter().map(|&stem| campro_train::config::UnetConfig {
                widths: w.clone(),
                stem,
                restorer: cfg.model.restorer,
                face_gate: cfg.model.face_gate,
                gate_blocks: cfg.model.gate_blocks,
            })
        })
        .collect();
    let mut t = Table::new([
        Column::new("widths", "widths", 0),
        Column::new("stem", "stem", 0),
        Column::new("restorer", "restorer", 0),
        Column::new("parameters", "parameters", 0),
        Column::new("MACs/pixel", "macs_per_pixel", 0),
        Column::new("ONNX", "onnx_bytes", 0),
        Column::new("tract 640x480, 1 thread (ms)", "tract_640x480_ms", 0),
        Column::new("tract fps", "tract_fps", 1),
        Column::new(
            format!("training step ({} x {}², {threads} threads) (ms)", cfg.data.batch, cfg.data.crop),
            "train_step_ms",
            0,
        ),
        Column::machine("batch"),
        Column::machine("crop"),
        Column::machine("threads"),
    ]);
    for shape in &shapes {
        let unet = campro_train::unet::Unet::new(shape, 1, &ctx.device)?;
        // A restoration stage costs its lookup whatever the table holds: the identity's.
        let table = shape.restorer.then(|| {
            let one = image::RgbImage::new(1, 1);
            campro_eval::restore::Restorer::fit(|i: &image::RgbImage| i.clone(), [&one]).map(|r| r.table().clone())
        });
        let net = campro_train::enhancer::EnhancerNet { unet, table: table.transpose()? };
        let onnx = net.onnx_bytes()?;
        let bytes = onnx.len();
        let enh = campro_eval::enhance::Enhancer::from_bytes(&onnx, Path::new("the benchmark's U-Net"))?;
        let infer = campro_train::bench::median_secs(a.timing.runs as usize, || {
            enh.enhance(&frame)?;
            Ok(())
        })?;
        let step_cfg = campro_train::config::EnhancerConfig { model: shape.clone(), ..cfg.clone() };
        let step = ctx.install(|| campro_train::bench::enhancer_step(&ctx, &step_cfg, a.timing.runs as usize))?;
        let widths: Vec<String> = shape.widths.iter().map(|w| w.to_string()).collect();
        t.push(vec![
            widths.join(",").into(),
            shape.stem.into(),
            shape.restorer.to_string().into(),
            campro_train::unet::parameter_count(shape).into(),
            campro_train::unet::macs_per_pixel(shape).into(),
            Cell::Shown { value: bytes as f64, shown: format!("{:.2} MB", bytes as f64 / 1e6) },
            (infer * 1e3).into(),
            (1.0 / infer).into(),
            (step * 1e3).into(),
            cfg.data.batch.into(),
            cfg.data.crop.into(),
            threads.into(),
        ]);
    }
    match a.format {
        crate::args::Report::Json => crate::say!("{}", t.json()),
        crate::args::Report::Text => crate::say!("{}", t.markdown().trim_end()),
    }
    Ok(())
}

/// A `--device` value's device, or one line saying why not.
fn device_of(name: &str) -> Result<campro_nn::Device> {
    campro_nn::context::device(name).map_err(|e| anyhow::anyhow!("--device {e}"))
}
