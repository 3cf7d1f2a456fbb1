//! Errors of the evaluation crate: each names the file or field and the rule it broke.

use std::path::PathBuf;
use thiserror::Error;

#[derive(Debug, Error)]
#[non_exhaustive]
pub enum EvalError {
    /// The I/O error is part of the message, not a `source`, so a chain is printed once.
    #[error("{path}: {error}")]
    Io { path: PathBuf, error: std::io::Error },
    #[error("{path}: {field}: {rule}")]
    Manifest { path: PathBuf, field: String, rule: String },
    #[error("model {path}: {message}")]
    Model { path: PathBuf, message: String },
    #[error("image {path}: {message}")]
    Image { path: PathBuf, message: String },
    #[error("{path}:{line}: {message}")]
    Data { path: PathBuf, line: usize, message: String },
    #[error("{0}")]
    Invalid(String),
    /// Nothing to measure: no identity met a condition's rule (e.g. pose on a few
    /// identities, none of them turned).
    #[error("{0}")]
    NoIdentities(String),
    /// An input file could not be read (not a regular file, over its size cap, ...).
    #[error(transparent)]
    File(#[from] campro::file::FileError),
}

impl EvalError {
    pub fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |error| Self::Io { path, error }
    }
}

pub type Result<T> = std::result::Result<T, EvalError>;
