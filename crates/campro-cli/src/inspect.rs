//! `campro inspect`: per-image results people can look at. For each image, raw | protected
//! side by side with the faces the face detector finds (magenta, with its five landmarks) and the people
//! the person detector finds (green) drawn on each panel, a JSON of the detections, and an
//! `index.html` (with `index.json`) linking them all.
//!
//! Inputs are read as `simulate` reads them (regular files with a byte cap, folders walked
//! without following links, one shared decode budget); outputs are written atomically under
//! names taken from the input paths, never from file contents.

use crate::args::{InspectArgs, Report};
use crate::simulate::{self, Budget};
use crate::{escape, page, say, write_atomic};
use anyhow::{anyhow, bail, Result};
use campro::pipeline::fast::Exact8;
use campro::Params;
use campro_eval::face::{Face, FaceDetector};
use campro_eval::person::{Detection, PersonDetector};
use image::{Rgb, RgbImage};
use rayon::prelude::*;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Face boxes and landmarks.
pub const FACE_COLOUR: Rgb<u8> = Rgb([255, 0, 255]);
/// Person boxes.
pub const PERSON_COLOUR: Rgb<u8> = Rgb([0, 255, 0]);
/// White pixels between the panels.
pub const GAP: u32 = 8;

/// The models an inspection runs.
pub struct Detectors {
    pub faces: FaceDetector,
    /// Name (for the report) and detector, for raw images.
    pub people: (String, PersonDetector),
    /// The preset's own fine-tuned detector for the protected panel, if asked for.
    pub own: Option<(String, PersonDetector)>,
    /// People below this score (in [0, 1]) are not drawn or listed.
    pub confidence: f32,
}

/// What one panel shows.
struct Panel {
    name: &'static str,
    image: RgbImage,
    faces: Vec<Face>,
    people: Vec<Detection>,
    detector: String,
}

/// Line thickness of the drawn boxes for an image of this size (pixels, at least 1).
pub fn thickness(w: u32, h: u32) -> u32 {
    (w.min(h) / 160).max(2)
}

/// Draws `bbox` (`[x0, y0, x1, y1]`, image pixels) as a hollow rectangle `t` pixels thick
/// growing *outwards*, inside a black ring one pixel wide (visible on any protected colour),
/// so what the box marks (a small face above all) is never covered; boxes reaching outside
/// the image are clipped.
fn draw_box(img: &mut RgbImage, bbox: [f32; 4], t: u32, colour: Rgb<u8>) {
    use imageproc::rect::Rect;
    let [x0, y0, x1, y1] = bbox.map(|v| if v.is_finite() { v.clamp(-1e6, 1e6).round() as i32 } else { 0 });
    if x1 - x0 <= 0 || y1 - y0 <= 0 {
        return;
    }
    let ring = |i: i32| Rect::at(x0 - i, y0 - i).of_size((x1 - x0 + 2 * i) as u32, (y1 - y0 + 2 * i) as u32);
    for i in 1..=t as i32 {
        imageproc::drawing::draw_hollow_rect_mut(img, ring(i), colour);
    }
    imageproc::drawing::draw_hollow_rect_mut(img, ring(t as i32 + 1), Rgb([0, 0, 0]));
}

/// The panel with its detections' boxes drawn around them (landmarks stay in the JSON: dots
/// on a small face hide what one needs to judge).
fn drawn(p: &Panel) -> RgbImage {
    let mut img = p.image.clone();
    let t = thickness(img.width(), img.height());
    for d in &p.people {
        draw_box(&mut img, d.bbox, t, PERSON_COLOUR);
    }
    for f in &p.faces {
        draw_box(&mut img, f.bbox, t, FACE_COLOUR);
    }
    img
}

/// The panels side by side, [`GAP`] white pixels apart.
fn side_by_side(panels: &[RgbImage]) -> RgbImage {
    let h = panels.iter().map(|p| p.height()).max().unwrap_or(0);
    let w = panels.iter().map(|p| p.width()).sum::<u32>() + GAP * panels.len().saturating_sub(1) as u32;
    let mut out = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let mut x = 0i64;
    for p in panels {
        image::imageops::replace(&mut out, p, x, 0);
        x += (p.width() + GAP) as i64;
    }
    out
}

