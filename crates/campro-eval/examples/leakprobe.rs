use campro_eval::data::{read_rgb8, Lfw};
use campro_eval::face::{central_face, Embedder, FaceDetector};
use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use rayon::prelude::*;
use std::path::Path;
fn rss() -> usize { std::fs::read_to_string("/proc/self/statm").unwrap().split_whitespace().nth(1).unwrap().parse::<usize>().unwrap() * 4 / 1024 }
fn load(n: &str) -> Model { Model::load(Manifest::load(Path::new(&format!("crates/campro-eval/models/{n}.json")), Path::new("../shared/models")).unwrap()).unwrap() }
fn main() {
    let n: usize = std::env::args().nth(1).unwrap().parse().unwrap();
    let which: Vec<String> = std::env::args().skip(2).collect();
    let lfw = Lfw::open(Path::new("../shared/data/lfw")).unwrap();
    let det = FaceDetector::new(load("yunet")).unwrap();
    let embs: Vec<Embedder> = which.iter().map(|w| Embedder::new(load(w)).unwrap()).collect();
    let paths: Vec<_> = lfw.people.values().flatten().take(n).collect();
    let store = std::sync::Mutex::new(Vec::new());
    paths.par_iter().for_each(|p| {
        let img = read_rgb8(p).unwrap();
        if let Some(f) = central_face(&det.detect(&img).unwrap(), img.width(), img.height()) {
            let e: Vec<Vec<f32>> = embs.iter().map(|e| e.embed(&e.align(&img, &f.landmarks)).unwrap()).collect();
            store.lock().unwrap().push(e);
        }
    });
    println!("{n} photos {which:?}: {} MB", rss());
}
