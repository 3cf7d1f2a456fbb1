//! `campro`: the desktop command-line tool. It only parses arguments, reads and writes
//! files and prints; every computation is a call into the `campro` library.

mod bench;
mod capture;
mod eval;
mod inspect;
mod man;
mod presets;
mod retrain;
mod simulate;
mod train;
mod video;

use anyhow::{anyhow, bail, Context, Result};
use campro::ccm::{self, Mat3};
use campro::compare;
use campro::emulate::DeviceModel;
use campro::pipeline::{Depth, Prepared};
use campro::targets::camera2::{self, Camera2, Options, RationalMode};
use campro::targets::{Condition, Support};
use campro::Params;
use campro_testkit::stress;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The recommended preset: `campro demo`'s default. Of the learnt sets it is the most
/// useful one that meets both privacy targets on the paper's protocol (trained/README.md).
const DEFAULT_PARAMS: &str = include_str!("../../../params/campro-omega-0.5.json");
/// The file name [`DEFAULT_PARAMS`] is bundled as, for messages.
const DEFAULT_PARAMS_FILE: &str = "params/campro-omega-0.5.json";

/// What a PARAMS argument is, in every command's help.
const PARAMS_HELP: &str = "Parameter set: a bundled preset's name (campro presets lists them) or a JSON file";

