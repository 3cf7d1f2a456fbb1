//! The AVX-512 engine of [`super::Exact8`] (x86-64 with AVX-512 F, BW, DQ and VBMI,
//! checked at run time): 64 pixels per step and no gathers, every table lookup is a
//! register permute. Each stretch of blocks runs in two passes over an L1 scratch, so
//! each pass keeps its own tables in registers and its chains short:
//!
//! - Pass 1, deinterleave: 192 bytes of RGB become three 64-byte planes (two byte
//!   permutes each). Degamma: the f32 table over the 256 input codes is held as four byte
//!   planes of 256 bytes; each plane is looked up for 64 pixels at once (two merge-masked
//!   `vpermi2b`, one per half of the plane), and the bytes are re-assembled into f32 lanes
//!   by unpacks.
//! - Pass 2, matrix: `x' = CCM · (k - 1) · v - h` in f32 by FMA (x' is the curve input in
//!   segment units, offset by the half-integer h of [`half`]), clamped to [-h, h] by one
//!   `vrangeps` (absolute minimum, sign kept).
//! - Curve: uniform knots only (k <= 32). Rounding x' to the nearest integer n picks the
//!   segment (h is a half-integer, so each open segment is one n) and `n mod 32` the table
//!   slot: its slope and intercept (pre-scaled by 255, so `w = b + x' · a` is the curve in
//!   output LSB) come from two `vpermt2ps`, one FMA evaluates. The clamped ends round onto
//!   slots of their own (see [`slots`]).
//! - Output: the tables are pre-scaled by 2^16 and shifted by `0.5 + E_c` (output channel
//!   c), so one conversion to integer holds the code (rounded half up) in its high 16 bits
//!   and the distance past the rounding boundary in its low 16 bits. A lane whose low
//!   bits are below `2^17 · E_c + 0.5` (within `E_c` of a boundary) is flagged by one
//!   unsigned word compare, and that sample is redone by the f64 reference while its
//!   bytes are still in cache, so the result is bit-identical to the reference.
//!   Flagged samples are queued and redone eight at a time by [`Reference`], the
//!   reference's own f64 operations in the same order on eight lanes (IEEE arithmetic
//!   is deterministic, so each lane equals `Prepared::pixel` rounded, bit for bit; the
//!   exhaustive test over all 2^24 code triples checks it).
//! - Clipped lanes: `x' = ±h` exactly (the matrix output clipped at that end) reads an
//!   end slot, which holds the rounded code of the curve's end if that code is the same
//!   over the last `E`-wide stretch of input, so a curve ending exactly on a rounding tie
//!   (y = 0.5) does not send every clipped pixel to the reference.
//!
//! `E_c` (output LSB) = `255 · L · P_c + 1.01 · u · (513 + 2 · h · D)` (u = 2^-24; L the
//! curve's largest slope; D the largest knot step in LSB), with the position error
//! `P_c = 1.01 · u · (2.0001 · S_c + 2|M_c0| + |M_c1| + 3h / (k - 1))` in curve-input
//! units (S_c the absolute sum of CCM row c; see [`position_error`]): the products of the
//! f32 CCM and degamma entries err `2u` relative, and the three FMA roundings each at
//! most u of a partial sum (the last one only where it is not clamped, so at most h);
//! the curve amplifies P_c by L; the intercept
//! (|b| <= 256 + h · D with the shift), the slope (times |x'| <= h) and the final FMA
//! (|w| <= 256.5) each round once. Scaling by 2^16 is exact; the rounding to n is exact
//! and the curve continuous, so the segment choice adds nothing (at a knot either
//! neighbour's line holds the knot); the conversion to integer adds 0.5 units of 2^-16
//! LSB, which the flag threshold includes.

use crate::params::Params;
use crate::tone_curve::ToneCurve;
use std::arch::x86_64::*;

/// Pixels per step.
pub(super) const BLOCK: usize = 64;
/// Bytes per step.
pub(super) const BLOCK_BYTES: usize = 3 * BLOCK;
/// Blocks whose flagged pixels are collected before they are redone (12 KiB of input).
const STRETCH: usize = 64;
/// Blocks degammaed into an L1 scratch (pass 1) before the matrix and curve pass over
/// them (pass 2).
const PASS: usize = 8;

/// Round to nearest, ties to even, exceptions suppressed (both conversions).
const NEAREST: i32 = _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC;
/// The tables' scale: one output LSB is 2^16 units of the converted integer.
const SCALE: f64 = 65536.0;
/// Least `E_c` used for the shift and the flag window (8 units of 2^-16 LSB): an
/// always-flagged end value sits `E_c` into the window `[0, 2 E_c)`, farther than the few
/// units its shared slot's line may round by.
const MIN_E: f64 = 8.0 / SCALE;

