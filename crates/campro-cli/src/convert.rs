//! `campro convert` and `campro compare`: a parameter set on a camera stack (Camera2's
//! rationals and curve points, or a stack's own file), and what the device then does,
//! measured against the desktop pipeline.

use crate::args::{CompareArgs, ConvertArgs, DeviceArgs, FileTargetArgs, Format, Report};
use crate::{load_params, not_an_input, say, say_bytes, write_atomic};
use anyhow::{anyhow, bail, Result};
use campro::ccm::{self, Mat3};
use campro::compare;
use campro::emulate::DeviceModel;
use campro::targets::camera2::{self, Camera2, Options, RationalMode};
use campro::targets::Support;
use campro::Params;
use campro_eval::table::{Cell, Column, Table};
use std::path::{Path, PathBuf};

/// Measured conversion error above which `convert` warns, 8-bit LSB.
const CONVERT_WARN_LSB: f64 = 2.0;

/// `campro convert`.
pub fn convert(a: ConvertArgs) -> Result<()> {
    if a.target != "camera2" {
        return convert_file(a);
    }
    let ConvertArgs { params, device, format, output, force, .. } = a;
    if let Some(o) = &output {
        not_an_input("--output", o, &[&params])?;
        not_an_input("--output", o, &device.paths())?;
    }
    let p = load_params(&params)?;
    let (m, opts) = device_setup(&p, &device)?;
    let v = camera2::convert(&p, &m, &opts).map_err(|e| flagged(e, &device))?;
    let r = &v.report;
    if r.curve_simplified && r.curve_max_abs * 255.0 > 0.5 {
        eprintln!(
            "warning: the curve lost knots to fit {} points: it errs up to {:.2} LSB (8-bit); a device with more TONEMAP_MAX_CURVE_POINTS (--max-curve-points) errs less",
            opts.max_curve_points,
            r.curve_max_abs * 255.0
        );
    }
    let gains = device_gains(&device)?;
    let text = match format {
        Format::Json => serde_json::to_string(&camera2_json(&v, gains))? + "\n",
        Format::Kotlin => v.to_kotlin(gains),
    };
    write_or_print(output.as_deref(), text.as_bytes(), force)?;
    note_assumed_identity(&device);
    Ok(())
}

/// The Camera2 values as `convert --format json` prints them: with the device's
/// white-balance gains (`colorCorrectionGains`, null when none are known).
pub(crate) fn camera2_json(v: &camera2::Camera2Values, gains: Option<[f32; 4]>) -> serde_json::Value {
    let mut j = v.to_json();
    j["colorCorrectionGains"] = gains.map_or(serde_json::Value::Null, |g| serde_json::json!(g));
    j
}

/// `campro convert --target` of a file-based stack: the stack's file, checked on its
/// emulation before it is written.
fn convert_file(a: ConvertArgs) -> Result<()> {
    let ConvertArgs { params, target, files, output, force, format, .. } = a;
    if matches!(format, Format::Kotlin) {
        bail!(
            "--format kotlin: only --target camera2 has a Kotlin form; --target {target} writes the stack's own file"
        );
    }
    if output.is_none() && target == "hald" {
        bail!("a Hald image is binary: pass --output FILE.ppm");
    }
    if let Some(o) = &output {
        not_an_input("--output", o, &[&params])?;
        not_an_input("--output", o, &files.paths())?;
    }
    let p = load_params(&params)?;
    let t = files.target(&target, Camera2::default())?;
    let (bytes, base) = files.export(t.as_ref(), &p)?;
    // What the stack will do with it, measured as compare does (fewer random pixels):
    // a conversion that errs visibly never passes in silence.
    let conditions = t.emulate(&p, &bytes, base.as_deref())?;
    let rows = compare::comparison(&p, &conditions, 20_000, 1)?;
    let worst = rows.iter().map(|r| r.stats.max_lsb()).fold(0.0, f64::max);
    eprintln!(
        "measured against the desktop pipeline: up to {worst:.2} LSB (8-bit) over {} conditions; campro compare --target {target} shows each",
        conditions.len()
    );
    if worst > CONVERT_WARN_LSB {
        eprintln!(
            "warning: --target {target} errs by up to {worst:.1} LSB: the deployed camera differs visibly from the preset (more LUT points, or another target, err less)"
        );
    }
    write_or_print(output.as_deref(), &bytes, force)
}