#[derive(Parser)]
#[command(
    name = "campro",
    version,
    arg_required_else_help = true,
    about = "CamPro anti-facial-recognition ISP parameters: simulate, convert to Camera2, compare"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Check parameter files; prints a summary of each, fails on the first broken rule.
    Validate {
        /// Parameter files (JSON, format campro-params v1).
        #[arg(required = true)]
        params: Vec<PathBuf>,
        /// Text (one line per file) or one JSON object per file, one a line.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell) to stdout.
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Print a manual page (roff) to stdout, `campro man > campro.1`, or a command's
    /// (`campro man eval privacy`); with -o, write one page per command into a folder; with
    /// --markdown, the whole reference as Markdown (docs/cli.md).
    Man {
        /// The command whose page to print (default: campro's own page).
        command: Vec<String>,
        /// Write campro.1 and one page per command (campro-simulate.1, campro-eval-privacy.1,
        /// ...) into this folder.
        #[arg(short, long, conflicts_with_all = ["command", "markdown"])]
        output: Option<PathBuf>,
        /// Print every command's help as one Markdown page instead.
        #[arg(long, conflicts_with = "command")]
        markdown: bool,
        /// Replace pages that exist in the output folder.
        #[arg(long, requires = "output")]
        force: bool,
    },
    /// Convert a CamPro checkpoint (Pipeline.save .pt) to a parameter file.
    ImportPt {
        /// The checkpoint.
        checkpoint: PathBuf,
        /// Output parameter file.
        #[arg(short, long)]
        output: PathBuf,
        /// Overwrite an existing output.
        #[arg(long)]
        force: bool,
    },
    /// Map parameters onto a camera stack (Camera2: COLOR_CORRECTION_TRANSFORM, TONEMAP_CURVE).
    Convert {
        #[arg(help = PARAMS_HELP)]
        params: PathBuf,
        /// The camera stack: camera2 (JSON or Kotlin values), or a file for another stack
        /// (rpi-*, rkaiq-*, cube, hald; campro convert --help lists them).
        #[arg(long, default_value = "camera2", value_parser = target_names())]
        target: String,
        #[command(flatten)]
        device: DeviceArgs,
        #[command(flatten)]
        files: FileTargetArgs,
        /// Camera2 values as JSON, or as Kotlin statements for a CaptureRequest.Builder.
        #[arg(long, value_enum, default_value_t = Format::Json)]
        format: Format,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Replace the output file if it exists.
        #[arg(long)]
        force: bool,
    },
    /// Run the desktop pipeline on images and videos (files, folders, standard input, a
    /// camera): each output keeps its input's format (JPEG, PNG, TIFF, the video's container).
    Simulate {
        #[arg(help = PARAMS_HELP)]
        params: PathBuf,
        /// Images, videos or folders (recursive); `-` reads one video from standard input
        /// (a container, or raw RGB frames with --size); /dev/videoN a live camera (Linux).
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// Output folder; for one video also a video file name, `-` (standard output,
        /// Matroska) or a V4L2 output device (v4l2loopback).
        #[arg(short, long)]
        output: PathBuf,
        /// Output bit depth of images; 16 also gives video 16-bit frames (video of more
        /// than 8 bits gets them anyway).
        #[arg(long, value_enum, default_value_t = BitDepth::Eight)]
        bit_depth: BitDepth,
        /// JPEG quality of JPEG outputs (a JPEG input stays JPEG), 1 to 100.
        #[arg(long, default_value_t = 92, value_parser = clap::value_parser!(u8).range(1..=100))]
        quality: u8,
        /// Write every image in this format instead of its input's (png for exact work:
        /// a JPEG output is lossy).
        #[arg(long, value_enum)]
        image_format: Option<simulate::ImageFormat>,
        /// Raw standard input's frame size (WxH, 8-bit RGB), or the size asked of a camera.
        #[arg(long, value_parser = parse_size)]
        size: Option<(u32, u32)>,
        /// Raw standard input's frame rate (default 30), or the rate asked of a camera
        /// (frames a second: 30, 29.97 or 30000/1001).
        #[arg(long, value_parser = parse_rate)]
        rate: Option<String>,
        /// Stop each video after this many frames (a live camera runs until Ctrl-C without).
        #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
        frames: Option<u64>,
        /// Overwrite existing outputs.
        #[arg(long)]
        force: bool,
        /// Worker threads (default: all cores; more than the cores is clamped, with a warning).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
        jobs: Option<u32>,
        /// Video encoder (ffmpeg's name): libx264, libx265, libvpx-vp9, ffv1 (lossless, in Matroska), ...
        #[arg(long, default_value = "libx264")]
        codec: String,
        /// Video constant quality (lower is better; H.264's 18 looks lossless to most).
        #[arg(long, default_value_t = 18, value_parser = clap::value_parser!(u32).range(0..=63), conflicts_with = "bitrate")]
        crf: u32,
        /// Video bitrate instead of --crf (ffmpeg's -b:v, e.g. 8M).
        #[arg(long, value_parser = parse_bitrate)]
        bitrate: Option<String>,
        /// Video encoder preset (libx264/libx265: ultrafast ... veryslow).
        #[arg(long)]
        preset: Option<String>,
        /// Also run the preset's image enhancer (provenance.enhancer, from campro
        /// train-enhancer) on the camera's 8-bit output: what a human viewer is shown.
        #[arg(long, conflicts_with = "bit_depth")]
        enhance: bool,
        #[command(flatten)]
        scale: capture::ScaleArg,
        /// Leave outputs that exist and skip their inputs (re-runs do only what is missing).
        #[arg(long, conflicts_with = "force")]
        skip_existing: bool,
        /// Progress on stderr only, or also one JSON object on stdout: each input's output,
        /// status (written, skipped, failed) and time.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
    /// Look at what a parameter set does to your images: raw | protected side by side with
    /// the faces (YuNet) and people (person detector) found on each, a JSON of the
    /// detections per image, and OUTPUT/index.html linking them.
    Inspect {
        #[arg(help = PARAMS_HELP)]
        params: PathBuf,
        /// Images or folders (recursive).
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// Output folder (new or empty, unless --force).
        #[arg(short, long)]
        output: PathBuf,
        /// The shared data folder (default: $CAMPRO_SHARED or ../shared).
        #[arg(long)]
        shared: Option<PathBuf>,
        /// Folder of the model files (default: SHARED/models).
        #[arg(long)]
        models: Option<PathBuf>,
        /// Person detector: a bundled name or a manifest file.
        #[arg(long, default_value = "yolox-nano")]
        person_detector: String,
        /// Find people on the protected panel with the detector fine-tuned for PARAMS
        /// (its provenance.detector), as the camera's user would.
        #[arg(long)]
        own_detector: bool,
        /// Draw and list people scored at least this, in [0, 1].
        #[arg(long, default_value_t = 0.25, value_parser = eval::parse_confidence)]
        confidence: f64,
        /// Write into an output folder that already holds files.
        #[arg(long)]
        force: bool,
        /// A line per image, or the index as one JSON object.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
        /// Add a third panel: the preset's image enhancer on the protected image
        /// (provenance.enhancer), with what each detector finds there.
        #[arg(long)]
        enhance: bool,
        #[command(flatten)]
        scale: capture::ScaleArg,
    },
    /// Compare a simulated Camera2 device with the desktop pipeline (grey levels, RGB cube, random pixels, the chart).
    Compare {
        #[arg(help = PARAMS_HELP)]
        params: PathBuf,
        /// The camera stack to emulate (camera2, rpi-*, rkaiq-*, cube, hald).
        #[arg(long, default_value = "camera2", value_parser = target_names())]
        target: String,
        #[command(flatten)]
        files: FileTargetArgs,
        #[command(flatten)]
        device: DeviceArgs,
        /// Emulate a HAL that rounds matrix entries to this many fractional bits (0 to 52).
        #[arg(long, value_parser = clap::value_parser!(u32).range(0..=52))]
        matrix_frac_bits: Option<u32>,
        /// Emulate a device LUT of this many evenly spaced entries (2 to 65536).
        #[arg(long, value_parser = clap::value_parser!(u32).range(2..=65536))]
        lut_size: Option<u32>,
        /// Random pixels to test (1 to 10,000,000).
        #[arg(long, default_value_t = 100_000, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
        random: u32,
        /// Seed of the random pixels.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// A text report, or one JSON object.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
    /// Print the run-time-versus-error table (image paths, Camera2 updates, skips) as Markdown;
    /// `bench train` times the optimiser's steps.
    #[command(args_conflicts_with_subcommands = true)]
    Bench {
        #[command(subcommand)]
        what: Option<BenchWhat>,
        /// Parameters to use instead of a strong, paper-like set.
        #[arg(long)]
        params: Option<PathBuf>,
        /// Fewer repetitions and a smaller error sample (for CI).
        #[arg(long)]
        quick: bool,
        /// A Markdown table, or one JSON object.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
    /// Randomised numerical soak: adversarial cases checked against every invariant until time runs out.
    Stress {
        /// How long to run.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// First seed (cases use seed, seed+1, ...).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// A summary line, or one JSON object.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
    /// Evaluate privacy (face recognition), utility (person detection) and image quality with real models.
    Eval {
        #[command(subcommand)]
        what: Box<eval::EvalCmd>,
    },
    /// Learn CamPro parameters against a face-recognition attacker (Algorithm 1; privacy player).
    Train {
        /// TOML configuration (every key optional: the paper's defaults).
        config: PathBuf,
        /// The learnt parameter set (JSON, as `convert`, `simulate` and `eval` read it).
        #[arg(short, long, default_value = "campro-trained.json")]
        output: PathBuf,
        /// The training log (CSV, one line per round), with LOG-losses.svg and LOG-accuracy.svg.
        #[arg(long)]
        log: Option<PathBuf>,
        /// Checkpoint folder (every budget.checkpoint_every rounds and at the end).
        #[arg(long)]
        checkpoints: Option<PathBuf>,
        /// Resume from this checkpoint folder (same configuration and face set).
        #[arg(long)]
        resume: Option<PathBuf>,
        /// Start the camera from this parameter set (evenly spaced knots, camera.knots of
        /// them, degamma camera.gamma) instead of the identity.
        #[arg(long, conflicts_with = "resume")]
        init: Option<PathBuf>,
        /// Replace existing output files.
        #[arg(long)]
        force: bool,
    },
    /// Fine-tune the person detector behind a parameter set's camera (the paper's utility
    /// protocol), for `eval utility --own-detector`: writes PARAMS.detector.onnx and
    /// PARAMS.detector.json beside PARAMS and names them in its provenance.
    FinetuneDetector {
        /// The parameter set (JSON); its provenance gains `detector`.
        params: PathBuf,
        /// TOML configuration whose `[detector]` and `seed` are used (default: the paper's).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Detector steps of `detector.batch` images.
        #[arg(long, default_value_t = 500)]
        steps: usize,
        /// Stop after this many seconds even if steps remain.
        #[arg(long, default_value_t = f64::INFINITY)]
        seconds: f64,
        /// The fine-tuning log (CSV, one line per step).
        #[arg(long)]
        log: Option<PathBuf>,
        /// Replace existing detector files and log.
        #[arg(long)]
        force: bool,
    },
    /// Train the image enhancer of a parameter set (paper Sec. IV-D: a U-Net from captured
    /// images back to the scene, faces left unrestored): writes PARAMS.enhancer.onnx and
    /// PARAMS.enhancer.json beside PARAMS and names them in its provenance. With
    /// data.faces = "restore" it trains the restoration attacker's network instead
    /// (PARAMS.restorer.*, for eval privacy --attack restore-net).
    TrainEnhancer(train::TrainEnhancerArgs),
    /// List the bundled presets (usable by name anywhere: `campro simulate campro-omega-0.5 ...`).
    Presets {
        /// Readable text, or one JSON array.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
    /// Run the recommended learnt preset (or --params) on a built-in chart: before/after PNGs, Camera2 values, error report.
    Demo {
        /// Output folder.
        #[arg(short, long, default_value = "campro-demo")]
        output: PathBuf,
        /// Parameters to use instead of the recommended preset.
        #[arg(long)]
        params: Option<PathBuf>,
        /// Write into an output folder that already holds files.
        #[arg(long)]
        force: bool,
        /// Readable text, or one JSON object.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
}

#[derive(Subcommand)]
enum BenchWhat {
    /// Medians of the optimiser's training steps: MobileFaceNet 8x3x112x96 and YOLOX-Nano
    /// 1x3x416x416 (forward, sum, backward; the PyTorch anchor's shapes) and the attacker,
    /// privacy and detector steps at the configuration's shapes.
    Train(train::BenchTrainArgs),
    /// The enhancer's cost per U-Net size: parameters, multiply-accumulates per pixel, ONNX
    /// bytes, tract's time per 640x480 frame on one thread and a training step's time.
    Enhancer(train::BenchEnhancerArgs),
}

#[derive(Args, Clone)]
struct DeviceArgs {
    /// The device's colour transform, nine numbers row-major (A11 A12 A13 A21 ... A33).
    #[arg(long, num_args = 9, allow_negative_numbers = true, value_name = "A", conflicts_with = "capture_result")]
    device_ccm: Option<Vec<f64>>,
    /// A saved capture result (JSON with colorCorrectionTransform) giving the device transform.
    #[arg(long)]
    capture_result: Option<PathBuf>,
    /// The device's white-balance gains metered with its transform (R G_EVEN G_ODD B, each in
    /// (0, 64]): printed into the Kotlin statements and the JSON (a capture result's
    /// colorCorrectionGains give them too).
    #[arg(long, num_args = 4, value_name = "G", conflicts_with = "capture_result", value_parser = parse_gain)]
    device_gains: Option<Vec<f32>>,
    /// Colour temperature (K, 1000 to 40000) at which to interpolate the parameter file's ct_calibration.
    #[arg(long, allow_negative_numbers = true, conflicts_with_all = ["device_ccm", "capture_result"], value_parser = parse_ct)]
    ct: Option<f64>,
    /// The device's TONEMAP_MAX_CURVE_POINTS (2 to 65536).
    #[arg(long, default_value_t = camera2::DEFAULT_MAX_CURVE_POINTS as u32, value_parser = clap::value_parser!(u32).range(2..=65536))]
    max_curve_points: u32,
    /// Rationals: best approximation with denominators up to this.
    #[arg(long, default_value_t = camera2::DEFAULT_MAX_DENOMINATOR, conflicts_with = "fixed_denominator")]
    max_denominator: u32,
    /// Rationals: every entry over this fixed denominator (e.g. 1024) instead.
    #[arg(long)]
    fixed_denominator: Option<u32>,
}

/// `--bitrate`: digits with an optional k, M or G (ffmpeg's -b:v).
fn parse_bitrate(s: &str) -> std::result::Result<String, String> {
    let digits = s.trim_end_matches(['k', 'K', 'M', 'G']);
    if !digits.is_empty()
        && digits.len() <= 12
        && digits.bytes().all(|b| b.is_ascii_digit())
        && s.len() - digits.len() <= 1
    {
        Ok(s.to_string())
    } else {
        Err(format!("must be a bitrate such as 8M or 2500k, got {s}"))
    }
}

/// `--device-gains`: a white-balance gain in (0, 64].
fn parse_gain(s: &str) -> std::result::Result<f32, String> {
    camera2::gain(s.parse().ok())
        .ok_or_else(|| format!("must be a gain in (0, {}], got {}", camera2::MAX_GAIN, short(s, 40)))
}

/// `--size`: WxH, each side 1 to 16384 pixels.
fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let side = |v: &str| v.parse::<u32>().ok().filter(|v| (1..=16384).contains(v));
    s.split_once(['x', 'X'])
        .and_then(|(w, h)| Some((side(w)?, side(h)?)))
        .ok_or_else(|| format!("must be WIDTHxHEIGHT with sides of 1 to 16384 pixels, got {}", short(s, 40)))
}

/// `--rate`: frames a second, a positive number (`29.97`) or fraction (`30000/1001`) up to 1000.
fn parse_rate(s: &str) -> std::result::Result<String, String> {
    let num = |v: &str| v.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0);
    let value = match s.split_once('/') {
        Some((n, d)) if n.bytes().all(|b| b.is_ascii_digit()) && d.bytes().all(|b| b.is_ascii_digit()) => {
            num(n).zip(num(d)).map(|(n, d)| n / d)
        }
        Some(_) => None,
        None if s.len() <= 12 && s.bytes().all(|b| b.is_ascii_digit() || b == b'.') => num(s),
        None => None,
    };
    match value {
        Some(v) if v <= 1000.0 => Ok(s.to_string()),
        _ => Err(format!("must be frames a second up to 1000 (30, 29.97 or 30000/1001), got {}", short(s, 40))),
    }
}

/// `--ct`: a finite colour temperature in the calibration range.
fn parse_ct(s: &str) -> std::result::Result<f64, String> {
    let (lo, hi) = campro::color_temp::CT_RANGE;
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        _ => Err(format!("must be a colour temperature in [{lo}, {hi}] K, got {s}")),
    }
}

/// The registered stack names, for `--target` (`campro convert --help` lists them).
fn target_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        campro::targets::REGISTRY.iter().map(|e| clap::builder::PossibleValue::new(e.name).help(e.about)),
    )
}

/// Options of the file-based targets.
#[derive(Args, Clone)]
struct FileTargetArgs {
    /// The stack's own tuning / IQ file to patch (Raspberry Pi, Rockchip).
    #[arg(long)]
    base: Option<PathBuf>,
    /// Points per axis of a .cube LUT.
    #[arg(long, default_value_t = 33)]
    cube_size: usize,
    /// Hald CLUT level L (an L^3 x L^3 image, L^2 points per axis).
    #[arg(long, default_value_t = 8)]
    hald_level: usize,
    /// Clamp values the stack cannot hold (saying which) instead of refusing them.
    #[arg(long)]
    clamp: bool,
}

impl DeviceArgs {
    /// The option the device transform came from, as the user typed it.
    fn flag(&self) -> String {
        match &self.capture_result {
            Some(f) => format!("--capture-result {}", crate::shown(f)),
            None if self.ct.is_some() => "--ct".into(),
            None => "--device-ccm".into(),
        }
    }

    /// The files these options read.
    fn paths(&self) -> Vec<&Path> {
        self.capture_result.iter().map(PathBuf::as_path).collect()
    }
}

impl FileTargetArgs {
    /// The files these options read.
    fn paths(&self) -> Vec<&Path> {
        self.base.iter().map(PathBuf::as_path).collect()
    }

    /// The core target called `name` with these options (and `camera2`'s device
    /// settings), refusing the stacks that cannot hold a curve.
    fn target(&self, name: &str, camera2: Camera2) -> Result<Box<dyn campro::targets::Target>> {
        let entry = campro::targets::entry(name).ok_or_else(|| anyhow!("--target: unknown target {name}"))?;
        match (entry.name, entry.support) {
            (_, Support::Refused(_)) => bail!("{}", campro::targets::refusal(name).unwrap_or_default()),
            ("camera2", _) => Ok(Box::new(camera2)),
            ("cube", _) => {
                if !(2..=256).contains(&self.cube_size) {
                    bail!("--cube-size must be in 2..=256, got {}", self.cube_size);
                }
                Ok(Box::new(campro::targets::cube::CubeFile {
                    kind: campro::targets::cube::Kind::Cube,
                    size: self.cube_size,
                }))
            }
            ("hald", _) => {
                if !(2..=16).contains(&self.hald_level) {
                    bail!("--hald-level must be in 2..=16, got {}", self.hald_level);
                }
                Ok(Box::new(campro::targets::cube::CubeFile::hald(self.hald_level)))
            }
            (_, Support::Deploy(make)) => Ok(make()),
        }
    }

    /// The file `t` exports for `p` (the base read here); values out of the stack's range
    /// are refused, or clamped with `--clamp` and listed on stderr.
    fn export(&self, t: &dyn campro::targets::Target, p: &Params) -> Result<(Vec<u8>, Option<String>)> {
        let base = self.base_text()?;
        let bytes = if self.clamp {
            let (bytes, clamped) = t.export_clamped(p, base.as_deref())?;
            for c in &clamped {
                eprintln!("warning: {c} (compare measures what that costs)");
            }
            bytes
        } else {
            t.export(p, base.as_deref())?
        };
        Ok((bytes, base))
    }

    /// The base file's text (a regular file of at most 16 MiB), if given.
    fn base_text(&self) -> Result<Option<String>> {
        let Some(f) = &self.base else { return Ok(None) };
        Ok(Some(campro::file::read_text_capped(f, 16 << 20, "a tuning file (--base)")?))
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum BitDepth {
    #[value(name = "8")]
    Eight,
    #[value(name = "16")]
    Sixteen,
}

#[derive(Clone, Copy, ValueEnum)]
enum Format {
    Json,
    Kotlin,
}

#[derive(Clone, Copy, ValueEnum)]
enum Report {
    Text,
    Json,
}

fn main() {
    // No panic message or backtrace ever reaches the user (RUST_BACKTRACE set or not): a
    // bug is reported as one line, and the process exits 101 as a panic would.
    std::panic::set_hook(Box::new(|info| {
        let what = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown".into());
        let first = what.lines().next().unwrap_or_default();
        eprintln!("error: internal error (a bug in campro, please report it): {}", escape(first));
    }));
    // Ctrl-C or SIGTERM during a long write: the unfinished hidden `.campro-*` files go.
    let _ = ctrlc::set_handler(|| {
        video::kill_children();
        campro_eval::atomic::remove_partial_files();
        eprintln!("interrupted");
        std::process::exit(130);
    });
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // --help and --version print as clap writes them.
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            // A usage error is printed whole, as clap words it: the flag and the rule, a
            // "did you mean", the valid values, the usage line. Every line escaped and cut.
            let text = e.render().to_string();
            for line in text.lines().filter(|l| !l.trim().is_empty()) {
                eprintln!("{}", short(&escape(line), MAX_ERROR_CHARS));
            }
            std::process::exit(2);
        }
    };
    if let Err(e) = run(cli) {
        eprintln!("error: {}", one_line(&e));
        std::process::exit(1);
    }
}

/// An error chain as one line: each cause's first line (a backtrace some libraries
/// append with `RUST_BACKTRACE` set never shows), a cause that the text so far already
/// says left out, control characters escaped.
pub(crate) fn one_line(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        let first = text.lines().map(str::trim).find(|l| !l.is_empty()).unwrap_or_default();
        if first.is_empty() || out.contains(first) {
            continue;
        }
        // A cause that repeats the text so far (a path added twice) is not said again.
        let first = first.strip_prefix(out.as_str()).map(|r| r.trim_start_matches(": ")).unwrap_or(first);
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(first);
    }
    short(&escape(&out), MAX_ERROR_CHARS)
}

