//! The tone ("gamma") curve: a piecewise-linear function on [0, 1] given by knots.
//!
//! CamPro (paper Eq. 2) fixes the knot inputs `x` (evenly spaced, 32 by default) and
//! learns the outputs `y` in [0, 1], which may go up and down. Inputs outside [0, 1]
//! are clamped, as every ISP LUT does.

use crate::error::{check_range, ValidationError};

/// Most knots a curve may have (a 12-bit LUT is the densest real ISP table).
pub const MAX_KNOTS: usize = 4096;

/// A validated piecewise-linear curve: `x` strictly increasing from 0 to 1,
/// `y` in [0, 1], at least 2 knots.
#[derive(Debug, Clone, PartialEq)]
pub struct ToneCurve {
    x: Vec<f64>,
    y: Vec<f64>,
    /// `x[i] == i / (k - 1)` (to within 1e-12): lets `eval` index instead of search.
    uniform: bool,
}

impl ToneCurve {
    /// Builds a curve from knots; errors name `x[i]` / `y[i]` and the rule broken.
    pub fn new(x: Vec<f64>, y: Vec<f64>) -> Result<Self, ValidationError> {
        if y.len() < 2 {
            return Err(ValidationError::WrongLength {
                field: "y".into(),
                expected: "at least 2".into(),
                got: y.len(),
            });
        }
        if y.len() > MAX_KNOTS {
            return Err(ValidationError::WrongLength {
                field: "y".into(),
                expected: format!("at most {MAX_KNOTS}"),
                got: y.len(),
            });
        }
        if x.len() != y.len() {
            return Err(ValidationError::WrongLength {
                field: "x".into(),
                expected: format!("{} (as many as y)", y.len()),
                got: x.len(),
            });
        }
        for (i, &v) in x.iter().enumerate() {
            check_range(|| format!("x[{i}]"), v, 0.0, 1.0)?;
        }
        for (i, &v) in y.iter().enumerate() {
            check_range(|| format!("y[{i}]"), v, 0.0, 1.0)?;
        }
        if x[0] != 0.0 {
            return Err(ValidationError::WrongEndpoint { field: "x[0]".into(), expected: 0.0, value: x[0] });
        }
        let last = x.len() - 1;
        if x[last] != 1.0 {
            return Err(ValidationError::WrongEndpoint { field: format!("x[{last}]"), expected: 1.0, value: x[last] });
        }
        for i in 1..x.len() {
            if x[i] <= x[i - 1] {
                return Err(ValidationError::NotIncreasing {
                    field: "x".into(),
                    index: i,
                    prev: x[i - 1],
                    value: x[i],
                });
            }
        }
        let n = (x.len() - 1) as f64;
        let uniform = x.iter().enumerate().all(|(i, &v)| (v - i as f64 / n).abs() <= 1e-12);
        Ok(Self { x, y, uniform })
    }

    /// Knots at evenly spaced inputs `i / (k - 1)`, as CamPro uses.
    pub fn uniform(y: Vec<f64>) -> Result<Self, ValidationError> {
        let n = y.len().max(2) - 1;
        let x = (0..y.len()).map(|i| i as f64 / n as f64).collect();
        Self::new(x, y)
    }

    /// The identity line with `k` evenly spaced knots (k >= 2).
    pub fn identity(k: usize) -> Self {
        let k = k.max(2);
        let x: Vec<f64> = (0..k).map(|i| i as f64 / (k - 1) as f64).collect();
        Self { y: x.clone(), x, uniform: true }
    }

    /// Samples `f` at `k` evenly spaced inputs (outputs clamped to [0, 1]; NaN becomes 0).
    pub fn from_fn(k: usize, f: impl Fn(f64) -> f64) -> Self {
        let mut c = Self::identity(k);
        for (y, &x) in c.y.iter_mut().zip(&c.x) {
            let v = f(x);
            *y = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        }
        c
    }

