//! Arguments of `check`.

use super::{EnhanceArgs, Report, PARAMS_HELP};
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// `campro check`.
#[derive(Args)]
pub struct CheckArgs {
    #[arg(help = PARAMS_HELP, required_unless_present = "record")]
    pub params: Option<PathBuf>,
    /// Photos or folders (recursive). Every face in them is its own identity: subfolders are
    /// not taken as persons (events, years and places are folders too); say who is who with
    /// --people or --person.
    #[arg(required_unless_present_any = ["persons", "people", "record"])]
    pub photos: Vec<PathBuf>,
    /// A folder of people: each subfolder holds one person's photos, named after the
    /// subfolder (re-identified among everyone's); repeatable.
    #[arg(long, value_name = "DIR", conflicts_with = "record")]
    pub people: Vec<PathBuf>,
    /// Verify a file against the record `simulate --record` (or the Android library, for a
    /// phone's photo or video) wrote beside it: `campro check --record OUT.jpg.campro.json
    /// FILE` (FILE the output: its hash; FILE the raw input of a desktop record: the camera
    /// run again and its output's hash compared). Exit status 3 if it is not what the
    /// record says.
    #[arg(long, value_name = "RECORD", conflicts_with_all = ["persons", "output", "fail_above"])]
    pub record: Option<PathBuf>,
    /// One person's photos, NAME=DIR (repeatable).
    #[arg(long = "person", value_name = "NAME=DIR", value_parser = parse_person)]
    pub persons: Vec<(String, PathBuf)>,
    /// Report folder: index.html, check.json, check.csv and the face crops (new or empty,
    /// unless --force). Without it, only the lines on stdout.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Write into a report folder that already holds files.
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub data: super::DataArgs,
    /// Face detector: a bundled name or a manifest file; `auto`: YuNet when the models
    /// folder has it, else CenterFace (what `campro models fetch` installs).
    #[arg(long, default_value = crate::models::AUTO)]
    pub face_detector: String,
    /// Face recognition models: bundled names or manifest files with task.thresholds
    /// (repeatable; default: every bundled face model the models folder holds, the ones
    /// missing named in the report).
    #[arg(long = "face-model")]
    pub face_models: Vec<String>,
    /// LFW identities added to the re-identification gallery (0: only your photos); needs
    /// LFW (--lfw, or SHARED/data/lfw).
    #[arg(long, default_value_t = 1000)]
    pub distractors: usize,
    /// LFW folder (default: SHARED/data/lfw).
    #[arg(long)]
    pub lfw: Option<PathBuf>,
    /// The views to check (repeatable; default: every one the preset has).
    #[arg(long = "view", value_enum)]
    pub views: Vec<ViewArg>,
    /// Photos the per-pixel restoration attacker fits its table on (default:
    /// SHARED/data/coco-person/images, else the photos checked: the strongest attacker).
    #[arg(long, value_name = "DIR")]
    pub restore_prior: Option<PathBuf>,
    /// Check what one device applies instead of the ideal preset: CamPro's Camera2 values
    /// for its transform (--capture-result or --device-ccm), as its HAL treats them
    /// (--matrix-frac-bits, --lut-size), emulated on each photo as `campro compare` does.
    #[command(flatten)]
    pub device: super::DeviceArgs,
    /// The device's HAL rounds matrix entries to this many fractional bits (0 to 52).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=52))]
    pub matrix_frac_bits: Option<u32>,
    /// The device's HAL resamples the curve to a LUT of this many entries (2 to 65536).
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..=65536))]
    pub lut_size: Option<u32>,
    /// Exit with status 3 when any face is linkable at this false-accept rate (1e-3 or 1e-2).
    #[arg(long, value_name = "FAR", value_parser = parse_far)]
    pub fail_above: Option<f64>,
    /// A line per photo and a summary, or the whole check as one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
    #[command(flatten)]
    pub scale: EnhanceArgs,
}

/// What a face is checked as.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ViewArg {
    /// What the camera writes.
    Captured,
    /// What a person is shown: the preset's enhancer behind its face guard.
    Enhanced,
    /// The per-pixel restoration that knows the camera (an attacker's).
    Restored,
    /// The learnt restorer trained against the preset (an attacker's).
    RestoreNet,
}

/// `--person NAME=DIR`: a non-empty name without control characters, and a folder.
fn parse_person(s: &str) -> Result<(String, PathBuf), String> {
    let (name, dir) = s.split_once('=').ok_or_else(|| format!("must be NAME=DIR, got {}", super::shown_arg(s)))?;
    if name.is_empty() || name.chars().any(char::is_control) || name.len() > 200 {
        return Err(format!(
            "NAME must be 1 to 200 characters without control characters, got {}",
            super::shown_arg(name)
        ));
    }
    if dir.is_empty() {
        return Err(format!("DIR must not be empty, got {}", super::shown_arg(s)));
    }
    Ok((name.to_string(), PathBuf::from(dir)))
}

/// `--fail-above`: one of the calibrated rates.
fn parse_far(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if campro_eval::check::FARS.contains(&v) => Ok(v),
        _ => Err(format!("must be 1e-3 or 1e-2 (the calibrated false-accept rates), got {}", super::shown_arg(s))),
    }
}
