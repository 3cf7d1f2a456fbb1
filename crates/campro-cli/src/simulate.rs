//! `campro simulate`: the desktop pipeline on image files and folders, into PNGs.
//!
//! Hostile input is normal input here: inputs are regular files read with a byte cap;
//! links, FIFOs and devices inside folders are skipped with a warning; an output folder
//! inside an input folder is never read back; an output that would replace an input is
//! refused; every decode draws its memory from one budget shared by all jobs, so a
//! decompression bomb is refused by its header and several large images wait for each
//! other instead of adding up.

use crate::capture::Capture;
use crate::video::{self, Encoding};
use crate::write_atomic;
use anyhow::{anyhow, bail, Result};
use campro::pipeline::fast::Exact8;
use campro::pipeline::{Depth, Prepared};
use campro::Params;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The file endings read as images.
const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "tif", "tiff"];
pub(crate) use campro_eval::image_file::Budget;

/// What a walk over the inputs found.
pub(crate) struct Inputs {
    /// (input file, output file).
    pub jobs: Vec<(PathBuf, PathBuf)>,
    /// Entries passed over, with why.
    pub skipped: Vec<(PathBuf, &'static str)>,
}

/// A path made absolute and, where it exists, with links resolved (for comparing).
fn resolved(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).or_else(|_| std::path::absolute(p)).unwrap_or_else(|_| p.to_path_buf())
}

/// Every (input file, output file) pair: folders are walked recursively and mirrored.
pub(crate) fn collect_inputs(inputs: &[PathBuf], out: &Path) -> Result<Inputs> {
    let out_abs = resolved(out);
    let mut found = Inputs { jobs: Vec::new(), skipped: Vec::new() };
    for input in inputs {
        let meta = std::fs::metadata(input).map_err(|e| anyhow!("{}: {e}", crate::shown(input)))?;
        if meta.is_dir() {
            if resolved(input) == out_abs {
                bail!("--output {}: is the input folder itself; outputs would replace inputs", crate::shown(out));
            }
            // Never descend into the output folder: what this run writes is not an input.
            let walk = walkdir::WalkDir::new(input).sort_by_file_name().into_iter();
            for entry in walk.filter_entry(|e| !(e.file_type().is_dir() && resolved(e.path()) == out_abs)) {
                let entry = entry?;
                let t = entry.file_type();
                if t.is_dir() {
                    continue;
                }
                if t.is_symlink() {
                    found
                        .skipped
                        .push((entry.path().to_path_buf(), "a symbolic link (links inside folders are not followed)"));
                    continue;
                }
                if !t.is_file() {
                    found.skipped.push((entry.path().to_path_buf(), "not a regular file"));
                    continue;
                }
                let rel = entry.path().strip_prefix(input).expect("walkdir yields paths under its root");
                found.jobs.push((entry.path().to_path_buf(), output_for(&out.join(rel))));
            }
        } else if meta.is_file() {
            let name = input.file_name().ok_or_else(|| anyhow!("{}: not a file name", crate::shown(input)))?;
            found.jobs.push((input.clone(), output_for(&out.join(Path::new(name)))));
        } else {
            bail!("{}: is not a regular file or folder", crate::shown(input));
        }
    }
    let mut seen = std::collections::HashSet::new();
    let sources: std::collections::HashSet<PathBuf> = found.jobs.iter().map(|(i, _)| resolved(i)).collect();
    for (i, o) in &found.jobs {
        if !seen.insert(o.clone()) {
            bail!("two inputs would both be written to {} (the second is {})", crate::shown(o), crate::shown(i));
        }
        if sources.contains(&resolved(o)) {
            bail!("--output: writing {} would replace an input; choose another output folder", crate::shown(o));
        }
    }
    Ok(found)
}

/// Where an input goes: images become PNGs, videos keep their container.
fn output_for(path: &Path) -> PathBuf {
    if video::is_video(path) {
        path.to_path_buf()
    } else {
        path.with_extension("png")
    }
}

pub(crate) fn is_image(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        .unwrap_or(false)
}

/// What `simulate` does with an output that exists already.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Existing {
    /// Refuse it (the default).
    Refuse,
    /// Replace it (`--force`).
    Replace,
    /// Leave it and skip its input (`--skip-existing`: re-runs do only what is missing).
    Skip,
}

/// One input's outcome, for `--format json`.
fn record(
    input: &Path,
    output: &Path,
    status: &str,
    started: std::time::Instant,
    error: Option<String>,
) -> serde_json::Value {
    serde_json::json!({
        "input": input.display().to_string(), "output": output.display().to_string(), "status": status,
        "ms": (started.elapsed().as_secs_f64() * 1000.0 * 10.0).round() / 10.0, "error": error,
    })
}

