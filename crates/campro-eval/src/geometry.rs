//! Image geometry: bilinear sampling and resizing, letterboxing, similarity transforms.
//!
//! Pixel centres sit at integer coordinates + 0.5 (OpenCV's and PyTorch's
//! `align_corners = false` convention).

use image::{Rgb, RgbImage};

/// A 2x3 affine map `[a b c; d e f]`: `(x, y) -> (a x + b y + c, d x + e y + f)`.
pub type Affine = [[f64; 3]; 2];

/// Bilinear sample at continuous pixel coordinates (x, y) (pixel centres at integers),
/// with `border` outside the image.
pub fn sample_bilinear(img: &RgbImage, x: f64, y: f64, border: [u8; 3]) -> [f64; 3] {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let px = |xi: i64, yi: i64| -> [f64; 3] {
        if xi < 0 || yi < 0 || xi >= w || yi >= h {
            border.map(f64::from)
        } else {
            img.get_pixel(xi as u32, yi as u32).0.map(f64::from)
        }
    };
    let (a, b, c, d) = (px(x0, y0), px(x0 + 1, y0), px(x0, y0 + 1), px(x0 + 1, y0 + 1));
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bot = c[k] + (d[k] - c[k]) * fx;
        top + (bot - top) * fy
    })
}

fn to_u8(v: f64) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// [`to_u8`] without a library call or the saturating cast's fix-ups (so loops of it
/// vectorise): `v` held to [-1, 256] (NaN to -1), where both give the clamped byte; then the
/// integer part by truncation and the exact remainder (`v - trunc(v)` is exact for any
/// finite f64) decide the half away from zero. The same byte as [`to_u8`] for every `v`.
#[inline(always)]
fn to_u8_fast(v: f64) -> u8 {
    #[allow(clippy::manual_clamp)] // f64::clamp keeps a NaN; max turns it into -1
    let v = v.max(-1.0).min(256.0);
    // SAFETY: v is finite and in [-1, 256], so its truncation is an i32.
    let t = unsafe { v.to_int_unchecked::<i32>() };
    let r = t + i32::from(v - f64::from(t) >= 0.5);
    r.clamp(0, 255) as u8
}

/// Resizes with bilinear interpolation and half-pixel centres (as OpenCV's INTER_LINEAR;
/// edge pixels are replicated). The same f64 arithmetic as [`sample_bilinear`] at each
/// pixel's source point, so the same bytes (a test compares them), computed separably:
/// each source row's horizontal interpolation (`a + (b - a) fx`) once, kept while output
/// rows use it, then the vertical one per output byte (loops the compiler vectorises).
pub fn resize_bilinear(img: &RgbImage, width: u32, height: u32) -> RgbImage {
    resize_bilinear_region(img, (width, height), [0, 0, width, height])
}

