//! Fast paths of the desktop pipeline, each checked against the f64 reference
//! ([`super::Prepared`]) with a stated error.
//!
//! - [`Exact8`]: 8-bit in, 8-bit out, **bit-identical** to the reference's rounded
//!   output. The matrix is split per input channel into tables of `CCM[:, j] · degamma(x)`
//!   (f32, three 4-lane loads per pixel); the clipped sum indexes a table of 2^16 cells
//!   over [0, 1] holding the rounded curve output wherever it is the same for every value
//!   the cell (widened by the f32 error bound) can hold. Cells where a rounding boundary
//!   falls inside are marked, and their pixels take the reference path. So the error is
//!   the reference's own rounding (<= 0.5 LSB); the marked fraction, reported by
//!   [`Exact8::fallback_fraction`], grows with the curve's slope.
//!   On x86-64 CPUs with AVX-512 (F, BW, DQ, VBMI) and a uniform curve of at most 32
//!   knots, whole blocks of 64 pixels run on the gather-free engine of [`avx512`]
//!   instead, which flags lanes near a rounding boundary for the reference in the same
//!   way (redone eight at a time by the reference's own f64 operations on vector lanes):
//!   still bit-identical. [`Exact8::engine`] says which runs.
//! - [`F32Path`]: any depth in and out, in f32: a degamma table over every input code, the
//!   3x3 matrix, and the curve by exact piecewise-linear interpolation. Its error against
//!   the reference is stated by [`F32Path::error_bound`] (f32 rounding amplified by the
//!   curve's slope) plus the output rounding.
//! - Stage elision ([`Elision`]): an identity matrix skips the matrix, an identity curve
//!   skips the curve; both are exact.

#[cfg(target_arch = "x86_64")]
mod avx2;
#[cfg(target_arch = "x86_64")]
mod avx512;

use super::{degamma, Depth, Prepared};
use crate::ccm;
use crate::params::Params;
use crate::tone_curve::{ToneCurve, ToneCurves};
use std::sync::Arc;

/// Cells of [`Exact8`]'s output table over [0, 1] (2^16; the last cell holds t = 1).
const FINE: usize = 1 << 16;
/// Entries of the cell table: FINE + 1 cells and a padding entry, so that a 32-bit gather
/// of the last cell (the AVX2 engine's) stays inside it.
const CELLS: usize = FINE + 2;
/// Marks a cell whose pixels take the reference path. A cell below it holds its code.
const AMBIGUOUS: u16 = 0x100;
/// Marks a split cell: the low 15 bits index [`Exact8`]'s splits.
const SPLIT: u16 = 0x8000;
/// Pixels a block of [`Exact8`]'s portable engine looks up before it decides the ones that
/// need more.
const LANES: usize = 16;
/// Most split cells a table holds (indices below [`SPLIT`]).
const MAX_SPLITS: usize = 0x7FFF;

/// A cell holding exactly one rounding boundary of the reference's output, at curve input
/// `t*`: every input below `t*` gives `below`, every input from `t*` on gives `above`. Its
/// pixels whose f32 input lies within the error bound of `t*` (between `lo` and `hi`) have
/// that one input recomputed as the reference computes it (f64, same operations) and
/// compared with `t*`, no curve evaluated; the others are decided by comparing the f32
/// input with `lo` and `hi`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Split {
    /// `t*`, the least f64 input (in bit order, within the cell) whose code is `above`.
    at: f64,
    /// `t* - delta`, rounded down to f32: an f32 input below it is surely below `t*`.
    lo: f32,
    /// `t* + delta`, rounded up to f32: an f32 input from it on is surely at or above `t*`.
    hi: f32,
    below: u8,
    above: u8,
}

/// `a + b + c` lane by lane, summed in that order and clamped to [0, 1], as four lanes of
/// one register: SSE on x86-64 (`maxps`/`minps`), elsewhere `f32::max`/`min`, which
/// AArch64 lowers to single `fmaxnm`/`fminnm` (NEON on four lanes). Written out for x86-64
/// because LLVM scalarised the portable form there and turned its clamps into a branch a
/// lane (7.7 against 9.3 ms a 1080p bench frame). No NaN can occur (the terms are finite); -0.0
/// may become +0.0 or stay, which indexes the same cell and compares equal.
#[inline(always)]
fn clamped_sum(a: &[f32; 4], b: &[f32; 4], c: &[f32; 4]) -> [f32; 4] {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of the x86-64 baseline; the loads and the store are of 4 f32s.
    unsafe {
        use std::arch::x86_64::*;
        let x = _mm_add_ps(_mm_add_ps(_mm_loadu_ps(a.as_ptr()), _mm_loadu_ps(b.as_ptr())), _mm_loadu_ps(c.as_ptr()));
        let x = _mm_min_ps(_mm_max_ps(x, _mm_setzero_ps()), _mm_set1_ps(1.0));
        let mut t = [0f32; 4];
        _mm_storeu_ps(t.as_mut_ptr(), x);
        t
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        clamped_sum_portable(a, b, c)
    }
}