/// Whether this CPU can run the engine.
pub(super) fn supported() -> bool {
    is_x86_feature_detected!("avx512f")
        && is_x86_feature_detected!("avx512bw")
        && is_x86_feature_detected!("avx512dq")
        && is_x86_feature_detected!("avx512vbmi")
        && is_x86_feature_detected!("popcnt")
        && is_x86_feature_detected!("bmi1")
}

/// `h` for a curve of k uniform knots: the least half-integer of the form `2m - 1/2`
/// (so `round(±h)` ties away from the segments, onto the end slots) with
/// `h >= (k - 1) / 2`; at most 15.5 for k <= 32.
fn half(k: usize) -> f64 {
    2.0 * (((k - 1) as f64 / 2.0 + 0.5) / 2.0).ceil() - 0.5
}

/// Error bound of the engine's value before rounding, in output LSB, for each output
/// channel (see the module doc).
fn error_lsb(params: &Params, c: &ToneCurve) -> [f64; 3] {
    let u = f32::EPSILON as f64 / 2.0;
    let l = c.max_slope();
    let h = half(c.len());
    let d = 255.0 * c.y().windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
    // The curve amplifies the position error by L; the intercept (|b| <= 256 + h·D), the
    // slope (times |x'| <= h) and the final FMA (|w| <= 256.5) round once each.
    [0, 1, 2].map(|row| 255.0 * l * position_error(params, c, row) + u * (513.0 + 2.0 * h * d) * 1.01)
}

/// The matrix output's error for one output channel (row c), in curve-input units. The
/// products `f32(CCM·(k - 1)) · f32(degamma)` are exact inside the FMAs but their factors
/// err u each: `2u·S_c` in all (S_c the row's absolute sum). The FMAs run over the columns
/// in order 0, 1, 2 from `-h`: the first two round partial sums bounded by `h + |M_c0|` and
/// `h + |M_c0| + |M_c1|` (units of `k - 1`), the last a sum that matters only where it is
/// not clamped, so bounded by h; each rounding errs at most u of its result. Plus the f64
/// reference's own rounding.
fn position_error(params: &Params, c: &ToneCurve, row: usize) -> f64 {
    let u = f32::EPSILON as f64 / 2.0;
    let m = params.ccm[row].map(f64::abs);
    let s = m[0] + m[1] + m[2];
    let top = (c.len() - 1) as f64;
    let h = half(c.len()) / top;
    u * (2.0001 * s + (h + m[0]) + (h + m[0] + m[1]) + h) * 1.01 + 1e-12 * (1.0 + s)
}

/// Tables of one parameter set. Only built where [`supported`] or the AVX2 engine's
/// features hold (see `Exact8::new`); the AVX2 engine ([`super::avx2::run_lines`]) runs the same arithmetic on
/// the same tables (the degamma, `m`, `half`, the lines and the thresholds), eight lanes a
/// step.
#[derive(Debug, Clone)]
pub(super) struct Kernel {
    /// `planes[b][x]`: byte b (little-endian) of the f32 degamma of code x.
    planes: [[u8; 256]; 4],
    /// The f32 degamma of each code (the planes' values), for the AVX2 engine's gathers.
    pub(super) degamma: [f32; 256],
    /// `CCM · (k - 1)`, row-major, f32.
    pub(super) m: [f32; 9],
    /// `h` ([`half`]): the curve input is `x' = x - h` (x in segment units), clamped to
    /// [-h, h].
    pub(super) half: f32,
    /// Per table slot `n mod 32` (n = x' rounded to nearest, ties to even), the line
    /// `w = intercept + x' · slope` in output LSB, scaled by 2^16 and shifted by
    /// `0.5 + E_c` for output channel c (see [`slots`]).
    pub(super) intercept: [[f32; 32]; 3],
    pub(super) slope: [f32; 32],
    /// A lane of channel c whose low 16 bits are below `threshold[c]` is within `E_c` of
    /// a rounding boundary: `ceil(2^17 · E_c + 0.5)` (`E_c` at least [`MIN_E`]).
    pub(super) threshold: [i32; 3],
    /// Byte permutes: deinterleave (plane c: first from bytes 0..128, then 128..192)
    /// and interleave (output register r: first R and G, then B).
    split: [[[u8; 64]; 2]; 3],
    merge: [[[u8; 64]; 2]; 3],
    /// The f64 reference for flagged pixels.
    pub(super) reference: Reference,
}

