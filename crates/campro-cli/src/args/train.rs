//! Arguments of the training commands: `train`, `finetune-detector`, `train-enhancer`.
//! The run's files (log, checkpoints, resume, force) are one flattened group.

use clap::Args;
use std::path::PathBuf;

/// A training run's files: its log, its checkpoints, where it resumes from, and whether
/// it may replace what an earlier run wrote.
#[derive(Args)]
pub struct RunFiles {
    /// The training log (CSV, one line per round or step), with its charts beside it
    /// (LOG-losses.svg and LOG-accuracy.svg or LOG-psnr.svg).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Checkpoint folder (every budget.checkpoint_every rounds or steps, and at the end).
    #[arg(long)]
    pub checkpoints: Option<PathBuf>,
    /// Resume from this checkpoint folder (same configuration and data).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace existing output files and log.
    #[arg(long)]
    pub force: bool,
}

/// `campro train`.
#[derive(Args)]
pub struct TrainArgs {
    /// TOML configuration (every key optional: the paper's defaults).
    pub config: PathBuf,
    /// The learnt parameter set (JSON, as `convert`, `simulate` and `eval` read it).
    #[arg(short, long, default_value = "campro-trained.json")]
    pub output: PathBuf,
    /// Start the camera from this parameter set (evenly spaced knots: camera.knots of
    /// them, or k where camera.knots = (k - 1)·m + 1, the same curve on a finer grid;
    /// degamma camera.gamma) instead of the identity.
    #[arg(long, conflicts_with = "resume")]
    pub init: Option<PathBuf>,
    /// Where the run computes: cpu, cuda or cuda:N (a build with --features cuda:
    /// docs/gpu.md). A checkpoint resumes on any device.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    #[command(flatten)]
    pub files: RunFiles,
}

/// `campro finetune-detector`.
#[derive(Args)]
pub struct FinetuneDetectorArgs {
    /// The parameter set (JSON); its provenance gains `detector`.
    pub params: PathBuf,
    /// TOML configuration whose `[detector]` and `seed` are used (default: the paper's).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Detector steps of `detector.batch` images (1 to 10,000,000).
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    pub steps: u32,
    /// Stop after this many seconds even if steps remain.
    #[arg(long, default_value_t = f64::INFINITY)]
    pub seconds: f64,
    /// The fine-tuning log (CSV, one line per step).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Replace existing detector files and log.
    #[arg(long)]
    pub force: bool,
}

/// `campro train-enhancer`.
#[derive(Args)]
pub struct TrainEnhancerArgs {
    /// The parameter set (JSON) whose camera the enhancer inverts; its provenance gains
    /// `enhancer`. LFW identities it held out (`provenance.data.validation_identities`)
    /// are never read.
    pub params: PathBuf,
    /// TOML configuration (every key optional: the paper's settings, sized for the CPU).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Start from the weights in this checkpoint folder of another run, or in an enhancer
    /// file (PARAMS.enhancer.onnx): a fresh step count and log; a face gate it lacks starts
    /// fresh.
    #[arg(long, conflicts_with = "resume")]
    pub init: Option<PathBuf>,
    #[command(flatten)]
    pub files: RunFiles,
}