/// [`clamped_sum`] in portable Rust (the path of every CPU but x86-64; tested against the
/// SSE one here).
#[inline(always)]
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
// max then min (AArch64's fmaxnm and fminnm), not `clamp`'s compares and selects.
#[allow(clippy::manual_clamp)]
fn clamped_sum_portable(a: &[f32; 4], b: &[f32; 4], c: &[f32; 4]) -> [f32; 4] {
    let mut t = [0f32; 4];
    for k in 0..4 {
        t[k] = (a[k] + b[k] + c[k]).max(0.0).min(1.0);
    }
    t
}

/// Round-half-up to an output code, as [`Prepared::run`] does.
#[inline]
fn quantize(v: f64, max: f64) -> u16 {
    (v * max + 0.5) as u16
}

/// Which stages an image path can skip for a parameter set, exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Elision {
    /// The CCM is exactly the identity: `clip(CCM · v) = v` for linear v in [0, 1].
    pub matrix: bool,
    /// The curve is exactly `y = x` (every knot on the line): interpolation is the identity.
    pub curve: bool,
}

impl Elision {
    /// What `p` lets the pipeline skip.
    pub fn of(p: &Params) -> Self {
        Self { matrix: p.ccm == ccm::IDENTITY, curve: p.tone_curves.is_identity(0.0) }
    }
}

/// Whether the AVX2 engine beats the scalar tables on this CPU: `tables` (the first
/// `Exact8` of the process) run on both over 16,384 pixels of a fixed scene (best of three,
/// about a millisecond in all), once per process. Either is bit-identical, so the choice
/// changes speed only.
fn avx2_pays(tables: &Exact8) -> bool {
    static PAYS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *PAYS.get_or_init(|| {
        let src: Vec<u8> = (0..3 * 16384u32).map(|i| (i.wrapping_mul(2654435761) >> 24) as u8).collect();
        let mut dst = vec![0u8; src.len()];
        let mut time = |engine: Engine| {
            let x = Exact8 { engine, ..tables.clone() };
            (0..3)
                .map(|_| {
                    let t = std::time::Instant::now();
                    x.run(&src, &mut dst);
                    t.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min)
        };
        time(Engine::Avx2) < time(Engine::Scalar)
    })
}

/// 8-bit RGB in, 8-bit RGB out, bit-identical to [`Prepared::run`] with 8-bit output.
#[derive(Debug, Clone)]
pub struct Exact8<'a> {
    reference: Prepared<'a>,
    /// `terms[256 * j + x] = (CCM[0][j], CCM[1][j], CCM[2][j], 0) · degamma(x / 255)`.
    /// Fixed-size, so that an index `256 * j + u8` needs no bounds check.
    terms: Box<[[f32; 4]; 3 * 256]>,
    /// Per output channel, FINE + 1 cells: the output code, [`AMBIGUOUS`], or [`SPLIT`] |
    /// an index into `splits`; then a padding entry ([`CELLS`]). Fixed-size, so that an
    /// index clamped to `FINE` needs no bounds check; one table shared by the three
    /// channels when the curve is.
    cells: [Arc<[u16; CELLS]>; 3],
    splits: Vec<Split>,
    ambiguous: usize,
    elision: Elision,
    #[cfg(target_arch = "x86_64")]
    simd: Option<avx512::Kernel>,
    /// The engine [`Exact8::run`] uses.
    engine: Engine,
}

/// Pixels of one [`Exact8::run`] redone by the f64 reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Fallbacks {
    /// Flagged by the AVX-512 engine or the AVX2 one on its tables (a value within its
    /// error bound of a rounding boundary).
    pub flagged: usize,
    /// Outside whole blocks (or without the engine): ambiguous in the scalar tables.
    pub ambiguous: usize,
}

