//! The benchmarks' inputs and timer: one parameter set, one synthetic frame, medians
//! (`cargo bench` and `campro bench`; feature `stress`: not in the default build).

use crate::{Params, ToneCurve};

/// The benchmarks' parameter set ("bench"), like the paper's strong checkpoints: CCM
/// entries to ±4.4 and a 32-knot curve with slopes to 3.5.
pub fn bench_params() -> Params {
    let ccm = [[1.2101, 0.0430, -0.6679], [-4.3933, 1.1114, -2.2755], [0.2930, 1.3570, 1.3287]];
    let mut p = Params::new(ccm, ToneCurve::from_fn(32, |t| (7.0 * t).sin() * 0.5 + 0.5), 2.2).expect("valid");
    p.name = "bench".into();
    p
}

/// Median seconds of `f` over `runs` runs, after one warm-up run (the benchmarks' timer:
/// medians, since the machines they run on are shared and noisy).
pub fn median_seconds(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let s = std::time::Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// A `w` x `h` interleaved RGB8 test frame that looks like a photo to a cache: smooth
/// colour gradients, a few flat regions and fine texture (deterministic).
pub fn test_frame(w: usize, h: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(w * h * 3);
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for y in 0..h {
        for x in 0..w {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let noise = ((state >> 59) as i32) - 16; // texture, ±16 codes
            let (u, v) = (x as f64 / w as f64, y as f64 / h as f64);
            let flat = (x / 240 + y / 270) % 5 == 0; // flat patches (walls, sky)
            let base = if flat {
                [0.8, 0.75, 0.7]
            } else {
                [0.5 + 0.4 * (6.0 * u).sin(), 0.5 + 0.4 * (5.0 * v + 1.0).sin(), 0.5 + 0.4 * (4.0 * (u + v)).cos()]
            };
            for c in base {
                let n = if flat { 0 } else { noise };
                out.push(((c * 255.0) as i32 + n).clamp(0, 255) as u8);
            }
        }
    }
    out
}
