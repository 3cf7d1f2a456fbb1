//! Shared helpers for the host integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared` beside the project (or `$CAMPRO_SHARED`), joined with `rel`, if present.
/// Absent: prints why the test is skipped and returns `None`; under CI (`CI=true`) a
/// missing file fails the test instead.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let root = std::env::var_os("CAMPRO_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared"));
    let p = root.join(rel);
    if p.exists() {
        return Some(p);
    }
    if std::env::var("CI").map(|v| v == "true").unwrap_or(false) {
        panic!("CI=true but the shared file {} is missing", p.display());
    }
    eprintln!("SKIP: {} not found (set CAMPRO_SHARED to the shared/ folder)", p.display());
    None
}

/// Reads an .npy array: (shape, values as f64).
pub fn npy(path: &std::path::Path) -> (Vec<usize>, Vec<f64>) {
    let bytes = std::fs::read(path).unwrap();
    let arr = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape: Vec<usize> = arr.shape().iter().map(|&d| d as usize).collect();
    let data = match arr.dtype() {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Uint => arr.into_vec::<u8>().unwrap().into_iter().map(f64::from).collect(),
        _ => arr.into_vec::<f32>().unwrap().into_iter().map(f64::from).collect(),
    };
    (shape, data)
}