/// The f64 reference pipeline (`Prepared::pixel`, then round half up to a code) on eight
/// pixels at once, for a uniform curve of at most 32 knots: the same operations in the
/// same order as the scalar code (no fused multiply-adds), so every lane is bit-identical
/// to it. (Clamping may turn a -0.0 into +0.0; both reach the same code.)
#[derive(Debug, Clone)]
pub(super) struct Reference {
    /// Degamma of each code, f64 (the `Prepared` table).
    degamma: [f64; 256],
    /// The CCM, row-major.
    m: [f64; 9],
    /// `k - 1` (the segment scale) and the last segment `k - 2`.
    scale: f64,
    last: i64,
    /// Per segment: `x_i`, `x_{i+1} - x_i`, `y_i`, `y_{i+1} - y_i` (padded with zeros).
    x0: [f64; 32],
    dx: [f64; 32],
    y0: [f64; 32],
    dy: [f64; 32],
}

impl Reference {
    fn new(params: &Params, c: &ToneCurve, degamma: &[f64]) -> Self {
        let (x, y) = (c.x(), c.y());
        let k = c.len();
        let mut t = Self {
            degamma: [0.0; 256],
            m: [0.0; 9],
            scale: (k - 1) as f64,
            last: (k - 2) as i64,
            x0: [0.0; 32],
            dx: [0.0; 32],
            y0: [0.0; 32],
            dy: [0.0; 32],
        };
        t.degamma.copy_from_slice(degamma);
        for (i, row) in params.ccm.iter().enumerate() {
            t.m[3 * i..3 * i + 3].copy_from_slice(row);
        }
        for i in 0..k - 1 {
            (t.x0[i], t.dx[i], t.y0[i], t.dy[i]) = (x[i], x[i + 1] - x[i], y[i], y[i + 1] - y[i]);
        }
        t
    }

    /// Output channel `c` (0..3) of the pixel `rgb`, rounded: [`Reference::redo`]'s
    /// operations on one lane in scalar f64 (the AVX2 engine's redo, where 4-lane f64 has no
    /// 32-entry permute), so bit-identical to it and to the reference.
    #[inline]
    pub(super) fn sample(&self, rgb: [u8; 3], c: usize) -> u8 {
        let v = rgb.map(|x| self.degamma[x as usize]);
        let m = [self.m[3 * c], self.m[3 * c + 1], self.m[3 * c + 2]];
        let t = ((m[0] * v[0] + m[1] * v[1]) + m[2] * v[2]).clamp(0.0, 1.0);
        // t · (k - 1) is in [0, 31]: the conversion truncates as `vcvttpd2qq` does.
        let seg = ((t * self.scale) as i64).min(self.last) as usize % 32;
        let a = (t - self.x0[seg]) / self.dx[seg];
        let w = self.y0[seg] + a * self.dy[seg];
        // `vcvttpd2dq`, then the low byte, as the vector redo stores it.
        (w * 255.0 + 0.5) as i32 as u8
    }