/// An error about the input `path` as one line, the path said once (an error that names
/// it already is not prefixed with it again).
pub(crate) fn about(path: &Path, e: &anyhow::Error) -> String {
    let line = one_line(e);
    let p = shown(path);
    if line.contains(&p) {
        line
    } else {
        format!("{p}: {line}")
    }
}

/// Measured conversion error above which `convert` warns, 8-bit LSB.
const CONVERT_WARN_LSB: f64 = 2.0;

/// Longest error line printed, characters.
const MAX_ERROR_CHARS: usize = 1000;

/// Writes one line to stdout; a closed stdout (`| head`) ends the command quietly.
pub(crate) fn say(args: std::fmt::Arguments) {
    if let Err(e) = writeln!(std::io::stdout().lock(), "{args}") {
        quiet_exit(e);
    }
}

/// Writes bytes to stdout, as [`say`].
pub(crate) fn say_bytes(bytes: &[u8]) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(bytes).and_then(|()| out.flush()) {
        quiet_exit(e);
    }
}

/// Ends the process after a failed write to stdout: quietly (status 0) when the reader
/// went away, with a one-line error otherwise.
fn quiet_exit(e: std::io::Error) -> ! {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(0);
    }
    eprintln!("error: standard output: {e}");
    std::process::exit(1);
}

