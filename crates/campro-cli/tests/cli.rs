//! The `campro` command line, end to end: outputs, bad input (one-line errors, non-zero
//! exit, no panic, no partial files), overwrite rules.

mod common;

use campro::Params;
use common::{bundled, campro, fails_with, write_pt};
use std::io::Write;
use std::path::{Path, PathBuf};

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        walk(dir).into_iter().map(|p| p.strip_prefix(dir).unwrap().display().to_string()).collect();
    v.sort();
    v
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p))
        } else {
            out.push(p)
        }
    }
    out
}

#[test]
fn validate_bundled_and_bad_files() {
    campro().arg("validate").arg(bundled("identity.json")).arg(bundled("color-inversion.json")).assert().success();
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(
        &bad,
        r#"{"format":"campro-params","version":1,"ccm":[[1,0,0],[0,1,0],[0,0,1]],"tone_curve":{"y":[0,2]}}"#,
    )
    .unwrap();
    fails_with(campro().arg("validate").arg(&bad), "tone_curve.y[1]");
    std::fs::write(&bad, "{ not json").unwrap();
    fails_with(campro().arg("validate").arg(&bad), "invalid JSON");
    fails_with(campro().arg("validate").arg(dir.path().join("missing.json")), "missing.json");
}

#[test]
fn convert_json_has_camera2_keys() {
    let out = campro()
        .args([
            "convert",
            "--target",
            "camera2",
            "--device-ccm",
            "1.78",
            "-0.62",
            "-0.16",
            "-0.28",
            "1.62",
            "-0.34",
            "0.02",
            "-0.71",
            "1.69",
        ])
        .arg(bundled("color-inversion.json"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let cst: Vec<i64> = v["colorCorrectionTransform"].as_array().unwrap().iter().map(|x| x.as_i64().unwrap()).collect();
    assert_eq!(cst.len(), 18);
    // Identity CCM: the device matrix itself, exactly representable.
    assert_eq!(cst[0] as f64 / cst[1] as f64, 1.78);
    assert_eq!(cst[14] as f64 / cst[15] as f64, -0.71);
    for ch in ["red", "green", "blue"] {
        let c: Vec<f64> = v["tonemapCurve"][ch].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        assert_eq!(c.len(), 64);
        assert_eq!((c[0], c[1], c[62], c[63]), (0.0, 1.0, 1.0, 0.0));
    }
    let kt = campro().args(["convert", "--format", "kotlin"]).arg(bundled("identity.json")).output().unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(
        kt.contains("ColorSpaceTransform(intArrayOf(1, 1, 0, 1,")
            && kt.contains("TonemapCurve(campro, campro, campro)")
    );
}

#[test]
fn convert_sends_a_curve_per_channel() {
    // A version 2 set: red inverted, green a ramp to 0.5, blue the identity (2 knots each).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("three.json");
    std::fs::write(
        &path,
        r#"{"format":"campro-params","version":2,"ccm":[[1,0,0],[0,1,0],[0,0,1]],
            "tone_curves":{"red":{"y":[1,0]},"green":{"y":[0,0.5]},"blue":{"y":[0,1]}}}"#,
    )
    .unwrap();
    let out = campro().args(["convert", "--target", "camera2"]).arg(&path).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let curve = |ch: &str| -> Vec<f64> {
        v["tonemapCurve"][ch].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
    };
    assert_eq!(curve("red"), vec![0.0, 1.0, 1.0, 0.0]);
    assert_eq!(curve("green"), vec![0.0, 0.0, 1.0, 0.5]);
    assert_eq!(curve("blue"), vec![0.0, 0.0, 1.0, 1.0]);
    let kt = campro().args(["convert", "--format", "kotlin"]).arg(&path).output().unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(
        kt.contains("val green = floatArrayOf(0.0f, 0.0f, 1.0f, 0.5f)")
            && kt.contains("TonemapCurve(red, green, blue)"),
        "{kt}"
    );
    // A stack with one gamma curve refuses it by name; the 3D LUT holds it.
    if let Some(base) = campro_testkit::shared("fixtures/targets/rpi_pisp_imx219.json") {
        fails_with(
            campro().args(["convert"]).arg(&path).args(["--target", "rpi-pisp", "--base"]).arg(base),
            "a curve per channel",
        );
    }
    let lut = campro().args(["convert"]).arg(&path).args(["--target", "cube", "--cube-size", "2"]).output().unwrap();
    assert!(lut.status.success(), "{}", String::from_utf8_lossy(&lut.stderr));
    // The LUT's (1, 0, 0) node: red through the inverted curve, green and blue at 0.
    assert!(String::from_utf8(lut.stdout).unwrap().lines().any(|l| l == "0.000000 0.000000 0.000000"));
}

#[test]
fn convert_capture_result_and_bad_device_input() {
    let dir = tempfile::tempdir().unwrap();
    let cr = dir.path().join("cr.json");
    std::fs::write(&cr, r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1]}"#).unwrap();
    let out = campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr).output().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["colorCorrectionTransform"][0], 2);
    assert!(v["colorCorrectionGains"].is_null(), "no gains in the result, none invented");

    // The gains metered with the transform travel into the JSON and the Kotlin statements.
    std::fs::write(
        &cr,
        r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1], "colorCorrectionGains": [2.25, 1, 1, 1.5]}"#,
    )
    .unwrap();
    let convert = |format: &str| {
        let out = campro()
            .arg("convert")
            .arg(bundled("identity.json"))
            .arg("--capture-result")
            .arg(&cr)
            .args(["--format", format])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    let v: serde_json::Value = serde_json::from_str(&convert("json")).unwrap();
    assert_eq!(v["colorCorrectionGains"], serde_json::json!([2.25, 1.0, 1.0, 1.5]));
    let kt = convert("kotlin");
    assert!(kt.contains("COLOR_CORRECTION_GAINS, RggbChannelVector(2.25f, 1.0f, 1.0f, 1.5f))"), "{kt}");
    let kt = campro()
        .args(["convert", "identity", "--format", "kotlin", "--device-gains", "1.9", "1", "1", "2.5"])
        .output()
        .unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(kt.contains("RggbChannelVector(1.9f, 1.0f, 1.0f, 2.5f)"), "{kt}");
    let kt = campro().args(["convert", "identity", "--format", "kotlin"]).output().unwrap();
    let kt = String::from_utf8(kt.stdout).unwrap();
    assert!(
        kt.contains("meteringResult.get(CaptureResult.COLOR_CORRECTION_GAINS)"),
        "unknown gains are read back: {kt}"
    );
    std::fs::write(
        &cr,
        r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1], "colorCorrectionGains": [2, 1, 1]}"#,
    )
    .unwrap();
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr),
        "colorCorrectionGains: must have 4 entries, got 3",
    );
    std::fs::write(&cr, r#"{"colorCorrectionTransform": [2,1,0,1,0,1, 0,1,1,1,0,1, 0,1,0,1,1,1], "colorCorrectionGains": [2, 1, 1, -1]}"#).unwrap();
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr),
        "colorCorrectionGains[3]",
    );
    fails_with(campro().args(["convert", "identity", "--device-gains", "1", "1", "1", "0"]), "--device-gains");

    std::fs::write(&cr, r#"{"colorCorrectionTransform": [1,0]}"#).unwrap();
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).arg("--capture-result").arg(&cr),
        "colorCorrectionTransform",
    );
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).args([
            "--device-ccm",
            "1",
            "0",
            "0",
            "0",
            "1",
            "0",
            "0",
            "0",
            "NaN",
        ]),
        "--device-ccm[2][2]",
    );
    fails_with(
        campro().arg("convert").arg(bundled("identity.json")).args(["--max-curve-points", "1"]),
        "--max-curve-points",
    );
    fails_with(campro().arg("convert").arg(bundled("identity.json")).args(["--ct", "5000"]), "ct_calibration");
}

#[test]
fn convert_output_file_is_not_overwritten_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("v.json");
    std::fs::write(&o, "keep").unwrap();
    fails_with(campro().arg("convert").arg(bundled("identity.json")).arg("-o").arg(&o), "exists");
    assert_eq!(std::fs::read_to_string(&o).unwrap(), "keep");
    campro().arg("convert").arg(bundled("identity.json")).arg("-o").arg(&o).arg("--force").assert().success();
    assert!(std::fs::read_to_string(&o).unwrap().contains("colorCorrectionTransform"));
    assert_eq!(files_in(dir.path()), vec!["v.json"], "no temporary files left");
}