/// The `[x, y, w, h]` window (clipped to the output) of [`resize_bilinear`]`(img, width,
/// height)`, the same bytes, computed from the source rows it needs only: a tile of a
/// large image's enlarged pyramid level without the level (the face guard's).
pub fn resize_bilinear_region(img: &RgbImage, (width, height): (u32, u32), [x, y, w, h]: [u32; 4]) -> RgbImage {
    let (x, y) = (x.min(width), y.min(height));
    let (w, h) = (w.min(width - x), h.min(height - y));
    let (iw, ih) = (img.width() as usize, img.height() as usize);
    if iw == 0 || ih == 0 || w == 0 || h == 0 {
        return RgbImage::new(w, h);
    }
    // Along one axis: the first source index, the next one (the same at the far edge,
    // where the weight is 0) and the weight of the next.
    let taps = |out: u32, len: usize, from: u32, n: u32| -> Vec<(usize, usize, f64)> {
        let (scale, max) = (len as f64 / out as f64, len as f64 - 1.0);
        (from..from + n)
            .map(|o| {
                let u = ((o as f64 + 0.5) * scale - 0.5).clamp(0.0, max);
                let i = u.floor();
                (i as usize, (i as usize + 1).min(len - 1), u - i)
            })
            .collect()
    };
    let (xs, ys) = (taps(width, iw, x, w), taps(height, ih, y, h));
    let (raw, stride, row_len) = (img.as_raw(), iw * 3, w as usize * 3);
    // Per output byte: the source bytes of its two columns and the weight.
    let (mut at0, mut at1, mut wx) =
        (Vec::with_capacity(row_len), Vec::with_capacity(row_len), Vec::with_capacity(row_len));
    for &(x0, x1, fx) in &xs {
        for k in 0..3 {
            at0.push(x0 * 3 + k);
            at1.push(x1 * 3 + k);
            wx.push(fx);
        }
    }
    let across = |y: usize, into: &mut Vec<f64>| {
        let r = &raw[y * stride..][..stride];
        into.clear();
        into.extend(at0.iter().zip(&at1).zip(&wx).map(|((&i0, &i1), &fx)| {
            let (a, b) = (f64::from(r[i0]), f64::from(r[i1]));
            a + (b - a) * fx
        }));
    };
    // The horizontal rows of the last source rows used, by source row index.
    let (mut top, mut bot) = ((usize::MAX, Vec::with_capacity(row_len)), (usize::MAX, Vec::with_capacity(row_len)));
    let mut out = vec![0u8; row_len * h as usize];
    for (row, &(y0, y1, fy)) in out.chunks_exact_mut(row_len).zip(&ys) {
        // Moving down, the last row's bottom is often this one's top.
        if top.0 != y0 {
            if bot.0 == y0 {
                std::mem::swap(&mut top, &mut bot);
            } else {
                top.0 = y0;
                across(y0, &mut top.1);
            }
        }
        if bot.0 != y1 {
            bot.0 = y1;
            across(y1, &mut bot.1);
        }
        for ((o, &t), &b) in row.iter_mut().zip(&top.1).zip(&bot.1) {
            *o = to_u8_fast(t + (b - t) * fy);
        }
    }
    RgbImage::from_raw(w, h, out).expect("w x h x 3 bytes")
}

/// The size (width, height) the image of `dims` takes on a [`letterbox`] canvas.
pub fn letterbox_size(dims: (u32, u32), width: u32, height: u32, scale: f64) -> (u32, u32) {
    (
        ((dims.0 as f64 * scale).round() as u32).clamp(1, width),
        ((dims.1 as f64 * scale).round() as u32).clamp(1, height),
    )
}

/// Scales `img` by `scale` (bilinear) and places it at the top-left of a `width x height`
/// canvas filled with `pad`. Returns the canvas; a point of the canvas maps back to the
/// image by dividing by `scale`.
pub fn letterbox(img: &RgbImage, width: u32, height: u32, scale: f64, pad: u8) -> RgbImage {
    let (sw, sh) = letterbox_size(img.dimensions(), width, height, scale);
    let scaled = if (sw, sh) == img.dimensions() { img.clone() } else { resize_bilinear(img, sw, sh) };
    let mut canvas = RgbImage::from_pixel(width, height, Rgb([pad; 3]));
    image::imageops::replace(&mut canvas, &scaled, 0, 0);
    canvas
}

/// The least-squares similarity transform (rotation, uniform scale, translation; no
/// reflection) taking `src` points onto `dst` (Umeyama 1991, closed form in 2-D).
pub fn similarity(src: &[[f64; 2]], dst: &[[f64; 2]]) -> Affine {
    let n = src.len() as f64;
    let mean = |p: &[[f64; 2]]| {
        let s = p.iter().fold([0.0; 2], |a, q| [a[0] + q[0], a[1] + q[1]]);
        [s[0] / n, s[1] / n]
    };
    let (ms, md) = (mean(src), mean(dst));
    // With complex numbers z = x + iy: dst ≈ c·src + t, c = Σ conj(s)·d / Σ |s|².
    let (mut re, mut im, mut ss) = (0.0, 0.0, 0.0);
    for (s, d) in src.iter().zip(dst) {
        let (sx, sy) = (s[0] - ms[0], s[1] - ms[1]);
        let (dx, dy) = (d[0] - md[0], d[1] - md[1]);
        re += sx * dx + sy * dy;
        im += sx * dy - sy * dx;
        ss += sx * sx + sy * sy;
    }
    let (a, b) = if ss > 0.0 { (re / ss, im / ss) } else { (1.0, 0.0) };
    [[a, -b, md[0] - (a * ms[0] - b * ms[1])], [b, a, md[1] - (b * ms[0] + a * ms[1])]]
}

