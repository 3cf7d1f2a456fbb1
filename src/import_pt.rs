//! Reading CamPro's own checkpoints (`Pipeline.save`: `torch.save` of an OrderedDict
//! `stage -> state_dict | None`, stages `degamma`, `ccm` {`ccm`: 3x3}, `gamma`
//! {`keypoints`: [k]}).
//!
//! The zip is read with `zip`, the pickle with [`crate::pickle`], which builds a tree of
//! plain values, never executes anything and bounds work, memory and depth. The tree is
//! then checked against an allow list of globals (OrderedDict, torch's tensor rebuild
//! functions and storage types); anything else is rejected by name. Storages tagged for
//! any device (`cpu`, `cuda:0`, ...) are read the same way: the bytes in the archive are
//! what matter. A checkpoint with neither a `ccm` nor a `gamma` stage is refused (it
//! would import as an unprotected identity).

use crate::ccm::Mat3;
use crate::params::Params;
use crate::pickle::{self, Value};
use crate::tone_curve::ToneCurve;
use std::io::{Cursor, Read};
use std::path::Path;

/// Largest checkpoint file read (bytes).
pub const MAX_FILE_BYTES: u64 = 64 << 20;
/// Largest pickle stream and storage entry read (bytes).
pub const MAX_ENTRY_BYTES: u64 = 16 << 20;

const ALLOWED_GLOBALS: &[(&str, &str)] = &[
    ("collections", "OrderedDict"),
    ("torch._utils", "_rebuild_tensor_v2"),
    ("torch._utils", "_rebuild_parameter"),
    ("torch", "FloatStorage"),
    ("torch", "DoubleStorage"),
];