    /// The rounded outputs of the first eight samples of a queue: lane l is output channel
    /// `channel[l]` (0..3) of the pixel at byte offset `at[l]` of `src`; written to the
    /// same place of `dst`.
    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vbmi,popcnt,bmi1")]
    fn redo<const N: usize>(&self, at: &[usize; N], channel: &[i64; N], src: &[u8], dst: &mut [u8]) {
        const { assert!(N >= 8) };
        let (Some(at), Some(channel)) = (at.first_chunk::<8>(), channel.first_chunk::<8>()) else {
            unreachable!("N >= 8")
        };
        // Permute from a 32-entry table: two 16-entry permutes, bit 4 picks.
        let load = |t: &[f64; 32]| {
            // SAFETY: four loads of eight f64 inside a 32-entry array.
            unsafe { [0, 8, 16, 24].map(|o| _mm512_loadu_pd(t[o..].as_ptr())) }
        };
        let (tx0, tdx, ty0, tdy) = (load(&self.x0), load(&self.dx), load(&self.y0), load(&self.dy));
        let (zero, one) = (_mm512_setzero_pd(), _mm512_set1_pd(1.0));
        let mut lin = [zero; 3];
        for (c, l) in lin.iter_mut().enumerate() {
            let codes = at.map(|i| src[i + c] as i32);
            // SAFETY: eight i32 read from an eight-element array; the gather reads
            // `degamma[code]` with code < 256.
            unsafe {
                let idx = _mm256_loadu_si256(codes.as_ptr().cast());
                *l = _mm512_i32gather_pd::<8>(idx, self.degamma.as_ptr());
            }
        }
        // SAFETY: eight i64 loaded from an eight-element array.
        let row = unsafe { _mm512_loadu_si512(channel.as_ptr().cast()) };
        // Lane l's matrix row: column j of the CCM permuted by the lane's channel.
        let m = |j: usize| {
            _mm512_permutexvar_pd(row, _mm512_setr_pd(self.m[j], self.m[3 + j], self.m[6 + j], 0.0, 0.0, 0.0, 0.0, 0.0))
        };
        let pick = |t: &[__m512d; 4], seg: __m512i, high: __mmask8| {
            let lo = _mm512_permutex2var_pd(t[0], seg, t[1]);
            let hi = _mm512_permutex2var_pd(t[2], seg, t[3]);
            _mm512_mask_blend_pd(high, lo, hi)
        };
        // ccm::apply: (m0·v0 + m1·v1) + m2·v2, each product and sum rounded.
        let s = _mm512_add_pd(
            _mm512_add_pd(_mm512_mul_pd(m(0), lin[0]), _mm512_mul_pd(m(1), lin[1])),
            _mm512_mul_pd(m(2), lin[2]),
        );
        // clip01 (no NaN can occur: finite CCM, degamma in [0, 1]).
        let t = _mm512_min_pd(_mm512_max_pd(s, zero), one);
        // ToneCurve::eval on uniform knots: segment min(trunc(t · (k - 1)), k - 2).
        let seg = _mm512_min_epi64(
            _mm512_cvttpd_epi64(_mm512_mul_pd(t, _mm512_set1_pd(self.scale))),
            _mm512_set1_epi64(self.last),
        );
        let high = _mm512_test_epi64_mask(seg, _mm512_set1_epi64(16));
        let a = _mm512_div_pd(_mm512_sub_pd(t, pick(&tx0, seg, high)), pick(&tdx, seg, high));
        let v = _mm512_add_pd(pick(&ty0, seg, high), _mm512_mul_pd(a, pick(&tdy, seg, high)));
        // quantize: (v · 255 + 0.5) truncated.
        let q = _mm512_cvttpd_epi32(_mm512_add_pd(_mm512_mul_pd(v, _mm512_set1_pd(255.0)), _mm512_set1_pd(0.5)));
        let mut out = [0i32; 8];
        // SAFETY: eight i32 stored into an eight-element array.
        unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), q) };
        for l in 0..8 {
            dst[at[l] + channel[l] as usize] = out[l] as u8;
        }
    }
}

/// What a table slot stands for.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Slot {
    Unused,
    /// Segment s of the curve, `x in [s, s + 1]`.
    Segment(usize),
    /// Only `x' = -h` (the matrix output clipped at 0) and/or values past the top end
    /// (`x >= k - 1`, clipped at 1).
    Ends {
        low: bool,
        high: bool,
    },
}