/// Applies an affine map to a point.
pub fn apply(m: &Affine, p: [f64; 2]) -> [f64; 2] {
    [m[0][0] * p[0] + m[0][1] * p[1] + m[0][2], m[1][0] * p[0] + m[1][1] * p[1] + m[1][2]]
}

/// Inverse of an invertible affine map (None when singular).
pub fn invert(m: &Affine) -> Option<Affine> {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    if det.abs() < 1e-12 || !det.is_finite() {
        return None;
    }
    let (a, b, d, e) = (m[1][1] / det, -m[0][1] / det, -m[1][0] / det, m[0][0] / det);
    Some([[a, b, -(a * m[0][2] + b * m[1][2])], [d, e, -(d * m[0][2] + e * m[1][2])]])
}

/// Warps `img` into a `width x height` crop: crop pixel p takes the source at `m⁻¹(p)`
/// (the map is between pixel-index coordinates, as OpenCV's warpAffine), bilinear, black
/// outside. Returns None when the map is singular.
pub fn warp_affine(img: &RgbImage, m: &Affine, width: u32, height: u32) -> Option<RgbImage> {
    let inv = invert(m)?;
    Some(RgbImage::from_fn(width, height, |x, y| {
        let [u, v] = apply(&inv, [x as f64, y as f64]);
        Rgb(sample_bilinear(img, u, v, [0; 3]).map(to_u8))
    }))
}