#[test]
fn import_pt_reads_fixture_and_refuses_hostile_files() {
    let dir = tempfile::tempdir().unwrap();
    if let Some(ck) = campro_testkit::shared("fixtures/campro-pt/params_03_mixed.pt") {
        let out = dir.path().join("p.json");
        campro().arg("import-pt").arg(&ck).arg("-o").arg(&out).assert().success();
        let p = Params::from_file(&out).unwrap();
        assert_eq!(p, {
            let mut q = campro::import_pt::read_checkpoint(&ck).unwrap();
            q.provenance = p.provenance.clone();
            q
        });
        fails_with(campro().arg("import-pt").arg(&ck).arg("-o").arg(&out), "exists");

        // The same checkpoint with its storages tagged for CUDA is read the same way.
        let mut zin = zip::ZipArchive::new(std::fs::File::open(&ck).unwrap()).unwrap();
        let mut entries = Vec::new();
        for i in 0..zin.len() {
            let mut f = zin.by_index(i).unwrap();
            let mut b = Vec::new();
            std::io::Read::read_to_end(&mut f, &mut b).unwrap();
            entries.push((f.name().to_string(), b));
        }
        let cuda = dir.path().join("cuda.pt");
        let mut z = zip::ZipWriter::new(std::fs::File::create(&cuda).unwrap());
        let o = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
        for (name, mut b) in entries {
            if name.ends_with("data.pkl") {
                let from = b"X\x03\x00\x00\x00cpu";
                let to = b"X\x06\x00\x00\x00cuda:0";
                let pos = b.windows(from.len()).position(|w| w == from).unwrap();
                b.splice(pos..pos + from.len(), to.iter().copied());
            }
            z.start_file(name, o).unwrap();
            z.write_all(&b).unwrap();
        }
        z.finish().unwrap();
        let pc = campro::import_pt::read_checkpoint(&cuda).unwrap();
        assert_eq!(pc.provenance["device"], "cuda:0");
        assert_eq!((pc.ccm, pc.tone_curves.channel(0).clone()), (p.ccm, p.tone_curves.channel(0).clone()));
    }

    // A pickle calling os.system must be refused by name, never run.
    let evil = dir.path().join("evil.pt");
    write_pt(&evil, b"\x80\x02cos\nsystem\nq\x00X\x05\x00\x00\x00touchq\x01\x85q\x02Rq\x03.", &[]);
    let out = dir.path().join("evil.json");
    fails_with(campro().arg("import-pt").arg(&evil).arg("-o").arg(&out), "os.system");
    assert!(!out.exists());

    // Memo bombs: each BINGET doubles the object it unfolds to (2^40 leaves). Fetches
    // share, so it is 40 small nodes, walked once each, refused for its layout at once.
    let mut bomb = b"\x80\x02]q\x00".to_vec();
    for _ in 0..40 {
        bomb.extend_from_slice(b"h\x00h\x00\x86q\x00");
    }
    bomb.push(b'.');
    write_pt(&evil, &bomb, &[]);
    fails_with(
        campro().arg("import-pt").arg(&evil).arg("-o").arg(&out).timeout(std::time::Duration::from_secs(60)),
        "expected an OrderedDict of stages, found a tuple",
    );

    // Not a zip, a truncated zip, a zip without data.pkl.
    std::fs::write(&evil, b"definitely not a checkpoint").unwrap();
    fails_with(campro().arg("import-pt").arg(&evil).arg("-o").arg(&out), "zip");
    write_pt(&evil, b"\x80\x02}q\x00.", &[]);
    let bytes = std::fs::read(&evil).unwrap();
    std::fs::write(&evil, &bytes[..bytes.len() / 2]).unwrap();
    fails_with(campro().arg("import-pt").arg(&evil).arg("-o").arg(&out), "checkpoint");
    // A pickle that is not a dict of stages.
    write_pt(&evil, b"\x80\x02]q\x00.", &[]);
    fails_with(campro().arg("import-pt").arg(&evil).arg("-o").arg(&out), "OrderedDict");
    assert!(!out.exists());
}

fn write_png8(path: &Path, w: u32, h: u32, data: &[u8]) {
    image::save_buffer(path, data, w, h, image::ExtendedColorType::Rgb8).unwrap();
}

#[test]
fn simulate_folders_depths_and_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    let px: Vec<u8> = (0..4 * 3 * 3).map(|i| (i * 7 % 256) as u8).collect();
    write_png8(&input.join("a.png"), 4, 3, &px);
    image::save_buffer(input.join("sub/b.jpg"), &px, 4, 3, image::ExtendedColorType::Rgb8).unwrap();
    let px16: Vec<u16> = (0..4 * 3 * 3).map(|i| (i * 1777 % 65536) as u16).collect();
    image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(4, 3, px16.clone())
        .unwrap()
        .save(input.join("sub/c.tif"))
        .unwrap();
    std::fs::write(input.join("notes.txt"), "hello").unwrap();
    std::fs::write(input.join("broken.png"), b"\x89PNG\r\n\x1a\n garbage").unwrap();
    let out = dir.path().join("out");
    let params = bundled("color-inversion.json");

    let run = campro()
        .arg("simulate")
        .arg(&params)
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .args(["--bit-depth", "16"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "a corrupt image makes the run fail");
    assert!(err.contains("notes.txt") && err.contains("warning"), "{err}");
    assert!(err.contains("broken.png") && !err.contains("panicked"), "{err}");
    // Each keeps its format, but a JPEG asked for 16 bits becomes a PNG (JPEG has no 16 bits).
    assert_eq!(files_in(&out), vec!["a.png", "sub/b.png", "sub/c.tif"], "the good images are written, nothing partial");

    // 16-bit output of an 8-bit PNG: each channel within 0.5 LSB of the f64 pipeline.
    let p = Params::from_file(&params).unwrap();
    let got = image::open(out.join("a.png")).unwrap().into_rgb16().into_raw();
    for (s, d) in px.chunks(3).zip(got.chunks(3)) {
        let want = campro::pipeline::process_f64(&p, [s[0] as f64 / 255.0, s[1] as f64 / 255.0, s[2] as f64 / 255.0]);
        for k in 0..3 {
            assert!((d[k] as f64 - want[k] * 65535.0).abs() <= 0.5 + 1e-9);
        }
    }
    // 16-bit TIFF input is read at 16 bits and written as a 16-bit TIFF.
    let tiff = image::open(out.join("sub/c.tif")).unwrap();
    assert_eq!(tiff.color(), image::ColorType::Rgb16);
    let got = tiff.into_rgb16().into_raw();
    for (s, d) in px16.chunks(3).zip(got.chunks(3)) {
        let want =
            campro::pipeline::process_f64(&p, [s[0] as f64 / 65535.0, s[1] as f64 / 65535.0, s[2] as f64 / 65535.0]);
        for k in 0..3 {
            assert!((d[k] as f64 - want[k] * 65535.0).abs() <= 0.5 + 1e-9);
        }
    }

    // Existing outputs are kept without --force, replaced with it.
    std::fs::remove_file(input.join("broken.png")).unwrap();
    let before = std::fs::read(out.join("a.png")).unwrap();
    fails_with(campro().arg("simulate").arg(&params).arg(input.join("a.png")).arg("-o").arg(&out), "exists");
    assert_eq!(std::fs::read(out.join("a.png")).unwrap(), before);
    campro()
        .arg("simulate")
        .arg(&params)
        .arg(input.join("a.png"))
        .arg("-o")
        .arg(&out)
        .arg("--force")
        .assert()
        .success();
    let eight = image::open(out.join("a.png")).unwrap();
    assert_eq!(eight.color(), image::ColorType::Rgb8);
    assert_eq!(files_in(&out), vec!["a.png", "sub/b.png", "sub/c.tif"]);
}