/// Why a checkpoint could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CheckpointError {
    /// The file could not be read.
    #[error(transparent)]
    File(#[from] crate::file::FileError),
    /// Not a zip archive with a `data.pkl`.
    #[error("not a PyTorch zip checkpoint: {0}")]
    Zip(String),
    /// An entry is larger than [`MAX_ENTRY_BYTES`].
    #[error("checkpoint is larger than the {limit}-byte limit ({what})")]
    TooLarge {
        /// Which entry, how large.
        what: String,
        /// The limit, bytes.
        limit: u64,
    },
    /// The pickle is malformed or too costly to read.
    #[error("pickle: {0}")]
    Pickle(#[from] pickle::PickleError),
    /// The pickle names a global outside the allow list.
    #[error("pickle refers to global {module}.{name}, which is not allowed in a CamPro checkpoint")]
    ForbiddenGlobal {
        /// Its module.
        module: String,
        /// Its name.
        name: String,
    },
    /// The objects are not a CamPro pipeline's state.
    #[error("unexpected checkpoint layout at {at}: {problem}")]
    Layout {
        /// Where (`ccm.ccm`, `<root>`).
        at: String,
        /// What is wrong.
        problem: String,
    },
    /// The values break a parameter rule.
    #[error("checkpoint values are not valid parameters: {0}")]
    Invalid(#[from] crate::ValidationError),
}

fn layout(at: &str, problem: impl Into<String>) -> CheckpointError {
    CheckpointError::Layout { at: at.into(), problem: problem.into() }
}

/// A tensor read from the archive, as f64 in row-major order.
#[derive(Debug, Clone, PartialEq)]
pub struct Tensor {
    /// Its shape.
    pub shape: Vec<usize>,
    /// Its values, row-major.
    pub data: Vec<f64>,
    /// `float32` or `float64`.
    pub dtype: &'static str,
    /// The device it was saved from (`cpu`, `cuda:0`).
    pub device: String,
}

/// Reads a CamPro checkpoint into a parameter set (description and provenance filled in).
pub fn read_checkpoint(path: &Path) -> Result<Params, CheckpointError> {
    let bytes = crate::file::read_capped(path, MAX_FILE_BYTES, "a checkpoint")?;
    let mut p = read_checkpoint_bytes(&bytes)?;
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    p.name = name.clone();
    p.description = format!(
        "Imported from the CamPro checkpoint {}",
        path.file_name().map(|s| s.to_string_lossy()).unwrap_or_default()
    );
    p.provenance.insert(
        "checkpoint".into(),
        serde_json::Value::String(path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()),
    );
    Ok(p)
}

/// Reads a CamPro checkpoint held in memory.
pub fn read_checkpoint_bytes(bytes: &[u8]) -> Result<Params, CheckpointError> {
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).map_err(|e| CheckpointError::Zip(e.to_string()))?;
    let pkl_name = zip
        .file_names()
        .find(|n| n.ends_with("/data.pkl") || *n == "data.pkl")
        .map(str::to_owned)
        .ok_or_else(|| CheckpointError::Zip("no data.pkl entry".into()))?;
    let prefix = pkl_name.strip_suffix("data.pkl").unwrap_or("").to_owned();
    let big_endian = match read_entry(&mut zip, &format!("{prefix}byteorder")) {
        Ok(b) => b.trim_ascii() == b"big",
        Err(_) => false,
    };
    let pkl = read_entry(&mut zip, &pkl_name)?;
    let root = pickle::read(&pkl, pickle::Limits::default())?;
    check_globals(&root)?;

    let stages = dict_of(&root)
        .ok_or_else(|| layout("<root>", format!("expected an OrderedDict of stages, found {}", root.kind())))?;
    let mut order = Vec::new();
    let mut ccm: Option<Tensor> = None;
    let mut keypoints: Option<Tensor> = None;
    for (k, v) in stages {
        let name = k
            .as_str()
            .ok_or_else(|| layout("<root>", format!("stage names must be strings, found {}", k.kind())))?
            .to_string();
        if order.contains(&name) {
            return Err(layout(&name, "the stage appears twice"));
        }
        match name.as_str() {
            "degamma" => {
                if *v != Value::None {
                    return Err(layout("degamma", "expected None (degamma has no parameters)"));
                }
            }
            "ccm" => ccm = Some(state_tensor(&mut zip, &prefix, big_endian, v, "ccm", "ccm")?),
            "gamma" => keypoints = Some(state_tensor(&mut zip, &prefix, big_endian, v, "gamma", "keypoints")?),
            other => return Err(layout(other, "unknown stage (CamPro pipelines have degamma, ccm, gamma)")),
        }
        order.push(name);
    }
    // CamPro's pipelines run degamma, ccm, gamma, as this crate does.
    if !order.windows(2).all(|w| stage_rank(&w[0]) < stage_rank(&w[1])) {
        return Err(layout("<root>", format!("stages {order:?} are not in the order degamma, ccm, gamma")));
    }
    if ccm.is_none() && keypoints.is_none() {
        return Err(layout(
            "<root>",
            "neither a ccm nor a gamma stage: nothing to import (it would be an unprotected identity)",
        ));
    }
    let mut m: Mat3 = crate::ccm::IDENTITY;
    let mut dtype = "float32";
    let mut device = "cpu".to_string();
    if let Some(t) = &ccm {
        if t.shape != [3, 3] {
            return Err(layout("ccm.ccm", format!("expected shape [3, 3], found {:?}", t.shape)));
        }
        for i in 0..9 {
            m[i / 3][i % 3] = t.data[i];
        }
        dtype = t.dtype;
        device = t.device.clone();
    }
    let curve = match &keypoints {
        Some(t) => {
            if t.shape.len() != 1 || t.shape[0] < 2 {
                return Err(layout("gamma.keypoints", format!("expected shape [k] with k >= 2, found {:?}", t.shape)));
            }
            ToneCurve::uniform(t.data.clone()).map_err(|e| e.within("gamma.keypoints"))?
        }
        None => ToneCurve::identity(2),
    };
    let degamma = if order.iter().any(|s| s == "degamma") { 2.2 } else { 1.0 };
    let mut p = Params::new(m, curve, degamma).map_err(CheckpointError::Invalid)?;
    p.provenance.insert("source".into(), "CamPro Pipeline.save checkpoint".into());
    p.provenance.insert("stages".into(), serde_json::json!(order));
    p.provenance.insert("dtype".into(), dtype.into());
    p.provenance.insert("device".into(), device.into());
    Ok(p)
}

fn read_entry(zip: &mut zip::ZipArchive<Cursor<&[u8]>>, name: &str) -> Result<Vec<u8>, CheckpointError> {
    let f = zip.by_name(name).map_err(|e| CheckpointError::Zip(format!("{name}: {e}")))?;
    if f.size() > MAX_ENTRY_BYTES {
        return Err(CheckpointError::TooLarge {
            what: format!("entry {name} is {} bytes", f.size()),
            limit: MAX_ENTRY_BYTES,
        });
    }
    let mut buf = Vec::with_capacity(f.size() as usize);
    // take() guards against a size field that lies.
    f.take(MAX_ENTRY_BYTES + 1).read_to_end(&mut buf).map_err(|e| CheckpointError::Zip(format!("{name}: {e}")))?;
    if buf.len() as u64 > MAX_ENTRY_BYTES {
        return Err(CheckpointError::TooLarge { what: format!("entry {name}"), limit: MAX_ENTRY_BYTES });
    }
    Ok(buf)
}

fn stage_rank(s: &str) -> usize {
    ["degamma", "ccm", "gamma"].iter().position(|c| *c == s).unwrap_or(usize::MAX)
}

/// The (key, value) pairs of a dict, of an `OrderedDict()` call filled by SETITEMS (read
/// as a dict), or of either with BUILD state (a state dict's `_metadata`) attached.
fn dict_of(v: &Value) -> Option<Vec<(&Value, &Value)>> {
    match v {
        Value::Dict(_) => Some(v.as_dict()?.collect()),
        Value::Build(n) => dict_of(&n.items[0]),
        _ => None,
    }
}

fn check_globals(v: &Value) -> Result<(), CheckpointError> {
    for (module, name) in v.globals() {
        if !ALLOWED_GLOBALS.iter().any(|(m, c)| *m == module && *c == name) {
            return Err(CheckpointError::ForbiddenGlobal { module: module.into(), name: name.into() });
        }
    }
    Ok(())
}

/// The tensor `key` of the state dict of `stage`.
fn state_tensor(
    zip: &mut zip::ZipArchive<Cursor<&[u8]>>,
    prefix: &str,
    big_endian: bool,
    state: &Value,
    stage: &str,
    key: &str,
) -> Result<Tensor, CheckpointError> {
    let at = format!("{stage}.{key}");
    let kv = dict_of(state).ok_or_else(|| layout(stage, format!("expected a state_dict, found {}", state.kind())))?;
    let value = kv
        .into_iter()
        .find(|(k, _)| k.as_str() == Some(key))
        .map(|(_, v)| v)
        .ok_or_else(|| layout(stage, format!("state_dict has no '{key}'")))?;
    let r = tensor_ref(value, &at, 1 << 20)?;
    let bytes = read_entry(zip, &format!("{prefix}data/{}", r.key))?;
    r.gather(&bytes, big_endian, &at)
}

/// Where a tensor's values are: a storage, an offset, a shape and strides.
#[derive(Debug, Clone)]
struct TensorRef {
    key: String,
    dtype: &'static str,
    width: usize,
    device: String,
    offset: usize,
    shape: Vec<usize>,
    stride: Vec<usize>,
    numel: usize,
}

/// Reads a `_rebuild_tensor_v2` call (an `nn.Parameter` around one is unwrapped) whose
/// storage reference is `('storage', type, key, device, numel)` (zip checkpoints) or the
/// same with a sixth view field (legacy checkpoints); at most `max_numel` elements.
fn tensor_ref(value: &Value, at: &str, max_numel: usize) -> Result<TensorRef, CheckpointError> {
    // A call `callable(args...)` as (callable, args).
    let call = |v: &'_ Value| match v {
        Value::Reduce(n) => Some((n.items[0].clone(), n.items[1].as_seq().map(<[Value]>::to_vec))),
        _ => None,
    };
    // Unwrap nn.Parameter if present.
    let value = match call(value) {
        Some((c, args)) if c.is_global("torch._utils", "_rebuild_parameter") => match args {
            Some(a) if !a.is_empty() => a[0].clone(),
            _ => return Err(layout(at, "malformed _rebuild_parameter arguments")),
        },
        _ => value.clone(),
    };
    let args = match call(&value) {
        Some((c, args)) if c.is_global("torch._utils", "_rebuild_tensor_v2") => {
            args.ok_or_else(|| layout(at, "malformed _rebuild_tensor_v2 arguments"))?
        }
        _ => return Err(layout(at, format!("expected a tensor, found {}", value.kind()))),
    };
    if args.len() < 4 {
        return Err(layout(at, "tensor rebuild needs storage, offset, shape and stride"));
    }
    let storage = match &args[0] {
        Value::PersistentId(n) => n.items[0].as_seq().ok_or_else(|| layout(at, "malformed storage reference"))?,
        _ => return Err(layout(at, "expected a storage reference")),
    };
    if !(5..=6).contains(&storage.len()) || storage[0].as_str() != Some("storage") {
        return Err(layout(at, "storage reference is not ('storage', type, key, device, numel)"));
    }
    let (dtype, width) = match &storage[1] {
        v if v.is_global("torch", "FloatStorage") => ("float32", 4usize),
        v if v.is_global("torch", "DoubleStorage") => ("float64", 8),
        v if v.is_global("torch", "LongStorage") => ("int64", 8),
        _ => return Err(layout(at, "storage type must be FloatStorage, DoubleStorage or LongStorage")),
    };
    let (key, device) = match (storage[2].as_str(), storage[3].as_str()) {
        (Some(k), Some(d)) => (k.to_string(), d.to_string()),
        _ => return Err(layout(at, "storage key and device must be strings")),
    };
    if key.is_empty() || key.len() > 64 || !key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(layout(at, format!("storage key {key:?} is not a plain name")));
    }
    let offset = int(&args[1]).ok_or_else(|| layout(at, "storage offset must be a non-negative integer"))?;
    let shape = ints(&args[2]).ok_or_else(|| layout(at, "shape must be a tuple of non-negative integers"))?;
    let stride = ints(&args[3]).ok_or_else(|| layout(at, "stride must be a tuple of non-negative integers"))?;
    if shape.len() != stride.len() || shape.len() > 4 {
        return Err(layout(at, "shape and stride must have the same rank (at most 4)"));
    }
    let numel: usize = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .filter(|&n| n <= max_numel)
        .ok_or_else(|| layout(at, "tensor is too large"))?;
    Ok(TensorRef { key, dtype, width, device, offset, shape, stride, numel })
}

