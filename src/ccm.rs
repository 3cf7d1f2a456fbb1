//! 3x3 colour correction matrices.
//!
//! Convention (the paper's Eq. 1): row-major, acting on column vectors,
//! `out = CCM · in`, so `m[i][j]` is the weight of input channel `j` in output
//! channel `i`. Composing "first `a`, then `b`" is therefore `mul(b, a)`.

/// A 3x3 matrix, row-major: `m[row][col]`.
pub type Mat3 = [[f64; 3]; 3];

/// Largest |entry| accepted anywhere a matrix is read (parameter sets, device
/// transforms, calibrations). CamPro clamps to ±5 while training; no ISP register holds
/// more than ±8. Larger values are a sign of a broken file.
pub const CCM_LIMIT: f64 = 32.0;

/// The identity matrix.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Matrix product `a · b` (apply `b` first, then `a`).
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    out
}

/// `m · v` for a column vector `v`.
#[inline]
pub fn apply(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// Every entry multiplied by `k`.
pub fn scale(m: &Mat3, k: f64) -> Mat3 {
    m.map(|row| row.map(|v| v * k))
}

/// `(1 - t) · a + t · b`, entrywise.
pub fn lerp(a: &Mat3, b: &Mat3, t: f64) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = (1.0 - t) * a[i][j] + t * b[i][j];
        }
    }
    out
}

/// Determinant.
pub fn det(m: &Mat3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Inverse by the adjugate; `None` when the matrix is singular or so close to it
/// that the inverse is meaningless (|det| below 1e-12 times the product of row norms).
pub fn inverse(m: &Mat3) -> Option<Mat3> {
    let d = det(m);
    let scale: f64 = m.iter().map(|r| r.iter().map(|v| v * v).sum::<f64>().sqrt()).product();
    if !d.is_finite() || scale == 0.0 || d.abs() <= 1e-12 * scale {
        return None;
    }
    let c = |r0: usize, c0: usize, r1: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [c(1, 1, 2, 2), -c(0, 1, 2, 2), c(0, 1, 1, 2)],
        [-c(1, 0, 2, 2), c(0, 0, 2, 2), -c(0, 0, 1, 2)],
        [c(1, 0, 2, 1), -c(0, 0, 2, 1), c(0, 0, 1, 1)],
    ];
    Some(scale_inv(&adj, d))
}

fn scale_inv(m: &Mat3, d: f64) -> Mat3 {
    m.map(|row| row.map(|v| v / d))
}

/// Largest row sum of absolute values (the infinity norm): the most any output
/// channel can move when every input moves by at most 1.
pub fn norm_inf(m: &Mat3) -> f64 {
    m.iter().map(|r| r.iter().map(|v| v.abs()).sum::<f64>()).fold(0.0, f64::max)
}

/// Smallest and largest entry.
pub fn min_max(m: &Mat3) -> (f64, f64) {
    m.iter().flatten().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)))
}

/// True when every entry is finite.
pub fn is_finite(m: &Mat3) -> bool {
    m.iter().flatten().all(|v| v.is_finite())
}

/// Largest entrywise difference `max |a - b|`.
pub fn max_abs_diff(a: &Mat3, b: &Mat3) -> f64 {
    let mut d: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            d = d.max((a[i][j] - b[i][j]).abs());
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn product_order_is_column_vector_convention() {
        // a swaps R and G; b doubles R. "b then a" = mul(a, b): R_in ends up doubled in G.
        let a = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let b = [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert_eq!(apply(&mul(&a, &b), [1.0, 0.0, 0.0]), [0.0, 2.0, 0.0]);
        assert_eq!(apply(&a, apply(&b, [0.3, 0.5, 0.7])), apply(&mul(&a, &b), [0.3, 0.5, 0.7]));
    }

    #[test]
    fn inverse_of_hand_computed_matrix() {
        // det = 2*(3*1-0) - 0 + 1*(0-3*1)... use a matrix with a known inverse.
        let m = [[2.0, 0.0, 0.0], [0.0, 4.0, 0.0], [1.0, 0.0, 1.0]];
        let inv = inverse(&m).unwrap();
        let want = [[0.5, 0.0, 0.0], [0.0, 0.25, 0.0], [-0.5, 0.0, 1.0]];
        assert!(max_abs_diff(&inv, &want) < 1e-15);
        assert!(max_abs_diff(&mul(&m, &inv), &IDENTITY) < 1e-15);
        assert_eq!(det(&m), 8.0);
    }

    #[test]
    fn singular_matrix_has_no_inverse() {
        let m = [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]];
        assert!(inverse(&m).is_none());
        assert!(inverse(&[[0.0; 3]; 3]).is_none());
    }
}
