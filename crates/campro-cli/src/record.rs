//! The record beside a protected file (`simulate --record`: `NAME.EXT.campro.json`): which
//! preset (name and SHA-256), which campro, which path and its stated error bound, and the
//! SHA-256 of the input and the output; and its verification (`campro check --record`).

use anyhow::{anyhow, Context, Result};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

pub use campro::record::{FileRecord, PresetRecord, Record, MAX_RECORD_BYTES};

/// A digest as lowercase hex.
fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// The hex SHA-256 of `bytes`.
pub fn sha256(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// The hex SHA-256 of a regular file and its size, streamed (no size limit: only hashed).
pub fn sha256_file(path: &Path) -> Result<(String, u64)> {
    let mut f = campro::file::open_regular(path).with_context(|| crate::shown(path))?;
    let mut h = Sha256::new();
    let n = std::io::copy(&mut f, &mut h).with_context(|| crate::shown(path))?;
    Ok((hex(&h.finalize()), n))
}

/// The bytes a PARAMS argument names: a bundled preset's JSON, or the file's.
pub fn preset_bytes(given: &Path) -> Result<Vec<u8>> {
    if let Some(p) = crate::presets::named(given) {
        return Ok(p.json.as_bytes().to_vec());
    }
    Ok(campro::file::read_capped(given, campro::params::MAX_JSON_BYTES as u64, "a parameter file")?)
}

/// The bytes of the enhancer the preset `given` names (a bundled preset's built-in one, or
/// the file its provenance names beside it), for its hash.
pub fn enhancer_bytes(given: &Path, p: &campro::Params) -> Result<Vec<u8>> {
    if let Some(preset) = crate::presets::named(given) {
        return preset
            .enhancer
            .map(<[u8]>::to_vec)
            .ok_or_else(|| anyhow!("{}: this bundled preset has no enhancer", preset.name));
    }
    let named = p.provenance_fields().map_err(|e| anyhow!("{}: {e}", crate::shown(given)))?.enhancer;
    let file = named.ok_or_else(|| anyhow!("{}: provenance.enhancer.onnx: missing", crate::shown(given)))?.onnx;
    let path = crate::capture::beside(given, "provenance.enhancer.onnx", &file)?;
    Ok(campro::file::read_capped(&path, 1 << 30, "an enhancer")?)
}

/// The record of the file at `p`: its name, SHA-256 and size.
pub fn file_record(p: &Path) -> Result<FileRecord> {
    let (sha256, bytes) = sha256_file(p)?;
    Ok(FileRecord { name: file_name(p), sha256, bytes })
}

/// The record of a file's `bytes`, read already, named by `p`'s file name.
pub fn bytes_record(p: &Path, bytes: &[u8]) -> FileRecord {
    FileRecord { name: file_name(p), sha256: sha256(bytes), bytes: bytes.len() as u64 }
}

fn file_name(p: &Path) -> String {
    p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}

/// Where the record of `output` lies: `output` with `.campro.json` appended to its name.
pub fn path_of(output: &Path) -> PathBuf {
    let mut name = output.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".campro.json");
    output.with_file_name(name)
}

/// What every record of one run shares.
#[derive(Debug, Clone)]
pub struct RunRecord {
    pub preset: PresetRecord,
    pub enhancer_sha256: Option<String>,
    pub bit_depth: u8,
    pub metadata: String,
}

impl RunRecord {
    /// The run's part of the records: the set `p` as `given` names it and its file's
    /// SHA-256, the enhancer's SHA-256 when the run enhances, the bit depth written (8
    /// whenever it enhances: the enhancer takes the camera's 8 bits) and the metadata policy.
    pub fn new(
        given: String,
        p: &campro::Params,
        preset_sha256: String,
        enhancer_sha256: Option<String>,
        depth: campro::pipeline::Depth,
        metadata: crate::metadata::Policy,
    ) -> Result<Self> {
        let bit_depth = if enhancer_sha256.is_some() || depth == campro::pipeline::Depth::Eight { 8 } else { 16 };
        Ok(Self {
            preset: PresetRecord {
                name: p.name.clone(),
                given,
                sha256: preset_sha256,
                best_round: p.provenance_fields().ok().and_then(|f| f.best_round),
            },
            enhancer_sha256,
            bit_depth,
            metadata: serde_json::to_value(metadata)?.as_str().unwrap_or_default().to_string(),
        })
    }

    /// Writes the record of `output` (made from `input`) beside it.
    pub fn write(&self, input: &Path, output: &Path, jpeg_quality: Option<u8>, force: bool) -> Result<()> {
        self.write_for(file_record(input)?, output, jpeg_quality, force)
    }

    /// [`RunRecord::write`] with the input already described.
    pub fn write_for(&self, input: FileRecord, output: &Path, jpeg_quality: Option<u8>, force: bool) -> Result<()> {
        let r = Record {
            campro_record: campro::record::RECORD_VERSION,
            campro_version: env!("CARGO_PKG_VERSION").to_string(),
            preset: self.preset.clone(),
            path: if self.enhancer_sha256.is_some() {
                campro::record::PATH_CAMERA_ENHANCER
            } else {
                campro::record::PATH_CAMERA
            }
            .to_string(),
            bit_depth: self.bit_depth,
            bound_lsb: 0.5,
            enhancer_sha256: self.enhancer_sha256.clone(),
            jpeg_quality,
            metadata: self.metadata.clone(),
            input: Some(input),
            output: file_record(output)?,
            device: None,
        };
        crate::write_atomic(&path_of(output), r.to_json().as_bytes(), force)
    }
}

/// Reads a record (a regular file of at most 64 KB, every field checked).
pub fn read(path: &Path) -> Result<Record> {
    let text = campro::file::read_text_capped(path, MAX_RECORD_BYTES, "a campro record")?;
    Record::from_json(&text).map_err(|e| anyhow!("{}: {e}", crate::shown(path)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_abc_is_the_fips_vector() {
        assert_eq!(sha256(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }

    #[test]
    fn the_record_lies_beside_its_output() {
        assert_eq!(path_of(Path::new("out/IMG_1.jpg")), Path::new("out/IMG_1.jpg.campro.json"));
    }
}
