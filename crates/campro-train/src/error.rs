//! The optimiser's one error enum, [`TrainError`], and its `Result` alias.

/// Any error of the optimiser: one variant per kind.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TrainError {
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error(transparent)]
    Faces(#[from] FacesError),
    /// A network's checkpoint or graph (campro-nn).
    #[error(transparent)]
    Nn(#[from] campro_nn::NnError),
    #[error("tensor: {0}")]
    Tensor(#[from] candle_core::Error),
    #[error(transparent)]
    Eval(#[from] campro_eval::EvalError),
    #[error("{0}")]
    Unsupported(String),
    /// An input the configuration names is not there (its key and path).
    #[error("{key} = {path}: no such file or folder (a configuration's paths are relative to the folder campro runs in; the repository's configurations run from its root, with ../shared beside it)")]
    Missing { key: &'static str, path: String },
    #[error("training diverged: {0}")]
    Diverged(String),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// A training log (CSV) that does not read back: the line (1-based) and the rule.
    #[error("line {line}: {rule}")]
    Log { line: usize, rule: String },
}

impl From<campro_nn::torch_legacy::TorchError> for TrainError {
    fn from(e: campro_nn::torch_legacy::TorchError) -> Self {
        TrainError::Nn(e.into())
    }
}

impl From<campro_nn::onnx_net::GraphError> for TrainError {
    fn from(e: campro_nn::onnx_net::GraphError) -> Self {
        TrainError::Nn(e.into())
    }
}

/// `Result` with this crate's [`TrainError`].
pub type Result<T, E = TrainError> = std::result::Result<T, E>;

/// Why a training checkpoint could not be written or read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CheckpointError {
    #[error("{path}: {message}")]
    Io { path: std::path::PathBuf, message: String },
    #[error("{path}: {message}")]
    Format { path: std::path::PathBuf, message: String },
}

/// Reading or building the face set (`faces`): the evaluation's models, the cache, the data.
#[derive(Debug, thiserror::Error)]
pub enum FacesError {
    #[error(transparent)]
    Eval(#[from] campro_eval::EvalError),
    #[error("{path}: {message}")]
    Cache { path: std::path::PathBuf, message: String },
    #[error("{0}")]
    Data(String),
}
