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
//!   come from two `vpermi2ps`, one FMA evaluates.
//! - Output: round to nearest. A lane whose value lies within the path's error bound `E`
//!   of a rounding boundary is flagged, and its pixel is redone by the f64 reference
//!   within the same block (its bytes are still in L1), so the result is bit-identical to
//!   the reference.
//! - Clipped lanes: `x = k - 1` exactly (the matrix output clipped at that end) reads
//!   table slot `k - 1` (slope 0), which holds the rounded code of the curve's end if that
//!   code is the same over the last `E`-wide stretch of input, so a curve ending exactly
//!   on a rounding tie (y = 0.5) does not send every clipped pixel to the reference. The
//!   orientation (x or `k - 1 - x`) is chosen so that this slot serves the end that
//!   needs it.
//!
//! `E` (output LSB) = `255 · L · 5u · (S + 1) + u · (2 · 255 + 2 · (k - 1) · D)`, widened
//! by 1% (u = 2^-24; S the largest absolute row sum of the CCM; L the curve's largest
//! slope; D the largest knot step in LSB): the matrix sum carries at most `5u · (S + 1)` in
//! curve-input units (f32 CCM and degamma entries, three FMA roundings, partial sums
//! bounded by `S + 1` with the reversed start), which the curve amplifies by L; the
//! intercept (|b| <= 255 + (k - 1) · D) and the slope each round once, as does the final
//! FMA (|w| <= 255). `floor` is exact and the curve continuous, so the segment choice
//! adds nothing.

use crate::params::Params;
use std::arch::x86_64::*;