/// Which engine [`Exact8::run`] uses for whole blocks. All are bit-identical to the
/// reference; they differ in speed only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    /// The tables, 16 pixels a block with their fallbacks queued after it (any CPU, any
    /// curve; the fast path on ARM, where LLVM lowers its four-lane sums to NEON).
    Scalar,
    /// Eight pixels a step (x86-64 with AVX2 and FMA): the AVX-512 engine's arithmetic on
    /// its tables (uniform curve of <= 32 knots: the degamma by scalar loads, every other
    /// lookup a register permute), else the scalar tables by gathers (any curve).
    Avx2,
    /// 64 pixels per step with AVX-512 (x86-64; uniform curve of <= 32 knots).
    Avx512,
}

/// The environment variable that picks an engine (`scalar`, `avx2` or `avx512`), for
/// timing and testing each on one machine; unset, the fastest that runs is used.
pub const ENGINE_VARIABLE: &str = "CAMPRO_ENGINE";

impl Engine {
    /// Every engine, slowest first.
    pub const ALL: [Engine; 3] = [Engine::Scalar, Engine::Avx2, Engine::Avx512];

    /// Whether this CPU runs it for some parameter set (AVX-512 also needs a uniform curve
    /// of at most 32 knots: [`Exact8::runs`] says for one).
    pub fn runs_here(self) -> bool {
        match self {
            Engine::Scalar => true,
            #[cfg(target_arch = "x86_64")]
            Engine::Avx2 => avx2::available(),
            #[cfg(target_arch = "x86_64")]
            Engine::Avx512 => avx512::supported(),
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// Its name, as [`ENGINE_VARIABLE`] takes it.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Scalar => "scalar",
            Engine::Avx2 => "avx2",
            Engine::Avx512 => "avx512",
        }
    }

    /// The engine [`ENGINE_VARIABLE`] names: None when unset; the line saying what it takes
    /// when it names none.
    pub fn from_env() -> Result<Option<Engine>, String> {
        match std::env::var(ENGINE_VARIABLE) {
            Err(std::env::VarError::NotPresent) => Ok(None),
            Ok(v) => Engine::ALL.into_iter().find(|e| e.name() == v).map(Some).ok_or_else(|| {
                format!("{ENGINE_VARIABLE}={}: not an engine (scalar, avx2 or avx512)", v.escape_debug())
            }),
            Err(_) => Err(format!("{ENGINE_VARIABLE}: not UTF-8 (scalar, avx2 or avx512)")),
        }
    }
}

impl<'a> Exact8<'a> {
    /// Builds the tables (about a millisecond) for the engine [`ENGINE_VARIABLE`] asks for
    /// where it runs here, else the fastest here.
    pub fn new(params: &'a Params) -> Self {
        let reference = Prepared::new(params, Depth::Eight);
        let d: Vec<f64> = (0..256).map(|c| degamma(c as f64 / 255.0, params.degamma)).collect();
        let m = &params.ccm;
        let mut terms = Box::new([[0f32; 4]; 3 * 256]);
        for j in 0..3 {
            for x in 0..256 {
                terms[256 * j + x] = [(m[0][j] * d[x]) as f32, (m[1][j] * d[x]) as f32, (m[2][j] * d[x]) as f32, 0.0];
            }
        }
        // |f32 sum - f64 reference sum| <= 3 · 2^-24 · Σ_j |CCM_cj| (one rounding per
        // term, two per addition, partial sums bounded by the row's absolute sum), plus
        // the reference's own f64 rounding.
        let row = crate::ccm::norm_inf(m);
        let delta = 3.0 * row * f32::EPSILON as f64 / 2.0 * 1.0000001 + 1e-12;
        let mut splits = Vec::new();
        let mut ambiguous = 0;
        let mut table = |curve: &ToneCurve| {
            let (mut cells, a) = cell_table(curve, delta, &mut splits);
            ambiguous += a;
            cells.push(0);
            let cells: Box<[u16; CELLS]> = cells.into_boxed_slice().try_into().expect("FINE + 1 cells and a pad");
            Arc::<[u16; CELLS]>::from(cells)
        };
        let cells = match &params.tone_curves {
            ToneCurves::Shared(t) => {
                let one = table(t);
                [one.clone(), one.clone(), one]
            }
            ToneCurves::PerChannel(t) => [table(&t[0]), table(&t[1]), table(&t[2])],
        };
        let mut e = Self {
            #[cfg(target_arch = "x86_64")]
            simd: (avx512::supported() || avx2::available()).then(|| avx512::Kernel::new(params, &d)).flatten(),
            reference,
            terms,
            cells,
            splits,
            ambiguous,
            elision: Elision::of(params),
            engine: Engine::Scalar,
        };
        // The engine asked for where it runs here, else AVX-512 where it runs, else the
        // faster of AVX2 and the scalar tables on this CPU (gathers are slower than scalar
        // loads on some: AMD Zen 1 takes 1.4x as long with them).
        let asked = Engine::from_env().ok().flatten().filter(|&a| e.runs(a));
        e.engine = match asked {
            Some(a) => a,
            None if e.runs(Engine::Avx512) => Engine::Avx512,
            None if e.runs(Engine::Avx2) && avx2_pays(&e) => Engine::Avx2,
            None => Engine::Scalar,
        };
        e
    }