#[test]
fn photos_keep_their_format_and_one_input_may_name_its_output() {
    let dir = tempfile::tempdir().unwrap();
    // A smooth 64 x 48 photo (JPEG compresses it well) as a JPEG at quality 100.
    let (w, h) = (64u32, 48u32);
    let px: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            [(x * 4) as u8, (y * 5) as u8, ((x + y) * 2) as u8]
        })
        .collect();
    let photo = dir.path().join("photo.jpg");
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 100)
        .encode(&px, w, h, image::ExtendedColorType::Rgb8)
        .unwrap();
    std::fs::write(&photo, &jpeg).unwrap();
    let params = bundled("campro-omega-0.5.json");
    let p = Params::from_file(&params).unwrap();
    let decoded = image::open(&photo).unwrap().into_rgb8().into_raw();
    let mut want = vec![0u8; decoded.len()];
    campro::pipeline::fast::Exact8::new(&p).run(&decoded, &mut want);
    let mean_error =
        |got: &[u8]| got.iter().zip(&want).map(|(&g, &w)| (g as f64 - w as f64).abs()).sum::<f64>() / got.len() as f64;
    let simulate_into = |out: &Path, flags: &[&str]| {
        campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(out).args(flags).assert().success();
    };
    // Into a folder: photo.jpg stays photo.jpg, a JPEG, at the quality asked.
    let mut sizes = Vec::new();
    for q in [95, 30] {
        let out = dir.path().join(format!("q{q}"));
        simulate_into(&out, &["--quality", &q.to_string()]);
        assert_eq!(files_in(&out), vec!["photo.jpg"]);
        let bytes = std::fs::read(out.join("photo.jpg")).unwrap();
        assert_eq!(image::guess_format(&bytes).unwrap(), image::ImageFormat::Jpeg);
        let got = image::load_from_memory(&bytes).unwrap().into_rgb8().into_raw();
        sizes.push((bytes.len(), mean_error(&got)));
    }
    // Lower quality: a smaller file further from the exact output (which the higher one is near).
    assert!(sizes[1].0 < sizes[0].0 && sizes[1].1 > sizes[0].1, "{sizes:?}");
    assert!(sizes[0].1 < 3.0, "quality 95 is within 3 levels on average: {sizes:?}");

    // --image-format png: the folder gets photo.png, the exact path bit for bit.
    let out = dir.path().join("png");
    simulate_into(&out, &["--image-format", "png"]);
    assert_eq!(files_in(&out), vec!["photo.png"]);
    assert_eq!(image::open(out.join("photo.png")).unwrap().into_rgb8().into_raw(), want);

    // One input and an output with an image ending: that file, in the format it names.
    let named = dir.path().join("protected.png");
    campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(&named).assert().success();
    let img = image::open(&named).unwrap();
    assert_eq!(img.into_rgb8().into_raw(), want, "PNG out of a JPEG: the exact path, bit for bit");
    fails_with(campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(&named), "exists");
    fails_with(campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(dir.path().join("x.mp4")), "an image");
    fails_with(campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(&photo), "replace");
    fails_with(
        campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(dir.path().join("q")).args(["--quality", "0"]),
        "--quality",
    );
}

