//! `campro bench`: one table of run time against error for every path and setting,
//! with the copy baseline measured in the same run. Medians over repeated runs.

use crate::args::{BenchArgs, Report};
use campro::bench::test_frame;
use campro::ccm::{self, Mat3};
use campro::color_temp::DngCalibration;
use campro::compare::random_pixels;
use campro::lut3d::{Interp, Lut3d};
use campro::pipeline::fast::{Exact8, F32Path};
use campro::pipeline::{Depth, Prepared};
use campro::targets::camera2::Camera2Loop;
use campro::targets::camera2::{convert, Options, RationalMode};
use campro::Params;
use campro_eval::table::{Cell, Column, Table};
use rayon::prelude::*;
use std::hint::black_box;
use std::time::Instant;

const PHONE: Mat3 = [[1.78, -0.62, -0.16], [-0.28, 1.62, -0.34], [0.02, -0.71, 1.69]];

use campro::bench::median_seconds as median;

/// Median seconds per call of `f`, timed in batches of `batch` calls.
fn per_call(batch: usize, runs: usize, mut f: impl FnMut()) -> f64 {
    median(runs, || {
        for _ in 0..batch {
            f()
        }
    }) / batch as f64
}

/// One row of the table.
pub struct Row {
    group: &'static str,
    name: String,
    time: Time,
    /// Largest and mean error in 8-bit LSB (NaN: not measured).
    max_lsb: f64,
    mean_lsb: f64,
    note: String,
}

/// A median time and what it is per.
#[derive(Clone, Copy)]
enum Time {
    /// Seconds per 1920x1080 frame.
    Frame(f64),
    /// Seconds per Camera2 update.
    Update(f64),
    /// Not timed.
    None,
}

/// A 1920x1080 frame in megapixels.
const FRAME_MPX: f64 = 1920.0 * 1080.0 / 1e6;

impl std::fmt::Display for Time {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match *self {
            Time::Frame(s) => write!(f, "{:.2} ms/frame ({:.2} ms/Mpx)", s * 1e3, s * 1e3 / FRAME_MPX),
            Time::Update(s) => write!(f, "{:.3} us/update", s * 1e6),
            Time::None => f.write_str("-"),
        }
    }
}

fn err8(out: &[u8], want: &[[f64; 3]]) -> (f64, f64) {
    let (mut max, mut sum) = (0f64, 0f64);
    for (o, w) in out.chunks_exact(3).zip(want) {
        for k in 0..3 {
            let e = (o[k] as f64 - w[k] * 255.0).abs();
            max = max.max(e);
            sum += e;
        }
    }
    (max, sum / (3 * want.len()) as f64)
}

