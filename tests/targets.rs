//! File-based deployment targets (Raspberry Pi, Rockchip, 3D LUTs) against the real
//! reference files in ../shared/fixtures/targets and against hand-derived values.

use campro::ccm::{self, Mat3};
use campro::compare::{deployment_vs_desktop, random_pixels};
use campro::lut3d::Lut3d;
use campro::targets::cube::{parse_cube, parse_hald, CubeFile, Kind};
use campro::targets::rkaiq::Rkaiq;
use campro::targets::rpi::{self, Rpi};
use campro::targets::{Feed, Target, TargetError};
use campro::{Params, ToneCurve};
use campro_testkit::shared;

fn fixture(name: &str) -> Option<String> {
    shared(&format!("fixtures/targets/{name}")).map(|p| std::fs::read_to_string(p).unwrap())
}

fn bundled(name: &str) -> Params {
    Params::from_file(&campro_testkit::workspace_root().join(format!("params/{name}.json"))).unwrap()
}

/// A paper-like set: strong CCM, jagged (non-monotonic) curve.
fn strong() -> Params {
    let m = [[1.2101, 0.0430, -0.6679], [-1.3933, 1.1114, 0.2755], [0.2930, -0.3570, 1.3287]];
    Params::new(m, ToneCurve::from_fn(32, |t| (5.0 * t).sin() * 0.45 + 0.5), 2.2).unwrap()
}

/// |device - desktop| bound for an ISP that applies `mq` (ideal `m`) and curve `hw`
/// (ideal `ideal`), for sensor RGB synthesised through `device^-1` from [0,1]^3.
fn isp_bound(hw: &ToneCurve, ideal: &ToneCurve, mq: &Mat3, m: &Mat3, device: &Mat3) -> f64 {
    let inv = ccm::inverse(device).unwrap();
    let range = inv.map(|r| r.iter().map(|v| v.abs()).sum::<f64>());
    // Curve difference on a fine grid plus every knot of both (exact for piecewise-linear).
    let curve_diff = (0..=65535)
        .map(|i| i as f64 / 65535.0)
        .chain(hw.x().iter().copied())
        .chain(ideal.x().iter().copied())
        .map(|t| (hw.eval(t) - ideal.eval(t)).abs())
        .fold(0.0, f64::max);
    campro::emulate::error_bound([curve_diff; 3], [hw.max_slope(); 3], mq, m, range) + 1e-9
}

#[test]
fn rpi_export_patches_only_ccm_and_gamma_and_parses_back() {
    for (t, file) in [(Rpi::Vc4, "rpi_vc4_imx219.json"), (Rpi::Pisp, "rpi_pisp_imx219.json")] {
        let Some(base) = fixture(file) else { return };
        let p = strong();
        let out = t.export(&p, Some(&base)).unwrap();
        let (root, tuning) = rpi::parse(std::str::from_utf8(&out).unwrap(), "export").unwrap();
        let (base_root, base_tuning) = rpi::parse(&base, file).unwrap();
        assert_eq!(tuning.ce_enable, Some(0));
        assert_eq!(tuning.ccms.len(), base_tuning.ccms.len());
        for ((ct, m), (bct, bm)) in tuning.ccms.iter().zip(&base_tuning.ccms) {
            assert_eq!(ct, bct);
            // Hand-composed entry (0,0): Σ_k CCM[0][k] · M[k][0].
            let want = (0..3).map(|k| p.ccm[0][k] * bm[k][0]).sum::<f64>();
            assert!((m[0][0] - want).abs() < 1e-12, "{ct}: {} vs {want}", m[0][0]);
        }
        // Gamma: CamPro knots on 0..65535.
        assert_eq!(tuning.gamma.len(), 32);
        assert_eq!(tuning.gamma[31], (65535.0, (p.tone_curves.channel(0).y()[31] * 65535.0).round()));
        assert_eq!(tuning.gamma[1].0, (65535.0f64 / 31.0).round());
        // Every other algorithm block is untouched.
        let others = |r: &serde_json::Value| {
            r["algorithms"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|a| a.get("rpi.ccm").is_none() && a.get("rpi.contrast").is_none())
                .cloned()
                .collect::<Vec<_>>()
        };
        assert_eq!(others(&root), others(&base_root), "{file}");
        assert_eq!(root["target"], base_root["target"]);
    }
}

