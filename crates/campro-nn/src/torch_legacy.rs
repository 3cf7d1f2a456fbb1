//! PyTorch's legacy (pre-1.6, non-zip) `torch.save` format, read with the core's bounded
//! pickle reader ([`campro::import_pt::read_legacy_state_dict`], the same one CamPro
//! checkpoints go through): the file is a regular file read with a byte cap, the pickles
//! build values within fixed limits and never execute code, and every storage size is
//! checked against the bytes that are left.

use candle_core::{Device, Tensor};
use std::collections::HashMap;
use std::path::Path;

/// Largest legacy checkpoint read, bytes.
pub const MAX_FILE_BYTES: u64 = 256 << 20;

#[derive(Debug, thiserror::Error)]
pub enum TorchError {
    #[error("{path}: {message}")]
    Format { path: String, message: String },
    #[error(transparent)]
    File(#[from] campro::file::FileError),
}

/// Reads every tensor of `key`'s state dict (or of the top-level dict when `key` is None)
/// as f32 on `device` (integer buffers such as `num_batches_tracked` are skipped).
pub fn read_state_dict(path: &Path, key: Option<&str>, device: &Device) -> Result<HashMap<String, Tensor>, TorchError> {
    let p = campro::file::shown(path);
    let fmt = |message: String| TorchError::Format { path: p.clone(), message };
    let bytes = campro::file::read_capped(path, MAX_FILE_BYTES, "a torch checkpoint")?;
    let tensors = campro::import_pt::read_legacy_state_dict(&bytes, key).map_err(|e| fmt(e.to_string()))?;
    let mut out = HashMap::new();
    for (name, t) in tensors {
        if t.dtype == "int64" {
            continue;
        }
        let data: Vec<f32> = t.data.iter().map(|&v| v as f32).collect();
        let tensor = Tensor::from_vec(data, t.shape, device).map_err(|e| fmt(format!("{name}: {e}")))?;
        out.insert(name, tensor);
    }
    Ok(out)
}