    /// Knot inputs, strictly increasing from 0 to 1.
    pub fn x(&self) -> &[f64] {
        &self.x
    }
    /// Knot outputs, each in [0, 1].
    pub fn y(&self) -> &[f64] {
        &self.y
    }
    /// Number of knots.
    pub fn len(&self) -> usize {
        self.x.len()
    }
    /// Never true: a curve has at least 2 knots.
    pub fn is_empty(&self) -> bool {
        false
    }
    /// Whether the knots are evenly spaced.
    pub fn is_uniform(&self) -> bool {
        self.uniform
    }

    /// Index `i` of the segment `[x[i], x[i+1]]` holding `t` (t in [0, 1]).
    #[inline]
    fn segment(&self, t: f64) -> usize {
        let last = self.x.len() - 2;
        if self.uniform {
            ((t * (last + 1) as f64) as usize).min(last)
        } else {
            self.x.partition_point(|&v| v <= t).saturating_sub(1).min(last)
        }
    }

    /// The curve at `t` (clamped to [0, 1] first), by linear interpolation, in f64.
    #[inline]
    pub fn eval(&self, t: f64) -> f64 {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let i = self.segment(t);
        let (x0, x1, y0, y1) = (self.x[i], self.x[i + 1], self.y[i], self.y[i + 1]);
        let a = (t - x0) / (x1 - x0);
        y0 + a * (y1 - y0)
    }

    /// Largest |slope| of any segment: the curve's Lipschitz constant, which bounds how
    /// much an input error grows in the output.
    pub fn max_slope(&self) -> f64 {
        self.x.windows(2).zip(self.y.windows(2)).map(|(x, y)| ((y[1] - y[0]) / (x[1] - x[0])).abs()).fold(0.0, f64::max)
    }

    /// Whether this is the identity line (every knot within `tol` of `y = x`).
    pub fn is_identity(&self, tol: f64) -> bool {
        self.x.iter().zip(&self.y).all(|(x, y)| (x - y).abs() <= tol)
    }

    /// `t -> self(min(1, s · t))` for a scale `s >= 1`: the curve that undoes a matrix
    /// divided by `s`, exactly (a knot at `x / s` for each knot, plus `(1, y_last)`).
    pub fn fold_scale(&self, s: f64) -> Self {
        assert!(s.is_finite() && s >= 1.0, "fold_scale needs a finite s >= 1, got {s}");
        if s == 1.0 {
            return self.clone();
        }
        let mut x: Vec<f64> = self.x.iter().map(|&v| v / s).collect();
        let mut y = self.y.clone();
        x.push(1.0);
        y.push(*self.y.last().unwrap());
        Self { x, y, uniform: false }
    }

    /// Exact `max_t |self(t) - other(t)|` over [0, 1]: both are piecewise linear, so
    /// the maximum sits at a knot of one of them.
    pub fn max_abs_diff(&self, other: &Self) -> f64 {
        self.x.iter().chain(other.x.iter()).map(|&t| (self.eval(t) - other.eval(t)).abs()).fold(0.0, f64::max)
    }

    /// `n` evenly spaced samples of the curve, as a fixed-grid LUT of `n` entries.
    pub fn resample_uniform(&self, n: usize) -> Self {
        Self::from_fn(n, |t| self.eval(t))
    }