#[test]
fn rpi_hardware_curves_by_hand() {
    // VC4 forces (65535, 65535): a curve ending at 0.5 comes out ending at 1.
    let half = ToneCurve::from_fn(2, |t| 0.5 * t);
    let vc4 = Rpi::Vc4.hardware_curve(&half);
    assert_eq!(vc4.len(), 33);
    assert_eq!(vc4.eval(1.0), 1.0);
    // At x = 1024 the sample is floor(0.5 · 1024) = 512.
    assert_eq!(vc4.eval(1024.0 / 65535.0), 512.0 / 65535.0);
    // PiSP: a decreasing curve disables gamma (identity).
    let inv = ToneCurve::from_fn(2, |t| 1.0 - t);
    let pisp = Rpi::Pisp.hardware_curve(&inv);
    assert_eq!(pisp.eval(0.25), 0.25);
    // PiSP slope cap: a jump from 0 to 1 right after x = 0 rises at most 16383 per segment.
    let jump = ToneCurve::new(vec![0.0, 1.0 / 65535.0, 1.0], vec![0.0, 1.0, 1.0]).unwrap();
    let pisp = Rpi::Pisp.hardware_curve(&jump);
    assert_eq!(pisp.eval(512.0 / 65535.0), 16383.0 / 65535.0);
    assert_eq!(pisp.eval(1024.0 / 65535.0), 32766.0 / 65535.0);
    // The last LUT entry (63488) has no slope: flat to the end.
    assert_eq!(pisp.eval(1.0), pisp.eval(63488.0 / 65535.0));
    // The curve error report agrees: VC4 cannot hold y(1) = 0.5.
    assert!((rpi::curve_error(Rpi::Vc4, &half) - 0.5).abs() < 1e-12);
}

