//! Plane operations of the reduced-resolution path, on (3, H, W) f32 planes in [0, 1]:
//! padding and cropping, averaging down, the guided filter's coefficients and bilinear
//! upsampling, the face gate's blend and its pixelated target. Edges: a plane's real part is
//! its top-left `size`; past it, rows and columns repeat the last real one.

use image::RgbImage;

/// The top-left `w` x `h` of a (3, `ph`, `pw`) float image in [0, 1] (the enhancer's
/// output on [`padded_chw`]'s input), rounded to 8 bits and clamped.
pub fn cropped_rgb8(v: &[f32], pw: usize, ph: usize, w: u32, h: u32) -> RgbImage {
    let mut out = RgbImage::new(w, h);
    put_rgb8_rows(v, pw, ph, w as usize, &mut out);
    out
}

/// Writes the first `w` columns of a (3, `n`, `pw`) float strip in [0, 1], rounded to 8 bits
/// and clamped, into `rows` (packed RGB rows `w` pixels wide; as many as it holds, at most n).
pub(super) fn put_rgb8_rows(v: &[f32], pw: usize, n: usize, w: usize, rows: &mut [u8]) {
    let q = |f: f32| (f * 255.0).round().clamp(0.0, 255.0) as u8;
    let plane = pw * n;
    for (y, row) in rows.chunks_exact_mut(3 * w).take(n).enumerate() {
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            let i = y * pw + x;
            px.copy_from_slice(&[q(v[i]), q(v[plane + i]), q(v[2 * plane + i])]);
        }
    }
}

/// The low-resolution rows a strip of a (3, H, `pw`) image gives when averaged down `f`
/// times a side: the strip holds the image's rows `y0..y0 + n` (y0 a multiple of `f`) and
/// the image's top-left `size` is real (the last block of a row or column averages what it
/// has); each low row `y0 / f ..` that the strip's real rows make is written, all three
/// channels, into the (3, `low.1`, `low.0`) `out`. [`padded_low`] then pads it.
pub(super) fn average_strip_into(
    strip: &[f32],
    pw: usize,
    (y0, n): (usize, usize),
    size: (usize, usize),
    f: usize,
    low: (usize, usize),
    out: &mut [f32],
) {
    use rayon::prelude::*;
    let (w, h) = size;
    let sw = w.div_ceil(f);
    let (lpw, lph) = low;
    let real = (y0 + n).min(h);
    let (first, end) = (y0 / f, real.div_ceil(f));
    out.par_chunks_mut(lpw).enumerate().filter(|(row, _)| (first..end).contains(&(row % lph))).for_each(
        |(row, line)| {
            let (c, sy) = (row / lph, row % lph);
            let plane = &strip[c * pw * n..(c + 1) * pw * n];
            let (r0, r1) = (sy * f, (sy * f + f).min(h));
            for (sx, v) in line.iter_mut().enumerate().take(sw) {
                let (x0, x1) = (sx * f, (sx * f + f).min(w));
                let sum: f32 =
                    (r0..r1).map(|y| plane[(y - y0) * pw + x0..(y - y0) * pw + x1].iter().sum::<f32>()).sum();
                *v = sum / ((r1 - r0) * (x1 - x0)) as f32;
            }
        },
    );
}

/// Pads a (3, `lph`, `lpw`) image whose top-left `sw` x `sh` is real by repeating its last
/// real column and row.
pub(super) fn padded_low(out: &mut [f32], (lpw, lph): (usize, usize), (sw, sh): (usize, usize)) {
    for c in 0..3 {
        let plane = &mut out[c * lpw * lph..(c + 1) * lpw * lph];
        for y in 0..sh {
            let last = plane[y * lpw + sw - 1];
            plane[y * lpw + sw..(y + 1) * lpw].fill(last);
        }
        for y in sh..lph {
            plane.copy_within((sh - 1) * lpw..sh * lpw, y * lpw);
        }
    }
}

/// The face gate's blend, as the file makes it: `ungated + gate · (toward − ungated)`, on
/// (3, H, W) planes of `plane` pixels and a (1, H, W) gate.
pub(super) fn blended(mut ungated: Vec<f32>, gate: &[f32], toward: &[f32], plane: usize) -> Vec<f32> {
    use rayon::prelude::*;
    ungated.par_chunks_mut(plane).zip(toward.par_chunks(plane)).for_each(|(line, to)| {
        for ((v, &t), &g) in line.iter_mut().zip(to).zip(gate) {
            *v += g * (t - *v);
        }
    });
    ungated
}

/// Radius of the guided filter's window at low resolution, pixels (a 5 x 5 window).
pub(super) const GUIDE_RADIUS: usize = 2;
/// The guided filter's regulariser (values in 0..1): flatter than this a window is fitted
/// by its mean.
pub(super) const GUIDE_EPS: f32 = 1e-4;

/// Per channel, the coefficients (gain, offset) of the guided filter that fits `output`
/// as a linear function of `input` in every window, averaged over the windows that hold
/// each pixel: (3, `lph`, `lpw`) planes whose top-left `size` is real.
pub(super) fn guided_coefficients(
    input: &[f32],
    output: &[f32],
    size: (usize, usize),
    lpw: usize,
    lph: usize,
) -> (Vec<f32>, Vec<f32>) {
    let n = lpw * lph;
    let (mut gain, mut offset) = (vec![0f32; 3 * n], vec![0f32; 3 * n]);
    for c in 0..3 {
        let (i, p) = (&input[c * n..(c + 1) * n], &output[c * n..(c + 1) * n]);
        let ip: Vec<f32> = i.iter().zip(p).map(|(a, b)| a * b).collect();
        let ii: Vec<f32> = i.iter().map(|a| a * a).collect();
        let (mi, mp, mip, mii) =
            (boxed(i, lpw, size), boxed(p, lpw, size), boxed(&ip, lpw, size), boxed(&ii, lpw, size));
        let a: Vec<f32> = (0..n).map(|k| (mip[k] - mi[k] * mp[k]) / (mii[k] - mi[k] * mi[k] + GUIDE_EPS)).collect();
        let b: Vec<f32> = (0..n).map(|k| mp[k] - a[k] * mi[k]).collect();
        gain[c * n..(c + 1) * n].copy_from_slice(&boxed(&a, lpw, size));
        offset[c * n..(c + 1) * n].copy_from_slice(&boxed(&b, lpw, size));
    }
    (gain, offset)
}