    /// The best curve with at most `max_points` knots chosen among this curve's knots
    /// (endpoints kept, outputs unchanged), minimising the maximum error over [0, 1].
    /// Returns the curve and that error. Exact for up to [`SIMPLIFY_EXACT_MAX`] knots
    /// (dynamic programming over segments); beyond, a greedy pass for each tolerance
    /// of a bisection (not guaranteed optimal).
    pub fn simplify(&self, max_points: usize) -> (Self, f64) {
        let max_points = max_points.max(2);
        if max_points >= self.len() {
            return (self.clone(), 0.0);
        }
        if self.len() <= SIMPLIFY_EXACT_MAX {
            let err = self.segment_errors();
            let keep = min_max_path(&err, max_points);
            return self.subset(&keep, &err);
        }
        // Bisection on the tolerance with a greedy farthest-reach cover.
        let (mut lo, mut hi) = (0.0, 1.0);
        let mut best = self.greedy(hi);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            let k = self.greedy(mid);
            if k.len() <= max_points {
                hi = mid;
                best = k;
            } else {
                lo = mid;
            }
        }
        let c = self.pick(&best);
        let e = self.max_abs_diff(&c);
        (c, e)
    }

    /// The fewest knots (a subset of this curve's) keeping the maximum error at most
    /// `tol`; returns the curve and its actual error.
    pub fn simplify_within(&self, tol: f64) -> (Self, f64) {
        if self.len() <= SIMPLIFY_EXACT_MAX {
            let err = self.segment_errors();
            // Shortest path through edges whose error is within tol.
            let n = self.len();
            let mut count = vec![usize::MAX; n];
            let mut prev = vec![0usize; n];
            count[0] = 1;
            for j in 1..n {
                for i in 0..j {
                    if count[i] != usize::MAX && err[i][j] <= tol && count[i] + 1 < count[j] {
                        count[j] = count[i] + 1;
                        prev[j] = i;
                    }
                }
            }
            let mut keep = vec![n - 1];
            while *keep.last().unwrap() != 0 {
                keep.push(prev[*keep.last().unwrap()]);
            }
            keep.reverse();
            return self.subset(&keep, &err);
        }
        let keep = self.greedy(tol);
        let c = self.pick(&keep);
        let e = self.max_abs_diff(&c);
        (c, e)
    }

    fn pick(&self, keep: &[usize]) -> Self {
        let x = keep.iter().map(|&i| self.x[i]).collect();
        let y = keep.iter().map(|&i| self.y[i]).collect();
        Self::new(x, y).expect("a subset of valid knots with both ends is valid")
    }

    fn subset(&self, keep: &[usize], err: &[Vec<f64>]) -> (Self, f64) {
        let e = keep.windows(2).map(|w| err[w[0]][w[1]]).fold(0.0, f64::max);
        (self.pick(keep), e)
    }

    /// `err[i][j]`: max error of the chord from knot i to knot j over the knots between.
    fn segment_errors(&self) -> Vec<Vec<f64>> {
        let n = self.len();
        (0..n).map(|i| (0..n).map(|j| if j > i + 1 { self.chord_error(i, j) } else { 0.0 }).collect()).collect()
    }

    fn greedy(&self, tol: f64) -> Vec<usize> {
        let n = self.len();
        let mut keep = vec![0];
        let mut i = 0;
        while i < n - 1 {
            let mut j = i + 1;
            while j + 1 < n && self.chord_error(i, j + 1) <= tol {
                j += 1;
            }
            keep.push(j);
            i = j;
        }
        keep
    }

    fn chord_error(&self, i: usize, j: usize) -> f64 {
        let slope = (self.y[j] - self.y[i]) / (self.x[j] - self.x[i]);
        (i + 1..j).map(|k| (self.y[k] - (self.y[i] + slope * (self.x[k] - self.x[i]))).abs()).fold(0.0, f64::max)
    }
}

/// Output channels in the order of [`ToneCurves::channel`] and of Camera2's
/// `TonemapCurve` (`CHANNEL_RED`, `CHANNEL_GREEN`, `CHANNEL_BLUE`).
pub const CHANNELS: [&str; 3] = ["red", "green", "blue"];

/// The tone curves of a camera: one curve for the three channels (the paper's camera, a
/// version 1 parameter file) or one per channel (Camera2's `TONEMAP_CURVE` takes three; a
/// non-linear colour transform at no cost on the phone). Three equal curves are the shared
/// case: [`ToneCurves::per_channel`] folds them, so a set is written as before.
#[derive(Debug, Clone, PartialEq)]
pub enum ToneCurves {
    /// One curve for red, green and blue.
    Shared(ToneCurve),
    /// Red, green, blue; at least two differ.
    PerChannel(Box<[ToneCurve; 3]>),
}

