//! Times the default exact 8-bit path against a copy on one 1080p frame (one thread):
//! `cargo run --release --example exact8_time [-- RUNS [PARAMS.json]]` (`CAMPRO_ENGINE`
//! picks the engine). Medians of the same run.
use campro::pipeline::fast::Exact8;
use campro_testkit::bench::{bench_params, median_seconds as median, test_frame};
use std::hint::black_box;

fn main() {
    let runs: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(201);
    let p = match std::env::args().nth(2) {
        Some(path) => campro::Params::from_json(&std::fs::read_to_string(&path).expect("a readable file"))
            .expect("a parameter file"),
        None => bench_params(),
    };
    let frame = test_frame(1920, 1080);
    let mut out = vec![0u8; frame.len()];
    let exact = Exact8::new(&p);
    let mut fell = Default::default();
    let copy = median(runs, || out.copy_from_slice(black_box(&frame)));
    let t = median(runs, || fell = exact.run(black_box(&frame), &mut out));
    println!(
        "copy {:.3} ms, exact8 ({:?}) {:.3} ms = {:.2}x copy, {:?}",
        copy * 1e3,
        exact.engine(),
        t * 1e3,
        t / copy,
        fell
    );
}
