//! The AVX-512 engine of [`super::Exact8`] (x86-64 with AVX-512 F, BW, DQ and VBMI,
//! checked at run time): 64 pixels per step and no gathers, every table lookup is a
//! register permute.
//!
//! - Deinterleave: 192 bytes of RGB become three 64-byte planes (two byte permutes each).
//! - Degamma: the f32 table over the 256 input codes is held as four byte planes of
//!   256 bytes; each plane is looked up for 64 pixels at once (two `vpermi2b` and a
//!   blend), and the bytes are re-assembled into f32 lanes by unpacks.
//! - Matrix: `x = CCM · (k - 1)` in f32 by FMA, clamped to [0, k - 1]: the curve input
//!   in segment units. (Or `k - 1 - x`, with the curve reversed; see below.)
//! - Curve: uniform knots only (k <= 32): `floor` picks the segment, its slope and
//!   intercept (pre-scaled by 255, so `w = b_s + x · a_s` is the curve in output LSB)
//!   come from two `vpermi2ps`, one FMA evaluates. Only the low end is clamped in f32:
//!   above `k - 1` the segment index is clamped as an integer, onto slot `k - 1` whose
//!   slope is 0.
//! - Output: the tables are pre-scaled by 2^16 and shifted by `0.5 + E`, so one
//!   conversion to integer holds the code (rounded half up) in its high 16 bits and the
//!   distance past the rounding boundary in its low 16 bits. A lane whose low bits are
//!   below `2^17 · E + 0.5` (within `E` of a boundary) is flagged by one unsigned word
//!   compare, and its pixel is redone by the f64 reference while its bytes are still in
//!   L1, so the result is bit-identical to the reference.
//!   Flagged pixels are queued and redone eight at a time by [`Reference`], the
//!   reference's own f64 operations in the same order on eight lanes (IEEE arithmetic
//!   is deterministic, so each lane equals `Prepared::pixel` rounded, bit for bit; the
//!   exhaustive test over all 2^24 code triples checks it), about 15x cheaper per pixel
//!   than the scalar call.
//! - Clipped lanes: `x = k - 1` exactly (the matrix output clipped at that end) reads
//!   table slot `k - 1` (slope 0), which holds the rounded code of the curve's end if that
//!   code is the same over the last `E`-wide stretch of input, so a curve ending exactly
//!   on a rounding tie (y = 0.5) does not send every clipped pixel to the reference. The
//!   orientation (x or `k - 1 - x`) is chosen so that this slot serves the end that
//!   needs it.
//!
//! `E` (output LSB) = `255 · L · 5u · (S + 1) + u · (2 · 256 + 2 · (k - 1) · D)`, widened
//! by 1% (u = 2^-24; S the largest absolute row sum of the CCM; L the curve's largest
//! slope; D the largest knot step in LSB): the matrix sum carries at most `5u · (S + 1)` in
//! curve-input units (f32 CCM and degamma entries, three FMA roundings, partial sums
//! bounded by `S + 1` with the reversed start), which the curve amplifies by L; the
//! intercept (|b| <= 256 + (k - 1) · D with the shift) and the slope each round once, as
//! does the final FMA (|w| <= 256). Scaling by 2^16 is exact; `floor` is exact and the
//! curve continuous, so the segment choice adds nothing; the conversion to integer adds
//! 0.5 units of 2^-16 LSB, which the flag threshold includes.

use crate::params::Params;
use std::arch::x86_64::*;

/// Pixels per step.
pub(super) const BLOCK: usize = 64;
/// Bytes per step.
pub(super) const BLOCK_BYTES: usize = 3 * BLOCK;
/// Blocks whose flagged pixels are collected before they are redone (12 KiB of input).
const STRETCH: usize = 64;

/// Whether this CPU can run the engine.
pub(super) fn supported() -> bool {
    is_x86_feature_detected!("avx512f")
        && is_x86_feature_detected!("avx512bw")
        && is_x86_feature_detected!("avx512dq")
        && is_x86_feature_detected!("avx512vbmi")
}

