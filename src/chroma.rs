//! How much colour an image has beyond its brightness: the measure behind "grey input".
//!
//! A global matrix and tone curve protect a face by folding colours onto each other, and
//! a picture whose colours lie on one line (black-and-white, infrared and night cameras,
//! sepia, a face under one-coloured light) gives them nothing to fold: the camera maps
//! that line to a curve, nearly one-to-one, and a restoration that knows the camera
//! inverts it (100 grey LFW identities: restored 98.5% top-1, against 3.5% in colour).
//! So an image is measured by how far its colours stray from being a function of
//! brightness, whatever the tint.
//!
//! [`measure`]: pixels are put in 64 bins of BT.601 luma (`(77 R + 150 G + 29 B) >> 8`, four
//! codes a bin); the spread is the root-mean-square distance, in 8-bit codes, of each
//! pixel's (R, G, B) from the mean colour of its bin, the squares summed over the bins
//! and divided by the pixels less the bins used (the pooled within-bin variance, unbiased:
//! a bin of one pixel says nothing about the spread). A grey image spread evenly over its
//! codes has `sqrt(5)` = 2.24 (four codes a bin: squared deviations 5 a channel, over pooled over
//! 256 − 64 degrees of freedom: 3 · 5 · 64 / 192), a tinted monochrome one about as
//! much; colour photos measured 6.9 to 40 (200 LFW photos, 1st percentile 8.2; 300 COCO
//! scenes, 5th percentile 3.1: COCO holds black-and-white photos). Under [`MIN_PIXELS`]
//! pixels a picture is too small to hold a face and is not called grey.

/// Spread (8-bit codes, RMS) below which an image counts as grey ([`is_grey`]): twice a
/// pure grey image's most, under every colour photo of LFW measured (6.9 and up).
pub const GREY_SPREAD: f64 = 4.0;

/// Most pixels [`measure`] reads: larger images are read at an even stride (a 1080p video
/// frame, measured on every frame, at every 32nd pixel).
pub const MAX_SAMPLES: usize = 1 << 16;

/// BT.601 luma of an 8-bit RGB pixel in integers, `(77 R + 150 G + 29 B) >> 8` (0..=255):
/// what [`measure`] bins by, and the grey a monochrome camera would record.
#[inline]
pub fn luma(p: [u8; 3]) -> u8 {
    ((77 * p[0] as u32 + 150 * p[1] as u32 + 29 * p[2] as u32) >> 8) as u8
}

/// Fewest pixels a picture must have to be called grey ([`Chroma::is_grey`]).
pub const MIN_PIXELS: usize = 256;

/// Luma bins of [`measure`].
const BINS: usize = 64;

/// Standard deviation of luma (8-bit codes) under which a picture is flat: it shows no
/// scene (a uniform fill), so whatever its colour it is not called grey.
pub const FLAT_DETAIL: f64 = 2.0;

/// What [`measure`] finds in a picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chroma {
    /// The colour spread (module docs), 8-bit codes RMS.
    pub spread: f64,
    /// The standard deviation of luma, 8-bit codes: how much scene there is.
    pub detail: f64,
    /// Pixels read.
    pub pixels: usize,
}

impl Chroma {
    /// Grey or near grey: a scene (at least [`MIN_PIXELS`] pixels, [`Chroma::detail`] at
    /// least [`FLAT_DETAIL`]) whose colours spread less than [`GREY_SPREAD`] from a
    /// function of brightness.
    pub fn is_grey(&self) -> bool {
        self.pixels >= MIN_PIXELS && self.spread < GREY_SPREAD && self.detail >= FLAT_DETAIL
    }
}

/// The colour spread and luma detail of interleaved 8-bit RGB pixels (module docs); zeros
/// for no pixels. A trailing partial pixel is ignored. Reads at most [`MAX_SAMPLES`]
/// pixels.
pub fn measure(rgb: &[u8]) -> Chroma {
    let n = rgb.len() / 3;
    if n == 0 {
        return Chroma { spread: 0.0, detail: 0.0, pixels: 0 };
    }
    let stride = n.div_ceil(MAX_SAMPLES);
    let mut count = [0u64; BINS];
    let mut sum = [[0f64; 3]; BINS];
    let mut squares = [[0f64; 3]; BINS];
    let (mut luma_sum, mut luma_squares) = (0f64, 0f64);
    for p in rgb.chunks_exact(3).step_by(stride) {
        let luma = luma([p[0], p[1], p[2]]) as u32;
        luma_sum += luma as f64;
        luma_squares += (luma * luma) as f64;
        let b = luma as usize / (256 / BINS);
        count[b] += 1;
        for c in 0..3 {
            let v = p[c] as f64;
            sum[b][c] += v;
            squares[b][c] += v * v;
        }
    }
    let total = count.iter().sum::<u64>() as f64;
    let used = count.iter().filter(|&&c| c > 0).count() as f64;
    let within: f64 = (0..BINS)
        .filter(|&b| count[b] > 0)
        .map(|b| (0..3).map(|c| squares[b][c] - sum[b][c] * sum[b][c] / count[b] as f64).sum::<f64>())
        .sum();
    let mean = luma_sum / total;
    Chroma {
        spread: (within.max(0.0) / (total - used).max(1.0)).sqrt(),
        detail: (luma_squares / total - mean * mean).max(0.0).sqrt(),
        pixels: total as usize,
    }
}

