//! Parameter sets as the commands take them (a bundled preset's name or a file), and the
//! commands on parameter files themselves: `validate` and `import-pt`.

use crate::args::{ImportPtArgs, Report, ValidateArgs};
use crate::{escape, not_an_input, presets, say, write_atomic};
use anyhow::{anyhow, Result};
use campro::ccm;
use campro::Params;
use std::path::Path;

/// The parameter set `path` names: a bundled preset's name, or a parameter file.
pub(crate) fn load_params(path: &Path) -> Result<Params> {
    if let Some(preset) = presets::named(path) {
        return Ok(Params::from_json(preset.json)?);
    }
    // A bare name that is no file: most likely a preset's name mistyped (`campro-omega0.5`,
    // `campro-omega-05.json`), so the error offers the nearest.
    if !path.exists() && path.components().count() == 1 {
        return Err(presets::not_found(path));
    }
    if path.is_dir() {
        return Err(anyhow!(
            "{}: is a folder; the parameter set (a preset from campro presets, or a .json file) comes first, e.g. campro simulate PRESET PHOTOS...",
            crate::shown(path)
        ));
    }
    Params::from_file(path).map_err(|e| match e {
        // The file error names the path already.
        campro::params::ParamsError::File(f) => anyhow!("{f}"),
        e => anyhow!("{}: {e}", crate::shown(path)),
    })
}

/// `campro validate`: a line (or a JSON object) per file; fails on the first broken rule.
pub fn validate(a: &ValidateArgs) -> Result<()> {
    for path in &a.params {
        let v = load_params(path)?;
        let (lo, hi) = ccm::min_max(&v.ccm);
        match a.format {
            Report::Json => say!(
                "{}",
                serde_json::json!({
                    "file": path.display().to_string(), "ok": true, "name": v.name, "description": v.description,
                    "knots": v.tone_curves.knots(), "perChannel": v.tone_curves.shared().is_none(),
                    "evenlySpaced": v.tone_curves.is_uniform(), "degamma": v.degamma,
                    "ccmMin": lo, "ccmMax": hi, "ctCalibrations": v.ct_calibration.len(),
                })
            ),
            Report::Text => say!(
                "{}: ok ({}: {} knots{}{}, degamma {}, CCM range [{lo:.3}, {hi:.3}], {} CT calibrations)",
                path.display(),
                if v.name.is_empty() { "unnamed".to_string() } else { escape(&v.name) },
                v.tone_curves.knots(),
                if v.tone_curves.is_uniform() { " evenly spaced" } else { "" },
                if v.tone_curves.shared().is_none() { ", a curve per channel" } else { "" },
                v.degamma,
                v.ct_calibration.len()
            ),
        }
    }
    Ok(())
}

/// `campro import-pt`: a CamPro checkpoint as a parameter file.
pub fn import_pt(a: &ImportPtArgs) -> Result<()> {
    not_an_input("--output", &a.output, &[&a.checkpoint])?;
    let p = campro::import_pt::read_checkpoint(&a.checkpoint)
        .map_err(|e| anyhow!("{}: {e}", crate::shown(&a.checkpoint)))?;
    write_atomic(&a.output, p.to_json().as_bytes(), a.force)?;
    eprintln!("wrote {} ({} knots)", crate::shown(&a.output), p.tone_curves.knots());
    Ok(())
}
