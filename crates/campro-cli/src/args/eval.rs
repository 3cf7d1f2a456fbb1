//! Arguments of `eval privacy|utility|quality|all|frontier`, with the adaptive attacks'
//! settings (`--attack retrain`'s `--retrain-*`).

use super::EnhanceArgs;
use campro_eval::baselines::Baseline;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum EvalCmd {
    /// Face identification (closed set, 10 runs, nearest + linear, both protection orders) and LFW verification.
    Privacy {
        #[command(flatten)]
        common: Common,
        #[command(flatten)]
        p: PrivacyArgs,
    },
    /// Person detection on COCO: AP, AP@0.5, AP@0.75, precision / recall / F1.
    Utility {
        #[command(flatten)]
        common: Common,
        #[command(flatten)]
        u: UtilityArgs,
    },
    /// RMSE, PSNR, SSIM, MS-SSIM of protected against raw images.
    Quality {
        #[command(flatten)]
        common: Common,
        /// Images to score (default: the COCO person images).
        #[arg(long)]
        images: Option<PathBuf>,
        /// Only the COCO images no training reads (id % 5 == 0, 399 of 2,044: the enhancer's
        /// and the detectors' held-out images), by file name.
        #[arg(long)]
        held_out: bool,
    },
    /// All three plus report.md with the privacy-utility trade-off plot.
    All {
        #[command(flatten)]
        common: Common,
        #[command(flatten)]
        p: PrivacyArgs,
        #[command(flatten)]
        u: UtilityArgs,
    },
    /// Calibrate face models' verification thresholds on LFW (for `campro check`): the
    /// cosine above which at most 1e-3 and 1e-2 of pairs of different people score, printed
    /// as each manifest's task.thresholds (JSON, a line per model).
    #[command(
        after_help = "Examples:\n  campro eval thresholds --face-model faceplugin --face-model mobilefacenet-casia --folds 2"
    )]
    Thresholds {
        #[command(flatten)]
        data: super::DataArgs,
        /// LFW folder (default: SHARED/data/lfw).
        #[arg(long)]
        lfw: Option<PathBuf>,
        /// Face detector: a bundled name or a manifest file.
        #[arg(long, default_value = "yunet")]
        face_detector: String,
        /// Face recognition models: bundled names or manifest files (repeatable).
        #[arg(long = "face-model", default_values_t = ["faceplugin".to_string(), "mobilefacenet-casia".to_string()])]
        face_models: Vec<String>,
        /// Use the images of pairs.txt's first N folds (1..=10; 2: about 1,200 images, 700,000 pairs).
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=10))]
        folds: u8,
    },
    /// The privacy-utility frontier across runs (the paper's Figure 10) from measured points:
    /// frontier.svg and frontier.md.
    Frontier {
        /// CSV of points read off the reports: `set,hours,top1,top1_attacked,ap_ratio`
        /// (campro_eval::frontier), at most 1 MB.
        points: PathBuf,
        /// Output folder (a new or empty folder, unless --force).
        #[arg(short, long)]
        output: PathBuf,
        /// Write into an output folder that already holds files (replacing its reports).
        #[arg(long)]
        force: bool,
    },
}

#[derive(Args)]
pub struct Common {
    /// CamPro parameter sets to evaluate (raw images are always included).
    pub params: Vec<PathBuf>,
    /// Baselines: lowres-S or defocus-K-SIGMA (repeatable).
    #[arg(long = "baseline", value_name = "B")]
    pub baselines: Vec<Baseline>,
    /// Add the paper's seven baselines (lowres 4/8/16, defocus 9/3, 13/5, 15/7, 25/7).
    #[arg(long)]
    pub paper_baselines: bool,
    #[command(flatten)]
    pub data: super::DataArgs,
    /// Use only the first N (images, or identities for privacy): quick looks and CI.
    #[arg(long, value_parser = parse_limit)]
    pub limit: Option<usize>,
    /// Output folder for the CSV, JSON, SVG and Markdown reports (a new or empty folder,
    /// unless --force).
    #[arg(short, long, default_value = "campro-eval")]
    pub output: PathBuf,
    /// Write into an output folder that already holds files (replacing its reports).
    #[arg(long)]
    pub force: bool,
    /// Also score what each parameter set's image enhancer (provenance.enhancer) makes of
    /// its captured images: rows "NAME enhanced".
    #[arg(long)]
    pub enhanced: bool,
    #[command(flatten)]
    pub scale: EnhanceArgs,
}

