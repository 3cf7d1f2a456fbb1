//! Numerical stress: adversarial random cases and the invariants every path must keep.
//! The property tests (`tests/stress.rs`) and the soak (`campro stress --seconds N`) both
//! draw cases here and call [`check`], so they test the same things. (Feature `stress`:
//! not in the default build.)

use crate::ccm::{self, Mat3};
use crate::compare::random_pixels;
use crate::emulate::{DeviceModel, Emulator};
use crate::params::Params;
use crate::pipeline::fast::{Exact8, F32Path};
use crate::pipeline::{from_linear, Depth, Prepared};
use crate::targets::camera2::{self, Camera2Loop, ConvertError, Options, RationalMode, MATRIX_RANGE};
use crate::tone_curve::{ToneCurve, ToneCurves};

/// An invariant a stress case broke.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("seed {seed}: {what}")]
pub struct Invariant {
    /// The case's seed (rerun it with `campro stress --seed`).
    pub seed: u64,
    /// Which invariant, with the values.
    pub what: String,
}

/// One stress case.
#[derive(Debug, Clone)]
pub struct Case {
    /// The parameter set (adversarial CCM and curve).
    pub params: Params,
    /// The device transform.
    pub device: Mat3,
    /// Point budget and rational mode.
    pub opts: Options,
    /// The seed it was drawn from.
    pub seed: u64,
}

/// SplitMix64: small, seedable, good enough to spread cases.
#[derive(Debug, Clone)]
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// One of `v`, uniformly.
    pub fn pick<T: Copy>(&mut self, v: &[T]) -> T {
        v[(self.next_u64() % v.len() as u64) as usize]
    }
}

/// A CCM entry: often at the training clamp ±5, sometimes 0 or tiny, else uniform.
fn entry(r: &mut Rng) -> f64 {
    match r.next_u64() % 6 {
        0 => r.pick(&[5.0, -5.0]),
        1 => r.pick(&[0.0, 1e-12, -1e-12]),
        _ => r.range(-5.0, 5.0),
    }
}

/// A curve with jumps, plateaus, closely packed knots or plain noise.
fn curve(r: &mut Rng) -> ToneCurve {
    match r.next_u64() % 4 {
        0 => ToneCurve::uniform((0..32).map(|_| r.unit()).collect()).expect("valid"),
        1 => {
            // Plateaus and jumps: a staircase on a non-uniform grid with 1e-6-wide risers.
            let steps = 2 + (r.next_u64() % 6) as usize;
            let mut x = vec![0.0];
            let mut y = vec![r.unit()];
            for s in 1..steps {
                let at = s as f64 / steps as f64;
                x.extend([at, at + 1e-6]);
                y.extend([*y.last().expect("non-empty"), r.unit()]);
            }
            x.push(1.0);
            y.push(r.unit());
            ToneCurve::new(x, y).expect("valid staircase")
        }
        2 => {
            // Knots packed within 1e-4 near one spot, the rest sparse.
            let at = r.range(0.1, 0.9);
            let mut x: Vec<f64> = (0..20).map(|i| at + i as f64 * 5e-6).collect();
            x.extend([0.0, 1.0, r.range(0.0, 0.09), r.range(0.91, 0.999)]);
            x.sort_by(f64::total_cmp);
            x.dedup();
            let y = x.iter().map(|_| r.unit()).collect();
            ToneCurve::new(x, y).expect("valid packed curve")
        }
        _ => {
            let f = r.range(1.0, 30.0);
            ToneCurve::from_fn(2 + (r.next_u64() % 200) as usize, |t| (t * f).sin() * 0.5 + 0.5)
        }
    }
}

/// A device transform: a phone-like one, a near-singular one, or random.
fn device(r: &mut Rng) -> Mat3 {
    match r.next_u64() % 4 {
        0 => ccm::IDENTITY,
        1 => [[1.78, -0.62, -0.16], [-0.28, 1.62, -0.34], [0.02, -0.71, 1.69]],
        2 => {
            // Rows almost dependent (condition number ~1e9).
            let a = [r.range(0.5, 1.5), r.range(-0.5, 0.5), r.range(-0.5, 0.5)];
            [a, a.map(|v| v * (1.0 + 1e-9)), [r.unit(), r.unit(), r.unit()]]
        }
        _ => [[0.0; 3]; 3].map(|row: [f64; 3]| row.map(|_| r.range(-2.0, 3.0))),
    }
}

/// The case for `seed`.
pub fn random_case(seed: u64) -> Case {
    let mut r = Rng(seed);
    let ccm = [[0.0; 3]; 3].map(|row: [f64; 3]| row.map(|_| entry(&mut r)));
    let mut params =
        Params::new(ccm, curve(&mut r), r.pick(&[2.2, 2.2, 1.0, 2.4, 0.45])).expect("generated params are valid");
    params.name = format!("stress-{seed}");
    let rational = match r.next_u64() % 3 {
        0 => RationalMode::Best { max_denominator: r.pick(&[1, 2, 10, 256, 1 << 16, 1 << 24, i32::MAX as u32]) },
        1 => RationalMode::Fixed { denominator: r.pick(&[1, 100, 1024, 1 << 16, 1 << 20]) },
        _ => RationalMode::Best { max_denominator: 1 << 16 },
    };
    let opts = Options { max_curve_points: r.pick(&[2, 3, 8, 16, 64, 1024]), rational };
    let device = device(&mut r);
    // A third of the sets have a curve per channel (drawn last: the shared sets stay what
    // their seeds always gave).
    if r.next_u64().is_multiple_of(3) {
        let red = params.tone_curves.channel(0).clone();
        params.tone_curves = ToneCurves::per_channel([red, curve(&mut r), curve(&mut r)]);
    }
    Case { params, device, opts, seed }
}

