//! `campro simulate`: the desktop pipeline on image files, videos and folders (each output
//! keeps its input's format: JPEG, PNG, TIFF or the video's container), and on one video
//! stream (standard input, a camera) into a file, standard output or a device.
//!
//! Hostile input is normal input here: inputs are regular files read with a byte cap;
//! links, FIFOs and devices inside folders are skipped with a warning; an output folder
//! inside an input folder is never read back; an output that would replace an input is
//! refused; every decode draws its memory from one budget shared by all jobs, so a
//! decompression bomb is refused by its header and several large images wait for each
//! other instead of adding up.

use crate::args::{BitDepth, Report, SimulateArgs};
use crate::capture::{Capture, Frame, Pixels};
use crate::output::file_key;
use crate::video::{self, Encoding, FrameFormat, Sink, Source};
use crate::write_atomic;
use anyhow::{anyhow, bail, Result};
use campro::pipeline::fast::Exact8;
use campro::pipeline::{Depth, Prepared};
use campro::Params;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// The file endings read as images.
const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "tif", "tiff", "webp"];
pub(crate) use campro_eval::image_file::Budget;

/// What a walk over the inputs found.
pub(crate) struct Inputs {
    /// (input file, output file).
    pub jobs: Vec<(PathBuf, PathBuf)>,
    /// Entries passed over, with why.
    pub skipped: Vec<(PathBuf, &'static str)>,
}

/// Which files a command reads, and what it says of the others when it passes them over.
pub(crate) struct Reads<'a> {
    pub reads: &'a dyn Fn(&Path) -> bool,
    /// The skip reason of a file it does not read ("not a PNG, JPEG, TIFF or video file").
    pub otherwise: &'static str,
}

/// Every (input file, output file) pair of the files `which` reads: folders are walked
/// recursively and mirrored; `name` turns a mirrored path into its output's (the ending).
/// Other files (sidecars such as `IMG_1.xmp` or `a.txt` beside `a.png`) are skipped with
/// a reason before outputs are compared, so they never collide with what is written.
pub(crate) fn collect_inputs(
    inputs: &[PathBuf],
    out: &Path,
    name: &dyn Fn(&Path) -> PathBuf,
    which: &Reads,
) -> Result<Inputs> {
    let out_abs = file_key(out);
    let mut found = Inputs { jobs: Vec::new(), skipped: Vec::new() };
    for input in inputs {
        let meta = std::fs::metadata(input).map_err(|e| anyhow!("{}: {e}", crate::shown(input)))?;
        if meta.is_dir() {
            if file_key(input) == out_abs {
                bail!("--output {}: is the input folder itself; outputs would replace inputs", crate::shown(out));
            }
            // Never descend into the output folder: what this run writes is not an input.
            let walk = walkdir::WalkDir::new(input).sort_by_file_name().into_iter();
            for entry in walk.filter_entry(|e| !(e.file_type().is_dir() && file_key(e.path()) == out_abs)) {
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
                if !(which.reads)(entry.path()) {
                    found.skipped.push((entry.path().to_path_buf(), skip_reason(entry.path(), which.otherwise)));
                    continue;
                }
                let rel = entry.path().strip_prefix(input).expect("walkdir yields paths under its root");
                found.jobs.push((entry.path().to_path_buf(), name(&out.join(rel))));
            }
        } else if meta.is_file() {
            let file = input.file_name().ok_or_else(|| anyhow!("{}: not a file name", crate::shown(input)))?;
            if !(which.reads)(input) {
                found.skipped.push((input.clone(), skip_reason(input, which.otherwise)));
                continue;
            }
            found.jobs.push((input.clone(), name(&out.join(Path::new(file)))));
        } else {
            bail!("{}: is not a regular file or folder", crate::shown(input));
        }
    }
    let mut seen = std::collections::HashSet::new();
    let sources: std::collections::HashSet<PathBuf> = found.jobs.iter().map(|(i, _)| file_key(i)).collect();
    for (i, o) in &found.jobs {
        if !seen.insert(o.clone()) {
            bail!("two inputs would both be written to {} (the second is {})", crate::shown(o), crate::shown(i));
        }
        if sources.contains(&file_key(o)) {
            bail!("--output: writing {} would replace an input; choose another output folder", crate::shown(o));
        }
    }
    Ok(found)
}