/// `--limit`: at least 1 (an empty selection has nothing to score).
fn parse_limit(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("must be a whole number >= 1, got {}", super::shown_arg(s))),
    }
}

/// `--confidence`: a score threshold in [0, 1].
pub(super) fn parse_confidence(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("must be a number in [0, 1], got {}", super::shown_arg(s))),
    }
}

#[derive(Args)]
pub struct PrivacyArgs {
    /// LFW folder (default: SHARED/data/lfw).
    #[arg(long)]
    pub lfw: Option<PathBuf>,
    /// The COCO person folder whose held-out images the small and group conditions paste
    /// faces into (default: SHARED/data/coco-person).
    #[arg(long, value_name = "DIR")]
    pub backdrops: Option<PathBuf>,
    /// Face detector: a bundled name or a manifest file.
    #[arg(long, default_value = "yunet")]
    pub face_detector: String,
    /// Face recognition models: bundled names or manifest files (repeatable).
    #[arg(long = "face-model", default_values_t = ["faceplugin".to_string(), "mobilefacenet-casia".to_string()])]
    pub face_models: Vec<String>,
    /// Only these identities: a parameter set from `campro train` (a file or a bundled
    /// preset's name: its held-out `provenance.data.validation_identities`) or a text file of
    /// LFW names, one per line.
    #[arg(long, value_name = "FILE")]
    pub identities: Option<PathBuf>,
    /// Other LFW identities (≥ 2 photos) to add to the gallery as distractors, raw and never
    /// probed: a number (seeded choice) or `all` (the paper's gallery of every subject).
    #[arg(long, value_name = "N|all", default_value = "0", value_parser = parse_distractors)]
    pub distractors: usize,
    /// Runs (random gallery/probe splits) to average, 1 to 1000.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=1000))]
    pub runs: u16,
    /// Seed of the seeded choices (identities, images kept, each run's gallery and probes).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Photos kept per identity (gallery, probe and the linear classifier's training photos).
    #[arg(long, default_value_t = 6)]
    pub pool: usize,
    /// Skip the pairs.txt verification.
    #[arg(long)]
    pub no_verification: bool,
    /// Verification pairs of each kind per fold (default: all 300).
    #[arg(long)]
    pub pairs_per_fold: Option<usize>,
    /// Also attack each parameter set after a restoration that knows the camera: every
    /// protected colour mapped back to the mean raw colour producing it, under the colour
    /// histogram of `--restore-prior` (rows "NAME restored"; campro_eval::restore).
    #[arg(long)]
    pub restore: bool,
    /// Raw images whose colours are the restoration's prior: the first 200 of this folder
    /// (default: SHARED/data/coco-person/images, people but not LFW's).
    #[arg(long, value_name = "DIR")]
    pub restore_prior: Option<PathBuf>,
    /// Adaptive attacks of the paper's Sec. VII beyond --restore (repeatable):
    /// `restore-net`, each parameter set's learnt restoration network
    /// (provenance.restorer, from campro train-enhancer with data.faces = "restore") on its
    /// captured images: rows "NAME restore-net"; `retrain`, each face model fine-tuned on
    /// the set's protected faces of identities never probed (needs --identities; the
    /// --retrain-* options): rows "NAME retrained".
    #[arg(long = "attack", value_enum)]
    pub attacks: Vec<AttackArg>,
    #[command(flatten)]
    pub retrain: RetrainArgs,
    /// How the attacker enrolled its gallery and classifier photos: `raw` (the paper's
    /// protocol) or `camera` (through the same camera as the probes: the re-enrolment
    /// attacker, who matches protected to protected).
    #[arg(long, value_enum, default_value = "raw")]
    pub enrol: EnrolArg,
    /// What the camera is pointed at (repeatable; default: every one): colour (LFW as it
    /// is), grey (every photo made black-and-white first, as a night, infrared or
    /// monochrome camera sees it), small (each probe's face 12-48 px wide in a held-out
    /// COCO scene, cropped, aligned and upsampled after the camera, as CCTV would), group
    /// (each probe's face beside three other people's in one scene) or pose (each person's
    /// most frontal photo enrolled, the most turned probed). Colour's report is written into
    /// --output, each other's into a folder of its name there, and conditions.md gives the
    /// worst over them.
    #[arg(long = "condition", value_enum)]
    pub conditions: Vec<ConditionArg>,
}