/// Pixels per step.
pub(super) const BLOCK: usize = 64;
/// Bytes per step.
pub(super) const BLOCK_BYTES: usize = 3 * BLOCK;

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
    (255.0 * l * 5.0 * u * (s + 1.0) + u * (2.0 * 255.0 + 2.0 * top * d)) * 1.01 + 1e-12 * (1.0 + l * s) * 255.0
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
    /// `k - 1`.
    top: f32,
    /// `255 · y_i - i · slope_i` (of the curve in this orientation): segment i's line at
    /// x = 0; slot `k - 1` holds the end's code (or code + 0.5, always flagged, when the
    /// end is ambiguous); padded after.
    intercept: [f32; 32],
    /// `255 · (y_{i+1} - y_i)`, zero from `k - 1` on.
    slope: [f32; 32],
    /// A lane with `|w - round(w)| > margin` is within `E` of a rounding boundary.
    margin: f32,
    /// Byte permutes: deinterleave (plane c: first from bytes 0..128, then 128..192)
    /// and interleave (output register r: first R and G, then B).
    split: [[[u8; 64]; 2]; 3],
    merge: [[[u8; 64]; 2]; 3],
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
        let mut intercept = [0f32; 32];
        let mut slope = [0f32; 32];
        for i in 0..k - 1 {
            let a = 255.0 * (ys[i + 1] - ys[i]);
            intercept[i] = (255.0 * ys[i] - i as f64 * a) as f32;
            slope[i] = a as f32;
        }
        intercept[k - 1..].fill(match end {
            Some(q) => q as f32,
            None => (255.0 * ys[k - 1]).floor() as f32 + 0.5,
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
        Some(Self { planes, m, start, top: top as f32, intercept, slope, margin: (0.5 - e) as f32, split, merge })
    }

    /// Runs whole blocks: `src.len() == dst.len()`, a multiple of [`BLOCK_BYTES`]. Each
    /// flagged pixel's output is `exact(its input)`, computed as its block is done.
    /// Returns how many were flagged.
    pub(super) fn run(&self, src: &[u8], dst: &mut [u8], exact: impl Fn([u8; 3]) -> [u8; 3]) -> usize {
        assert!(src.len() == dst.len() && src.len().is_multiple_of(BLOCK_BYTES));
        // SAFETY: a Kernel exists only where `supported()` held, so the CPU has every
        // feature `blocks` is compiled for.
        unsafe { self.blocks(src, dst, &exact) }
    }

    #[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vbmi")]
    fn blocks(&self, src: &[u8], dst: &mut [u8], exact: &dyn Fn([u8; 3]) -> [u8; 3]) -> usize {
        let mut flagged = 0;
        // SAFETY (all loads and stores below): every pointer is into `self`'s arrays of
        // 64 bytes / 16 f32, or into a 192-byte chunk of `src` / `dst`.
        let ld = |b: &[u8; 64]| unsafe { _mm512_loadu_si512(b.as_ptr().cast()) };
        let tables: [[__m512i; 4]; 4] = std::array::from_fn(|b| std::array::from_fn(|q| unsafe { _mm512_loadu_si512(self.planes[b][64 * q..].as_ptr().cast()) }));
        let split = self.split.map(|s| s.map(|v| ld(&v)));
        let merge = self.merge.map(|s| s.map(|v| ld(&v)));
        let m = self.m.map(|v| _mm512_set1_ps(v));
        let (zero, start, top, margin) = (_mm512_setzero_ps(), _mm512_set1_ps(self.start), _mm512_set1_ps(self.top), _mm512_set1_ps(self.margin));
        let (v0, v1) = unsafe { (_mm512_loadu_ps(self.intercept.as_ptr()), _mm512_loadu_ps(self.intercept[16..].as_ptr())) };
        let (s0, s1) = unsafe { (_mm512_loadu_ps(self.slope.as_ptr()), _mm512_loadu_ps(self.slope[16..].as_ptr())) };

        for (si, di) in src.chunks_exact(BLOCK_BYTES).zip(dst.chunks_exact_mut(BLOCK_BYTES)) {
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
            let mut flags = [0u16; 4];
            let mut q = [[_mm512_setzero_si512(); 4]; 3];
            for g in 0..4 {
                // Largest |w - round(w)| over the three channels (vrangeps: max |a|, |b|).
                let mut worst = zero;
                for c in 0..3 {
                    let s = _mm512_fmadd_ps(m[3 * c], lin[0][g], start);
                    let s = _mm512_fmadd_ps(m[3 * c + 1], lin[1][g], s);
                    let s = _mm512_fmadd_ps(m[3 * c + 2], lin[2][g], s);
                    let x = _mm512_min_ps(_mm512_max_ps(s, zero), top);
                    let seg = _mm512_cvttps_epi32(x);
                    let b = _mm512_permutex2var_ps(v0, seg, v1);
                    let a = _mm512_permutex2var_ps(s0, seg, s1);
                    let w = _mm512_fmadd_ps(x, a, b);
                    let off = _mm512_reduce_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(w);
                    worst = _mm512_range_ps::<0b1011>(worst, off);
                    q[c][g] = _mm512_cvtps_epi32(w);
                }
                flags[g] = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(worst, margin);
            }
            // Pack back to byte planes (packs undo the unpack order), then interleave.
            let mut planes = [_mm512_setzero_si512(); 3];
            for c in 0..3 {
                let a = _mm512_packus_epi32(q[c][0], q[c][1]);
                let b = _mm512_packus_epi32(q[c][2], q[c][3]);
                planes[c] = _mm512_packus_epi16(a, b);
            }
            for (r, mg) in merge.iter().enumerate() {
                let t = _mm512_permutex2var_epi8(planes[0], mg[0], planes[1]);
                let out = _mm512_permutex2var_epi8(t, mg[1], planes[2]);
                unsafe { _mm512_storeu_si512(di[64 * r..].as_mut_ptr().cast(), out) };
            }
            if flags.iter().any(|&f| f != 0) {
                // Lane l of group g is pixel 16·(l / 4) + 4·g + l % 4.
                let mut any = 0u64;
                for (g, &f) in flags.iter().enumerate() {
                    for l in 0..16 {
                        any |= ((f >> l & 1) as u64) << (16 * (l / 4) + 4 * g + l % 4);
                    }
                }
                flagged += any.count_ones() as usize;
                while any != 0 {
                    let i = 3 * any.trailing_zeros() as usize;
                    di[i..i + 3].copy_from_slice(&exact([si[i], si[i + 1], si[i + 2]]));
                    any &= any - 1;
                }
            }
        }
        flagged
    }
}