#[test]
fn rpi_matrices_are_quantised_and_clamped() {
    let Some(base) = fixture("rpi_pisp_imx219.json") else { return };
    let mut p = strong();
    p.ccm = [[4.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let f = Rpi::Pisp.format().matrix.unwrap();
    assert_eq!(f.quantize(100.0), 8.0 - 1.0 / 1024.0);
    assert_eq!(f.quantize(-100.0), -8.0);
    assert_eq!(f.quantize(0.30), (0.30f64 * 1024.0).round() / 1024.0);
    let v = Rpi::Vc4.format().matrix.unwrap();
    assert_eq!(v.quantize(1.23456), 1.235);
    // 4 · 2.12 > 8: refused by name, unless clamping is asked for; then the clamp is
    // listed and the measured error is large for bright reds.
    let e = Rpi::Pisp.export(&p, Some(&base)).unwrap_err().to_string();
    assert!(
        e.contains("rpi.ccm.ccms[0].ccm[0]") && e.contains("outside the ISP's range") && e.contains("--clamp"),
        "{e}"
    );
    let (out, clamped) = Rpi::Pisp.export_clamped(&p, Some(&base)).unwrap();
    assert!(!clamped.is_empty() && clamped.iter().all(|c| c.ends_with("clamped")), "{clamped:?}");
    let conds = Rpi::Pisp.emulate(&p, &out, Some(&base)).unwrap();
    let s = deployment_vs_desktop(&p, &conds[0].feed, conds[0].emulator.as_ref(), &[[255, 40, 40]]).unwrap();
    assert!(s.max_lsb() > 1.0, "{}", s.max_lsb());
    // A VC4 file is not a PiSP base (and the other way round).
    let Some(vc4) = fixture("rpi_vc4_imx219.json") else { return };
    let e = Rpi::Pisp.export(&bundled("identity"), Some(&vc4)).unwrap_err().to_string();
    assert!(e.contains("target") && e.contains("bcm2835") && e.contains("\"pisp\""), "{e}");
    let e = Rpi::Vc4.export(&bundled("identity"), Some(&base)).unwrap_err().to_string();
    assert!(e.contains("needs a \"bcm2835\" tuning file"), "{e}");
}

#[test]
fn isp_targets_stay_within_their_stated_bound() {
    let px = random_pixels(5000, 3);
    let targets: Vec<(Box<dyn Target>, &str)> = vec![
        (Box::new(Rpi::Vc4), "rpi_vc4_imx219.json"),
        (Box::new(Rpi::Pisp), "rpi_pisp_imx219.json"),
        (Box::new(Rkaiq::Isp20), "rkaiq_isp20_imx415_ccm_gamma_excerpt.json"),
        (Box::new(Rkaiq::Isp3x), "rkaiq_isp3x_imx415_ccm_gamma_excerpt.json"),
    ];
    for (t, file) in targets {
        let Some(base) = fixture(file) else { return };
        for p in [bundled("identity"), bundled("srgb-passthrough"), strong()] {
            let out = t.export(&p, Some(&base)).unwrap();
            let conds = t.emulate(&p, &out, Some(&base)).unwrap();
            assert!(!conds.is_empty());
            for c in &conds {
                let Feed::Sensor(device) = c.feed else { panic!("ISP targets take sensor RGB") };
                let m = ccm::mul(&p.ccm, &device);
                let fmt = t.format().matrix.unwrap();
                let hw = match t.name() {
                    "rpi-vc4" | "rpi-pisp" => {
                        let r = if t.name() == "rpi-vc4" { Rpi::Vc4 } else { Rpi::Pisp };
                        let pts: Vec<(f64, f64)> = p
                            .tone_curves
                            .channel(0)
                            .x()
                            .iter()
                            .zip(p.tone_curves.channel(0).y())
                            .map(|(x, y)| ((x * 65535.0).round() / 65535.0, (y * 65535.0).round() / 65535.0))
                            .collect();
                        r.hardware_curve(
                            &ToneCurve::new(pts.iter().map(|p| p.0).collect(), pts.iter().map(|p| p.1).collect())
                                .unwrap(),
                        )
                    }
                    "rkaiq-isp20" => Rkaiq::Isp20.hardware_curve(p.tone_curves.channel(0)),
                    _ => Rkaiq::Isp3x.hardware_curve(p.tone_curves.channel(0)),
                };
                let bound = isp_bound(&hw, p.tone_curves.channel(0), &fmt.apply(&m), &m, &device);
                let s = deployment_vs_desktop(&p, &c.feed, c.emulator.as_ref(), &px).unwrap();
                assert!(s.max_abs <= bound, "{} {} {}: {} > bound {}", t.name(), p.name, c.label, s.max_abs, bound);
            }
        }
    }
}

#[test]
fn rkaiq_grids_and_export() {
    let g20 = Rkaiq::Isp20.grid();
    let g3x = Rkaiq::Isp3x.grid();
    assert_eq!(g20.len(), 45);
    assert_eq!(g3x.len(), 49);
    assert_eq!(&g20[..14], &[0., 1., 2., 3., 4., 5., 6., 7., 8., 10., 12., 14., 16., 20.]);
    assert_eq!(&g20[40..], &[2048., 2560., 3072., 3584., 4095.]);
    assert_eq!(&g3x[40..], &[2048., 2304., 2560., 2816., 3072., 3328., 3584., 3840., 4095.]);
    for (t, file, curves) in [
        (Rkaiq::Isp20, "rkaiq_isp20_imx415_ccm_gamma_excerpt.json", 5),
        (Rkaiq::Isp3x, "rkaiq_isp3x_imx415_ccm_gamma_excerpt.json", 1),
    ] {
        let Some(base) = fixture(file) else { return };
        let (_, theirs) = t.parse(&base, file).unwrap();
        assert_eq!(theirs.curves.len(), curves, "{file}");
        assert!(theirs.matrices.len() >= 10, "{file}: {} matrices", theirs.matrices.len());
        let p = strong();
        let out = t.export(&p, Some(&base)).unwrap();
        let (_, ours) = t.parse(std::str::from_utf8(&out).unwrap(), "export").unwrap();
        let grid = t.grid();
        for (_, y) in &ours.curves {
            for (x, v) in grid.iter().zip(y) {
                assert_eq!(*v, (p.tone_curves.channel(0).eval(x / 4095.0) * 4095.0).round());
            }
        }
        for ((name, _, m), (bname, _, bm)) in ours.matrices.iter().zip(&theirs.matrices) {
            assert_eq!(name, bname);
            let want = ccm::mul(&p.ccm, bm);
            for i in 0..3 {
                for j in 0..3 {
                    assert!((m[i][j] - want[i][j]).abs() <= 5e-7, "{name}: written with 6 decimals");
                }
            }
        }
    }
}

#[test]
fn single_curve_stacks_refuse_a_curve_per_channel_and_luts_hold_it() {
    let mut p = strong();
    let c = p.tone_curves.channel(0).clone();
    p.tone_curves = campro::ToneCurves::per_channel([c.clone(), ToneCurve::from_fn(32, |t| 1.0 - t), c]);
    if let Some(base) = fixture("rpi_pisp_imx219.json") {
        let e = Rpi::Pisp.export(&p, Some(&base)).unwrap_err().to_string();
        assert!(e.contains("one gamma curve") && e.contains("a curve per channel"), "{e}");
    }
    if let Some(base) = fixture("rkaiq_isp3x_imx415_ccm_gamma_excerpt.json") {
        let e = Rkaiq::Isp3x.export(&p, Some(&base)).unwrap_err().to_string();
        assert!(e.contains("a curve per channel"), "{e}");
    }
    // A 3D LUT is any colour map: within the baked LUT's Lipschitz bound (the steepest
    // channel's slope), plus the file's 6 decimals and 8-bit rounding.
    let t = CubeFile { kind: Kind::Cube, size: 33 };
    let text = t.export(&p, None).unwrap();
    let conds = t.emulate(&p, &text, None).unwrap();
    let bound = Lut3d::bake(&p, 33).error_bound() * 255.0;
    let px = random_pixels(5000, 4);
    for c in &conds {
        let s = deployment_vs_desktop(&p, &c.feed, c.emulator.as_ref(), &px).unwrap();
        assert!(s.max_lsb() <= bound + 0.51, "{}: {} > {bound} + 0.51", c.label, s.max_lsb());
    }
}

#[test]
fn cube_and_hald_parse_back_and_errors_shrink_with_size() {
    let p = strong();
    let px = random_pixels(20_000, 8);
    let mut prev = f64::INFINITY;
    for n in [17, 33, 65] {
        let t = CubeFile { kind: Kind::Cube, size: n };
        let text = t.export(&p, None).unwrap();
        let text = std::str::from_utf8(&text).unwrap();
        assert!(text.lines().any(|l| l == format!("LUT_3D_SIZE {n}")));
        let lut = parse_cube(text).unwrap();
        let baked = Lut3d::bake(&p, n);
        let worst = lut
            .data()
            .iter()
            .zip(baked.data())
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0f32, f32::max);
        assert!(worst <= 5.1e-7, "{n}: {worst}");
        // Red fastest: the second node is (r = 1 step, g = 0, b = 0).
        let second = campro::pipeline::process_f64(&p, [1.0 / (n - 1) as f64, 0.0, 0.0]);
        assert!((lut.data()[1][0] as f64 - second[0]).abs() < 1e-6);
        let conds = t.emulate(&p, text.as_bytes(), None).unwrap();
        assert_eq!(conds.len(), 2);
        let mut here = 0f64;
        for c in &conds {
            let s = deployment_vs_desktop(&p, &c.feed, c.emulator.as_ref(), &px).unwrap();
            assert!(
                s.max_abs <= baked.error_bound() + 1e-6,
                "{n} {}: {} > {}",
                c.label,
                s.max_abs,
                baked.error_bound()
            );
            here = here.max(s.max_abs);
        }
        assert!(here < prev, "error did not shrink at {n}: {here} vs {prev}");
        prev = here;
    }
    let h = CubeFile::hald(4);
    let img = h.export(&p, None).unwrap();
    assert!(img.starts_with(b"P6\n64 64\n65535\n"));
    let lut = parse_hald(&img).unwrap();
    assert_eq!(lut.size(), 16);
    let baked = Lut3d::bake(&p, 16);
    let worst = lut
        .data()
        .iter()
        .zip(baked.data())
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k].clamp(0.0, 1.0)).abs()))
        .fold(0f32, f32::max);
    assert!(worst <= 0.5 / 65535.0 + 1e-7, "{worst}");
}