/// Writes `bytes` to `output`, or to standard output without one.
fn write_or_print(output: Option<&Path>, bytes: &[u8], force: bool) -> Result<()> {
    match output {
        Some(o) => write_atomic(o, bytes, force),
        None => {
            say_bytes(bytes);
            Ok(())
        }
    }
}

/// `campro compare`.
pub fn compare(a: CompareArgs) -> Result<()> {
    let CompareArgs { params, target, files, device, matrix_frac_bits, lut_size, random, seed, format } = a;
    let p = load_params(&params)?;
    let (m, options) = device_setup(&p, &device)?;
    let model = DeviceModel { matrix_frac_bits, lut_size: lut_size.map(|n| n as usize) };
    let t = files.target(&target, Camera2::new(m, options, model))?;
    let (exported, base) = files.export(t.as_ref(), &p)?;
    let conditions = t.emulate(&p, &exported, base.as_deref())?;
    let rows = compare::comparison(&p, &conditions, random as usize, seed)?;
    let table = comparison_table(&rows);
    let (holds, verdict) = verdict(&rows);
    match format {
        Report::Text => {
            say!("target {} ({} bytes exported)", t.name(), exported.len());
            say_bytes(table.text().as_bytes());
            say!("verdict: {verdict}");
        }
        Report::Json => {
            let mut json = serde_json::json!({
                "target": t.name(), "exportedBytes": exported.len(), "comparison": table.json(),
                "holds": holds, "verdict": verdict,
            });
            if target == "camera2" {
                json["camera2"] = serde_json::from_slice(&exported)?;
            }
            say!("{}", serde_json::to_string_pretty(&json)?)
        }
    }
    if target == "camera2" {
        note_assumed_identity(&device);
    }
    Ok(())
}

/// What a comparison says in one sentence, and whether the stack holds the preset: every
/// condition within its stated bound (where one is stated) and the worst error under half
/// an 8-bit code (below that, no output code can differ by more than rounding).
pub fn verdict(rows: &[compare::Row]) -> (bool, String) {
    let worst = rows.iter().map(|r| r.stats.max_lsb()).fold(0.0, f64::max);
    let over: Vec<&compare::Row> =
        rows.iter().filter(|r| r.bound.is_some_and(|b| r.stats.max_lsb() > b * 255.0 * (1.0 + 1e-9) + 1e-9)).collect();
    let bound = if over.is_empty() {
        "every condition within its stated bound".to_string()
    } else {
        format!(
            "OVER the stated bound on {} of {} conditions ({}, {}: {:.4} LSB against {:.4})",
            over.len(),
            rows.len(),
            over[0].condition,
            over[0].pixels,
            over[0].stats.max_lsb(),
            over[0].bound.unwrap_or_default() * 255.0
        )
    };
    let holds = over.is_empty() && worst <= 0.5;
    let reach = if worst <= 0.5 {
        format!("this stack holds the preset (at most {worst:.4} LSB, under half an 8-bit code)")
    } else if worst <= CONVERT_WARN_LSB {
        format!("this stack comes close to the preset (up to {worst:.2} LSB: some output codes differ)")
    } else {
        format!("this stack cannot hold the preset (up to {worst:.1} LSB: a visibly different camera)")
    };
    (holds, format!("{bound}; {reach}"))
}

