//! The AVX2 engine of [`super::Exact8`] (x86-64 with AVX2, checked at run time): the
//! scalar tables, eight pixels a step by gathers. Each step deinterleaves 24 bytes of RGB
//! into three vectors of 32-bit codes (two loads, six byte shuffles), gathers the nine
//! matrix-times-degamma terms (`terms[256 j + x][c]`), sums them in the scalar engine's
//! order ((r + g) + b, no FMA) and clamps them to [0, 1], so every lane's curve input is
//! the scalar engine's f32 bit for bit; truncates `t · FINE` to the cell (as the scalar
//! `to_int_unchecked` does) and gathers the three cells. A lane whose cell holds a split
//! or is ambiguous is redone by the scalar engine's own decision ([`super::Exact8::decide`])
//! after the step: the engine's output equals the scalar engine's, which equals the
//! reference's on every code triple (the exhaustive test runs each engine).

use super::{Exact8, AMBIGUOUS, FINE};
use std::arch::x86_64::*;

/// Pixels per step.
pub(super) const STEP: usize = 8;
/// Bytes per step.
pub(super) const STEP_BYTES: usize = 3 * STEP;

/// Whether this CPU runs the engine.
pub(super) fn available() -> bool {
    is_x86_feature_detected!("avx2")
}

/// Byte shuffle taking the channel at `offset` of four packed RGB pixels (bytes `offset`,
/// `offset + 3`, ... of a 16-byte load starting at `base`) into four zero-extended 32-bit
/// lanes; -1 zeroes a byte.
const fn spread(base: i8, offset: i8) -> [i8; 16] {
    let mut m = [-1i8; 16];
    let mut p = 0;
    while p < 4 {
        m[4 * p] = base + offset + 3 * p as i8;
        p += 1;
    }
    m
}

/// The engine over whole steps of `src` into `dst`; returns the pixels the reference redid
/// and the bytes done.
///
/// # Safety
/// The CPU has AVX2 ([`available`]).
#[target_feature(enable = "avx2")]
pub(super) unsafe fn run(e: &Exact8, src: &[u8], dst: &mut [u8]) -> (usize, usize) {
    let whole = src.len().min(dst.len()) / STEP_BYTES * STEP_BYTES;
    let terms = e.terms.as_ptr() as *const f32;
    let cells = e.cells.as_ptr() as *const i32;
    // The low half's four pixels come from bytes 0..16 (pixels 0..3 at 0, 3, 6, 9), the
    // high half's from bytes 8..24 (pixels 4..7 at 12 - 8 = 4, 7, 10, 13).
    let lo = |c: i8| _mm_loadu_si128(spread(0, c).as_ptr() as *const __m128i);
    let hi = |c: i8| _mm_loadu_si128(spread(4, c).as_ptr() as *const __m128i);
    let (lo_r, lo_g, lo_b) = (lo(0), lo(1), lo(2));
    let (hi_r, hi_g, hi_b) = (hi(0), hi(1), hi(2));
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let fine = _mm256_set1_ps(FINE as f32);
    let last = _mm256_set1_epi32(FINE as i32);
    let low16 = _mm256_set1_epi32(0xFFFF);
    let code_max = _mm256_set1_epi32(AMBIGUOUS as i32 - 1);
    let mut fell = 0;
    for (s, d) in src[..whole].chunks_exact(STEP_BYTES).zip(dst[..whole].chunks_exact_mut(STEP_BYTES)) {
        let a = _mm_loadu_si128(s.as_ptr() as *const __m128i);
        let b = _mm_loadu_si128(s.as_ptr().add(8) as *const __m128i);
        let channel = |ml: __m128i, mh: __m128i| _mm256_set_m128i(_mm_shuffle_epi8(b, mh), _mm_shuffle_epi8(a, ml));
        // Index of terms[256 j + x][0] in floats: 4 (256 j + x).
        let r = _mm256_slli_epi32::<2>(channel(lo_r, hi_r));
        let g = _mm256_add_epi32(_mm256_slli_epi32::<2>(channel(lo_g, hi_g)), _mm256_set1_epi32(4 * 256));
        let bl = _mm256_add_epi32(_mm256_slli_epi32::<2>(channel(lo_b, hi_b)), _mm256_set1_epi32(4 * 512));
        let mut code = [_mm256_setzero_si256(); 3];
        for (c, out) in code.iter_mut().enumerate() {
            let k = _mm256_set1_epi32(c as i32);
            let tr = _mm256_i32gather_ps::<4>(terms, _mm256_add_epi32(r, k));
            let tg = _mm256_i32gather_ps::<4>(terms, _mm256_add_epi32(g, k));
            let tb = _mm256_i32gather_ps::<4>(terms, _mm256_add_epi32(bl, k));
            let t = _mm256_min_ps(_mm256_max_ps(_mm256_add_ps(_mm256_add_ps(tr, tg), tb), zero), one);
            let cell = _mm256_min_epi32(_mm256_cvttps_epi32(_mm256_mul_ps(t, fine)), last);
            // Cells are u16: a 32-bit gather at byte 2 · cell, its low half kept (the
            // table has a padding cell past FINE for the last one's high half).
            *out = _mm256_and_si256(_mm256_i32gather_epi32::<2>(cells, cell), low16);
        }
        let any = _mm256_or_si256(_mm256_or_si256(code[0], code[1]), code[2]);
        let flags = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(any, code_max))) as u32;
        let mut lanes = [[0u32; STEP]; 3];
        for c in 0..3 {
            _mm256_storeu_si256(lanes[c].as_mut_ptr() as *mut __m256i, code[c]);
        }
        for p in 0..STEP {
            d[3 * p] = lanes[0][p] as u8;
            d[3 * p + 1] = lanes[1][p] as u8;
            d[3 * p + 2] = lanes[2][p] as u8;
        }
        let mut f = flags;
        while f != 0 {
            fell += e.redo(s, d, 3 * f.trailing_zeros() as usize) as usize;
            f &= f - 1;
        }
    }
    (fell, whole)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shuffles_take_each_channel_of_eight_pixels() {
        if !available() {
            eprintln!("SKIP: no AVX2");
            return;
        }
        let src: Vec<u8> = (0..24).collect();
        // SAFETY: AVX2 checked above.
        unsafe {
            let a = _mm_loadu_si128(src.as_ptr() as *const __m128i);
            let b = _mm_loadu_si128(src.as_ptr().add(8) as *const __m128i);
            for c in 0..3 {
                let lo = _mm_loadu_si128(spread(0, c).as_ptr() as *const __m128i);
                let hi = _mm_loadu_si128(spread(4, c).as_ptr() as *const __m128i);
                let v = _mm256_set_m128i(_mm_shuffle_epi8(b, hi), _mm_shuffle_epi8(a, lo));
                let mut got = [0u32; 8];
                _mm256_storeu_si256(got.as_mut_ptr() as *mut __m256i, v);
                let want: Vec<u32> = (0..8).map(|p| (3 * p + c as usize) as u32).collect();
                assert_eq!(got.to_vec(), want, "channel {c}");
            }
        }
    }
}