/// Largest difference between a pixel's channels (8-bit codes) for it to count as neutral
/// in [`neutral_share`].
pub const NEUTRAL_RANGE: u8 = 6;

/// Share of a picture's mid-tone pixels (luma 40..=215, where colour shows) that are
/// neutral (channels within [`NEUTRAL_RANGE`] codes), read at an even stride of at most
/// [`MAX_SAMPLES`] pixels; 0 without mid-tones. A selective-colour photo (grey but for one
/// object) has colour spread enough to pass [`measure`] and a share of 0.79 to 0.93; so do
/// snow and overcast scenes (0.77 to 0.90), so a high share only says where to look next
/// (the faces), not that the picture is grey.
pub fn neutral_share(rgb: &[u8]) -> f64 {
    let n = rgb.len() / 3;
    let stride = n.div_ceil(MAX_SAMPLES).max(1);
    let (mut mid, mut neutral) = (0u64, 0u64);
    for p in rgb.chunks_exact(3).step_by(stride) {
        if (40..=215).contains(&luma([p[0], p[1], p[2]])) {
            mid += 1;
            let (lo, hi) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
            neutral += u64::from(hi - lo <= NEUTRAL_RANGE);
        }
    }
    if mid == 0 {
        0.0
    } else {
        neutral as f64 / mid as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_grey_code_once_has_the_bins_own_spread() {
        // Each bin holds four consecutive grey codes: per channel the squared deviations of
        // {0, 1, 2, 3} from 1.5 sum to 5; 3 channels x 64 bins over 256 - 64 degrees of
        // freedom: 5.
        let rgb: Vec<u8> = (0..=255u8).flat_map(|v| [v, v, v]).collect();
        let m = measure(&rgb);
        assert!((m.spread - 5f64.sqrt()).abs() < 1e-12, "{m:?}");
        assert!(m.is_grey());
    }

    #[test]
    fn a_tint_is_still_one_line_of_colours() {
        // Sepia-like: (v, 0.85 v, 0.6 v); in each bin the colours differ by a few codes.
        let rgb: Vec<u8> = (0..=255u32).flat_map(|v| [v as u8, (v * 85 / 100) as u8, (v * 60 / 100) as u8]).collect();
        assert!(measure(&rgb).is_grey(), "{:?}", measure(&rgb));
    }

    #[test]
    fn two_colours_of_one_brightness_spread_by_their_distance() {
        // Luma 115 and 113 (bin 28), 128 pixels of each: each pixel is |A - B| / 2 from
        // their mean; 256 squares of d² / 4 over 256 - 1 degrees of freedom.
        let (a, b) = ([150u8, 100, 100], [255u8, 62, 0]);
        let d2: f64 = (0..3).map(|c| (a[c] as f64 - b[c] as f64).powi(2)).sum();
        let rgb = [a, b].concat().repeat(128);
        assert!((measure(&rgb).spread - (256.0 * d2 / 4.0 / 255.0).sqrt()).abs() < 1e-9);
        assert!(!measure(&rgb).is_grey());
    }

    #[test]
    fn large_images_are_sampled_and_empty_ones_are_zero() {
        assert_eq!(measure(&[]), Chroma { spread: 0.0, detail: 0.0, pixels: 0 });
        assert_eq!(measure(&[1, 2]), Chroma { spread: 0.0, detail: 0.0, pixels: 0 });
        // 4 × MAX_SAMPLES pixels alternating two colours of one bin: the stride (4) reads
        // only the even ones, all of the first colour.
        let rgb: Vec<u8> =
            (0..4 * MAX_SAMPLES).flat_map(|i| if i % 2 == 0 { [150, 100, 100] } else { [255, 62, 0] }).collect();
        assert_eq!(measure(&rgb).spread, 0.0);
    }

    #[test]
    fn a_flat_fill_is_no_scene_whatever_its_colour() {
        // One colour: spread and detail 0, so not grey (nothing to protect or restore).
        let flat = [[100u8, 150, 200]; 512].concat();
        assert_eq!(measure(&flat), Chroma { spread: 0.0, detail: 0.0, pixels: 512 });
        assert!(!measure(&flat).is_grey());
        // Two grey levels, 0 and 255, half each: luma 0 and 255, standard deviation 127.5.
        let two = [[0u8; 3], [255u8; 3]].concat().repeat(128);
        assert!((measure(&two).detail - 127.5).abs() < 1e-9);
        assert!(measure(&two).is_grey());
    }

    #[test]
    fn a_few_pixels_are_not_called_grey() {
        // Twelve pixels along a tinted line: too few to hold a face.
        let line: Vec<u8> = (0..36).map(|i| (i * 7 % 256) as u8).collect();
        assert_eq!(measure(&line).pixels, 12);
        assert!(!measure(&line).is_grey());
    }

    #[test]
    fn the_neutral_share_counts_mid_tones_within_the_range() {
        // 3 neutral mid-tones (one at the range's edge), 1 coloured, 2 too dark or bright
        // to count: 3 of 4.
        let rgb = [100, 100, 100, 120, 126, 123, 50, 52, 51, 200, 90, 90, 10, 10, 10, 250, 250, 250];
        assert_eq!(neutral_share(&rgb), 0.75);
        // One code past the range is coloured; nothing mid-tone is 0.
        assert_eq!(neutral_share(&[120, 127, 123]), 0.0);
        assert_eq!(neutral_share(&[0, 0, 0, 255, 255, 255]), 0.0);
    }
}
