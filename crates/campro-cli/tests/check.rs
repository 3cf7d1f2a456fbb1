//! `campro check` on held-out LFW photos: presets that do not protect are said to, a learnt
//! preset hides the faces as captured, and every kind of photo (no face, grey-scale, a
//! hostile person name) gets its own line and a page whose images all open.

mod common;
use common::{bundled, campro, fails_with};
use serde_json::Value;
use std::path::{Path, PathBuf};

const FACES: [&str; 4] = [
    "data/lfw/images_deepfunneled/Ben_Affleck/Ben_Affleck_0001.jpg",
    "data/lfw/images_deepfunneled/Ben_Affleck/Ben_Affleck_0002.jpg",
    "data/lfw/images_deepfunneled/Sophia_Loren/Sophia_Loren_0002.jpg",
    "data/lfw/images_deepfunneled/Sophia_Loren/Sophia_Loren_0003.jpg",
];

fn shared() -> Option<PathBuf> {
    let mut needs =
        vec!["models/yunet_s_640_640.onnx", "models/faceplugin_fr_feature.onnx", "models/mobilefacenet_casia.onnx"];
    needs.extend(FACES);
    campro_testkit::shared_root(&needs)
}

/// Two persons' folders (Ben, Sophia; two held-out photos each) under `dir`.
fn persons(shared: &Path, dir: &Path) -> PathBuf {
    let root = dir.join("photos");
    for (k, f) in FACES.iter().enumerate() {
        let person = root.join(if k < 2 { "Ben" } else { "Sophia" });
        std::fs::create_dir_all(&person).unwrap();
        std::fs::copy(shared.join(f), person.join(Path::new(f).file_name().unwrap())).unwrap();
    }
    root
}

/// The flags of a quick check: the shared data, the captured view alone, no distractors.
fn captured_only(shared: &Path) -> [&std::ffi::OsStr; 6] {
    [
        "--shared".as_ref(),
        shared.as_os_str(),
        "--view".as_ref(),
        "captured".as_ref(),
        "--distractors".as_ref(),
        "0".as_ref(),
    ]
}

