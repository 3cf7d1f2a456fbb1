//! `campro inspect` on shared images: the index page's links open, each picture is raw |
//! protected with the detections boxed only around what the JSON says (never over a face),
//! and the protected panel is the exact pipeline's output.

mod common;
use common::{bundled, campro, fails_with};
use image::RgbImage;
use serde_json::Value;
use std::path::Path;

/// The detectors inspect runs and an LFW face, under the shared data folder.
const YUNET: &str = "models/yunet_s_640_640.onnx";
const YOLOX: &str = "models/yolox_nano.onnx";
const FACE: &str = "data/lfw/images_deepfunneled/Aaron_Eckhart/Aaron_Eckhart_0001.jpg";

/// Every `href="..."` and `src="..."` value of an HTML page but links inside it (`#id`).
fn links(html: &str) -> Vec<String> {
    let mut out = Vec::new();
    for attr in ["href=\"", "src=\""] {
        let mut rest = html;
        while let Some(i) = rest.find(attr) {
            rest = &rest[i + attr.len()..];
            let end = rest.find('"').expect("closed attribute");
            if !rest.starts_with('#') {
                out.push(rest[..end].to_string());
            }
            rest = &rest[end..];
        }
    }
    out
}

/// Whether (x, y) is within `margin` pixels outside a box drawn for this panel's detections
/// (boxes are drawn around what they mark, outwards).
fn near_drawing(panel: &Value, x: f32, y: f32, margin: f32) -> bool {
    let near_box = |b: &Value| {
        let b: Vec<f32> = b.as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
        let inside_outer = x >= b[0] - margin && x <= b[2] + margin && y >= b[1] - margin && y <= b[3] + margin;
        let inside_box = x > b[0] + 1.0 && x < b[2] - 1.0 && y > b[1] + 1.0 && y < b[3] - 1.0;
        inside_outer && !inside_box
    };
    let faces = panel["faces"].as_array().unwrap();
    let people = panel["people"].as_array().unwrap();
    faces.iter().any(|f| near_box(&f["bbox"])) || people.iter().any(|d| near_box(&d["bbox"]))
}

#[test]
fn inspect_writes_pictures_json_and_an_index_whose_links_open() {
    let Some(shared) = campro_testkit::shared_root(&[YUNET, YOLOX, FACE, "data/coco-person/images/000000000785.jpg"])
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("inspect out");
    let face = shared.join(FACE);
    let street = shared.join("data/coco-person/images/000000000785.jpg");
    let params = bundled("campro-omega-0.5.json");
    let run = campro()
        .args(["inspect".as_ref(), params.as_os_str(), face.as_os_str(), street.as_os_str(), "-o".as_ref()])
        .arg(&out)
        .arg("--shared")
        .arg(&shared)
        .args(["--format", "json"])
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let printed: Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(printed["images"].as_array().unwrap().len(), 2);
    assert_eq!(printed, serde_json::from_slice::<Value>(&std::fs::read(out.join("index.json")).unwrap()).unwrap());

    // Every link of the page opens a file inside the output folder: per image its picture
    // twice (a panel each) and once in the lightbox, and its JSON.
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    // One story with check: the page says what each command counts.
    assert!(html.contains("<p id=\"one-story\">inspect and check look at the same photos"), "one story");
    let links = links(&html);
    assert_eq!(links.len(), 8, "{links:?}");
    assert_eq!(html.matches("<figcaption>").count(), 4, "a captioned figure per panel");
    let p = params.to_str().unwrap();
    let fast =
        campro::pipeline::fast::Exact8::new(Box::leak(Box::new(campro::Params::from_file(Path::new(p)).unwrap())));
    for link in &links {
        let rel = percent_encoding::percent_decode_str(link).decode_utf8().unwrap();
        let file = out.join(rel.as_ref());
        assert!(file.is_file() && file.starts_with(&out), "{link} does not open");
        if !link.ends_with(".png") {
            continue;
        }
        let json: Value = serde_json::from_slice(&std::fs::read(file.with_extension("json")).unwrap()).unwrap();
        let input = Path::new(json["input"].as_str().unwrap());
        let raw = image::open(input).unwrap().to_rgb8();
        let (w, h) = raw.dimensions();
        let picture = image::open(&file).unwrap().to_rgb8();
        assert_eq!(picture.dimensions(), (2 * w + 8, h));
        let mut protected = RgbImage::new(w, h);
        fast.run(raw.as_raw(), &mut protected);
        let panels = json["panels"].as_array().unwrap();
        assert_eq!(panels[0]["panel"], "raw");
        assert_eq!(panels[1]["panel"], "protected");
        // Away from the drawn boxes each panel is its image, pixel for pixel (inside every
        // box too: a face is never drawn over); on them it is not (something was drawn).
        let (mut checked, mut drawn) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                for (k, img) in [&raw, &protected].into_iter().enumerate() {
                    let shown = picture[(x + k as u32 * (w + 8), y)];
                    if !near_drawing(&panels[k], x as f32, y as f32, 8.0) {
                        assert_eq!(shown, img[(x, y)], "{link} panel {k} at ({x}, {y})");
                        checked += 1;
                    } else if shown != img[(x, y)] {
                        drawn += 1;
                    }
                }
            }
        }
        assert!(checked > (w * h) as usize, "{checked}");
        let found: usize =
            panels.iter().map(|p| p["faces"].as_array().unwrap().len() + p["people"].as_array().unwrap().len()).sum();
        assert_eq!(found > 0, drawn > 0, "{link}: {found} detections, {drawn} drawn pixels");
    }
    // In a real browser every picture of the page loads.
    if let Some(browser) = common::browser() {
        let seen = common::open_in_browser(browser, &out.join("index.html"));
        assert!(seen.starts_with("RESULT images=6 broken=0 scripts=0 "), "{seen}");
    }
    // The LFW photo's raw panel shows the face YuNet finds, near the centre of the 250x250 image.
    let fj: Value = serde_json::from_slice(&std::fs::read(out.join("Aaron_Eckhart_0001.json")).unwrap()).unwrap();
    let b = &fj["panels"][0]["faces"][0]["bbox"];
    let (cx, cy) = (
        (b[0].as_f64().unwrap() + b[2].as_f64().unwrap()) / 2.0,
        (b[1].as_f64().unwrap() + b[3].as_f64().unwrap()) / 2.0,
    );
    assert!((cx - 125.0).abs() < 25.0 && (cy - 125.0).abs() < 30.0, "face centre ({cx}, {cy})");

    // A second run into the same folder is refused without --force.
    fails_with(
        campro()
            .args(["inspect".as_ref(), params.as_os_str(), face.as_os_str(), "-o".as_ref()])
            .arg(&out)
            .arg("--shared")
            .arg(&shared),
        "--output",
    );
}

