//! The real `libcampro_jni.so` through the real Kotlin wrapper on the host JVM.
//!
//! Builds the expected values with the Rust core (bundled params and the shared CamPro
//! checkpoints, identity and phone-like devices, two curve/denominator budgets, the DNG
//! colour-temperature route), compiles `android/campro/src/main/kotlin/org/campro/*.kt`
//! (the Android-free wrapper) with `jni-bridge/jvm-test/HostTest.kt`, and runs it:
//! exact equality with the core, bad input, threads, and a 10^6-update soak.
//!
//! Needs `java` and a Kotlin compiler (`$KOTLINC`, `kotlinc` on PATH, or
//! `npm ci --prefix jni-bridge/jvm-test`); skips without them unless `CI=true`.

use campro_testkit as shared;

use campro::ccm::Mat3;
use campro::color_temp::DngCalibration;
use campro::targets::camera2::{convert, matrix_from_rationals, Camera2Values, Options, RationalMode};
use campro::Params;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

const ID: [i32; 18] = [1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1];
const PHONE: [i32; 18] = [178, 100, -62, 100, -16, 100, -28, 100, 162, 100, -34, 100, 2, 100, -71, 100, 169, 100];

fn in_ci() -> bool {
    std::env::var("CI").map(|v| v == "true").unwrap_or(false)
}

fn skip(why: &str) {
    assert!(!in_ci(), "CI=true but {why}");
    eprintln!("SKIP: {why}");
}

fn runs(cmd: &Path) -> bool {
    Command::new(cmd).arg("-version").output().map(|o| o.status.success()).unwrap_or(false)
}

/// `$KOTLINC`, `kotlinc` on PATH, or npm's pinned compiler (installed here with
/// `npm ci` on first use when npm exists, so `cargo test` alone sets it up).
fn kotlinc(root: &Path) -> Option<PathBuf> {
    let npm_dir = root.join("jni-bridge/jvm-test");
    let from_npm = npm_dir.join("node_modules/kotlin-compiler/bin/kotlinc");
    let candidates =
        [std::env::var_os("KOTLINC").map(PathBuf::from), Some(PathBuf::from("kotlinc")), Some(from_npm.clone())];
    if let Some(k) = candidates.into_iter().flatten().find(|c| runs(c)) {
        return Some(k);
    }
    eprintln!("no Kotlin compiler found: npm ci --prefix {}", npm_dir.display());
    let ok = Command::new("npm")
        .args(["ci", "--no-audit", "--no-fund", "--prefix"])
        .arg(&npm_dir)
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    (ok && runs(&from_npm)).then_some(from_npm)
}

fn ints(v: &[i32]) -> String {
    v.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(" ")
}

fn write_case(out: &mut String, name: &str, params: &Path, opts: &Options, input: &str, v: &Camera2Values) {
    let den = match opts.rational {
        RationalMode::Best { max_denominator } => max_denominator,
        RationalMode::Fixed { .. } => unreachable!("the bridge uses best rationals"),
    };
    let r = &v.report;
    let report = [
        1.0,
        r.bound,
        r.matrix_max_abs,
        r.curve_max_abs,
        r.curve_lipschitz,
        v.scale,
        r.curve_points as f64,
        r.curve_simplified as u8 as f64,
        (v.tonemap_curve.red.len() / 2) as f64,
        (v.tonemap_curve.green.len() / 2) as f64,
        (v.tonemap_curve.blue.len() / 2) as f64,
    ];
    writeln!(out, "case {name}\nparams {}\nopts {} {den}\n{input}", params.display(), opts.max_curve_points).unwrap();
    writeln!(out, "transform {}", ints(&v.color_correction_transform)).unwrap();
    let t = &v.tonemap_curve;
    for (c, pairs) in [&t.red, &t.green, &t.blue].into_iter().enumerate() {
        let bits: Vec<i32> = pairs.iter().map(|f| f.to_bits() as i32).collect();
        writeln!(out, "curve {c} {}", ints(&bits)).unwrap();
    }
    let rep: Vec<String> = report.iter().map(|d| (d.to_bits() as i64).to_string()).collect();
    writeln!(out, "report {}", rep.join(" ")).unwrap();
}

/// Parameter files to test: the bundled sets and every shared checkpoint (as JSON).
fn parameter_files(root: &Path, tmp: &Path) -> Vec<(String, PathBuf)> {
    let mut files: Vec<(String, PathBuf)> = std::fs::read_dir(root.join("params"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .map(|p| (p.file_stem().unwrap().to_string_lossy().into_owned(), p))
        .collect();
    files.sort();
    if let Some(dir) = shared::shared("fixtures/campro-pt") {
        let mut pts: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "pt"))
            .collect();
        pts.sort();
        assert!(!pts.is_empty(), "no checkpoints in {}", dir.display());
        for pt in pts {
            let p = campro::import_pt::read_checkpoint(&pt).unwrap();
            let name = pt.file_stem().unwrap().to_string_lossy().into_owned();
            let json = tmp.join(format!("{name}.json"));
            std::fs::write(&json, p.to_json()).unwrap();
            files.push((name, json));
        }
    }
    // A version 2 set: a curve per channel (red inverted, green a wave, blue a root).
    let mut three = Params::from_file(&root.join("params/campro-omega-0.5.json")).unwrap();
    let (f, g, h) = (|t: f64| 1.0 - t, |t: f64| 0.5 + 0.45 * (9.0 * t).sin(), |t: f64| t.sqrt());
    three.tone_curves = campro::ToneCurves::per_channel([
        campro::ToneCurve::from_fn(32, f),
        campro::ToneCurve::from_fn(32, g),
        campro::ToneCurve::from_fn(32, h),
    ]);
    let json = tmp.join("per-channel.json");
    std::fs::write(&json, three.to_json()).unwrap();
    files.push(("per-channel".into(), json));
    files
}