/// `println!` through [`say`].
#[macro_export]
macro_rules! say {
    ($($t:tt)*) => { $crate::say(format_args!($($t)*)) };
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        Cmd::Eval { what } => eval::run(*what),
        Cmd::Train { config, output, log, checkpoints, resume, init, force } => {
            train::train(&config, &output, log.as_deref(), checkpoints, resume, init.as_deref(), force)
        }
        Cmd::FinetuneDetector { params, config, steps, seconds, log, force } => {
            train::finetune_detector(&params, config.as_deref(), steps, seconds, log.as_deref(), force)
        }
        Cmd::TrainEnhancer(a) => train::train_enhancer(&a),
        Cmd::Completions { shell } => {
            let mut buf = Vec::new();
            clap_complete::generate(shell, &mut <Cli as clap::CommandFactory>::command(), "campro", &mut buf);
            say_bytes(&buf);
            Ok(())
        }
        Cmd::Man { command, output, markdown, force } => man::run(&command, output.as_deref(), markdown, force),
        Cmd::Validate { params, format: Report::Json } => {
            for p in params {
                let v = load_params(&p)?;
                let (lo, hi) = ccm::min_max(&v.ccm);
                say!(
                    "{}",
                    serde_json::json!({
                        "file": p.display().to_string(), "ok": true, "name": v.name, "description": v.description,
                        "knots": v.tone_curve.len(), "evenlySpaced": v.tone_curve.is_uniform(), "degamma": v.degamma,
                        "ccmMin": lo, "ccmMax": hi, "ctCalibrations": v.ct_calibration.len(),
                    })
                );
            }
            Ok(())
        }
        Cmd::Validate { params, .. } => {
            for p in params {
                let v = load_params(&p)?;
                say!(
                    "{}: ok ({}: {} knots{}, degamma {}, CCM range [{:.3}, {:.3}], {} CT calibrations)",
                    p.display(),
                    if v.name.is_empty() { "unnamed".to_string() } else { escape(&v.name) },
                    v.tone_curve.len(),
                    if v.tone_curve.is_uniform() { " evenly spaced" } else { "" },
                    v.degamma,
                    ccm::min_max(&v.ccm).0,
                    ccm::min_max(&v.ccm).1,
                    v.ct_calibration.len()
                );
            }
            Ok(())
        }
        Cmd::ImportPt { checkpoint, output, force } => {
            not_an_input("--output", &output, &[&checkpoint])?;
            let p = campro::import_pt::read_checkpoint(&checkpoint)
                .map_err(|e| anyhow!("{}: {e}", crate::shown(&checkpoint)))?;
            write_atomic(&output, p.to_json().as_bytes(), force)?;
            eprintln!("wrote {} ({} knots)", crate::shown(&output), p.tone_curve.len());
            Ok(())
        }
        Cmd::Convert { params, target, files, output, force, format, .. } if target != "camera2" => {
            if matches!(format, Format::Kotlin) {
                bail!("--format kotlin: only --target camera2 has a Kotlin form; --target {target} writes the stack's own file");
            }
            if output.is_none() && target == "hald" {
                bail!("a Hald image is binary: pass --output FILE.ppm");
            }
            if let Some(o) = &output {
                not_an_input("--output", o, &[&params])?;
                not_an_input("--output", o, &files.paths())?;
            }
            let p = load_params(&params)?;
            let t = files.target(&target, Camera2::default())?;
            let (bytes, base) = files.export(t.as_ref(), &p)?;
            // What the stack will do with it, measured as compare does (fewer random pixels):
            // a conversion that errs visibly never passes in silence.
            let conditions = t.emulate(&p, &bytes, base.as_deref())?;
            let rows = comparison(&p, &conditions, 20_000, 1)?;
            let worst = rows.iter().map(|r| r.stats.max_lsb()).fold(0.0, f64::max);
            eprintln!(
                "measured against the desktop pipeline: up to {worst:.2} LSB (8-bit) over {} conditions; campro compare --target {target} shows each",
                conditions.len()
            );
            if worst > CONVERT_WARN_LSB {
                eprintln!(
                    "warning: --target {target} errs by up to {worst:.1} LSB: the deployed camera differs visibly from the preset (more LUT points, or another target, err less)"
                );
            }
            match output {
                Some(o) => write_atomic(&o, &bytes, force),
                None => {
                    say_bytes(&bytes);
                    Ok(())
                }
            }
        }
        Cmd::Compare { params, target, files, device, matrix_frac_bits, lut_size, random, seed, format } => {
            let p = load_params(&params)?;
            let (m, options) = device_setup(&p, &device)?;
            let t = files.target(
                &target,
                Camera2::new(m, options, DeviceModel { matrix_frac_bits, lut_size: lut_size.map(|n| n as usize) }),
            )?;
            let (exported, base) = files.export(t.as_ref(), &p)?;
            let conditions = t.emulate(&p, &exported, base.as_deref())?;
            let rows = comparison(&p, &conditions, random as usize, seed)?;
            match format {
                Report::Text => {
                    say!("target {} ({} bytes exported)", t.name(), exported.len());
                    print_comparison(&rows);
                }
                Report::Json => {
                    let mut json = comparison_json(t.name(), exported.len(), &rows);
                    if target == "camera2" {
                        json["camera2"] = serde_json::from_slice(&exported)?;
                    }
                    say!("{}", serde_json::to_string_pretty(&json)?)
                }
            }
            Ok(())
        }
        Cmd::Convert { params, device, format, output, force, .. } => {
            if let Some(o) = &output {
                not_an_input("--output", o, &[&params])?;
                not_an_input("--output", o, &device.paths())?;
            }
            let p = load_params(&params)?;
            let (m, opts) = device_setup(&p, &device)?;
            let v = camera2::convert(&p, &m, &opts).map_err(|e| flagged(e, &device))?;
            let r = &v.report;
            if r.curve_simplified && r.curve_max_abs * 255.0 > 0.5 {
                eprintln!(
                    "warning: the curve lost knots to fit {} points: it errs up to {:.2} LSB (8-bit); a device with more TONEMAP_MAX_CURVE_POINTS (--max-curve-points) errs less",
                    opts.max_curve_points,
                    r.curve_max_abs * 255.0
                );
            }
            let gains = device_gains(&device)?;
            let text = match format {
                Format::Json => {
                    let mut j = v.to_json();
                    j["colorCorrectionGains"] = gains.map_or(serde_json::Value::Null, |g| serde_json::json!(g));
                    serde_json::to_string(&j)? + "\n"
                }
                Format::Kotlin => v.to_kotlin(gains),
            };
            match output {
                Some(o) => write_atomic(&o, text.as_bytes(), force),
                None => {
                    say_bytes(text.as_bytes());
                    Ok(())
                }
            }
        }
        Cmd::Simulate {
            params,
            inputs,
            output,
            bit_depth,
            quality,
            image_format,
            size,
            rate,
            frames,
            force,
            jobs,
            codec,
            crf,
            bitrate,
            preset,
            enhance,
            scale,
            skip_existing,
            format,
        } => {
            let enc = video::Encoding { codec, crf: Some(crf), bitrate, preset };
            let p = load_params(&params)?;
            let enhancer = if enhance { Some(capture::enhancer_of(&params, &p, scale)?) } else { None };
            let options = simulate::Options {
                depth: match bit_depth {
                    BitDepth::Eight => Depth::Eight,
                    BitDepth::Sixteen => Depth::Sixteen,
                },
                existing: match (force, skip_existing) {
                    (true, _) => simulate::Existing::Replace,
                    (_, true) => simulate::Existing::Skip,
                    _ => simulate::Existing::Refuse,
                },
                jobs: jobs.map(|j| j as usize),
                enc: &enc,
                enhancer: enhancer.as_ref(),
                json: matches!(format, Report::Json),
                quality,
                image_format,
                frames: video::FrameFormat { size, rate },
                max_frames: frames,
            };
            simulate::simulate(&p, &inputs, &output, &options)
        }
        Cmd::Inspect {
            params,
            inputs,
            output,
            shared,
            models,
            person_detector,
            own_detector,
            confidence,
            force,
            format,
            enhance,
            scale,
        } => {
            let p = load_params(&params)?;
            check_output_folder(&output, force, "--output")?;
            let enhancer = if enhance { Some(capture::enhancer_of(&params, &p, scale)?) } else { None };
            let given = models.is_some();
            let models = models.unwrap_or_else(|| eval::shared_dir(shared.as_deref()).join("models"));
            if !models.is_dir() {
                bail!(
                    "{} {}: no such folder; inspect runs the face and person models of the shared data folder: pass --shared DIR or set CAMPRO_SHARED (default ../shared), or --models DIR",
                    if given { "--models" } else { "the models folder" },
                    crate::shown(&models)
                );
            }
            let people = eval::load(&person_detector, &models)?;
            let own = if own_detector {
                let own = eval::own_detectors(std::slice::from_ref(&params))?;
                let manifest = own.values().next().ok_or_else(|| {
                    anyhow!(
                        "--own-detector: {} names no fine-tuned detector (provenance.detector)",
                        crate::shown(&params)
                    )
                })?;
                let m = eval::load(&manifest.to_string_lossy(), &models)?;
                Some((m.manifest.name.clone(), campro_eval::person::PersonDetector::new(m)?))
            } else {
                None
            };
            let det = inspect::Detectors {
                faces: campro_eval::face::FaceDetector::new(eval::load("yunet", &models)?)?,
                people: (people.manifest.name.clone(), campro_eval::person::PersonDetector::new(people)?),
                own,
                confidence: confidence as f32,
            };
            inspect::inspect(&params, &p, &inputs, &output, &det, enhancer.as_ref(), matches!(format, Report::Json))
        }
        Cmd::Presets { format } => presets::list(matches!(format, Report::Json)),
        Cmd::Demo { output, params, force, format } => demo(&output, params.as_deref(), force, format),
        Cmd::Bench { what: Some(BenchWhat::Train(a)), .. } => train::bench_train(&a),
        Cmd::Bench { what: Some(BenchWhat::Enhancer(a)), .. } => train::bench_enhancer(&a),
        Cmd::Bench { what: None, params, quick, format } => {
            let p = match params {
                Some(path) => load_params(&path)?,
                None => bench::default_params(),
            };
            let rows = bench::run(&p, quick);
            match format {
                Report::Text => bench::markdown(&rows).iter().for_each(|line| say!("{line}")),
                Report::Json => say!("{}", bench::json(&rows)),
            }
            Ok(())
        }
        Cmd::Stress { seconds, seed, format } => stress(seconds, seed, format),
    }
}