#[test]
fn inspect_names_a_missing_model_folder() {
    let dir = tempfile::tempdir().unwrap();
    let img = dir.path().join("a.png");
    RgbImage::new(4, 4).save(&img).unwrap();
    fails_with(
        campro()
            .args(["inspect".as_ref(), bundled("campro-omega-0.5.json").as_os_str(), img.as_os_str(), "-o".as_ref()])
            .arg(dir.path().join("out"))
            .arg("--models")
            .arg(dir.path().join("no-models")),
        "no-models",
    );
}

/// A grey photo, which `simulate` refuses under a preset not rated for grey, and a
/// selective-colour one (refused by its grey face), are flagged on `inspect`'s page and in
/// its JSON, not shown as protected without a word.
#[test]
fn inspect_flags_grey_photos_as_simulate_refuses_them() {
    let Some(shared) = campro_testkit::shared_root(&[YUNET, YOLOX, FACE]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let face = shared.join(FACE);
    let grey = dir.path().join("grey.png");
    let luma = image::DynamicImage::ImageLuma8(image::open(&face).unwrap().to_luma8()).to_rgb8();
    luma.save(&grey).unwrap();
    // Selective colour: grey but for a vivid patch, colour enough for the whole-frame
    // measure; simulate refuses it by its grey face, and inspect says so too.
    let mut patched = luma.clone();
    for (x, y, p) in patched.enumerate_pixels_mut() {
        if x < 80 && y >= 170 {
            *p = if (x / 8) % 2 == 0 { image::Rgb([220, 30, 40]) } else { image::Rgb([30, 160, 60]) };
        }
    }
    assert!(!campro::chroma::measure(patched.as_raw()).is_grey());
    let selective = dir.path().join("selective.png");
    patched.save(&selective).unwrap();
    let out = dir.path().join("out");
    let run = campro()
        .args(["inspect", "campro-omega-0.5"])
        .arg(&grey)
        .arg(&selective)
        .arg(&face)
        .arg("-o")
        .arg(&out)
        .arg("--shared")
        .arg(&shared)
        .args(["--format", "json"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("grey.png") && err.contains("simulate refuses it"), "{err}");
    let v: Value = serde_json::from_slice(&std::fs::read(out.join("grey.json")).unwrap()).unwrap();
    assert_eq!(v["grey_refused"], true);
    let v: Value = serde_json::from_slice(&std::fs::read(out.join("selective.json")).unwrap()).unwrap();
    assert_eq!(v["grey_refused"], true);
    let v: Value = serde_json::from_slice(&std::fs::read(out.join("Aaron_Eckhart_0001.json")).unwrap()).unwrap();
    assert_eq!(v["grey_refused"], false);
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert_eq!(
        html.matches(
            "A grey picture, or grey faces in a mostly colourless one: <code>campro simulate</code> refuses it"
        )
        .count(),
        2
    );
}
