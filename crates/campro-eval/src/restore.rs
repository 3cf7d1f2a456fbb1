//! The restoration attack on a per-pixel colour map (the paper's adaptive attack by image
//! restoration, Sec. VII, in its simplest exact form): an attacker who knows the camera
//! maps each protected colour back to the mean raw colour that produces it, weighted by how
//! often that raw colour occurs in natural images, then runs face recognition as usual.
//!
//! For a bijective map (colour inversion) this recovers the raw image up to quantisation,
//! so identification comes back; for a many-to-one map (CamPro's clipping CCM and folding
//! curve) it recovers only the per-colour average, which is the point of the design. This
//! is the best any per-pixel restorer can do in squared error under that colour prior (up to
//! the binning below); a network looking at neighbourhoods can do better.
//!
//! The fit runs every pixel of the prior through the camera and averages the raw colours that
//! land in each protected-colour bin (`BITS` bits a channel). Pixel by pixel, not bin by bin:
//! a folding curve is steep (CamPro's spreads one raw level over about ten protected ones), so
//! one raw bin's pixels land in many protected bins. A bin that few pixels reach borrows from
//! its parent, the bin one bit coarser a channel: its estimate is `(sum + K·parent) / (n + K)`
//! with `K` = [`SHRINK`] pseudo-pixels, down from the prior's mean colour at zero bits. A bin
//! no pixel reaches gets its parent's estimate, so every protected colour has one.

use crate::Result;
use image::RgbImage;

/// Bits per channel of the colour bins (2^18 bins).
pub const BITS: u32 = 6;
const SIDE: usize = 1 << BITS;
const SHIFT: u32 = 8 - BITS;

/// Pseudo-pixels of the parent bin's estimate in each bin's (the shrinkage toward the coarser
/// bin): a bin reached by `n` pixels weighs its own mean `n / (n + SHRINK)`.
pub const SHRINK: f64 = 4.0;

/// The bin of a colour: `(r >> 2) · 4096 + (g >> 2) · 64 + (b >> 2)`.
pub fn bin(p: [u8; 3]) -> usize {
    ((p[0] >> SHIFT) as usize * SIDE + (p[1] >> SHIFT) as usize) * SIDE + (p[2] >> SHIFT) as usize
}

/// The bin one bit coarser a channel that holds bin `b` of a level `side` bins a channel wide
/// (bins indexed as in [`bin`]: red major, blue minor).
fn parent(b: usize, side: usize) -> usize {
    let (r, g, bl) = (b / (side * side), b / side % side, b % side);
    let half = side / 2;
    ((r / 2) * half + g / 2) * half + bl / 2
}

/// The per-pixel MMSE inverse of one colour map.
#[derive(Debug, Clone)]
pub struct Restorer {
    /// Per protected-colour bin ([`bin`]), the restored colour.
    table: Vec<[u8; 3]>,
}