impl TensorRef {
    /// The tensor's values from its storage's bytes, by strides, as f64.
    fn gather(&self, bytes: &[u8], big_endian: bool, at: &str) -> Result<Tensor, CheckpointError> {
        let width = self.width;
        let count = bytes.len() / width;
        let mut data = Vec::with_capacity(self.numel);
        for flat in 0..self.numel {
            let mut rem = flat;
            let mut idx = self.offset;
            for d in (0..self.shape.len()).rev() {
                idx += (rem % self.shape[d]) * self.stride[d];
                rem /= self.shape[d];
            }
            if idx >= count {
                return Err(layout(at, format!("element {flat} lies outside its storage ({count} values)")));
            }
            let b = &bytes[idx * width..(idx + 1) * width];
            let v = match (self.dtype, big_endian) {
                ("float32", false) => f32::from_le_bytes(b.try_into().unwrap()) as f64,
                ("float32", true) => f32::from_be_bytes(b.try_into().unwrap()) as f64,
                ("float64", false) => f64::from_le_bytes(b.try_into().unwrap()),
                ("float64", true) => f64::from_be_bytes(b.try_into().unwrap()),
                (_, false) => i64::from_le_bytes(b.try_into().unwrap()) as f64,
                (_, true) => i64::from_be_bytes(b.try_into().unwrap()) as f64,
            };
            data.push(v);
        }
        Ok(Tensor { shape: self.shape.clone(), data, dtype: self.dtype, device: self.device.clone() })
    }
}