/// The curve's lines per slot, for `x' = x - h` clamped to [-h, h] and `n = round(x')`
/// (ties to even) looked up at `n mod 32`. Inside, segment s (`x in [s, s + 1)`) is
/// `n = s - h + 1/2`, one n for the whole open segment since h is a half-integer; at a
/// knot (a tie) either neighbour's line holds the knot's value. The n past the segments
/// are the ends: `n = round(-h)`, below segment 0 (only `x' = -h` rounds there), and
/// every n above segment `k - 2` (`x in [k - 1, 2h]`, where the reference has clipped
/// at 1: slope 0).
/// An end slot holds the end's code + 1/2 if that code is the same over the last
/// stretch of input (`codes`), else the code boundary next above the end's value (in
/// the flag window once shifted, so always flagged); it has slope 0, or, where both ends
/// share a slot (h = 15.5: `round(-h) = -16` and `round(h) = 16`), the line through both
/// end values at `x' = ∓h` (exact to a few units of 2^-16 LSB, well inside the window's
/// margins of at least [`MIN_E`]).
/// Returns `(h, intercept, slope)` in output LSB, the intercepts before the shift E
/// (each channel adds its own; the slopes do not depend on it), or `None` if a segment
/// would share a slot.
fn slots(y: &[f64], codes: [Option<u16>; 2]) -> Option<(f64, [f64; 32], [f64; 32])> {
    let k = y.len();
    let h = half(k);
    let mut kinds = [Slot::Unused; 32];
    let (lo, hi) = ((-h).round_ties_even() as i64, h.round_ties_even() as i64);
    for n in lo..=hi {
        let seg = n as f64 + h - 0.5;
        let slot = &mut kinds[n.rem_euclid(32) as usize];
        *slot = match (*slot, seg) {
            (Slot::Unused, s) if s >= 0.0 && s <= (k - 2) as f64 => Slot::Segment(s as usize),
            (Slot::Unused, s) => Slot::Ends { low: s < 0.0, high: s >= 0.0 },
            (Slot::Ends { low, high }, s) if s < 0.0 || s > (k - 2) as f64 => {
                Slot::Ends { low: low || s < 0.0, high: high || s >= 0.0 }
            }
            _ => return None,
        };
    }
    let end = |code: Option<u16>, v: f64| match code {
        Some(q) => q as f64 + 0.5,
        None => (255.0 * v).floor() + 1.0,
    };
    let (v_lo, v_hi) = (end(codes[0], y[0]), end(codes[1], y[k - 1]));
    let mut intercept = [0.0; 32];
    let mut slope = [0.0; 32];
    for (i, kind) in kinds.iter().enumerate() {
        (intercept[i], slope[i]) = match *kind {
            Slot::Unused => (0.0, 0.0),
            Slot::Segment(s) => {
                let a = 255.0 * (y[s + 1] - y[s]);
                (255.0 * y[s] + (h - s as f64) * a + 0.5, a)
            }
            Slot::Ends { low: true, high: true } => ((v_lo + v_hi) / 2.0, (v_hi - v_lo) / (2.0 * h)),
            Slot::Ends { low: true, .. } => (v_lo, 0.0),
            Slot::Ends { .. } => (v_hi, 0.0),
        };
    }
    Some((h, intercept, slope))
}