fn json_run(args: &[&std::ffi::OsStr]) -> (Option<i32>, Value, String) {
    let out = campro().args(args).args(["--format", "json"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!err.contains("panicked"), "{err}");
    let v: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {err}"));
    (out.status.code(), v, err)
}

#[test]
fn presets_that_do_not_protect_are_said_to() {
    let Some(shared) = shared() else { return };
    let dir = tempfile::tempdir().unwrap();
    let photos = persons(&shared, dir.path());
    for preset in ["identity.json", "srgb-passthrough.json"] {
        let params = bundled(preset);
        let (code, v, err) = json_run(&[
            "check".as_ref(),
            params.as_os_str(),
            "--people".as_ref(),
            photos.as_os_str(),
            "--shared".as_ref(),
            shared.as_os_str(),
            "--view".as_ref(),
            "captured".as_ref(),
            "--distractors".as_ref(),
            "5".as_ref(),
            "--fail-above".as_ref(),
            "1e-3".as_ref(),
        ]);
        let s = &v["summary"];
        let faces = s["faces"].as_u64().unwrap() - s["at_edge"].as_u64().unwrap();
        assert!(faces >= 4, "{preset}: {v}");
        // Every face is linkable by its own raw photo, and the exit status says so.
        assert_eq!(s["linkable"][0].as_u64().unwrap(), faces, "{preset}: {s}");
        assert_eq!(code, Some(3), "{preset}: {err}");
        // The person is found first among the persons and the distractors.
        assert_eq!(s["worst_rank"], 1, "{preset}");
        assert!(v["gallery"].as_u64().unwrap() >= 2 + 5, "two persons and five distractors at least: {}", v["gallery"]);
    }
}

/// Every `src="..."` of an HTML page.
fn sources(html: &str) -> Vec<String> {
    html.split("src=\"").skip(1).map(|r| r[..r.find('"').unwrap()].to_string()).collect()
}

#[test]
fn a_learnt_preset_hides_faces_as_captured_and_every_photo_gets_its_line() {
    let Some(shared) = shared() else { return };
    let dir = tempfile::tempdir().unwrap();
    let photos = persons(&shared, dir.path());
    // A loose grey-scale face and a photo without a face beside the persons.
    let loose = dir.path().join("loose");
    std::fs::create_dir_all(&loose).unwrap();
    let face = image::open(shared.join(FACES[0])).unwrap().grayscale().to_rgb8();
    face.save(loose.join("grey.png")).unwrap();
    image::RgbImage::from_fn(160, 120, |x, y| image::Rgb([(x * 3 % 256) as u8, (y * 5 % 256) as u8, 90]))
        .save(loose.join("no face.png"))
        .unwrap();
    // A person named like markup: shown, never run.
    let hostile = "<b>x</b>\"&";
    let out = dir.path().join("report");
    let params = bundled("campro-omega-0.5-hour.json");
    let sophia = photos.join("Sophia");
    let run = campro()
        .arg("check")
        .arg(&params)
        .arg(photos.join("Ben"))
        .arg(&loose)
        .arg("--person")
        .arg(format!("{hostile}={}", sophia.display()))
        .arg("--shared")
        .arg(&shared)
        .args(["--distractors", "10", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    let text = String::from_utf8_lossy(&run.stdout);
    let line = |needle: &str| {
        text.lines().find(|l| l.contains(needle)).unwrap_or_else(|| panic!("no line with {needle:?}: {text}"))
    };
    assert!(line("no face.png").ends_with("no face found"), "{text}");
    assert!(line("grey.png").contains("grey-scale photo"), "{text}");
    assert!(line("Sophia_Loren_0002").contains("(<b>x</b>\"&)"), "{text}");
    assert!(text.lines().last().unwrap().contains("faces linkable at FAR 1e-3"), "{text}");
    assert!(text.lines().last().unwrap().contains("(chance 1 in "), "{text}");

    let v: Value = serde_json::from_slice(&std::fs::read(out.join("check.json")).unwrap()).unwrap();
    // The first line is the plain verdict, the same as the JSON's; the grey photo is set apart
    // when the preset is not rated for grey (simulate refuses it), counted otherwise.
    let first = text.lines().next().unwrap();
    assert_eq!(first, v["verdict"].as_str().unwrap());
    assert!(first.contains("could be matched to") && first.contains("Ranks are out of"), "{first}");
    let rated = std::fs::read_to_string(&params).unwrap().contains("\"rated\": true");
    assert_eq!(first.contains("1 black-and-white photo ("), !rated, "{first}");
    assert_eq!(v["verdict_counts"]["grey_photos_refused"].as_u64().unwrap(), u64::from(!rated));
    let views: Vec<&str> = v["views"].as_array().unwrap().iter().map(|x| x.as_str().unwrap()).collect();
    assert_eq!(views, ["captured", "enhanced", "restored"], "the preset ships an enhancer, no restorer");
    let models = v["models"].as_array().unwrap().len();
    let photos_v = v["photos"].as_array().unwrap();
    assert_eq!(photos_v.len(), 6);
    // As captured, no colour face is linkable at FAR 1e-3 by either model.
    let mut rows = 0;
    for p in photos_v {
        let grey = p["grey"].as_bool().unwrap();
        assert_eq!(grey, p["path"].as_str().unwrap().ends_with("grey.png"));
        for f in p["faces"].as_array().unwrap() {
            rows += f["views"].as_array().unwrap().len() * models;
            if grey || f["at_edge"].as_bool().unwrap() {
                continue;
            }
            let captured = &f["views"][0];
            for (s, t) in captured["similarity"].as_array().unwrap().iter().zip(v["models"].as_array().unwrap()) {
                assert!(s.as_f64().unwrap() <= t["thresholds"]["far_1e-3"].as_f64().unwrap(), "{}: {s}", p["path"]);
            }
        }
    }
    let csv = std::fs::read_to_string(out.join("check.csv")).unwrap();
    assert!(csv.starts_with("photo,person,face,view,model,similarity,threshold_far_1e-3"), "{csv}");
    assert_eq!(csv.lines().count(), 1 + rows);

    // The page: the name escaped, every image present in the report folder.
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("&lt;b&gt;x&lt;/b&gt;&quot;&amp;") && !html.contains(hostile), "name not escaped");
    assert!(
        html.contains("<p id=\"verdict\"><strong>") && html.contains("<p id=\"one-story\">inspect and check"),
        "verdict and one story"
    );
    let srcs = sources(&html);
    assert_eq!(
        srcs.len(),
        2 * (rows / models + v["summary"]["faces"].as_u64().unwrap() as usize),
        "a raw crop per face and one per view, each in its figure and in the face's lightbox"
    );
    for s in &srcs {
        assert!(!s.contains("..") && !s.starts_with('/'), "{s}");
        let file = out.join(percent_encoding::percent_decode_str(s).decode_utf8().unwrap().as_ref());
        let img = image::open(&file).unwrap_or_else(|e| panic!("{s}: {e}"));
        assert_eq!(img.width(), 112, "{s}: the first model's crop");
    }
    // In a real browser: every image loads, and the hostile name made no element.
    if let Some(browser) = common::browser() {
        let seen = common::open_in_browser(browser, &out.join("index.html"));
        assert!(
            seen.starts_with(&format!("RESULT images={} broken=0 scripts=0 bold=0 title=campro check", srcs.len())),
            "{seen}"
        );
    }
}

#[test]
fn bad_check_arguments_get_one_line() {
    let params = bundled("campro-omega-0.5.json");
    fails_with(campro().arg("check").arg(&params).args(["--person", "nobody"]), "--person");
    fails_with(campro().arg("check").arg(&params).args(["x.jpg", "--fail-above", "0.5"]), "must be 1e-3 or 1e-2");
    // The report never goes into a photo folder, --force or not: the next run would take its
    // crops as a person's photos.
    let photos = tempfile::tempdir().unwrap();
    std::fs::create_dir(photos.path().join("ann")).unwrap();
    for out in [photos.path().to_path_buf(), photos.path().join("report"), photos.path().join("ann/../x")] {
        fails_with(
            campro().arg("check").arg(&params).arg(photos.path()).arg("-o").arg(&out).arg("--force"),
            "is inside the photo folder",
        );
    }
    // Nor into a --people or --person folder.
    fails_with(
        campro().arg("check").arg(&params).arg("--people").arg(photos.path()).arg("-o").arg(photos.path().join("r")),
        "is inside the photo folder",
    );
    fails_with(
        campro()
            .arg("check")
            .arg(&params)
            .arg("--person")
            .arg(format!("ann={}", photos.path().join("ann").display()))
            .arg("-o")
            .arg(photos.path().join("ann/r")),
        "is inside the photo folder",
    );
    // --people is a folder of people's folders.
    let file = photos.path().join("ann/x.jpg");
    std::fs::write(&file, b"x").unwrap();
    fails_with(campro().arg("check").arg(&params).arg("--people").arg(&file), "--people");
    let Some(shared) = shared() else { return };
    // A folder given plainly is never taken for persons (events and years are folders too);
    // a --people folder's subfolders are.
    let trip = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(trip.path().join("2024")).unwrap();
    std::fs::copy(shared.join(FACES[0]), trip.path().join("2024/a.jpg")).unwrap();
    for (flag, person) in [(None, Value::Null), (Some("--people"), Value::from("2024"))] {
        let mut args: Vec<&std::ffi::OsStr> = vec!["check".as_ref(), params.as_os_str()];
        args.extend(flag.map(std::ffi::OsStr::new));
        args.push(trip.path().as_os_str());
        args.extend(captured_only(&shared));
        let (_, v, err) = json_run(&args);
        assert_eq!(v["photos"][0]["person"], person, "{flag:?}: {err}");
    }
    // A face model whose manifest has no thresholds is named, with the command that calibrates it.
    let dir = tempfile::tempdir().unwrap();
    let manifest = dir.path().join("mine.json");
    let model = shared.join("models/faceplugin_fr_feature.onnx");
    std::fs::write(
        &manifest,
        serde_json::json!({
            "name": "mine", "file": model,
            "input": { "width": 112, "height": 112, "channels": "rgb", "mean": [127, 127, 127], "std": [128, 128, 128] },
            "task": { "kind": "face_embedder", "output": "output",
                      "template": [[38.2946, 51.6963], [73.5318, 51.5014], [56.0252, 71.7366], [41.5493, 92.3655], [70.7299, 92.2041]] }
        })
        .to_string(),
    )
    .unwrap();
    fails_with(
        campro()
            .arg("check")
            .arg(&params)
            .arg(shared.join(FACES[0]))
            .arg("--shared")
            .arg(&shared)
            .arg("--face-model")
            .arg(&manifest),
        "campro eval thresholds",
    );
}

#[test]
fn a_record_beside_each_output_verifies_the_output_and_its_raw_input() {
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("raw.png");
    image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([(x * 4) as u8, (y * 5) as u8, ((x + y) * 2) as u8]))
        .save(&raw)
        .unwrap();
    let out = dir.path().join("out.png");
    let run =
        campro().args(["simulate", "campro-omega-0.5"]).arg(&raw).arg("-o").arg(&out).arg("--record").output().unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let record = dir.path().join("out.png.campro.json");
    let r: Value = serde_json::from_slice(&std::fs::read(&record).unwrap()).unwrap();
    assert_eq!(r["preset"]["name"], "campro-omega-0.5");
    assert_eq!(r["path"], "camera");
    assert_eq!(r["bound_lsb"], 0.5);
    // The preset's hash is that of its bundled JSON (the same bytes as params/).
    let bytes = std::fs::read(bundled("campro-omega-0.5.json")).unwrap();
    use sha2::Digest;
    let hex: String = sha2::Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(r["preset"]["sha256"], hex.as_str());
    let hex_of = |p: &Path| -> String {
        sha2::Sha256::digest(std::fs::read(p).unwrap()).iter().map(|b| format!("{b:02x}")).collect()
    };
    assert_eq!(r["output"]["sha256"], hex_of(&out).as_str());
    assert_eq!(r["input"]["sha256"], hex_of(&raw).as_str());

    let verify = |file: &Path| {
        let o = campro().arg("check").arg("--record").arg(&record).arg(file).output().unwrap();
        assert!(!String::from_utf8_lossy(&o.stderr).contains("panicked"));
        (o.status.code(), String::from_utf8_lossy(&o.stdout).into_owned())
    };
    let (code, text) = verify(&out);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("the output its record names") && text.contains("unproven"), "{text}");
    let (code, text) = verify(&raw);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("run again it gives the output its record names"), "{text}");
    // One changed pixel in the output: not what the record says.
    let mut img = image::open(&out).unwrap().to_rgb8();
    img.put_pixel(0, 0, image::Rgb([1, 2, 3]));
    let forged = dir.path().join("forged.png");
    img.save(&forged).unwrap();
    let (code, text) = verify(&forged);
    assert_eq!(code, Some(3), "{text}");
    assert!(text.contains("NOT what its record names"), "{text}");
    // A record whose hash is no hash: one line naming the field.
    let mut bad = r.clone();
    bad["output"]["sha256"] = "zz".into();
    let bad_path = dir.path().join("bad.campro.json");
    std::fs::write(&bad_path, bad.to_string()).unwrap();
    fails_with(campro().arg("check").arg("--record").arg(&bad_path).arg(&out), "output.sha256: must be 64 hex digits");
    let mut extra = r.clone();
    extra["surprise"] = 1.into();
    std::fs::write(&bad_path, extra.to_string()).unwrap();
    fails_with(campro().arg("check").arg("--record").arg(&bad_path).arg(&out), "unknown field");
    // Forgeries. A hand-written record naming the raw photo itself as the preset's output:
    // the hash matches, and the output says that proves nothing of how it was made.
    let mut lie = r.clone();
    lie["output"]["sha256"] = hex_of(&raw).into();
    lie["output"]["name"] = "raw.png".into();
    std::fs::write(&bad_path, lie.to_string()).unwrap();
    let o = campro().arg("check").arg("--record").arg(&bad_path).arg(&raw).output().unwrap();
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("not how it was made") && said.contains("unproven"), "{said}");
    // An edited preset: the name of another bundled preset, or another preset's hash.
    let identity = sha2::Sha256::digest(std::fs::read(bundled("identity.json")).unwrap());
    let identity: String = identity.iter().map(|b| format!("{b:02x}")).collect();
    for (field, value) in [("name", "identity"), ("sha256", identity.as_str())] {
        let mut edited = r.clone();
        edited["preset"][field] = value.into();
        std::fs::write(&bad_path, edited.to_string()).unwrap();
        fails_with(campro().arg("check").arg("--record").arg(&bad_path).arg(&out), &format!("preset.{field}:"));
    }
    // Fields out of range or against each other.
    for (field, value) in
        [("bit_depth", Value::from(3)), ("jpeg_quality", 0.into()), ("metadata", "orientation".into())]
    {
        let mut edited = r.clone();
        edited[field] = value;
        std::fs::write(&bad_path, edited.to_string()).unwrap();
        fails_with(campro().arg("check").arg("--record").arg(&bad_path).arg(&out), &format!("{field}:"));
    }
    let mut edited = r.clone();
    edited["path"] = "camera+enhancer".into();
    std::fs::write(&bad_path, edited.to_string()).unwrap();
    fails_with(campro().arg("check").arg("--record").arg(&bad_path).arg(&out), "enhancer_sha256:");
    // A second run without --force does not replace the record either.
    fails_with(campro().args(["simulate", "campro-omega-0.5"]).arg(&raw).arg("-o").arg(&out).arg("--record"), "exists");
}

