//! The AVX2 engines of [`super::Exact8`] (x86-64 with AVX2 and FMA, checked at run time).
//!
//! [`run_lines`], for a uniform curve of at most 32 knots: the AVX-512 engine's arithmetic
//! ([`super::avx512`]) on its tables, eight lanes a step. The degamma is 24 scalar loads
//! from the f32 table (three gathers took 20% longer on AMD Zen 4); the matrix the same three FMAs from `-h`; the clamp to [-h, h] a max and
//! a min (equal to `vrangeps`'s absolute minimum with the input's sign for every finite
//! input, -0.0 included); the segment's slope and intercept come from the 32-entry tables
//! by four `vpermps` and three blends on bits 3 and 4 of `n` (the slot `n mod 32`, as
//! `vpermt2ps` reads it); the line is one FMA and one conversion, both rounding to
//! nearest-even as the AVX-512 engine's do. Every lane's value is therefore the AVX-512
//! engine's bit for bit, within its stated bound `E_c` of the reference, and a channel
//! within `E_c` of a rounding boundary is queued alone (no branch a channel) and redone by
//! the reference's own f64 operations on that channel ([`super::avx512::Reference::sample`],
//! the AVX-512 engine's eight-lane redo in scalar f64), which is the reference's code. (It
//! had been redone as the scalar engine decides a pixel, all three channels through its
//! tables and then the f64 reference: 0.5 ms of a `campro-omega-0.5` frame with 0.85% of
//! pixels flagged, against 0.1 ms now.)
//!
//! [`run`], for any other curve: the scalar tables, eight pixels a step by gathers. Each step deinterleaves 24 bytes of RGB
//! into three vectors of 32-bit codes (two loads, six byte shuffles), gathers the nine
//! matrix-times-degamma terms (`terms[256 j + x][c]`), sums them in the scalar engine's
//! order ((r + g) + b, no FMA) and clamps them to [0, 1], so every lane's curve input is
//! the scalar engine's f32 bit for bit; truncates `t · FINE` to the cell (as the scalar
//! `to_int_unchecked` does) and gathers the three cells. A lane whose cell holds a split
//! or is ambiguous is redone by the scalar engine's own decision ([`super::Exact8::decide`])
//! after the step: the engine's output equals the scalar engine's, which equals the
//! reference's on every code triple (the exhaustive test runs each engine).

use super::avx512::Kernel;
use super::{Exact8, AMBIGUOUS, FINE};
use std::arch::x86_64::*;

/// Pixels per step.
pub(super) const STEP: usize = 8;
/// Bytes per step.
pub(super) const STEP_BYTES: usize = 3 * STEP;

/// Whether this CPU runs the engines.
pub(super) fn available() -> bool {
    is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
}

/// The AVX-512 engine's line tables' entries `t` at slots `n mod 32` (`n` in each lane):
/// a permute of each quarter by bits 0..3, then blends on bit 3 and bit 4.
#[inline(always)]
unsafe fn pick(t: &[__m256; 4], n: __m256i) -> __m256 {
    let bit3 = _mm256_castsi256_ps(_mm256_slli_epi32::<28>(n));
    let bit4 = _mm256_castsi256_ps(_mm256_slli_epi32::<27>(n));
    let lo = _mm256_blendv_ps(_mm256_permutevar8x32_ps(t[0], n), _mm256_permutevar8x32_ps(t[1], n), bit3);
    let hi = _mm256_blendv_ps(_mm256_permutevar8x32_ps(t[2], n), _mm256_permutevar8x32_ps(t[3], n), bit3);
    _mm256_blendv_ps(lo, hi, bit4)
}

/// Channel `c` of a step's eight pixels `s` through the 256-entry degamma table: scalar
/// loads inserted. A function called without closures, so that it is inlined into the AVX2
/// loop: a closure there (`array::from_fn`, `map`) was compiled as a call per channel whose
/// result went through the stack, more than doubling the time (10.5 against 4.5 ms a frame).
///
/// # Safety
/// `s` holds [`STEP_BYTES`] bytes, `c < 3`, `degamma` points at 256 floats.
#[inline(always)]
unsafe fn linear(degamma: *const f32, s: &[u8], c: usize) -> __m256 {
    // SAFETY: 3 p + c < 24 = STEP_BYTES, the chunk's length; a code indexes the table.
    macro_rules! g {
        ($p:expr) => {
            *degamma.add(*s.get_unchecked(3 * $p + c) as usize)
        };
    }
    _mm256_setr_ps(g!(0), g!(1), g!(2), g!(3), g!(4), g!(5), g!(6), g!(7))
}

/// [`run_lines`]'s byte shuffle: from the packs' order in each 128-bit half (R0..R3,
/// G0..G3, B0..B3) to four RGB pixels in its first 12 bytes.
const PACK: [i8; 16] = [0, 4, 8, 1, 5, 9, 2, 6, 10, 3, 7, 11, -1, -1, -1, -1];

/// Flagged samples held before [`run_lines`] decides them.
const QUEUE: usize = 256;

