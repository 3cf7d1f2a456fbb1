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
    campro::file::atomic::write(&dir.join(name), bytes, true).map_err(io)
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

/// The tensors a file may hold: name → shape, all f32. A file is read only if every tensor
/// its header names is here with this shape; one this leaves out is an error, one it names
/// that the file lacks is the caller's to judge.
pub type Expected = HashMap<String, Vec<usize>>;

/// The header's allowance beyond the tensor bytes (names, dtypes, shapes, offsets as JSON).
pub const HEADER_MAX: u64 = 1 << 20;

/// The most bytes a file of `expected` tensors can take: the tensors (f32), the header and
/// its 8-byte length.
pub fn byte_cap(expected: &Expected) -> u64 {
    let data: u64 = expected.values().map(|s| 4 * s.iter().map(|&d| d as u64).product::<u64>()).sum();
    data.saturating_add(8 + HEADER_MAX)
}

/// Reads the safetensors file `path` as regular file of at most [`byte_cap`] bytes
/// (special files and links to them are refused; a sparse file of gigabytes is refused by
/// its size before a byte is read), then checks its header against `expected` (every name
/// known, f32, its shape) before any tensor is made.
pub fn read_tensors(
    path: &Path,
    expected: &Expected,
    device: &Device,
) -> Result<HashMap<String, Tensor>, CheckpointError> {
    let format = |message: String| CheckpointError::Format { path: path.to_path_buf(), message };
    let bytes = campro::file::read_capped(path, byte_cap(expected), "a tensor file")
        .map_err(|e| CheckpointError::Io { path: path.to_path_buf(), message: e.reason() })?;
    let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| format(e.to_string()))?;
    let views = st.tensors();
    for (name, view) in &views {
        let Some(shape) = expected.get(name) else {
            return Err(format(format!("tensor {name:?} is not one this file may hold")));
        };
        if view.dtype() != safetensors::Dtype::F32 || view.shape() != shape.as_slice() {
            return Err(format(format!(
                "tensor {name:?} is {:?} {:?}; expected F32 {shape:?}",
                view.dtype(),
                view.shape()
            )));
        }
    }
    views
        .into_iter()
        .map(|(name, view)| {
            let t = Tensor::from_raw_buffer(view.data(), candle_core::DType::F32, view.shape(), device)
                .map_err(|e| format(format!("tensor {name:?}: {e}")))?;
            Ok((name, t))
        })
        .collect()
}

/// Refuses a checkpoint whose counter (`"round"` or `"step"`, its value) is past the run's
/// budget (its field, its value; budgets are at most [`crate::config::MAX_ROUNDS`]): a
/// counter of u64::MAX once wrapped to 0 and restarted the run.
pub fn within_budget(
    dir: &Path,
    (what, at): (&str, usize),
    (field, budget): (&str, usize),
) -> Result<(), CheckpointError> {
    if at > budget {
        return Err(CheckpointError::Format {
            path: dir.to_path_buf(),
            message: format!(
                "a checkpoint of {what} {at}, past {field} {budget} (at most {}): nothing to resume",
                crate::config::MAX_ROUNDS
            ),
        });
    }
    Ok(())
}

/// Reads a checkpoint written by [`save`]: its state (capped JSON) and its tensors, read
/// only if they are among `expected` ([`read_tensors`]).
pub fn load<S: serde::de::DeserializeOwned>(
    dir: &Path,
    expected: &Expected,
    device: &Device,
) -> Result<(HashMap<String, Tensor>, S), CheckpointError> {
    let sp = dir.join(STATE);
    let text = campro::file::read_capped(&sp, 16 << 20, "a checkpoint state")
        .map_err(|e| CheckpointError::Io { path: sp.clone(), message: e.reason() })?;
    let state: S =
        serde_json::from_slice(&text).map_err(|e| CheckpointError::Format { path: sp, message: e.to_string() })?;
    let tensors = read_tensors(&dir.join(TENSORS), expected, device)?;
    Ok((tensors, state))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expected() -> Expected {
        [("a".to_string(), vec![2, 3]), ("b".to_string(), vec![4])].into()
    }

    #[test]
    fn a_file_of_the_expected_tensors_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let a = Tensor::arange(0f32, 6.0, &Device::Cpu).unwrap().reshape((2, 3)).unwrap();
        write_tensors(dir.path(), "t.safetensors", &[("a".to_string(), a.clone())].into()).unwrap();
        let got = read_tensors(&dir.path().join("t.safetensors"), &expected(), &Device::Cpu).unwrap();
        assert_eq!(got["a"].to_vec2::<f32>().unwrap(), a.to_vec2::<f32>().unwrap());
        // 6 + 4 floats, the header and its length.
        assert_eq!(byte_cap(&expected()), 40 + 8 + HEADER_MAX);
    }

    #[test]
    fn an_unknown_name_another_shape_or_dtype_is_refused_by_its_header() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.safetensors");
        let err = |t: HashMap<String, Tensor>| {
            write_tensors(dir.path(), "t.safetensors", &t).unwrap();
            read_tensors(&p, &expected(), &Device::Cpu).unwrap_err().to_string()
        };
        let z = |s: &[usize]| Tensor::zeros(s, candle_core::DType::F32, &Device::Cpu).unwrap();
        assert!(err([("extra".to_string(), z(&[1]))].into()).contains("\"extra\" is not one this file may hold"));
        assert!(err([("a".to_string(), z(&[3, 2]))].into()).contains("expected F32 [2, 3]"));
        let f64s = Tensor::zeros(4, candle_core::DType::F64, &Device::Cpu).unwrap();
        assert!(err([("b".to_string(), f64s)].into()).contains("is F64"));
    }

    #[cfg(unix)]
    #[test]
    fn a_file_larger_than_its_tensors_can_be_is_refused_unread() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.safetensors");
        // Sparse: 2.8 GB on paper, nothing on disk.
        std::fs::File::create(&p).unwrap().set_len(2_800_000_000).unwrap();
        let e = read_tensors(&p, &expected(), &Device::Cpu).unwrap_err().to_string();
        assert!(e.contains("t.safetensors"), "{e}");
        // A link to a device is not a regular file.
        let link = dir.path().join("zero.safetensors");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        assert!(read_tensors(&link, &expected(), &Device::Cpu).is_err());
    }
}