/// The mean over the (2 [`GUIDE_RADIUS`] + 1)² window around each pixel of a plane (row
/// stride `stride`), the window cut to the top-left `size`; pixels outside it copy the
/// nearest inside.
pub(super) fn boxed(v: &[f32], stride: usize, size: (usize, usize)) -> Vec<f32> {
    let (w, h) = size;
    let r = GUIDE_RADIUS;
    let mut rows = vec![0f32; v.len()];
    for y in 0..h {
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
            rows[y * stride + x] = v[y * stride + x0..y * stride + x1].iter().sum::<f32>() / (x1 - x0) as f32;
        }
    }
    let mut out = vec![0f32; v.len()];
    let lh = v.len() / stride;
    for y in 0..lh {
        let yy = y.min(h - 1);
        let (y0, y1) = (yy.saturating_sub(r), (yy + r + 1).min(h));
        for x in 0..stride {
            let xx = x.min(w - 1);
            out[y * stride + x] = (y0..y1).map(|k| rows[k * stride + xx]).sum::<f32>() / (y1 - y0) as f32;
        }
    }
    out
}

/// Bilinear taps from `n` full-resolution positions onto `low` positions computed at 1/`f`
/// resolution: (first, second, weight of the second), between the low-resolution pixel
/// centres, clamped at the image's edge.
pub(super) fn taps(n: usize, low: usize, f: usize) -> Vec<(usize, usize, f32)> {
    (0..n)
        .map(|p| {
            let u = ((p as f32 + 0.5) / f as f32 - 0.5).clamp(0.0, (low - 1) as f32);
            let i = (u.floor() as usize).min(low.saturating_sub(2));
            (i, (i + 1).min(low - 1), u - i as f32)
        })
        .collect()
}

/// One full-resolution row of a plane (row stride `stride`) computed at low resolution,
/// bilinear through the row's tap `row` and the columns' `cols`, handed to `put`.
pub(super) fn upsample_row(
    plane: &[f32],
    stride: usize,
    row: (usize, usize, f32),
    cols: &[(usize, usize, f32)],
    line: &mut [f32],
    put: impl Fn(&mut f32, f32),
) {
    let (y0, y1, fy) = row;
    let (top, bottom) = (&plane[y0 * stride..], &plane[y1 * stride..]);
    for (v, &(x0, x1, fx)) in line.iter_mut().zip(cols) {
        let t = top[x0] + fx * (top[x1] - top[x0]);
        let b = bottom[x0] + fx * (bottom[x1] - bottom[x0]);
        put(v, t + fy * (b - t));
    }
}

/// A (3, `ph`, `pw`) image pixelated in `n` x `n` blocks (each block's mean; edge blocks
/// average what they hold): the gate's target at full resolution.
pub(super) fn pixelated(img: &[f32], pw: usize, ph: usize, n: usize) -> Vec<f32> {
    use rayon::prelude::*;
    let mut out = vec![0f32; img.len()];
    // One band of n rows of one channel at a time.
    out.par_chunks_mut(pw * ph).zip(img.par_chunks(pw * ph)).for_each(|(dst, src)| {
        dst.par_chunks_mut(pw * n).zip(src.par_chunks(pw * n)).for_each(|(dst, src)| {
            let rows = dst.len() / pw;
            for bx in (0..pw).step_by(n) {
                let x1 = (bx + n).min(pw);
                let sum: f64 =
                    (0..rows).map(|y| src[y * pw + bx..y * pw + x1].iter().map(|&v| v as f64).sum::<f64>()).sum();
                let mean = (sum / (rows * (x1 - bx)) as f64) as f32;
                for y in 0..rows {
                    dst[y * pw + bx..y * pw + x1].fill(mean);
                }
            }
        })
    });
    out
}

/// `img` as (3, H', W') floats in [0, 1], H' and W' rounded up to multiples of `multiple` by
/// repeating the last row and column; returns the data, W' and H'.
pub fn padded_chw(img: &RgbImage, multiple: usize) -> (Vec<f32>, usize, usize) {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (pw, ph) = (w.div_ceil(multiple) * multiple, h.div_ceil(multiple) * multiple);
    (chw_rows(img, pw, 0..ph), pw, ph)
}

/// Rows `rows` of [`padded_chw`]'s image `pw` wide, as (3, rows, `pw`) floats.
pub(super) fn chw_rows(img: &RgbImage, pw: usize, rows: std::ops::Range<usize>) -> Vec<f32> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let plane = pw * rows.len();
    let mut data = vec![0f32; 3 * plane];
    for (r, y) in rows.enumerate() {
        for x in 0..pw {
            let p = img.get_pixel(x.min(w - 1) as u32, y.min(h - 1) as u32).0;
            for c in 0..3 {
                data[c * plane + r * pw + x] = p[c] as f32 / 255.0;
            }
        }
    }
    data
}