/// A comparison's rows as a table: errors in 8-bit LSB, PSNR in dB, the stated bound.
pub fn comparison_table(rows: &[compare::Row]) -> Table {
    let mut t = Table::new([
        Column::new("condition", "condition", 0),
        Column::new("pixels", "pixels", 0),
        Column::new("count", "count", 0),
        Column::new("max LSB", "maxLsb", 4),
        Column::new("mean LSB", "meanLsb", 5),
        Column::new("PSNR dB", "psnrDb", 2),
        Column::new("bound LSB", "boundLsb", 4),
    ]);
    for r in rows {
        let s = &r.stats;
        t.push(vec![
            r.condition.as_str().into(),
            r.pixels.as_str().into(),
            (s.count / 3).into(),
            s.max_lsb().into(),
            s.mean_lsb().into(),
            s.psnr().into(),
            Cell::opt(r.bound.map(|b| b * 255.0)),
        ]);
    }
    t
}

impl DeviceArgs {
    /// The option the device transform came from, as the user typed it.
    fn flag(&self) -> String {
        match &self.capture_result {
            Some(f) => format!("--capture-result {}", crate::shown(f)),
            None if self.ct.is_some() => "--ct".into(),
            None => "--device-ccm".into(),
        }
    }

    /// The files these options read.
    fn paths(&self) -> Vec<&Path> {
        self.capture_result.iter().map(PathBuf::as_path).collect()
    }
}

impl FileTargetArgs {
    /// The files these options read.
    fn paths(&self) -> Vec<&Path> {
        self.base.iter().map(PathBuf::as_path).collect()
    }

    /// The core target called `name` with these options (and `camera2`'s device
    /// settings), refusing the stacks that cannot hold a curve.
    fn target(&self, name: &str, camera2: Camera2) -> Result<Box<dyn campro::targets::Target>> {
        let entry = campro::targets::entry(name).ok_or_else(|| anyhow!("--target: unknown target {name}"))?;
        match (entry.name, entry.support) {
            (_, Support::Refused(_)) => bail!("{}", campro::targets::refusal(name).unwrap_or_default()),
            ("camera2", _) => Ok(Box::new(camera2)),
            ("cube", _) => {
                if !(2..=256).contains(&self.cube_size) {
                    bail!("--cube-size must be in 2..=256, got {}", self.cube_size);
                }
                Ok(Box::new(campro::targets::cube::CubeFile {
                    kind: campro::targets::cube::Kind::Cube,
                    size: self.cube_size,
                }))
            }
            ("hald", _) => {
                if !(2..=16).contains(&self.hald_level) {
                    bail!("--hald-level must be in 2..=16, got {}", self.hald_level);
                }
                Ok(Box::new(campro::targets::cube::CubeFile::hald(self.hald_level)))
            }
            (_, Support::Deploy(make)) => Ok(make()),
        }
    }

    /// The file `t` exports for `p` (the base read here); values out of the stack's range
    /// are refused, or clamped with `--clamp` and listed on stderr.
    fn export(&self, t: &dyn campro::targets::Target, p: &Params) -> Result<(Vec<u8>, Option<String>)> {
        let base = self.base_text()?;
        let bytes = if self.clamp {
            let (bytes, clamped) = t.export_clamped(p, base.as_deref())?;
            for c in &clamped {
                eprintln!("warning: {c} (compare measures what that costs)");
            }
            bytes
        } else {
            t.export(p, base.as_deref())?
        };
        Ok((bytes, base))
    }

    /// The base file's text (a regular file of at most 16 MiB), if given.
    fn base_text(&self) -> Result<Option<String>> {
        let Some(f) = &self.base else { return Ok(None) };
        Ok(Some(campro::file::read_text_capped(f, 16 << 20, "a tuning file (--base)")?))
    }
}

