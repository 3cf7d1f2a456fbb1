//! Arguments of the commands on parameter files themselves: validate, import-pt, presets,
//! demo, and of the manual (man).

use super::Report;
use clap::Args;
use std::path::PathBuf;

/// `campro validate`.
#[derive(Args)]
pub struct ValidateArgs {
    /// Parameter files (JSON, format campro-params v1, or v2 with a tone curve per channel).
    #[arg(required = true)]
    pub params: Vec<PathBuf>,
    /// Text (one line per file) or one JSON object per file, one a line.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}

/// `campro man`.
#[derive(Args)]
pub struct ManArgs {
    /// The command whose page to print (default: campro's own page).
    pub command: Vec<String>,
    /// Write campro.1 and one page per command (campro-simulate.1, campro-eval-privacy.1,
    /// ...) into this folder.
    #[arg(short, long, conflicts_with_all = ["command", "markdown"])]
    pub output: Option<PathBuf>,
    /// Print every command's help as one Markdown page instead.
    #[arg(long, conflicts_with = "command")]
    pub markdown: bool,
    /// Replace pages that exist in the output folder.
    #[arg(long, requires = "output")]
    pub force: bool,
}

/// `campro import-pt`.
#[derive(Args)]
pub struct ImportPtArgs {
    /// The checkpoint.
    pub checkpoint: PathBuf,
    /// Output parameter file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Overwrite an existing output.
    #[arg(long)]
    pub force: bool,
}

/// `campro presets`.
#[derive(Args)]
pub struct PresetsArgs {
    /// Readable text, or one JSON array.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}

/// `campro demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(short, long, default_value = "campro-demo")]
    pub output: PathBuf,
    /// Parameters to use instead of the recommended preset.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Write into an output folder that already holds files.
    #[arg(long)]
    pub force: bool,
    /// Readable text, or one JSON object.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}