/// The first pickle of a legacy (pre-1.6, non-zip) `torch.save` file, byte for byte:
/// protocol 2, the magic number 0x1950a86a20f9469cfc6c as a 10-byte LONG1, STOP.
const LEGACY_MAGIC: [u8; 15] =
    [0x80, 0x02, 0x8a, 0x0a, 0x6c, 0xfc, 0x9c, 0x46, 0xf9, 0x20, 0x6a, 0xa8, 0x50, 0x19, 0x2e];

/// Globals a legacy state dict may name (checked like a CamPro checkpoint's; nothing runs).
const LEGACY_GLOBALS: &[(&str, &str)] = &[
    ("collections", "OrderedDict"),
    ("torch._utils", "_rebuild_tensor_v2"),
    ("torch._utils", "_rebuild_parameter"),
    ("torch", "FloatStorage"),
    ("torch", "DoubleStorage"),
    ("torch", "LongStorage"),
];

/// Reads the state dict of a legacy (pre-1.6, non-zip) `torch.save` file with the same
/// bounded pickle reader as CamPro checkpoints: the magic pickle, protocol, system info,
/// the object pickle, the storage keys, then each storage as a little-endian i64 element
/// count and its bytes. Returns every tensor of `key`'s state dict (or of the top-level
/// dict when `key` is None), in the dict's order. `bytes` is the whole file (read with
/// [`crate::file::read_capped`]); every element count is checked against what is left.
pub fn read_legacy_state_dict(bytes: &[u8], key: Option<&str>) -> Result<Vec<(String, Tensor)>, CheckpointError> {
    let fmt = |problem: String| layout("<legacy>", problem);
    let Some(mut rest) = bytes.strip_prefix(&LEGACY_MAGIC[..]) else {
        return Err(fmt(if bytes.starts_with(b"PK") {
            "a zip checkpoint, not the legacy format".into()
        } else {
            "not a legacy torch checkpoint (magic number missing)".into()
        }));
    };
    // Limits for a network's state dict: hundreds of tensors, each a few dozen values.
    let limits = pickle::Limits { max_work: 20_000_000, max_nodes: 5_000_000, ..pickle::Limits::default() };
    let next = |rest: &mut &[u8]| -> Result<Value, CheckpointError> {
        let (v, used) = pickle::read_prefix(rest, limits)?;
        *rest = &rest[used..];
        Ok(v)
    };
    let _protocol = next(&mut rest)?;
    let _sys_info = next(&mut rest)?;
    let main = next(&mut rest)?;
    let keys = next(&mut rest)?;
    for v in [&main, &keys] {
        for (module, name) in v.globals() {
            if !LEGACY_GLOBALS.iter().any(|(m, c)| *m == module && *c == name) {
                return Err(CheckpointError::ForbiddenGlobal { module: module.into(), name: name.into() });
            }
        }
    }
    let keys: Vec<String> = keys
        .as_seq()
        .ok_or_else(|| fmt("the storage key list is missing".into()))?
        .iter()
        .map(|k| k.as_str().map(str::to_string).ok_or_else(|| fmt("a storage key is not a string".into())))
        .collect::<Result<_, _>>()?;
    let root = dict_of(&main).ok_or_else(|| fmt(format!("expected a dict, found {}", main.kind())))?;
    let dict = match key {
        Some(k) => {
            let v = root
                .into_iter()
                .find(|(name, _)| name.as_str() == Some(k))
                .map(|(_, v)| v)
                .ok_or_else(|| fmt(format!("no {k:?} in the checkpoint")))?;
            dict_of(v).ok_or_else(|| layout(k, format!("expected a state dict, found {}", v.kind())))?
        }
        None => root,
    };
    let mut refs = Vec::with_capacity(dict.len());
    for (name, v) in dict {
        let name = name.as_str().ok_or_else(|| fmt("a state dict key is not a string".into()))?;
        refs.push((name.to_string(), tensor_ref(v, name, 1 << 24)?));
    }
    // Storages follow in key order; each must be referenced, with a known width.
    let mut storages: std::collections::HashMap<&str, &[u8]> = std::collections::HashMap::new();
    for k in &keys {
        let width = refs
            .iter()
            .find(|(_, r)| &r.key == k)
            .map(|(_, r)| r.width)
            .ok_or_else(|| fmt(format!("storage {k} is not used by any tensor")))?;
        let n = rest.get(..8).ok_or_else(|| fmt(format!("storage {k}: the file ends before its size")))?;
        let n = i64::from_le_bytes(n.try_into().expect("8 bytes"));
        rest = &rest[8..];
        let len = usize::try_from(n)
            .ok()
            .and_then(|n| n.checked_mul(width))
            .filter(|&b| b <= rest.len())
            .ok_or_else(|| fmt(format!("storage {k}: {n} elements do not fit in the {} bytes left", rest.len())))?;
        storages.insert(k, &rest[..len]);
        rest = &rest[len..];
    }
    let mut out = Vec::with_capacity(refs.len());
    for (name, r) in refs {
        let data = storages.get(r.key.as_str()).ok_or_else(|| layout(&name, format!("storage {} missing", r.key)))?;
        out.push((name.clone(), r.gather(data, false, &name)?));
    }
    Ok(out)
}

