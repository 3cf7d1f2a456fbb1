//! The privacy-utility frontier across training runs (the paper's Figure 10): each parameter
//! set a point, privacy against the strongest attack measured on x, the person AP its own
//! detector keeps on y, and which points no other point beats on both.
//!
//! The points come from a small CSV of numbers read off the evaluation reports (privacy and
//! utility are measured by different commands, on different days, with detectors that are
//! not committed), one row per set:
//!
//! ```text
//! set,hours,top1,top1_attacked,ap_ratio
//! campro-omega-0.5,1.9,0.81,3.06,63
//! ```
//!
//! `top1`: the worst top-1 % over the face models and classifiers as captured;
//! `top1_attacked`: the same, worst over every attack measured as well (restoration,
//! re-enrolment, ...); `ap_ratio`: person AP as % of raw; `hours`: the run's training time
//! (empty for a fixed transform). Lines starting with `#` are comments.

use crate::plot::{chart, Series, Style};
use crate::table::{Column, Table};
use crate::{EvalError, Result};

/// At most this many points (a frontier of runs, not a dataset).
pub const MAX_POINTS: usize = 200;
/// The CSV's header, exactly.
pub const HEADER: &str = "set,hours,top1,top1_attacked,ap_ratio";

/// One parameter set's measured point.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub set: String,
    /// Training time in hours (None: not trained).
    pub hours: Option<f64>,
    /// Worst top-1 % as captured, in [0, 100].
    pub top1: f64,
    /// Worst top-1 % over every attack measured, in [0, 100].
    pub top1_attacked: f64,
    /// Person AP as % of raw, in [0, 200].
    pub ap_ratio: f64,
}

/// Parses the CSV; errors name the line and the field.
pub fn parse(csv: &str) -> Result<Vec<Point>> {
    let bad = |line: usize, m: String| EvalError::Invalid(format!("frontier points, line {line}: {m}"));
    let mut lines = csv.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.starts_with('#'));
    match lines.next() {
        Some((_, h)) if h == HEADER => {}
        Some((n, h)) => {
            return Err(bad(
                n,
                format!("the header must be `{HEADER}`, not `{}`", h.chars().take(80).collect::<String>()),
            ))
        }
        None => return Err(bad(0, "empty: a header and at least one point".into())),
    }
    let mut points = Vec::new();
    for (n, line) in lines.filter(|(_, l)| !l.is_empty()) {
        if points.len() == MAX_POINTS {
            return Err(bad(n, format!("more than {MAX_POINTS} points")));
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 5 {
            return Err(bad(n, format!("{} fields, expected 5 ({HEADER})", f.len())));
        }
        let set = f[0];
        if set.is_empty() || set.len() > 100 || set.chars().any(|c| c.is_control()) {
            return Err(bad(n, "set: 1 to 100 characters, no control characters".into()));
        }
        let num = |k: usize, name: &str, hi: f64| -> Result<f64> {
            match f[k].parse::<f64>() {
                Ok(v) if v.is_finite() && (0.0..=hi).contains(&v) => Ok(v),
                _ => Err(bad(n, format!("{name} must be a number in [0, {hi}], not `{}`", f[k]))),
            }
        };
        let hours = if f[1].is_empty() { None } else { Some(num(1, "hours", 1e4)?) };
        let (top1, top1_attacked, ap_ratio) =
            (num(2, "top1", 100.0)?, num(3, "top1_attacked", 100.0)?, num(4, "ap_ratio", 200.0)?);
        if top1_attacked < top1 {
            return Err(bad(n, "top1_attacked is the worst over the attacks and captured, so at least top1".into()));
        }
        points.push(Point { set: set.to_string(), hours, top1, top1_attacked, ap_ratio });
    }
    if points.is_empty() {
        return Err(bad(0, "no points".into()));
    }
    Ok(points)
}