    /// Whether `engine` runs on this CPU for these parameters.
    pub fn runs(&self, engine: Engine) -> bool {
        match engine {
            #[cfg(target_arch = "x86_64")]
            Engine::Avx512 => self.simd.is_some() && avx512::supported(),
            other => other.runs_here(),
        }
    }

    /// The same path on `engine`; None where it does not run ([`Exact8::runs`]).
    pub fn with_engine(mut self, engine: Engine) -> Option<Self> {
        self.runs(engine).then(|| {
            self.engine = engine;
            self
        })
    }

    /// The same path on the scalar engine (for comparisons and tests).
    pub fn scalar(self) -> Self {
        self.with_engine(Engine::Scalar).expect("the scalar engine runs everywhere")
    }

    /// The engine [`Exact8::run`] uses.
    pub fn engine(&self) -> Engine {
        self.engine
    }

    /// Fraction of the output tables' cells whose pixels all take the reference path
    /// (a cell with more than one rounding boundary, or a knot, inside), over the distinct
    /// tables (one for a shared curve, three for a curve per channel).
    pub fn fallback_fraction(&self) -> f64 {
        self.ambiguous as f64 / (self.tables() * (FINE + 1)) as f64
    }

    /// Distinct cell tables: 1 (a shared curve) or 3.
    fn tables(&self) -> usize {
        if self.reference.params().tone_curves.shared().is_some() {
            1
        } else {
            3
        }
    }

    /// Fraction of the output tables' cells that hold one rounding boundary: only their
    /// pixels within the error bound of it take the reference.
    pub fn split_fraction(&self) -> f64 {
        self.splits.len() as f64 / (self.tables() * (FINE + 1)) as f64
    }

    /// Stages this parameter set lets the path skip.
    pub fn elision(&self) -> Elision {
        self.elision
    }

    /// One pixel.
    #[inline]
    pub fn pixel(&self, rgb: [u8; 3]) -> [u8; 3] {
        self.pixel_flagged(rgb).0
    }

    /// The table entries of one pixel and its three curve inputs: a code below
    /// [`AMBIGUOUS`] per channel where the cell decides alone. Written for every CPU: fixed
    /// tables indexed by bytes and by a cell clamped to [`FINE`] need no bounds checks, the
    /// four-lane sum (the fourth is padding) is one SSE or NEON register ([`clamped_sum`]),
    /// and the float-to-cell conversion has no saturation fix-ups (its input is in [0, FINE]).
    #[inline(always)]
    fn lookup(&self, rgb: [u8; 3]) -> ([u16; 3], [f32; 4]) {
        let terms = &*self.terms;
        let (a, b, c) = (&terms[rgb[0] as usize], &terms[256 + rgb[1] as usize], &terms[512 + rgb[2] as usize]);
        let t = clamped_sum(a, b, c);
        let cell = |c: usize| {
            // SAFETY: t is in [0, 1] (clamped above), so t · FINE is exact (a power of two)
            // and in [0, 65536], finite and within i32 (a signed conversion is one
            // instruction; an unsigned one is five on x86-64).
            let i = unsafe { (t[c] * FINE as f32).to_int_unchecked::<i32>() } as usize;
            self.cells[c][i.min(FINE)]
        };
        ([cell(0), cell(1), cell(2)], t)
    }

    /// One pixel, and whether it took the reference path.
    #[inline(always)]
    fn pixel_flagged(&self, rgb: [u8; 3]) -> ([u8; 3], bool) {
        let (e, t) = self.lookup(rgb);
        if (e[0] | e[1] | e[2]) < AMBIGUOUS {
            return ([e[0] as u8, e[1] as u8, e[2] as u8], false);
        }
        self.decide(rgb, e, t)
    }

