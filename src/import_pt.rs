//! Reading CamPro's own checkpoints (`Pipeline.save`: `torch.save` of an OrderedDict
//! `stage -> state_dict | None`, stages `degamma`, `ccm` {`ccm`: 3x3}, `gamma`
//! {`keypoints`: [k]}).
//!
//! The zip is read with `zip`, the pickle with candle's pickle reader, which builds an
//! object tree and never executes anything. The tree is then checked against an allow
//! list of globals (OrderedDict, torch's tensor rebuild functions and storage types);
//! anything else is rejected by name. Storages tagged for any device (`cpu`, `cuda:0`,
//! ...) are read the same way: the bytes in the archive are what matter. Sizes, opcode
//! counts and memo copies are bounded, so a hostile file cannot exhaust memory.

use crate::ccm::Mat3;
use crate::params::Params;
use crate::tone_curve::ToneCurve;
use candle_core::pickle::{Object, Stack};
use std::io::{Cursor, Read};
use std::path::Path;

/// Largest checkpoint file read (bytes).
pub const MAX_FILE_BYTES: u64 = 64 << 20;
/// Largest pickle stream and storage entry read (bytes).
pub const MAX_ENTRY_BYTES: u64 = 16 << 20;
const MAX_OPS: usize = 200_000;
const MAX_COPIED_NODES: usize = 1_000_000;

const ALLOWED_GLOBALS: &[(&str, &str)] = &[
    ("collections", "OrderedDict"),
    ("torch._utils", "_rebuild_tensor_v2"),
    ("torch._utils", "_rebuild_parameter"),
    ("torch", "FloatStorage"),
    ("torch", "DoubleStorage"),
];

/// Why a checkpoint could not be read.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("not a PyTorch zip checkpoint: {0}")]
    Zip(String),
    #[error("checkpoint is larger than the {limit}-byte limit ({what})")]
    TooLarge { what: String, limit: u64 },
    #[error("corrupt pickle stream: {0}")]
    Pickle(String),
    #[error("pickle refers to global {module}.{name}, which is not allowed in a CamPro checkpoint")]
    ForbiddenGlobal { module: String, name: String },
    #[error("unexpected checkpoint layout at {at}: {problem}")]
    Layout { at: String, problem: String },
    #[error("checkpoint values are not valid parameters: {0}")]
    Invalid(#[from] crate::ValidationError),
}

fn layout(at: &str, problem: impl Into<String>) -> CheckpointError {
    CheckpointError::Layout { at: at.into(), problem: problem.into() }
}

/// A tensor read from the archive, as f64 in row-major order.
#[derive(Debug, Clone, PartialEq)]
pub struct Tensor {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
    pub dtype: &'static str,
    pub device: String,
}

/// Reads a CamPro checkpoint into a parameter set (description and provenance filled in).
pub fn read_checkpoint(path: &Path) -> Result<Params, CheckpointError> {
    let io = |source| CheckpointError::Io { path: path.display().to_string(), source };
    let size = std::fs::metadata(path).map_err(io)?.len();
    if size > MAX_FILE_BYTES {
        return Err(CheckpointError::TooLarge { what: format!("file is {size} bytes"), limit: MAX_FILE_BYTES });
    }
    let bytes = std::fs::read(path).map_err(io)?;
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
    let root = unpickle(&pkl)?;
    check_globals(&root)?;

    let stages = match root {
        Object::Dict(kv) => kv,
        other => return Err(layout("<root>", format!("expected an OrderedDict of stages, found {}", kind(&other)))),
    };
    let mut order = Vec::new();
    let mut ccm: Option<Tensor> = None;
    let mut keypoints: Option<Tensor> = None;
    for (k, v) in stages {
        let name = match k {
            Object::Unicode(s) => s,
            other => return Err(layout("<root>", format!("stage names must be strings, found {}", kind(&other)))),
        };
        match name.as_str() {
            "degamma" => {
                if v != Object::None {
                    return Err(layout("degamma", "expected None (degamma has no parameters)"));
                }
            }
            "ccm" => ccm = Some(state_tensor(&mut zip, &prefix, big_endian, v, "ccm", "ccm")?),
            "gamma" => keypoints = Some(state_tensor(&mut zip, &prefix, big_endian, v, "gamma", "keypoints")?),
            other => return Err(layout(other, "unknown stage (CamPro pipelines have degamma, ccm, gamma)")),
        }
        order.push(name);
    }
    // The pickle reader does not keep SETITEMS order, so the stage order cannot be
    // checked; CamPro's pipelines always run degamma, ccm, gamma, as this crate does.
    order.sort_by_key(|s| ["degamma", "ccm", "gamma"].iter().position(|c| c == s));
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

/// Runs the pickle opcodes into an object tree, bounding work and memo copies.
fn unpickle(pkl: &[u8]) -> Result<Object, CheckpointError> {
    let mut cur = Cursor::new(pkl);
    let mut stack = Stack::empty();
    let mut copied = 0usize;
    for _ in 0..MAX_OPS {
        let pos = cur.position() as usize;
        let op = *pkl.get(pos).ok_or_else(|| CheckpointError::Pickle("stream ends before STOP".into()))?;
        let done = stack.read(&mut cur).map_err(|e| CheckpointError::Pickle(e.to_string()))?;
        if done {
            return stack.finalize().map_err(|e| CheckpointError::Pickle(e.to_string()));
        }
        // BINGET / LONG_BINGET copy a memo entry: count what they copy.
        if op == b'h' || op == b'j' {
            if let Some(top) = stack.stack().last() {
                copied += count_nodes(top, MAX_COPIED_NODES + 1);
                if copied > MAX_COPIED_NODES {
                    return Err(CheckpointError::Pickle("memo references copy too much data".into()));
                }
            }
        }
    }
    Err(CheckpointError::Pickle(format!("more than {MAX_OPS} opcodes")))
}

fn count_nodes(o: &Object, cap: usize) -> usize {
    let mut n = 1;
    let mut todo = vec![o];
    while let Some(o) = todo.pop() {
        if n > cap {
            break;
        }
        match o {
            Object::Tuple(v) | Object::List(v) => {
                n += v.len();
                todo.extend(v.iter());
            }
            Object::Dict(kv) => {
                n += 2 * kv.len();
                for (k, v) in kv {
                    todo.push(k);
                    todo.push(v);
                }
            }
            Object::Reduce { callable, args } | Object::Build { callable, args } => {
                n += 2;
                todo.push(callable);
                todo.push(args);
            }
            Object::PersistentLoad(b) => {
                n += 1;
                todo.push(b);
            }
            _ => {}
        }
    }
    n
}

fn check_globals(o: &Object) -> Result<(), CheckpointError> {
    let mut todo = vec![o];
    while let Some(o) = todo.pop() {
        match o {
            Object::Class { module_name, class_name }
                if !ALLOWED_GLOBALS.iter().any(|(m, c)| m == module_name && c == class_name) =>
            {
                return Err(CheckpointError::ForbiddenGlobal { module: module_name.clone(), name: class_name.clone() });
            }
            Object::Tuple(v) | Object::List(v) => todo.extend(v.iter()),
            Object::Dict(kv) => {
                for (k, v) in kv {
                    todo.push(k);
                    todo.push(v);
                }
            }
            Object::Reduce { callable, args } | Object::Build { callable, args } => {
                todo.push(callable);
                todo.push(args);
            }
            Object::PersistentLoad(b) => todo.push(b),
            _ => {}
        }
    }
    Ok(())
}

fn kind(o: &Object) -> &'static str {
    match o {
        Object::Class { .. } => "a global",
        Object::Int(_) | Object::Long(_) => "an integer",
        Object::Float(_) => "a float",
        Object::Unicode(_) => "a string",
        Object::Bool(_) => "a bool",
        Object::None => "None",
        Object::Tuple(_) => "a tuple",
        Object::List(_) => "a list",
        Object::Mark => "a mark",
        Object::Dict(_) => "a dict",
        Object::Reduce { .. } => "a reduce call",
        Object::Build { .. } => "a build call",
        Object::PersistentLoad(_) => "a persistent reference",
    }
}