/// Runs `p` over every image and video under `inputs` into PNGs and videos under `out`;
/// with `json`, prints what happened to each input (written, skipped, failed, with its time)
/// as one JSON object on stdout.
#[allow(clippy::too_many_arguments)]
pub fn simulate(
    p: &Params,
    inputs: &[PathBuf],
    out: &Path,
    depth: Depth,
    existing: Existing,
    jobs: Option<usize>,
    enc: &Encoding,
    enhancer: Option<&campro_eval::enhance::Enhancer>,
    json: bool,
) -> Result<()> {
    let force = existing == Existing::Replace;
    let records = std::sync::Mutex::new(Vec::new());
    let note = |v: serde_json::Value| records.lock().unwrap_or_else(|p| p.into_inner()).push(v);
    let skipped = AtomicUsize::new(0);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = match jobs {
        Some(j) if j > cores => {
            eprintln!("warning: --jobs {j} is more than the {cores} cores; using {cores}");
            cores
        }
        Some(j) => j,
        None => cores,
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let found = collect_inputs(inputs, out)?;
    for (i, why) in &found.skipped {
        eprintln!("warning: skipping {}: {why}", crate::shown(i));
    }
    let (videos, rest): (Vec<_>, Vec<_>) = found.jobs.into_iter().partition(|(i, _)| video::is_video(i));
    let (images, others): (Vec<_>, Vec<_>) = rest.into_iter().partition(|(i, _)| is_image(i));
    for (i, _) in &others {
        eprintln!("warning: skipping {} (not a PNG, JPEG, TIFF or video file)", crate::shown(i));
    }
    if images.is_empty() && videos.is_empty() {
        bail!("no PNG, JPEG, TIFF or video file among the inputs: nothing to do");
    }
    // A lossless codec moves outputs into Matroska: two inputs must not meet there
    // (a.mp4 and a.mkv would both become a.mkv, and one would be lost).
    let mut targets: std::collections::HashMap<PathBuf, &PathBuf> =
        images.iter().map(|(i, o)| (o.clone(), i)).collect();
    for (i, wanted) in &videos {
        if let Some(other) = targets.insert(enc.output_path(wanted), i) {
            bail!(
                "{} and {} would both be written to {} (--codec {} writes Matroska); simulate them into different folders",
                crate::shown(other),
                crate::shown(i),
                crate::shown(&enc.output_path(wanted)),
                enc.codec
            );
        }
    }
    let bar = if images.len() > 4 {
        indicatif::ProgressBar::new(images.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed_precise} eta {eta}")
            .expect("valid template"),
    );
    // The 16-bit degamma table (65536 powers) is built only if a 16-bit image turns up.
    let prepared8 = Prepared::new(p, Depth::Eight);
    let fast8 = Exact8::new(p);
    let prepared16 = std::sync::OnceLock::new();
    let budget = Budget::global();
    let failed = AtomicUsize::new(0);
    let capture = Capture { fast8: &fast8, enhancer };
    let paths = Paths { capture: &capture, p8: &prepared8, p16: &prepared16, budget, depth, force };
    pool.install(|| {
        images.par_iter().for_each(|(i, o)| {
            let started = std::time::Instant::now();
            if existing == Existing::Skip && o.exists() {
                skipped.fetch_add(1, Ordering::Relaxed);
                note(record(i, o, "skipped", started, None));
                bar.inc(1);
                return;
            }
            let r = if !force && o.exists() {
                Err(anyhow!("{} exists (use --force to overwrite, or --skip-existing)", crate::shown(o)))
            } else {
                paths.one(i, o, &|w| bar.suspend(|| eprintln!("warning: {}: {w}", crate::shown(i))))
            };
            match r {
                Ok(()) => note(record(i, o, "written", started, None)),
                Err(e) => {
                    let line = crate::about(i, &e);
                    bar.suspend(|| eprintln!("error: {line}"));
                    failed.fetch_add(1, Ordering::Relaxed);
                    note(record(i, o, "failed", started, Some(line)));
                }
            }
            bar.inc(1);
        })
    });
    bar.finish_and_clear();
    let mut failed = failed.into_inner();
    let mut skipped = skipped.into_inner();
    if !images.is_empty() {
        let done = images.len() - failed - skipped;
        let note = if skipped > 0 { format!(" ({skipped} skipped: already there)") } else { String::new() };
        eprintln!("simulated {done} of {} images into {}{note}", images.len(), crate::shown(out));
    }
    // Videos one after another, each frame on every core.
    for (i, wanted) in &videos {
        let o = enc.output_path(wanted);
        if &o != wanted {
            eprintln!(
                "note: {} is written as {} ({} needs Matroska)",
                crate::shown(wanted),
                crate::shown(&o),
                enc.codec
            );
        }
        let warn = |w: &str| eprintln!("warning: {}: {w}", crate::shown(i));
        let started = std::time::Instant::now();
        if existing == Existing::Skip && o.exists() {
            skipped += 1;
            eprintln!("skipped {}: {} is already there", crate::shown(i), crate::shown(&o));
            note(record(i, &o, "skipped", started, None));
            continue;
        }
        let r = if !force && o.exists() {
            Err(anyhow!("{} exists (use --force to overwrite, or --skip-existing)", crate::shown(&o)))
        } else {
            pool.install(|| video::simulate(&capture, i, &o, enc, force, &warn))
        };
        match r {
            Ok(n) => {
                eprintln!("simulated {n} frames of {} into {}", crate::shown(i), crate::shown(&o));
                let mut r = record(i, &o, "written", started, None);
                r["frames"] = n.into();
                note(r);
            }
            Err(e) => {
                let line = crate::about(i, &e);
                eprintln!("error: {line}");
                failed += 1;
                note(record(i, &o, "failed", started, Some(line)));
            }
        }
    }
    if json {
        let mut files = records.into_inner().unwrap_or_else(|p| p.into_inner());
        files.sort_by(|a, b| a["input"].as_str().cmp(&b["input"].as_str()));
        let written = files.len() - failed - skipped;
        crate::say!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "output": out.display().to_string(), "written": written, "skipped": skipped, "failed": failed, "files": files,
            }))?
        );
    }
    if failed > 0 {
        bail!("{failed} input(s) failed");
    }
    Ok(())
}