/// Whether each point is on the frontier: no other point is at least as private (lower
/// `top1_attacked`) and at least as useful (higher `ap_ratio`), and better on one.
pub fn on_frontier(points: &[Point]) -> Vec<bool> {
    points
        .iter()
        .map(|p| {
            !points.iter().any(|q| {
                q.top1_attacked <= p.top1_attacked
                    && q.ap_ratio >= p.ap_ratio
                    && (q.top1_attacked < p.top1_attacked || q.ap_ratio > p.ap_ratio)
            })
        })
        .collect()
}

/// The plot (SVG) and the table of `points`.
pub fn render(points: &[Point]) -> (String, Table) {
    let front = on_frontier(points);
    let label = |p: &Point| match p.hours {
        Some(h) => format!("{} ({h:.1} h)", p.set),
        None => p.set.clone(),
    };
    let series: Vec<Series> =
        points.iter().map(|p| Series { name: label(p), points: vec![(p.top1_attacked, p.ap_ratio)] }).collect();
    let svg = chart(
        "Privacy vs utility across runs (cf. the paper's Figure 10)",
        "worst top-1 (%) over models, classifiers and attacks; lower = more private",
        "person AP, % of raw (own detector)",
        &series,
        Style::Points,
        None,
        None,
    );
    let mut t = Table::new([
        Column::new("set", "set", 0),
        Column::new("training time", "training_time", 0),
        Column::new("worst top-1 %, captured", "top1", 2),
        Column::new("worst top-1 %, attacked", "top1_attacked", 2),
        Column::new("AP, % of raw", "ap_ratio", 0),
        Column::new("on the frontier", "on_frontier", 0),
    ]);
    for (p, f) in points.iter().zip(&front) {
        t.push(vec![
            p.set.as_str().into(),
            p.hours.map_or("—".to_string(), |h| format!("{h:.1} h")).into(),
            p.top1.into(),
            p.top1_attacked.into(),
            p.ap_ratio.into(),
            if *f { "yes" } else { "" }.into(),
        ]);
    }
    (svg, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "# a comment\nset,hours,top1,top1_attacked,ap_ratio\na,1.0,0.5,3.0,60\nb,2.0,0.2,13.2,34\nc,,5.0,100,74\nd,1.5,0.4,2.7,59\n";

    #[test]
    fn points_parse_and_the_frontier_is_the_undominated_ones() {
        let p = parse(CSV).unwrap();
        assert_eq!(p.len(), 4);
        assert_eq!(p[2], Point { set: "c".into(), hours: None, top1: 5.0, top1_attacked: 100.0, ap_ratio: 74.0 });
        // By hand: b (13.2, 34) is beaten by a (3.0, 60) on both; a, c (the most useful) and
        // d (the most private) are not beaten.
        assert_eq!(on_frontier(&p), vec![true, false, true, true]);
        let (svg, table) = render(&p);
        let md = table.markdown();
        assert!(svg.starts_with("<svg") && svg.contains("a (1.0 h)") && svg.contains(">c<"));
        assert!(
            md.contains("| b | 2.0 h | 0.20 | 13.20 | 34 |  |") && md.contains("| c | — | 5.00 | 100.00 | 74 | yes |")
        );
    }

    #[test]
    fn bad_points_name_the_line_and_the_rule() {
        let err = |s: &str| parse(s).unwrap_err().to_string();
        assert!(err("set,top1\n").contains("line 1: the header must be"));
        assert!(err(&format!("{HEADER}\na,1,0.5,3\n")).contains("line 2: 4 fields"));
        assert!(
            err(&format!("{HEADER}\na,1,0.5,NaN,60\n")).contains("line 2: top1_attacked must be a number in [0, 100]")
        );
        assert!(err(&format!("{HEADER}\na,1,5,3,60\n")).contains("at least top1"));
        assert!(err(&format!("{HEADER}\n,1,5,6,60\n")).contains("set: 1 to 100"));
        assert!(err(&format!("{HEADER}\n")).contains("no points"));
        let many = format!("{HEADER}\n{}", "a,1,1,1,1\n".repeat(MAX_POINTS + 1));
        assert!(err(&many).contains("more than 200 points"));
    }
}