#[test]
fn a_device_is_checked_as_its_hal_applies_the_values() {
    let Some(shared) = shared() else { return };
    let dir = tempfile::tempdir().unwrap();
    let photos = persons(&shared, dir.path());
    let similarities = |extra: &[&str]| -> (Vec<f64>, Value) {
        let mut args: Vec<&std::ffi::OsStr> =
            vec!["check".as_ref(), "campro-omega-0.5".as_ref(), "--people".as_ref(), photos.as_os_str()];
        args.extend(captured_only(&shared));
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        let (code, v, err) = json_run(&args);
        assert!(code == Some(0) || code == Some(3), "{err}");
        let s = v["photos"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|p| {
                p["faces"].as_array().unwrap().iter().map(|f| f["views"][0]["similarity"][0].as_f64().unwrap())
            })
            .collect();
        (s, v)
    };
    let (ideal, _) = similarities(&[]);
    // An exact device reporting the identity: the emulator (f64, per pixel) gives the exact
    // 8-bit pipeline's pictures, so the same similarities.
    let (exact, v) = similarities(&["--matrix-frac-bits", "52"]);
    assert!(v["notes"][0].as_str().unwrap().contains("bound against the ideal preset 0.000 LSB"), "{}", v["notes"]);
    assert_eq!(ideal.len(), exact.len());
    for (a, b) in ideal.iter().zip(&exact) {
        assert!((a - b).abs() < 2e-3, "{ideal:?} vs {exact:?}");
    }
    // A device that resamples the curve to 8 entries runs another camera: faces come back.
    let (crude, v) = similarities(&["--lut-size", "8"]);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(mean(&crude) > mean(&ideal) + 0.1, "{crude:?} vs {ideal:?}");
    assert!(v["summary"]["linkable"][0].as_u64().unwrap() > 0, "{}", v["summary"]);
}

#[test]
fn a_view_that_fails_refuses_the_check_instead_of_scoring_another_picture() {
    let Some(shared) = shared() else { return };
    // A face on a strip wider than the enhancer takes (16,384 pixels a side; the detector
    // sees it at 640 wide, the face about 45 pixels): the enhanced
    // view cannot run on it, and the check says so instead of scoring the captured picture
    // under the enhanced view's name.
    let dir = tempfile::tempdir().unwrap();
    let face =
        image::open(shared.join(FACES[0])).unwrap().resize(1200, 1200, image::imageops::FilterType::Triangle).to_rgb8();
    let mut strip = image::RgbImage::from_pixel(16400, 1200, image::Rgb([120, 110, 100]));
    image::imageops::replace(&mut strip, &face, 7600, 0);
    let photo = dir.path().join("strip.png");
    strip.save(&photo).unwrap();
    fails_with(
        campro().args(["check", "campro-omega-0.5"]).arg(&photo).arg("--shared").arg(&shared).args([
            "--view",
            "enhanced",
            "--distractors",
            "0",
        ]),
        "the enhanced view",
    );
}
