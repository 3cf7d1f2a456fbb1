//! Every fast path against the f64 reference, over every 8-bit code triple (2^24) or
//! dense 16-bit samples, held to its stated error.

use campro::compare::random_pixels;
use campro::pipeline::fast::{Engine, Exact8, F32Path};
use campro::pipeline::{Depth, Prepared};
use campro::{Params, ToneCurve, ToneCurves};

fn all_triples() -> Vec<u8> {
    let mut v = Vec::with_capacity(3 << 24);
    for r in 0..=255u8 {
        for g in 0..=255u8 {
            for b in 0..=255u8 {
                v.extend([r, g, b]);
            }
        }
    }
    v
}

/// Like the paper's strong checkpoints: entries near ±5, a jagged curve (slopes ~30).
fn strong() -> Params {
    let m = [[1.2101, 0.0430, -4.6679], [-4.3933, 4.1114, -2.2755], [0.2930, -3.3570, 4.9287]];
    let jag = ToneCurve::uniform(
        (0..32).map(|i| if i % 2 == 0 { 0.05 * (i % 7) as f64 } else { 1.0 - 0.03 * i as f64 }).collect(),
    )
    .unwrap();
    Params::new(m, jag, 2.2).unwrap()
}

fn sets() -> Vec<Params> {
    // Every bundled set (params/*.json), in name order.
    let mut files: Vec<_> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/params"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    let mut v: Vec<Params> = files.iter().map(|f| Params::from_file(f).unwrap()).collect();
    v.push(strong());
    // Jumps and plateaus on a non-uniform grid.
    let steps = ToneCurve::new(vec![0.0, 0.2, 0.2001, 0.5, 0.50001, 1.0], vec![0.0, 0.0, 1.0, 1.0, 0.3, 0.9]).unwrap();
    v.push(Params::new([[0.9, 0.2, -0.1], [0.1, 0.8, 0.1], [-0.2, 0.1, 1.1]], steps, 2.2).unwrap());
    // 17 uniform knots (table slots 16..31 are the end's) under a matrix that clips far
    // past both ends: the block engine's segment index is clamped as an integer.
    let short = ToneCurve::from_fn(17, |t| 0.5 + 0.45 * (9.0 * t).sin());
    v.push(Params::new([[2.5, 1.5, -1.0], [-2.0, 3.0, 1.0], [1.0, -3.0, 4.0]], short, 2.2).unwrap());
    // 2, 30 and 31 knots (the engine's end slots: 2 and 30 have separate ones, 31 shares
    // one between both ends, like 32), matrices clipping at both ends.
    for (k, ccm) in [
        (2, [[1.8, -0.9, 0.4], [-1.2, 2.6, -0.7], [0.3, -1.5, 2.9]]),
        (30, [[-2.0, 4.0, -1.0], [3.5, -3.0, 1.5], [0.5, 0.5, -0.8]]),
        (31, [[4.9, -4.9, 1.0], [-0.4, 1.1, 0.2], [2.0, 2.0, -3.5]]),
    ] {
        let c = ToneCurve::from_fn(k, |t| 0.5 + 0.45 * (11.0 * t + 0.3).sin());
        v.push(Params::new(ccm, c, 2.2).unwrap());
    }
    // A curve per channel (the version 2 format): 64 knots each (Camera2's guaranteed
    // budget), different shapes, under the strong matrix (red starts on a rounding tie,
    // 0.5: every pixel clipped to 0 there is decided in f64); and 32 knots where two channels
    // share a curve and the third is jagged.
    let wave = |k: usize, f: f64, phase: f64| ToneCurve::from_fn(k, move |t| 0.5 + 0.48 * (f * t + phase).sin());
    let three = ToneCurves::per_channel([wave(64, 13.0, 0.0), wave(64, 5.0, 1.0), ToneCurve::from_fn(64, |t| 1.0 - t)]);
    let mut p = Params::new(strong().ccm, three, 2.2).unwrap();
    p.name = "per-channel-64".into();
    v.push(p);
    let jagged = strong().tone_curves.channel(0).clone();
    let two = ToneCurves::per_channel([wave(32, 7.0, 0.5), jagged, wave(32, 7.0, 0.5)]);
    let mut p = Params::new([[0.9, 0.2, -0.1], [0.1, 0.8, 0.1], [-0.2, 0.1, 1.1]], two, 2.2).unwrap();
    p.name = "per-channel-32".into();
    v.push(p);
    v
}