impl ToneCurves {
    /// Three curves (red, green, blue); [`ToneCurves::Shared`] when all are equal.
    pub fn per_channel(curves: [ToneCurve; 3]) -> Self {
        if curves[0] == curves[1] && curves[1] == curves[2] {
            let [r, _, _] = curves;
            Self::Shared(r)
        } else {
            Self::PerChannel(Box::new(curves))
        }
    }

    /// The curve of output channel `c` (0 red, 1 green, 2 blue).
    #[inline]
    pub fn channel(&self, c: usize) -> &ToneCurve {
        match self {
            Self::Shared(t) => t,
            Self::PerChannel(t) => &t[c],
        }
    }

    /// The three curves, red first.
    pub fn each(&self) -> [&ToneCurve; 3] {
        [0, 1, 2].map(|c| self.channel(c))
    }

    /// The one curve of a shared set; `None` when the channels differ.
    pub fn shared(&self) -> Option<&ToneCurve> {
        match self {
            Self::Shared(t) => Some(t),
            Self::PerChannel(_) => None,
        }
    }

    /// Each curve mapped by `f`, staying shared when shared.
    pub fn map(&self, f: impl Fn(&ToneCurve) -> ToneCurve) -> Self {
        match self {
            Self::Shared(t) => Self::Shared(f(t)),
            Self::PerChannel(t) => Self::per_channel([f(&t[0]), f(&t[1]), f(&t[2])]),
        }
    }

    /// The largest knot count of the three.
    pub fn knots(&self) -> usize {
        self.each().iter().map(|t| t.len()).max().unwrap_or(0)
    }

    /// Whether every curve's knots are evenly spaced.
    pub fn is_uniform(&self) -> bool {
        self.each().iter().all(|t| t.is_uniform())
    }

    /// The largest slope of the three ([`ToneCurve::max_slope`]).
    pub fn max_slope(&self) -> f64 {
        self.each().iter().map(|t| t.max_slope()).fold(0.0, f64::max)
    }

    /// Whether every curve is the identity line within `tol`.
    pub fn is_identity(&self, tol: f64) -> bool {
        self.each().iter().all(|t| t.is_identity(tol))
    }

    /// The largest [`ToneCurve::max_abs_diff`] between corresponding curves.
    pub fn max_abs_diff(&self, other: &Self) -> f64 {
        (0..3).map(|c| self.channel(c).max_abs_diff(other.channel(c))).fold(0.0, f64::max)
    }
}

impl From<ToneCurve> for ToneCurves {
    fn from(t: ToneCurve) -> Self {
        Self::Shared(t)
    }
}

/// Up to this many knots `simplify` is exactly optimal (O(n^3) time).
pub const SIMPLIFY_EXACT_MAX: usize = 600;

