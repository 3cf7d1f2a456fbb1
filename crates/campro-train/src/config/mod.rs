//! The optimiser's configuration: one TOML file holds every hyper-parameter (paper
//! defaults), so a run is reproducible from its file and seed. Unknown keys are refused;
//! each rule names its key.
//!
//! `config/train.rs`: `campro train`'s file ([`Config`]); `config/enhancer.rs`: `campro train-enhancer`'s
//! ([`EnhancerConfig`]); here, what both share: the error, the rule check and the reader.

use std::path::Path;

mod enhancer;
mod train;

pub use enhancer::*;
pub use train::*;

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: {key}: {rule}")]
    Rule { path: String, key: String, rule: String },
    /// The fields together cost more than the budget ([`crate::cost`]).
    #[error("{key}: {rule}")]
    Budget { key: &'static str, rule: String },
}

/// The most rounds (camera training) or steps (the enhancer) a budget may ask: far beyond
/// any run (a round takes seconds), so that a counter can never wrap.
pub const MAX_ROUNDS: usize = 10_000_000;

/// The first of `checks` (holds, key, rule) that does not hold, as (key, rule).
pub(crate) fn first_broken(checks: &[(bool, &'static str, &'static str)]) -> Result<(), (&'static str, &'static str)> {
    match checks.iter().find(|c| !c.0) {
        Some(&(_, key, rule)) => Err((key, rule)),
        None => Ok(()),
    }
}

/// `budget.memory` when a configuration leaves it out: 1 GiB, MiB.
pub const DEFAULT_MEMORY_MIB: u64 = 1024;

/// The range of `budget.memory`, MiB.
pub(crate) const MEMORY_MIB: std::ops::RangeInclusive<u64> = 64..=1 << 20;

/// A configuration file's rules: the first broken one as (key, rule).
pub trait Rules {
    fn check(&self) -> Result<(), (&'static str, &'static str)>;
}

/// Reads and checks a TOML configuration (missing keys take their defaults): a regular
/// file of at most 1 MiB.
pub fn load<T: serde::de::DeserializeOwned + Rules>(path: &Path) -> Result<T, ConfigError> {
    let p = path.display().to_string();
    let text = campro::file::read_text_capped(path, 1 << 20, "a configuration")
        .map_err(|e| ConfigError::Parse { path: p.clone(), message: e.reason() })?;
    parse(&text, &p)
}

/// Parses and checks a TOML configuration; `origin` names it in errors.
pub fn parse<T: serde::de::DeserializeOwned + Rules>(text: &str, origin: &str) -> Result<T, ConfigError> {
    let c: T = toml::from_str(text).map_err(|e| ConfigError::Parse {
        path: origin.into(),
        message: e.message().to_string() + &span(text, e.span()),
    })?;
    c.check().map_err(|(key, rule)| ConfigError::Rule { path: origin.into(), key: key.into(), rule: rule.into() })?;
    Ok(c)
}

fn span(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    match span {
        Some(r) => {
            let line = text[..r.start.min(text.len())].lines().count().max(1);
            format!(" (line {line})")
        }
        None => String::new(),
    }
}