/// Runs every row: medians of `quick` (3) or full (11) repetitions, more for the
/// millisecond rows.
pub fn run(params: &Params, quick: bool) -> Vec<Row> {
    let runs = if quick { 3 } else { 11 };
    // The millisecond rows (copy, exact 8-bit) take many more runs: on a shared machine
    // their medians move by tens of percent over a handful.
    let many = if quick { 31 } else { 101 };
    let (w, h) = (1920usize, 1080usize);
    let frame = test_frame(w, h);
    let mut out = vec![0u8; frame.len()];
    let mut rows = Vec::new();
    let ms = Time::Frame;

    // Error sample: the frame plus random pixels, against the unrounded f64 reference.
    let mut sample: Vec<u8> = frame.clone();
    sample.extend(random_pixels(if quick { 100_000 } else { 1_000_000 }, 7).into_iter().flatten());
    let reference = Prepared::new(params, Depth::Eight);
    let want: Vec<[f64; 3]> =
        sample.chunks_exact(3).map(|c| reference.pixel([c[0] as u16, c[1] as u16, c[2] as u16])).collect();
    let mut sample_out = vec![0u8; sample.len()];

    let copy = median(many, || out.copy_from_slice(black_box(&frame)));
    rows.push(Row {
        group: "image",
        name: "copy (baseline)".into(),
        time: ms(copy),
        max_lsb: 0.0,
        mean_lsb: 0.0,
        note: "1.00x".into(),
    });
    let ratio = |s: f64| format!("{:.1}x copy", s / copy);

    let f16: Vec<u16> = frame.iter().map(|&v| v as u16).collect();
    let s16: Vec<u16> = sample.iter().map(|&v| v as u16).collect();
    let mut o16 = vec![0u16; f16.len()];
    let mut so16 = vec![0u16; s16.len()];
    let t = median(runs.min(5), || reference.run(black_box(&f16), &mut o16, Depth::Eight));
    reference.run(&s16, &mut so16, Depth::Eight);
    let e = err8(&so16.iter().map(|&v| v as u8).collect::<Vec<_>>(), &want);
    rows.push(Row {
        group: "image",
        name: "f64 reference, 1 thread".into(),
        time: ms(t),
        max_lsb: e.0,
        mean_lsb: e.1,
        note: ratio(t),
    });

    let exact = Exact8::new(params);
    let t = median(many, || {
        exact.run(black_box(&frame), &mut out);
    });
    let fell = exact.run(&frame, &mut out);
    exact.run(&sample, &mut sample_out);
    let e = err8(&sample_out, &want);
    let px = (w * h) as f64 / 100.0;
    let fb = format!(
        "{}, {:?} engine; {:.2}% px flagged to the reference, {:.3}% px to the reference in the tables",
        ratio(t),
        exact.engine(),
        fell.flagged as f64 / px,
        fell.ambiguous as f64 / px
    );
    rows.push(Row {
        group: "image",
        name: "exact 8-bit, 1 thread (default)".into(),
        time: ms(t),
        max_lsb: e.0,
        mean_lsb: e.1,
        note: fb,
    });
    // A row per engine and frame (the bench frame, and a COCO photo where the shared data
    // has one): time, ns a pixel, against a copy, and the pixels sent to the reference.
    let photo = coco_frame(w, h);
    let frames: Vec<(&str, &[u8])> =
        std::iter::once(("bench frame", frame.as_slice())).chain(photo.as_deref().map(|p| ("COCO photo", p))).collect();
    for engine in campro::pipeline::fast::Engine::ALL {
        let name = format!("exact 8-bit, {} engine, 1 thread", engine.name());
        let Some(x) = Exact8::new(params).with_engine(engine) else {
            rows.push(Row {
                group: "engine",
                name,
                time: Time::None,
                max_lsb: f64::NAN,
                mean_lsb: f64::NAN,
                note: match engine {
                    campro::pipeline::fast::Engine::Avx512 => "not on this CPU or curve (needs AVX-512 F, BW, DQ and VBMI, and a uniform curve of at most 32 knots)",
                    _ => "not on this CPU",
                }
                .into(),
            });
            continue;
        };
        x.run(&sample, &mut sample_out);
        let e = err8(&sample_out, &want);
        for (what, f) in &frames {
            let t = median(runs, || {
                x.run(black_box(f), &mut out);
            });
            let fell = x.run(f, &mut out);
            rows.push(Row {
                group: "engine",
                name: format!("{name}, {what}"),
                time: ms(t),
                max_lsb: e.0,
                mean_lsb: e.1,
                note: format!(
                    "{:.2} ns/px, {}; {:.3}% px to the reference",
                    t * 1e9 / (w * h) as f64,
                    ratio(t),
                    (fell.flagged + fell.ambiguous) as f64 / px
                ),
            });
        }
    }
    let scalar = Exact8::new(params).scalar();
    let t = median(runs, || {
        scalar.run_reusing_repeats(black_box(&frame), &mut out);
    });
    rows.push(Row {
        group: "skip",
        name: "exact 8-bit scalar + reuse repeated pixels, 1 thread".into(),
        time: ms(t),
        max_lsb: e.0,
        mean_lsb: e.1,
        note: ratio(t),
    });
    let f32p = F32Path::new(params, Depth::Eight);
    let t = median(runs, || f32p.run(black_box(&frame), &mut out, Depth::Eight));
    f32p.run(&sample, &mut sample_out, Depth::Eight);
    let e = err8(&sample_out, &want);
    rows.push(Row {
        group: "image",
        name: "f32, 1 thread".into(),
        time: ms(t),
        max_lsb: e.0,
        mean_lsb: e.1,
        note: format!("{}, bound {:.1e} LSB + rounding", ratio(t), f32p.error_bound() * 255.0),
    });

    // Stage elision: the same output with an exactly-identity CCM, elided or not.
    let mut id_ccm = params.clone();
    id_ccm.ccm = ccm::IDENTITY;
    let mut almost = id_ccm.clone();
    almost.ccm[2][2] = 1.0 + 1e-15;
    let (fa, fb2) = (F32Path::new(&id_ccm, Depth::Eight), F32Path::new(&almost, Depth::Eight));
    let ta = median(runs, || fa.run(black_box(&frame), &mut out, Depth::Eight));
    let tb = median(runs, || fb2.run(black_box(&frame), &mut out, Depth::Eight));
    rows.push(Row {
        group: "skip",
        name: "f32, identity CCM elided".into(),
        time: ms(ta),
        max_lsb: f64::NAN,
        mean_lsb: f64::NAN,
        note: format!("vs {} not elided: saves {:.0}%", ms(tb), 100.0 * (1.0 - ta / tb)),
    });

    for n in [17, 33, 65] {
        let lut = Lut3d::bake(params, n);
        for interp in [Interp::Trilinear, Interp::Tetrahedral] {
            let t = median(runs, || lut.run(black_box(&frame), &mut out, interp));
            lut.run(&sample, &mut sample_out, interp);
            let e = err8(&sample_out, &want);
            rows.push(Row {
                group: "image",
                name: format!("3D LUT {n}^3 {interp:?}, 1 thread"),
                time: ms(t),
                max_lsb: e.0,
                mean_lsb: e.1,
                note: ratio(t),
            });
        }
    }

    // Last of the image rows: rayon's workers may spin briefly after it.
    let threads = rayon::current_num_threads();
    let row = 3 * w;
    let t = median(many, || {
        frame.par_chunks(row * 16).zip(out.par_chunks_mut(row * 16)).for_each(|(s, d)| {
            exact.run(s, d);
        })
    });
    rows.push(Row {
        group: "image",
        name: format!("exact 8-bit, {threads} threads (simulate)"),
        time: ms(t),
        max_lsb: e.0,
        mean_lsb: e.1,
        note: ratio(t),
    });

    // Camera2 updates.
    let us = Time::Update;
    let batch = if quick { 200 } else { 2000 };
    let t = per_call(batch, runs, || {
        black_box(convert(black_box(params), black_box(&PHONE), &Options::default()).unwrap());
    });
    let v = convert(params, &PHONE, &Options::default()).unwrap();
    rows.push(Row {
        group: "camera2",
        name: "full conversion (compose, scale, rationals, curve, bound)".into(),
        time: us(t),
        max_lsb: v.report.bound_lsb(),
        mean_lsb: f64::NAN,
        note: "max = stated bound".into(),
    });
    let mut l = Camera2Loop::new(params.clone(), Options::default(), 0.0).unwrap();
    let mut other = PHONE;
    other[0][0] += 0.01;
    let mut k = 0u64;
    let t = per_call(batch, runs, || {
        k += 1;
        black_box(l.update(if k.is_multiple_of(2) { &PHONE } else { &other }).unwrap().recomputed);
    });
    rows.push(Row {
        group: "camera2",
        name: "loop update, scene moved (curve half cached)".into(),
        time: us(t),
        max_lsb: v.report.bound_lsb(),
        mean_lsb: f64::NAN,
        note: String::new(),
    });
    let mut l = Camera2Loop::new(params.clone(), Options::default(), 0.25 / 255.0).unwrap();
    l.update(&PHONE).unwrap();
    let t = per_call(batch * 10, runs, || {
        black_box(l.update(black_box(&PHONE)).unwrap().recomputed);
    });
    rows.push(Row {
        group: "skip",
        name: "loop update, scene unchanged (skipped)".into(),
        time: us(t),
        max_lsb: v.report.bound_lsb(),
        mean_lsb: f64::NAN,
        note: String::new(),
    });

    for d in [16u32, 256, 4096, 1 << 16, 1 << 24] {
        let o = Options { rational: RationalMode::Best { max_denominator: d }, ..Options::default() };
        let t = per_call(batch, runs, || {
            black_box(convert(params, &PHONE, &o).unwrap());
        });
        let v = convert(params, &PHONE, &o).unwrap();
        rows.push(Row {
            group: "camera2",
            name: format!("rationals, denominator <= {d}"),
            time: us(t),
            max_lsb: v.report.bound_lsb(),
            mean_lsb: f64::NAN,
            note: format!("entry error {:.1e}", v.report.matrix_max_abs),
        });
    }
    // Curve budgets on a fine (256-knot) version of the curve.
    let mut fine = params.clone();
    fine.tone_curves = params.tone_curves.map(|c| c.resample_uniform(256));
    for pts in [8usize, 16, 32, 64, 256] {
        let o = Options { max_curve_points: pts, ..Options::default() };
        let t = per_call(batch / 10 + 1, runs, || {
            black_box(convert(&fine, &PHONE, &o).unwrap());
        });
        let v = convert(&fine, &PHONE, &o).unwrap();
        rows.push(Row {
            group: "camera2",
            name: format!("256-knot curve in {pts} points"),
            time: us(t),
            max_lsb: v.report.bound_lsb(),
            mean_lsb: f64::NAN,
            note: format!("curve error {:.3} LSB", v.report.curve_max_abs * 255.0),
        });
    }
    for tol_lsb in [0.1, 0.5, 1.0] {
        // The red channel's (all of a shared curve's).
        let (c, e) = fine.tone_curves.channel(0).simplify_within(tol_lsb / 255.0);
        rows.push(Row {
            group: "skip",
            name: format!("fewest curve points within {tol_lsb} LSB"),
            time: Time::None,
            max_lsb: e * 255.0,
            mean_lsb: f64::NAN,
            note: format!("{} of 256 points", c.len()),
        });
    }
    // Colour temperature drifting 2800 K -> 6500 K over 1000 frames: recomputes saved by
    // the skip rule and the error it allowed.
    let fm1 = [[0.6, 0.3, 0.06], [0.25, 0.7, 0.05], [0.03, 0.1, 0.7]];
    let fm2 = [[0.65, 0.25, 0.07], [0.27, 0.68, 0.05], [0.02, 0.15, 0.65]];
    let cal = DngCalibration { illuminant1: 17, forward_matrix1: fm1, illuminant2: 21, forward_matrix2: fm2 };
    let mut jitter = campro::stress::Rng(11);
    let noise: Vec<f64> = (0..1000).map(|_| jitter.range(-10.0, 10.0)).collect();
    for (scene, ct_at) in [
        ("CT drift 2800->6500 K", Box::new(|f: usize| 2800.0 + 3700.0 * f as f64 / 999.0) as Box<dyn Fn(usize) -> f64>),
        ("CT 5000 K +-10 K estimator jitter", Box::new(|f: usize| 5000.0 + noise[f])),
    ] {
        for tol in [0.0, 0.1, 0.25, 1.0] {
            let mut l = Camera2Loop::new(params.clone(), Options::default(), tol / 255.0).unwrap();
            l.set_dng_calibration(cal.clone()).unwrap();
            let mut worst = 0f64;
            let s = Instant::now();
            for f in 0..1000 {
                worst = worst.max(l.update_ct(ct_at(f)).unwrap().bound);
            }
            let t = s.elapsed().as_secs_f64() / 1000.0;
            rows.push(Row {
                group: "skip",
                name: format!("{scene}, tolerance {tol} LSB"),
                time: us(t),
                max_lsb: worst * 255.0,
                mean_lsb: f64::NAN,
                note: format!("{} of 1000 frames recomputed", l.stats().recomputes),
            });
        }
    }

    rows
}

