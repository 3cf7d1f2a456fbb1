//! The face guard of the enhanced view: a guarantee the code enforces, not a property a
//! network learnt. The enhancer's learnt face gate can miss faces it was not trained on
//! (small, background, tilted, half hidden: a class photo's 15-pixel faces came back
//! whole), so after the enhancer runs, one or more face detectors (CenterFace, which the
//! registries carry, and YuNet when installed) search the enhanced image and the captured
//! image at every scale down to [`MIN_FACE`] pixels, and every face any of them finds in
//! either is hidden in the enhanced image: pixelated in blocks of a sixth of its width, or
//! filled with one colour ([`Hide`]). An image a detector cannot run on is not enhanced
//! (the error is returned; callers show the captured image or nothing).
//!
//! Scales: a detector finds faces from about its manifest's `min_face` pixels wide at the
//! scale it is shown (YuNet [`NATIVE_MIN_FACE`], CenterFace 20). So the image is searched
//! on a pyramid per detector: first enlarged so that a [`MIN_FACE`]-pixel face becomes a
//! `min_face`-pixel one, then halved level after level until the whole image fits one
//! input. Each level is cut into tiles of at most [`TILE`] pixels (narrower for a detector
//! that holds more a pixel: [`tile_for`]) overlapping by [`OVERLAP`] pixels, so every face
//! up to that size lies whole in one tile, and larger ones are whole at a later level (where
//! they are half as big); so a level keeps only its finds up to that size (the last level,
//! the whole image, keeps every size): larger finds at the fine levels were textures, not
//! faces. Each tile is resized from the image on its own (no level is ever held whole) and
//! at most [`TILES_AT_ONCE`] run at once, so the guard's memory does not grow with the
//! image or the machine's cores. The detector is fully convolutional and runs on a
//! whole tile at once, at the tile's size rounded up to a multiple of its largest stride.
//! Edges: tiles are placed inside the level image, the last of a row or column aligned to
//! its far edge; the rounding pads a tile with black (the detector's own letterbox).

use crate::enhance::Enhancer;
use crate::error::Result;
use crate::face::{Face, FaceDetector};
use crate::geometry::resize_bilinear_region;
use image::{Rgb, RgbImage};
use rayon::prelude::*;
use serde::Serialize;

/// Smallest face the guard promises to find, pixels of width in the image it checks.
pub const MIN_FACE: f64 = 10.0;
/// The face width (pixels, at the scale shown to the detector) from which YuNet finds
/// faces reliably; the pyramid's first level enlarges [`MIN_FACE`] to it. Measured on LFW
/// faces pasted into a 1280 x 720 COCO scene (`docs/enhancer.md`, "The guard's cost"): at
/// the image's own scale YuNet found 93.0% of 10-pixel and 94.7% of 11-pixel faces, at 1.6x
/// all 612 and 525 of 528; from 12 pixels 99.3% and more either way.
pub const NATIVE_MIN_FACE: f64 = crate::manifest::DEFAULT_MIN_FACE;
/// Overlap of neighbouring tiles of a level, pixels of that level.
pub const OVERLAP: usize = 160;
/// Largest tile, pixels of its level (width, height): the detector runs on a whole tile at
/// once (its size rounded up to a multiple of 32), so a 720p frame's enlarged level (2048 x
/// 1152) is two tiles of 2048 x 656, not eight of 640 x 640. Wide and at most 1.5 million
/// pixels because that is where tract runs YuNet fastest here (one thread: 141–162 ms a
/// million pixels for 1104 x 672 to 2048 x 720; 255–265 for tiles taller than wide such as
/// 1120 x 1152, 198–211 from 2.4 million pixels). YuNet holds about 100 bytes a pixel it runs
/// on (a 2048 x 1152 input peaked at 236 MB resident), so a tile about 150 MB.
/// A detector that holds more a pixel than YuNet gets narrower tiles ([`tile_for`]), so a
/// tile takes at most [`TILE_BYTES`].
pub const TILE: (usize, usize) = (2048, 720);
/// Most bytes one tile's run may hold: YuNet's on a whole [`TILE`].
pub const TILE_BYTES: u64 = 2048 * 720 * 100;
/// Tiles run at once: the guard holds at most this many [`TILE_BYTES`] whatever the
/// image's size and the machine's cores ([`FaceGuard::work_bytes`]).
pub const TILES_AT_ONCE: usize = 2;
/// The share of a detector's own score threshold from which the guard hides a region,
/// unless its manifest sets `guard_threshold` (YuNet 0.6 → 0.3): a miss shows a face and a
/// false alarm only pixelates a patch of background.
pub const THRESHOLD_SHARE: f32 = 0.5;

