use campro::compare::test_frame;
use campro::pipeline::fast::{Exact8, F32Path};
use campro::pipeline::Depth;
use campro::{Params, ToneCurve};
fn main() {
    let ccm = [[1.2101, 0.0430, -0.6679], [-4.3933, 1.1114, -2.2755], [0.2930, 1.3570, 1.3287]];
    let p = Params::new(ccm, ToneCurve::from_fn(32, |t| (7.0 * t).sin() * 0.5 + 0.5), 2.2).unwrap();
    let src = test_frame(1920, 1080);
    let mut dst = vec![0u8; src.len()];
    let e = Exact8::new(&p);
    let f = F32Path::new(&p, Depth::Eight);
    for _ in 0..3 {
        let t = std::time::Instant::now();
        let slow = e.run(&src, &mut dst);
        println!("exact8 {:?} fallback px {slow} cells {:.3}", t.elapsed(), e.fallback_fraction());
        let t = std::time::Instant::now();
        e.run_runs(&src, &mut dst);
        println!("exact8 runs {:?}", t.elapsed());
        let t = std::time::Instant::now();
        f.run(&src, &mut dst, Depth::Eight);
        println!("f32 {:?}", t.elapsed());
        let t = std::time::Instant::now();
        dst.copy_from_slice(&src);
        println!("copy {:?}", t.elapsed());
    }
}
