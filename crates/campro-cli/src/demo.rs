//! `campro demo`: the recommended preset (or --params) on the built-in chart: the chart
//! before and after, the Camera2 values, and the simulated device against the desktop
//! pipeline.

use crate::args::{DemoArgs, Report};
use crate::convert::comparison_table;
use crate::{check_output_folder, escape, load_params, say, say_bytes, simulate, write_atomic};
use anyhow::Result;
use campro::ccm;
use campro::pipeline::{Depth, Prepared};
use campro::targets::camera2::{self, Camera2, Options};
use campro::Params;

/// The recommended preset: `campro demo`'s default. Of the learnt sets it is the most
/// useful one that meets both privacy targets on the paper's protocol (trained/README.md).
const DEFAULT_PARAMS: &str = include_str!("../../../params/campro-omega-0.5.json");
/// The file name [`DEFAULT_PARAMS`] is bundled as, for messages.
const DEFAULT_PARAMS_NAME: &str = "campro-omega-0.5";

pub fn demo(a: &DemoArgs) -> Result<()> {
    let (out, force, format) = (a.output.as_path(), a.force, a.format);
    // A folder holding only an earlier demo's two files is the demo's own: replaced.
    let earlier_demo = std::fs::read_dir(out).is_ok_and(|entries| {
        entries.flatten().all(|e| matches!(e.file_name().to_str(), Some("chart.png" | "chart-protected.png")))
    });
    check_output_folder(out, force || earlier_demo, "--output")?;
    let (p, file) = match &a.params {
        Some(path) => (load_params(path)?, path.display().to_string()),
        None => {
            (Params::from_json(DEFAULT_PARAMS)?, format!("{DEFAULT_PARAMS_NAME} (the recommended preset, built in)"))
        }
    };
    let chart = campro::chart::render();
    let (w, h) = (campro::chart::WIDTH, campro::chart::HEIGHT);
    let src: Vec<u16> = chart.iter().map(|&v| v as u16).collect();
    let mut dst = vec![0u16; src.len()];
    Prepared::new(&p, Depth::Eight).run(&src, &mut dst, Depth::Eight);
    let before = out.join("chart.png");
    // Fixed names: never built from the file's contents.
    let after = out.join("chart-protected.png");
    for (path, png) in [
        (&before, simulate::encode_png(&src, w, h, Depth::Eight)?),
        (&after, simulate::encode_png(&dst, w, h, Depth::Eight)?),
    ] {
        // An earlier demo's identical file is left as it is; any other file of that name
        // (the user's own, or another preset's output) is replaced only with --force.
        let same = campro::file::read_capped(path, png.len() as u64, "an earlier demo output").is_ok_and(|b| b == png);
        if !same {
            write_atomic(path, &png, force)?;
        }
    }
    let v = camera2::convert(&p, &ccm::IDENTITY, &Options::default())?;
    let device = Camera2::default();
    let conditions = campro::targets::Target::emulate(&device, &p, &serde_json::to_vec(&v.to_json())?, None)?;
    let table = comparison_table(&campro::compare::comparison(&p, &conditions, 100_000, 1)?);
    if let Report::Json = format {
        let json = serde_json::json!({
            "preset": file, "name": p.name, "description": p.description,
            "input": before.display().to_string(), "output": after.display().to_string(),
            "camera2": v.to_json(),
            "conversion": {
                "matrix_scale": v.scale, "matrix_max_abs": v.report.matrix_max_abs,
                "curve_max_abs": v.report.curve_max_abs, "bound_lsb": v.report.bound_lsb(),
            },
            "comparison": table.json(),
        });
        say!("{json}");
        return Ok(());
    }
    say!("preset: {file}");
    say!("parameters: {} - {}", escape(&p.name), escape(&p.description));
    say!("wrote {} (input) and {} (desktop pipeline output)\n", crate::shown(&before), crate::shown(&after));
    say!("Camera2 values (device transform: identity; for a phone: `campro convert PRESET --capture-result result.json`, docs/commands.md):");
    say!("  COLOR_CORRECTION_TRANSFORM (num/den pairs): {:?}", v.color_correction_transform);
    let c = &v.tonemap_curve.red;
    let pts: Vec<String> = c.chunks(2).take(4).map(|p| format!("({:.4}, {:.4})", p[0], p[1])).collect();
    say!(
        "  TONEMAP_CURVE: {} points per channel: {}, ... ({:.4}, {:.4})",
        c.len() / 2,
        pts.join(", "),
        c[c.len() - 2],
        c[c.len() - 1]
    );
    say!(
        "  matrix scale {}, rational error {:.2e}, curve error {:.2e}, bound {:.2e} LSB over sensor RGB in [0,1]",
        v.scale,
        v.report.matrix_max_abs,
        v.report.curve_max_abs,
        v.report.bound_lsb()
    );
    say!("\nSimulated device vs desktop pipeline:");
    say_bytes(table.text().as_bytes());
    Ok(())
}