/// The score from which the guard hides what `detector` finds.
pub fn threshold(detector: &FaceDetector) -> f32 {
    detector.guard_threshold(THRESHOLD_SHARE)
}
/// Each side of a found face's box is widened by this share of its width or height before
/// it is hidden (hair, ears, chin).
pub const MARGIN: f32 = 0.25;
/// Pixelation blocks across a face's width: each block is a sixth of the face's width
/// (at least 2 pixels), so no more than six blocks span a face.
pub const BLOCKS_ACROSS: f32 = 6.0;
/// Largest image the guard checks, pixels (16384 x 12288: a 200-megapixel photo fits).
/// Its levels are never held whole (tiles are resized from the image one at a time), so
/// this bounds the time: on two cores a 50-megapixel photo took 38 s with YuNet's guard
/// and about 5 minutes with CenterFace's.
pub const MAX_PIXELS: u64 = 16384 * 12288;

/// How a found face is hidden.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Hide {
    /// Blocks of a sixth of the face's width, each its mean colour.
    #[default]
    Pixelate,
    /// The widened box filled with its mean colour.
    Solid,
}

/// One or more face detectors run as the enhanced view's guard: every face any of them
/// finds is hidden (the union), so adding a detector never shows a face another hid.
pub struct FaceGuard {
    detectors: Vec<FaceDetector>,
    hide: Hide,
}

/// What the guard did to one image.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Checked {
    /// Faces found on the enhanced image and on the captured one, after merging the two
    /// and the pyramid's overlapping finds (non-maximum suppression).
    pub faces: usize,
    /// The regions hidden, `[x0, y0, x1, y1]` in pixels (widened, clipped), one a find
    /// before merging: overlapping finds are all hidden.
    pub hidden: Vec<[u32; 4]>,
}

impl FaceGuard {
    /// A guard of one detector.
    pub fn new(detector: FaceDetector, hide: Hide) -> Self {
        Self { detectors: vec![detector], hide }
    }

    /// A guard of several detectors (at least one), whose finds are joined.
    pub fn of(detectors: Vec<FaceDetector>, hide: Hide) -> Result<Self> {
        if detectors.is_empty() {
            return Err(crate::EvalError::Invalid("the face guard needs at least one face detector".into()));
        }
        Ok(Self { detectors, hide })
    }

    /// The detectors' names, in the order given.
    pub fn detectors(&self) -> Vec<&str> {
        self.detectors.iter().map(|d| d.name()).collect()
    }

    /// Bytes the guard holds beside the images it searches: [`TILES_AT_ONCE`] tiles'
    /// runs ([`TILE_BYTES`] each). Its levels are never held whole.
    pub fn work_bytes(&self) -> u64 {
        TILES_AT_ONCE as u64 * TILE_BYTES
    }

    /// How found faces are hidden.
    pub fn hide(&self) -> Hide {
        self.hide
    }

    /// Every face a detector scores at least [`threshold`] at any scale of its pyramid
    /// (module docs), in `img`'s pixels, before suppression (overlapping finds all kept).
    pub fn find(&self, img: &RgbImage) -> Result<Vec<Face>> {
        self.find_all(&[img])
    }