/// Where an input goes: a video keeps its container; an image keeps its format, or takes
/// `format` when one is asked; a HEIC photo (not written here) becomes a JPEG; a JPEG or
/// WebP at 16 bits becomes a PNG (neither has a 16-bit form); anything else becomes PNG.
pub(crate) fn output_for(path: &Path, depth: Depth, format: Option<ImageFormat>) -> PathBuf {
    if video::is_video(path) {
        return path.to_path_buf();
    }
    let own = if campro_eval::heif::named_heif(path) { Some(ImageFormat::Jpeg) } else { ImageFormat::of(path) };
    match format.or(own) {
        Some(f @ (ImageFormat::Jpeg | ImageFormat::Webp)) if depth == Depth::Eight => {
            path.with_extension(f.ending(path))
        }
        Some(f @ (ImageFormat::Png | ImageFormat::Tiff)) => path.with_extension(f.ending(path)),
        _ => path.with_extension("png"),
    }
}

/// The image formats `simulate` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ImageFormat {
    Png,
    Jpeg,
    Tiff,
    /// Lossless WebP (8 bits).
    Webp,
}

impl ImageFormat {
    /// The ending for this format: the path's own when it names this format already.
    fn ending(self, path: &Path) -> String {
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if Self::of(path) == Some(self) => e.to_string(),
            _ => match self {
                Self::Png => "png",
                Self::Jpeg => "jpg",
                Self::Tiff => "tif",
                Self::Webp => "webp",
            }
            .to_string(),
        }
    }

    /// The format a path names by its ending.
    pub(crate) fn of(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "png" => Some(Self::Png),
            "jpg" | "jpeg" => Some(Self::Jpeg),
            "tif" | "tiff" => Some(Self::Tiff),
            "webp" => Some(Self::Webp),
            _ => None,
        }
    }
}

/// Why a file a command does not read is passed over: `otherwise`, except HEIC/HEIF (every
/// iPhone's photos) on a machine without libheif, which gets the line saying what to do.
fn skip_reason(path: &Path, otherwise: &'static str) -> &'static str {
    if campro_eval::heif::named_heif(path) {
        return campro_eval::heif::MISSING;
    }
    otherwise
}

/// Whether `path` names an image read here: by its ending, HEIC/HEIF where libheif is.
pub(crate) fn is_image(path: &Path) -> bool {
    if campro_eval::heif::named_heif(path) {
        return campro_eval::heif::available();
    }
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        .unwrap_or(false)
}

/// One line for a whole run whose outputs exist already (unless `--force` or
/// `--skip-existing` says what to do with them): nothing is written, rather than an error
/// per file after the others were done.
fn refuse_existing(outputs: impl Iterator<Item = PathBuf>, existing: Existing) -> Result<()> {
    if existing != Existing::Refuse {
        return Ok(());
    }
    let (mut total, mut there, mut first) = (0usize, 0usize, None);
    for o in outputs {
        total += 1;
        if o.exists() {
            there += 1;
            first.get_or_insert(o);
        }
    }
    match first {
        None => Ok(()),
        Some(f) if total == 1 => {
            bail!("{} exists (use --force to overwrite, or --skip-existing); nothing was written", crate::shown(&f))
        }
        Some(f) => bail!(
            "{} exists, and {there} of {total} outputs in all; nothing was written: --force replaces them, --skip-existing does only the rest",
            crate::shown(&f)
        ),
    }
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

/// What became of one input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Written,
    /// Its output was there already (`--skip-existing`).
    Skipped,
    Failed,
}

/// One input's outcome: a line of `--format json`'s `files`.
#[derive(Debug, Clone, serde::Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Outcome {
    pub input: String,
    pub output: String,
    pub status: Status,
    /// Wall time of this input, milliseconds (one decimal).
    pub ms: f64,
    /// The one-line error of a failed input; null otherwise.
    pub error: Option<String>,
    /// Frames written (videos and streams).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<u64>,
    /// Frames a second sustained, and what the camera stage alone could do (streams).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub capacity_fps: Option<f64>,
    /// What the run let through and says so (grey input under `--allow-grey`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<&'static str>,
}

/// `--format json`: the output, the counts (from the outcomes) and each input's outcome.
#[derive(Debug, serde::Serialize)]
struct RunReport {
    output: String,
    written: usize,
    skipped: usize,
    failed: usize,
    files: Vec<Outcome>,
}