/// What one checked case did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Converted; every invariant held.
    Converted,
    /// Refused with a named error (e.g. a rational that cannot fit 32 bits).
    Refused,
}

/// Checks every invariant on `case`; `Err` says which one broke and how.
pub fn check(case: &Case) -> Result<Outcome, Invariant> {
    let Case { params: p, device, opts, seed } = case;
    let fail = |what: String| Err(Invariant { seed: *seed, what });
    let v = match camera2::convert(p, device, opts) {
        Ok(v) => v,
        // A rational that cannot fit 32 bits, refused with the entry named.
        Err(e @ ConvertError::Rational { .. }) => {
            let msg = e.to_string();
            return if msg.starts_with("colorCorrectionTransform[") {
                Ok(Outcome::Refused)
            } else {
                fail(format!("unnamed error {msg}"))
            };
        }
        Err(e) => return fail(format!("unexpected error: {e}")),
    };
    // The values: finite, in range, rationals within their bound, a valid curve.
    let m = v.matrix();
    let (lo, hi) = ccm::min_max(&m);
    if !(lo >= MATRIX_RANGE.0 - 1e-9 && hi <= MATRIX_RANGE.1 + 1e-9) {
        return fail(format!("sent matrix outside Camera2's range: [{lo}, {hi}]"));
    }
    let per_entry = camera2::rational_error_bound(opts.rational);
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // a NaN error must fail the check too
    if !(v.report.matrix_max_abs <= per_entry * (1.0 + 1e-12) + 1e-15) {
        return fail(format!("rational error {} > 1/(2·den) = {per_entry}", v.report.matrix_max_abs));
    }
    if v.color_correction_transform.iter().skip(1).step_by(2).any(|&d| d <= 0) {
        return fail("non-positive denominator".into());
    }
    let sent = v.curves();
    for (c, sent) in sent.each().into_iter().enumerate() {
        if sent.len() > opts.max_curve_points || sent.y().iter().any(|y| !(0.0..=1.0).contains(y)) {
            return fail(format!("bad curve {c}: {} points, budget {}", sent.len(), opts.max_curve_points));
        }
    }
    if !v.report.bound.is_finite() {
        return fail("bound not finite".into());
    }
    // The stated bound holds on the emulated device, for sensor RGB in [0, 1]^3.
    let dev = camera2::device(v.matrix(), sent, &DeviceModel::default());
    let mut r = Rng(seed ^ 0xA5A5);
    for _ in 0..400 {
        let s = [r.unit(), r.unit(), r.unit()];
        let got = dev.sensor_to_output(s);
        let want = from_linear(p, ccm::apply(device, s));
        for k in 0..3 {
            if !got[k].is_finite() || !(0.0..=1.0).contains(&got[k]) {
                return fail(format!("device output {got:?} not in [0, 1]"));
            }
            if (got[k] - want[k]).abs() > v.report.bound + 1e-9 {
                return fail(format!("|device - desktop| = {} > bound {}", (got[k] - want[k]).abs(), v.report.bound));
            }
        }
    }
    // The camera loop: an unchanged scene skips; a moved one stays within what it states.
    let loop_err = |e: &dyn std::fmt::Display| Invariant { seed: *seed, what: format!("camera loop: {e}") };
    let mut l = Camera2Loop::new(p.clone(), *opts, 1.0 / 255.0).map_err(|e| loop_err(&e))?;
    l.update(device).map_err(|e| loop_err(&e))?;
    if l.update(device).map_err(|e| loop_err(&e))?.recomputed {
        return fail("an unchanged device transform recomputed".into());
    }
    // Fast image paths against the reference.
    let reference = Prepared::new(p, Depth::Eight);
    let exact = Exact8::new(p);
    let f32p = F32Path::new(p, Depth::Eight);
    let pixels = random_pixels(2000, *seed);
    let src: Vec<u8> = pixels.iter().flatten().copied().collect();
    let mut run_out = vec![0u8; src.len()];
    exact.run(&src, &mut run_out); // the block engine (AVX-512 where the CPU has it)
    for (px, got) in pixels.into_iter().zip(run_out.chunks_exact(3)) {
        let want = reference.pixel(px.map(u16::from));
        let q = want.map(|x| (x * 255.0 + 0.5) as u8);
        if exact.pixel(px) != q || got != q {
            return fail(format!(
                "exact 8-bit path differs at {px:?}: {:?} / {got:?} ({:?}) vs {q:?}",
                exact.pixel(px),
                exact.engine()
            ));
        }
        let g = f32p.pixel(px.map(u16::from));
        for k in 0..3 {
            if (g[k] as f64 - want[k]).abs() > f32p.error_bound() {
                return fail(format!(
                    "f32 path error {} > its bound {}",
                    (g[k] as f64 - want[k]).abs(),
                    f32p.error_bound()
                ));
            }
        }
    }
    Ok(Outcome::Converted)
}