/// The device's white-balance gains: `--device-gains`, or a capture result's.
fn device_gains(d: &DeviceArgs) -> Result<Option<[f32; 4]>> {
    if let Some(g) = &d.device_gains {
        return Ok(Some([g[0], g[1], g[2], g[3]]));
    }
    let Some(f) = &d.capture_result else { return Ok(None) };
    let text = read_capture_result(f)?;
    camera2::gains_from_capture_result(&text).map_err(|e| anyhow!("--capture-result {}: {e}", crate::shown(f)))
}

/// The text of `--capture-result` (at most 1 MiB); one line naming the flag, and for a
/// missing file where one comes from, when it cannot be read.
fn read_capture_result(f: &Path) -> Result<String> {
    campro::file::read_text_capped(f, 1 << 20, "a capture result").map_err(|e| {
        let missing = !f.exists();
        anyhow!(
            "--capture-result {e}{}",
            if missing { " (a phone's capture result is saved as docs/commands.md shows)" } else { "" }
        )
    })
}

/// What `convert` and `compare` say (on stderr, after their output) when no device
/// transform is given: the values are for a camera whose own colour transform is the
/// identity, which no phone is.
fn note_assumed_identity(d: &DeviceArgs) {
    if d.device_ccm.is_none() && d.capture_result.is_none() && d.ct.is_none() {
        eprintln!("{NO_DEVICE_TRANSFORM}");
    }
}

/// The words of [`note_assumed_identity`].
const NO_DEVICE_TRANSFORM: &str = "note: no device transform given, so the identity was assumed (a camera whose own colour transform does nothing; no phone is one). For a phone, give the COLOR_CORRECTION_TRANSFORM of one of its auto-mode results: --device-ccm A11 .. A33, or --capture-result result.json (docs/commands.md says how to save one); --ct K uses the file's own calibration.";

/// The device matrix and conversion options from the command line.
pub fn device_setup(p: &Params, d: &DeviceArgs) -> Result<(Mat3, Options)> {
    let m = if let Some(v) = &d.device_ccm {
        [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]
    } else if let Some(f) = &d.capture_result {
        let text = read_capture_result(f)?;
        camera2::device_transform_from_capture_result(&text)
            .map_err(|e| anyhow!("--capture-result {}: {e}", crate::shown(f)))?
    } else if let Some(ct) = d.ct {
        if p.ct_calibration.is_empty() {
            bail!("--ct needs a parameter file with ct_calibration");
        }
        campro::color_temp::interpolate(&p.ct_calibration, ct)?
    } else {
        ccm::IDENTITY
    };
    // A device transform with no inverse maps colours onto a plane: nothing sensible can be
    // deployed on it, and compare refuses it too.
    // (Non-finite entries are named entry by entry by the conversion itself.)
    let finite = m.iter().flatten().all(|v| v.is_finite());
    if (d.device_ccm.is_some() || d.capture_result.is_some()) && finite && ccm::inverse(&m).is_none() {
        bail!("{}: the device transform is singular (determinant {:e}): no camera applies it", d.flag(), ccm::det(&m));
    }
    let rational = match d.fixed_denominator {
        Some(den) => RationalMode::Fixed { denominator: den },
        None => RationalMode::Best { max_denominator: d.max_denominator },
    };
    Ok((m, Options { max_curve_points: d.max_curve_points as usize, rational }))
}

/// A conversion error with the option the user typed in place of the library's field
/// name (`--device-ccm[1][2]: ...` rather than `device_ccm[1][2]: ...`; the transform is
/// named by where it came from: `--capture-result FILE` or `--ct`).
fn flagged(e: camera2::ConvertError, device: &DeviceArgs) -> anyhow::Error {
    let text = e.to_string();
    let transform = device.flag();
    for (field, flag) in [
        ("device_ccm", transform.as_str()),
        ("max_curve_points", "--max-curve-points"),
        ("max_denominator", "--max-denominator"),
        ("denominator", "--fixed-denominator"),
    ] {
        if let Some(rest) = text.strip_prefix(field) {
            return anyhow!("{flag}{rest}");
        }
    }
    anyhow!(text)
}
