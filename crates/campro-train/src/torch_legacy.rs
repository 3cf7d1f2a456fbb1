//! PyTorch's legacy (pre-1.6, non-zip) `torch.save` format: a pickle of the magic number,
//! the protocol version and system info, the object pickle (tensors as persistent-id
//! references to storages), a pickle of the storage keys, then each storage as a
//! little-endian i64 element count and its raw bytes. The pickles are read with candle's
//! pickle reader, which builds objects and never executes code.

use candle_core::pickle::{Object, Stack};
use candle_core::{DType, Device, Tensor};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// The first pickle of a legacy checkpoint, byte for byte: protocol 2, the magic number
/// 0x1950a86a20f9469cfc6c as a 10-byte LONG1, STOP.
const MAGIC_PICKLE: [u8; 15] =
    [0x80, 0x02, 0x8a, 0x0a, 0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19, 0x2e];

#[derive(Debug, thiserror::Error)]
pub enum TorchError {
    #[error("{path}: {message}")]
    Format { path: String, message: String },
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
}

fn pickle<R: BufRead>(r: &mut R) -> candle_core::Result<Object> {
    let mut s = Stack::empty();
    s.read_loop(r)?;
    s.finalize()
}

/// Reads every tensor of `key`'s state dict (or of the top-level dict when `key` is None)
/// as f32 (integer buffers such as `num_batches_tracked` are skipped).
pub fn read_state_dict(path: &Path, key: Option<&str>) -> Result<HashMap<String, Tensor>, TorchError> {
    let p = path.display().to_string();
    let fmt = |message: String| TorchError::Format { path: p.clone(), message };
    let file = std::fs::File::open(path).map_err(|error| TorchError::Io { path: p.clone(), error })?;
    let mut r = BufReader::new(file);
    let mut head = [0u8; 15];
    if r.read_exact(&mut head).is_err() || head != MAGIC_PICKLE {
        let kind = if head.starts_with(b"PK") {
            "a zip checkpoint, not the legacy format"
        } else {
            "not a legacy torch checkpoint (magic number missing)"
        };
        return Err(fmt(kind.into()));
    }
    let _protocol = pickle(&mut r).map_err(|e| fmt(e.to_string()))?;
    let _sys_info = pickle(&mut r).map_err(|e| fmt(e.to_string()))?;
    let main = pickle(&mut r).map_err(|e| fmt(e.to_string()))?;
    let keys = pickle(&mut r).map_err(|e| fmt(e.to_string()))?;
    let keys: Vec<String> = match keys {
        Object::List(v) => v
            .into_iter()
            .map(|k| k.unicode().map_err(|_| fmt("storage key is not a string".into())))
            .collect::<Result<_, _>>()?,
        _ => return Err(fmt("storage key list missing".into())),
    };
    let dict = match (main, key) {
        (Object::Dict(kv), Some(k)) => kv
            .into_iter()
            .find(|(name, _)| *name == Object::Unicode(k.to_string()))
            .map(|(_, v)| v)
            .ok_or_else(|| fmt(format!("no {k:?} in the checkpoint")))?,
        (o, _) => o,
    };
    let Object::Dict(entries) = dict else { return Err(fmt("the state dict is not a dict".into())) };
    let infos: Vec<_> =
        entries.into_iter().filter_map(|(n, v)| v.into_tensor_info(n, Path::new("")).ok().flatten()).collect();
    // Storages follow in key order: i64 element count, then the bytes.
    let mut storages: HashMap<String, (DType, Vec<u8>)> = HashMap::new();
    let dtype_of: HashMap<String, DType> =
        infos.iter().map(|i| (i.path.trim_start_matches('/').to_string(), i.dtype)).collect();
    for k in keys {
        let mut n = [0u8; 8];
        r.read_exact(&mut n).map_err(|e| fmt(format!("storage {k}: {e}")))?;
        let n = i64::from_le_bytes(n);
        let dtype = *dtype_of.get(&k).unwrap_or(&DType::F32);
        let bytes = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(dtype.size_in_bytes()))
            .filter(|&b| b <= 1 << 32)
            .ok_or_else(|| fmt(format!("storage {k}: bad size {n}")))?;
        let mut buf = vec![0u8; bytes];
        r.read_exact(&mut buf).map_err(|e| fmt(format!("storage {k}: {e}")))?;
        storages.insert(k, (dtype, buf));
    }
    let mut out = HashMap::new();
    for info in infos {
        if info.dtype != DType::F32 {
            continue;
        }
        let key = info.path.trim_start_matches('/');
        let (_, bytes) = storages.get(key).ok_or_else(|| fmt(format!("{}: storage {key} missing", info.name)))?;
        let all: Vec<f32> = bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        let shape = info.layout.shape().dims().to_vec();
        let strides = info.layout.stride().to_vec();
        let start = info.layout.start_offset() / 4;
        let numel: usize = shape.iter().product();
        // Gather by strides (checkpoints may hold views).
        let mut data = Vec::with_capacity(numel);
        let mut idx = vec![0usize; shape.len()];
        for _ in 0..numel {
            let off = start + idx.iter().zip(&strides).map(|(i, s)| i * s).sum::<usize>();
            data.push(*all.get(off).ok_or_else(|| fmt(format!("{}: view outside its storage", info.name)))?);
            for d in (0..shape.len()).rev() {
                idx[d] += 1;
                if idx[d] < shape[d] {
                    break;
                }
                idx[d] = 0;
            }
        }
        let t = Tensor::from_vec(data, shape, &Device::Cpu).map_err(|e| fmt(e.to_string()))?;
        out.insert(info.name, t);
    }
    Ok(out)
}