fn round2(v: f32) -> f64 {
    (v as f64 * 100.0).round() / 100.0
}

fn panel_json(p: &Panel) -> Value {
    json!({
        "panel": p.name,
        "person_detector": p.detector,
        "faces": p.faces.iter().map(|f| json!({
            "bbox": f.bbox.map(round2), "score": round2(f.score),
            "landmarks": f.landmarks.map(|l| l.map(round2)),
        })).collect::<Vec<_>>(),
        "people": p.people.iter().map(|d| json!({"bbox": d.bbox.map(round2), "score": round2(d.score)})).collect::<Vec<_>>(),
    })
}

/// Inspects one image: detections on raw and protected, the picture and its JSON written.
fn one(
    input: &Path,
    picture: &Path,
    fast: &Exact8,
    grey_refused: &dyn Fn(&RgbImage) -> bool,
    enhancer: Option<&campro_eval::guard::GuardedEnhancer>,
    det: &Detectors,
    budget: &Budget,
    warn: &dyn Fn(&str),
) -> Result<Value> {
    // The lease holds the image's memory and the enhancer's work until this picture is done,
    // and the panels: each image (3 bytes a pixel), its drawn copy (3) and the picture of
    // them side by side (3), with the PNG written from it.
    let panels = if enhancer.is_some() { 3 } else { 2 };
    let work =
        |w: u32, h: u32| (w as u64 * h as u64 * 9 * panels).saturating_add(enhancer.map_or(0, |e| e.work_bytes(w, h)));
    let (img, _lease) = campro_eval::image_file::read(input, budget, &work, warn)?;
    let raw = img.into_rgb8();
    // A grey picture `simulate` refuses (the preset is not rated for grey): shown, and said.
    let grey = grey_refused(&raw);
    if grey {
        warn("a grey picture, or grey faces in a mostly colourless one: simulate refuses it (this preset does not protect grey faces); its protected panel is what --allow-grey would write");
    }
    let mut protected = RgbImage::new(raw.width(), raw.height());
    fast.run(raw.as_raw(), &mut protected);
    let enhanced = enhancer.map(|e| crate::capture::enhance(e, &protected)).transpose()?;
    let mut panels = Vec::with_capacity(3);
    let named = [("raw", raw), ("protected", protected)].into_iter().chain(enhanced.map(|e| ("enhanced", e)));
    for (name, image) in named {
        let (pname, pdet) = match (&det.own, name) {
            (Some(own), "protected") => own,
            _ => &det.people,
        };
        let faces = det.faces.detect(&image)?;
        let mut people = pdet.detect(&image)?;
        people.retain(|d| d.score >= det.confidence);
        panels.push(Panel { name, image, faces, people, detector: pname.clone() });
    }
    let picture_img = side_by_side(&panels.iter().map(drawn).collect::<Vec<_>>());
    let mut png = Vec::new();
    picture_img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)?;
    let json_path = picture.with_extension("json");
    let (w, h) = (panels[0].image.width(), panels[0].image.height());
    let v = json!({
        "input": input.display().to_string(),
        "width": w,
        "height": h,
        "picture": picture.file_name().map(|n| n.to_string_lossy().into_owned()),
        "grey_refused": grey,
        "panels": panels.iter().map(panel_json).collect::<Vec<_>>(),
    });
    write_atomic(picture, &png, true)?;
    write_atomic(&json_path, (serde_json::to_string_pretty(&v)? + "\n").as_bytes(), true)?;
    Ok(v)
}

