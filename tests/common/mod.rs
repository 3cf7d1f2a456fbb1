//! Shared helpers for the host integration tests.
#![allow(dead_code)]

mod shared;
#[allow(unused_imports)]
pub use shared::{shared, shared_root, workspace_root};

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