impl RunReport {
    fn new(output: &str, mut files: Vec<Outcome>) -> Self {
        files.sort_by(|a, b| a.input.cmp(&b.input));
        let n = |s| files.iter().filter(|f| f.status == s).count();
        RunReport {
            output: output.into(),
            written: n(Status::Written),
            skipped: n(Status::Skipped),
            failed: n(Status::Failed),
            files,
        }
    }
}

/// The one outcome path of every output (an image, a video file, a stream): skipped when
/// it exists under `--skip-existing`, refused when it exists without `--force`, else made by
/// `make` and its record written (`--record`; `jpeg`: the output's JPEG quality). Timed; a
/// failure's line names `input`. Nothing is printed here.
fn settle<T>(
    input: &Path,
    output: &Path,
    existing: Existing,
    record: Option<&crate::record::RunRecord>,
    jpeg: Option<u8>,
    make: impl FnOnce() -> Result<T>,
) -> (Outcome, Option<T>) {
    let started = std::time::Instant::now();
    let exists = output.exists();
    let r = if existing == Existing::Skip && exists {
        None
    } else if existing != Existing::Replace && exists {
        Some(Err(anyhow!("{} exists (use --force to overwrite, or --skip-existing)", crate::shown(output))))
    } else {
        Some(make().and_then(|made| {
            if let Some(rec) = record {
                rec.write(input, output, jpeg, existing == Existing::Replace)?;
            }
            Ok(made)
        }))
    };
    let (status, error, made) = match r {
        None => (Status::Skipped, None, None),
        Some(Ok(made)) => (Status::Written, None, Some(made)),
        Some(Err(e)) => (Status::Failed, Some(crate::about(input, &e)), None),
    };
    let outcome = Outcome {
        input: input.display().to_string(),
        output: output.display().to_string(),
        status,
        ms: (started.elapsed().as_secs_f64() * 1e4).round() / 10.0,
        error,
        frames: None,
        fps: None,
        capacity_fps: None,
        warnings: Vec::new(),
    };
    (outcome, made)
}

/// How `simulate` runs.
pub struct Options<'a> {
    /// Output bit depth of images; `Sixteen` also makes video frames 16-bit.
    pub depth: Depth,
    pub existing: Existing,
    /// Worker threads (all cores when `None`).
    pub jobs: Option<usize>,
    pub enc: &'a Encoding,
    pub enhancer: Option<&'a campro_eval::guard::GuardedEnhancer>,
    /// Print one JSON object on stdout at the end.
    pub json: bool,
    /// JPEG quality, 1..=100.
    pub quality: u8,
    /// Every image output in this format instead of its input's.
    pub image_format: Option<ImageFormat>,
    /// Raw standard input's frame size and rate, or a camera's.
    pub frames: FrameFormat,
    /// Stop every video after this many frames.
    pub max_frames: Option<u64>,
    /// Write grey input although the preset is not rated for it (`--allow-grey`).
    pub allow_grey: bool,
    /// Where the face detectors are that look at the faces of mostly colourless photos
    /// ([`crate::capture::GreyPolicy::check_picture`]); None: the whole frame only.
    pub models: Option<PathBuf>,
    /// What image outputs keep of their inputs' metadata.
    pub metadata: crate::metadata::Policy,
    /// Write a record beside each output (`--record`).
    pub record: Option<&'a crate::record::RunRecord>,
}