/// The index page: the summary first, then a section per image (those that still show faces
/// after the camera first, most faces first), each panel a captioned figure at a useful size
/// that opens the whole picture in a lightbox.
/// `by` names the (face, person) detectors.
fn index_html(
    params: &str,
    by: (&str, &str),
    items: &[(PathBuf, Value)],
    failed: &[(PathBuf, String)],
    out: &Path,
) -> String {
    let panels: Vec<String> = items
        .first()
        .and_then(|(_, v)| v["panels"].as_array())
        .map(|a| a.iter().filter_map(|p| p["panel"].as_str().map(str::to_string)).collect())
        .unwrap_or_else(|| vec!["raw".into(), "protected".into()]);
    let arrows = panels.join(" &rarr; ");
    let mut s = page::head("campro inspect");
    // The summary a reader needs first: faces and people per panel over all images, and
    // the images where a face is still found after the camera (flagged, listed first).
    let total = |what| {
        (0..panels.len())
            .map(|k| items.iter().map(|(_, v)| count(v, k, what)).sum::<usize>().to_string())
            .collect::<Vec<_>>()
            .join(" &rarr; ")
    };
    let flagged = items.iter().filter(|(_, v)| shows_faces(v, panels.len())).count();
    s += &format!(
        "<h1>campro inspect</h1>\n<p id=\"summary\"{}>{} images. Faces found, {arrows}: <b class=\"face\">{}</b>; people: <b class=\"person\">{}</b>. {}</p>\n",
        if flagged > 0 { " class=\"alarm\"" } else { "" },
        items.len(),
        total("faces"),
        total("people"),
        if flagged == 0 {
            "No face is found in any picture after the camera.".to_string()
        } else {
            format!(
                "<span class=\"warn\">{flagged} image{} still show{} faces after the camera</span> (listed first, marked): look at them before you share.",
                if flagged == 1 { "" } else { "s" },
                if flagged == 1 { "s" } else { "" }
            )
        }
    );
    s += &format!(
        "<p>Parameters: {}. Panels, left to right: {}. <span class=\"face\">Faces</span> ({}) and \
         <span class=\"person\">people</span> ({}) found on each are boxed around, never over, \
         what was found. Click a panel for the whole picture at full size; the JSON beside each image has the \
         boxes, scores and face landmarks.</p>\n",
        page::html_escape(params),
        panels.join(", "),
        page::html_escape(by.0),
        page::html_escape(by.1)
    );
    s += &format!("<p id=\"one-story\">{}</p>\n", page::html_escape(page::ONE_STORY));
    // Flagged images first, the most faces after the camera first; then in input order.
    let mut order: Vec<(usize, &(PathBuf, Value))> = items.iter().enumerate().collect();
    order.sort_by_key(|(_, (_, v))| std::cmp::Reverse(faces_after(v, panels.len())));
    for (i, (picture, v)) in order {
        let flag = shows_faces(v, panels.len());
        let link = page::href(picture, out);
        let json_link = page::href(&picture.with_extension("json"), out);
        let name = page::html_escape(&href_name(picture, out));
        let size = (v["width"].as_u64().unwrap_or(1) as u32, v["height"].as_u64().unwrap_or(1) as u32);
        let (row, zoom) = (format!("row{i}"), format!("zoom{i}"));
        s += &format!(
            "<section class=\"row{}\" id=\"{row}\"><h2>{name}{} <a href=\"{json_link}\">JSON</a></h2><div class=\"figs\">",
            if flag { " flag" } else { "" },
            if flag { " <span class=\"warn\">faces found after the camera</span>" } else { "" },
        );
        if v["grey_refused"].as_bool() == Some(true) {
            s += "<p class=\"warn\">A grey picture, or grey faces in a mostly colourless one: <code>campro simulate</code> refuses it, since this preset does not protect grey faces (a restoration that knows the camera gives them back); the protected panel is what <code>--allow-grey</code> would write.</p>";
        }
        for (k, p) in panels.iter().enumerate() {
            let (f, n) = (count(v, k, "faces"), count(v, k, "people"));
            let warn = if k > 0 && f > 0 { " warn" } else { "" };
            let caption = format!(
                "<b>{}</b>: <span class=\"face{warn}\">{f} face{}</span>, <span class=\"person\">{n} {}</span>",
                page::html_escape(p),
                if f == 1 { "" } else { "s" },
                if n == 1 { "person" } else { "people" }
            );
            let alt = format!("{} ({p})", href_name(picture, out));
            s += &page::panel(&link, &alt, size, GAP, panels.len(), k, &zoom, &caption);
        }
        s += "</div></section>\n";
        let whole = page::big(&link, &href_name(picture, out), None);
        s += &page::lightbox(&zoom, &format!("{name}: {}", panels.join(" | ")), &whole, &row);
        s += "\n";
    }
    if !failed.is_empty() {
        s += "<h2>Failed</h2>\n<ul>\n";
        for (i, e) in failed {
            s += &format!("<li>{}: {}</li>\n", page::html_escape(&i.display().to_string()), page::html_escape(e));
        }
        s += "</ul>\n";
    }
    s + "</body></html>\n"
}