    /// The code of a split cell `e` for an f32 curve input `t` clear of its boundary's error
    /// bound (below `lo` or from `hi` on); `None` when `t` is within it or the cell is
    /// ambiguous (then [`Exact8::decide`] needs f64).
    #[inline(always)]
    fn split_code(&self, e: u16, t: f32) -> Option<u8> {
        if e & SPLIT == 0 {
            return None;
        }
        let s = &self.splits[(e & !SPLIT) as usize];
        if t < s.lo {
            Some(s.below)
        } else if t >= s.hi {
            Some(s.above)
        } else {
            None
        }
    }

    /// A pixel whose table entries `e` (for curve inputs `t`) hold a split or an ambiguous
    /// cell: a split cell decides by its boundary, and where the f32 input is within the
    /// bound of it, by the reference's own f64 input against the boundary; an ambiguous
    /// cell by the whole f64 reference. The flag says whether f64 was needed.
    #[cold]
    fn decide(&self, rgb: [u8; 3], e: [u16; 3], t: [f32; 4]) -> ([u8; 3], bool) {
        if e.contains(&AMBIGUOUS) {
            return (self.exact(rgb), true);
        }
        let mut out = [0u8; 3];
        let mut exact: Option<[f64; 3]> = None;
        for k in 0..3 {
            out[k] = match e[k] {
                code if code < AMBIGUOUS => code as u8,
                split => self.split_code(split, t[k]).unwrap_or_else(|| {
                    let s = &self.splits[(split & !SPLIT) as usize];
                    if exact.get_or_insert_with(|| self.curve_inputs(rgb))[k] < s.at {
                        s.below
                    } else {
                        s.above
                    }
                }),
            };
        }
        (out, exact.is_some())
    }

    /// Decides the pixel at byte `p` of `src` that an engine set aside (its cell holds a
    /// boundary or is ambiguous) into `dst`; whether f64 was needed.
    #[inline]
    fn redo(&self, src: &[u8], dst: &mut [u8], p: usize) -> bool {
        let rgb = [src[p], src[p + 1], src[p + 2]];
        let (e, t) = self.lookup(rgb);
        let (o, f) = self.decide(rgb, e, t);
        dst[p..p + 3].copy_from_slice(&o);
        f
    }

    /// The reference's curve inputs for a pixel, bit for bit: its f64 degamma table, the
    /// matrix by [`ccm::apply`], clipped by [`super::clip01`] (what [`super::from_linear`]
    /// hands the curve).
    fn curve_inputs(&self, rgb: [u8; 3]) -> [f64; 3] {
        let r = &self.reference;
        super::clip01(ccm::apply(&r.params.ccm, rgb.map(|c| r.degamma[c as usize])))
    }

    /// The portable engine on whole blocks of [`LANES`] pixels: each block's codes are
    /// looked up and stored without a branch, the pixels that need more (a split or
    /// ambiguous cell, 0.01 to 0.3% of a photo for the bundled presets) queued and decided
    /// after the block. Returns the pixels the reference redid and the bytes done.
    fn run_blocks(&self, src: &[u8], dst: &mut [u8]) -> (usize, usize) {
        const BLOCK: usize = 3 * LANES;
        let mut fell = 0;
        let mut queue = [0u8; LANES];
        let whole = src.len() / BLOCK * BLOCK;
        for (s, d) in src[..whole].chunks_exact(BLOCK).zip(dst[..whole].chunks_exact_mut(BLOCK)) {
            let s: &[u8; BLOCK] = s.try_into().expect("a whole block");
            let d: &mut [u8; BLOCK] = d.try_into().expect("a whole block");
            let mut n = 0;
            for p in 0..LANES {
                let (e, t) = self.lookup([s[3 * p], s[3 * p + 1], s[3 * p + 2]]);
                let mut more = false;
                for k in 0..3 {
                    d[3 * p + k] = if e[k] < AMBIGUOUS {
                        e[k] as u8
                    } else {
                        // A split cell whose f32 input is clear of its boundary is decided
                        // here, as `decide` would; only the rest is queued.
                        self.split_code(e[k], t[k]).unwrap_or_else(|| {
                            more = true;
                            0
                        })
                    };
                }
                queue[n] = p as u8;
                n += more as usize;
            }
            for &p in &queue[..n] {
                fell += self.redo(s, d, 3 * p as usize) as usize;
            }
        }
        (fell, whole)
    }