/// Error bound of the engine's value before rounding, in output LSB (see the module doc).
pub(super) fn error_lsb(params: &Params) -> f64 {
    let u = f32::EPSILON as f64 / 2.0;
    let s = crate::ccm::norm_inf(&params.ccm);
    let c = &params.tone_curve;
    let l = c.max_slope();
    let top = (c.len() - 1) as f64;
    let d = 255.0 * c.y().windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
    // 1e-12 · (1 + L·S) covers the f64 reference's own rounding.
    (255.0 * l * 5.0 * u * (s + 1.0) + u * (2.0 * 256.0 + 2.0 * top * d)) * 1.01 + 1e-12 * (1.0 + l * s) * 255.0
}

/// The same bound in curve-input units (the matrix output's error).
fn position_error(params: &Params) -> f64 {
    let u = f32::EPSILON as f64 / 2.0;
    let s = crate::ccm::norm_inf(&params.ccm);
    5.0 * u * (s + 1.0) * 1.01 + 1e-12 * (1.0 + s)
}

/// Tables of one parameter set. Only built where [`supported`] holds.
#[derive(Debug, Clone)]
pub(super) struct Kernel {
    /// `planes[b][x]`: byte b (little-endian) of the f32 degamma of code x.
    planes: [[u8; 256]; 4],
    /// `±CCM · (k - 1)`, row-major, f32 (negated when reversed).
    m: [f32; 9],
    /// Start of the FMA chain: 0, or `k - 1` when reversed.
    start: f32,
    /// `k - 1`, the last table slot.
    last: i32,
    /// `2^16 · (255 · y_i - i · slope_i + 0.5 + E)` (of the curve in this orientation):
    /// segment i's line at x = 0, shifted; slot `k - 1` holds the end's code, shifted the
    /// same way (or code + 0.5, always flagged, when the end is ambiguous); padded after.
    intercept: [f32; 32],
    /// `2^16 · 255 · (y_{i+1} - y_i)`, zero from `k - 1` on.
    slope: [f32; 32],
    /// A lane whose low 16 bits are below this is within `E` of a rounding boundary:
    /// `ceil(2^17 · E + 0.5)`.
    threshold: i32,
    /// Byte permutes: deinterleave (plane c: first from bytes 0..128, then 128..192)
    /// and interleave (output register r: first R and G, then B).
    split: [[[u8; 64]; 2]; 3],
    merge: [[[u8; 64]; 2]; 3],
    /// The f64 reference for flagged pixels.
    reference: Reference,
}

