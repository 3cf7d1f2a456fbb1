//! `cargo bench`: Camera2 conversion per update and the desktop pipeline per frame,
//! against a plain copy of the same frame measured in the same run. `campro bench`
//! prints the same rows with their errors as one table.

use campro::ccm;
use campro::pipeline::fast::{Exact8, F32Path};
use campro::pipeline::{Depth, Prepared};
use campro::targets::camera2::{convert, Options};
use campro::targets::camera2::{Camera2Loop, DEFAULT_TOLERANCE};
use campro::Params;
use campro_testkit::bench::test_frame;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;

const PHONE: campro::Mat3 = [[1.78, -0.62, -0.16], [-0.28, 1.62, -0.34], [0.02, -0.71, 1.69]];

fn params() -> Params {
    campro_testkit::bench::bench_params()
}

fn bench_convert(c: &mut Criterion) {
    let p = params();
    let mut g = c.benchmark_group("convert");
    g.bench_function("camera2 (32 knots, scaled)", |b| {
        b.iter(|| convert(black_box(&p), black_box(&PHONE), &Options::default()).unwrap())
    });
    g.bench_function("camera2 (32 knots -> 16 points)", |b| {
        let o = Options { max_curve_points: 16, ..Options::default() };
        b.iter(|| convert(black_box(&p), black_box(&PHONE), &o).unwrap())
    });
    let id = Params::identity_curve(32);
    g.bench_function("camera2 (identity)", |b| {
        b.iter(|| convert(black_box(&id), black_box(&ccm::IDENTITY), &Options::default()).unwrap())
    });
    g.bench_function("loop update, scene unchanged (skip)", |b| {
        let mut l = Camera2Loop::new(p.clone(), Options::default(), DEFAULT_TOLERANCE).unwrap();
        l.update(&PHONE).unwrap();
        b.iter(|| l.update(black_box(&PHONE)).unwrap().recomputed)
    });
    g.bench_function("loop update, scene moved (recompute, cached curve)", |b| {
        let mut l = Camera2Loop::new(p.clone(), Options::default(), 0.0).unwrap();
        let mut other = PHONE;
        other[0][0] += 0.01;
        let mut k = 0u32;
        b.iter(|| {
            k += 1;
            l.update(black_box(if k.is_multiple_of(2) { &PHONE } else { &other })).unwrap().recomputed
        })
    });
    g.finish();
}

fn bench_simulate(c: &mut Criterion) {
    let p = params();
    let (w, h) = (1920usize, 1080usize);
    let src8 = test_frame(w, h);
    let src: Vec<u16> = src8.iter().map(|&v| v as u16).collect();
    let mut dst = vec![0u16; src.len()];
    let mut dst8 = vec![0u8; src8.len()];
    let prep = Prepared::new(&p, Depth::Eight);
    let exact = Exact8::new(&p);
    let scalar = Exact8::new(&p).scalar();
    let f32p = F32Path::new(&p, Depth::Eight);
    let mut g = c.benchmark_group("simulate 1080p");
    g.throughput(Throughput::Elements((w * h) as u64));
    g.sample_size(10);
    g.bench_function("copy (baseline)", |b| b.iter(|| dst8.copy_from_slice(black_box(&src8))));
    g.bench_function("f64 reference, 1 thread", |b| b.iter(|| prep.run(black_box(&src), &mut dst, Depth::Eight)));
    g.bench_function(format!("exact 8-bit ({:?} engine), 1 thread", exact.engine()), |b| {
        b.iter(|| exact.run(black_box(&src8), &mut dst8))
    });
    g.bench_function("exact 8-bit scalar tables, 1 thread", |b| b.iter(|| scalar.run(black_box(&src8), &mut dst8)));
    g.bench_function("f32, 1 thread", |b| b.iter(|| f32p.run(black_box(&src8), &mut dst8, Depth::Eight)));
    g.finish();
}

criterion_group!(benches, bench_convert, bench_simulate);
criterion_main!(benches);