fn int(v: &Value) -> Option<usize> {
    v.as_int().filter(|&x| (0..1 << 40).contains(&x)).map(|x| x as usize)
}

fn ints(v: &Value) -> Option<Vec<usize>> {
    match v {
        Value::Tuple(_) => v.as_seq()?.iter().map(int).collect(),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A legacy `torch.save` of {"net_state_dict": {w: 2x3 floats 1..6, wt: its transpose
    /// (a view of the same storage), n: a long 7}, "epoch": 68}, written by Python's pickle
    /// (protocol 2) with torch's persistent ids and storage layout.
    const LEGACY_HEX: &str = concat!(
        "80028a0a6cfc9c46f9206aa850192e80024de9032e80027d7100580d0000006c6974746c655f656e6469616e71018873",
        "2e80027d710028580e0000006e65745f73746174655f64696374710163636f6c6c656374696f6e730a4f726465726564",
        "446963740a71022952710328580100000077710463746f7263682e5f7574696c730a5f72656275696c645f74656e736f",
        "725f76320a71052828580700000073746f72616765710663746f7263680a466c6f617453746f726167650a7107580100",
        "0000307108580300000063707571094b064e74710a514b004b024b0386710b4b034b0186710c8968022952710d74710e",
        "52710f5802000000777471106805282868066807680868094b064e747111514b004b034b028671124b014b0386711389",
        "68022952711474711552711658010000006e711768052828680663746f7263680a4c6f6e6753746f726167650a711858",
        "0100000031711968094b014e74711a514b0029298968022952711b74711c52711d75580500000065706f6368711e4b44",
        "752e80025d71002858010000003071015801000000317102652e06000000000000000000803f00000040000040400000",
        "80400000a0400000c04001000000000000000700000000000000",
    );

    fn legacy() -> Vec<u8> {
        (0..LEGACY_HEX.len()).step_by(2).map(|i| u8::from_str_radix(&LEGACY_HEX[i..i + 2], 16).unwrap()).collect()
    }

    #[test]
    fn legacy_state_dicts_are_read_by_the_bounded_reader() {
        let b = legacy();
        let t = read_legacy_state_dict(&b, Some("net_state_dict")).unwrap();
        let names: Vec<&str> = t.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["w", "wt", "n"]);
        assert_eq!(t[0].1.shape, [2, 3]);
        assert_eq!(t[0].1.data, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        // The transpose is gathered by its strides from the same storage.
        assert_eq!(t[1].1.data, [1.0, 4.0, 2.0, 5.0, 3.0, 6.0]);
        assert_eq!((t[2].1.dtype, t[2].1.data.as_slice()), ("int64", &[7.0][..]));
        let e = read_legacy_state_dict(&b, Some("nope")).unwrap_err().to_string();
        assert!(e.contains("no \"nope\""), "{e}");
    }

    #[test]
    fn hostile_legacy_files_are_refused_with_one_line() {
        let b = legacy();
        // A storage claiming more elements than the file holds: refused, nothing allocated.
        let at = b.len() - 8 - 8 - 24 - 8;
        let mut big = b.clone();
        big[at..at + 8].copy_from_slice(&(1i64 << 60).to_le_bytes());
        let e = read_legacy_state_dict(&big, Some("net_state_dict")).unwrap_err().to_string();
        assert!(e.contains("do not fit"), "{e}");
        let e = read_legacy_state_dict(&b[..b.len() - 3], Some("net_state_dict")).unwrap_err().to_string();
        assert!(e.contains("do not fit"), "{e}");
        // A zip, or anything else.
        let e = read_legacy_state_dict(b"PK\x03\x04", None).unwrap_err().to_string();
        assert!(e.contains("a zip checkpoint"), "{e}");
        // A global that is not a tensor part: refused before anything is built from it.
        let mut evil = b.clone();
        let pos = evil.windows(13).position(|w| w == b"FloatStorage\n").unwrap();
        evil[pos..pos + 12].copy_from_slice(b"FloatStoragX");
        let e = read_legacy_state_dict(&evil, Some("net_state_dict")).unwrap_err().to_string();
        assert!(e.contains("torch.FloatStoragX"), "{e}");
        // A pickle nested deeper than the limit: an error, not a stack overflow.
        let mut deep = LEGACY_MAGIC.to_vec();
        deep.extend(b"\x80\x02");
        deep.extend(std::iter::repeat_n(b']', 100_000));
        let e = read_legacy_state_dict(&deep, None).unwrap_err().to_string();
        assert!(e.starts_with("pickle: "), "{e}");
    }
}