/// The tensor `key` of the state dict of `stage`.
fn state_tensor(
    zip: &mut zip::ZipArchive<Cursor<&[u8]>>,
    prefix: &str,
    big_endian: bool,
    state: Object,
    stage: &str,
    key: &str,
) -> Result<Tensor, CheckpointError> {
    let at = format!("{stage}.{key}");
    let kv = match state {
        Object::Dict(kv) => kv,
        other => return Err(layout(stage, format!("expected a state_dict, found {}", kind(&other)))),
    };
    let value = kv
        .into_iter()
        .find(|(k, _)| matches!(k, Object::Unicode(s) if s == key))
        .map(|(_, v)| v)
        .ok_or_else(|| layout(stage, format!("state_dict has no '{key}'")))?;
    // Unwrap nn.Parameter if present.
    let value = match value {
        Object::Reduce { callable, args } if is_class(&callable, "torch._utils", "_rebuild_parameter") => match *args {
            Object::Tuple(mut a) if !a.is_empty() => a.remove(0),
            _ => return Err(layout(&at, "malformed _rebuild_parameter arguments")),
        },
        v => v,
    };
    let args = match value {
        Object::Reduce { callable, args } if is_class(&callable, "torch._utils", "_rebuild_tensor_v2") => match *args {
            Object::Tuple(a) => a,
            _ => return Err(layout(&at, "malformed _rebuild_tensor_v2 arguments")),
        },
        other => return Err(layout(&at, format!("expected a tensor, found {}", kind(&other)))),
    };
    if args.len() < 4 {
        return Err(layout(&at, "tensor rebuild needs storage, offset, shape and stride"));
    }
    let storage = match &args[0] {
        Object::PersistentLoad(b) => match b.as_ref() {
            Object::Tuple(t) => t.clone(),
            _ => return Err(layout(&at, "malformed storage reference")),
        },
        _ => return Err(layout(&at, "expected a storage reference")),
    };
    // ('storage', torch.FloatStorage, key, device, numel)
    if storage.len() != 5 || storage[0] != Object::Unicode("storage".into()) {
        return Err(layout(&at, "storage reference is not ('storage', type, key, device, numel)"));
    }
    let (dtype, width) = match &storage[1] {
        Object::Class { class_name, .. } if class_name == "FloatStorage" => ("float32", 4usize),
        Object::Class { class_name, .. } if class_name == "DoubleStorage" => ("float64", 8),
        _ => return Err(layout(&at, "storage type must be FloatStorage or DoubleStorage")),
    };
    let (skey, device) = match (&storage[2], &storage[3]) {
        (Object::Unicode(k), Object::Unicode(d)) => (k.clone(), d.clone()),
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

fn is_class(o: &Object, module: &str, name: &str) -> bool {
    matches!(o, Object::Class { module_name, class_name } if module_name == module && class_name == name)
}

fn int(o: &Object) -> Option<usize> {
    match o {
        Object::Int(v) if *v >= 0 => Some(*v as usize),
        Object::Long(v) if *v >= 0 && *v < (1 << 40) => Some(*v as usize),
        _ => None,
    }
}

fn ints(o: &Object) -> Option<Vec<usize>> {
    match o {
        Object::Tuple(v) => v.iter().map(int).collect(),
        _ => None,
    }
}
