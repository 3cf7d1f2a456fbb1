//! The face guard's recall on small faces, and why its pyramid starts enlarged: LFW faces
//! pasted at 10 to 20 pixels wide (the detector's box) in rows across a 1280 x 720 COCO
//! scene, three placements a width; a face counts as found when a detection's box holds its
//! centre. Columns: YuNet at the image's own scale (640 x 640 tiles), on the image enlarged
//! 1.6x (the guard's first level, 640 x 640 tiles), and the guard itself (every level, its
//! own tiles, threshold [`THRESHOLD`]). Reads `CAMPRO_SHARED` or `../shared`; about 5
//! minutes on 2 cores.
//!
//! `cargo run --release -p campro-eval --example guard_recall`

use campro_eval::data::read_rgb8;
use campro_eval::face::{central_face, FaceDetector};
use campro_eval::geometry::resize_bilinear;
use campro_eval::guard::{tiles, FaceGuard, Hide, THRESHOLD};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use campro_eval::place::{paste, pasted_side};
use image::RgbImage;
use std::path::{Path, PathBuf};

/// Boxes YuNet finds in `img` scaled by `s`, over 640 x 640 tiles, in `img`'s pixels.
fn boxes(det: &FaceDetector, img: &RgbImage, s: f64) -> Vec<[f32; 4]> {
    let (w, h) = ((img.width() as f64 * s).round() as u32, (img.height() as f64 * s).round() as u32);
    let level = resize_bilinear(img, w, h);
    let mut out = vec![];
    for (x, _) in tiles(w as usize, 640) {
        for (y, _) in tiles(h as usize, 640) {
            let (x, y) = (x as u32, y as u32);
            let tile = image::imageops::crop_imm(&level, x, y, 640.min(w - x), 640.min(h - y)).to_image();
            for f in det.detect_scaled(&tile, 1.0, THRESHOLD).unwrap() {
                let b = f.bbox;
                let k = s as f32;
                out.push([(b[0] + x as f32) / k, (b[1] + y as f32) / k, (b[2] + x as f32) / k, (b[3] + y as f32) / k]);
            }
        }
    }
    out
}

fn main() {
    let shared = std::env::var_os("CAMPRO_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/yunet.json");
    let load =
        || FaceDetector::new(Model::load(Manifest::load(&manifest, &shared.join("models")).unwrap()).unwrap()).unwrap();
    let (det, guard) = (load(), FaceGuard::new(load(), Hide::Pixelate));
    let root = shared.join("data/lfw/images_deepfunneled");
    let mut people: Vec<String> =
        std::fs::read_dir(&root).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    people.sort();
    let scene = read_rgb8(&shared.join("data/coco-person/images/000000000802.jpg")).unwrap();
    let scene = image::imageops::resize(&scene, 1280, 720, image::imageops::FilterType::Triangle);
    println!("| face width | faces | found at 1x | at 1.6x | by the guard |\n|---|---|---|---|---|");
    let mut k = 0usize;
    for width in [10u32, 11, 12, 13, 14, 16, 20] {
        let (mut n, mut found) = (0u32, [0u32; 3]);
        for round in 0..3 {
            let mut img = scene.clone();
            let mut pasted = vec![];
            let side = pasted_side(width) + 12;
            let mut y = 8 + round * 3;
            while y + side < 720 {
                let mut x = 8 + round * 5;
                while x + side < 1280 {
                    let p = &people[(k * 37) % people.len()];
                    k += 1;
                    let photo = read_rgb8(&root.join(format!("{p}/{p}_0001.jpg"))).unwrap();
                    if let Some(f) = central_face(&det.detect(&photo).unwrap(), photo.width(), photo.height()) {
                        pasted.push(paste(&mut img, &photo, &f, width as f32, x as i64, y as i64).bbox);
                    }
                    x += side + 6 * side / 4;
                }
                y += 2 * side;
            }
            let guarded: Vec<[f32; 4]> = guard.find(&img).unwrap().iter().map(|f| f.bbox).collect();
            let sets = [boxes(&det, &img, 1.0), boxes(&det, &img, 1.6), guarded];
            for p in &pasted {
                let (cx, cy) = ((p[0] + p[2]) / 2.0, (p[1] + p[3]) / 2.0);
                n += 1;
                for (count, set) in found.iter_mut().zip(&sets) {
                    *count += set.iter().any(|b| cx > b[0] && cx < b[2] && cy > b[1] && cy < b[3]) as u32;
                }
            }
        }
        let pc = |c: u32| format!("{c} ({:.1}%)", 100.0 * c as f64 / n as f64);
        println!("| {width} px | {n} | {} | {} | {} |", pc(found[0]), pc(found[1]), pc(found[2]));
    }
}
