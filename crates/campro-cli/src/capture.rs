//! What a camera shows: the exact 8-bit pipeline on a frame, then, with `--enhance`, the
//! preset's image enhancer; and the networks a parameter set names beside it (its
//! enhancer, an attacker's restoration network). Shared by `simulate` (images and video),
//! `inspect` and `eval`.

use crate::args::ScaleArg;
use anyhow::{anyhow, bail, Result};
use campro::pipeline::fast::Exact8;
use campro::pipeline::{Depth, Prepared};
use campro::Params;
use rayon::prelude::*;
use std::path::Path;

/// Largest image the enhancer runs on (pixels, 3840 x 2160): its activations take about
/// 200 bytes a pixel at the recommended size.
pub const MAX_ENHANCE_PIXELS: u64 = 3840 * 2160;

/// What `simulate` does to a frame: the camera (exact, on every core), then, with
/// `--enhance`, the preset's enhancer (tract, one thread a frame).
pub(crate) struct Capture<'a, 'p> {
    /// The exact 8-bit path.
    pub fast8: &'a Exact8<'p>,
    /// The reference path tabulated for 8-bit input (also the params).
    pub p8: &'a Prepared<'p>,
    /// The same for 16-bit input: its 65,536-entry degamma table is built on first use.
    pub p16: &'a std::sync::OnceLock<Prepared<'p>>,
    pub enhancer: Option<&'a campro_eval::enhance::Enhancer>,
}

impl<'p> Capture<'_, 'p> {
    /// The reference path for 16-bit input.
    pub fn prepared16(&self) -> &Prepared<'p> {
        self.p16.get_or_init(|| Prepared::new(self.p8.params(), Depth::Sixteen))
    }

    /// `dst` = the 16-bit capture of the `w`-pixel-wide 16-bit RGB frame `src` (the exact
    /// reference path on every core; no enhancer: it takes 8 bits).
    pub fn run16(&self, src: &[u16], dst: &mut [u16], w: u32) {
        let prep = self.prepared16();
        let row = 3 * w as usize;
        src.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| prep.run(s, d, Depth::Sixteen));
    }

    /// `dst` = the capture of the `w` x `h` RGB frame `src`.
    pub fn run(&self, src: &[u8], dst: &mut [u8], w: u32, h: u32) -> Result<()> {
        let row = 3 * w as usize;
        src.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| {
            self.fast8.run(s, d);
        });
        if let Some(e) = self.enhancer {
            let captured = image::RgbImage::from_raw(w, h, dst.to_vec()).expect("a whole frame");
            dst.copy_from_slice(enhance(e, &captured)?.as_raw());
        }
        Ok(())
    }
}

/// The enhancer `e` on a captured image, refused over [`MAX_ENHANCE_PIXELS`].
pub fn enhance(e: &campro_eval::enhance::Enhancer, captured: &image::RgbImage) -> Result<image::RgbImage> {
    let (w, h) = captured.dimensions();
    if w as u64 * h as u64 > MAX_ENHANCE_PIXELS {
        bail!("--enhance: the image is {w} x {h}; the enhancer runs on at most 3840 x 2160 pixels");
    }
    Ok(e.enhance(captured)?)
}

/// What a parameter set's provenance can name beside it: its enhancer (shown to people) or
/// the restoration network trained against it (an attacker's, for `eval privacy --attack
/// restore-net`). Both are written by `campro train-enhancer`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Network {
    Enhancer,
    Restorer,
}

impl Network {
    /// The provenance key, the file suffix (`PARAMS.KEY.onnx`) and the manifest's kind.
    pub fn key(self) -> &'static str {
        match self {
            Network::Enhancer => "enhancer",
            Network::Restorer => "restorer",
        }
    }
}

/// The enhancer a parameter set names (`provenance.enhancer.onnx`, beside the file at
/// `params_path`).
pub fn enhancer_of(params_path: &Path, p: &Params, scale: ScaleArg) -> Result<campro_eval::enhance::Enhancer> {
    Ok(network_of(params_path, p, Network::Enhancer)?.with_scale(scale.enhance_scale))
}

/// The network `which` a parameter set names (`provenance.KEY.onnx`, a file name beside the
/// file at `params_path`).
pub fn network_of(params_path: &Path, p: &Params, which: Network) -> Result<campro_eval::enhance::Enhancer> {
    let key = which.key();
    if let (Some(preset), Network::Enhancer) = (crate::presets::named(params_path), which) {
        let bytes = preset.enhancer.ok_or_else(|| {
            anyhow!("{}: this bundled preset has no enhancer (campro presets says which do)", preset.name)
        })?;
        return Ok(campro_eval::enhance::Enhancer::from_bytes(bytes, params_path)?);
    }
    let file = p.provenance.get(key).and_then(|e| e.get("onnx")).and_then(|f| f.as_str()).ok_or_else(|| {
        anyhow!(
            "{}: provenance.{key}.onnx: missing (this preset has no {key}; train one with campro train-enhancer{})",
            params_path.display(),
            if which == Network::Restorer { " and data.faces = \"restore\"" } else { "" }
        )
    })?;
    Ok(campro_eval::enhance::Enhancer::load(&beside(params_path, &format!("provenance.{key}.onnx"), file)?)?)
}

/// The file a preset's provenance names (`field`): a bare file name beside the preset,
/// never a path taken from the file's contents (no folder, no `..`, no absolute path).
pub(crate) fn beside(params_path: &Path, field: &str, file: &str) -> Result<std::path::PathBuf> {
    let name = Path::new(file);
    if name.components().count() != 1 || !matches!(name.components().next(), Some(std::path::Component::Normal(_))) {
        bail!(
            "{}: {field}: must be a file name beside the preset, got {:?}",
            crate::shown(params_path),
            crate::short(file, 120)
        );
    }
    let dir = params_path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    Ok(dir.join(name))
}