#[test]
fn malformed_files_name_the_field() {
    let cases: [(&str, &str); 5] = [
        ("TITLE \"x\"\n0 0 0\n", "LUT_3D_SIZE must come before"),
        ("LUT_3D_SIZE 2\n0 0 0\n", "LUT entries: must have 2^3 = 8 entries, got 1"),
        ("LUT_3D_SIZE 300\n", "LUT_3D_SIZE must be in 2..=256"),
        ("LUT_3D_SIZE 2\n0 0 nan\n", "line 2: values must be finite"),
        ("LUT_3D_SIZE 2\nDOMAIN_MAX 2 2 2\n", "DOMAIN_MAX must be 1 1 1"),
    ];
    for (text, want) in cases {
        let e = parse_cube(text).unwrap_err().to_string();
        assert!(e.contains(want), "{text:?}: {e}");
    }
    assert!(parse_hald(b"P6\n10 10\n255\n").unwrap_err().to_string().contains("Hald level"));
    assert!(parse_hald(b"P6\n8 8\n255\n\x00").unwrap_err().to_string().contains("length"));
    let bad_ct = r#"{"algorithms":[{"rpi.ccm":{"ccms":[{"ct":5000,"ccm":[1,0,0,0,1,0,0,0,1]},{"ct":4000,"ccm":[1,0,0,0,1,0,0,0,1]}]}},{"rpi.contrast":{"gamma_curve":[0,0,65535,65535]}}]}"#;
    let e = rpi::parse(bad_ct, "t.json").unwrap_err().to_string();
    assert!(e.contains("rpi.ccm.ccms[1].ct") && e.contains("strictly increasing"), "{e}");
    let bad_gamma = bad_ct.replace("\"ct\":4000", "\"ct\":6000").replace("[0,0,65535,65535]", "[0,0,65535]");
    let e = rpi::parse(&bad_gamma, "t.json").unwrap_err().to_string();
    assert!(e.contains("gamma_curve") && e.contains("pairs"), "{e}");
    let short = r#"{"ccMatrix":[1,0,0,0,1,0,0,0,1],"Gamma_curve":[0,4095]}"#;
    let e = Rkaiq::Isp3x.parse(short, "iq.json").unwrap_err().to_string();
    assert!(e.contains("/Gamma_curve") && e.contains("49 values"), "{e}");
    assert!(matches!(Rpi::Vc4.export(&strong(), None), Err(TargetError::NeedsBase { .. })));
}

#[test]
fn scalar_gamma_stacks_are_refused_with_the_lut_route() {
    for name in ["rkisp1", "simple", "uvc"] {
        let why = campro::targets::refusal(name).unwrap();
        assert!(why.contains("scalar gamma") && why.contains("--target cube"), "{why}");
    }
    assert!(campro::targets::refusal("rpi-vc4").is_none());
    // The rkisp1 tuning file indeed carries no curve (and no CCM) to patch.
    if let Some(p) = shared("fixtures/targets/rkisp1_imx219.yaml") {
        let text = std::fs::read_to_string(p).unwrap();
        assert!(!text.contains("Goc") && !text.contains("gamma"), "the reference rkisp1 file changed");
    }
}
