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
//! land in each protected-colour bin ([`SIDE`] bins a channel, 2^18 in all). Pixel by pixel,
//! not bin by bin: a folding curve is steep (CamPro's spreads one raw level over about ten
//! protected ones), so one raw bin's pixels land in many protected bins. A bin that few pixels
//! reach borrows from its parent, the bin one step coarser a channel (bins 2q and 2q + 1 of a
//! channel merged): its estimate is `(sum + K·parent) / (n + K)` with `K` = [`SHRINK`]
//! pseudo-pixels, down from the prior's mean colour at one bin a channel. A bin no pixel
//! reaches gets its parent's estimate, so every protected colour has one.
//!
//! The bins are fitted too ([`Binning`]): each channel's 256 protected levels split into
//! [`SIDE`] runs holding about equal numbers of the prior's protected pixels. A camera's
//! output uses its levels unevenly (CamPro's folding curve puts most pixels on some ninety
//! levels a channel), and equal-width bins of 4 levels merge busy levels whose raw colours
//! differ: on `campro-omega-0.5` and the held-out COCO images this table scores 19.95 dB
//! against raw, and a simplified fit 19.8 dB with these bins and 17.7 dB with equal-width
//! ones at the same 2^18 entries (`docs/enhancer.md`, "Equal-mass bins").

use crate::Result;
use image::RgbImage;

/// Bins a channel (2^18 bins in all; a power of two: the shrinkage halves it per step).
pub const SIDE: usize = 64;

/// Pseudo-pixels of the parent bin's estimate in each bin's (the shrinkage toward the coarser
/// bin): a bin reached by `n` pixels weighs its own mean `n / (n + SHRINK)`.
pub const SHRINK: f64 = 4.0;

/// Per channel, the bin (0..[`SIDE`]) of each 8-bit protected level; non-decreasing in the
/// level, every bin holding at least one level.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Binning {
    levels: [[u8; 256]; 3],
}

impl Binning {
    /// Equal-width bins: level `v` in bin `v · SIDE / 256`.
    pub fn uniform() -> Self {
        Self { levels: [std::array::from_fn(|v| (v * SIDE / 256) as u8); 3] }
    }

    /// Bins of about equal mass under `histogram` (per channel, pixels at each level), level
    /// by level: a bin's share is the mass not yet binned over the bins not yet closed; a bin
    /// closes before a level that would overshoot its share by more than the bin falls short
    /// of it, after a level that fills it, and whenever each bin left can have only one
    /// level. So a level heavier than its share fills a bin alone and the rest re-split; a
    /// uniform histogram gives [`Binning::uniform`].
    pub fn equal_mass(histogram: &[[u64; 256]; 3]) -> Self {
        let levels = std::array::from_fn(|c| {
            let h = &histogram[c];
            let mut rest: i128 = h.iter().map(|&n| n as i128).sum();
            let (mut q, mut bin, mut acc) = ([0u8; 256], 0usize, 0i128);
            for v in 0..256 {
                // Bins left after this one, and this one's share (times the bins sharing).
                let bins = |bin: usize| (SIDE - 1 - bin, (SIDE - bin) as i128);
                let (left, sharing) = bins(bin);
                let (over, under) = ((acc + h[v] as i128) * sharing - rest, rest - acc * sharing);
                if acc > 0 && left > 0 && over > 0 && over > under {
                    rest -= acc;
                    (acc, bin) = (0, bin + 1);
                }
                q[v] = bin as u8;
                acc += h[v] as i128;
                let (left, sharing) = bins(bin);
                if left > 0 && ((acc > 0 && acc * sharing >= rest) || 255 - v <= left) {
                    rest -= acc;
                    (acc, bin) = (0, bin + 1);
                }
            }
            q
        });
        Self { levels }
    }

    /// Per channel, each level's bin.
    pub fn levels(&self) -> &[[u8; 256]; 3] {
        &self.levels
    }

    /// The bin of a colour, red major: `(q_r · SIDE + q_g) · SIDE + q_b`.
    pub fn bin(&self, p: [u8; 3]) -> usize {
        let q = |c: usize| self.levels[c][p[c] as usize] as usize;
        (q(0) * SIDE + q(1)) * SIDE + q(2)
    }
}

/// The bin one step coarser a channel that holds bin `b` of a level `side` bins a channel wide
/// (bins indexed as in [`Binning::bin`]: red major, blue minor).
fn parent(b: usize, side: usize) -> usize {
    let (r, g, bl) = (b / (side * side), b / side % side, b % side);
    let half = side / 2;
    ((r / 2) * half + g / 2) * half + bl / 2
}

/// A fitted restoration: the bins and, per bin ([`Binning::bin`]), the restored colour. What
/// the enhancer's first stage looks up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Table {
    pub binning: Binning,
    /// [`SIDE`]^3 restored colours.
    pub entries: Vec<[u8; 3]>,
}