fn cases(root: &Path, tmp: &Path) -> (String, usize) {
    let mut out = String::new();
    let mut n = 0;
    let fm1 = [[0.6, 0.3, 0.06], [0.25, 0.7, 0.05], [0.03, 0.1, 0.7]];
    let fm2 = [[0.65, 0.25, 0.07], [0.27, 0.68, 0.05], [0.02, 0.15, 0.65]];
    let q = |m: &Mat3| -> [i32; 18] {
        let mut v = [0; 18];
        for i in 0..9 {
            v[2 * i] = (m[i / 3][i % 3] * 10000.0).round() as i32;
            v[2 * i + 1] = 10000;
        }
        v
    };
    let (fq1, fq2) = (q(&fm1), q(&fm2));
    let cal = DngCalibration {
        illuminant1: 17,
        forward_matrix1: matrix_from_rationals(&fq1).unwrap(),
        illuminant2: 21,
        forward_matrix2: matrix_from_rationals(&fq2).unwrap(),
    };
    for (name, path) in parameter_files(root, tmp) {
        let p = Params::from_file(&path).unwrap();
        for (pts, den) in [(64usize, 1u32 << 16), (16, 1024)] {
            let opts = Options { max_curve_points: pts, rational: RationalMode::Best { max_denominator: den } };
            for (dname, dev) in [("identity", ID), ("phone", PHONE)] {
                let v = convert(&p, &matrix_from_rationals(&dev).unwrap(), &opts).unwrap();
                write_case(
                    &mut out,
                    &format!("{name}/{dname}/{pts}pts/{den}"),
                    &path,
                    &opts,
                    &format!("device {}", ints(&dev)),
                    &v,
                );
                n += 1;
            }
            let ct = 4300.0;
            let v = convert(&p, &cal.device_transform(ct).unwrap(), &opts).unwrap();
            let input = format!("dng 17 {} 21 {} {ct}", ints(&fq1), ints(&fq2));
            write_case(&mut out, &format!("{name}/dng-{ct}K/{pts}pts/{den}"), &path, &opts, &input, &v);
            n += 1;
        }
    }
    (out, n)
}

#[test]
fn kotlin_wrapper_through_jni_on_the_host_jvm() {
    let root = shared::workspace_root();
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("jvm-host");
    let java = PathBuf::from("java");
    if !runs(&java) {
        return skip("no `java` on PATH (JDK 17)");
    }
    let Some(kotlinc) = kotlinc(&root) else {
        return skip("no Kotlin compiler: run `npm ci --prefix jni-bridge/jvm-test` or set KOTLINC");
    };

    // `cargo test` links tests against the rlib only: build the .so itself, as the app
    // would (this crate alone, so the core has no desktop features), in its own target
    // folder so it does not wait on the outer cargo's lock.
    let target = tmp.join("cargo-target");
    let status = Command::new(env!("CARGO"))
        .args(["build", "--release", "--lib", "-p", "campro-jni", "--features", "test-exports", "--manifest-path"])
        .arg(root.join("Cargo.toml"))
        .arg("--target-dir")
        .arg(&target)
        .status()
        .unwrap();
    assert!(status.success(), "building libcampro_jni.so failed");
    let lib = target.join("release/libcampro_jni.so");
    assert!(lib.exists(), "{} missing after the build", lib.display());
    std::fs::create_dir_all(&tmp).unwrap();
    let (text, n) = cases(&root, &tmp);
    let cases_file = tmp.join("cases.txt");
    std::fs::write(&cases_file, text).unwrap();

    // The Android-free part of the library module, exactly as the app compiles it.
    let wrapper = root.join("android/campro/src/main/kotlin/org/campro");
    let mut sources: Vec<PathBuf> = std::fs::read_dir(&wrapper)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "kt"))
        .collect();
    sources.sort();
    // Its one annotation dependency (androidx.annotation's @GuardedBy, documentation only).
    sources.push(root.join("android/jvm-test/stubs/kotlin/androidx/annotation/GuardedBy.kt"));
    sources.push(root.join("jni-bridge/jvm-test/TestHooks.kt"));
    sources.push(root.join("jni-bridge/jvm-test/HostTest.kt"));
    let jar = tmp.join("host-test.jar");
    let out =
        Command::new(&kotlinc).args(&sources).args(["-include-runtime", "-nowarn", "-d"]).arg(&jar).output().unwrap();
    assert!(
        out.status.success(),
        "kotlinc failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );

    let soak = std::env::var("CAMPRO_JVM_SOAK").unwrap_or_else(|_| "1000000".into());
    let out = Command::new(&java)
        .arg("-Xmx256m")
        .arg(format!("-Djava.library.path={}", lib.parent().unwrap().display()))
        .arg("-cp")
        .arg(&jar)
        .arg("HostTestKt")
        .arg(&lib)
        .arg(&cases_file)
        .arg(&soak)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "host JVM test failed (see FAIL lines above)");
    assert!(stdout.contains(&format!("ALL PASSED ({n} value cases)")), "expected {n} value cases");
    assert!(!stdout.contains("FAIL "));
}