/// Intersection over union of two boxes `[x0, y0, x1, y1]`.
pub fn iou(a: [f32; 4], b: [f32; 4]) -> f32 {
    let iw = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let ih = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = iw * ih;
    let area = |r: [f32; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let union = area(a) + area(b) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// Greedy non-maximum suppression: indices of kept boxes, by descending score.
pub fn nms(boxes: &[[f32; 4]], scores: &[f32], iou_threshold: f32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&i, &j| scores[j].total_cmp(&scores[i]).then(i.cmp(&j)));
    let mut keep: Vec<usize> = Vec::new();
    for i in order {
        if keep.iter().all(|&k| iou(boxes[k], boxes[i]) <= iou_threshold) {
            keep.push(i);
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn similarity_recovers_a_known_map() {
        // Rotation by 30°, scale 1.7, shift (5, -3): src -> dst exactly.
        let (c, s) = (1.7 * 30f64.to_radians().cos(), 1.7 * 30f64.to_radians().sin());
        let truth: Affine = [[c, -s, 5.0], [s, c, -3.0]];
        let src = [[10.0, 20.0], [40.0, 22.0], [25.0, 35.0], [12.0, 50.0], [38.0, 51.0]];
        let dst: Vec<[f64; 2]> = src.iter().map(|&p| apply(&truth, p)).collect();
        let m = similarity(&src, &dst);
        for r in 0..2 {
            for k in 0..3 {
                assert!((m[r][k] - truth[r][k]).abs() < 1e-12, "{m:?}");
            }
        }
        let inv = invert(&m).unwrap();
        let back = apply(&inv, apply(&m, [3.0, 4.0]));
        assert!((back[0] - 3.0).abs() < 1e-12 && (back[1] - 4.0).abs() < 1e-12);
    }

    #[test]
    fn similarity_never_reflects() {
        // A mirrored point set: the best similarity cannot flip, so it is not exact.
        let src = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let dst = [[0.0, 0.0], [-1.0, 0.0], [0.0, 1.0]];
        let m = similarity(&src, &dst);
        let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
        assert!(det >= 0.0);
    }

    #[test]
    fn iou_and_nms_by_hand() {
        // Two 2x2 boxes overlapping in a 1x2 strip: IoU = 2 / (4 + 4 − 2) = 1/3.
        assert!((iou([0., 0., 2., 2.], [1., 0., 3., 2.]) - 1.0 / 3.0).abs() < 1e-7);
        assert_eq!(iou([0., 0., 1., 1.], [2., 2., 3., 3.]), 0.0);
        let boxes = [[0., 0., 2., 2.], [1., 0., 3., 2.], [0.1, 0., 2.1, 2.], [5., 5., 6., 6.]];
        let scores = [0.8, 0.9, 0.7, 0.1];
        // 1 (0.9) first; 0 overlaps it by 1/3 (kept at 0.5); 2 overlaps 0 by 0.9 (dropped).
        assert_eq!(nms(&boxes, &scores, 0.5), vec![1, 0, 3]);
        assert_eq!(nms(&boxes, &scores, 0.3), vec![1, 3]);
    }

    #[test]
    fn fast_rounding_is_the_library_rounding() {
        // Halves (away from zero), the largest f64 below a half (whose `v + 0.5` rounds up
        // to 1), just below and above the ends, and far outside.
        let below_half = 0.5 - f64::EPSILON / 4.0;
        let mut cases = vec![0.0, -0.0, 0.5, 1.5, 2.5, 254.5, 255.0, 255.49, 255.5, below_half, 1.0 + below_half];
        cases.extend([-0.4, -0.5, -0.6, -1.5, -1e-300, 1e-300, 300.0, -300.0, 2e9, -2e9, 1e300, f64::NAN]);
        cases.extend([f64::INFINITY, f64::NEG_INFINITY, 255.5 - f64::EPSILON * 64.0, 256.0, 256.5]);
        cases.extend((0..=2560).map(|i| f64::from(i) / 10.0));
        for v in cases {
            assert_eq!(to_u8_fast(v), to_u8(v), "{v:e}");
        }
    }

    #[test]
    fn bilinear_resize_of_a_ramp_is_linear_inside() {
        // A horizontal ramp 0, 10, ..., 70 upsampled 2x: interior pixels interpolate.
        let img = RgbImage::from_fn(8, 1, |x, _| Rgb([(x * 10) as u8; 3]));
        let up = resize_bilinear(&img, 16, 1);
        // Output x maps to input (x + 0.5)/2 − 0.5: x = 3 -> 1.25 -> 12.5 -> rounds to 13 (half away).
        assert_eq!(up.get_pixel(3, 0).0[0], 13);
        assert_eq!(up.get_pixel(0, 0).0[0], 0); // clamped at the edge
        assert_eq!(up.get_pixel(15, 0).0[0], 70);
    }

    #[test]
    fn bilinear_resize_samples_every_pixel_at_its_source_point() {
        // The second implementation: sample_bilinear at each output pixel's source point
        // (clamped into the image), rounded, on noise, up, down and across both.
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let img = RgbImage::from_fn(37, 23, |_, _| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            Rgb([state as u8, (state >> 8) as u8, (state >> 16) as u8])
        });
        for (w, h) in [(59, 37), (16, 11), (37, 23), (60, 9), (1, 1), (100, 1)] {
            let got = resize_bilinear(&img, w, h);
            let (sx, sy) = (37.0 / w as f64, 23.0 / h as f64);
            for (x, y, p) in got.enumerate_pixels() {
                let u = ((x as f64 + 0.5) * sx - 0.5).clamp(0.0, 36.0);
                let v = ((y as f64 + 0.5) * sy - 0.5).clamp(0.0, 22.0);
                assert_eq!(p.0, sample_bilinear(&img, u, v, [0; 3]).map(to_u8), "{w} x {h} at ({x}, {y})");
            }
        }
    }

    #[test]
    fn a_resized_window_is_that_window_of_the_whole_resize() {
        let img = RgbImage::from_fn(41, 29, |x, y| Rgb([(x * 7 + y) as u8, (x * y) as u8, (3 * y) as u8 ^ x as u8]));
        for (size, window) in [
            ((82, 58), [0, 0, 82, 58]),
            ((82, 58), [13, 7, 30, 21]),
            ((82, 58), [70, 50, 40, 40]), // clipped at the far edges
            ((20, 15), [5, 0, 15, 15]),
            ((82, 58), [90, 0, 4, 4]), // wholly outside: empty
        ] {
            let whole = resize_bilinear(&img, size.0, size.1);
            let got = resize_bilinear_region(&img, size, window);
            let [x, y, w, h] = window;
            let (w, h) = (w.min(size.0.saturating_sub(x)), h.min(size.1.saturating_sub(y)));
            assert_eq!(got.dimensions(), (w, h), "{size:?} {window:?}");
            let want = image::imageops::crop_imm(&whole, x.min(size.0), y.min(size.1), w, h).to_image();
            assert!(got == want, "{size:?} {window:?}");
        }
    }
}
