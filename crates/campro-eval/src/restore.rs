//! The restoration attack on a per-pixel colour map (the paper's adaptive attack by image
//! restoration, Sec. VII, in its simplest exact form): an attacker who knows the camera
//! maps each protected colour back to the mean raw colour that produces it, weighted by how
//! often that raw colour occurs in natural images, then runs face recognition as usual.
//!
//! For a bijective map (colour inversion) this recovers the raw image up to quantisation,
//! so identification comes back; for a many-to-one map (CamPro's clipping CCM and folding
//! curve) it recovers only the per-colour average, which is the point of the design. This
//! is the best any per-pixel restorer can do in squared error under that colour prior; a
//! network looking at neighbourhoods could do better.
//!
//! Colours are binned at `BITS` bits per channel on both sides: raw colours by their bin
//! (represented by the mean of the prior's pixels in it), protected colours by theirs. A
//! protected bin the prior never reaches is left as it is.

use crate::Result;
use image::RgbImage;

/// Bits per channel of the colour bins (2^18 bins).
pub const BITS: u32 = 6;
const SIDE: usize = 1 << BITS;
const SHIFT: u32 = 8 - BITS;

/// The bin of a colour: `(r >> 2) · 4096 + (g >> 2) · 64 + (b >> 2)`.
pub fn bin(p: [u8; 3]) -> usize {
    ((p[0] >> SHIFT) as usize * SIDE + (p[1] >> SHIFT) as usize) * SIDE + (p[2] >> SHIFT) as usize
}

/// The per-pixel MMSE inverse of one colour map.
#[derive(Debug, Clone)]
pub struct Restorer {
    /// Per protected-colour bin, the restored colour (None: never reached).
    lut: Vec<Option<[u8; 3]>>,
}

impl Restorer {
    /// Fits the inverse of `protect` (a per-pixel map: each output pixel may depend on its
    /// input pixel only) under the colour histogram of `prior` (raw images).
    pub fn fit<'a>(
        protect: impl Fn(&RgbImage) -> RgbImage,
        prior: impl IntoIterator<Item = &'a RgbImage>,
    ) -> Result<Self> {
        // The prior: per raw bin, pixel count and colour sum.
        let mut count = vec![0u64; SIDE * SIDE * SIDE];
        let mut sum = vec![[0u64; 3]; SIDE * SIDE * SIDE];
        for img in prior {
            for p in img.pixels() {
                let b = bin(p.0);
                count[b] += 1;
                (0..3).for_each(|c| sum[b][c] += p.0[c] as u64);
            }
        }
        let filled: Vec<usize> = (0..count.len()).filter(|&b| count[b] > 0).collect();
        if filled.is_empty() {
            return Err(crate::EvalError::Invalid("restoration prior: no pixels".into()));
        }
        // Each filled bin's mean colour, through the camera as one row of pixels.
        let reps: Vec<[u8; 3]> =
            filled.iter().map(|&b| std::array::from_fn(|c| ((sum[b][c] + count[b] / 2) / count[b]) as u8)).collect();
        let row = RgbImage::from_raw(reps.len() as u32, 1, reps.iter().flatten().copied().collect()).expect("sized");
        let seen = protect(&row);
        if seen.dimensions() != row.dimensions() {
            return Err(crate::EvalError::Invalid("restoration: the protection changed the image size".into()));
        }
        let mut w = vec![0u64; SIDE * SIDE * SIDE];
        let mut acc = vec![[0u64; 3]; SIDE * SIDE * SIDE];
        for ((&b, rep), out) in filled.iter().zip(&reps).zip(seen.pixels()) {
            let o = bin(out.0);
            w[o] += count[b];
            (0..3).for_each(|c| acc[o][c] += count[b] * rep[c] as u64);
        }
        let lut = (0..w.len())
            .map(|o| (w[o] > 0).then(|| std::array::from_fn(|c| ((acc[o][c] + w[o] / 2) / w[o]) as u8)))
            .collect();
        Ok(Self { lut })
    }

    /// The whole lookup table, per protected-colour bin ([`bin`]): the restored colour, or,
    /// for a bin the prior never reached, the bin's centre (where [`Self::apply`] keeps the
    /// pixel, within 2 LSB of it). What the enhancer's first stage looks up
    /// ([`apply_table`]).
    pub fn table(&self) -> Vec<[u8; 3]> {
        let centre = |b: usize, k: u32| (((b >> (k * BITS)) & (SIDE - 1)) << SHIFT) as u8 + (1 << (SHIFT - 1));
        self.lut.iter().enumerate().map(|(b, c)| c.unwrap_or([centre(b, 2), centre(b, 1), centre(b, 0)])).collect()
    }

    /// Restores a protected image pixel by pixel.
    pub fn apply(&self, img: &RgbImage) -> RgbImage {
        let mut out = img.clone();
        for p in out.pixels_mut() {
            if let Some(c) = self.lut[bin(p.0)] {
                p.0 = c;
            }
        }
        out
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
    fn the_whole_table_is_apply_with_bin_centres_where_unreached() {
        // The prior holds only dark colours: bright protected bins are never reached.
        let dark = vec![RgbImage::from_fn(64, 64, |x, y| image::Rgb([x as u8, y as u8, 10]))];
        let same: Box<ProtectFn> = Box::new(|img: &RgbImage| img.clone());
        let r = Restorer::fit(same.as_ref(), &dark).unwrap();
        let t = r.table();
        assert_eq!(t.len(), 1 << 18);
        // Reached: the prior's mean of the bin [4, 8) x [0, 4) x [8, 12): (5.5, 1.5, 10) rounded.
        assert_eq!(t[bin([5, 2, 10])], [6, 2, 10]);
        assert_eq!(apply_table(&t, &dark[0]), r.apply(&dark[0]));
        // Unreached: the bin's centre (bin 50 of red: 200..204 → 202).
        assert_eq!(t[bin([201, 130, 255])], [202, 130, 254]);
        let bright = RgbImage::from_pixel(2, 1, image::Rgb([201, 130, 255]));
        assert_eq!(apply_table(&t, &bright).get_pixel(0, 0).0, [202, 130, 254]);
        assert_eq!(r.apply(&bright), bright);
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
        // averages the bins' mean reds, 191.5 ± rounding; green is uniform, 127.5.
        let hi = r.apply(&RgbImage::from_pixel(1, 1, image::Rgb([255, 255, 255]))).get_pixel(0, 0).0;
        let lo = r.apply(&RgbImage::from_pixel(1, 1, image::Rgb([0, 0, 0]))).get_pixel(0, 0).0;
        assert!((hi[0] as i32 - 192).abs() <= 1 && (hi[1] as i32 - 128).abs() <= 1, "{hi:?}");
        assert!((lo[0] as i32 - 64).abs() <= 1 && (lo[1] as i32 - 128).abs() <= 1, "{lo:?}");
        // A colour the camera never produces is left alone.
        let odd = r.apply(&RgbImage::from_pixel(1, 1, image::Rgb([10, 200, 30]))).get_pixel(0, 0).0;
        assert_eq!(odd, [10, 200, 30]);
        assert!(Restorer::fit(fold.as_ref(), &[]).is_err());
    }
}