    /// [`Self::find`] over several images (of the same scene: their finds together), their
    /// pyramid levels and tiles one pool of work.
    pub fn find_all(&self, images: &[&RgbImage]) -> Result<Vec<Face>> {
        for img in images {
            let (w, h) = img.dimensions();
            if w as u64 * h as u64 > MAX_PIXELS {
                return Err(crate::EvalError::Invalid(format!(
                    "the face guard checks images of at most {MAX_PIXELS} pixels; this one is {w} x {h}"
                )));
            }
        }
        let mut all = Vec::new();
        for detector in &self.detectors {
            all.extend(find_with(detector, images)?);
        }
        Ok(all)
    }

    /// Hides in `shown` (the enhanced image) every face found in it or in `captured` (the
    /// same scene as the camera gave it; same size).
    pub fn apply(&self, captured: &RgbImage, shown: &mut RgbImage) -> Result<Checked> {
        if captured.dimensions() != shown.dimensions() {
            return Err(crate::EvalError::Invalid(format!(
                "the face guard: captured {:?} and enhanced {:?} differ in size",
                captured.dimensions(),
                shown.dimensions()
            )));
        }
        let faces = self.find_all(&[shown, captured])?;
        let hidden: Vec<[u32; 4]> =
            faces.iter().filter_map(|f| widened(f.bbox, shown.width(), shown.height())).collect();
        for (f, r) in faces.iter().zip(&hidden) {
            hide_region(shown, *r, f.bbox[2] - f.bbox[0], self.hide);
        }
        Ok(Checked { faces: self.detectors[0].suppressed(faces).len(), hidden })
    }
}

