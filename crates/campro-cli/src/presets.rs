//! The bundled presets, built into the binary: `campro simulate campro-omega-0.5 photos -o out`
//! works from any folder. A name is taken as a preset only when no file of that name
//! exists, so files keep working as before (a copied preset with its enhancer beside it too).

use anyhow::{anyhow, Result};
use std::path::Path;

/// One bundled parameter set, and its image enhancer when it ships one.
pub struct Preset {
    /// The name (`params/NAME.json` in the repository).
    pub name: &'static str,
    /// The parameter file's JSON.
    pub json: &'static str,
    /// `params/NAME.enhancer.onnx`, when present.
    pub enhancer: Option<&'static [u8]>,
    /// `params/NAME.detector.onnx`, the person detector fine-tuned behind its camera
    /// (half-precision weights), when present: `eval utility --own-detector`.
    pub detector: Option<&'static [u8]>,
    /// What to pick it for, in plain words (`campro presets` prints it first).
    pub pick: &'static str,
}

/// Every bundled preset, sorted by name (`params/*.json`; a test checks the list is whole).
pub const PRESETS: &[Preset] = &[
    Preset {
        name: "campro-omega-0.5",
        json: include_str!("../../../params/campro-omega-0.5.json"),
        detector: Some(include_bytes!("../../../params/campro-omega-0.5.detector.onnx")),
        enhancer: Some(include_bytes!("../../../params/campro-omega-0.5.enhancer.onnx")),
        pick: "Pick this for everyday use: faces are hidden and people are still found, with an enhanced view for people to watch.",
    },
    Preset {
        name: "campro-omega-0.5-distill",
        json: include_str!("../../../params/campro-omega-0.5-distill.json"),
        detector: Some(include_bytes!("../../../params/campro-omega-0.5-distill.detector.onnx")),
        enhancer: None,
        pick: "Pick this when finding people matters more than hiding faces: it hides faces less well than campro-omega-0.5.",
    },
    Preset {
        name: "campro-omega-0.5-hour",
        json: include_str!("../../../params/campro-omega-0.5-hour.json"),
        detector: Some(include_bytes!("../../../params/campro-omega-0.5-hour.detector.onnx")),
        enhancer: Some(include_bytes!("../../../params/campro-omega-0.5-hour.enhancer.onnx")),
        pick: "Pick this where hiding faces matters most: the most private camera here, with an enhanced view.",
    },
    Preset { name: "campro-omega-1", json: include_str!("../../../params/campro-omega-1.json"), enhancer: None, detector: Some(include_bytes!("../../../params/campro-omega-1.detector.onnx")), pick: "Detection first: people are found more often, faces are hidden less well. Not for privacy-critical use." },
    Preset {
        name: "campro-omega-1-shared-continued",
        json: include_str!("../../../params/campro-omega-1-shared-continued.json"),
        detector: Some(include_bytes!("../../../params/campro-omega-1-shared-continued.detector.onnx")),
        enhancer: Some(include_bytes!("../../../params/campro-omega-1-shared-continued.enhancer.onnx")),
        pick: "Pick this when people must be found and an attacker may learn to undo the camera: faces are recognised more often as captured than with campro-omega-0.5, less often after any attack; with an enhanced view.",
    },
    Preset { name: "campro-omega-5", json: include_str!("../../../params/campro-omega-5.json"), enhancer: None, detector: Some(include_bytes!("../../../params/campro-omega-5.detector.onnx")), pick: "For experiments only: faces are recognised often in its pictures." },
    Preset { name: "color-inversion", json: include_str!("../../../params/color-inversion.json"), enhancer: None, detector: None, pick: "No protection: an example transform that is easily undone. For comparisons." },
    Preset { name: "identity", json: include_str!("../../../params/identity.json"), enhancer: None, detector: None, pick: "No protection: the unprotected starting point. For comparisons." },
    Preset { name: "srgb-passthrough", json: include_str!("../../../params/srgb-passthrough.json"), enhancer: None, detector: None, pick: "No protection: an ordinary camera's picture. For comparisons." },
];

/// The preset `arg` names, when `arg` is not an existing path but a bundled preset's name
/// (with or without `.json`).
pub fn named(arg: &Path) -> Option<&'static Preset> {
    if arg.exists() || arg.components().count() != 1 {
        return None;
    }
    let s = arg.to_str()?;
    let name = s.strip_suffix(".json").unwrap_or(s);
    PRESETS.iter().find(|p| p.name == name)
}