/// What `-` and device paths mean among the inputs and for the output: one video stream.
fn stream_job(inputs: &[PathBuf], out: &Path, o: &Options) -> Result<Option<(Source, Sink)>> {
    let is_dash = |p: &Path| p.as_os_str() == "-";
    let source_of = |i: &Path| -> Option<Source> {
        if is_dash(i) {
            Some(Source::Stdin(o.frames.clone()))
        } else if video::is_device(i) {
            Some(Source::Camera(i.to_path_buf(), o.frames.clone()))
        } else if video::url_scheme(i).is_some() {
            Some(Source::Url(i.to_string_lossy().into_owned(), o.frames.clone()))
        } else {
            None
        }
    };
    // A camera or loopback device named but absent: one line saying so, before any rule
    // about what else was asked of it.
    for d in inputs.iter().map(|i| i.as_path()).chain([out]) {
        if d.starts_with("/dev") && !d.exists() {
            bail!("{}: no such device (a camera is /dev/videoN: ls /dev/video* lists them; an output device comes from v4l2loopback)", crate::shown(d));
        }
    }
    let stream_in = inputs.iter().find_map(|i| source_of(i));
    let stream_out = if is_dash(out) {
        Some(Sink::Stdout)
    } else if video::is_device(out) {
        Some(Sink::Device(out.to_path_buf()))
    } else {
        None
    };
    if stream_in.is_none() && o.frames != FrameFormat::default() {
        bail!("--size, --rate and --stall: only for standard input (-), a camera (/dev/videoN) or a network stream (rtsp://…)");
    }
    if let Some(Source::Url(u, _)) = &stream_in {
        video::check_protocol(&video::url_scheme(Path::new(u)).unwrap_or_default())?;
        eprintln!("{}: a live network stream: its video only (no audio is kept)", crate::escape(u));
    }
    if stream_in.is_none() && stream_out.is_none() {
        return Ok(None);
    }
    if inputs.len() != 1 {
        bail!(
            "standard input, a camera, a network stream, standard output or a device: one input only ({} given)",
            inputs.len()
        );
    }
    let source = match stream_in {
        Some(s) => s,
        None if video::is_video(&inputs[0]) && inputs[0].is_file() => Source::File(inputs[0].clone()),
        None => bail!(
            "--output {}: streams a video; {} is not a video file (endings: {})",
            crate::shown(out),
            crate::shown(&inputs[0]),
            video::VIDEO_EXTENSIONS.join(", ")
        ),
    };
    let sink = match stream_out {
        Some(s) => s,
        None if video::is_video(out) && !out.is_dir() => Sink::File(o.enc.output_path(out)),
        None => bail!(
            "--output {}: with standard input, a camera or a network stream, give a video file name (endings: {}), - (standard output) or a V4L2 device",
            crate::shown(out),
            video::VIDEO_EXTENSIONS.join(", ")
        ),
    };
    if o.enc.codec == "rawvideo" && sink != Sink::Stdout {
        bail!("--codec rawvideo: raw frames go to standard output only (-o -)");
    }
    Ok(Some((source, sink)))
}

/// One input file and an output with an image or video ending that is not a folder: the
/// output is that file (`simulate P photo.jpg -o protected.jpg`), in the format its ending
/// names.
fn single_file(inputs: &[PathBuf], out: &Path) -> Result<Option<(PathBuf, PathBuf)>> {
    let [input] = inputs else { return Ok(None) };
    let named = video::is_video(out) || ImageFormat::of(out).is_some();
    if !named || out.is_dir() || !input.is_file() {
        return Ok(None);
    }
    if video::is_video(input) != video::is_video(out) {
        bail!(
            "--output {}: {} is {}; name a {} file or a folder",
            crate::shown(out),
            crate::shown(input),
            if video::is_video(input) { "a video" } else { "an image" },
            if video::is_video(input) { "video" } else { "PNG, JPEG, TIFF or WebP" }
        );
    }
    if file_key(input) == file_key(out) {
        bail!("--output: writing {} would replace its input", crate::shown(out));
    }
    Ok(Some((input.clone(), out.to_path_buf())))
}

/// One video stream: `source` into `sink`, through [`settle`] when the sink is a file.
fn stream(capture: &Capture, source: &Source, sink: &Sink, o: &Options, pool: &rayon::ThreadPool) -> Result<()> {
    if o.record.is_some() {
        bail!("--record: a record holds its input's hash, and standard input, a camera or a network stream is no file; simulate a file, or record the stream to a file first");
    }
    let job = video::Job {
        capture,
        enc: o.enc,
        force: o.existing == Existing::Replace,
        sixteen: o.depth == Depth::Sixteen,
        max_frames: o.max_frames,
        metadata: o.metadata,
    };
    let warn = |w: &str| eprintln!("warning: {}: {w}", source.shown());
    let run = || pool.install(|| video::simulate(&job, source, sink, &warn));
    let input = PathBuf::from(source.shown());
    // Standard output and a device are streams, not files that could be there already.
    let (mut outcome, done) = match sink {
        Sink::File(f) => settle(&input, f, o.existing, None, None, run),
        _ => settle(&input, Path::new(&sink_shown(sink)), Existing::Replace, None, None, run),
    };
    if let Some(done) = &done {
        eprintln!("{}", summary(&source.shown(), &sink_shown(sink), done));
        outcome.frames = Some(done.frames);
        outcome.fps = Some((done.fps * 10.0).round() / 10.0);
        outcome.capacity_fps = Some((done.capacity * 10.0).round() / 10.0);
    } else if outcome.status == Status::Skipped {
        eprintln!("skipped {}: {} is already there", source.shown(), outcome.output);
    }
    let error = outcome.error.clone();
    if o.json {
        print_json(&RunReport::new(&sink_shown(sink), vec![outcome]))?;
    }
    match error {
        Some(line) => bail!("{line}"),
        None => Ok(()),
    }
}