pub(crate) fn load_params(path: &Path) -> Result<Params> {
    if let Some(preset) = presets::named(path) {
        return Ok(Params::from_json(preset.json)?);
    }
    if !path.exists() && path.components().count() == 1 && path.extension().is_none() {
        return Err(presets::not_found(path));
    }
    Params::from_file(path).map_err(|e| match e {
        // The file error names the path already.
        campro::params::ParamsError::File(f) => anyhow!("{f}"),
        e => anyhow!("{}: {e}", crate::shown(path)),
    })
}

/// The device matrix and conversion options from the command line.
/// The device's white-balance gains: `--device-gains`, or a capture result's.
fn device_gains(d: &DeviceArgs) -> Result<Option<[f32; 4]>> {
    if let Some(g) = &d.device_gains {
        return Ok(Some([g[0], g[1], g[2], g[3]]));
    }
    let Some(f) = &d.capture_result else { return Ok(None) };
    let text = campro::file::read_text_capped(f, 1 << 20, "a capture result")?;
    camera2::gains_from_capture_result(&text).map_err(|e| anyhow!("--capture-result {}: {e}", crate::shown(f)))
}

fn device_setup(p: &Params, d: &DeviceArgs) -> Result<(Mat3, Options)> {
    let m = if let Some(v) = &d.device_ccm {
        [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]
    } else if let Some(f) = &d.capture_result {
        let text = campro::file::read_text_capped(f, 1 << 20, "a capture result")?;
        camera2::device_transform_from_capture_result(&text)
            .map_err(|e| anyhow!("--capture-result {}: {e}", crate::shown(f)))?
    } else if let Some(ct) = d.ct {
        if p.ct_calibration.is_empty() {
            bail!("--ct needs a parameter file with ct_calibration");
        }
        campro::color_temp::interpolate(&p.ct_calibration, ct)?
    } else {
        ccm::IDENTITY
    };
    // A device transform with no inverse maps colours onto a plane: nothing sensible can be
    // deployed on it, and compare refuses it too.
    // (Non-finite entries are named entry by entry by the conversion itself.)
    let finite = m.iter().flatten().all(|v| v.is_finite());
    if (d.device_ccm.is_some() || d.capture_result.is_some()) && finite && ccm::inverse(&m).is_none() {
        bail!("{}: the device transform is singular (determinant {:e}): no camera applies it", d.flag(), ccm::det(&m));
    }
    let rational = match d.fixed_denominator {
        Some(den) => RationalMode::Fixed { denominator: den },
        None => RationalMode::Best { max_denominator: d.max_denominator },
    };
    Ok((m, Options { max_curve_points: d.max_curve_points as usize, rational }))
}