/// What every job shares.
struct Paths<'a, 'p> {
    capture: &'a Capture<'a, 'p>,
    p8: &'a Prepared<'p>,
    p16: &'a std::sync::OnceLock<Prepared<'p>>,
    budget: &'a Budget,
    depth: Depth,
    force: bool,
}

impl Paths<'_, '_> {
    fn one(&self, input: &Path, output: &Path, warn: &dyn Fn(&str)) -> Result<()> {
        let (img, _lease) = campro_eval::image_file::read(input, self.budget, warn)?;
        let (w, h) = (img.width(), img.height());
        let sixteen = matches!(img.color().bytes_per_pixel() / img.color().channel_count(), 2 | 4);
        let row = 3 * w as usize;
        if self.capture.enhancer.is_some() || (!sixteen && self.depth == Depth::Eight) {
            // 8 bits in and out: the exact path (AVX-512 blocks where the CPU has them),
            // bit-identical to the reference; the enhancer reads what an 8-bit camera gives.
            if sixteen {
                warn("--enhance: read as 8 bits (the enhancer takes the camera's 8-bit output)");
            }
            let src = img.into_rgb8().into_raw();
            let mut dst = vec![0u8; src.len()];
            self.capture.run(&src, &mut dst, w, h)?;
            drop(src);
            return write_atomic(output, &encode_png8(&dst, w, h)?, self.force);
        }
        let (src, prep): (Vec<u16>, &Prepared) = if sixteen {
            (img.into_rgb16().into_raw(), self.p16.get_or_init(|| Prepared::new(self.p8.params(), Depth::Sixteen)))
        } else {
            (img.into_rgb8().into_raw().into_iter().map(u16::from).collect(), self.p8)
        };
        let mut dst = vec![0u16; src.len()];
        src.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| prep.run(s, d, self.depth));
        drop(src);
        let png = encode_png(&dst, w, h, self.depth)?;
        write_atomic(output, &png, self.force)
    }
}

/// 8-bit RGB samples as a PNG.
fn encode_png8(samples: &[u8], w: u32, h: u32) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut buf = Vec::new();
    image::codecs::png::PngEncoder::new(&mut buf).write_image(samples, w, h, image::ExtendedColorType::Rgb8)?;
    Ok(buf)
}

/// RGB samples (codes of `depth`) as a PNG of that depth.
pub fn encode_png(samples: &[u16], w: u32, h: u32, depth: Depth) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    match depth {
        Depth::Eight => encode_png8(&samples.iter().map(|&v| v as u8).collect::<Vec<u8>>(), w, h),
        Depth::Sixteen => {
            let mut buf = Vec::new();
            let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_ne_bytes()).collect();
            image::codecs::png::PngEncoder::new(&mut buf).write_image(&bytes, w, h, image::ExtendedColorType::Rgb16)?;
            Ok(buf)
        }
    }
}
