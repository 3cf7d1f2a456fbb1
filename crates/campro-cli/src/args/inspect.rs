//! Arguments of `inspect`.

use super::{EnhanceArgs, Report, PARAMS_HELP};
use clap::Args;
use std::path::PathBuf;

/// `campro inspect`.
#[derive(Args)]
pub struct InspectArgs {
    #[arg(help = PARAMS_HELP)]
    pub params: PathBuf,
    /// Images or folders (recursive).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output folder (new or empty, unless --force).
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub data: super::DataArgs,
    /// Person detector: a bundled name, `people` (built in) or a manifest file; `auto`:
    /// YOLOX-Nano when the models folder has it, else `people`.
    #[arg(long, default_value = crate::models::AUTO)]
    pub person_detector: String,
    /// Face detector: a bundled name or a manifest file; `auto`: YuNet when the models
    /// folder has it, else CenterFace (what `campro models fetch` installs).
    #[arg(long, default_value = crate::models::AUTO)]
    pub face_detector: String,
    /// Find people on the protected panel with the detector fine-tuned for PARAMS
    /// (its provenance.detector), as the camera's user would.
    #[arg(long)]
    pub own_detector: bool,
    /// Draw and list people scored at least this, in [0, 1].
    #[arg(long, default_value_t = 0.25, value_parser = super::eval::parse_confidence)]
    pub confidence: f64,
    /// Write into an output folder that already holds files.
    #[arg(long)]
    pub force: bool,
    /// A line per image, or the index as one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
    /// Add a third panel: the preset's image enhancer on the protected image
    /// (provenance.enhancer), with what each detector finds there.
    #[arg(long)]
    pub enhance: bool,
    #[command(flatten)]
    pub scale: EnhanceArgs,
}
