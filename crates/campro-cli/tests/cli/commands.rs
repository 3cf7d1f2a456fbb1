//! `import-pt`, `demo`, help, completions and the manual, `stress`, `bench train`.

use super::*;

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