/// Writes `bytes` to `path` whole or not at all ([`campro_eval::atomic::write`]). Refuses
/// to replace `path` unless `force` (checked once, at the rename).
pub(crate) fn write_atomic(path: &Path, bytes: &[u8], force: bool) -> Result<()> {
    output_result(path, campro_eval::atomic::write(path, bytes, force))
}

/// An output write's result, with "exists (use --force ...)" for a refused overwrite.
pub(crate) fn output_result(path: &Path, r: std::io::Result<()>) -> Result<()> {
    match r {
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            bail!("{} exists (use --force to overwrite)", crate::shown(path))
        }
        r => r.with_context(|| path.display().to_string()),
    }
}

/// One row of a comparison: the condition, the pixel set, the measured error and the
/// condition's stated bound (output units), if any.
struct Row {
    condition: String,
    pixels: String,
    stats: compare::Stats,
    bound: Option<f64>,
}

/// Every condition on every test pixel set (every grey level first).
fn comparison(p: &Params, conditions: &[Condition], random: usize, seed: u64) -> Result<Vec<Row>> {
    let sets: Vec<(String, Vec<[u8; 3]>)> = std::iter::once(("every grey level".to_string(), compare::grey_levels()))
        .chain(pixel_sets(random, seed))
        .collect();
    let mut rows = Vec::new();
    for c in conditions {
        for (name, px) in &sets {
            let stats = compare::deployment_vs_desktop(p, &c.feed, c.emulator.as_ref(), px)?;
            rows.push(Row { condition: c.label.clone(), pixels: name.clone(), stats, bound: c.bound });
        }
    }
    Ok(rows)
}