#[test]
fn exact8_is_bit_identical_to_the_reference_on_every_code_triple() {
    let src = all_triples();
    let src16: Vec<u16> = src.iter().map(|&v| v as u16).collect();
    let mut want = vec![0u16; src.len()];
    let mut got = vec![0u8; src.len()];
    for p in sets() {
        Prepared::new(&p, Depth::Eight).run(&src16, &mut want, Depth::Eight);
        // Every engine that runs on this CPU for these parameters.
        let mut flagged = Vec::new();
        for fast in every_engine(&p) {
            let fell = fast.run(&src, &mut got);
            flagged.push((fast.engine(), fell.flagged));
            let diff = want.iter().zip(&got).filter(|(a, b)| **a != **b as u16).count();
            assert_eq!(diff, 0, "{} ({:?}): {diff} samples differ", p.name, fast.engine());
            let n = (1 << 24) as f64;
            eprintln!(
                "{} ({:?}): {:.3}% of pixels flagged by the engine, {:.3}% to the reference in the tables ({:.2}% of cells ambiguous, {:.2}% split)",
                p.name,
                fast.engine(),
                100.0 * fell.flagged as f64 / n,
                100.0 * fell.ambiguous as f64 / n,
                100.0 * fast.fallback_fraction(),
                100.0 * fast.split_fraction()
            );
        }
        // The AVX2 engine on the line tables computes the AVX-512 engine's values lane for
        // lane: it flags the same pixels.
        if let [.., (Engine::Avx2, a), (Engine::Avx512, b)] = flagged[..] {
            assert_eq!(a, b, "{}: AVX2 and AVX-512 flag different pixels", p.name);
        }
    }
}

/// The path on every engine this CPU runs for `p`.
fn every_engine(p: &Params) -> Vec<Exact8<'_>> {
    Engine::ALL.into_iter().filter_map(|e| Exact8::new(p).with_engine(e)).collect()
}