/// `--condition` (campro_eval::scene::Scene).
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ConditionArg {
    Colour,
    Grey,
    Small,
    Group,
    Pose,
}

impl From<ConditionArg> for campro_eval::scene::Scene {
    fn from(c: ConditionArg) -> Self {
        match c {
            ConditionArg::Colour => Self::Colour,
            ConditionArg::Grey => Self::Grey,
            ConditionArg::Small => Self::Small,
            ConditionArg::Group => Self::Group,
            ConditionArg::Pose => Self::Pose,
        }
    }
}

/// `--attack`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AttackArg {
    RestoreNet,
    Retrain,
}

/// `--enrol` (campro_eval::privacy::Enrolment).
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum EnrolArg {
    Raw,
    Camera,
}

#[derive(Args)]
pub struct UtilityArgs {
    /// COCO person folder (default: SHARED/data/coco-person).
    #[arg(long)]
    pub coco: Option<PathBuf>,
    /// Person detector: a bundled name or a manifest file.
    #[arg(long, default_value = "yolox-nano")]
    pub person_detector: String,
    /// Confidence for precision / recall / F1, in [0, 1].
    #[arg(long, default_value_t = 0.25, value_parser = parse_confidence)]
    pub confidence: f64,
    /// Score each parameter set from `campro train` or `campro finetune-detector` with the
    /// detector fine-tuned beside it (its `provenance.detector.manifest`); raw images and
    /// other sets use --person-detector. Implies --held-out.
    #[arg(long)]
    pub own_detector: bool,
    /// Only the images no detector fine-tuning trains on (COCO id % 5 == 0, 399 of 2,044).
    #[arg(long)]
    pub held_out: bool,
}

/// `--distractors`: a count, or `all` (every other identity).
fn parse_distractors(v: &str) -> Result<usize, String> {
    match v {
        "all" => Ok(usize::MAX),
        n => n.parse().map_err(|_| format!("expected a count or `all`, got {:?}", super::shown_arg(n))),
    }
}

/// The re-training attacker's settings (`--attack retrain`).
#[derive(Args, Clone)]
pub struct RetrainArgs {
    /// Re-training: photos per training identity (white-box: as many as it likes; gray-box:
    /// the few it photographs itself, e.g. 2).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub retrain_photos: u32,
    /// Re-training: at most this many training identities (seeded choice; default all
    /// with 2 or more photos that the evaluation does not probe).
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..))]
    pub retrain_identities: Option<u32>,
    /// Re-training: passes over the training faces (the paper: 20).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub retrain_epochs: u32,
    /// Re-training: SGD rate for three quarters of the epochs, then a tenth. The paper's
    /// 0.1 diverges on the shared models (batch norm folded), and 0.01 did on faceplugin
    /// with 1,177 identities.
    #[arg(long, default_value_t = 0.003, value_parser = parse_lr)]
    pub retrain_lr: f64,
    /// Re-training: faces per step.
    #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub retrain_batch: u32,
    /// Re-training: the head's loss, `softmax` (a linear classifier) or `arcface` (scale
    /// 64, margin 0.5); the paper tries both.
    #[arg(long, value_enum, default_value = "softmax")]
    pub retrain_loss: LossArg,
}

/// `--retrain-loss`.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum LossArg {
    Softmax,
    Arcface,
}

/// `--retrain-lr`: a rate in (0, 10].
fn parse_lr(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v <= 10.0 => Ok(v),
        _ => Err(format!("must be a number in (0, 10], got {}", super::shown_arg(s))),
    }
}