/// The test pixels every comparison uses: the RGB cube, random pixels, the chart.
fn pixel_sets(random: usize, seed: u64) -> [(String, Vec<[u8; 3]>); 3] {
    let chart: Vec<[u8; 3]> = campro::chart::render().chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    [
        ("RGB cube, step 5".to_string(), compare::code_cube(5)),
        (format!("{random} random pixels"), compare::random_pixels(random, seed)),
        ("built-in chart".to_string(), chart),
    ]
}

fn print_comparison(rows: &[Row]) {
    say!(
        "{:<16} {:<22} {:>10} {:>10} {:>10} {:>12}",
        "condition",
        "pixels",
        "max LSB",
        "mean LSB",
        "PSNR dB",
        "bound LSB"
    );
    for r in rows {
        let bound = r.bound.map_or("-".to_string(), |b| format!("{:.4}", b * 255.0));
        let s = &r.stats;
        say!(
            "{:<16} {:<22} {:>10.4} {:>10.5} {:>10.2} {:>12}",
            r.condition,
            r.pixels,
            s.max_lsb(),
            s.mean_lsb(),
            s.psnr(),
            bound
        );
    }
}

fn comparison_json(target: &str, exported_bytes: usize, rows: &[Row]) -> serde_json::Value {
    serde_json::json!({
        "target": target, "exportedBytes": exported_bytes,
        "comparison": rows.iter().map(|r| serde_json::json!({
            "condition": r.condition, "pixels": r.pixels, "count": r.stats.count / 3,
            "maxLsb": r.stats.max_lsb(), "meanLsb": r.stats.mean_lsb(), "psnrDb": r.stats.psnr(), "boundLsb": r.bound.map(|b| b * 255.0),
        })).collect::<Vec<_>>(),
    })
}

