//! The models the commands run: the bundled manifests (files resolved against `--models`)
//! and loading one by name or manifest path. Shared by eval, inspect and the enhancer's
//! face guard.

use anyhow::{bail, Result};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use std::path::Path;

/// The bundled YOLOX-Nano manifest (also the template of a fine-tuned detector's).
pub const YOLOX_MANIFEST: &str = include_str!("../../../crates/campro-eval/models/yolox_nano.json");

/// The model name of YOLOX-Nano fine-tuned behind the parameter set `set`'s camera (what
/// `finetune-detector` writes in its manifest and a built-in detector is loaded as).
pub(crate) fn fine_tuned_name(set: &str) -> String {
    format!("yolox-nano fine-tuned ({set})")
}

/// The shipped manifests (files resolved against `--models`).
pub(crate) const BUNDLED: [(&str, &str); 4] = [
    ("yunet", include_str!("../../../crates/campro-eval/models/yunet.json")),
    ("yolox-nano", YOLOX_MANIFEST),
    ("faceplugin", include_str!("../../../crates/campro-eval/models/faceplugin.json")),
    ("mobilefacenet-casia", include_str!("../../../crates/campro-eval/models/mobilefacenet_casia.json")),
];

/// The manifest of a bundled model's name, or of a manifest file's path (its model file
/// resolved against `models`).
pub(crate) fn manifest(name_or_path: &str, models: &Path) -> Result<Manifest> {
    if let Some((n, text)) = BUNDLED.iter().find(|(n, _)| *n == name_or_path) {
        return Ok(Manifest::parse(text, Path::new(&format!("bundled manifest {n}")), models)?);
    }
    let p = Path::new(name_or_path);
    if !p.is_file() {
        bail!("{name_or_path:?} is neither a bundled model ({}) nor a manifest file", BUNDLED.map(|b| b.0).join(", "));
    }
    Ok(Manifest::load(p, models)?)
}

/// [`manifest`]'s model, loaded (and said on stderr).
pub(crate) fn load(name: &str, models: &Path) -> Result<Model> {
    let m = manifest(name, models)?;
    eprintln!("loading {} ({})", m.name, crate::shown(&m.file));
    Ok(Model::load(m)?)
}