/// Decides each flagged sample (the byte offset in `src` of one channel of a pixel, the
/// channel its offset mod 3) by the f64 reference, one channel alone
/// ([`super::avx512::Reference::sample`]).
#[inline(never)]
fn decide_queued(k: &Kernel, src: &[u8], dst: &mut [u8], queue: &[usize]) {
    for &at in queue {
        let p = at - at % 3;
        dst[at] = k.reference.sample([src[p], src[p + 1], src[p + 2]], at % 3);
    }
}

/// The engine on the AVX-512 engine's tables `k` over whole steps of `src` into `dst`;
/// returns the pixels flagged (and redone by the reference) and the bytes done.
///
/// # Safety
/// The CPU has AVX2 and FMA ([`available`]).
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn run_lines(k: &Kernel, src: &[u8], dst: &mut [u8]) -> (usize, usize) {
    let whole = src.len().min(dst.len()) / STEP_BYTES * STEP_BYTES;
    let quarters = |t: &[f32; 32]| [0, 8, 16, 24].map(|o| _mm256_loadu_ps(t[o..].as_ptr()));
    let slope = quarters(&k.slope);
    let intercept = k.intercept.each_ref().map(quarters);
    let m = k.m.map(|v| _mm256_set1_ps(v));
    let (start, top) = (_mm256_set1_ps(-k.half), _mm256_set1_ps(k.half));
    let threshold = k.threshold.map(|t| _mm256_set1_epi32(t));
    let low16 = _mm256_set1_epi32(0xFFFF);
    let pack = _mm256_broadcastsi128_si256(_mm_loadu_si128(PACK.as_ptr() as *const __m128i));
    let degamma = k.degamma.as_ptr();
    let mut flagged = 0;
    let mut queue = [0usize; QUEUE];
    let mut queued = 0;
    for at in (0..whole).step_by(STEP_BYTES) {
        let s = &src[at..at + STEP_BYTES];
        let d = &mut dst[at..at + STEP_BYTES];
        // The degamma by scalar loads (a byte index, then the f32 inserted): 20% faster
        // than three gathers on AMD Zen 4, where a gather is slow.
        let lin = [linear(degamma, s, 0), linear(degamma, s, 1), linear(degamma, s, 2)];
        let mut near = [0u32; 3];
        let mut code = [_mm256_setzero_si256(); 3];
        for c in 0..3 {
            let x = _mm256_fmadd_ps(m[3 * c], lin[0], start);
            let x = _mm256_fmadd_ps(m[3 * c + 1], lin[1], x);
            let x = _mm256_fmadd_ps(m[3 * c + 2], lin[2], x);
            let x = _mm256_min_ps(_mm256_max_ps(x, start), top);
            // Round to nearest, ties to even (the MXCSR default, as Rust leaves it).
            let n = _mm256_cvtps_epi32(x);
            let t = _mm256_cvtps_epi32(_mm256_fmadd_ps(x, pick(&slope, n), pick(&intercept[c], n)));
            let close = _mm256_cmpgt_epi32(threshold[c], _mm256_and_si256(t, low16));
            near[c] = _mm256_movemask_ps(_mm256_castsi256_ps(close)) as u32;
            // The code: the high 16 bits (saturated to a byte by the packs below, as the
            // AVX-512 engine's packs do).
            code[c] = _mm256_srai_epi32::<16>(t);
        }
        // Per 128-bit half: R0..R3 G0..G3 B0..B3 (B again), then interleaved.
        let words = _mm256_packs_epi32(code[0], code[1]);
        let blue = _mm256_packs_epi32(code[2], code[2]);
        let out = _mm256_shuffle_epi8(_mm256_packus_epi16(words, blue), pack);
        // Pixels 0..3 (12 bytes, then 4 spare bytes that the next store overwrites), 4..7.
        _mm_storeu_si128(d.as_mut_ptr() as *mut __m128i, _mm256_castsi256_si128(out));
        let high = _mm256_extracti128_si256::<1>(out);
        _mm_storel_epi64(d.as_mut_ptr().add(12) as *mut __m128i, high);
        (d.as_mut_ptr().add(20) as *mut i32).write_unaligned(_mm_extract_epi32::<2>(high));
        // Flagged samples are queued, without a branch a channel, and decided after a
        // stretch of steps (a call in the loop would make it keep its tables on the stack).
        let mut f = near[0] | near[1] | near[2];
        flagged += f.count_ones() as usize;
        while f != 0 {
            let lane = f.trailing_zeros() as usize;
            for (c, n) in near.iter().enumerate() {
                queue[queued] = at + 3 * lane + c;
                queued += (n >> lane & 1) as usize;
            }
            f &= f - 1;
        }
        if queued > QUEUE - 3 * STEP {
            decide_queued(k, src, dst, &queue[..queued]);
            queued = 0;
        }
    }
    decide_queued(k, src, dst, &queue[..queued]);
    (flagged, whole)
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
    let cells = e.cells.each_ref().map(|t| t.as_ptr() as *const i32);
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
            *out = _mm256_and_si256(_mm256_i32gather_epi32::<2>(cells[c], cell), low16);
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