fn sink_shown(sink: &Sink) -> String {
    match sink {
        Sink::File(p) | Sink::Device(p) => crate::shown(p),
        Sink::Stdout => "standard output".into(),
    }
}

/// The line a finished video gets: frames, bits and the rate sustained against the source's.
fn summary(input: &str, output: &str, done: &video::Outcome) -> String {
    let bits = if done.sixteen { ", 16-bit frames" } else { "" };
    let rate = match done.source_fps {
        Some(s) => {
            format!("{:.1} frames a second, the camera stage alone {:.1}; the source's {s:.1}", done.fps, done.capacity)
        }
        None => format!("{:.1} frames a second", done.fps),
    };
    format!("simulated {} frames of {input} into {output} ({rate}{bits})", done.frames)
}

/// Prints the `--format json` object on stdout.
fn print_json(report: &RunReport) -> Result<()> {
    crate::say!("{}", serde_json::to_string_pretty(report)?);
    Ok(())
}

/// `campro simulate`: the arguments as [`Options`], then [`simulate`].
pub fn run(a: SimulateArgs) -> Result<()> {
    let SimulateArgs {
        params,
        inputs,
        output,
        bit_depth,
        quality,
        image_format,
        size,
        rate,
        stall,
        frames,
        force,
        jobs,
        codec,
        crf,
        bitrate,
        preset,
        enhance,
        scale,
        data,
        allow_grey,
        metadata,
        skip_existing,
        record,
        format,
    } = a;
    let enc = video::Encoding { codec, crf: Some(crf), bitrate, preset };
    let p = crate::load_params(&params)?;
    let enhancer =
        if enhance { Some(crate::capture::enhancer_of(&params, &p, scale, &data.models_dir())?) } else { None };
    let depth = match bit_depth {
        BitDepth::Eight => Depth::Eight,
        BitDepth::Sixteen => Depth::Sixteen,
    };
    let record = if record {
        use crate::record::{enhancer_bytes, preset_bytes, sha256};
        let enhancer = if enhance { Some(sha256(&enhancer_bytes(&params, &p)?)) } else { None };
        let preset = sha256(&preset_bytes(&params)?);
        Some(crate::record::RunRecord::new(params.display().to_string(), &p, preset, enhancer, depth, metadata)?)
    } else {
        None
    };
    let options = Options {
        depth,
        existing: match (force, skip_existing) {
            (true, _) => Existing::Replace,
            (_, true) => Existing::Skip,
            _ => Existing::Refuse,
        },
        jobs: jobs.map(|j| j as usize),
        enc: &enc,
        enhancer: enhancer.as_ref(),
        json: matches!(format, Report::Json),
        quality,
        image_format,
        frames: video::FrameFormat { size, rate, stall },
        max_frames: frames,
        allow_grey,
        models: Some(data.models_dir()),
        metadata,
        record: record.as_ref(),
    };
    simulate(&p, &inputs, &output, &options)
}