/// Knot indices of the path 0 -> n-1 with at most `m` nodes minimising the largest edge cost.
fn min_max_path(err: &[Vec<f64>], m: usize) -> Vec<usize> {
    let n = err.len();
    // best[c][j]: min over paths 0..j using c+1 nodes of the max edge cost.
    let mut best = vec![vec![f64::INFINITY; n]; m];
    let mut prev = vec![vec![0usize; n]; m];
    best[0][0] = 0.0;
    for c in 1..m {
        for j in 1..n {
            for i in 0..j {
                let v = best[c - 1][i].max(err[i][j]);
                if v < best[c][j] {
                    best[c][j] = v;
                    prev[c][j] = i;
                }
            }
        }
    }
    let c_best = (1..m).min_by(|&a, &b| best[a][n - 1].total_cmp(&best[b][n - 1]).then(a.cmp(&b))).unwrap();
    let mut keep = vec![n - 1];
    let (mut c, mut j) = (c_best, n - 1);
    while c > 0 {
        j = prev[c][j];
        keep.push(j);
        c -= 1;
    }
    keep.reverse();
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eval_interpolates_linearly_and_clamps() {
        let c = ToneCurve::uniform(vec![0.0, 1.0, 0.5]).unwrap();
        assert_eq!(c.eval(0.25), 0.5);
        assert_eq!(c.eval(0.5), 1.0);
        assert_eq!(c.eval(0.75), 0.75);
        assert_eq!(c.eval(-3.0), 0.0);
        assert_eq!(c.eval(7.0), 0.5);
        let nu = ToneCurve::new(vec![0.0, 0.1, 1.0], vec![0.0, 0.9, 1.0]).unwrap();
        assert!(!nu.is_uniform());
        assert!((nu.eval(0.05) - 0.45).abs() < 1e-15);
        assert!((nu.eval(0.55) - 0.95).abs() < 1e-15);
    }

    #[test]
    fn validation_names_the_rule() {
        assert!(matches!(ToneCurve::uniform(vec![0.5]), Err(ValidationError::WrongLength { .. })));
        assert!(matches!(
            ToneCurve::new(vec![0.0, 0.5, 0.5, 1.0], vec![0.0; 4]),
            Err(ValidationError::NotIncreasing { index: 2, .. })
        ));
        assert!(matches!(ToneCurve::new(vec![0.1, 1.0], vec![0.0; 2]), Err(ValidationError::WrongEndpoint { .. })));
        assert!(matches!(ToneCurve::new(vec![0.0, 0.9], vec![0.0; 2]), Err(ValidationError::WrongEndpoint { .. })));
        let e = ToneCurve::uniform(vec![0.0, 1.2]).unwrap_err();
        assert_eq!(e.field(), "y[1]");
        let e = ToneCurve::uniform(vec![0.0, f64::NAN]).unwrap_err();
        assert!(matches!(e, ValidationError::NonFinite { .. }));
    }

    #[test]
    fn fold_scale_is_exact() {
        let c = ToneCurve::uniform(vec![0.2, 0.9, 0.1, 0.6, 0.3]).unwrap();
        let s = 2.5;
        let f = c.fold_scale(s);
        for i in 0..=1000 {
            let t = i as f64 / 1000.0;
            assert!((f.eval(t) - c.eval((s * t).min(1.0))).abs() < 1e-15, "t={t}");
        }
    }

    #[test]
    fn simplify_drops_collinear_knots_exactly() {
        // A polyline with 3 real corners sampled at 33 knots: 4 points represent it exactly.
        let f = |t: f64| {
            if t < 0.25 {
                2.0 * t
            } else if t < 0.75 {
                0.5 + (0.25 - t)
            } else {
                t - 0.75
            }
        };
        let c = ToneCurve::from_fn(33, f);
        let (s, e) = c.simplify(4);
        assert_eq!(s.len(), 4);
        assert!(e < 1e-12, "{e}");
        assert!(c.max_abs_diff(&s) < 1e-12);
        let (s3, e3) = c.simplify(3);
        assert!(e3 > 0.1 && (c.max_abs_diff(&s3) - e3).abs() < 1e-12);
    }

    #[test]
    fn simplify_is_optimal_on_a_small_case_by_brute_force() {
        let c = ToneCurve::uniform(vec![0.0, 0.8, 0.1, 0.7, 0.3, 0.9, 0.2, 1.0]).unwrap();
        for m in 2..8 {
            let (_, e) = c.simplify(m);
            // Enumerate every subset of interior knots of size at most m-2.
            let mut best = f64::INFINITY;
            for mask in 0u32..(1 << 6) {
                if mask.count_ones() as usize > m - 2 {
                    continue;
                }
                let mut keep = vec![0];
                keep.extend((1..7).filter(|i| mask & (1 << (i - 1)) != 0));
                keep.push(7);
                best = best.min(c.max_abs_diff(&c.pick(&keep)));
            }
            assert!((e - best).abs() < 1e-12, "m={m}: {e} vs {best}");
        }
    }

    #[test]
    fn simplify_within_uses_fewest_points() {
        let c = ToneCurve::from_fn(64, |t| t.powf(1.0 / 2.2));
        let (s, e) = c.simplify_within(1e-3);
        assert!(e <= 1e-3);
        let (_, e_fewer) = c.simplify(s.len() - 1);
        assert!(e_fewer > 1e-3, "one point fewer should break the tolerance");
    }
}
