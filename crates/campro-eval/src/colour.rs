//! Colour difference as people see it: 8-bit sRGB to CIELAB (D65) and CIEDE2000 (Sharma,
//! Wu and Dalal 2005), for the enhanced view's colour fidelity. A ΔE00 of about 1 is the
//! smallest difference an observer notices side by side; 2 to 3 is seen at a glance.

use image::RgbImage;

/// CIELAB (L* 0..100, a*, b*) of an 8-bit sRGB colour: the sRGB transfer curve undone, the
/// BT.709 primaries to XYZ, D65 white (0.95047, 1, 1.08883).
pub fn lab([r, g, b]: [u8; 3]) -> [f64; 3] {
    let lin = |c: u8| {
        let c = f64::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let (r, g, b) = (lin(r), lin(g), lin(b));
    let x = (0.4124564 * r + 0.3575761 * g + 0.1804375 * b) / 0.95047;
    let y = 0.2126729 * r + 0.7151522 * g + 0.0721750 * b;
    let z = (0.0193339 * r + 0.1191920 * g + 0.9503041 * b) / 1.08883;
    let f = |t: f64| {
        const D: f64 = 6.0 / 29.0;
        if t > D * D * D {
            t.cbrt()
        } else {
            t / (3.0 * D * D) + 4.0 / 29.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIEDE2000 colour difference of two CIELAB colours (kL = kC = kH = 1), as Sharma et al.
/// state it (hue mean and difference taken the short way round; 0 hue where chroma is 0).
pub fn ciede2000(l1: [f64; 3], l2: [f64; 3]) -> f64 {
    let ([lp1, a1, b1], [lp2, a2, b2]) = (l1, l2);
    let pow7 = |v: f64| v.powi(7);
    let c_bar = ((a1 * a1 + b1 * b1).sqrt() + (a2 * a2 + b2 * b2).sqrt()) / 2.0;
    let g = 0.5 * (1.0 - (pow7(c_bar) / (pow7(c_bar) + pow7(25.0))).sqrt());
    let (ap1, ap2) = ((1.0 + g) * a1, (1.0 + g) * a2);
    let (cp1, cp2) = ((ap1 * ap1 + b1 * b1).sqrt(), (ap2 * ap2 + b2 * b2).sqrt());
    let hue = |b: f64, a: f64| if b == 0.0 && a == 0.0 { 0.0 } else { b.atan2(a).to_degrees().rem_euclid(360.0) };
    let (hp1, hp2) = (hue(b1, ap1), hue(b2, ap2));
    let dl = lp2 - lp1;
    let dc = cp2 - cp1;
    let chroma0 = cp1 * cp2 == 0.0;
    let dh = if chroma0 {
        0.0
    } else {
        let d = hp2 - hp1;
        if d.abs() <= 180.0 {
            d
        } else if d > 180.0 {
            d - 360.0
        } else {
            d + 360.0
        }
    };
    let dhh = 2.0 * (cp1 * cp2).sqrt() * (dh.to_radians() / 2.0).sin();
    let l_bar = (lp1 + lp2) / 2.0;
    let cp_bar = (cp1 + cp2) / 2.0;
    let hp_bar = if chroma0 {
        hp1 + hp2
    } else if (hp1 - hp2).abs() <= 180.0 {
        (hp1 + hp2) / 2.0
    } else if hp1 + hp2 < 360.0 {
        (hp1 + hp2 + 360.0) / 2.0
    } else {
        (hp1 + hp2 - 360.0) / 2.0
    };
    let cos = |deg: f64| deg.to_radians().cos();
    let t = 1.0 - 0.17 * cos(hp_bar - 30.0) + 0.24 * cos(2.0 * hp_bar) + 0.32 * cos(3.0 * hp_bar + 6.0)
        - 0.20 * cos(4.0 * hp_bar - 63.0);
    let d_theta = 30.0 * (-((hp_bar - 275.0) / 25.0).powi(2)).exp();
    let rc = 2.0 * (pow7(cp_bar) / (pow7(cp_bar) + pow7(25.0))).sqrt();
    let sl = 1.0 + 0.015 * (l_bar - 50.0).powi(2) / (20.0 + (l_bar - 50.0).powi(2)).sqrt();
    let sc = 1.0 + 0.045 * cp_bar;
    let sh = 1.0 + 0.015 * cp_bar * t;
    let rt = -(2.0 * d_theta).to_radians().sin() * rc;
    let (l, c, h) = (dl / sl, dc / sc, dhh / sh);
    (l * l + c * c + h * h + rt * c * h).max(0.0).sqrt()
}

/// ΔE00 between two 8-bit sRGB colours.
pub fn delta_e(a: [u8; 3], b: [u8; 3]) -> f64 {
    ciede2000(lab(a), lab(b))
}

/// What [`compare`] finds between two images of one size, over the pixels it counts.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Fidelity {
    /// Mean ΔE00.
    pub mean: f64,
    /// 95th percentile ΔE00 (a 0.25-wide histogram's).
    pub p95: f64,
    /// Share of the pixels counted whose ΔE00 is above 5 (a different colour to anyone).
    pub over5: f64,
    /// Pixels counted.
    pub pixels: usize,
}

/// ΔE00 of `b` against `a` (same size) over the pixels `counted` says, read at an even
/// stride of at most `1 << 18` pixels (a sample: its mean's standard error is well under
/// 0.01 at this size). None when no pixel counts.
pub fn compare(a: &RgbImage, b: &RgbImage, counted: impl Fn(u32, u32) -> bool) -> Option<Fidelity> {
    assert_eq!(a.dimensions(), b.dimensions(), "images of one size");
    let (w, h) = a.dimensions();
    let n = w as usize * h as usize;
    let stride = n.div_ceil(1 << 18).max(1);
    const BIN: f64 = 0.25;
    let mut hist = vec![0u64; 401];
    let (mut sum, mut count, mut over) = (0f64, 0usize, 0usize);
    for i in (0..n).step_by(stride) {
        let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
        if !counted(x, y) {
            continue;
        }
        let d = delta_e(a.get_pixel(x, y).0, b.get_pixel(x, y).0);
        sum += d;
        count += 1;
        over += usize::from(d > 5.0);
        hist[((d / BIN) as usize).min(400)] += 1;
    }
    if count == 0 {
        return None;
    }
    let want = (0.95 * count as f64).ceil() as u64;
    let mut seen = 0;
    let bin = hist.iter().position(|&k| {
        seen += k;
        seen >= want
    })?;
    Some(Fidelity {
        mean: sum / count as f64,
        p95: (bin + 1) as f64 * BIN,
        over5: over as f64 / count as f64,
        pixels: count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sharmas_test_pairs() {
        // Sharma, Wu and Dalal (2005), Table 1: pairs 1, 2, 3, 7, 17, 19, 25 and 34.
        let pairs = [
            ([50.0, 2.6772, -79.7751], [50.0, 0.0, -82.7485], 2.0425),
            ([50.0, 3.1571, -77.2803], [50.0, 0.0, -82.7485], 2.8615),
            ([50.0, 2.8361, -74.0200], [50.0, 0.0, -82.7485], 3.4412),
            ([50.0, 0.0, 0.0], [50.0, -1.0, 2.0], 2.3669),
            ([50.0, 2.5, 0.0], [73.0, 25.0, -18.0], 27.1492),
            ([50.0, 2.5, 0.0], [50.0, 3.1736, 0.5854], 1.0000),
            ([60.2574, -34.0099, 36.2677], [60.4626, -34.1751, 39.4387], 1.2644),
            ([2.0776, 0.0795, -1.1350], [0.9033, -0.0636, -0.5514], 0.9082),
        ];
        for (a, b, want) in pairs {
            let got = ciede2000(a, b);
            assert!((got - want).abs() < 5e-5, "{a:?} {b:?}: {got} against {want}");
            // Symmetric.
            assert!((ciede2000(b, a) - got).abs() < 1e-9);
        }
    }

    #[test]
    fn srgb_primaries_and_white_in_lab() {
        // White is L* 100 with no colour; sRGB red is (53.24, 80.09, 67.20) in every table.
        let w = lab([255, 255, 255]);
        assert!((w[0] - 100.0).abs() < 1e-3 && w[1].abs() < 1e-2 && w[2].abs() < 1e-2, "{w:?}");
        let r = lab([255, 0, 0]);
        assert!((r[0] - 53.24).abs() < 0.01 && (r[1] - 80.09).abs() < 0.01 && (r[2] - 67.20).abs() < 0.01, "{r:?}");
        assert_eq!(lab([0, 0, 0]), [0.0, 0.0, 0.0]);
    }

    #[test]
    fn compare_counts_only_what_it_is_told() {
        let a = RgbImage::from_pixel(4, 2, image::Rgb([120, 120, 120]));
        let mut b = a.clone();
        b.put_pixel(0, 0, image::Rgb([255, 0, 0]));
        let all = compare(&a, &b, |_, _| true).unwrap();
        assert_eq!((all.pixels, all.over5), (8, 1.0 / 8.0));
        assert!((all.mean - delta_e([120; 3], [255, 0, 0]) / 8.0).abs() < 1e-12);
        let without = compare(&a, &b, |x, y| (x, y) != (0, 0)).unwrap();
        assert_eq!((without.mean, without.p95, without.over5), (0.0, 0.25, 0.0));
        assert!(compare(&a, &b, |_, _| false).is_none());
    }
}