/// Runs `p` over every image and video under `inputs` into images and videos under `out`
/// (or one video stream, see [`stream_job`]); with `json`, prints what happened to each
/// input (written, skipped, failed, with its time) as one JSON object on stdout.
pub fn simulate(p: &Params, inputs: &[PathBuf], out: &Path, o: &Options) -> Result<()> {
    let force = o.existing == Existing::Replace;
    let threads = crate::args::cores_for("--jobs", o.jobs);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    // The 16-bit degamma table (65536 powers) is built only if a 16-bit image turns up.
    let prepared8 = Prepared::new(p, Depth::Eight);
    let fast8 = Exact8::new(p);
    let prepared16 = std::sync::OnceLock::new();
    let mut grey = crate::capture::GreyPolicy::new(p, o.allow_grey);
    if let Some(models) = &o.models {
        grey = grey.with_faces(models);
    }
    let capture = Capture { fast8: &fast8, p8: &prepared8, p16: &prepared16, enhancer: o.enhancer, grey: &grey };
    if let Some((source, sink)) = stream_job(inputs, out, o)? {
        return stream(&capture, &source, &sink, o, &pool);
    }
    let enc = o.enc;
    if enc.codec == "rawvideo" {
        bail!("--codec rawvideo: raw frames go to standard output only (-o -)");
    }
    let found = match single_file(inputs, out)? {
        Some(job) => Inputs { jobs: vec![job], skipped: Vec::new() },
        None => collect_inputs(
            inputs,
            out,
            &|p| output_for(p, o.depth, o.image_format),
            &Reads {
                reads: &|p| is_image(p) || video::is_video(p),
                otherwise: "not a PNG, JPEG, TIFF, WebP or video file",
            },
        )?,
    };
    for (i, why) in &found.skipped {
        eprintln!("warning: skipping {}: {why}", crate::shown(i));
    }
    let (videos, images): (Vec<_>, Vec<_>) = found.jobs.into_iter().partition(|(i, _)| video::is_video(i));
    if images.is_empty() && videos.is_empty() {
        bail!("no PNG, JPEG, TIFF, WebP or video file among the inputs: nothing to do");
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
    refuse_existing(
        images.iter().map(|(_, o)| o.clone()).chain(videos.iter().map(|(_, w)| enc.output_path(w))),
        o.existing,
    )?;
    let bar = if images.len() > 4 {
        crate::output::count_bar("", images.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let budget = Budget::global();
    let paths = Paths { capture: &capture, budget, depth: o.depth, force, quality: o.quality, metadata: o.metadata };
    let mut outcomes: Vec<Outcome> = pool.install(|| {
        images
            .par_iter()
            .map(|(i, out)| {
                let jpeg = matches!(ImageFormat::of(out), Some(ImageFormat::Jpeg)).then_some(o.quality);
                let warn = |w: &str| bar.suspend(|| eprintln!("warning: {}: {w}", crate::shown(i)));
                let (mut outcome, grey) = settle(i, out, o.existing, o.record, jpeg, || paths.one(i, out, &warn));
                if grey == Some(true) {
                    outcome.warnings.push(crate::capture::GREY_ALLOWED);
                }
                if let Some(line) = &outcome.error {
                    bar.suspend(|| eprintln!("error: {line}"));
                }
                bar.inc(1);
                outcome
            })
            .collect()
    });
    bar.finish_and_clear();
    if !images.is_empty() {
        let n = |s| outcomes.iter().filter(|f: &&Outcome| f.status == s).count();
        let skipped = n(Status::Skipped);
        let note = if skipped > 0 { format!(" ({skipped} skipped: already there)") } else { String::new() };
        eprintln!("simulated {} of {} images into {}{note}", n(Status::Written), images.len(), crate::shown(out));
    }
    // Videos one after another, each frame on every core.
    for (i, wanted) in &videos {
        let out = enc.output_path(wanted);
        if &out != wanted {
            eprintln!(
                "note: {} is written as {} ({} needs Matroska)",
                crate::shown(wanted),
                crate::shown(&out),
                enc.codec
            );
        }
        let warn = |w: &str| eprintln!("warning: {}: {w}", crate::shown(i));
        let job = video::Job {
            capture: &capture,
            enc,
            force,
            sixteen: o.depth == Depth::Sixteen,
            max_frames: o.max_frames,
            metadata: o.metadata,
        };
        let (mut outcome, done) = settle(i, &out, o.existing, o.record, None, || {
            pool.install(|| video::simulate(&job, &Source::File(i.clone()), &Sink::File(out.clone()), &warn))
        });
        match (&done, &outcome.error) {
            (Some(done), _) => {
                eprintln!("{}", summary(&crate::shown(i), &crate::shown(&out), done));
                outcome.frames = Some(done.frames);
            }
            (None, Some(line)) => eprintln!("error: {line}"),
            (None, None) => eprintln!("skipped {}: {} is already there", crate::shown(i), crate::shown(&out)),
        }
        outcomes.push(outcome);
    }
    let report = RunReport::new(&out.display().to_string(), outcomes);
    if o.json {
        print_json(&report)?;
    }
    if report.failed > 0 {
        bail!("{} input(s) failed", report.failed);
    }
    Ok(())
}

/// What every job shares.
pub(crate) struct Paths<'a, 'p> {
    pub capture: &'a Capture<'a, 'p>,
    pub budget: &'a Budget,
    pub depth: Depth,
    pub force: bool,
    pub quality: u8,
    pub metadata: crate::metadata::Policy,
}

impl Paths<'_, '_> {
    /// Simulates one image; Ok(true) when it was grey and let through (`--allow-grey`).
    fn one(&self, input: &Path, output: &Path, warn: &dyn Fn(&str)) -> Result<bool> {
        let bytes = campro::file::read_capped(input, campro_eval::image_file::MAX_FILE_BYTES, "an image")?;
        self.one_of(input, &bytes, output, warn)
    }

    /// [`Paths::one`] on the input's bytes, already read (`input` names them).
    pub(crate) fn one_of(&self, input: &Path, bytes: &[u8], output: &Path, warn: &dyn Fn(&str)) -> Result<bool> {
        let (file, grey) = self.encoded(input, bytes, output, warn)?;
        write_atomic(output, &file, self.force)?;
        Ok(grey)
    }

    /// The file [`Paths::one_of`] writes to `output` (its format from `output`'s ending),
    /// and whether the input was grey and let through.
    pub(crate) fn encoded(
        &self,
        input: &Path,
        bytes: &[u8],
        output: &Path,
        warn: &dyn Fn(&str),
    ) -> Result<(Vec<u8>, bool)> {
        let (img, _lease, meta) = campro_eval::image_file::decode_with_metadata(
            input,
            bytes,
            self.budget,
            // An 8-bit picture written at 16 bits is widened: the difference is this job's.
            &|w, h| {
                let wide = if self.depth == Depth::Sixteen {
                    (w as u64 * h as u64).saturating_mul(
                        campro_eval::image_file::PEAK_BYTES_PER_PIXEL - campro_eval::image_file::PEAK_BYTES_PER_PIXEL_8,
                    )
                } else {
                    0
                };
                self.capture.work(w, h).saturating_add(wide)
            },
            warn,
        )?;
        let kept = crate::metadata::kept(self.metadata, meta.exif.as_deref(), meta.icc, warn);
        let (w, h) = (img.width(), img.height());
        let sixteen = crate::capture::sixteen_bit(&img);
        let format = ImageFormat::of(output).unwrap_or(ImageFormat::Png);
        let (pixels, grey) = if sixteen && self.capture.enhancer.is_none() {
            let src = img.into_rgb16().into_raw();
            self.capture.picture(Frame::Sixteen(&src), w, h, self.depth, warn)?
        } else {
            if sixteen {
                warn("--enhance: read as 8 bits (the enhancer takes the camera's 8-bit output)");
            }
            self.capture.picture8(img.into_rgb8().into_raw(), w, h, self.depth, warn)?
        };
        Ok((encode(format, pixels.samples(), w, h, self.quality, &kept)?, grey))
    }
}

/// RGB samples of 8 or 16 bits.
pub(crate) enum Samples<'a> {
    Eight(&'a [u8]),
    Sixteen(&'a [u16]),
}

impl Pixels {
    /// The samples, borrowed.
    pub(crate) fn samples(&self) -> Samples<'_> {
        match self {
            Pixels::Eight(v) => Samples::Eight(v),
            Pixels::Sixteen(v) => Samples::Sixteen(v),
        }
    }
}

/// `samples` (a `w` x `h` RGB image) as a file of `format`; JPEG at `quality` (8 bits
/// only), carrying the `kept` metadata where the format can (TIFF takes no EXIF here).
pub(crate) fn encode(
    format: ImageFormat,
    samples: Samples,
    w: u32,
    h: u32,
    quality: u8,
    kept: &crate::metadata::Kept,
) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let (bytes, color) = match samples {
        Samples::Eight(s) => (std::borrow::Cow::Borrowed(s), image::ExtendedColorType::Rgb8),
        Samples::Sixteen(s) => {
            (std::borrow::Cow::Owned(s.iter().flat_map(|v| v.to_ne_bytes()).collect()), image::ExtendedColorType::Rgb16)
        }
    };
    let mut buf = std::io::Cursor::new(Vec::new());
    // An encoder that cannot carry a block leaves it out (the output is still written).
    fn with<E: ImageEncoder>(mut e: E, kept: &crate::metadata::Kept) -> E {
        if let Some(icc) = &kept.icc {
            let _ = e.set_icc_profile(icc.clone());
        }
        if let Some(exif) = &kept.exif {
            let _ = e.set_exif_metadata(exif.clone());
        }
        e
    }
    match format {
        ImageFormat::Png => {
            with(image::codecs::png::PngEncoder::new(&mut buf), kept).write_image(&bytes, w, h, color)?
        }
        ImageFormat::Tiff => {
            with(image::codecs::tiff::TiffEncoder::new(&mut buf), kept).write_image(&bytes, w, h, color)?
        }
        ImageFormat::Jpeg => with(image::codecs::jpeg::JpegEncoder::new_with_quality(&mut buf, quality), kept)
            .write_image(&bytes, w, h, color)?,
        ImageFormat::Webp => {
            with(image::codecs::webp::WebPEncoder::new_lossless(&mut buf), kept).write_image(&bytes, w, h, color)?
        }
    }
    Ok(buf.into_inner())
}

/// RGB samples (codes of `depth`) as a PNG of that depth.
pub fn encode_png(samples: &[u16], w: u32, h: u32, depth: Depth) -> Result<Vec<u8>> {
    match depth {
        Depth::Eight => {
            let eight: Vec<u8> = samples.iter().map(|&v| v as u8).collect();
            encode(ImageFormat::Png, Samples::Eight(&eight), w, h, 100, &Default::default())
        }
        Depth::Sixteen => encode(ImageFormat::Png, Samples::Sixteen(samples), w, h, 100, &Default::default()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `settle` with a `make` that writes "new" into the output and counts its calls.
    fn settled(out: &Path, existing: Existing, calls: &std::cell::Cell<u32>) -> Outcome {
        let make = || {
            calls.set(calls.get() + 1);
            write_atomic(out, b"new", existing == Existing::Replace)
        };
        settle(Path::new("in.png"), out, existing, None, None, make).0
    }

    #[test]
    fn one_outcome_path_skips_refuses_or_replaces_what_is_there() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.png");
        let calls = std::cell::Cell::new(0);
        // Absent: made under every policy.
        let first = settled(&out, Existing::Refuse, &calls);
        assert_eq!((first.status, calls.get()), (Status::Written, 1));
        assert_eq!(std::fs::read(&out).unwrap(), b"new");
        std::fs::write(&out, b"old").unwrap();
        // There: skipped untouched, refused untouched with the one line, or replaced.
        let skipped = settled(&out, Existing::Skip, &calls);
        assert_eq!((skipped.status, skipped.error.as_deref(), calls.get()), (Status::Skipped, None, 1));
        let refused = settled(&out, Existing::Refuse, &calls);
        assert_eq!((refused.status, calls.get()), (Status::Failed, 1));
        let line = refused.error.unwrap();
        assert!(line.starts_with("in.png: ") && line.contains("exists (use --force"), "{line}");
        assert_eq!(std::fs::read(&out).unwrap(), b"old");
        let replaced = settled(&out, Existing::Replace, &calls);
        assert_eq!((replaced.status, calls.get()), (Status::Written, 2));
        assert_eq!(std::fs::read(&out).unwrap(), b"new");
        // A failing `make`: its line names the input.
        let (failed, made) =
            settle(Path::new("x.png"), &dir.path().join("y.png"), Existing::Refuse, None, None, || -> Result<()> {
                bail!("broken")
            });
        assert_eq!((failed.status, failed.error.as_deref(), made), (Status::Failed, Some("x.png: broken"), None));
    }

    #[test]
    fn the_json_report_counts_its_outcomes_and_names_keys_as_before() {
        let o = |input: &str, status| Outcome {
            input: input.into(),
            output: "o".into(),
            status,
            ms: 1.0,
            error: None,
            frames: (input == "a.mp4").then_some(3),
            fps: None,
            capacity_fps: (input == "a.mp4").then_some(2.5),
            warnings: Vec::new(),
        };
        let r =
            RunReport::new("out", vec![o("c", Status::Failed), o("a.mp4", Status::Written), o("b", Status::Skipped)]);
        assert_eq!((r.written, r.skipped, r.failed), (1, 1, 1));
        let v = serde_json::to_value(&r).unwrap();
        assert_eq!(v["files"][0]["input"], "a.mp4", "sorted by input");
        assert_eq!(v["files"][0]["capacityFps"], 2.5);
        assert_eq!(v["files"][0]["frames"], 3);
        assert!(v["files"][1].get("frames").is_none() && v["files"][1]["error"].is_null());
        assert_eq!(v["files"][2]["status"], "failed");
    }
}
