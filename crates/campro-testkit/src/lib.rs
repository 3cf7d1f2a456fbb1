//! campro's test and bench scaffolding, kept out of the shipped libraries: the numerical
//! stress cases and invariants ([`stress`], used by the property tests and
//! `campro stress`), the benchmarks' frames and parameter sets ([`bench`]), and the
//! helpers that find the real data and models in `../shared` ([`shared`]).
#![warn(missing_docs)]

pub mod bench;
pub mod shared;
pub mod stress;

pub use shared::{npy, shared, shared_root, workspace_root};

/// An error of the scaffolding: an invariant that broke.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A stress case broke an invariant.
    #[error("seed {seed}: {what}")]
    Invariant {
        /// The case's seed (rerun it with `campro stress --seed`).
        seed: u64,
        /// Which invariant, with the values.
        what: String,
    },
}

/// `Result` with this crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