#[test]
fn compare_reports_within_bound() {
    let out = campro()
        .arg("compare")
        .arg(bundled("color-inversion.json"))
        .args(["--format", "json", "--random", "2000", "--lut-size", "256", "--matrix-frac-bits", "10"])
        .args(["--device-ccm", "1.78", "-0.62", "-0.16", "-0.28", "1.62", "-0.34", "0.02", "-0.71", "1.69"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = v["comparison"].as_array().unwrap();
    assert_eq!(rows.len(), 4);
    for r in rows {
        assert!(r["maxLsb"].as_f64().unwrap() <= r["boundLsb"].as_f64().unwrap() + 1e-9, "{r}");
        assert!(r["maxLsb"].as_f64().unwrap() > 0.0, "a 256-entry LUT and Q10 matrix cost something");
    }
    assert!(v["verdict"].as_str().unwrap().starts_with("every condition within its stated bound"), "{v}");
    campro()
        .arg("compare")
        .arg(bundled("identity.json"))
        .assert()
        .success()
        .stdout(predicates::str::contains("every grey level"))
        .stdout(predicates::str::contains(
            "verdict: every condition within its stated bound; this stack holds the preset (at most",
        ));
    // A 4-entry device LUT cannot hold a learnt curve: the verdict says so.
    let out = campro()
        .arg("compare")
        .arg(bundled("campro-omega-0.5.json"))
        .args(["--format", "json", "--random", "2000", "--lut-size", "4"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["holds"], false, "{v}");
    assert!(v["verdict"].as_str().unwrap().contains("this stack cannot hold the preset (up to"), "{v}");
}

#[test]
fn demo_writes_before_and_after() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    // The default: the recommended preset, named on stdout, its pipeline on the chart.
    campro()
        .arg("demo")
        .arg("-o")
        .arg(&out)
        .assert()
        .success()
        .stdout(predicates::str::contains("COLOR_CORRECTION_TRANSFORM"))
        .stdout(predicates::str::contains("preset: campro-omega-0.5 (the recommended preset, built in)"));
    let preset = Params::from_file(&bundled("campro-omega-0.5.json")).unwrap();
    let chart = image::open(out.join("chart.png")).unwrap().into_rgb8();
    let protected = image::open(out.join("chart-protected.png")).unwrap().into_rgb8();
    for (x, y) in [(32, 3 * 64 + 32), (0, 4 * 64 + 5), (200, 100)] {
        let want = campro::pipeline::process_f64(&preset, chart.get_pixel(x, y).0.map(|c| c as f64 / 255.0));
        assert_eq!(protected.get_pixel(x, y).0, want.map(|v| (v * 255.0).round() as u8), "({x}, {y})");
    }
    // Another set, by --params: colour inversion.
    let out = dir.path().join("demo-inversion");
    campro().arg("demo").arg("-o").arg(&out).arg("--params").arg(bundled("color-inversion.json")).assert().success();
    let before = image::open(out.join("chart.png")).unwrap().into_rgb8();
    let after = image::open(out.join("chart-protected.png")).unwrap().into_rgb8();
    // Colour inversion: white patch (243) becomes dark, black ramp start becomes white.
    assert_eq!(before.get_pixel(32, 3 * 64 + 32).0, [243, 243, 242]);
    assert!(after.get_pixel(32, 3 * 64 + 32).0[0] < 20);
    assert_eq!(after.get_pixel(0, 4 * 64 + 5).0, [255, 255, 255]);
}

#[test]
fn help_for_every_command() {
    for c in ["validate", "import-pt", "convert", "simulate", "inspect", "compare", "demo", "bench", "stress"] {
        campro().args([c, "--help"]).assert().success();
    }
}

#[test]
fn file_targets_convert_compare_and_refuse() {
    let dir = tempfile::tempdir().unwrap();
    let cube = dir.path().join("campro.cube");
    campro()
        .args(["convert"])
        .arg(bundled("srgb-passthrough.json"))
        .args(["--target", "cube", "--cube-size", "9", "-o"])
        .arg(&cube)
        .assert()
        .success();
    let text = std::fs::read_to_string(&cube).unwrap();
    assert_eq!(campro::targets::cube::parse_cube(&text).unwrap().size(), 9);
    let out = campro()
        .args(["compare"])
        .arg(bundled("srgb-passthrough.json"))
        .args(["--target", "cube", "--random", "500", "--format", "json"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["target"], "cube");
    assert_eq!(
        v["comparison"].as_array().unwrap().len(),
        8,
        "2 interpolations x 4 pixel sets (every grey level first)"
    );
    fails_with(campro().args(["convert"]).arg(bundled("identity.json")).args(["--target", "rkisp1"]), "--target cube");
    fails_with(campro().args(["convert"]).arg(bundled("identity.json")).args(["--target", "rpi-vc4"]), "--base");
    fails_with(campro().args(["convert"]).arg(bundled("identity.json")).args(["--target", "hald"]), "binary");
    // Nothing half-written on a refusal.
    fails_with(
        campro()
            .args(["convert"])
            .arg(bundled("identity.json"))
            .args(["--target", "uvc", "-o"])
            .arg(dir.path().join("x.json")),
        "scalar gamma",
    );
    assert!(!dir.path().join("x.json").exists());
}

/// `eval all` on a few images and identities: every report is written, laid out as stated.
#[test]
fn eval_all_with_a_limit_writes_every_report() {
    let Some(shared) = campro_testkit::shared_root(&[
        "models/yunet_s_640_640.onnx",
        "data/lfw/pairs.txt",
        "data/coco-person/instances_person.json",
    ]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ev");
    campro()
        .args(["eval", "all"])
        .arg(bundled("identity.json"))
        .arg(bundled("color-inversion.json"))
        .args(["--baseline", "lowres-8", "--limit", "4", "--runs", "2", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    for f in [
        "privacy.csv",
        "privacy.md",
        "verification.csv",
        "cmc.svg",
        "utility.csv",
        "quality.csv",
        "report.md",
        "tradeoff.svg",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let csv = |name: &str| -> Vec<Vec<String>> {
        std::fs::read_to_string(out.join(name))
            .unwrap()
            .lines()
            .map(|l| l.split(',').map(String::from).collect())
            .collect()
    };
    // Table I layout: dataset, order, image type, classifier, one column per model, average.
    let p = csv("privacy.csv");
    assert_eq!(p[0].join(","), "dataset,order,image_type,classifier,faceplugin,mobilefacenet-casia,average");
    assert_eq!(p.len(), 1 + 2 * 4 * 2, "2 orders x 4 image types x 2 classifiers");
    for row in &p[1..] {
        let v: Vec<f64> = row[4..].iter().map(|x| x.parse().unwrap()).collect();
        assert!(v.iter().all(|x| (0.0..=100.0).contains(x)));
        assert!((v[2] - (v[0] + v[1]) / 2.0).abs() < 0.01, "average column: {row:?}");
        if row[2] == "raw" {
            assert!(v[2] >= 75.0, "raw faces of 4 identities are recognised: {row:?}");
        }
    }
    let u = csv("utility.csv");
    assert_eq!(u.len(), 1 + 4);
    assert_eq!(u[1][0], "raw");
    // Quality compares protected images with raw: no raw row.
    let q = csv("quality.csv");
    assert_eq!(
        q.iter().skip(1).map(|r| r[0].as_str()).collect::<Vec<_>>(),
        ["identity", "color-inversion", "lowres-8"]
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("tradeoff.svg") && report.contains("| lowres-8 |"));
}

/// `eval privacy --distractors`: the probed identities and their gallery and probe photos
/// stay the same while the gallery grows, so under the nearest classifier no probe's rank
/// can improve: every CMC point is at most the one without distractors.
#[test]
fn privacy_distractors_only_enlarge_the_gallery() {
    let Some(shared) = campro_testkit::shared_root(&["models/yunet_s_640_640.onnx", "data/lfw/pairs.txt"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], out: &str| -> serde_json::Value {
        let out = dir.path().join(out);
        campro()
            .args(["eval", "privacy"])
            .args(["--condition", "colour"])
            .arg(bundled("color-inversion.json"))
            .args(["--limit", "4", "--runs", "3", "--no-verification", "--shared"])
            .arg(&shared)
            .args(extra)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        privacy_json(&out)
    };
    let (a, b) = (run(&[], "plain"), run(&["--distractors", "6"], "more"));
    assert_eq!(a["identities"], b["identities"]);
    assert_eq!(a["gallery"], a["identities"]);
    let (n, g) = (b["identities"].as_u64().unwrap(), b["gallery"].as_u64().unwrap());
    assert!(g > n && g <= n + 6, "gallery {g} for {n} probed identities and 6 distractors");
    let md = std::fs::read_to_string(dir.path().join("more/privacy.md")).unwrap();
    assert!(md.contains(&format!("gallery of {g} identities, {} of them distractors", g - n)), "{md}");
    assert!(md.contains(&format!("(chance {:.2}%)", 100.0 / g as f64)), "{md}");
    let rows = |v: &serde_json::Value| v["identification"].as_array().unwrap().clone();
    let (ra, rb) = (rows(&a), rows(&b));
    assert_eq!(ra.len(), rb.len());
    let mut compared = 0;
    for (x, y) in ra.iter().zip(&rb) {
        assert_eq!(
            (&x["condition"], &x["order"], &x["model"], &x["classifier"]),
            (&y["condition"], &y["order"], &y["model"], &y["classifier"])
        );
        if x["classifier"] == "nearest" {
            for (p, q) in x["cmc"].as_array().unwrap().iter().zip(y["cmc"].as_array().unwrap()) {
                assert!(q.as_f64().unwrap() <= p.as_f64().unwrap() + 1e-12, "{x} vs {y}");
            }
            compared += 1;
        }
    }
    assert_eq!(compared, 2 * 2 * 2, "2 conditions x 2 orders x 2 models");
    let bad = campro().args(["eval", "privacy", "--distractors", "many"]).output().unwrap();
    assert!(
        !bad.status.success()
            && String::from_utf8_lossy(&bad.stderr).contains("expected a count or `all`, got \"many\"")
    );
}

/// `eval privacy --restore`: each parameter set gets a "NAME restored" row. Colour inversion
/// is a bijection, so restoring it gives most of the raw accuracy back; baselines get none.
#[test]
fn privacy_restore_undoes_a_bijective_camera() {
    let Some(shared) = campro_testkit::shared_root(&[
        "models/yunet_s_640_640.onnx",
        "data/lfw/pairs.txt",
        "data/coco-person/instances_person.json",
    ]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    campro()
        .args(["eval", "privacy"])
        .args(["--condition", "colour"])
        .arg(bundled("color-inversion.json"))
        .args(["--baseline", "lowres-8", "--restore", "--limit", "8", "--runs", "3", "--no-verification", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let v = privacy_json(&out);
    let top1 = |cond: &str| -> f64 {
        let rows: Vec<f64> = v["identification"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["condition"] == cond && r["order"] == "paper" && r["classifier"] == "nearest")
            .map(|r| 100.0 * r["top1_mean"].as_f64().unwrap())
            .collect();
        assert_eq!(rows.len(), 2, "{cond}: one row per model");
        rows.iter().sum::<f64>() / 2.0
    };
    let (inverted, restored, raw) = (top1("color-inversion"), top1("color-inversion restored"), top1("raw"));
    assert!(restored > inverted + 30.0 && restored > 0.6 * raw, "inverted {inverted}, restored {restored}, raw {raw}");
    let names: Vec<&str> =
        v["identification"].as_array().unwrap().iter().map(|r| r["condition"].as_str().unwrap()).collect();
    assert!(!names.contains(&"lowres-8 restored"), "only parameter sets are restored");
}

/// `eval privacy --enrol camera`: the attacker enrols its gallery through the same camera.
/// The raw condition's scores cannot change (its camera is the identity). A camera that
/// outputs one grey for every pixel makes every protected face the same, so the nearest
/// classifier's ties leave it at chance, 1 / gallery, exactly; enrolled raw, the same
/// camera sends every probe to one gallery face. Colour inversion keeps identities apart,
/// so matching inverted to inverted identifies more than matching it to raw faces.
#[test]
fn privacy_camera_enrolment_matches_protected_to_protected() {
    let Some(shared) = campro_testkit::shared_root(&["models/yunet_s_640_640.onnx", "data/lfw/pairs.txt"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut flat: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(bundled("color-inversion.json")).unwrap()).unwrap();
    flat["name"] = "flat-grey".into();
    flat["tone_curve"]["y"] = serde_json::json!(vec![0.5; 32]);
    let flat_path = dir.path().join("flat-grey.json");
    std::fs::write(&flat_path, serde_json::to_string(&flat).unwrap()).unwrap();
    let run = |enrol: &str| -> serde_json::Value {
        let out = dir.path().join(enrol);
        campro()
            .args(["eval", "privacy"])
            .args(["--condition", "colour"])
            .arg(bundled("color-inversion.json"))
            .arg(&flat_path)
            .args(["--limit", "8", "--runs", "3", "--no-verification", "--enrol", enrol, "--shared"])
            .arg(&shared)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        let md = std::fs::read_to_string(out.join("privacy.md")).unwrap();
        assert!(md.contains(if enrol == "camera" { "Enrolled through the camera" } else { "Enrolled raw" }), "{md}");
        privacy_json(&out)
    };
    let (raw, cam) = (run("raw"), run("camera"));
    assert_eq!(cam["options"]["enrolment"], "camera");
    let rows = |v: &serde_json::Value, cond: &str, cls: &str| -> Vec<f64> {
        let r: Vec<f64> = v["identification"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["condition"] == cond && r["order"] == "paper" && r["classifier"] == cls)
            .map(|r| r["top1_mean"].as_f64().unwrap())
            .collect();
        assert_eq!(r.len(), 2, "{cond} {cls}: one row per model");
        r
    };
    for cls in ["nearest", "linear"] {
        assert_eq!(rows(&raw, "raw", cls), rows(&cam, "raw", cls), "the raw condition is enrolled the same either way");
    }
    let gallery = cam["gallery"].as_f64().unwrap();
    for t in rows(&cam, "flat-grey", "nearest") {
        assert!(
            (t - 1.0 / gallery).abs() < 1e-12,
            "flat camera enrolled through itself: {t}, chance {}",
            1.0 / gallery
        );
    }
    for t in rows(&raw, "flat-grey", "nearest") {
        assert!(t <= 1.0 / gallery + 1e-12, "every probe goes to the same gallery face: {t}");
    }
    let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    let (as_raw, as_cam) =
        (mean(rows(&raw, "color-inversion", "nearest")), mean(rows(&cam, "color-inversion", "nearest")));
    assert!(as_cam > as_raw + 0.2, "colour inversion enrolled raw {as_raw}, through the camera {as_cam}");
    let bad = campro().args(["eval", "privacy", "--enrol", "sideways"]).output().unwrap();
    assert!(!bad.status.success() && String::from_utf8_lossy(&bad.stderr).contains("sideways"));
}

/// `--attack retrain` on tiny data: each face model is fine-tuned on colour-inverted faces of
/// identities the evaluation never probes, written beside its log, and scored on the same
/// probes as the plain rows.
#[test]
fn privacy_retrain_attack_fine_tunes_each_model_on_unprobed_identities() {
    let Some(shared) = campro_testkit::shared_root(&["models/yunet_s_640_640.onnx", "data/lfw/pairs.txt"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let probed = ["Colin_Powell", "George_W_Bush", "Gerhard_Schroeder", "Donald_Rumsfeld", "Ariel_Sharon"];
    let list = dir.path().join("probed.txt");
    std::fs::write(&list, probed.join("\n")).unwrap();
    let out = dir.path().join("ev");
    campro()
        .args(["eval", "privacy"])
        .args(["--condition", "colour"])
        .arg(bundled("color-inversion.json"))
        .arg("--identities")
        .arg(&list)
        .args(["--runs", "1", "--no-verification", "--attack", "retrain", "--retrain-identities", "6"])
        .args(["--retrain-photos", "3", "--retrain-epochs", "2", "--retrain-batch", "8", "--retrain-lr", "0.01"])
        .arg("--shared")
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let v = privacy_json(&out);
    let rows: Vec<&serde_json::Value> = v["identification"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["condition"] == "color-inversion retrained" && r["order"] == "paper")
        .collect();
    // Two models, two classifiers, rates in [0, 1].
    assert_eq!(rows.len(), 4, "{rows:?}");
    assert!(rows.iter().all(|r| (0.0..=1.0).contains(&r["top1_mean"].as_f64().unwrap())));
    for model in ["faceplugin", "mobilefacenet-casia"] {
        let file = |ext: &str| out.join(format!("retrain/color-inversion.{model}.{ext}"));
        assert!(file("onnx").is_file(), "{model}: no fine-tuned model");
        let rec: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(file("json")).unwrap()).unwrap();
        let names: Vec<&str> = rec["identities"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
        assert!(names.len() >= 2 && names.len() <= 6, "{names:?}");
        assert!(names.iter().all(|n| !probed.contains(n)), "trained on a probed identity: {names:?}");
        assert_eq!(rec["log"]["classes"].as_u64().unwrap() as usize, names.len());
        assert_eq!(rec["log"]["epoch_loss"].as_array().unwrap().len(), 2);
    }
    fails_with(
        campro().args(["eval", "privacy", "--attack", "retrain", "--limit", "3"]).arg("-o").arg(dir.path().join("x")),
        "--attack retrain needs --identities",
    );
}

#[test]
fn eval_refuses_bad_arguments_clearly() {
    let out = campro().args(["eval", "quality", "--baseline", "lowres-0"]).output().unwrap();
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("expected lowres-S (S ≥ 1)"));
    fails_with(
        campro().args(["eval", "quality", "--shared", "/nonexistent-shared"]),
        "/nonexistent-shared/data/coco-person/images",
    );
    fails_with(
        campro().args(["eval", "utility", "--person-detector", "nosuchmodel", "--shared", "/nonexistent-shared"]),
        "reading the COCO person set",
    );
    let Some(_) = campro_testkit::shared("data/coco-person/instances_person.json") else { return };
    let shared = campro_testkit::shared("").unwrap();
    fails_with(
        campro().args(["eval", "utility", "--person-detector", "nosuchmodel", "--shared"]).arg(&shared),
        "neither a bundled model",
    );
}

/// `train` with all three players on tiny data writes a parameter set, the fine-tuned
/// detector (ONNX + manifest) beside it and the log; `eval utility` runs that detector and
/// `eval privacy --identities` scores only the identities the run held out.
#[test]
fn train_writes_params_and_detector_that_eval_reads() {
    let Some(models) = campro_testkit::shared("models/yolox_nano.onnx") else { return };
    let Some(lfw) = campro_testkit::shared("data/lfw/pairs.txt") else { return };
    let Some(coco) = campro_testkit::shared("data/coco-person/instances_person.json") else { return };
    let shared = models.parent().unwrap().parent().unwrap().to_path_buf();
    let dir = tempfile::tempdir().unwrap();
    let q = |p: &std::path::Path| format!("{:?}", p.to_str().unwrap());
    let cfg = format!(
        "[attacker]\ncheckpoint = {}\npretrain_steps = 2\n[protector]\nomega = 1.0\n[data]\nlfw = {}\nmodels = {}\nmax_identities = 5\nbatch = 8\ncache = {}\n[detector]\nmodel = {}\ndata = {}\nsize = 128\nbatch = 2\nmax_images = 2\n[budget]\nrounds = 2\n",
        q(&models.with_file_name("mobilefacenet_casia_068.ckpt")),
        q(lfw.parent().unwrap()),
        q(models.parent().unwrap()),
        q(&dir.path().join("cache")),
        q(&models),
        q(coco.parent().unwrap())
    );
    std::fs::write(dir.path().join("tiny.toml"), cfg).unwrap();
    let p = dir.path().join("p.json");
    campro()
        .arg("train")
        .arg(dir.path().join("tiny.toml"))
        .arg("-o")
        .arg(&p)
        .arg("--log")
        .arg(dir.path().join("log.csv"))
        .assert()
        .success();
    campro().arg("validate").arg(&p).assert().success();
    let log = std::fs::read_to_string(dir.path().join("log.csv")).unwrap();
    assert!(
        log.starts_with(
            "round,seconds,attacker_ce,attacker_accuracy,privacy_loss,detection_loss,check_accuracy,validation_top1,validation_ap\n"
        )
            && log.lines().count() == 4,
        "{log}"
    );
    let manifest = dir.path().join("p.detector.json");
    assert!(dir.path().join("p.detector.onnx").is_file() && manifest.is_file());
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    assert_eq!(v["provenance"]["detector"]["onnx"], "p.detector.onnx");
    let held_out = v["provenance"]["data"]["validation_identities"].as_array().unwrap().len();
    assert_eq!(held_out, 1);
    // Run from another folder: the manifest finds its ONNX beside itself.
    let out = dir.path().join("ev");
    campro()
        .current_dir("/")
        .args(["eval", "utility"])
        .arg(&p)
        .arg("--person-detector")
        .arg(&manifest)
        .args(["--limit", "2", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    assert!(std::fs::read_to_string(out.join("utility.md")).unwrap().contains("fine-tuned (p)"));
    // --own-detector: raw with the bundled detector, p with its own, rows in order.
    campro()
        .args(["eval", "utility"])
        .arg(&p)
        .args(["--own-detector", "--limit", "2", "--force", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    let md = std::fs::read_to_string(out.join("utility.md")).unwrap();
    assert!(md.contains("yolox-nano; p each with its own fine-tuned detector"), "{md}");
    assert!(md.contains("2 images (those held out of detector fine-tuning: COCO id % 5 == 0)"), "{md}");
    let scored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("utility.json")).unwrap()).unwrap();
    assert_eq!(scored["options"]["held_out"], true);
    let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| raw") || l.starts_with("| p ")).collect();
    assert_eq!(rows.len(), 2, "{md}");
    assert!(rows[0].starts_with("| raw"));
    campro()
        .args(["eval", "privacy"])
        .args(["--condition", "colour"])
        .arg(&p)
        .arg("--identities")
        .arg(&p)
        .args(["--runs", "1", "--no-verification", "--force", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    assert!(std::fs::read_to_string(out.join("privacy.md")).unwrap().contains("Closed set: 1 identities"));
    let names = dir.path().join("names.txt");
    std::fs::write(&names, "# two people\nNo_Such_Person\n").unwrap();
    fails_with(
        campro()
            .args(["eval", "privacy"])
            .arg(&p)
            .arg("--identities")
            .arg(&names)
            .args(["--force", "--shared"])
            .arg(&shared)
            .arg("-o")
            .arg(&out),
        "\"No_Such_Person\" is not in LFW",
    );
}

/// The bundled presets' own detectors: by name from any folder (built into the binary),
/// and from the repository's parameter file (the ONNX file beside it, no manifest).
#[test]
fn a_bundled_preset_s_own_detector_is_built_in() {
    let Some(models) = campro_testkit::shared("models/yolox_nano.onnx") else { return };
    let shared = models.parent().unwrap().parent().unwrap().to_path_buf();
    let dir = tempfile::tempdir().unwrap();
    let file = campro_testkit::workspace_root().join("params/campro-omega-0.5.json");
    for (k, preset) in [std::ffi::OsStr::new("campro-omega-0.5"), file.as_os_str()].into_iter().enumerate() {
        let out = dir.path().join(format!("ev{k}"));
        let run = campro()
            .current_dir(dir.path())
            .args(["eval", "utility"])
            .arg(preset)
            .args(["--own-detector", "--limit", "2", "--shared"])
            .arg(&shared)
            .arg("-o")
            .arg(&out)
            .assert()
            .success();
        let err = String::from_utf8_lossy(&run.get_output().stderr).into_owned();
        let said = if k == 0 { "(built in)" } else { "campro-omega-0.5.detector.onnx" };
        assert!(err.contains("loading yolox-nano fine-tuned (campro-omega-0.5)") && err.contains(said), "{err}");
        let md = std::fs::read_to_string(out.join("utility.md")).unwrap();
        assert!(md.contains("campro-omega-0.5 each with its own fine-tuned detector"), "{md}");
    }
}

#[test]
fn finetune_detector_writes_a_detector_for_any_params_and_records_it() {
    let Some(models) = campro_testkit::shared("models/yolox_nano.onnx") else { return };
    let Some(coco) = campro_testkit::shared("data/coco-person/instances_person.json") else { return };
    let shared = models.parent().unwrap().parent().unwrap().to_path_buf();
    let dir = tempfile::tempdir().unwrap();
    let q = |p: &std::path::Path| format!("{:?}", p.to_str().unwrap());
    let cfg = format!(
        "seed = 3\n[detector]\nmodel = {}\ndata = {}\nsize = 128\nbatch = 2\nmax_images = 2\n",
        q(&models),
        q(coco.parent().unwrap())
    );
    std::fs::write(dir.path().join("ft.toml"), cfg).unwrap();
    let p = dir.path().join("inv.json");
    std::fs::copy(campro_testkit::workspace_root().join("params/campro-omega-1.json"), &p).unwrap();
    let before: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    let run = || {
        let mut c = campro();
        c.arg("finetune-detector")
            .arg(&p)
            .arg("--config")
            .arg(dir.path().join("ft.toml"))
            .args(["--steps", "2", "--log"])
            .arg(dir.path().join("ft.csv"));
        c
    };
    run().assert().success();
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
    assert_eq!(v["ccm"], before["ccm"], "the camera is not touched");
    let d = &v["provenance"]["detector"];
    assert_eq!((d["onnx"].as_str(), d["manifest"].as_str()), (Some("inv.detector.onnx"), Some("inv.detector.json")));
    assert_eq!(
        (d["finetune"]["steps"].as_u64(), d["finetune"]["images"].as_u64(), d["finetune"]["seed"].as_u64()),
        (Some(2), Some(2), Some(3))
    );
    assert!(d["held_out_images"].as_str().unwrap().contains("% 5 == 0"));
    assert_eq!(std::fs::read_to_string(dir.path().join("ft.csv")).unwrap().lines().count(), 3);
    // Written at half precision: YOLOX-Nano's 3.66 MB of f32 weights in under 2 MB (the
    // repository's file limit, so presets ship theirs).
    let written = std::fs::metadata(dir.path().join("inv.detector.onnx")).unwrap().len();
    assert!(written < 2_000_000 && written > 1_700_000, "{written} bytes");
    // A written (half-precision) detector is a starting point for more fine-tuning.
    let again = dir.path().join("again.toml");
    let first = dir.path().join("first.detector.onnx");
    std::fs::copy(dir.path().join("inv.detector.onnx"), &first).unwrap();
    std::fs::write(
        &again,
        std::fs::read_to_string(dir.path().join("ft.toml")).unwrap().replace(&q(&models), &q(&first)),
    )
    .unwrap();
    let twice = dir.path().join("twice.json");
    std::fs::copy(&p, &twice).unwrap();
    campro().arg("finetune-detector").arg(&twice).arg("--config").arg(&again).args(["--steps", "1"]).assert().success();
    // Existing outputs are kept unless --force.
    fails_with(&mut run(), "exists (use --force");
    run().arg("--force").assert().success();
    let out = dir.path().join("ev");
    campro()
        .args(["eval", "utility"])
        .arg(&p)
        .args(["--own-detector", "--limit", "2", "--force", "--shared"])
        .arg(&shared)
        .arg("-o")
        .arg(&out)
        .assert()
        .success();
    assert!(std::fs::read_to_string(out.join("utility.md"))
        .unwrap()
        .contains("inv each with its own fine-tuned detector"));
    fails_with(campro().arg("finetune-detector").arg(&p).args(["--steps", "0"]), "0 is not in 1..=10000000");
    fails_with(campro().arg("finetune-detector").arg(&p).args(["--seconds", "NaN"]), "--seconds: must be > 0");
    // A curve with uneven knots cannot drive the optimiser's camera.
    let uneven = dir.path().join("uneven.json");
    let mut u = before.clone();
    u["tone_curve"] = serde_json::json!({ "x": [0.0, 0.3, 1.0], "y": [0.0, 0.5, 1.0] });
    std::fs::write(&uneven, u.to_string()).unwrap();
    fails_with(
        campro()
            .arg("finetune-detector")
            .arg(&uneven)
            .arg("--config")
            .arg(dir.path().join("ft.toml"))
            .args(["--steps", "1"]),
        "tone_curve: the optimiser's camera needs evenly spaced knots",
    );
    // ... nor start it (train --init), which also excludes --resume; no output is written.
    let trained = dir.path().join("t.json");
    let train = |init: &Path| {
        let mut c = campro();
        c.arg("train").arg(dir.path().join("ft.toml")).arg("--init").arg(init).arg("-o").arg(&trained);
        c
    };
    fails_with(&mut train(&uneven), "tone_curve: the optimiser's camera needs evenly spaced knots");
    let both = train(&p).arg("--resume").arg(dir.path()).output().unwrap();
    assert!(
        !both.status.success()
            && String::from_utf8_lossy(&both.stderr)
                .contains("'--init <INIT>' cannot be used with '--resume <RESUME>'")
    );
    assert!(!trained.exists());
}

/// Completions and the manual page come from the same clap definition as the parser.
#[test]
fn completions_man_page_and_json_validation() {
    let out = campro().args(["completions", "bash"]).output().unwrap();
    let bash = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && bash.contains("_campro()"), "{bash}");
    for sub in ["simulate", "convert", "eval", "train", "completions"] {
        assert!(bash.contains(sub), "bash completion lacks {sub}");
    }
    let man = campro().arg("man").output().unwrap();
    let man = String::from_utf8_lossy(&man.stdout);
    assert!(man.contains(".TH campro 1") && man.contains("simulate"), "{man}");
    let out = campro()
        .args(["validate", "--format", "json"])
        .arg(bundled("identity.json"))
        .arg(bundled("color-inversion.json"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let lines: Vec<serde_json::Value> =
        String::from_utf8_lossy(&out.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["name"], "identity");
    assert_eq!(lines[0]["knots"], 32);
    assert_eq!(lines[1]["name"], "color-inversion");
    assert_eq!(lines[1]["ok"], true);
}

#[test]
fn demo_and_stress_print_json() {
    let dir = tempfile::tempdir().unwrap();
    let out = campro()
        .args(["demo", "--format", "json", "--params"])
        .arg(bundled("color-inversion.json"))
        .arg("-o")
        .arg(dir.path().join("d"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["name"], "color-inversion");
    // Inversion: the curve falls from 1 to 0; the device output is the desktop's within
    // the stated bound on every compared pixel set.
    let red: Vec<f64> =
        v["camera2"]["tonemapCurve"]["red"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    assert_eq!((red[1], red[red.len() - 1]), (1.0, 0.0));
    let rows = v["comparison"].as_array().unwrap();
    // Grey levels, the RGB cube, random pixels, the chart.
    assert_eq!(rows.len(), 4);
    for r in rows {
        assert!(r["maxLsb"].as_f64().unwrap() <= r["boundLsb"].as_f64().unwrap(), "{r}");
    }
    let out = campro().args(["stress", "--seconds", "0.3", "--seed", "5", "--format", "json"]).output().unwrap();
    assert!(out.status.success());
    let s: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let cases = s["cases"].as_u64().unwrap();
    assert!(cases > 0);
    assert_eq!(s["converted"].as_u64().unwrap() + s["refused"].as_u64().unwrap(), cases);
    assert_eq!(s["next_seed"].as_u64().unwrap(), 5 + cases);
}

#[test]
fn bench_train_prints_step_medians_as_json() {
    let Some(shared) = campro_testkit::shared_root(&["models/yolox_nano.onnx"]) else {
        return;
    };
    let out = campro()
        .args(["bench", "train", "--runs", "1", "--only", "yolox", "--threads", "1", "--format", "json", "--shared"])
        .arg(&shared)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["threads"], 1);
    assert!(v["yolox_nano_1x416_ms"].as_f64().unwrap() > 0.0);
    assert!(v.get("mobilefacenet_8x112x96_ms").is_none(), "only the step asked for: {v}");
    fails_with(
        campro()
            .args(["bench", "train", "--runs", "1", "--only", "yolox", "--anchor", "/nonexistent/python", "--shared"])
            .arg(&shared),
        "--anchor",
    );
}

/// The privacy report an `eval privacy -o OUT` wrote.
fn privacy_json(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("privacy.json")).unwrap()).unwrap()
}

/// `eval frontier`: the plot and table of measured points; a bad CSV, a folder as the CSV
/// and an earlier run's output are refused in one line.
#[test]
fn eval_frontier_plots_the_points_and_refuses_bad_ones() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("p.csv"),
        "set,hours,top1,top1_attacked,ap_ratio\nslow,2.4,0.48,13.23,34\nfast,1.0,0.48,2.74,59\nfixed,,5,100,74\n",
    )
    .unwrap();
    campro().args(["eval", "frontier"]).arg(d.join("p.csv")).arg("-o").arg(d.join("f")).assert().success();
    let md = std::fs::read_to_string(d.join("f/frontier.md")).unwrap();
    // "slow" is beaten on both axes by "fast"; the other two are on the frontier.
    assert!(md.contains("| slow | 2.4 h | 0.48 | 13.23 | 34 |  |"), "{md}");
    assert!(
        md.contains("| fast | 1.0 h | 0.48 | 2.74 | 59 | yes |")
            && md.contains("| fixed | — | 5.00 | 100.00 | 74 | yes |")
    );
    assert!(std::fs::read_to_string(d.join("f/frontier.svg")).unwrap().contains("fast (1.0 h)"));
    let frontier = |csv: &Path, out: &str| {
        let mut c = campro();
        c.args(["eval", "frontier"]).arg(csv).arg("-o").arg(d.join(out));
        c
    };
    fails_with(&mut frontier(&d.join("p.csv"), "f"), "already holds files");
    std::fs::write(d.join("bad.csv"), "set,hours,top1,top1_attacked,ap_ratio\na,1,0.5,inf,60\n").unwrap();
    fails_with(&mut frontier(&d.join("bad.csv"), "g"), "line 2: top1_attacked must be a number in [0, 100]");
    fails_with(&mut frontier(d, "h"), "is a directory; only regular files are read");
}

/// Sidecars beside photos (`a.txt` by `a.png`, Lightroom's `IMG_1.xmp`, `x.webp.txt`) are
/// skipped with a warning each and never collide with the outputs: the photos are written.
#[test]
fn sidecars_are_skipped_not_a_collision() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    for name in ["a", "IMG_1", "x"] {
        image::RgbImage::from_pixel(16, 12, image::Rgb([200, 120, 90]))
            .save(photos.join(format!("{name}.png")))
            .unwrap();
    }
    for side in ["a.txt", "IMG_1.xmp", "x.webp.txt"] {
        std::fs::write(photos.join(side), b"sidecar").unwrap();
    }
    let out = dir.path().join("out");
    let run = campro()
        .arg("simulate")
        .arg(bundled("campro-omega-0.5.json"))
        .arg(&photos)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    for name in ["a.png", "IMG_1.png", "x.png"] {
        assert!(out.join(name).is_file(), "{name} not written: {err}");
    }
    for side in ["a.txt", "IMG_1.xmp", "x.webp.txt"] {
        assert!(
            err.contains(&format!(
                "skipping {}: not a PNG, JPEG, TIFF, WebP or video file",
                photos.join(side).display()
            )),
            "{err}"
        );
        assert!(!out.join(side).exists());
    }
    assert!(!err.contains("would both be written"), "{err}");
}

/// `img` as a JPEG, and the same JPEG stored "sideways": an APP1 Exif block (a
/// little-endian TIFF header and one IFD entry, Orientation (0x0112) = 6) after its SOI.
fn sideways_jpeg(img: &image::RgbImage) -> (Vec<u8>, Vec<u8>) {
    let mut plain = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut plain), image::ImageFormat::Jpeg).unwrap();
    let mut exif = b"Exif\0\0II*\0\x08\0\0\0\x01\0".to_vec();
    exif.extend_from_slice(&[0x12, 0x01, 3, 0, 1, 0, 0, 0, 6, 0, 0, 0, 0, 0, 0, 0]);
    let mut tagged = plain[..2].to_vec();
    tagged.extend_from_slice(&[0xff, 0xe1]);
    tagged.extend_from_slice(&((exif.len() + 2) as u16).to_be_bytes());
    tagged.extend_from_slice(&exif);
    tagged.extend_from_slice(&plain[2..]);
    (plain, tagged)
}

/// A phone's folder in one run: an iPhone's HEIC photo (the eval crate's fixture:
/// orientation 6 as a HEIF rotation), a JPEG stored sideways with EXIF orientation 6, a
/// WebP, and sidecars (Lightroom's `.xmp`, a `notes.txt`). The HEIC is read through libheif
/// and written as an upright JPEG (without libheif: skipped with the one line that says
/// what to install), the JPEG comes out turned, the WebP stays a WebP, the sidecars are
/// skipped with a warning each, and the run succeeds.
#[test]
fn a_phone_folder_goes_through_upright_in_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    let fixture = campro_testkit::workspace_root().join("crates/campro-eval/tests/data/quadrants-exif6.heic");
    std::fs::copy(fixture, photos.join("IMG_0001.HEIC")).unwrap();
    let img = image::RgbImage::from_fn(20, 10, |x, y| image::Rgb([(x * 12) as u8, (y * 20) as u8, 120]));
    std::fs::write(photos.join("IMG_0002.JPG"), sideways_jpeg(&img).1).unwrap();
    image::RgbImage::from_fn(12, 8, |x, y| image::Rgb([90, (x * 20) as u8, (y * 30) as u8]))
        .save(photos.join("IMG_0003.webp"))
        .unwrap();
    std::fs::write(photos.join("IMG_0002.xmp"), b"<x:xmpmeta/>").unwrap();
    std::fs::write(photos.join("notes.txt"), b"holiday").unwrap();
    let out = dir.path().join("out");
    // --allow-grey: the HEIC fixture's five flat colours each sit at a brightness of their
    // own, which the grey measure rightly calls a function of brightness.
    let run = campro()
        .arg("simulate")
        .arg("campro-omega-0.5")
        .arg(&photos)
        .arg("-o")
        .arg(&out)
        .arg("--allow-grey")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    let jpeg = image::open(out.join("IMG_0002.JPG")).unwrap_or_else(|e| panic!("{e}: {err}"));
    assert_eq!((jpeg.width(), jpeg.height()), (10, 20), "turned by its EXIF orientation");
    assert_eq!(image::open(out.join("IMG_0003.webp")).unwrap().width(), 12);
    for side in ["IMG_0002.xmp", "notes.txt"] {
        assert!(err.contains(&format!("skipping {}", photos.join(side).display())), "{err}");
        assert!(!out.join(side).exists());
    }
    if campro_eval::heif::available() {
        let img = image::open(out.join("IMG_0001.jpg")).unwrap_or_else(|e| panic!("{e}: {err}"));
        assert_eq!((img.width(), img.height()), (48, 64), "upright, as the rotation says");
        assert!(!err.contains("libheif"), "{err}");
    } else {
        assert!(std::env::var("CI").as_deref() != Ok("true"), "CI=true but libheif is missing");
        assert!(err.contains("IMG_0001.HEIC: HEIC needs the system's libheif"), "{err}");
        assert!(!out.join("IMG_0001.jpg").exists());
    }
}

/// A WebP photo is read and written back as a lossless WebP: its pixels are the camera's
/// output of the same picture given as a PNG (both lossless, so every code must match).
#[test]
fn a_webp_photo_stays_a_lossless_webp_with_the_cameras_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let img =
        image::RgbImage::from_fn(24, 16, |x, y| image::Rgb([(x * 10) as u8, (y * 15) as u8, ((x + y) * 5) as u8]));
    let (webp, png) = (dir.path().join("w/p.webp"), dir.path().join("p/p.png"));
    for f in [&webp, &png] {
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
    }
    let mut bytes = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut bytes)
        .encode(img.as_raw(), 24, 16, image::ExtendedColorType::Rgb8)
        .unwrap();
    std::fs::write(&webp, bytes).unwrap();
    img.save(&png).unwrap();
    for (input, out) in [(&webp, "ow"), (&png, "op")] {
        campro()
            .arg("simulate")
            .arg(bundled("campro-omega-0.5.json"))
            .arg(input.parent().unwrap())
            .arg("-o")
            .arg(dir.path().join(out))
            .assert()
            .success();
    }
    let written = dir.path().join("ow/p.webp");
    assert_eq!(image::ImageFormat::from_path(&written).unwrap(), image::ImageFormat::WebP);
    let from_webp = image::open(&written).unwrap().into_rgb8();
    let from_png = image::open(dir.path().join("op/p.png")).unwrap().into_rgb8();
    assert_eq!(from_webp, from_png);
    assert_ne!(from_webp, img, "the camera changed nothing");
}

/// The EXIF fields of an image file's block, as (tag, value) text; none without a block.
fn exif_fields(path: &Path) -> Vec<(String, String)> {
    use image::ImageDecoder;
    let bytes = std::fs::read(path).unwrap();
    let mut d =
        image::ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format().unwrap().into_decoder().unwrap();
    let Some(block) = d.exif_metadata().unwrap() else { return Vec::new() };
    let e = exif::Reader::new().read_raw(block).unwrap();
    e.fields().map(|f| (f.tag.to_string(), f.display_value().to_string())).collect()
}

/// A phone's JPEG with the date, the camera, GPS, a serial number, a maker note and
/// orientation 6: by default the output keeps date and camera, drops the rest and says
/// orientation 1; `--metadata keep` keeps GPS too (never the maker note); `strip` nothing.
/// The colour profile travels with keep-safe and keep.
#[test]
fn metadata_policy_keeps_the_date_and_camera_and_drops_gps() {
    use exif::{Field, In, Tag, Value};
    use image::ImageEncoder;
    let dir = tempfile::tempdir().unwrap();
    let fields = [
        Field { tag: Tag::Make, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"Phone".to_vec()]) },
        Field { tag: Tag::Model, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"X1".to_vec()]) },
        Field { tag: Tag::Orientation, ifd_num: In::PRIMARY, value: Value::Short(vec![6]) },
        Field {
            tag: Tag::DateTimeOriginal,
            ifd_num: In::PRIMARY,
            value: Value::Ascii(vec![b"2026:12:06 09:00:00".to_vec()]),
        },
        Field { tag: Tag::BodySerialNumber, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"SN123".to_vec()]) },
        Field { tag: Tag::MakerNote, ifd_num: In::PRIMARY, value: Value::Undefined(vec![7; 40], 0) },
        Field {
            tag: Tag::GPSLatitude,
            ifd_num: In::PRIMARY,
            value: Value::Rational(vec![(48, 1).into(), (12, 1).into(), (0, 1).into()]),
        },
    ];
    let mut w = exif::experimental::Writer::new();
    fields.iter().for_each(|f| w.push_field(f));
    let mut block = std::io::Cursor::new(Vec::new());
    w.write(&mut block, true).unwrap();
    let img = image::RgbImage::from_fn(24, 16, |x, y| image::Rgb([(x * 9) as u8, (y * 14) as u8, 90]));
    let mut jpeg = Vec::new();
    let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 95);
    enc.set_exif_metadata(block.into_inner()).unwrap();
    enc.set_icc_profile(vec![0; 128]).unwrap();
    enc.write_image(img.as_raw(), 24, 16, image::ExtendedColorType::Rgb8).unwrap();
    let input = dir.path().join("IMG_1.jpg");
    std::fs::write(&input, jpeg).unwrap();
    let run = |policy: Option<&str>, out: &str| {
        let mut c = campro();
        c.arg("simulate").arg(bundled("campro-omega-0.5.json")).arg(&input).arg("-o").arg(dir.path().join(out));
        if let Some(p) = policy {
            c.args(["--metadata", p]);
        }
        c.assert().success();
        exif_fields(&dir.path().join(out))
    };
    let has = |f: &[(String, String)], tag: &str| f.iter().any(|(t, _)| t == tag);
    let safe = run(None, "safe.jpg");
    assert!(has(&safe, "Make") && has(&safe, "Model") && has(&safe, "DateTimeOriginal"), "{safe:?}");
    for gone in ["GPSLatitude", "BodySerialNumber", "MakerNote"] {
        assert!(!has(&safe, gone), "{gone} kept: {safe:?}");
    }
    assert!(safe.iter().any(|(t, v)| t == "Orientation" && v.contains("row 0 at top")), "{safe:?}");
    // The pixels were turned: 16 wide, 24 tall.
    assert_eq!(image::image_dimensions(dir.path().join("safe.jpg")).unwrap(), (16, 24));
    let keep = run(Some("keep"), "keep.jpg");
    assert!(has(&keep, "GPSLatitude") && has(&keep, "BodySerialNumber") && !has(&keep, "MakerNote"), "{keep:?}");
    assert!(run(Some("strip"), "strip.jpg").is_empty());
    let icc = |name: &str| {
        use image::ImageDecoder;
        let bytes = std::fs::read(dir.path().join(name)).unwrap();
        image::codecs::jpeg::JpegDecoder::new(std::io::Cursor::new(bytes)).unwrap().icc_profile().unwrap()
    };
    assert_eq!(icc("safe.jpg"), Some(vec![0; 128]));
    assert_eq!(icc("strip.jpg"), None);
}

/// A phone JPEG stored sideways with EXIF orientation 6 (turn 90° clockwise to show) comes
/// out turned: the output is as tall as the stored picture is wide, and each pixel is the
/// untagged copy's pixel at the turned place (the same decoded pixel through the camera).
#[test]
fn exif_orientation_turns_the_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (20u32, 10u32);
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        if x < w / 2 {
            image::Rgb([220, 40, 30])
        } else {
            image::Rgb([30, 60, (y * 20) as u8])
        }
    });
    let (plain, tagged) = sideways_jpeg(&img);
    let (a, b) = (dir.path().join("plain.jpg"), dir.path().join("turned.jpg"));
    std::fs::write(&a, &plain).unwrap();
    std::fs::write(&b, &tagged).unwrap();
    let out = dir.path().join("out");
    let preset = bundled("campro-omega-0.5.json");
    for (input, name) in [(&a, "plain.png"), (&b, "turned.png")] {
        let run = campro()
            .arg("simulate")
            .arg(&preset)
            .arg(input)
            .arg("-o")
            .arg(out.join(name))
            .args(["--image-format", "png"])
            .output()
            .unwrap();
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    }
    let p = image::open(out.join("plain.png")).unwrap().to_rgb8();
    let t = image::open(out.join("turned.png")).unwrap().to_rgb8();
    assert_eq!((p.width(), p.height()), (w, h));
    assert_eq!((t.width(), t.height()), (h, w), "turned: as tall as the stored picture is wide");
    // Turning 90° clockwise moves the stored (x, y) to (h - 1 - y, x).
    for y in 0..h {
        for x in 0..w {
            assert_eq!(p.get_pixel(x, y), t.get_pixel(h - 1 - y, x), "stored ({x}, {y})");
        }
    }
}

/// `--record` hashes its input file: a stream (standard input here) has none, so the run is
/// refused in one line before anything is read, rather than written without its record.
#[test]
fn a_record_of_a_stream_is_refused_not_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("live.mkv");
    fails_with(
        campro().args(["simulate", "campro-omega-0.5", "-", "-o"]).arg(&out).arg("--record").write_stdin(Vec::new()),
        "--record: a record holds its input's hash",
    );
    assert!(!out.exists());
}
