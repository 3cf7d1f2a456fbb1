//! The face guard of the enhanced view: a guarantee the code enforces, not a property a
//! network learnt. The enhancer's learnt face gate can miss faces it was not trained on
//! (small, background, tilted, half hidden: a class photo's 15-pixel faces came back
//! whole), so after the enhancer runs, a face detector searches the enhanced image and
//! the captured image at every scale down to [`MIN_FACE`] pixels, and every face found in
//! either is hidden in the enhanced image: pixelated in blocks of a sixth of its width, or
//! filled with one colour ([`Hide`]). An image the detector cannot run on is not enhanced
//! (the error is returned; callers show the captured image or nothing).
//!
//! Scales: the detector (YuNet: a 640 x 640 input, anchors on strides 8, 16 and 32) finds
//! faces from about [`NATIVE_MIN_FACE`] pixels wide at the scale it is shown. So the image
//! is searched on a pyramid: first enlarged so that a [`MIN_FACE`]-pixel face becomes a
//! [`NATIVE_MIN_FACE`]-pixel one, then halved level after level until the whole image fits
//! one input. Each level is cut into input-sized tiles overlapping by [`OVERLAP`] pixels,
//! so every face up to that size lies whole in one tile, and larger ones are whole at a
//! later level (where they are half as big); so a level keeps only its finds up to that
//! size (the last level, the whole image, keeps every size): larger finds at the fine
//! levels were textures, not faces. Edges: tiles are placed inside the level
//! image; the last tile of a row or column is aligned to its far edge, and a level smaller
//! than the input is padded with black (the detector's own letterbox).

use crate::enhance::Enhancer;
use crate::error::Result;
use crate::face::{Face, FaceDetector};
use crate::geometry::resize_bilinear;
use image::{Rgb, RgbImage};
use rayon::prelude::*;
use serde::Serialize;

/// Smallest face the guard promises to find, pixels of width in the image it checks.
pub const MIN_FACE: f64 = 10.0;
/// The face width (pixels, at the scale shown to the detector) from which YuNet finds
/// faces reliably; the pyramid's first level enlarges [`MIN_FACE`] to it.
pub const NATIVE_MIN_FACE: f64 = 16.0;
/// Overlap of neighbouring tiles of a level, pixels of that level.
pub const OVERLAP: usize = 160;
/// Detection score from which the guard hides a region: below the detector's own
/// threshold (0.6 for YuNet), since a miss shows a face and a false alarm only pixelates
/// a patch of background.
pub const THRESHOLD: f32 = 0.3;
/// Each side of a found face's box is widened by this share of its width or height before
/// it is hidden (hair, ears, chin).
pub const MARGIN: f32 = 0.25;
/// Pixelation blocks across a face's width: each block is a sixth of the face's width
/// (at least 2 pixels), so no more than six blocks span a face.
pub const BLOCKS_ACROSS: f32 = 6.0;
/// Largest image the guard checks, pixels (the detector's pyramid is bounded by it: its
/// first level of a 48-megapixel image holds 75 million pixels, 225 MB).
pub const MAX_PIXELS: u64 = 48_000_000;

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

/// A face detector run as the enhanced view's guard.
pub struct FaceGuard {
    detector: FaceDetector,
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
    pub fn new(detector: FaceDetector, hide: Hide) -> Self {
        Self { detector, hide }
    }

    /// How found faces are hidden.
    pub fn hide(&self) -> Hide {
        self.hide
    }

