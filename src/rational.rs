//! Rational approximation of matrix entries, as Camera2's `Rational` (i32 / i32) needs.
//!
//! - [`best`]: the closest `p/q` with `1 <= q <= max_den` (continued fractions with
//!   semiconvergents). Its error is at most `1 / (2 · max_den)` and usually far less.
//! - [`fixed`]: `round(x · den) / den`, like a fixed-point ISP register (error at most
//!   `1 / (2 · den)`).

/// A rational number `num / den` with `den > 0`, both fitting in i32.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rational {
    /// Numerator.
    pub num: i32,
    /// Denominator (> 0).
    pub den: i32,
}

impl Rational {
    /// The value as f64.
    pub fn to_f64(self) -> f64 {
        self.num as f64 / self.den as f64
    }
}

/// Why a value has no rational approximation within i32.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RationalError {
    /// The value is NaN or infinite.
    #[error("value {0} is not finite")]
    NonFinite(f64),
    /// The denominator (bound) is 0 or does not fit an `i32`.
    #[error("denominator bound must be in [1, {max}], got {got}", max = i32::MAX)]
    BadDenominator {
        /// The denominator given.
        got: u64,
    },
    /// The numerator would not fit an `i32`.
    #[error("value {value} times denominator {den} overflows a 32-bit numerator")]
    Overflow {
        /// The value.
        value: f64,
        /// The denominator.
        den: u64,
    },
}

fn check(x: f64, den: u64) -> Result<(), RationalError> {
    if !x.is_finite() {
        return Err(RationalError::NonFinite(x));
    }
    if den == 0 || den > i32::MAX as u64 {
        return Err(RationalError::BadDenominator { got: den });
    }
    if (x.abs() * den as f64).round() > i32::MAX as f64 {
        return Err(RationalError::Overflow { value: x, den });
    }
    Ok(())
}

/// `round(x · den) / den`.
pub fn fixed(x: f64, den: u64) -> Result<Rational, RationalError> {
    check(x, den)?;
    Ok(Rational { num: (x * den as f64).round() as i32, den: den as i32 })
}

/// The best rational approximation of `x` with denominator at most `max_den`.
pub fn best(x: f64, max_den: u64) -> Result<Rational, RationalError> {
    check(x, max_den)?;
    let neg = x < 0.0;
    let y0 = x.abs();
    // Convergents h/k; (h_prev, k_prev) = (0, 1) and (h, k) = (1, 0) to start.
    let (mut h_prev, mut k_prev, mut h, mut k): (u64, u64, u64, u64) = (0, 1, 1, 0);
    let mut y = y0;
    let mut best = (y0.round() as u64, 1u64);
    for _ in 0..64 {
        let a = y.floor();
        if a > 4e18 {
            break;
        }
        let a = a as u64;
        let k_next = a.saturating_mul(k).saturating_add(k_prev);
        if k_next > max_den {
            // Largest semiconvergent that still fits, then keep whichever is closer.
            if let Some(t) = (max_den - k_prev).checked_div(k) {
                let semi = (t * h + h_prev, t * k + k_prev);
                best = closer(y0, best, (h, k));
                best = closer(y0, best, semi);
            }
            break;
        }
        let h_next = a.saturating_mul(h).saturating_add(h_prev);
        (h_prev, k_prev, h, k) = (h, k, h_next, k_next);
        best = closer(y0, best, (h, k));
        let frac = y - a as f64;
        if frac <= 0.0 || (h as f64 / k as f64 - y0).abs() == 0.0 {
            break;
        }
        y = 1.0 / frac;
    }
    // Never worse than the fixed grid at max_den (guards float error in the expansion).
    best = closer(y0, best, ((y0 * max_den as f64).round() as u64, max_den));
    let (p, q) = reduce(best.0, best.1);
    Ok(Rational { num: if neg { -(p as i64) } else { p as i64 } as i32, den: q as i32 })
}

fn closer(x: f64, a: (u64, u64), b: (u64, u64)) -> (u64, u64) {
    if b.1 == 0 {
        return a;
    }
    let ea = (x - a.0 as f64 / a.1 as f64).abs();
    let eb = (x - b.0 as f64 / b.1 as f64).abs();
    if eb < ea || (eb == ea && b.1 < a.1) {
        b
    } else {
        a
    }
}

fn reduce(p: u64, q: u64) -> (u64, u64) {
    let (mut a, mut b) = (p, q);
    while b != 0 {
        (a, b) = (b, a % b);
    }
    if a <= 1 {
        (p, q)
    } else {
        (p / a, q / a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_approximations() {
        assert_eq!(best(std::f64::consts::PI, 7).unwrap(), Rational { num: 22, den: 7 });
        assert_eq!(best(std::f64::consts::PI, 113).unwrap(), Rational { num: 355, den: 113 });
        // 1/3 is found exactly; -0.75 = -3/4.
        assert_eq!(best(1.0 / 3.0, 1000).unwrap(), Rational { num: 1, den: 3 });
        assert_eq!(best(-0.75, 1000).unwrap(), Rational { num: -3, den: 4 });
        assert_eq!(best(0.0, 10).unwrap(), Rational { num: 0, den: 1 });
        assert_eq!(fixed(0.3, 1024).unwrap(), Rational { num: 307, den: 1024 });
    }

    #[test]
    fn best_equals_brute_force() {
        let mut s = 12345u64;
        for _ in 0..2000 {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let x = ((s >> 11) as f64 / (1u64 << 53) as f64) * 9.0 - 4.5;
            let d = 1 + (s % 300);
            let r = best(x, d).unwrap();
            let e = (x - r.to_f64()).abs();
            let brute = (1..=d).map(|q| (x - (x * q as f64).round() / q as f64).abs()).fold(f64::INFINITY, f64::min);
            assert!(e <= brute + 1e-15, "x={x} d={d}: {r:?} err {e} vs {brute}");
            assert!(e <= 0.5 / d as f64 + 1e-15);
        }
    }

    #[test]
    fn rejects_what_does_not_fit() {
        assert!(matches!(best(f64::NAN, 10), Err(RationalError::NonFinite(_))));
        assert!(matches!(best(1.0, 0), Err(RationalError::BadDenominator { .. })));
        assert!(matches!(fixed(3.0, 1 << 30), Err(RationalError::Overflow { .. })));
        assert!(best(1e12, 10).is_err());
    }
}