/// [`FaceGuard::find_all`] with one detector.
fn find_with(detector: &FaceDetector, images: &[&RgbImage]) -> Result<Vec<Face>> {
    let (iw, ih) = detector.input_size();
    // (image, scale, whether it is the image's last level)
    let wanted: Vec<(usize, f64, bool)> = images
        .iter()
        .enumerate()
        .flat_map(|(k, img)| {
            let scales = pyramid(img.width(), img.height(), iw, ih, detector.min_face());
            let n = scales.len();
            scales.into_iter().enumerate().map(move |(l, s)| (k, s, l + 1 == n))
        })
        .collect();
    // Levels are never made whole: each tile is resized from its image on its own (the
    // same bytes as the level's window, `resize_bilinear_region`), so what the guard holds
    // is a few tiles whatever the image's size (a 50-megapixel photo's first level would
    // be 200 million pixels).
    let tile = tile_for(detector);
    let jobs: Vec<(usize, (u32, u32), [u32; 4])> = wanted
        .iter()
        .enumerate()
        .flat_map(|(l, &(k, s, _))| {
            let (lw, lh) = level_size(images[k].width(), images[k].height(), s);
            let (xs, ys) = (tiles(lw as usize, tile.0), tiles(lh as usize, tile.1));
            xs.into_iter().flat_map(move |(x, w)| {
                ys.clone().into_iter().map(move |(y, h)| (l, (lw, lh), [x as u32, y as u32, w as u32, h as u32]))
            })
        })
        .collect();
    // At most TILES_AT_ONCE tiles at once, however many cores there are.
    let found = jobs
        .chunks(TILES_AT_ONCE)
        .flat_map(|at_once| {
            at_once
                .par_iter()
                .map(|&(l, size, region)| {
                    let (k, s, last) = wanted[l];
                    let img = images[k];
                    let faces = if size == img.dimensions() {
                        detector.detect_region(img, region, threshold(detector))?
                    } else {
                        let tile = resize_bilinear_region(img, size, region);
                        let (x, y) = (region[0] as f32, region[1] as f32);
                        detector
                            .detect_region(&tile, [0, 0, tile.width(), tile.height()], threshold(detector))?
                            .into_iter()
                            .map(|f| f.mapped(|p| [p[0] + x, p[1] + y]))
                            .collect()
                    };
                    let inv = (1.0 / s) as f32;
                    // A level answers for faces up to OVERLAP pixels (whole in one of its
                    // tiles); bigger ones are the next level's, where they are half as big, and
                    // bigger finds here were textures (300-pixel "faces" on enhanced walls).
                    // The last level, the whole image, answers for every size.
                    Ok(faces
                        .into_iter()
                        .filter(|f| last || (f.bbox[2] - f.bbox[0]).max(f.bbox[3] - f.bbox[1]) <= OVERLAP as f32)
                        .map(|f| f.mapped(|p| [p[0] * inv, p[1] * inv]))
                        .collect::<Vec<_>>())
                })
                .collect::<Vec<_>>()
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(found.into_iter().flatten().collect())
}

/// An enhancer whose every output has passed the face guard: what a person is shown.
pub struct GuardedEnhancer {
    pub enhancer: Enhancer,
    pub guard: FaceGuard,
}

impl GuardedEnhancer {
    /// Bytes an enhancement of a `w` x `h` image holds besides the captured and the
    /// enhanced image: the enhancer's ([`Enhancer::work_bytes`]), then the guard's; the
    /// enhancer's are freed before the guard runs, so the larger of the two.
    pub fn work_bytes(&self, w: u32, h: u32) -> u64 {
        self.enhancer.work_bytes(w, h).max(self.guard.work_bytes())
    }

    /// The enhanced image of a captured one with every face the guard finds hidden, and
    /// what the guard did; an error (the image is then not to be shown enhanced) when the
    /// enhancer or the guard cannot run.
    pub fn enhance_checked(&self, captured: &RgbImage) -> Result<(RgbImage, Checked)> {
        self.enhance_checked_on(captured, 1)
    }

    /// [`Self::enhance_checked`] with the network on `threads` threads
    /// ([`Enhancer::enhance_on`]; the guard is the same).
    pub fn enhance_checked_on(&self, captured: &RgbImage, threads: usize) -> Result<(RgbImage, Checked)> {
        let mut shown = self.enhancer.enhance_on(captured, threads)?;
        let checked = self.guard.apply(captured, &mut shown)?;
        Ok((shown, checked))
    }

    /// [`Self::enhance_checked`]'s image.
    pub fn enhance(&self, captured: &RgbImage) -> Result<RgbImage> {
        Ok(self.enhance_checked(captured)?.0)
    }

    /// [`Self::enhance_checked_on`]'s image.
    pub fn enhance_on(&self, captured: &RgbImage, threads: usize) -> Result<RgbImage> {
        Ok(self.enhance_checked_on(captured, threads)?.0)
    }
}

/// The pyramid's scales for a `w` x `h` image and a detector input of `iw` x `ih` that
/// finds faces from `native` pixels wide: from `native` / [`MIN_FACE`], halving, down to
/// the scale at which the image fits the input (included; never above the first).
pub fn pyramid(w: u32, h: u32, iw: usize, ih: usize, native: f64) -> Vec<f64> {
    let fit = (iw as f64 / w as f64).min(ih as f64 / h as f64);
    let mut s = native / MIN_FACE;
    let mut out = Vec::new();
    while s > fit {
        out.push(s);
        s /= 2.0;
    }
    out.push(fit.min(native / MIN_FACE));
    out
}

/// The size of the pyramid level at scale `s` (at least a pixel a side).
fn level_size(w: u32, h: u32, s: f64) -> (u32, u32) {
    (((w as f64 * s).round() as u32).max(1), ((h as f64 * s).round() as u32).max(1))
}

/// The largest tile for `detector`: [`TILE`], narrowed (to a multiple of 32, wider than
/// twice [`OVERLAP`]) until its run holds at most [`TILE_BYTES`].
pub fn tile_for(detector: &FaceDetector) -> (usize, usize) {
    let fits = (TILE_BYTES / (TILE.1 as u64 * detector.bytes_per_pixel().max(1))) as usize;
    ((fits / 32 * 32).clamp(2 * OVERLAP + 32, TILE.0), TILE.1)
}

/// Tiles along a side of `len` pixels, as (origin, length): as few as fit in `max` pixels
/// each (more than [`OVERLAP`]) with neighbours overlapping by at least [`OVERLAP`], all of
/// one length (the last aligned to the far edge), so a level's tiles share one planned
/// network size.
pub fn tiles(len: usize, max: usize) -> Vec<(usize, usize)> {
    if len <= max {
        return vec![(0, len)];
    }
    let n = (len - OVERLAP).div_ceil(max - OVERLAP);
    let side = (len + (n - 1) * OVERLAP).div_ceil(n);
    let step = side - OVERLAP;
    let mut out: Vec<(usize, usize)> = (0..n - 1).map(|i| (i * step, side)).collect();
    out.push((len - side, side));
    out
}

/// `bbox` widened by [`MARGIN`] of its size on each side, clipped to a `w` x `h` image, in
/// whole pixels (`[x0, y0, x1, y1)`); None when nothing of it is inside.
pub fn widened(bbox: [f32; 4], w: u32, h: u32) -> Option<[u32; 4]> {
    let (bw, bh) = (bbox[2] - bbox[0], bbox[3] - bbox[1]);
    if !(bw.is_finite() && bh.is_finite()) || bw <= 0.0 || bh <= 0.0 {
        return None;
    }
    let clip = |v: f32, hi: u32| v.clamp(0.0, hi as f32);
    let x0 = clip((bbox[0] - MARGIN * bw).floor(), w) as u32;
    let y0 = clip((bbox[1] - MARGIN * bh).floor(), h) as u32;
    let x1 = clip((bbox[2] + MARGIN * bw).ceil(), w) as u32;
    let y1 = clip((bbox[3] + MARGIN * bh).ceil(), h) as u32;
    (x1 > x0 && y1 > y0).then_some([x0, y0, x1, y1])
}

/// Hides the region `r` (`[x0, y0, x1, y1)`) of a face `face_width` pixels wide: blocks of
/// `max(2, ceil(face_width / 6))` pixels from the region's top-left corner (the last ones
/// cut by the region's edge), each set to its mean colour (rounded); or the whole region
/// set to its mean colour.
pub fn hide_region(img: &mut RgbImage, r: [u32; 4], face_width: f32, how: Hide) {
    let [x0, y0, x1, y1] = r;
    let block = match how {
        Hide::Pixelate => ((face_width / BLOCKS_ACROSS).ceil() as u32).max(2),
        Hide::Solid => (x1 - x0).max(y1 - y0),
    };
    for by in (y0..y1).step_by(block as usize) {
        for bx in (x0..x1).step_by(block as usize) {
            let (ex, ey) = ((bx + block).min(x1), (by + block).min(y1));
            let mut sum = [0u64; 3];
            for y in by..ey {
                for x in bx..ex {
                    let p = img.get_pixel(x, y).0;
                    (0..3).for_each(|c| sum[c] += p[c] as u64);
                }
            }
            let n = ((ex - bx) * (ey - by)) as u64;
            let mean = Rgb(sum.map(|v| ((v + n / 2) / n) as u8));
            for y in by..ey {
                for x in bx..ex {
                    img.put_pixel(x, y, mean);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pyramid_starts_enlarged_and_ends_fitting() {
        // 1600 x 800 into 640 x 640: 1.6, 0.8, then the fit 0.4 (0.4 < 0.8 / 2 is not
        // reached: 0.8 > 0.4, so 0.4 is the last).
        let p = pyramid(1600, 800, 640, 640, NATIVE_MIN_FACE);
        assert_eq!(p, vec![1.6, 0.8, 0.4]);
        // An image that fits at the first scale: one level.
        assert_eq!(pyramid(100, 100, 640, 640, NATIVE_MIN_FACE), vec![1.6]);
        // 400 x 400 enlarged 1.6 is 640: fits, one level at 1.6.
        assert_eq!(pyramid(400, 400, 640, 640, NATIVE_MIN_FACE), vec![1.6]);
    }

    #[test]
    fn tiles_cover_the_side_with_overlap() {
        assert_eq!(tiles(500, 640), vec![(0, 500)]);
        assert_eq!(tiles(720, 720), vec![(0, 720)]);
        // 1152 (a 720p frame's enlarged height) in 720: two tiles of (1152 + 160) / 2 = 656.
        assert_eq!(tiles(1152, 720), vec![(0, 656), (496, 656)]);
        // 4032 + 160 * 3 over four tiles of at most 1280: 1128, stepping 968.
        assert_eq!(tiles(4032, 1280), vec![(0, 1128), (968, 1128), (1936, 1128), (2904, 1128)]);
        // Every pixel is covered, neighbours overlap by at least OVERLAP, no tile is longer
        // than the limit, and no fewer tiles would do.
        for max in [640, 720, 2048] {
            for len in [1, 721, 1281, 1440, 1919, 2433, 4032, 6144, 9999] {
                let t = tiles(len, max);
                assert_eq!(t[0].0, 0);
                assert_eq!(t.last().unwrap().0 + t.last().unwrap().1, len);
                assert!(t.iter().all(|&(_, side)| side <= max && side == t[0].1), "{len}: {t:?}");
                for w in t.windows(2) {
                    assert!(w[0].0 + w[0].1 >= w[1].0 + OVERLAP, "{len}: {t:?}");
                }
                assert!(t.len() == 1 || (t.len() - 1) * max - (t.len() - 2) * OVERLAP < len, "{len}: {t:?}");
            }
        }
    }

    #[test]
    fn widened_by_the_margin_and_clipped() {
        // A 40 x 40 box at (20, 20): 10 pixels more on each side.
        assert_eq!(widened([20.0, 20.0, 60.0, 60.0], 100, 100), Some([10, 10, 70, 70]));
        assert_eq!(widened([0.0, 0.0, 40.0, 40.0], 50, 45), Some([0, 0, 50, 45]));
        assert_eq!(widened([200.0, 0.0, 240.0, 40.0], 100, 100), None);
        assert_eq!(widened([10.0, 10.0, 10.0, 20.0], 100, 100), None);
        assert_eq!(widened([f32::NAN, 0.0, 1.0, 1.0], 100, 100), None);
    }

    #[test]
    fn pixelation_blocks_are_their_means() {
        // A 12-pixel face: blocks of 2; a 2 x 2 block of 0, 10, 20, 31 -> mean 15.25 -> 15.
        let mut img = RgbImage::from_fn(4, 2, |x, y| Rgb([(x * 10 + y * 20 + (x * y)) as u8; 3]));
        hide_region(&mut img, [0, 0, 2, 2], 12.0, Hide::Pixelate);
        for (x, y) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            assert_eq!(img.get_pixel(x, y).0, [15; 3]);
        }
        // Outside the region: untouched.
        assert_eq!(img.get_pixel(2, 0).0, [20; 3]);
        // A 60-pixel face: blocks of 10 pixels; the image is constant within each block.
        let mut big = RgbImage::from_fn(30, 30, |x, y| Rgb([(x * 7 + y * 3) as u8, 9, 200]));
        hide_region(&mut big, [0, 0, 30, 30], 60.0, Hide::Pixelate);
        for y in 0..30 {
            for x in 0..30 {
                assert_eq!(big.get_pixel(x, y), big.get_pixel(x / 10 * 10, y / 10 * 10));
            }
        }
        // Solid: one colour over the region.
        let mut s = RgbImage::from_fn(8, 4, |x, _| Rgb([x as u8 * 30, 0, 0]));
        hide_region(&mut s, [0, 0, 8, 4], 4.0, Hide::Solid);
        assert!(s.pixels().all(|p| p.0 == [105, 0, 0])); // mean of 0, 30, ..., 210
    }
}