/// The f64 reference pipeline (`Prepared::pixel`, then round half up to a code) on eight
/// pixels at once, for a uniform curve of at most 32 knots: the same operations in the
/// same order as the scalar code (no fused multiply-adds), so every lane is bit-identical
/// to it. (Clamping may turn a -0.0 into +0.0; both reach the same code.)
#[derive(Debug, Clone)]
struct Reference {
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
    fn new(params: &Params, degamma: &[f64]) -> Self {
        let c = &params.tone_curve;
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

    /// The rounded outputs of eight pixels, given as byte offsets into `src`; written to
    /// the same offsets of `dst`.
    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vbmi")]
    fn redo(&self, at: &[usize; 8], src: &[u8], dst: &mut [u8]) {
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
        let pick = |t: &[__m512d; 4], seg: __m512i, high: __mmask8| {
            let lo = _mm512_permutex2var_pd(t[0], seg, t[1]);
            let hi = _mm512_permutex2var_pd(t[2], seg, t[3]);
            _mm512_mask_blend_pd(high, lo, hi)
        };
        let mut out = [[0i32; 8]; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let m = |j: usize| _mm512_set1_pd(self.m[3 * c + j]);
            // ccm::apply: (m0·v0 + m1·v1) + m2·v2, each product and sum rounded.
            let s = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(m(0), lin[0]), _mm512_mul_pd(m(1), lin[1])), _mm512_mul_pd(m(2), lin[2]));
            // clip01 (no NaN can occur: finite CCM, degamma in [0, 1]).
            let t = _mm512_min_pd(_mm512_max_pd(s, zero), one);
            // ToneCurve::eval on uniform knots: segment min(trunc(t · (k - 1)), k - 2).
            let seg = _mm512_min_epi64(_mm512_cvttpd_epi64(_mm512_mul_pd(t, _mm512_set1_pd(self.scale))), _mm512_set1_epi64(self.last));
            let high = _mm512_test_epi64_mask(seg, _mm512_set1_epi64(16));
            let a = _mm512_div_pd(_mm512_sub_pd(t, pick(&tx0, seg, high)), pick(&tdx, seg, high));
            let v = _mm512_add_pd(pick(&ty0, seg, high), _mm512_mul_pd(a, pick(&tdy, seg, high)));
            // quantize: (v · 255 + 0.5) truncated.
            let q = _mm512_cvttpd_epi32(_mm512_add_pd(_mm512_mul_pd(v, _mm512_set1_pd(255.0)), _mm512_set1_pd(0.5)));
            // SAFETY: eight i32 stored into an eight-element array.
            unsafe { _mm256_storeu_si256(o.as_mut_ptr().cast(), q) };
        }
        for (l, &i) in at.iter().enumerate() {
            dst[i..i + 3].copy_from_slice(&[out[0][l] as u8, out[1][l] as u8, out[2][l] as u8]);
        }
    }
}