fn demo(out: &Path, params: Option<&Path>, force: bool, format: Report) -> Result<()> {
    // A folder holding only an earlier demo's two files is the demo's own: replaced.
    let earlier_demo = std::fs::read_dir(out).is_ok_and(|entries| {
        entries.flatten().all(|e| matches!(e.file_name().to_str(), Some("chart.png" | "chart-protected.png")))
    });
    check_output_folder(out, force || earlier_demo, "--output")?;
    let (p, file) = match params {
        Some(path) => (load_params(path)?, path.display().to_string()),
        None => (Params::from_json(DEFAULT_PARAMS)?, format!("{DEFAULT_PARAMS_FILE} (the recommended preset)")),
    };
    let chart = campro::chart::render();
    let (w, h) = (campro::chart::WIDTH, campro::chart::HEIGHT);
    let src: Vec<u16> = chart.iter().map(|&v| v as u16).collect();
    let mut dst = vec![0u16; src.len()];
    Prepared::new(&p, Depth::Eight).run(&src, &mut dst, Depth::Eight);
    let before = out.join("chart.png");
    // Fixed names: never built from the file's contents.
    let after = out.join("chart-protected.png");
    for (path, png) in [
        (&before, simulate::encode_png(&src, w, h, Depth::Eight)?),
        (&after, simulate::encode_png(&dst, w, h, Depth::Eight)?),
    ] {
        // An earlier demo's identical file is left as it is; any other file of that name
        // (the user's own, or another preset's output) is replaced only with --force.
        let same = campro::file::read_capped(path, png.len() as u64, "an earlier demo output").is_ok_and(|b| b == png);
        if !same {
            write_atomic(path, &png, force)?;
        }
    }
    let v = camera2::convert(&p, &ccm::IDENTITY, &Options::default())?;
    let device = Camera2::default();
    let conditions = campro::targets::Target::emulate(&device, &p, &serde_json::to_vec(&v.to_json())?, None)?;
    let rows = comparison(&p, &conditions, 100_000, 1)?;
    if let Report::Json = format {
        let json = serde_json::json!({
            "preset": file, "name": p.name, "description": p.description,
            "input": before.display().to_string(), "output": after.display().to_string(),
            "camera2": v.to_json(),
            "conversion": {
                "matrix_scale": v.scale, "matrix_max_abs": v.report.matrix_max_abs,
                "curve_max_abs": v.report.curve_max_abs, "bound_lsb": v.report.bound_lsb(),
            },
            "comparison": comparison_json("camera2", 0, &rows)["comparison"],
        });
        say!("{json}");
        return Ok(());
    }
    say!("preset: {file}");
    say!("parameters: {} - {}", escape(&p.name), escape(&p.description));
    say!("wrote {} (input) and {} (desktop pipeline output)\n", crate::shown(&before), crate::shown(&after));
    say!("Camera2 values (device transform: identity; `campro convert --device-ccm ...` for yours):");
    say!("  COLOR_CORRECTION_TRANSFORM (num/den pairs): {:?}", v.color_correction_transform);
    let c = &v.tonemap_curve.red;
    let pts: Vec<String> = c.chunks(2).take(4).map(|p| format!("({:.4}, {:.4})", p[0], p[1])).collect();
    say!(
        "  TONEMAP_CURVE: {} points per channel: {}, ... ({:.4}, {:.4})",
        c.len() / 2,
        pts.join(", "),
        c[c.len() - 2],
        c[c.len() - 1]
    );
    say!(
        "  matrix scale {}, rational error {:.2e}, curve error {:.2e}, bound {:.2e} LSB over sensor RGB in [0,1]",
        v.scale,
        v.report.matrix_max_abs,
        v.report.curve_max_abs,
        v.report.bound_lsb()
    );
    say!("\nSimulated device vs desktop pipeline:");
    print_comparison(&rows);
    Ok(())
}

fn stress(seconds: f64, seed: u64, format: Report) -> Result<()> {
    if !(seconds.is_finite() && seconds >= 0.0) {
        bail!("--seconds must be a finite number >= 0, got {seconds}");
    }
    let start = std::time::Instant::now();
    let (mut converted, mut refused) = (0u64, 0u64);
    let mut s = seed;
    while start.elapsed().as_secs_f64() < seconds {
        match stress::check(&stress::random_case(s)) {
            Ok(stress::Outcome::Converted) => converted += 1,
            Ok(stress::Outcome::Refused) => refused += 1,
            Err(e) => bail!("invariant broken after {} cases: {e}", converted + refused),
        }
        s = s.wrapping_add(1);
    }
    let secs = start.elapsed().as_secs_f64();
    match format {
        Report::Text => say!("stress: {} cases in {secs:.1} s (seeds {seed}..{s}): {converted} converted, {refused} refused with a named error, 0 invariants broken", converted + refused),
        Report::Json => say!("{}", serde_json::json!({
            "cases": converted + refused, "seconds": secs, "first_seed": seed, "next_seed": s,
            "converted": converted, "refused": refused, "invariants_broken": 0,
        })),
    }
    Ok(())
}

pub(crate) use campro::file::{escape, shown};

/// `text` cut to `max` characters, saying how much was left out (a value echoed from a
/// file or an argument must not flood the terminal).
pub(crate) fn short(text: &str, max: usize) -> String {
    let n = text.chars().count();
    if n <= max {
        return text.to_string();
    }
    let head: String = text.chars().take(max).collect();
    format!("{head}... ({} more characters)", n - max)
}

/// Whether `a` and `b` name the same existing file (the same inode on Unix, through links).
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
        false
    }
    #[cfg(not(unix))]
    {
        matches!((std::fs::canonicalize(a), std::fs::canonicalize(b)), (Ok(x), Ok(y)) if x == y)
    }
}

/// Refuses an output that is one of the command's inputs: an output never replaces what
/// it was made from, `--force` or not.
pub(crate) fn not_an_input(flag: &str, output: &Path, inputs: &[&Path]) -> Result<()> {
    if let Some(i) = inputs.iter().find(|i| same_file(output, i)) {
        bail!(
            "{flag} {}: is an input of this command ({}); outputs never replace their inputs",
            crate::shown(output),
            crate::shown(i)
        );
    }
    Ok(())
}

/// Refuses an output folder that already holds files unless `force` (a quick look must
/// not replace the results of a long run), and a path that is not a folder.
/// `flag` names the option the folder came from.
pub(crate) fn check_output_folder(out: &Path, force: bool, flag: &str) -> Result<()> {
    match std::fs::read_dir(out) {
        Ok(mut entries) => {
            if entries.next().is_some() && !force {
                bail!(
                    "{flag} {}: the folder already holds files (an earlier run's?); choose another or pass --force",
                    out.display()
                );
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(_) if out.exists() => bail!("{flag} {}: is not a folder", crate::shown(out)),
        Err(e) => Err(e).with_context(|| format!("{flag} {}", crate::shown(out))),
    }
}

/// A conversion error with the option the user typed in place of the library's field
/// name (`--device-ccm[1][2]: ...` rather than `device_ccm[1][2]: ...`; the transform is
/// named by where it came from: `--capture-result FILE` or `--ct`).
fn flagged(e: camera2::ConvertError, device: &DeviceArgs) -> anyhow::Error {
    let text = e.to_string();
    let transform = device.flag();
    for (field, flag) in [
        ("device_ccm", transform.as_str()),
        ("max_curve_points", "--max-curve-points"),
        ("max_denominator", "--max-denominator"),
        ("denominator", "--fixed-denominator"),
    ] {
        if let Some(rest) = text.strip_prefix(field) {
            return anyhow!("{flag}{rest}");
        }
    }
    anyhow!(text)
}
