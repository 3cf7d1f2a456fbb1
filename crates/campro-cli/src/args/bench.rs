//! Arguments of the measurements: `bench` (run time against error), `bench train`,
//! `bench enhancer` and `stress` (the numerical soak).

use super::Report;
use clap::{Args, Subcommand};
use std::path::PathBuf;

/// `campro bench`.
#[derive(Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub what: Option<BenchWhat>,
    /// Parameters to use instead of a strong, paper-like set.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Fewer repetitions and a smaller error sample (for CI).
    #[arg(long)]
    pub quick: bool,
    /// A Markdown table, or one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}

#[derive(Subcommand)]
pub enum BenchWhat {
    /// Medians of the optimiser's training steps: MobileFaceNet 8x3x112x96 and YOLOX-Nano
    /// 1x3x416x416 (forward, sum, backward; the PyTorch anchor's shapes) and the attacker,
    /// privacy and detector steps at the configuration's shapes.
    Train(BenchTrainArgs),
    /// The enhancer's cost per U-Net size: parameters, multiply-accumulates per pixel, ONNX
    /// bytes, tract's time per 640x480 frame on one thread and a training step's time.
    Enhancer(BenchEnhancerArgs),
}

/// `campro stress`.
#[derive(Args)]
pub struct StressArgs {
    /// How long to run (seconds, finite, at least 0).
    #[arg(long, default_value_t = 10.0, value_parser = parse_seconds)]
    pub seconds: f64,
    /// First seed (cases use seed, seed+1, ...).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A summary line, or one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}

/// `--seconds` of stress: a finite number >= 0.
fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("must be a finite number >= 0, got {}", super::shown_arg(s))),
    }
}

/// How a training-step timing runs: its threads and how many timed runs.
#[derive(Args)]
pub struct Timing {
    /// Threads of the training steps (default: all cores; more than the cores is clamped,
    /// with a warning; tract's inference runs on one).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// Timed runs of each measurement (the median is reported, after one warm-up).
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub runs: u32,
}

impl Timing {
    /// The threads asked for (at most the cores, [`super::cores_for`]), else every core.
    pub fn threads(&self) -> usize {
        super::cores_for("--threads", self.threads.map(|t| t as usize))
    }
}

/// `campro bench train`.
#[derive(Args)]
pub struct BenchTrainArgs {
    #[command(flatten)]
    pub timing: Timing,
    /// Where the steps run: cpu, cuda or cuda:N (a build with --features cuda: docs/gpu.md).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// The configuration whose face batch, person batch and size the players' steps use
    /// (default: the paper's).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Only these steps (repeatable; default: all).
    #[arg(long = "only", value_enum)]
    pub only: Vec<StepArg>,
    /// The shared data folder (default: $CAMPRO_SHARED or ../shared).
    #[arg(long)]
    pub shared: Option<PathBuf>,
    /// Also run PyTorch's anchor (SHARED/anchors/torch_step.py) with this Python, with the
    /// same threads, right after, and report the ratios.
    #[arg(long, value_name = "PYTHON")]
    pub anchor: Option<PathBuf>,
    /// A table, or one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}

/// `--only`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum StepArg {
    Mobilefacenet,
    Yolox,
    Attacker,
    Privacy,
    Detector,
}

/// `campro bench enhancer`.
#[derive(Args)]
pub struct BenchEnhancerArgs {
    /// U-Net widths to compare, comma-separated, full resolution first (repeatable; default:
    /// the configuration's).
    #[arg(long = "widths", value_delimiter = ',', num_args = 1.., action = clap::ArgAction::Append)]
    pub widths: Vec<usize>,
    /// Several sizes: repeat --size; each is one comma-separated list (overrides --widths).
    #[arg(long = "size", value_name = "W0,W1,...")]
    pub sizes: Vec<String>,
    /// Per-pixel stem widths to combine with each size (repeatable; default: the
    /// configuration's).
    #[arg(long = "stem")]
    pub stems: Vec<usize>,
    #[command(flatten)]
    pub timing: Timing,
    /// The configuration whose widths, batch and crop are used (default: the built-in one).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// A table, or one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}