/// The rows as one table: people read each time with its unit (`2.00 ms/frame (0.96
/// ms/Mpx)`) and small errors in scientific notation; CSV and JSON carry `seconds` per
/// `per` (`frame` of 1920x1080, `update`, or null when untimed) and errors in 8-bit LSB
/// (null when not measured).
pub fn table(rows: &[Row]) -> Table {
    let mut t = Table::new([
        Column::new("group", "group", 0),
        Column::new("path / setting", "name", 0),
        Column::new("median time", "seconds", 0),
        Column::machine("per"),
        Column::new("max err (LSB8)", "max_lsb", 0),
        Column::new("mean err (LSB8)", "mean_lsb", 0),
        Column::new("note", "note", 0),
    ]);
    let lsb = |v: f64| {
        let shown = if v.is_nan() {
            "-".to_string()
        } else if v == 0.0 {
            "0".into()
        } else if v < 0.01 {
            format!("{v:.1e}")
        } else {
            format!("{v:.3}")
        };
        Cell::Shown { value: v, shown }
    };
    for r in rows {
        let (seconds, per) = match r.time {
            Time::Frame(s) => (s, Cell::text("frame")),
            Time::Update(s) => (s, Cell::text("update")),
            Time::None => (f64::NAN, Cell::Missing),
        };
        t.push(vec![
            r.group.into(),
            r.name.clone().into(),
            Cell::Shown { value: seconds, shown: r.time.to_string() },
            per,
            lsb(r.max_lsb),
            lsb(r.mean_lsb),
            r.note.clone().into(),
        ]);
    }
    t
}

