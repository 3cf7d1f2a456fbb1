//! The face guard's recall per detector and face size: LFW faces pasted at 10 to 48 pixels
//! wide (the detector's box) in rows across 1280 x 720 COCO scenes, `ROUNDS` placements a
//! width; a face counts as found when a find's box holds its centre. Two views: the scene
//! as it is ("raw": the guard searching one picture), and as a person is shown it
//! ("enhanced": captured by `campro-omega-0.5`, enhanced by its enhancer, the guard
//! searching the enhanced picture and the captured one, as `GuardedEnhancer` does).
//! Columns: YuNet's guard, CenterFace's guard, and both (the union: what the guard hides
//! when both are installed). Also, per view, the finds of each detector that no pasted
//! face explains (the scene's own faces and false alarms) and how many of them the other
//! detector missed. Reads `CAMPRO_SHARED` or `../shared` (YuNet, LFW, COCO) and
//! CenterFace from `CAMPRO_MODELS` (else the user's data folder, where `campro models
//! fetch` puts it); about 15 minutes on 2 cores.
//!
//! `cargo run --release -p campro-eval --example guard_recall`

use campro::pipeline::fast::Exact8;
use campro::Params;
use campro_eval::data::read_rgb8;
use campro_eval::enhance::Enhancer;
use campro_eval::face::{central_face, FaceDetector};
use campro_eval::guard::{FaceGuard, Hide};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use campro_eval::place::{paste, pasted_side};
use image::RgbImage;
use std::path::{Path, PathBuf};

const WIDTHS: [u32; 6] = [10, 12, 16, 24, 32, 48];
const ROUNDS: usize = 2;
/// Held-out COCO people photos searched for real faces.
const COCO_PHOTOS: usize = 150;
const SCENES: [&str; 2] = ["000000000802.jpg", "000000000785.jpg"];

fn detector(manifest: &str, models: &Path) -> FaceDetector {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("models").join(manifest);
    FaceDetector::new(Model::load(Manifest::load(&path, models).unwrap()).unwrap()).unwrap()
}

fn holds(set: &[[f32; 4]], p: &[f32; 4]) -> bool {
    let (cx, cy) = ((p[0] + p[2]) / 2.0, (p[1] + p[3]) / 2.0);
    set.iter().any(|b| cx > b[0] && cx < b[2] && cy > b[1] && cy < b[3])
}