    /// Interleaved RGB8 in and out; `src.len() == dst.len()`, a multiple of 3. Uses
    /// [`Exact8::engine`] for whole blocks; returns how many pixels left it.
    pub fn run(&self, src: &[u8], dst: &mut [u8]) -> Fallbacks {
        assert_eq!(src.len(), dst.len(), "source and destination sample counts differ");
        let mut fell = Fallbacks::default();
        #[allow(unused_mut)]
        let (mut src, mut dst) = (src, dst);
        #[cfg(target_arch = "x86_64")]
        if let (Engine::Avx512, Some(k)) = (self.engine, &self.simd) {
            let whole = src.len() / avx512::BLOCK_BYTES * avx512::BLOCK_BYTES;
            fell.flagged = k.run(&src[..whole], &mut dst[..whole]);
            (src, dst) = (&src[whole..], &mut dst[whole..]);
        }
        #[cfg(target_arch = "x86_64")]
        if self.engine == Engine::Avx2 && avx2::available() {
            // SAFETY: AVX2 and FMA are detected.
            let (redone, whole) = match &self.simd {
                Some(k) => {
                    let (flagged, whole) = unsafe { avx2::run_lines(k, src, dst) };
                    fell.flagged += flagged;
                    (0, whole)
                }
                None => unsafe { avx2::run(self, src, dst) },
            };
            fell.ambiguous += redone;
            (src, dst) = (&src[whole..], &mut dst[whole..]);
        }
        let (blocks, done) = self.run_blocks(src, dst);
        fell.ambiguous += blocks;
        for (s, d) in src[done..].chunks_exact(3).zip(dst[done..].chunks_exact_mut(3)) {
            let (o, f) = self.pixel_flagged([s[0], s[1], s[2]]);
            fell.ambiguous += f as usize;
            d.copy_from_slice(&o);
        }
        fell
    }

    /// One pixel by the f64 reference, rounded.
    #[inline]
    fn exact(&self, rgb: [u8; 3]) -> [u8; 3] {
        self.reference.pixel(rgb.map(u16::from)).map(|x| quantize(x, 255.0) as u8)
    }

    /// [`Exact8::run`] that reuses the previous output while the input pixel repeats
    /// (flat regions, clipped highlights): same result, less work on such images.
    pub fn run_reusing_repeats(&self, src: &[u8], dst: &mut [u8]) -> usize {
        assert_eq!(src.len(), dst.len(), "source and destination sample counts differ");
        let mut slow = 0;
        let mut last_in = [0u8; 3];
        let mut last_out = self.pixel(last_in);
        for (s, d) in src.chunks_exact(3).zip(dst.chunks_exact_mut(3)) {
            let px = [s[0], s[1], s[2]];
            if px != last_in {
                let (o, f) = self.pixel_flagged(px);
                slow += f as usize;
                last_in = px;
                last_out = o;
            }
            d.copy_from_slice(&last_out);
        }
        slow
    }
}

/// The whole pipeline in f32, for any input and output depth.
#[derive(Debug, Clone)]
pub struct F32Path {
    degamma: Vec<f32>,
    m: [[f32; 3]; 3],
    /// Each output channel's curve.
    curves: [Segments; 3],
    elision: Elision,
    bound: f64,
}

/// One curve's segments in f32.
#[derive(Debug, Clone)]
struct Segments {
    /// Segment starts, values and slopes.
    x0: Vec<f32>,
    y0: Vec<f32>,
    slope: Vec<f32>,
    /// First segment that can hold a t in each of `GRID` equal cells.
    first: Vec<u32>,
    /// Segments per unit when the knots are evenly spaced (index = floor(t · n)).
    uniform: Option<f32>,
}

const GRID: usize = 1024;

impl Segments {
    fn new(c: &ToneCurve) -> Self {
        let (xs, ys) = (c.x(), c.y());
        let segs = xs.len() - 1;
        let slope: Vec<f64> = (0..segs).map(|i| (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i])).collect();
        let first = (0..GRID)
            .map(|g| {
                let t = g as f64 / GRID as f64;
                (xs.partition_point(|&v| v <= t).saturating_sub(1).min(segs - 1)) as u32
            })
            .collect();
        Self {
            x0: xs[..segs].iter().map(|&v| v as f32).collect(),
            y0: ys[..segs].iter().map(|&v| v as f32).collect(),
            slope: slope.iter().map(|&v| v as f32).collect(),
            first,
            uniform: c.is_uniform().then_some(segs as f32),
        }
    }

    #[inline(always)]
    fn eval(&self, t: f32) -> f32 {
        let last = self.x0.len() - 1;
        let s = if let Some(n) = self.uniform {
            ((t * n) as i32 as usize).min(last)
        } else {
            let mut s = self.first[((t * GRID as f32) as i32 as usize).min(GRID - 1)] as usize;
            while s < last && t >= self.x0[s + 1] {
                s += 1;
            }
            s
        };
        self.y0[s] + self.slope[s] * (t - self.x0[s])
    }
}