impl Kernel {
    /// `None` where the channels have their own curves (the scalar tables run those), the
    /// curve is not uniform or has more than 32 knots, or the bound is too
    /// wide to be worth it (E >= 0.25 LSB). (The caller builds it only where an engine that
    /// runs it runs.)
    pub(super) fn new(params: &Params, degamma: &[f64]) -> Option<Self> {
        let c = params.tone_curves.shared()?;
        let k = c.len();
        if !c.is_uniform() || k > 32 || degamma.len() != 256 {
            return None;
        }
        let e = error_lsb(params, c);
        if e.iter().any(|&e| e >= 0.25) {
            return None;
        }
        let mut planes = [[0u8; 256]; 4];
        let mut degamma32 = [0f32; 256];
        for (x, d) in degamma.iter().enumerate() {
            degamma32[x] = *d as f32;
            for (b, byte) in (*d as f32).to_le_bytes().into_iter().enumerate() {
                planes[b][x] = byte;
            }
        }
        let pos = (0..3).map(|row| position_error(params, c, row)).fold(0.0, f64::max);
        let mut hint = 0;
        let low_code = super::constant_code(c, 0.0, pos.min(1.0), &mut hint);
        let mut hint = 0;
        let high_code = super::constant_code(c, (1.0 - pos).max(0.0), 1.0, &mut hint);
        let top = (k - 1) as f64;
        let mut m = [0f32; 9];
        for (i, row) in params.ccm.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                m[3 * i + j] = (v * top) as f32;
            }
        }
        let e = e.map(|e| e.max(MIN_E));
        let threshold = e.map(|e| (2.0 * SCALE * e + 0.5).ceil() as i32);
        let (half, b, a) = slots(c.y(), [low_code, high_code])?;
        let intercept = e.map(|e| b.map(|b| (SCALE * (b + e)) as f32));
        let slope = a.map(|a| (SCALE * a) as f32);
        let mut split = [[[0u8; 64]; 2]; 3];
        let mut merge = [[[0u8; 64]; 2]; 3];
        for (c, plane) in split.iter_mut().enumerate() {
            #[allow(clippy::needless_range_loop)] // i is both the index and a value
            for i in 0..64 {
                let at = 3 * i + c;
                plane[0][i] = if at < 128 { at as u8 } else { 0 };
                plane[1][i] = if at < 128 { i as u8 } else { (64 + at - 128) as u8 };
            }
        }
        for (r, out) in merge.iter_mut().enumerate() {
            #[allow(clippy::needless_range_loop)] // j is both the index and a value
            for j in 0..64 {
                let o = 64 * r + j;
                let (plane, pos) = (o % 3, (o / 3) as u8);
                out[0][j] = match plane {
                    0 => pos,
                    1 => 64 + pos,
                    _ => 0,
                };
                out[1][j] = if plane == 2 { 64 + pos } else { j as u8 };
            }
        }
        let reference = Reference::new(params, c, degamma);
        Some(Self {
            planes,
            degamma: degamma32,
            m,
            half: half as f32,
            intercept,
            slope,
            threshold,
            split,
            merge,
            reference,
        })
    }

    /// Runs whole blocks: `src.len() == dst.len()`, a multiple of [`BLOCK_BYTES`]. Each
    /// flagged pixel is redone by the f64 reference within a few blocks. Returns how many
    /// were flagged.
    pub(super) fn run(&self, src: &[u8], dst: &mut [u8]) -> usize {
        assert!(src.len() == dst.len() && src.len().is_multiple_of(BLOCK_BYTES));
        assert!(supported(), "the AVX-512 engine on a CPU without it");
        // SAFETY: `supported()` holds, so the CPU has every feature `blocks` is compiled for.
        unsafe { self.blocks(src, dst) }
    }

    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vbmi,popcnt,bmi1")]
    fn blocks(&self, src: &[u8], dst: &mut [u8]) -> usize {
        let mut flagged = 0;
        // Flagged samples waiting for the reference: their pixels' byte offsets (room for
        // the seven left over and every sample of one block)...
        let mut queue = [0usize; 8 + 3 * BLOCK];
        // ...and their output channels.
        let mut channel = [0i64; 8 + 3 * BLOCK];
        let mut queued = 0;
        // SAFETY (all loads and stores below): every pointer is into `self`'s arrays of
        // 64 bytes / 16 f32, or into a 192-byte chunk of `src` / `dst`.
        let ld = |b: &[u8; 64]| unsafe { _mm512_loadu_si512(b.as_ptr().cast()) };
        let tables: [[__m512i; 4]; 4] = std::array::from_fn(|b| {
            std::array::from_fn(|q| unsafe { _mm512_loadu_si512(self.planes[b][64 * q..].as_ptr().cast()) })
        });
        let split = self.split.map(|s| s.map(|v| ld(&v)));
        let merge = self.merge.map(|s| s.map(|v| ld(&v)));
        let m = self.m.map(|v| _mm512_set1_ps(v));
        let (half, start) = (_mm512_set1_ps(self.half), _mm512_set1_ps(-self.half));
        let threshold = self.threshold.map(|t| _mm512_set1_epi32(t));
        // Word j of a pack: the high word of dword 4·(j / 8) + j % 4 of the first (j % 8 < 4)
        // or second register, the order of `packus_epi32`.
        let high_words = _mm512_set_epi16(
            63, 61, 59, 57, 31, 29, 27, 25, 55, 53, 51, 49, 23, 21, 19, 17, 47, 45, 43, 41, 15, 13, 11, 9, 39, 37, 35,
            33, 7, 5, 3, 1,
        );
        let v = self.intercept.map(|t| unsafe { [_mm512_loadu_ps(t.as_ptr()), _mm512_loadu_ps(t[16..].as_ptr())] });
        let (s0, s1) = unsafe { (_mm512_loadu_ps(self.slope.as_ptr()), _mm512_loadu_ps(self.slope[16..].as_ptr())) };

        // Flag masks of a stretch of blocks, one per output channel (bit order below),
        // scanned after the stretch: the scan's unpredictable branches stay out of the
        // vector loop.
        let mut masks = [[0u64; 3]; STRETCH];
        let mut scratch = [[[_mm512_setzero_ps(); 4]; 3]; PASS];
        let stretch_bytes = STRETCH * BLOCK_BYTES;
        for first in (0..src.len()).step_by(stretch_bytes) {
            let blocks = (src.len() - first).min(stretch_bytes) / BLOCK_BYTES;
            for sub in (0..blocks).step_by(PASS) {
                let n = (blocks - sub).min(PASS);
                // Pass 1: planes of 64 codes, then their degamma as 4 x 16 f32 lanes per
                // channel, into an L1 scratch. Lane l of group g holds pixel
                // 16·(l / 4) + 4·g + l % 4 (the unpack order).
                for (j, lin) in scratch[..n].iter_mut().enumerate() {
                    let base = first + (sub + j) * BLOCK_BYTES;
                    let si = &src[base..base + BLOCK_BYTES];
                    let mut raw = [_mm512_setzero_si512(); 3];
                    for (r, v) in raw.iter_mut().enumerate() {
                        *v = unsafe { _mm512_loadu_si512(si[64 * r..].as_ptr().cast()) };
                    }
                    // (Plain loops, not closures: closures here are not inlined.)
                    for c in 0..3 {
                        let t = _mm512_permutex2var_epi8(raw[0], split[c][0], raw[1]);
                        let codes = _mm512_permutex2var_epi8(t, split[c][1], raw[2]);
                        let high = _mm512_movepi8_mask(codes);
                        let mut bytes = [_mm512_setzero_si512(); 4];
                        for b in 0..4 {
                            // Codes below 128 from the first half of the plane, then the
                            // others (still holding their code) from the second half.
                            let lo = _mm512_mask2_permutex2var_epi8(tables[b][0], codes, !high, tables[b][1]);
                            bytes[b] = _mm512_mask2_permutex2var_epi8(tables[b][2], lo, high, tables[b][3]);
                        }
                        let (w01l, w01h) =
                            (_mm512_unpacklo_epi8(bytes[0], bytes[1]), _mm512_unpackhi_epi8(bytes[0], bytes[1]));
                        let (w23l, w23h) =
                            (_mm512_unpacklo_epi8(bytes[2], bytes[3]), _mm512_unpackhi_epi8(bytes[2], bytes[3]));
                        lin[c] = [
                            _mm512_castsi512_ps(_mm512_unpacklo_epi16(w01l, w23l)),
                            _mm512_castsi512_ps(_mm512_unpackhi_epi16(w01l, w23l)),
                            _mm512_castsi512_ps(_mm512_unpacklo_epi16(w01h, w23h)),
                            _mm512_castsi512_ps(_mm512_unpackhi_epi16(w01h, w23h)),
                        ];
                    }
                }
                // Pass 2: matrix, curve, flags, pack.
                for (j, lin) in scratch[..n].iter().enumerate() {
                    let base = first + (sub + j) * BLOCK_BYTES;
                    let di = &mut dst[base..base + BLOCK_BYTES];
                    // Flags: bit 2·l of group g's mask in channel c: lane l near a boundary.
                    let mut near = [[0u32; 4]; 3];
                    let mut q = [[_mm512_setzero_si512(); 4]; 3];
                    for g in 0..4 {
                        for c in 0..3 {
                            let s = _mm512_fmadd_ps(m[3 * c], lin[0][g], start);
                            let s = _mm512_fmadd_ps(m[3 * c + 1], lin[1][g], s);
                            let s = _mm512_fmadd_ps(m[3 * c + 2], lin[2][g], s);
                            // Absolute minimum, sign from s: sign(s) · min(|s|, h), the clamp to [-h, h].
                            let x = _mm512_range_ps::<0b0010>(s, half);
                            let seg = _mm512_cvt_roundps_epi32::<NEAREST>(x);
                            let b = _mm512_permutex2var_ps(v[c][0], seg, v[c][1]);
                            let a = _mm512_permutex2var_ps(s0, seg, s1);
                            let t = _mm512_cvt_roundps_epi32::<NEAREST>(_mm512_fmadd_ps(x, a, b));
                            near[c][g] = _mm512_mask_cmplt_epu16_mask(0x5555_5555, t, threshold[c]);
                            q[c][g] = t;
                        }
                    }
                    // Pack the codes (high words) back to byte planes (the packs' order undoes
                    // the unpack order), then interleave.
                    let mut planes = [_mm512_setzero_si512(); 3];
                    for c in 0..3 {
                        let a = _mm512_permutex2var_epi16(q[c][0], high_words, q[c][1]);
                        let b = _mm512_permutex2var_epi16(q[c][2], high_words, q[c][3]);
                        planes[c] = _mm512_packus_epi16(a, b);
                    }
                    for (r, mg) in merge.iter().enumerate() {
                        let t = _mm512_permutex2var_epi8(planes[0], mg[0], planes[1]);
                        let out = _mm512_permutex2var_epi8(t, mg[1], planes[2]);
                        unsafe { _mm512_storeu_si512(di[64 * r..].as_mut_ptr().cast(), out) };
                    }
                    // Bit 32·(g / 2) + 2·l + g % 2: lane l of group g.
                    masks[sub + j] = near.map(|n| (n[0] | n[1] << 1) as u64 | ((n[2] | n[3] << 1) as u64) << 32);
                }
            }
            for (j, mask) in masks[..blocks].iter().enumerate() {
                let any = mask[0] | mask[1] | mask[2];
                if any == 0 {
                    continue;
                }
                flagged += any.count_ones() as usize;
                let base = first + j * BLOCK_BYTES;
                let mut bits = any;
                while bits != 0 {
                    // Lane l of group g is pixel 16·(l / 4) + 4·g + l % 4. Each of its
                    // flagged channels is queued, without a branch per channel.
                    let bit = bits.trailing_zeros() as usize;
                    let (g, l) = (2 * (bit / 32) + bit % 2, bit % 32 / 2);
                    let at = base + 3 * (16 * (l / 4) + 4 * g + l % 4);
                    for (ch, m) in mask.iter().enumerate() {
                        (queue[queued], channel[queued]) = (at, ch as i64);
                        queued += (m >> bit & 1) as usize;
                    }
                    bits &= bits - 1;
                }
                while queued >= 8 {
                    self.reference.redo(&queue, &channel, src, dst);
                    queue.copy_within(8..queued, 0);
                    channel.copy_within(8..queued, 0);
                    queued -= 8;
                }
            }
        }
        if queued > 0 {
            // Fill the batch with repeats of a queued sample (redone twice, same result).
            let (first, ch) = (queue[0], channel[0]);
            queue[queued..8].fill(first);
            channel[queued..8].fill(ch);
            self.reference.redo(&queue, &channel, src, dst);
        }
        flagged
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table slots as the engine evaluates them (f32 FMA, one rounding; conversion
    /// ties to even), at the clamped ends and inside every segment, for every knot count
    /// and for several shifts E sharing one slope table (as the channels do).
    #[test]
    fn slots_give_each_input_its_line() {
        let eval = |intercept: &[f32; 32], slope: &[f32; 32], x: f32| {
            let n = (x as f64).round_ties_even() as i64;
            let i = n.rem_euclid(32) as usize;
            x.mul_add(slope[i], intercept[i]) as f64
        };
        for k in 2..=32usize {
            let y: Vec<f64> = (0..k).map(|i| 0.5 + 0.4 * ((3 * i + 1) % 7) as f64 / 7.0 - 0.2).collect();
            let h = half(k);
            assert!(h >= (k - 1) as f64 / 2.0 && h <= 15.5 && (h + 0.5) % 2.0 == 0.0, "{k}: h = {h}");
            for codes in [[Some(17), Some(200)], [None, None], [Some(3), None], [None, Some(255)]] {
                let (hh, b, a) = slots(&y, codes).expect("every k <= 32 fits");
                assert_eq!(hh, h);
                let slope = a.map(|a| (SCALE * a) as f32);
                for e in [MIN_E, 1e-3, 0.2] {
                    let intercept = b.map(|b| (SCALE * (b + e)) as f32);
                    let threshold = (2.0 * SCALE * e + 0.5).ceil();
                    // The clamped ends, and past the top (x in (k - 1, 2h], flat): the end's
                    // code + 1/2 + E, or the boundary above its value + E, which lies at
                    // least 4 units inside the flag window [0, threshold).
                    let mut ends = vec![(-h, codes[0], y[0]), (h, codes[1], y[k - 1])];
                    if 2.0 * h > (k - 1) as f64 + 0.25 {
                        ends.push((k as f64 - 0.75 - h, codes[1], y[k - 1]));
                    }
                    for (x, code, v) in ends {
                        let w = eval(&intercept, &slope, x as f32);
                        let want = SCALE * (e + code.map_or((255.0 * v).floor() + 1.0, |q| q as f64 + 0.5));
                        assert!((w - want).abs() <= 4.0, "{k} knots, E {e}, x' = {x}: {w} vs {want}");
                        let low = w.round_ties_even().rem_euclid(SCALE);
                        match code {
                            Some(_) => assert!(low >= threshold, "{k} knots, E {e}, x' = {x}: flagged"),
                            None => assert!(
                                low >= 4.0 && low + 4.0 <= threshold,
                                "{k} knots, E {e}, x' = {x}: {low} of {threshold}"
                            ),
                        }
                    }
                    // Inside: the curve through the knots, shifted by 0.5 + E (the ends, which
                    // may round onto an end slot, are checked above).
                    for j in 1..(k - 1) * 8 {
                        let x = j as f64 / 8.0; // segment units, knots included
                        let (s, f) = ((x as usize).min(k - 2), x - (x as usize).min(k - 2) as f64);
                        let want = SCALE * (255.0 * (y[s] + f * (y[s + 1] - y[s])) + 0.5 + e);
                        let w = eval(&intercept, &slope, (x - h) as f32);
                        assert!((w - want).abs() < 8.0, "{k} knots, E {e}, x = {x}: {w} vs {want}");
                    }
                }
            }
        }
    }
}