/// The most faces any panel after the first (the raw photo) of an image's JSON has found.
fn faces_after(v: &Value, panels: usize) -> usize {
    (1..panels).map(|k| count(v, k, "faces")).max().unwrap_or(0)
}

/// Whether any panel after the first (the raw photo) of an image's JSON has a face found:
/// the camera, or the enhanced view, shows a face a detector finds.
fn shows_faces(v: &Value, panels: usize) -> bool {
    faces_after(v, panels) > 0
}

/// How many `what` ("faces" or "people") panel `panel` of an image's JSON lists.
fn count(v: &Value, panel: usize, what: &str) -> usize {
    v["panels"][panel][what].as_array().map_or(0, |a| a.len())
}

/// The picture's path under `out`, for display.
fn href_name(picture: &Path, out: &Path) -> String {
    picture.strip_prefix(out).unwrap_or(picture).display().to_string()
}

/// `campro inspect`: the models loaded, then [`inspect`].
pub fn run(a: InspectArgs) -> Result<()> {
    let InspectArgs {
        params,
        inputs,
        output,
        data,
        person_detector,
        face_detector,
        own_detector,
        confidence,
        force,
        format,
        enhance,
        scale,
    } = a;
    let p = crate::load_params(&params)?;
    crate::check_output_folder(&output, force, "--output")?;
    let given = data.models.is_some();
    let models = data.models_dir();
    let enhancer = if enhance { Some(crate::capture::enhancer_of(&params, &p, scale, &models)?) } else { None };
    if !models.is_dir() {
        bail!(
            "{} {}: no such folder; `campro models fetch` installs the models a registry has (`campro models list` says where the others come from), or pass --models DIR, --shared DIR or set CAMPRO_SHARED",
            if given { "--models" } else { "the models folder" },
            crate::shown(&models)
        );
    }
    let people = crate::models::load(crate::models::person_detector(&person_detector, &models), &models)?;
    let own = if own_detector {
        let own = crate::eval::own_detectors(std::slice::from_ref(&params))?;
        let detector = own.values().next().ok_or_else(|| {
            anyhow!("--own-detector: {} names no fine-tuned detector (provenance.detector)", crate::shown(&params))
        })?;
        let m = detector.load(&models)?;
        Some((m.manifest.name.clone(), campro_eval::person::PersonDetector::new(m)?))
    } else {
        None
    };
    let det = Detectors {
        faces: campro_eval::face::FaceDetector::new(crate::models::load(
            crate::models::face_detector(&face_detector, &models),
            &models,
        )?)?,
        people: (people.manifest.name.clone(), campro_eval::person::PersonDetector::new(people)?),
        own,
        confidence: confidence as f32,
    };
    inspect(&params, &p, &inputs, &output, &det, enhancer.as_ref(), &models, matches!(format, Report::Json))
}