fn avx512_cpu() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        ["avx512f", "avx512bw", "avx512dq", "avx512vbmi"].iter().all(|f| match *f {
            "avx512f" => is_x86_feature_detected!("avx512f"),
            "avx512bw" => is_x86_feature_detected!("avx512bw"),
            "avx512dq" => is_x86_feature_detected!("avx512dq"),
            _ => is_x86_feature_detected!("avx512vbmi"),
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

#[test]
fn block_engine_is_chosen_where_it_applies() {
    let s = sets();
    let tables = |e: Engine| matches!(e, Engine::Scalar | Engine::Avx2);
    for p in &s[..4] {
        let e = Exact8::new(p).engine();
        assert!(if avx512_cpu() { e == Engine::Avx512 } else { tables(e) }, "{}: {e:?}", p.name);
        assert_eq!(Exact8::new(p).scalar().engine(), Engine::Scalar);
        assert_eq!(Exact8::new(p).with_engine(Engine::Avx512).is_some(), avx512_cpu());
    }
    // Non-uniform knots, or more than 32: the tables (AVX2 or scalar), never AVX-512. (Found
    // by its knots, not an index: an index into the list went stale when presets were added, and the
    // assertion only bites on an AVX-512 machine.)
    let steps = s.iter().find(|p| !p.tone_curves.channel(0).is_uniform()).expect("a set with non-uniform knots");
    assert!(tables(Exact8::new(steps).engine()));
    assert!(Exact8::new(steps).with_engine(Engine::Avx512).is_none());
    let fine = Params::new(campro::ccm::IDENTITY, ToneCurve::from_fn(33, |t| t * t), 2.2).unwrap();
    assert!(tables(Exact8::new(&fine).engine()));
}

/// A curve ending exactly on a rounding tie (255 · 0.5 = 127.5) at either end, and a
/// matrix that clips every pixel at that end: all outputs are the end's code, and the
/// block engine answers them itself instead of flagging every pixel.
#[test]
fn clipped_pixels_at_a_tie_end_stay_in_the_block_engine() {
    let frame = campro_testkit::bench::test_frame(320, 64);
    let half = |low: bool| ToneCurve::from_fn(32, move |t| if low { 0.5 + 0.3 * t } else { 0.8 - 0.3 * t });
    let neg = [[-1.0, -0.5, -0.2], [-0.3, -1.0, 0.0], [0.0, -0.2, -1.0]];
    let big = [[3.0, 2.0, 2.0], [2.0, 3.0, 2.0], [2.0, 2.0, 3.0]];
    for (name, ccm, low) in [("clip low, y(0) = 0.5", neg, true), ("clip high, y(1) = 0.5", big, false)] {
        let p = Params::new(ccm, half(low), 2.2).unwrap();
        for f in every_engine(&p) {
            let mut out = vec![0u8; frame.len()];
            let fell = f.run(&frame, &mut out);
            let reference = Prepared::new(&p, Depth::Eight);
            for (s, o) in frame.chunks_exact(3).zip(out.chunks_exact(3)) {
                let want = reference.pixel([s[0], s[1], s[2]].map(u16::from)).map(|v| (v * 255.0 + 0.5) as u8);
                assert_eq!(o, want, "{name} ({:?}): pixel {s:?}", f.engine());
            }
            // Pixels with a zero code in some channel do not clip (0 · anything = 0 is the
            // boundary itself), so a few may still be flagged.
            if f.engine() != Engine::Scalar {
                assert!(
                    fell.flagged * 100 < frame.len() / 3,
                    "{name} ({:?}): {} of {} pixels flagged",
                    f.engine(),
                    fell.flagged,
                    frame.len() / 3
                );
            }
        }
    }
}

/// Every uniform knot count the block engine takes (2..=32), with both ends of the curve
/// on a rounding tie and a matrix that clips pixels past both ends: bit-identical to the
/// reference, and the clipped pixels stay in the engine (its end slots) instead of all
/// being flagged.
#[test]
fn every_knot_count_is_exact_with_both_ends_clipped_on_a_tie() {
    let mut px = campro_testkit::bench::test_frame(256, 64);
    px.extend(random_pixels(20_000, 11).into_iter().flatten());
    let ccm = [[3.0, -2.5, 0.5], [-2.0, 3.5, -1.0], [0.6, -3.0, 3.2]];
    let mut out = vec![0u8; px.len()];
    for k in 2..=32 {
        // y = 0.5 at both ends (255 · 0.5 = 127.5, which rounds up to 128), above it in
        // between, so that the code just inside either end is 128 too.
        let c = ToneCurve::from_fn(k, |t| if t == 0.0 || t == 1.0 { 0.5 } else { 0.5 + 1.6 * t * (1.0 - t) });
        let p = Params::new(ccm, c, 2.2).unwrap();
        let reference = Prepared::new(&p, Depth::Eight);
        for f in every_engine(&p) {
            let fell = f.run(&px, &mut out);
            let mut clipped = 0;
            for (s, o) in px.chunks_exact(3).zip(out.chunks_exact(3)) {
                let want = reference.pixel([s[0], s[1], s[2]].map(u16::from)).map(|v| (v * 255.0 + 0.5) as u8);
                assert_eq!(o, want, "{k} knots ({:?}): pixel {s:?}", f.engine());
                clipped += want.contains(&128) as usize;
            }
            let n = px.len() / 3;
            assert!(clipped * 5 > n, "{k} knots: only {clipped} of {n} pixels clip");
            // (Two knots on a tie are a constant curve on the tie: every pixel is flagged.)
            if f.engine() != Engine::Scalar && k > 2 {
                assert!(fell.flagged * 20 < n, "{k} knots ({:?}): {} of {n} pixels flagged", f.engine(), fell.flagged);
            }
        }
    }
}

/// 31 and 32 knots, where both clamped ends share one table slot (a line through both
/// end values): one end's code is the same over its last stretch of input, the other end
/// sits on a rounding tie that the curve crosses just before it (so pixels clipped there
/// must be redone), and the matrix rows' error bounds differ widely (row sums 0.6 to 9).
#[test]
fn shared_end_slot_with_one_ambiguous_end_stays_exact() {
    let mut px = campro_testkit::bench::test_frame(256, 64);
    px.extend(random_pixels(20_000, 3).into_iter().flatten());
    let ccm = [[0.3, 0.2, 0.1], [4.5, -3.0, 1.5], [-1.0, 3.0, -0.5]];
    let mut out = vec![0u8; px.len()];
    for k in [31, 32] {
        for top_tie in [true, false] {
            // The tied end is y = 0.5 (127.5 rounds up to 128) approached from below
            // (127.x rounds to 127 just inside it); the other end is a plain 0.12 or 0.15.
            let c = ToneCurve::from_fn(k, |t| match (top_tie, t) {
                (true, 1.0) | (false, 0.0) => 0.5,
                (true, _) => 0.12 + 0.36 * t,
                (false, _) => 0.45 - 0.3 * t,
            });
            let p = Params::new(ccm, c, 2.2).unwrap();
            let reference = Prepared::new(&p, Depth::Eight);
            for f in every_engine(&p) {
                f.run(&px, &mut out);
                for (s, o) in px.chunks_exact(3).zip(out.chunks_exact(3)) {
                    let want = reference.pixel([s[0], s[1], s[2]].map(u16::from)).map(|v| (v * 255.0 + 0.5) as u8);
                    assert_eq!(
                        o,
                        want,
                        "{k} knots, tie at the {} end ({:?}): pixel {s:?}",
                        if top_tie { "top" } else { "bottom" },
                        f.engine()
                    );
                }
            }
        }
    }
}

#[test]
fn block_engine_handles_any_length_and_alignment() {
    let p = &strong();
    let reference = Prepared::new(p, Depth::Eight);
    let px: Vec<u8> = random_pixels(1001, 5).into_iter().flatten().collect();
    for f in every_engine(p) {
        for (start, len) in [(0, 1001), (1, 1000), (7, 64), (3, 63), (0, 0), (5, 129), (2, 7), (4, 9)] {
            let src = &px[3 * start..3 * (start + len)];
            let mut out = vec![0u8; src.len()];
            f.run(src, &mut out);
            for (s, o) in src.chunks_exact(3).zip(out.chunks_exact(3)) {
                let want = reference.pixel([s[0], s[1], s[2]].map(u16::from)).map(|v| (v * 255.0 + 0.5) as u8);
                assert_eq!(o, want, "start {start} len {len} ({:?}): pixel {s:?}", f.engine());
            }
        }
    }
}

#[test]
fn exact8_falls_back_rarely_for_gentle_curves() {
    // Colour inversion: slope up to ~6 near black.
    let p =
        &Params::from_file(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/params/color-inversion.json")))
            .unwrap();
    let f = Exact8::new(p);
    assert!(f.fallback_fraction() < 0.05, "{}", f.fallback_fraction());
}

#[test]
fn f32_path_within_half_an_lsb_plus_its_bound() {
    let src: Vec<u8> = all_triples().into_iter().step_by(7).collect::<Vec<_>>();
    let src: Vec<u8> = src[..src.len() / 3 * 3].to_vec();
    for p in sets() {
        let reference = Prepared::new(&p, Depth::Eight);
        let f = F32Path::new(&p, Depth::Eight);
        let mut worst: f64 = 0.0;
        for px in src.chunks_exact(3) {
            let want = reference.pixel([px[0] as u16, px[1] as u16, px[2] as u16]);
            let got = f.pixel([px[0] as u16, px[1] as u16, px[2] as u16]);
            for k in 0..3 {
                worst = worst.max((got[k] as f64 - want[k]).abs());
            }
        }
        assert!(worst <= f.error_bound(), "{}: measured {worst} > bound {}", p.name, f.error_bound());
        // Rounded to 8 bits: within 0.5 LSB plus the bound.
        let mut out = vec![0u8; src.len()];
        f.run(&src, &mut out, Depth::Eight);
        for (px, o) in src.chunks_exact(3).zip(out.chunks_exact(3)) {
            let want = reference.pixel([px[0] as u16, px[1] as u16, px[2] as u16]);
            for k in 0..3 {
                assert!((o[k] as f64 - want[k] * 255.0).abs() <= 0.5 + f.error_bound() * 255.0 + 1e-9);
            }
        }
    }
}

#[test]
fn f32_path_on_16_bit_input() {
    for p in sets() {
        let reference = Prepared::new(&p, Depth::Sixteen);
        let f = F32Path::new(&p, Depth::Sixteen);
        let px: Vec<u16> = random_pixels(200_000, 9)
            .iter()
            .zip(random_pixels(200_000, 10))
            .flat_map(|(a, b)| [0, 1, 2].map(|k| (a[k] as u16) << 8 | b[k] as u16))
            .collect();
        let mut out = vec![0u16; px.len()];
        f.run(&px, &mut out, Depth::Sixteen);
        for (s, o) in px.chunks_exact(3).zip(out.chunks_exact(3)) {
            let want = reference.pixel([s[0], s[1], s[2]]);
            for k in 0..3 {
                let e = (o[k] as f64 - want[k] * 65535.0).abs();
                assert!(e <= 0.5 + f.error_bound() * 65535.0 + 1e-6, "{}: {e} LSB16", p.name);
            }
        }
    }
}

#[test]
fn run_reuse_gives_the_same_image() {
    let frame = campro_testkit::bench::test_frame(640, 360);
    for p in sets() {
        let f = Exact8::new(&p);
        let (mut a, mut b) = (vec![0u8; frame.len()], vec![0u8; frame.len()]);
        f.run(&frame, &mut a);
        f.run_reusing_repeats(&frame, &mut b);
        assert_eq!(a, b, "{}", p.name);
    }
}

#[test]
fn lut3d_errors_within_their_bound_and_shrink_with_size() {
    use campro::lut3d::{Interp, Lut3d};
    let px = campro::compare::random_pixels(300_000, 4);
    for p in sets().into_iter().take(4) {
        let reference = Prepared::new(&p, Depth::Eight);
        let want: Vec<[f64; 3]> = px.iter().map(|c| reference.pixel(c.map(u16::from))).collect();
        for interp in [Interp::Trilinear, Interp::Tetrahedral] {
            let mut prev = f64::INFINITY;
            for n in [17, 33, 65] {
                let lut = Lut3d::bake(&p, n);
                let worst = px
                    .iter()
                    .zip(&want)
                    .map(|(c, w)| {
                        let g = lut.eval(c.map(|v| v as f32 / 255.0), interp);
                        (0..3).map(|k| (g[k] as f64 - w[k]).abs()).fold(0.0, f64::max)
                    })
                    .fold(0.0, f64::max);
                assert!(worst <= lut.error_bound(), "{} {interp:?} {n}: {worst} > {}", p.name, lut.error_bound());
                assert!(
                    worst <= prev * 1.05 + 1e-6,
                    "{} {interp:?}: error grew with size ({prev} -> {worst} at {n})",
                    p.name
                );
                prev = worst;
            }
        }
    }
}