impl F32Path {
    /// The f32 path for `params` on inputs of depth `input` (tables built here).
    pub fn new(params: &Params, input: Depth) -> Self {
        let max = input.max();
        let degamma = (0..=max).map(|c| degamma(c as f64 / max as f64, params.degamma) as f32).collect();
        let m = params.ccm.map(|r| r.map(|v| v as f32));
        // Error in output units: the matrix input t carries at most 5u·S (degamma table,
        // products, two sums; S the largest absolute row sum), amplified by the slope L
        // (the steepest of the channels' curves); the segment evaluation y0 + s·(t - x0)
        // adds u·(1 + 3L); knot positions rounded to f32 move segment ends by u, costing u·L.
        // u = 2^-24.
        let u = f32::EPSILON as f64 / 2.0;
        let s = crate::ccm::norm_inf(&params.ccm);
        let l = params.tone_curves.max_slope();
        let bound = (5.0 * u * s * l + u * (1.0 + 4.0 * l)) * 1.01;
        Self { degamma, m, curves: params.tone_curves.each().map(Segments::new), elision: Elision::of(params), bound }
    }

    /// Bound on |this path - reference| before output rounding, output units.
    pub fn error_bound(&self) -> f64 {
        self.bound
    }

    /// One pixel of integer codes (clamped to the input depth) to output in [0, 1].
    #[inline(always)]
    pub fn pixel(&self, rgb: [u16; 3]) -> [f32; 3] {
        let top = self.degamma.len() - 1;
        let d = rgb.map(|c| self.degamma[(c as usize).min(top)]);
        // (t in [0, 1] after the clamp, so the i32 conversions below cannot saturate.)
        let lin = if self.elision.matrix {
            d
        } else {
            let m = &self.m;
            [0, 1, 2].map(|i| (m[i][0] * d[0] + m[i][1] * d[1] + m[i][2] * d[2]).clamp(0.0, 1.0))
        };
        if self.elision.curve {
            lin
        } else {
            [0, 1, 2].map(|c| self.curves[c].eval(lin[c]))
        }
    }

    /// Interleaved RGB codes in and out, like [`Prepared::run`].
    pub fn run<S: Copy + Into<u16>, D: TryFrom<u16> + Copy>(&self, src: &[S], dst: &mut [D], out: Depth) {
        assert_eq!(src.len(), dst.len(), "source and destination sample counts differ");
        let scale = out.max() as f32;
        for (s, d) in src.chunks_exact(3).zip(dst.chunks_exact_mut(3)) {
            let v = self.pixel([s[0].into(), s[1].into(), s[2].into()]);
            for k in 0..3 {
                let q = (v[k] * scale + 0.5) as u16;
                d[k] = D::try_from(q).ok().expect("output depth fits the sample type");
            }
        }
    }
}

/// For each cell `[k, k+1) / FINE` widened by `delta`: the rounded 8-bit curve output if
/// it is the same over the whole interval; else a [`Split`] when the interval holds exactly
/// one rounding boundary and no knot (appended to `splits`, shared by the channels'
/// tables); else [`AMBIGUOUS`]. Returns the table and the number of ambiguous cells.
fn cell_table(curve: &ToneCurve, delta: f64, splits: &mut Vec<Split>) -> (Vec<u16>, usize) {
    let n = FINE as f64;
    let mut cells = Vec::with_capacity(FINE + 1);
    let mut ambiguous = 0;
    let mut knot = 0; // first knot index with x > lo
    for k in 0..=FINE {
        let lo = (k as f64 / n - delta).max(0.0);
        let hi = ((k + 1) as f64 / n + delta).min(1.0);
        match constant_code(curve, lo, hi, &mut knot) {
            Some(q) => cells.push(q),
            None => match split_at(curve, lo, hi, delta) {
                Some(s) if splits.len() < MAX_SPLITS => {
                    cells.push(SPLIT | splits.len() as u16);
                    splits.push(s);
                }
                _ => {
                    cells.push(AMBIGUOUS);
                    ambiguous += 1;
                }
            },
        }
    }
    (cells, ambiguous)
}