/// The table as one JSON object: the frame size and the rows.
pub fn json(rows: &[Row]) -> serde_json::Value {
    serde_json::json!({ "frame": [1920, 1080], "rows": table(rows).json() })
}

/// A 1920x1080 frame tiled from a COCO photo of the shared data folder ($CAMPRO_SHARED or
/// ../shared), where it is there: real pixels, whose share sent to the reference differs
/// from the synthetic frame's.
fn coco_frame(w: usize, h: usize) -> Option<Vec<u8>> {
    let path = crate::args::shared_dir(None).join("data/coco-person/images/000000000785.jpg");
    let budget = campro_eval::image_file::Budget::new(256 << 20);
    let (img, _lease) =
        campro_eval::image_file::read(&path, &budget, &campro_eval::image_file::no_work, &|_| {}).ok()?;
    let img = img.into_rgb8();
    let (iw, ih) = (img.width() as usize, img.height() as usize);
    let mut f = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let p = img.get_pixel((x % iw) as u32, (y % ih) as u32);
            f[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&p.0);
        }
    }
    Some(f)
}

/// `campro bench` (without a subcommand): the table for `--params` or, by default, a set
/// like the paper's strong checkpoints ([`campro::bench::bench_params`]).
pub fn run_command(a: &BenchArgs) -> anyhow::Result<()> {
    let p = match &a.params {
        Some(path) => crate::load_params(path)?,
        None => campro::bench::bench_params(),
    };
    let rows = run(&p, a.quick);
    match a.format {
        Report::Text => crate::say!("{}", table(&rows).markdown().trim_end()),
        Report::Json => crate::say!("{}", json(&rows)),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_print_as_markdown_and_json() {
        let row = |time, max_lsb| Row {
            group: "image",
            name: "x".into(),
            time,
            max_lsb,
            mean_lsb: f64::NAN,
            note: "n".into(),
        };
        let rows = [row(Time::Frame(0.002), 0.5), row(Time::Update(2e-6), 0.004), row(Time::None, 0.0)];
        let md = table(&rows).markdown();
        let md: Vec<&str> = md.lines().collect();
        assert_eq!(md[0], "| group | path / setting | median time | max err (LSB8) | mean err (LSB8) | note |");
        assert_eq!(md[2], "| image | x | 2.00 ms/frame (0.96 ms/Mpx) | 0.500 | - | n |");
        assert_eq!(md[3], "| image | x | 2.000 us/update | 4.0e-3 | - | n |");
        assert_eq!(md[4], "| image | x | - | 0 | - | n |");
        let j = json(&rows);
        assert_eq!(j["rows"][0]["seconds"], 0.002);
        assert_eq!(j["rows"][0]["per"], "frame");
        assert_eq!(j["rows"][1]["per"], "update");
        assert!(
            j["rows"][0]["mean_lsb"].is_null() && j["rows"][2]["per"].is_null() && j["rows"][2]["seconds"].is_null()
        );
    }
}