impl Restorer {
    /// Fits the inverse of `protect` (a per-pixel map: each output pixel may depend on its
    /// input pixel only) on the pixels of `prior` (raw images).
    pub fn fit<'a>(
        protect: impl Fn(&RgbImage) -> RgbImage,
        prior: impl IntoIterator<Item = &'a RgbImage>,
    ) -> Result<Self> {
        // Per protected bin at BITS bits: how many prior pixels land there, their raw sum.
        let mut count = vec![0u64; SIDE * SIDE * SIDE];
        let mut sum = vec![[0u64; 3]; SIDE * SIDE * SIDE];
        for img in prior {
            let seen = protect(img);
            if seen.dimensions() != img.dimensions() {
                return Err(crate::EvalError::Invalid("restoration: the protection changed the image size".into()));
            }
            for (raw, out) in img.pixels().zip(seen.pixels()) {
                let o = bin(out.0);
                count[o] += 1;
                (0..3).for_each(|c| sum[o][c] += raw.0[c] as u64);
            }
        }
        if count.iter().all(|&n| n == 0) {
            return Err(crate::EvalError::Invalid("restoration prior: no pixels".into()));
        }
        // The same sums at every coarser level: levels[k] has k bits a channel.
        let mut levels = vec![(count, sum)];
        for k in (0..BITS as usize).rev() {
            let side = 1usize << k;
            let (fine_n, fine_s) = &levels[0];
            let mut n = vec![0u64; side * side * side];
            let mut s = vec![[0u64; 3]; side * side * side];
            for (b, (&fn_, fs)) in fine_n.iter().zip(fine_s).enumerate() {
                let p = parent(b, 2 * side);
                n[p] += fn_;
                (0..3).for_each(|c| s[p][c] += fs[c]);
            }
            levels.insert(0, (n, s));
        }
        // Estimates from the top (the prior's mean colour) down.
        let (n0, s0) = &levels[0];
        let mut est: Vec<[f64; 3]> = vec![std::array::from_fn(|c| s0[0][c] as f64 / n0[0] as f64)];
        for (k, (n, s)) in levels.iter().enumerate().skip(1) {
            est = (0..n.len())
                .map(|b| {
                    let parent = est[parent(b, 1 << k)];
                    std::array::from_fn(|c| (s[b][c] as f64 + SHRINK * parent[c]) / (n[b] as f64 + SHRINK))
                })
                .collect();
        }
        let table = est.iter().map(|e| e.map(|v| v.round().clamp(0.0, 255.0) as u8)).collect();
        Ok(Self { table })
    }

    /// The whole lookup table, per protected-colour bin ([`bin`]): the restored colour. What
    /// the enhancer's first stage looks up ([`apply_table`]).
    pub fn table(&self) -> Vec<[u8; 3]> {
        self.table.clone()
    }

    /// Restores a protected image pixel by pixel.
    pub fn apply(&self, img: &RgbImage) -> RgbImage {
        apply_table(&self.table, img)
    }
}

