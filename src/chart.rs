//! A built-in test chart, generated in code: the 24 ColorChecker patches (their
//! published sRGB values) above grey, red, green and blue ramps over every 8-bit code.

/// ColorChecker Classic patches, 8-bit sRGB, row by row (dark skin ... black).
pub const COLORCHECKER_SRGB8: [[u8; 3]; 24] = [
    [115, 82, 68],
    [194, 150, 130],
    [98, 122, 157],
    [87, 108, 67],
    [133, 128, 177],
    [103, 189, 170],
    [214, 126, 44],
    [80, 91, 166],
    [193, 90, 99],
    [94, 60, 108],
    [157, 188, 64],
    [224, 163, 46],
    [56, 61, 150],
    [70, 148, 73],
    [175, 54, 60],
    [231, 199, 31],
    [187, 86, 149],
    [8, 133, 161],
    [243, 243, 242],
    [200, 200, 200],
    [160, 160, 160],
    [122, 122, 121],
    [85, 85, 85],
    [52, 52, 52],
];

/// Chart width in pixels (6 patches of 64, and 1.5 pixels per ramp code).
pub const WIDTH: u32 = 384;
const PATCH: u32 = 64;
const RAMP_H: u32 = 24;
/// Chart height in pixels (4 rows of patches, 4 ramps).
pub const HEIGHT: u32 = 4 * PATCH + 4 * RAMP_H;

/// The chart as interleaved 8-bit RGB, `WIDTH x HEIGHT`.
pub fn render() -> Vec<u8> {
    let mut img = Vec::with_capacity((WIDTH * HEIGHT * 3) as usize);
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let px = if y < 4 * PATCH {
                let (r, c) = (y / PATCH, x / PATCH);
                // A 4-pixel black border around each patch.
                let (u, v) = (x % PATCH, y % PATCH);
                if u < 4 || v < 4 || u >= PATCH - 4 || v >= PATCH - 4 {
                    [0, 0, 0]
                } else {
                    COLORCHECKER_SRGB8[(r * 6 + c) as usize]
                }
            } else {
                let ramp = (y - 4 * PATCH) / RAMP_H;
                let code = ((x as u64 * 255 + (WIDTH as u64 - 1) / 2) / (WIDTH as u64 - 1)) as u8;
                match ramp {
                    0 => [code; 3],
                    1 => [code, 0, 0],
                    2 => [0, code, 0],
                    _ => [0, 0, code],
                }
            };
            img.extend_from_slice(&px);
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chart_has_patches_and_full_ramps() {
        let img = render();
        assert_eq!(img.len(), (WIDTH * HEIGHT * 3) as usize);
        let at = |x: u32, y: u32| {
            let i = ((y * WIDTH + x) * 3) as usize;
            [img[i], img[i + 1], img[i + 2]]
        };
        assert_eq!(at(32, 32), [115, 82, 68]);
        assert_eq!(at(5 * 64 + 32, 3 * 64 + 32), [52, 52, 52]);
        let grey_row = 4 * 64 + 5;
        assert_eq!(at(0, grey_row), [0, 0, 0]);
        assert_eq!(at(WIDTH - 1, grey_row), [255, 255, 255]);
        let codes: std::collections::BTreeSet<u8> = (0..WIDTH).map(|x| at(x, grey_row)[0]).collect();
        assert_eq!(codes.len(), 256, "every 8-bit code appears in the ramp");
    }
}