/// Runs the inspection of every image under `inputs` into `out` (checked by the caller:
/// new, empty or forced); prints a line per image, or (`json_out`) the index as one JSON
/// object. `models`: where `simulate`'s grey check finds its face detectors.
#[allow(clippy::too_many_arguments)]
pub fn inspect(
    params_file: &Path,
    p: &Params,
    inputs: &[PathBuf],
    out: &Path,
    det: &Detectors,
    enhancer: Option<&campro_eval::guard::GuardedEnhancer>,
    models: &Path,
    json_out: bool,
) -> Result<()> {
    let which = simulate::Reads { reads: &simulate::is_image, otherwise: "not a PNG, JPEG, TIFF or WebP file" };
    let found = simulate::collect_inputs(inputs, out, &|p| p.with_extension("png"), &which)?;
    for (i, why) in &found.skipped {
        eprintln!("warning: skipping {}: {why}", crate::shown(i));
    }
    let images = found.jobs;
    if images.is_empty() {
        bail!("no PNG, JPEG, TIFF or WebP file among the inputs: nothing to inspect");
    }
    let fast = Exact8::new(p);
    // What simulate refuses as grey: the whole picture, or a face of a mostly colourless one.
    let grey = crate::capture::GreyPolicy::new(p, false).with_faces(models);
    let grey_refused = |img: &RgbImage| grey.check_picture(img.as_raw(), img.width(), img.height()).is_err();
    let budget = Budget::global();
    let bar = crate::output::count_bar("inspect", images.len() as u64);
    let results: Vec<Result<Value>> = images
        .par_iter()
        .map(|(i, o)| {
            let warn = |w: &str| bar.suspend(|| eprintln!("warning: {}: {w}", crate::shown(i)));
            let r = one(i, o, &fast, &grey_refused, enhancer, det, budget, &warn);
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    let mut done = Vec::new();
    let mut failed = Vec::new();
    for ((i, o), r) in images.into_iter().zip(results) {
        match r {
            Ok(v) => done.push((o, v)),
            Err(e) => {
                let line = crate::about(&i, &e);
                eprintln!("error: {line}");
                failed.push((i, line));
            }
        }
    }
    let params_name = format!("{} ({})", crate::shown(params_file), p.name);
    let panel_names: &[&str] =
        if enhancer.is_some() { &["raw", "protected", "enhanced"] } else { &["raw", "protected"] };
    let index = json!({
        "params": params_name,
        "face_detector": det.faces.name(),
        "person_detector": det.people.0,
        "own_detector": det.own.as_ref().map(|o| o.0.clone()),
        "confidence": det.confidence,
        "panels": panel_names,
        "images": done.iter().map(|(o, v)| json!({
            "input": v["input"], "picture": page::href(o, out), "json": page::href(&o.with_extension("json"), out),
            "faces": (0..panel_names.len()).map(|k| count(v, k, "faces")).collect::<Vec<_>>(),
            "people": (0..panel_names.len()).map(|k| count(v, k, "people")).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "failed": failed.iter().map(|(i, e)| json!({"input": i.display().to_string(), "error": e})).collect::<Vec<_>>(),
    });
    write_atomic(
        &out.join("index.html"),
        index_html(&params_name, (det.faces.name(), &det.people.0), &done, &failed, out).as_bytes(),
        true,
    )?;
    write_atomic(&out.join("index.json"), (serde_json::to_string_pretty(&index)? + "\n").as_bytes(), true)?;
    if json_out {
        say!("{}", serde_json::to_string(&index)?);
    } else {
        for (o, v) in &done {
            let n = |what| {
                panel_names
                    .iter()
                    .enumerate()
                    .map(|(k, p)| format!("{} {p}", count(v, k, what)))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            say!("{}: faces {}; people {}", escape(&href_name(o, out)), n("faces"), n("people"));
        }
        say!("index: {}", crate::shown(&out.join("index.html")));
    }
    if !failed.is_empty() {
        bail!("{} of {} image(s) failed", failed.len(), failed.len() + done.len());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_are_drawn_outwards_and_clipped() {
        let mut img = RgbImage::from_pixel(20, 12, Rgb([9, 9, 9]));
        draw_box(&mut img, [4.0, 4.0, 10.0, 8.0], 2, PERSON_COLOUR);
        // The box covers x 4..=9, y 4..=7: all of it untouched; rings at 1 and 2 pixels
        // outside (x 3 and 2, 10 and 11), then the black ring at 3 (x 1 and 12).
        for y in 4..8 {
            for x in 4..10 {
                assert_eq!(img[(x, y)], Rgb([9, 9, 9]), "({x}, {y})");
            }
        }
        assert_eq!(img[(3, 5)], PERSON_COLOUR);
        assert_eq!(img[(2, 5)], PERSON_COLOUR);
        assert_eq!(img[(10, 5)], PERSON_COLOUR);
        assert_eq!(img[(11, 5)], PERSON_COLOUR);
        assert_eq!(img[(6, 3)], PERSON_COLOUR);
        assert_eq!(img[(6, 9)], PERSON_COLOUR);
        assert_eq!(img[(1, 5)], Rgb([0, 0, 0]));
        assert_eq!(img[(12, 5)], Rgb([0, 0, 0]));
        assert_eq!(img[(6, 1)], Rgb([0, 0, 0]));
        assert_eq!(img[(0, 5)], Rgb([9, 9, 9]));
        assert_eq!(img[(13, 5)], Rgb([9, 9, 9]));
        // Partly outside and non-finite: no panic, the visible part drawn.
        draw_box(&mut img, [-5.0, 2.0, 25.0, 5.0], 1, FACE_COLOUR);
        assert_eq!(img[(15, 1)], FACE_COLOUR);
        draw_box(&mut img, [f32::NAN, 0.0, f32::INFINITY, 3.0], 3, FACE_COLOUR);
    }

    #[test]
    fn panels_sit_side_by_side() {
        let a = RgbImage::from_pixel(3, 2, Rgb([1, 2, 3]));
        let b = RgbImage::from_pixel(4, 2, Rgb([4, 5, 6]));
        let s = side_by_side(&[a, b]);
        assert_eq!(s.dimensions(), (3 + GAP + 4, 2));
        assert_eq!(s[(2, 1)], Rgb([1, 2, 3]));
        assert_eq!(s[(3, 0)], Rgb([255, 255, 255]));
        assert_eq!(s[(3 + GAP, 0)], Rgb([4, 5, 6]));
    }

    #[test]
    fn the_page_sums_up_and_lists_images_that_show_faces_first() {
        const NAMES: [&str; 3] = ["raw", "protected", "enhanced"];
        let item = |name: &str, faces: [usize; 3]| {
            let panel = |k: usize, n: usize| json!({"panel": NAMES[k], "faces": vec![json!({}); n], "people": []});
            (
                PathBuf::from(format!("/o/{name}.png")),
                json!({"panels": [panel(0, faces[0]), panel(1, faces[1]), panel(2, faces[2])]}),
            )
        };
        let mut items = [item("portrait", [1, 0, 0]), item("class", [31, 0, 32]), item("street", [0, 0, 0])];
        items[2].1["grey_refused"] = true.into();
        let html = index_html("p", ("yunet", "yolox-nano"), &items, &[], Path::new("/o"));
        // Totals per panel, and the one image that still shows faces named in the summary.
        assert!(html.contains("3 images. Faces found, raw &rarr; protected &rarr; enhanced: <b class=\"face\">32 &rarr; 0 &rarr; 32</b>"), "{html}");
        assert!(html.contains("1 image still shows faces after the camera"), "{html}");
        // The class photo's row comes first and is marked; the others keep their order.
        let (c, p, st) =
            (html.find("class.png").unwrap(), html.find("portrait.png").unwrap(), html.find("street.png").unwrap());
        assert!(c < p && p < st, "{html}");
        assert_eq!(html.matches("<section class=\"row flag\"").count(), 1);
        // Each panel is a captioned figure opening the lightbox of its picture.
        assert_eq!(html.matches("<figure>").count(), 9);
        assert!(html.contains("<b>enhanced</b>: <span class=\"face warn\">32 faces</span>"), "{html}");
        assert_eq!(html.matches("class=\"lb\"").count(), 3);
        // The grey picture is said to be refused by simulate, once.
        assert_eq!(
            html.matches(
                "A grey picture, or grey faces in a mostly colourless one: <code>campro simulate</code> refuses it"
            )
            .count(),
            1,
            "{html}"
        );
        let clean = index_html("p", ("yunet", "yolox-nano"), &items[..1], &[], Path::new("/o"));
        assert!(clean.contains("No face is found in any picture after the camera."), "{clean}");
    }
}