/// An image through a whole table of [`Restorer::table`]: each pixel replaced by its bin's
/// entry.
pub fn apply_table(table: &[[u8; 3]], img: &RgbImage) -> RgbImage {
    let mut out = img.clone();
    for p in out.pixels_mut() {
        p.0 = table[bin(p.0)];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProtectFn;

    fn prior() -> Vec<RgbImage> {
        // Every colour on a 4-level grid, plus a gradient.
        let mut a = RgbImage::new(256, 256);
        for (x, y, p) in a.enumerate_pixels_mut() {
            p.0 = [x as u8, y as u8, ((x + y) / 2) as u8];
        }
        vec![a]
    }

    #[test]
    fn a_bijection_is_undone_to_within_its_bins() {
        let invert: Box<ProtectFn> = Box::new(|img: &RgbImage| {
            let mut o = img.clone();
            o.pixels_mut().for_each(|p| p.0 = p.0.map(|v| 255 - v));
            o
        });
        let r = Restorer::fit(invert.as_ref(), &prior()).unwrap();
        let img = &prior()[0];
        let back = r.apply(&invert(img));
        // Within one bin (4 levels) of the raw colour everywhere.
        let worst = img.as_raw().iter().zip(back.as_raw()).map(|(a, b)| (*a as i32 - *b as i32).abs()).max().unwrap();
        assert!(worst <= 4, "{worst}");
        // The identity camera restores to within a bin as well.
        let same: Box<ProtectFn> = Box::new(|img: &RgbImage| img.clone());
        let r = Restorer::fit(same.as_ref(), &prior()).unwrap();
        let worst =
            img.as_raw().iter().zip(r.apply(img).as_raw()).map(|(a, b)| (*a as i32 - *b as i32).abs()).max().unwrap();
        assert!(worst <= 4, "{worst}");
    }

    #[test]
    fn every_bin_is_the_shrunk_mean_of_the_pixels_that_reach_it() {
        // The prior holds only dark colours: bright protected bins are never reached.
        let dark = vec![RgbImage::from_fn(64, 64, |x, y| image::Rgb([x as u8, y as u8, 10]))];
        let same: Box<ProtectFn> = Box::new(|img: &RgbImage| img.clone());
        let r = Restorer::fit(same.as_ref(), &dark).unwrap();
        let t = r.table();
        assert_eq!(t.len(), 1 << 18);
        assert_eq!(apply_table(&t, &dark[0]), r.apply(&dark[0]));
        // By hand, K = 4. Red and green are symmetric, blue is 10 throughout. The bins
        // [0, 2^(8−k)) of k = 0..2 bits hold all 4,096 pixels (mean 31.5); below that, the bin
        // holding [4, 8) x [0, 4) holds 1,024, 256, 64 and 16 pixels, means 15.5, 7.5, 3.5 and
        // (5.5, 1.5):
        //   3 bits: (1024 · 15.5 + 4 · 31.5) / 1028 = 15.5623
        //   4 bits: (256 · 7.5 + 4 · 15.5623) / 260 = 7.6240
        //   5 bits: (64 · 3.5 + 4 · 7.6240) / 68 = 3.7426
        //   6 bits: red (16 · 5.5 + 4 · 3.7426) / 20 = 5.149, green (16 · 1.5 + 4 · 3.7426) / 20 = 1.949.
        assert_eq!(SHRINK, 4.0);
        assert_eq!(t[bin([5, 2, 10])], [5, 2, 10]);
        // Unreached: every coarser bin up to the top is empty too, so the prior's mean colour,
        // (31.5, 31.5, 10) rounded.
        assert_eq!(t[bin([201, 130, 255])], [32, 32, 10]);
        let bright = RgbImage::from_pixel(2, 1, image::Rgb([201, 130, 255]));
        assert_eq!(r.apply(&bright), RgbImage::from_pixel(2, 1, image::Rgb([32, 32, 10])));
    }

    #[test]
    fn a_steep_curve_is_fitted_pixel_by_pixel() {
        // Red times 16, wrapped: one raw bin (4 levels) spreads over 64 protected levels, 16
        // bins. Each protected red bin [4j, 4j + 4) comes from the raw reds r with
        // 16r mod 256 in it, r = j / 4 + 16m for m = 0..16 when 4 | j (none otherwise), mean
        // j / 4 + 120; fitted bin by bin, all 16 of one raw bin's pixels would land in one
        // protected bin and leave the others to their parents.
        let steep: Box<ProtectFn> = Box::new(|img: &RgbImage| {
            let mut o = img.clone();
            o.pixels_mut().for_each(|p| p.0[0] = p.0[0].wrapping_mul(16));
            o
        });
        let prior = vec![RgbImage::from_fn(256, 16, |x, _| image::Rgb([x as u8, 100, 100]))];
        let t = Restorer::fit(steep.as_ref(), &prior).unwrap().table();
        for j in (0..64).step_by(4) {
            // 16 rows x 16 reds = 256 pixels a bin: the shrinkage moves the mean by < 0.2.
            let got = t[bin([4 * j as u8, 100, 100])];
            assert_eq!(got, [(j / 4 + 120) as u8, 100, 100], "bin {j}");
        }
    }

    #[test]
    fn a_many_to_one_map_restores_the_prior_mean_of_each_output() {
        // Everything above mid-grey in red goes to one colour, the rest to another.
        let fold: Box<ProtectFn> = Box::new(|img: &RgbImage| {
            let mut o = img.clone();
            o.pixels_mut().for_each(|p| p.0 = if p.0[0] >= 128 { [255, 255, 255] } else { [0, 0, 0] });
            o
        });
        let p = prior();
        let r = Restorer::fit(fold.as_ref(), &p).unwrap();
        // By hand: the prior's mean colour over the pixels with red ≥ 128 (x ≥ 128): red
        // 191.5, green 127.5 (32,768 pixels: the shrinkage moves them by < 0.01).
        let hi = r.apply(&RgbImage::from_pixel(1, 1, image::Rgb([255, 255, 255]))).get_pixel(0, 0).0;
        let lo = r.apply(&RgbImage::from_pixel(1, 1, image::Rgb([0, 0, 0]))).get_pixel(0, 0).0;
        assert!((hi[0] as i32 - 192).abs() <= 1 && (hi[1] as i32 - 128).abs() <= 1, "{hi:?}");
        assert!((lo[0] as i32 - 64).abs() <= 1 && (lo[1] as i32 - 128).abs() <= 1, "{lo:?}");
        // A colour the camera never produces: the prior's mean colour, (127.5, 127.5, 127.25)
        // rounded (blue is ⌊(x + y) / 2⌋).
        let odd = r.apply(&RgbImage::from_pixel(1, 1, image::Rgb([10, 200, 30]))).get_pixel(0, 0).0;
        assert_eq!(odd, [128, 128, 127]);
        assert!(Restorer::fit(fold.as_ref(), &[]).is_err());
    }
}