/// The error for a parameter argument that is neither a file nor a preset.
pub fn not_found(arg: &Path) -> anyhow::Error {
    let names: Vec<&str> = PRESETS.iter().map(|p| p.name).collect();
    match closest(&arg.to_string_lossy()) {
        Some(near) => anyhow!("{}: no such file, and not a bundled preset; did you mean {near}?", crate::shown(arg)),
        None => anyhow!(
            "{}: no such file, and not a bundled preset (campro presets lists them: {})",
            crate::shown(arg),
            names.join(", ")
        ),
    }
}

/// The bundled preset whose name is nearest `typed` (case ignored, a `.json` ending
/// dropped), when it is within a third of its length in edits (at least 2): a slip such as
/// `campro-omega0.5` or `Campro-Omega-05`, not another word.
fn closest(typed: &str) -> Option<&'static str> {
    let t = typed.to_ascii_lowercase();
    let t = t.strip_suffix(".json").unwrap_or(&t);
    PRESETS
        .iter()
        .map(|p| (strsim::levenshtein(t, p.name), p.name))
        .filter(|&(d, n)| d <= (n.len() / 3).max(2))
        .min()
        .map(|(_, n)| n)
}

/// A bundled preset as `campro presets` lists it (`--format json`: these keys in camelCase).
#[derive(Debug, Clone, serde::Serialize)]
#[serde(rename_all = "camelCase")]
pub struct PresetInfo {
    pub name: &'static str,
    /// What to pick it for, in plain words.
    pub pick: &'static str,
    /// It ships an image enhancer.
    pub enhancer: bool,
    /// It is rated for grey input (grey pictures are refused otherwise).
    pub rated_for_grey: bool,
    /// It protects faces ([`campro::Params::protective`]).
    pub protective: bool,
    /// Its measured privacy and utility, one line.
    pub description: String,
}

/// Every bundled preset, sorted by name.
pub fn infos() -> Result<Vec<PresetInfo>> {
    PRESETS
        .iter()
        .map(|p| {
            let params = campro::Params::from_json(p.json)?;
            Ok(PresetInfo {
                name: p.name,
                pick: p.pick,
                enhancer: p.enhancer.is_some(),
                rated_for_grey: params.rated_for_grey(),
                protective: params.protective(),
                description: params.description,
            })
        })
        .collect()
}

/// `campro presets`: each bundled preset's name, whether it ships an enhancer, and its
/// one-line privacy and utility description.
pub fn list(json: bool) -> Result<()> {
    let rows = infos()?;
    if json {
        // Through a Value, so that the keys come sorted as before.
        crate::say!("{}", serde_json::to_string_pretty(&serde_json::to_value(&rows)?)?);
    } else {
        for PresetInfo { name: n, pick, enhancer: e, rated_for_grey: g, protective, description: d } in rows {
            let grey = if g {
                ""
            } else {
                "\n    Not rated for grey input: black-and-white pictures are refused (--allow-grey writes them unprotected)."
            };
            let unprotective = if protective {
                ""
            } else {
                "\n    Not protective: its worst measured face-recognition top-1 is above 15%, or it has no rating (a phone never calls it Protected)."
            };
            crate::say!(
                "{n}{}\n    {pick}\n    Measured: {}{grey}{unprotective}",
                if e { " (with enhancer)" } else { "" },
                crate::escape(&d)
            );
        }
        crate::say!(
            "\n(top-1: how often a face-recognition system names the right person among 100 to 1,239; 1% is chance. AP: how well people are still found, against the unprotected picture.)"
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bundled_file_is_a_preset_and_parses() {
        let dir = campro_testkit::workspace_root().join("params");
        let mut files: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter_map(|n| n.strip_suffix(".json").map(str::to_string))
            .collect();
        files.sort();
        let names: Vec<&str> = PRESETS.iter().map(|p| p.name).collect();
        assert_eq!(names, files);
        for p in PRESETS {
            assert_eq!(p.json, std::fs::read_to_string(dir.join(format!("{}.json", p.name))).unwrap());
            assert_eq!(p.enhancer.is_some(), dir.join(format!("{}.enhancer.onnx", p.name)).exists());
            assert_eq!(p.detector.is_some(), dir.join(format!("{}.detector.onnx", p.name)).exists());
            campro::Params::from_json(p.json).unwrap();
        }
    }
}
