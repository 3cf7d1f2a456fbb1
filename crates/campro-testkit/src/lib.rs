//! campro's test scaffolding, kept out of the shipped libraries and binaries: the helpers
//! that find the real data and models in `../shared` ([`shared`]). The numerical stress
//! cases and the benchmarks' inputs, which the shipped `campro stress` and `campro bench`
//! run, are the core's (feature `stress`), re-exported here for the tests.
#![warn(missing_docs)]

pub mod shared;

pub use campro::{bench, stress};
pub use shared::{npy, registry, shared, shared_root, workspace_root};