impl Kernel {
    /// `None` where the CPU lacks the features, the curve is not uniform or has more
    /// than 32 knots, or the bound is too wide to be worth it (E >= 0.25 LSB).
    pub(super) fn new(params: &Params, degamma: &[f64]) -> Option<Self> {
        let c = &params.tone_curve;
        let k = c.len();
        if !supported() || !c.is_uniform() || k > 32 || degamma.len() != 256 {
            return None;
        }
        let e = error_lsb(params);
        if e >= 0.25 {
            return None;
        }
        let mut planes = [[0u8; 256]; 4];
        for (x, d) in degamma.iter().enumerate() {
            for (b, byte) in (*d as f32).to_le_bytes().into_iter().enumerate() {
                planes[b][x] = byte;
            }
        }
        // The rounded code at each clipped end if it is the same for every input the
        // f32 sum may have stood for; the end whose raw value sits near a rounding
        // boundary gets the slot.
        let y = c.y();
        let pos = position_error(params);
        let mut hint = 0;
        let low_code = super::constant_code(c, 0.0, pos.min(1.0), &mut hint);
        let mut hint = 0;
        let high_code = super::constant_code(c, (1.0 - pos).max(0.0), 1.0, &mut hint);
        let near_tie = |v: f64| ((255.0 * v).fract() - 0.5).abs() < e + 1e-6;
        let reverse = near_tie(y[0]) && !near_tie(y[k - 1]);
        let ys: Vec<f64> = if reverse { y.iter().rev().copied().collect() } else { y.to_vec() };
        let end = if reverse { low_code } else { high_code };
        let top = (k - 1) as f64;
        let sign = if reverse { -1.0 } else { 1.0 };
        let mut m = [0f32; 9];
        for (i, row) in params.ccm.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                m[3 * i + j] = (sign * v * top) as f32;
            }
        }
        let (scale, shift) = (65536.0, 0.5 + e);
        let mut intercept = [0f32; 32];
        let mut slope = [0f32; 32];
        for i in 0..k - 1 {
            let a = 255.0 * (ys[i + 1] - ys[i]);
            intercept[i] = (scale * (255.0 * ys[i] - i as f64 * a + shift)) as f32;
            slope[i] = (scale * a) as f32;
        }
        intercept[k - 1..].fill(match end {
            Some(q) => (scale * (q as f64 + shift)) as f32,
            None => (scale * ((255.0 * ys[k - 1]).floor() + 0.5 + shift)) as f32,
        });
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
        let start = if reverse { top as f32 } else { 0.0 };
        let reference = Reference::new(params, degamma);
        let threshold = (2.0 * scale * e + 0.5).ceil() as i32;
        Some(Self { planes, m, start, last: (k - 1) as i32, intercept, slope, threshold, split, merge, reference })
    }

    /// Runs whole blocks: `src.len() == dst.len()`, a multiple of [`BLOCK_BYTES`]. Each
    /// flagged pixel is redone by the f64 reference within a few blocks. Returns how many
    /// were flagged.
    pub(super) fn run(&self, src: &[u8], dst: &mut [u8]) -> usize {
        assert!(src.len() == dst.len() && src.len().is_multiple_of(BLOCK_BYTES));
        // SAFETY: a Kernel exists only where `supported()` held, so the CPU has every
        // feature `blocks` is compiled for.
        unsafe { self.blocks(src, dst) }
    }

    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vbmi")]
    fn blocks(&self, src: &[u8], dst: &mut [u8]) -> usize {
        let mut flagged = 0;
        // Byte offsets of flagged pixels waiting for the reference.
        let mut queue = [0usize; 8];
        let mut queued = 0;
        // SAFETY (all loads and stores below): every pointer is into `self`'s arrays of
        // 64 bytes / 16 f32, or into a 192-byte chunk of `src` / `dst`.
        let ld = |b: &[u8; 64]| unsafe { _mm512_loadu_si512(b.as_ptr().cast()) };
        let tables: [[__m512i; 4]; 4] = std::array::from_fn(|b| std::array::from_fn(|q| unsafe { _mm512_loadu_si512(self.planes[b][64 * q..].as_ptr().cast()) }));
        let split = self.split.map(|s| s.map(|v| ld(&v)));
        let merge = self.merge.map(|s| s.map(|v| ld(&v)));
        let m = self.m.map(|v| _mm512_set1_ps(v));
        let (zero, start) = (_mm512_setzero_ps(), _mm512_set1_ps(self.start));
        let (last, threshold) = (_mm512_set1_epi32(self.last), _mm512_set1_epi32(self.threshold));
        // Word j of a pack: the high word of dword 4·(j / 8) + j % 4 of the first (j % 8 < 4)
        // or second register, the order of `packus_epi32`.
        let high_words = _mm512_set_epi16(
            63, 61, 59, 57, 31, 29, 27, 25, 55, 53, 51, 49, 23, 21, 19, 17, 47, 45, 43, 41, 15, 13, 11, 9, 39, 37, 35, 33, 7, 5, 3, 1,
        );
        let (v0, v1) = unsafe { (_mm512_loadu_ps(self.intercept.as_ptr()), _mm512_loadu_ps(self.intercept[16..].as_ptr())) };
        let (s0, s1) = unsafe { (_mm512_loadu_ps(self.slope.as_ptr()), _mm512_loadu_ps(self.slope[16..].as_ptr())) };

        // Flag masks (bit i: pixel i of the block) of a stretch of blocks, scanned after
        // the stretch: the scan's unpredictable branches stay out of the vector loop.
        let mut masks = [0u64; STRETCH];
        let stretch_bytes = STRETCH * BLOCK_BYTES;
        for first in (0..src.len()).step_by(stretch_bytes) {
            let blocks = (src.len() - first).min(stretch_bytes) / BLOCK_BYTES;
            for (j, mask) in masks[..blocks].iter_mut().enumerate() {
                let base = first + j * BLOCK_BYTES;
                let (si, di) = (&src[base..base + BLOCK_BYTES], &mut dst[base..base + BLOCK_BYTES]);
                let mut raw = [_mm512_setzero_si512(); 3];
                for (r, v) in raw.iter_mut().enumerate() {
                    *v = unsafe { _mm512_loadu_si512(si[64 * r..].as_ptr().cast()) };
                }
                // Planes of 64 codes, then their degamma as 4 x 16 f32 lanes per channel.
                // Lane l of group g holds pixel 16·(l / 4) + 4·g + l % 4 (the unpack order).
                // (Plain loops, not closures: closures here are not inlined.)
                let mut lin = [[_mm512_setzero_ps(); 4]; 3];
                for c in 0..3 {
                    let t = _mm512_permutex2var_epi8(raw[0], split[c][0], raw[1]);
                    let codes = _mm512_permutex2var_epi8(t, split[c][1], raw[2]);
                    let high = _mm512_movepi8_mask(codes);
                    let mut bytes = [_mm512_setzero_si512(); 4];
                    for b in 0..4 {
                        let lo = _mm512_permutex2var_epi8(tables[b][0], codes, tables[b][1]);
                        let hi = _mm512_permutex2var_epi8(tables[b][2], codes, tables[b][3]);
                        bytes[b] = _mm512_mask_blend_epi8(high, lo, hi);
                    }
                    let (w01l, w01h) = (_mm512_unpacklo_epi8(bytes[0], bytes[1]), _mm512_unpackhi_epi8(bytes[0], bytes[1]));
                    let (w23l, w23h) = (_mm512_unpacklo_epi8(bytes[2], bytes[3]), _mm512_unpackhi_epi8(bytes[2], bytes[3]));
                    lin[c] = [
                        _mm512_castsi512_ps(_mm512_unpacklo_epi16(w01l, w23l)),
                        _mm512_castsi512_ps(_mm512_unpackhi_epi16(w01l, w23l)),
                        _mm512_castsi512_ps(_mm512_unpacklo_epi16(w01h, w23h)),
                        _mm512_castsi512_ps(_mm512_unpackhi_epi16(w01h, w23h)),
                    ];
                }
                // Flags: bit 2·l of group g's mask, lane l near a boundary in any channel.
                let mut near = [0u32; 4];
                let mut q = [[_mm512_setzero_si512(); 4]; 3];
                for g in 0..4 {
                    for c in 0..3 {
                        let s = _mm512_fmadd_ps(m[3 * c], lin[0][g], start);
                        let s = _mm512_fmadd_ps(m[3 * c + 1], lin[1][g], s);
                        let s = _mm512_fmadd_ps(m[3 * c + 2], lin[2][g], s);
                        let x = _mm512_max_ps(s, zero);
                        let seg = _mm512_min_epu32(_mm512_cvttps_epi32(x), last);
                        let b = _mm512_permutex2var_ps(v0, seg, v1);
                        let a = _mm512_permutex2var_ps(s0, seg, s1);
                        let t = _mm512_cvtps_epi32(_mm512_fmadd_ps(x, a, b));
                        near[g] |= _mm512_mask_cmplt_epu16_mask(0x5555_5555, t, threshold);
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
                *mask = (near[0] | near[1] << 1) as u64 | ((near[2] | near[3] << 1) as u64) << 32;
            }
            for (j, &mask) in masks[..blocks].iter().enumerate() {
                let mut any = mask;
                flagged += any.count_ones() as usize;
                while any != 0 {
                    // Lane l of group g is pixel 16·(l / 4) + 4·g + l % 4.
                    let bit = any.trailing_zeros() as usize;
                    let (g, l) = (2 * (bit / 32) + bit % 2, bit % 32 / 2);
                    queue[queued] = first + j * BLOCK_BYTES + 3 * (16 * (l / 4) + 4 * g + l % 4);
                    queued += 1;
                    if queued == 8 {
                        self.reference.redo(&queue, src, dst);
                        queued = 0;
                    }
                    any &= any - 1;
                }
            }
        }
        if queued > 0 {
            // Fill the batch with repeats of a queued pixel (redone twice, same result).
            let first = queue[0];
            queue[queued..].fill(first);
            self.reference.redo(&queue, src, dst);
        }
        flagged
    }
}

