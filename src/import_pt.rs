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
    // A call `callable(args...)` as (callable, args).
    let call = |v: &'_ Value| match v {
        Value::Reduce(n) => Some((n.items[0].clone(), n.items[1].as_seq().map(<[Value]>::to_vec))),
        _ => None,
    };
    // Unwrap nn.Parameter if present.
    let value = match call(value) {
        Some((c, args)) if c.is_global("torch._utils", "_rebuild_parameter") => match args {
            Some(a) if !a.is_empty() => a[0].clone(),
            _ => return Err(layout(&at, "malformed _rebuild_parameter arguments")),
        },
        _ => value.clone(),
    };
    let args = match call(&value) {
        Some((c, args)) if c.is_global("torch._utils", "_rebuild_tensor_v2") => {
            args.ok_or_else(|| layout(&at, "malformed _rebuild_tensor_v2 arguments"))?
        }
        _ => return Err(layout(&at, format!("expected a tensor, found {}", value.kind()))),
    };
    if args.len() < 4 {
        return Err(layout(&at, "tensor rebuild needs storage, offset, shape and stride"));
    }
    let storage = match &args[0] {
        Value::PersistentId(n) => n.items[0].as_seq().ok_or_else(|| layout(&at, "malformed storage reference"))?,
        _ => return Err(layout(&at, "expected a storage reference")),
    };
    // ('storage', torch.FloatStorage, key, device, numel)
    if storage.len() != 5 || storage[0].as_str() != Some("storage") {
        return Err(layout(&at, "storage reference is not ('storage', type, key, device, numel)"));
    }
    let (dtype, width) = match &storage[1] {
        v if v.is_global("torch", "FloatStorage") => ("float32", 4usize),
        v if v.is_global("torch", "DoubleStorage") => ("float64", 8),
        _ => return Err(layout(&at, "storage type must be FloatStorage or DoubleStorage")),
    };
    let (skey, device) = match (storage[2].as_str(), storage[3].as_str()) {
        (Some(k), Some(d)) => (k.to_string(), d.to_string()),
        _ => return Err(layout(&at, "storage key and device must be strings")),
    };
    if skey.is_empty() || !skey.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(layout(&at, format!("storage key {skey:?} is not a plain name")));
    }
    let offset = int(&args[1]).ok_or_else(|| layout(&at, "storage offset must be a non-negative integer"))?;
    let shape = ints(&args[2]).ok_or_else(|| layout(&at, "shape must be a tuple of non-negative integers"))?;
    let stride = ints(&args[3]).ok_or_else(|| layout(&at, "stride must be a tuple of non-negative integers"))?;
    if shape.len() != stride.len() || shape.len() > 4 {
        return Err(layout(&at, "shape and stride must have the same rank (at most 4)"));
    }
    let numel: usize = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .filter(|&n| n <= 1 << 20)
        .ok_or_else(|| layout(&at, "tensor is too large"))?;
    let bytes = read_entry(zip, &format!("{prefix}data/{skey}"))?;
    let count = bytes.len() / width;
    let mut data = Vec::with_capacity(numel);
    for flat in 0..numel {
        let mut rem = flat;
        let mut idx = offset;
        for d in (0..shape.len()).rev() {
            idx += (rem % shape[d]) * stride[d];
            rem /= shape[d];
        }
        if idx >= count {
            return Err(layout(&at, format!("element {flat} lies outside its storage ({count} values)")));
        }
        let b = &bytes[idx * width..(idx + 1) * width];
        let v = match (width, big_endian) {
            (4, false) => f32::from_le_bytes(b.try_into().unwrap()) as f64,
            (4, true) => f32::from_be_bytes(b.try_into().unwrap()) as f64,
            (_, false) => f64::from_le_bytes(b.try_into().unwrap()),
            (_, true) => f64::from_be_bytes(b.try_into().unwrap()),
        };
        data.push(v);
    }
    Ok(Tensor { shape, data, dtype, device })
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