/// The reference's 8-bit code for a curve input `t` in [0, 1], as [`Prepared::run`] rounds it.
fn code(curve: &ToneCurve, t: f64) -> u16 {
    quantize(curve.eval(t), 255.0)
}

/// The one rounding boundary in `[lo, hi]`, when there is exactly one and no knot: on one
/// segment the reference's output is a monotone function of its input (each f64 operation
/// of the interpolation is monotone), so codes that differ by one at the ends change once,
/// at the least f64 input `t*` that gives the upper end's code, found by bisecting the
/// f64 bit patterns (non-negative floats order as their bits).
fn split_at(curve: &ToneCurve, lo: f64, hi: f64, delta: f64) -> Option<Split> {
    let xs = curve.x();
    if xs.iter().any(|&x| x >= lo && x <= hi) {
        return None;
    }
    let (a, b) = (code(curve, lo), code(curve, hi));
    if a.abs_diff(b) != 1 {
        return None;
    }
    // Invariant: code(lo bits) == a, code(hi bits) == b.
    let (mut l, mut h) = (lo.to_bits(), hi.to_bits());
    while h - l > 1 {
        let m = l + (h - l) / 2;
        if code(curve, f64::from_bits(m)) == a {
            l = m;
        } else {
            h = m;
        }
    }
    let t = f64::from_bits(h);
    Some(Split { at: t, lo: f32_down(t - delta), hi: f32_up(t + delta), below: a as u8, above: b as u8 })
}

/// The largest f32 not above `v`.
fn f32_down(v: f64) -> f32 {
    let f = v as f32;
    if f as f64 > v {
        f.next_down()
    } else {
        f
    }
}

/// The least f32 not below `v`.
fn f32_up(v: f64) -> f32 {
    let f = v as f32;
    if (f as f64) < v {
        f.next_up()
    } else {
        f
    }
}

/// The reference's rounded 8-bit output if it is the same for every curve input in
/// `[lo, hi]` (within [0, 1]), else `None`. `knot` is a search hint: the first knot
/// index with x > lo, or any smaller index (0 is always valid); it is advanced.
fn constant_code(curve: &ToneCurve, lo: f64, hi: f64, knot: &mut usize) -> Option<u16> {
    let xs = curve.x();
    // Curve values at the interval's ends. At a knot `eval` is exact; elsewhere it is
    // within a few ulps of the true value, so widen by 1e-15 (f64, values <= 1).
    let at = |t: f64| {
        let y = curve.eval(t);
        let exact = xs.binary_search_by(|v| v.total_cmp(&t)).is_ok();
        if exact {
            (y, y)
        } else {
            (y - 1e-15, y + 1e-15)
        }
    };
    let (a, b) = (at(lo), at(hi));
    let (mut ymin, mut ymax) = (a.0.min(b.0), a.1.max(b.1));
    while *knot < xs.len() && xs[*knot] <= lo {
        *knot += 1;
    }
    let mut i = *knot;
    while i < xs.len() && xs[i] < hi {
        let y = curve.y()[i];
        ymin = ymin.min(y);
        ymax = ymax.max(y);
        i += 1;
    }
    let (qa, qb) = (quantize(ymin, 255.0), quantize(ymax, 255.0));
    (qa == qb).then_some(qa)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The x86-64 form of the clamped sum equals the portable one (what every other CPU
    /// runs) on sums below, at and above both ends, signed zeros and tiny values; values
    /// compare equal (a -0.0 may come out as either zero: the same cell).
    #[test]
    fn clamped_sum_is_the_portable_one() {
        let values = [-3.5f32, -1.0, -1e-30, -0.0, 0.0, 1e-30, 0.25, 0.5 - f32::EPSILON, 1.0, 1.0 + f32::EPSILON, 2.75];
        for &x in &values {
            for &y in &values {
                let (a, b, c) = ([x, y, x, 0.0], [y, 0.5, -0.5, 0.0], [0.125, x, y, 0.0]);
                let (fast, portable) = (clamped_sum(&a, &b, &c), clamped_sum_portable(&a, &b, &c));
                for k in 0..4 {
                    let want = (a[k] + b[k] + c[k]).clamp(0.0, 1.0);
                    assert_eq!(fast[k], want, "lane {k} of {a:?} + {b:?} + {c:?}");
                    assert_eq!(portable[k], want, "lane {k} of {a:?} + {b:?} + {c:?}");
                }
            }
        }
    }
}