    /// Every face scoring at least [`THRESHOLD`] at any scale of the pyramid (module docs),
    /// in `img`'s pixels, before suppression (overlapping finds all kept).
    pub fn find(&self, img: &RgbImage) -> Result<Vec<Face>> {
        let (w, h) = img.dimensions();
        if w as u64 * h as u64 > MAX_PIXELS {
            return Err(crate::EvalError::Invalid(format!(
                "the face guard checks images of at most {MAX_PIXELS} pixels; this one is {w} x {h}"
            )));
        }
        let (iw, ih) = self.detector.input_size();
        let levels: Vec<(f64, RgbImage)> = pyramid(w, h, iw, ih)
            .into_par_iter()
            .map(|s| {
                let (lw, lh) = level_size(w, h, s);
                (s, if (lw, lh) == (w, h) { img.clone() } else { resize_bilinear(img, lw, lh) })
            })
            .collect();
        let jobs: Vec<(usize, u32, u32)> = levels
            .iter()
            .enumerate()
            .flat_map(|(l, (_, level))| {
                let (lw, lh) = (level.width() as usize, level.height() as usize);
                tiles(lw, iw)
                    .into_iter()
                    .flat_map(move |x| tiles(lh, ih).into_iter().map(move |y| (l, x as u32, y as u32)))
            })
            .collect();
        let found = jobs
            .par_iter()
            .map(|&(l, x, y)| {
                let (s, level) = (levels[l].0, &levels[l].1);
                let tile = image::imageops::crop_imm(
                    level,
                    x,
                    y,
                    (iw as u32).min(level.width() - x),
                    (ih as u32).min(level.height() - y),
                )
                .to_image();
                let inv = (1.0 / s) as f32;
                // A level answers for faces up to OVERLAP pixels (whole in one of its
                // tiles); bigger ones are the next level's, where they are half as big, and
                // bigger finds here were textures (300-pixel "faces" on enhanced walls).
                // The last level, the whole image, answers for every size.
                let last = l + 1 == levels.len();
                Ok(self
                    .detector
                    .detect_scaled(&tile, 1.0, THRESHOLD)?
                    .into_iter()
                    .filter(|f| last || (f.bbox[2] - f.bbox[0]).max(f.bbox[3] - f.bbox[1]) <= OVERLAP as f32)
                    .map(|f| Face {
                        bbox: [
                            (f.bbox[0] + x as f32) * inv,
                            (f.bbox[1] + y as f32) * inv,
                            (f.bbox[2] + x as f32) * inv,
                            (f.bbox[3] + y as f32) * inv,
                        ],
                        score: f.score,
                        landmarks: f.landmarks.map(|p| [(p[0] + x as f32) * inv, (p[1] + y as f32) * inv]),
                    })
                    .collect::<Vec<_>>())
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(found.into_iter().flatten().collect())
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
        let mut faces = self.find(shown)?;
        faces.extend(self.find(captured)?);
        let hidden: Vec<[u32; 4]> =
            faces.iter().filter_map(|f| widened(f.bbox, shown.width(), shown.height())).collect();
        for (f, r) in faces.iter().zip(&hidden) {
            hide_region(shown, *r, f.bbox[2] - f.bbox[0], self.hide);
        }
        Ok(Checked { faces: self.detector.suppressed(faces).len(), hidden })
    }
}

/// An enhancer whose every output has passed the face guard: what a person is shown.
pub struct GuardedEnhancer {
    pub enhancer: Enhancer,
    pub guard: FaceGuard,
}

impl GuardedEnhancer {
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

/// The pyramid's scales for a `w` x `h` image and a detector input of `iw` x `ih`: from
/// [`NATIVE_MIN_FACE`] / [`MIN_FACE`], halving, down to the scale at which the image fits
/// the input (included; never above the first).
pub fn pyramid(w: u32, h: u32, iw: usize, ih: usize) -> Vec<f64> {
    let fit = (iw as f64 / w as f64).min(ih as f64 / h as f64);
    let mut s = NATIVE_MIN_FACE / MIN_FACE;
    let mut out = Vec::new();
    while s > fit {
        out.push(s);
        s /= 2.0;
    }
    out.push(fit.min(NATIVE_MIN_FACE / MIN_FACE));
    out
}

/// The size of the pyramid level at scale `s` (at least a pixel a side).
fn level_size(w: u32, h: u32, s: f64) -> (u32, u32) {
    (((w as f64 * s).round() as u32).max(1), ((h as f64 * s).round() as u32).max(1))
}

/// Tile origins along a side of `len` pixels for tiles of `tile` pixels overlapping by
/// [`OVERLAP`]: 0, then steps of `tile - OVERLAP`, the last aligned to the far edge.
pub fn tiles(len: usize, tile: usize) -> Vec<usize> {
    if len <= tile {
        return vec![0];
    }
    let step = tile.saturating_sub(OVERLAP).max(1);
    let mut out: Vec<usize> = (0..).map(|i| i * step).take_while(|&x| x + tile < len).collect();
    out.push(len - tile);
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
        let p = pyramid(1600, 800, 640, 640);
        assert_eq!(p, vec![1.6, 0.8, 0.4]);
        // An image that fits at the first scale: one level.
        assert_eq!(pyramid(100, 100, 640, 640), vec![1.6]);
        // 400 x 400 enlarged 1.6 is 640: fits, one level at 1.6.
        assert_eq!(pyramid(400, 400, 640, 640), vec![1.6]);
    }

    #[test]
    fn tiles_cover_the_side_with_overlap() {
        assert_eq!(tiles(500, 640), vec![0]);
        assert_eq!(tiles(640, 640), vec![0]);
        // step 480: 0, 480, then the far edge 1280 - 640 = 640.
        assert_eq!(tiles(1280, 640), vec![0, 480, 640]);
        // Every pixel is covered and neighbours overlap by at least OVERLAP.
        for len in [641, 1000, 1919, 4032] {
            let t = tiles(len, 640);
            assert_eq!(*t.last().unwrap() + 640, len);
            for w in t.windows(2) {
                assert!(w[0] + 640 >= w[1] + OVERLAP, "{len}: {t:?}");
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
