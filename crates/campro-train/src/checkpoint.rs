//! Training checkpoints: every trainable tensor (camera, attacker backbone and batch-norm
//! statistics, proxy head) in one safetensors file plus a small JSON state (round, seed, log),
//! both written through a temporary file and a rename, so a crash never leaves a torn
//! checkpoint. On resume the optimisers' moments start afresh and the batch order is
//! reseeded from (seed, round): a resumed run is deterministic, though not bit-identical to
//! an uninterrupted one.

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

use crate::error::CheckpointError;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct State {
    /// The last finished round.
    pub round: usize,
    pub seed: u64,
    /// Classes of the proxy head, in order (a resume must see the same face set).
    pub classes: Vec<String>,
    /// The training log up to `round` (empty in checkpoints written before it was kept).
    #[serde(default)]
    pub log: Vec<crate::log::LogRow>,
    /// The best validated camera so far (`[validation]`; its tensors are `best.NAME` in the
    /// tensor file); None without validation and in checkpoints written before it.
    #[serde(default)]
    pub best: Option<crate::validation::Best>,
}

const TENSORS: &str = "tensors.safetensors";
const STATE: &str = "state.json";

fn atomic(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), CheckpointError> {
    let io = |e: std::io::Error| CheckpointError::Io { path: dir.join(name), message: e.to_string() };
    campro_eval::atomic::write(&dir.join(name), bytes, true).map_err(io)
}

/// Writes `tensors` and `state` (the optimiser's [`State`], or another run's) into `dir`
/// (tensors first: a state always names a complete tensor file).
pub fn save<S: Serialize>(dir: &Path, tensors: &HashMap<String, Tensor>, state: &S) -> Result<(), CheckpointError> {
    write_tensors(dir, TENSORS, tensors)?;
    atomic(dir, STATE, &serde_json::to_vec_pretty(state).expect("state serialises"))
}

/// Writes `tensors` as `dir/name` (safetensors), whole or not at all.
pub fn write_tensors(dir: &Path, name: &str, tensors: &HashMap<String, Tensor>) -> Result<(), CheckpointError> {
    let bytes = safetensors::serialize(tensors, None)
        .map_err(|e| CheckpointError::Format { path: dir.join(name), message: e.to_string() })?;
    atomic(dir, name, &bytes)
}

/// Reads a checkpoint written by [`save`].
pub fn load<S: serde::de::DeserializeOwned>(
    dir: &Path,
    device: &Device,
) -> Result<(HashMap<String, Tensor>, S), CheckpointError> {
    let sp = dir.join(STATE);
    let text = campro::file::read_capped(&sp, 16 << 20, "a checkpoint state")
        .map_err(|e| CheckpointError::Io { path: sp.clone(), message: e.reason() })?;
    let state: S =
        serde_json::from_slice(&text).map_err(|e| CheckpointError::Format { path: sp, message: e.to_string() })?;
    let tp = dir.join(TENSORS);
    let tensors = candle_core::safetensors::load(&tp, device)
        .map_err(|e| CheckpointError::Format { path: tp, message: e.to_string() })?;
    Ok((tensors, state))
}