fn main() {
    let shared = std::env::var_os("CAMPRO_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
    let fetched = std::env::var_os("CAMPRO_MODELS")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".local/share/campro/models")))
        .unwrap();
    let project = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let params = Params::from_file(&project.join("params/campro-omega-0.5.json")).unwrap();
    let camera = Exact8::new(&params);
    let enhancer = Enhancer::load(&project.join("params/campro-omega-0.5.enhancer.onnx")).unwrap();
    let reference = detector("yunet.json", &shared.join("models"));
    let guards = [
        ("yunet", FaceGuard::new(detector("yunet.json", &shared.join("models")), Hide::Pixelate)),
        (
            "centerface",
            FaceGuard::new(
                detector(&std::env::var("CENTERFACE_MANIFEST").unwrap_or("centerface.json".into()), &fetched),
                Hide::Pixelate,
            ),
        ),
    ];
    let root = shared.join("data/lfw/images_deepfunneled");
    let mut people: Vec<String> =
        std::fs::read_dir(&root).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    people.sort();
    let scenes: Vec<RgbImage> = SCENES
        .iter()
        .map(|s| {
            let scene = read_rgb8(&shared.join("data/coco-person/images").join(s)).unwrap();
            image::imageops::resize(&scene, 1280, 720, image::imageops::FilterType::Triangle)
        })
        .collect();
    // [view][width] = (faces, found by yunet, by centerface, by both)
    let mut table = vec![vec![(0u32, 0u32, 0u32, 0u32); WIDTHS.len()]; 2];
    // [view] = (yunet's unexplained finds, of them missed by centerface, centerface's, missed by yunet)
    let mut extra = [(0usize, 0usize, 0usize, 0usize); 2];
    let mut k = 0usize;
    for (wi, &width) in WIDTHS.iter().enumerate() {
        for round in 0..ROUNDS {
            let mut img = scenes[round % scenes.len()].clone();
            let mut pasted = vec![];
            let side = pasted_side(width) + 12;
            let mut y = 8 + round as u32 * 3;
            while y + side < 720 {
                let mut x = 8 + round as u32 * 5;
                while x + side < 1280 {
                    let p = &people[(k * 37) % people.len()];
                    k += 1;
                    let photo = read_rgb8(&root.join(format!("{p}/{p}_0001.jpg"))).unwrap();
                    if let Some(f) = central_face(&reference.detect(&photo).unwrap(), photo.width(), photo.height()) {
                        pasted.push(paste(&mut img, &photo, &f, width as f32, x as i64, y as i64).bbox);
                    }
                    x += side + 6 * side / 4;
                }
                y += 2 * side;
            }
            let mut captured = img.clone();
            camera.run(img.as_raw(), &mut captured);
            let enhanced = enhancer.enhance(&captured).unwrap();
            for (view, images) in [vec![&img], vec![&enhanced, &captured]].iter().enumerate() {
                let sets: Vec<Vec<[f32; 4]>> =
                    guards.iter().map(|(_, g)| g.find_all(images).unwrap().iter().map(|f| f.bbox).collect()).collect();
                let row = &mut table[view][wi];
                for p in &pasted {
                    let (a, b) = (holds(&sets[0], p), holds(&sets[1], p));
                    row.0 += 1;
                    row.1 += a as u32;
                    row.2 += b as u32;
                    row.3 += (a || b) as u32;
                }
                // Finds no pasted face explains: their centre outside every pasted box.
                let own = |set: &[[f32; 4]]| -> Vec<[f32; 4]> {
                    set.iter().filter(|b| !holds(&pasted, b)).copied().collect()
                };
                let (ya, ca) = (own(&sets[0]), own(&sets[1]));
                let e = &mut extra[view];
                e.0 += ya.len();
                e.1 += ya.iter().filter(|b| !holds(&sets[1], b)).count();
                e.2 += ca.len();
                e.3 += ca.iter().filter(|b| !holds(&sets[0], b)).count();
            }
        }
        eprintln!("width {width} done");
    }
    // Real faces: the held-out COCO people photos (id % 5 == 0), YuNet's finds at its own
    // threshold as the reference, and the other way round; each guard searching the photo.
    let coco = shared.join("data/coco-person/images");
    let mut names: Vec<String> = std::fs::read_dir(&coco)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.trim_end_matches(".jpg").parse::<u64>().is_ok_and(|id| id % 5 == 0))
        .collect();
    names.sort();
    names.truncate(COCO_PHOTOS);
    let own = detector("centerface.json", &fetched);
    let (mut y_ref, mut y_by_c, mut c_ref, mut c_by_y) = (0, 0, 0, 0);
    let crops = std::env::var_os("CROPS").map(PathBuf::from);
    for n in &names {
        let img = read_rgb8(&coco.join(n)).unwrap();
        let sets: Vec<Vec<[f32; 4]>> =
            guards.iter().map(|(_, g)| g.find(&img).unwrap().iter().map(|f| f.bbox).collect()).collect();
        for (d, set, other, (r, by)) in
            [(&reference, &sets[1], 0, (&mut y_ref, &mut y_by_c)), (&own, &sets[0], 1, (&mut c_ref, &mut c_by_y))]
        {
            for f in d.detect(&img).unwrap() {
                *r += 1;
                let found = holds(set, &f.bbox);
                *by += found as usize;
                if let (false, Some(dir)) = (found, &crops) {
                    let b = f.bbox.map(|v| v.max(0.0) as u32);
                    let (w, h) = ((b[2] - b[0]).max(1), (b[3] - b[1]).max(1));
                    let crop = image::imageops::crop_imm(&img, b[0], b[1], w, h).to_image();
                    std::fs::create_dir_all(dir).unwrap();
                    crop.save(dir.join(format!(
                        "{}-missed-by-{}-{n}-{}.png",
                        guards[other].0,
                        guards[other ^ 1].0,
                        b[0]
                    )))
                    .unwrap();
                }
            }
        }
    }
    println!(
        "\n{} held-out COCO people photos: of YuNet's {y_ref} faces (score >= its 0.6) CenterFace's guard found {y_by_c}; of CenterFace's {c_ref} (>= 0.5) YuNet's guard found {c_by_y}",
        names.len()
    );
    let pc = |c: u32, n: u32| format!("{c} ({:.1}%)", 100.0 * c as f64 / n.max(1) as f64);
    for (view, name) in ["raw", "enhanced (campro-omega-0.5)"].iter().enumerate() {
        println!("\n{name}:\n\n| face width | faces | YuNet | CenterFace | both |\n|---|---|---|---|---|");
        for (wi, w) in WIDTHS.iter().enumerate() {
            let (n, a, b, u) = table[view][wi];
            println!("| {w} px | {n} | {} | {} | {} |", pc(a, n), pc(b, n), pc(u, n));
        }
        let e = extra[view];
        println!(
            "\nfinds no pasted face explains: YuNet {} ({} of them missed by CenterFace), CenterFace {} ({} missed by YuNet)",
            e.0, e.1, e.2, e.3
        );
    }
}