impl Table {
    /// The restored colour of one protected colour.
    pub fn lookup(&self, p: [u8; 3]) -> [u8; 3] {
        self.entries[self.binning.bin(p)]
    }

    /// Restores a protected image pixel by pixel.
    pub fn apply(&self, img: &RgbImage) -> RgbImage {
        let mut out = img.clone();
        out.pixels_mut().for_each(|p| p.0 = self.lookup(p.0));
        out
    }
}

/// The per-pixel MMSE inverse of one colour map.
#[derive(Debug, Clone)]
pub struct Restorer {
    table: Table,
}

impl Restorer {
    /// Fits the inverse of `protect` (a per-pixel map: each output pixel may depend on its
    /// input pixel only) on the pixels of `prior` (raw images), which is read twice (the
    /// bins, then the sums; `protect` runs twice on each image rather than keeping them).
    pub fn fit<'a, I>(protect: impl Fn(&RgbImage) -> RgbImage, prior: I) -> Result<Self>
    where
        I: IntoIterator<Item = &'a RgbImage>,
        I::IntoIter: Clone,
    {
        let prior = prior.into_iter();
        let seen = |img: &RgbImage| {
            let out = protect(img);
            if out.dimensions() != img.dimensions() {
                return Err(crate::EvalError::Invalid("restoration: the protection changed the image size".into()));
            }
            Ok(out)
        };
        let mut histogram = [[0u64; 256]; 3];
        for img in prior.clone() {
            for p in seen(img)?.pixels() {
                (0..3).for_each(|c| histogram[c][p.0[c] as usize] += 1);
            }
        }
        if histogram[0].iter().all(|&n| n == 0) {
            return Err(crate::EvalError::Invalid("restoration prior: no pixels".into()));
        }
        let binning = Binning::equal_mass(&histogram);
        // Per protected bin: how many prior pixels land there, their raw sum.
        let mut count = vec![0u64; SIDE * SIDE * SIDE];
        let mut sum = vec![[0u64; 3]; SIDE * SIDE * SIDE];
        for img in prior {
            for (raw, out) in img.pixels().zip(seen(img)?.pixels()) {
                let o = binning.bin(out.0);
                count[o] += 1;
                (0..3).for_each(|c| sum[o][c] += raw.0[c] as u64);
            }
        }
        // The same sums at every coarser level: levels[k] has 2^k bins a channel.
        let mut levels = vec![(count, sum)];
        for k in (0..SIDE.trailing_zeros() as usize).rev() {
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
        let entries = est.iter().map(|e| e.map(|v| v.round().clamp(0.0, 255.0) as u8)).collect();
        Ok(Self { table: Table { binning, entries } })
    }

    /// The fitted table: what the enhancer's first stage looks up.
    pub fn table(&self) -> &Table {
        &self.table
    }

    /// Restores a protected image pixel by pixel.
    pub fn apply(&self, img: &RgbImage) -> RgbImage {
        self.table.apply(img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProtectFn;

    fn prior() -> Vec<RgbImage> {
        // Every red and green level 256 times, blue their exclusive or: every level 256 times
        // too, and each aligned 4 x 4 block of (red, green) one blue bin of 4 levels.
        let mut a = RgbImage::new(256, 256);
        for (x, y, p) in a.enumerate_pixels_mut() {
            p.0 = [x as u8, y as u8, (x ^ y) as u8];
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
        // The prior is uniform on every channel, so the bins are 4 levels wide, and each
        // raw colour comes back within its bin (4 levels).
        assert_eq!(r.table().binning, Binning::uniform());
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
    fn bins_hold_about_equal_mass_and_a_heavy_level_its_own() {
        // Uniform: the equal-width bins.
        let flat = [[7u64; 256]; 3];
        assert_eq!(Binning::equal_mass(&flat), Binning::uniform());
        assert_eq!(Binning::uniform().levels()[1][255], 63);
        assert_eq!(Binning::uniform().bin([4, 8, 255]), (SIDE + 2) * SIDE + 63);
        // Red: level 100 holds half the pixels, the rest spread evenly over the other 255.
        // Level 100 fills a bin alone; the levels below share their part of the 64 bins by
        // mass. Green: everything on one level.
        let mut h = [[0u64; 256]; 3];
        h[0] = [2; 256];
        h[0][100] = 510;
        h[1][30] = 1000;
        h[2] = [1; 256];
        let b = Binning::equal_mass(&h);
        for q in b.levels() {
            // Non-decreasing, from bin 0 to bin 63, no bin skipped.
            assert_eq!((q[0], q[255]), (0, 63));
            assert!(q.windows(2).all(|w| w[1] == w[0] || w[1] == w[0] + 1), "{q:?}");
        }
        let red = b.levels()[0];
        // By hand: 1,020 pixels; the first bin's share is 1020 / 64 = 15.94, so 8 levels of 2
        // (16) fill it, and each next bin's share stays (1020 − 16k) / (64 − k), 8 levels, up
        // to bin 12 (levels 96..100, 8 pixels), which closes before level 100 (510: over its
        // share of 828 / 52 = 15.9 by 502, short of it by 7.9). Level 100 fills bin 13; the
        // 310 pixels left over 50 bins make shares of 6.2, 3 levels (6) a bin.
        assert_eq!(red[..8], [0; 8]);
        assert_eq!((red[8], red[95], red[96], red[99]), (1, 11, 12, 12));
        assert_eq!((red[100], red[101], red[103], red[104]), (13, 14, 14, 15));
        // Green: every pixel on level 30, so levels 0..=30 fill bin 0; then nothing is left
        // to share, and the levels above close a bin each only as they must (the last 62:
        // 194..=255 in bins 2..=63).
        let green = b.levels()[1];
        assert_eq!((green[30], green[31], green[193], green[194], green[195]), (0, 1, 1, 2, 3));
        // Blue: uniform, 4 levels a bin.
        assert_eq!(b.levels()[2], Binning::uniform().levels()[2]);
    }

    #[test]
    fn every_bin_is_the_shrunk_mean_of_the_pixels_that_reach_it() {
        // The prior holds only dark colours: bright protected bins are never reached.
        let dark = vec![RgbImage::from_fn(64, 64, |x, y| image::Rgb([x as u8, y as u8, 10]))];
        let same: Box<ProtectFn> = Box::new(|img: &RgbImage| img.clone());
        let r = Restorer::fit(same.as_ref(), &dark).unwrap();
        let t = r.table();
        assert_eq!(t.entries.len(), 1 << 18);
        assert_eq!(t.apply(&dark[0]), r.apply(&dark[0]));
        // By hand, K = 4. The bins: red and green hold 64 pixels on each of levels 0..64, so
        // each level up to 62 fills a bin alone and bin 63 holds 63..=255; blue is 10
        // throughout, bin 0. Red and green are symmetric. For [5, 2, 10] the bins one step
        // coarser a channel hold 4, 16, 64, 256, 1,024 and 4,096 pixels, means (4.5, 2.5),
        // (5.5, 1.5), 3.5, 7.5, 15.5 and 31.5, so from the top:
        //   1,024: (1024 · 15.5 + 4 · 31.5) / 1028 = 15.5623
        //     256: (256 · 7.5 + 4 · 15.5623) / 260 = 7.6240
        //      64: (64 · 3.5 + 4 · 7.6240) / 68 = 3.7426
        //      16: red (16 · 5.5 + 4 · 3.7426) / 20 = 5.149, green (16 · 1.5 + 4 · 3.7426) / 20 = 1.949
        //       4: red (4 · 4.5 + 4 · 5.149) / 8 = 4.824, green (4 · 2.5 + 4 · 1.949) / 8 = 2.224
        //       1: red (5 + 4 · 4.824) / 5 = 4.859, green (2 + 4 · 2.224) / 5 = 2.179.
        assert_eq!(SHRINK, 4.0);
        assert_eq!(t.lookup([5, 2, 10]), [5, 2, 10]);
        // Unreached: blue 255 is in bin 63, empty like every coarser bin holding it up to the
        // top, so the prior's mean colour, (31.5, 31.5, 10) rounded.
        assert_eq!(t.lookup([201, 130, 255]), [32, 32, 10]);
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
        let r = Restorer::fit(steep.as_ref(), &prior).unwrap();
        // Only the 16 multiples of 16 are reached, 256 pixels each: each fills a bin alone.
        let red = r.table().binning.levels()[0];
        let mut bins: Vec<u8> = (0..16).map(|m| red[16 * m]).collect();
        bins.dedup();
        assert_eq!(bins.len(), 16, "{red:?}");
        for j in (0..64).step_by(4) {
            // 16 rows x 16 reds = 256 pixels a bin: the shrinkage moves the mean by < 0.2.
            let got = r.table().lookup([4 * j as u8, 100, 100]);
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
        // The camera produces only black and white, so every channel's bin 0 is level 0 and
        // bin 63 holds 255. A colour high in red and low in green and blue shares no
        // coarser bin with either until one bin a channel: the prior's mean colour, 127.5
        // on every channel, rounded.
        let odd = r.apply(&RgbImage::from_pixel(1, 1, image::Rgb([250, 10, 30]))).get_pixel(0, 0).0;
        assert_eq!(odd, [128, 128, 128]);
        assert!(Restorer::fit(fold.as_ref(), &[]).is_err());
    }
}
