//! Report files: CSV tables laid out like the paper's (Table I privacy, Table III utility,
//! Table IV quality), the full results as JSON, SVG plots (CMC curves, the privacy-utility
//! trade-off of the paper's Figure 10) and one Markdown report per evaluation. Every file
//! is written to a temporary file and renamed, so a failed run leaves no partial output.

use crate::error::{EvalError, Result};
use crate::plot::{chart, Series, Style};
use crate::privacy::{Enrolment, Order, PrivacyReport};
use crate::quality::QualityReport;
use crate::utility::UtilityReport;
use std::fmt::Write as _;
use std::path::Path;

/// Writes (or replaces) one report file through [`crate::atomic::write`].
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    crate::atomic::write(path, bytes, true).map_err(EvalError::io(path))
}

fn json(v: &impl serde::Serialize) -> Vec<u8> {
    let mut s = serde_json::to_vec_pretty(v).expect("reports serialise");
    s.push(b'\n');
    s
}

fn models_of(r: &PrivacyReport) -> Vec<String> {
    let mut m: Vec<String> = Vec::new();
    for row in &r.identification {
        if !m.contains(&row.model) {
            m.push(row.model.clone());
        }
    }
    m
}

fn conditions_of<'a>(names: impl Iterator<Item = &'a String>) -> Vec<String> {
    let mut c: Vec<String> = Vec::new();
    for n in names {
        if !c.contains(n) {
            c.push(n.clone());
        }
    }
    c
}

/// Mean top-1 (0..1) of a condition over all models, for one order and classifier.
pub fn mean_top1(r: &PrivacyReport, condition: &str, order: Order, classifier: &str) -> Option<f64> {
    let v: Vec<f64> = r
        .identification
        .iter()
        .filter(|x| x.condition == condition && x.order == order && x.classifier == classifier)
        .map(|x| x.top1_mean)
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The privacy table as CSV, like the paper's Table I: one row per protection order x image
/// type x classifier, one column per model (top-1 %, mean over runs) and their average.
pub fn privacy_csv(r: &PrivacyReport) -> String {
    let models = models_of(r);
    let mut s = format!("dataset,order,image_type,classifier,{},average\n", models.join(","));
    for order in [Order::Paper, Order::EndToEnd] {
        for cond in conditions_of(r.identification.iter().map(|x| &x.condition)) {
            for cls in ["nearest", "linear"] {
                let vals: Vec<f64> = models
                    .iter()
                    .map(|m| {
                        r.identification
                            .iter()
                            .find(|x| x.order == order && x.condition == cond && x.classifier == cls && &x.model == m)
                            .map_or(f64::NAN, |x| 100.0 * x.top1_mean)
                    })
                    .collect();
                let avg = vals.iter().sum::<f64>() / vals.len() as f64;
                let cells: Vec<String> = vals.iter().map(|v| format!("{v:.2}")).collect();
                let _ = writeln!(s, "LFW,{},{},{cls},{},{avg:.2}", order.name(), csv(&cond), cells.join(","));
            }
        }
    }
    s
}

/// Writes privacy.json, privacy.csv, verification.csv, cmc.svg and privacy.md into `dir`.
pub fn write_privacy(r: &PrivacyReport, dir: &Path) -> Result<()> {
    write_atomic(&dir.join("privacy.json"), &json(r))?;
    write_atomic(&dir.join("privacy.csv"), privacy_csv(r).as_bytes())?;
    let mut v = String::from("dataset,image_type,model,accuracy_mean,accuracy_std,tar_at_far_1e-3,pairs\n");
    for x in &r.verification {
        let _ = writeln!(
            v,
            "LFW,{},{},{:.4},{:.4},{:.4},{}",
            csv(&x.condition),
            csv(&x.model),
            x.accuracy_mean,
            x.accuracy_std,
            x.tar_at_far_1e3,
            x.pairs
        );
    }
    write_atomic(&dir.join("verification.csv"), v.as_bytes())?;
    // CMC, paper order, nearest neighbour: one curve per condition x model.
    let series: Vec<Series> = r
        .identification
        .iter()
        .filter(|x| x.order == Order::Paper && x.classifier == "nearest")
        .map(|x| Series {
            name: format!("{} / {}", x.condition, x.model),
            points: x.cmc.iter().enumerate().map(|(k, &p)| ((k + 1) as f64, 100.0 * p)).collect(),
        })
        .collect();
    let svg = chart(
        "CMC, LFW closed set (paper order, nearest)",
        "rank",
        "identification rate (%)",
        &series,
        Style::Lines,
        Some((1.0, r.options.cmc_ranks as f64)),
        Some((0.0, 100.0)),
    );
    write_atomic(&dir.join("cmc.svg"), svg.as_bytes())?;
    write_atomic(&dir.join("privacy.md"), privacy_markdown(r).as_bytes())
}

/// The privacy report as Markdown.
pub fn privacy_markdown(r: &PrivacyReport) -> String {
    let models = models_of(r);
    let mut s = String::from("# Privacy: face identification on LFW\n\n");
    let camera = r.options.enrolment == Enrolment::Camera;
    let gallery = if r.gallery > r.identities {
        format!(
            "; gallery of {} identities, {} of them distractors (never probed)",
            r.gallery,
            r.gallery - r.identities
        )
    } else {
        String::new()
    };
    let enrolled = if camera {
        "Enrolled through the camera: the gallery and the linear classifier's photos are each image type's own protected photos (paper order), not raw ones (the re-enrolment attacker). "
    } else {
        "Enrolled raw: the gallery and the linear classifier's photos are raw. "
    };
    let _ = writeln!(
        s,
        "{enrolled}Closed set: {} identities, {} photos (pool ≤ {} per identity; {} pool photos without a face in the raw photo left out){gallery}, {} runs (seed {}), top-1 in % as mean ± std over runs (chance {:.2}%). Lower is better protection.\n",
        r.identities,
        r.images,
        r.options.pool,
        r.raw_undetected,
        r.options.runs,
        r.options.seed,
        100.0 / r.gallery as f64
    );
    let _ = writeln!(s, "| order | image type | classifier | {} | average |", models.join(" | "));
    let _ = writeln!(s, "|---|---|---|{}---|", "---|".repeat(models.len()));
    for order in [Order::Paper, Order::EndToEnd] {
        for cond in conditions_of(r.identification.iter().map(|x| &x.condition)) {
            for cls in ["nearest", "linear"] {
                let rows: Vec<_> = models
                    .iter()
                    .filter_map(|m| {
                        r.identification
                            .iter()
                            .find(|x| x.order == order && x.condition == cond && x.classifier == cls && &x.model == m)
                    })
                    .collect();
                let cells: Vec<String> =
                    rows.iter().map(|x| format!("{:.2} ± {:.2}", 100.0 * x.top1_mean, 100.0 * x.top1_std)).collect();
                let avg = rows.iter().map(|x| x.top1_mean).sum::<f64>() / rows.len().max(1) as f64;
                let det = rows
                    .first()
                    .and_then(|x| x.detection_rate)
                    .map_or(String::new(), |d| format!(" (faces found: {:.1}%)", 100.0 * d));
                let _ = writeln!(
                    s,
                    "| {} | {}{det} | {cls} | {} | {:.2} |",
                    order.name(),
                    md(&cond),
                    cells.join(" | "),
                    100.0 * avg
                );
            }
        }
    }
    if !r.verification.is_empty() {
        let _ = writeln!(
            s,
            "\n## Verification (pairs.txt, first photo {}, second under the image type)\n\n{} pairs used; {} skipped (image absent from this copy), {} skipped (no face in a raw photo).\n",
            if camera { "through the camera too" } else { "raw" },
            r.verification.first().map_or(0, |v| v.pairs),
            r.pairs_skipped_absent,
            r.pairs_skipped_undetected
        );
        s.push_str("| image type | model | 10-fold accuracy | TAR @ FAR 1e-3 |\n|---|---|---|---|\n");
        for v in &r.verification {
            let _ = writeln!(
                s,
                "| {} | {} | {:.4} ± {:.4} | {:.4} |",
                md(&v.condition),
                md(&v.model),
                v.accuracy_mean,
                v.accuracy_std,
                v.tar_at_far_1e3
            );
        }
    }
    let _ = writeln!(s, "\n![CMC](cmc.svg)\n\nRun time: {:.0} s.", r.seconds);
    s
}

/// A set name as one Markdown table cell: `|` escaped, line breaks and other control
/// characters written out, so a name cannot split a row or forge one.
pub fn md(text: &str) -> String {
    campro::file::escape(text).replace('|', "\\|")
}

/// A set name as one CSV field: quoted (quotes doubled) when it holds a comma, a quote or
/// a line break.
pub fn csv(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// Writes utility.json, utility.csv (the paper's Table III columns) and utility.md.
pub fn write_utility(r: &UtilityReport, dir: &Path) -> Result<()> {
    write_atomic(&dir.join("utility.json"), &json(r))?;
    let mut c = String::from("image_type,AP,AP50,AP75,precision,recall,F1,confidence,ground_truths,detections\n");
    let mut m = format!(
        "# Utility: person detection ({}) on COCO\n\n{} images{}; precision, recall and F1 at confidence {} and IoU 0.5.\n\n| image type | AP | AP@0.5 | AP@0.75 | precision | recall | F1 |\n|---|---|---|---|---|---|---|\n",
        r.detector,
        r.images,
        if r.options.held_out { format!(" (those held out of detector fine-tuning: COCO id % {} == 0)", crate::data::HOLDOUT_EVERY) } else { String::new() },
        r.options.confidence
    );
    for x in &r.rows {
        let t = &x.metrics;
        let _ = writeln!(
            c,
            "{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{}",
            csv(&x.condition),
            t.ap,
            t.ap50,
            t.ap75,
            t.precision,
            t.recall,
            t.f1,
            t.confidence,
            t.ground_truths,
            t.detections
        );
        let _ = writeln!(
            m,
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            md(&x.condition),
            t.ap,
            t.ap50,
            t.ap75,
            t.precision,
            t.recall,
            t.f1
        );
    }
    let _ = writeln!(m, "\nRun time: {:.0} s.", r.seconds);
    write_atomic(&dir.join("utility.csv"), c.as_bytes())?;
    write_atomic(&dir.join("utility.md"), m.as_bytes())
}

/// Writes quality.json, quality.csv (the paper's Table IV columns) and quality.md.
pub fn write_quality(r: &QualityReport, dir: &Path) -> Result<()> {
    write_atomic(&dir.join("quality.json"), &json(r))?;
    let mut c = String::from("image_type,RMSE,PSNR,SSIM,MS-SSIM,images,ms_ssim_images\n");
    let mut m = format!(
        "# Image quality against the raw images\n\n{} images (RMSE on 0..255; MS-SSIM over images ≥ 176 px a side).\n\n| image type | RMSE | PSNR (dB) | SSIM | MS-SSIM |\n|---|---|---|---|---|\n",
        r.images
    );
    for x in &r.rows {
        let _ = writeln!(
            c,
            "{},{:.4},{:.4},{:.4},{:.4},{},{}",
            csv(&x.condition),
            x.rmse,
            x.psnr,
            x.ssim,
            x.ms_ssim,
            x.images,
            x.ms_ssim_images
        );
        let _ =
            writeln!(m, "| {} | {:.2} | {:.2} | {:.3} | {:.3} |", md(&x.condition), x.rmse, x.psnr, x.ssim, x.ms_ssim);
    }
    let _ = writeln!(m, "\nRun time: {:.0} s.", r.seconds);
    write_atomic(&dir.join("quality.csv"), c.as_bytes())?;
    write_atomic(&dir.join("quality.md"), m.as_bytes())
}

/// The privacy-utility trade-off (the paper's Figure 10): x = mean top-1 over the face
/// models (paper order, nearest), y = person AP; one point per image type present in both.
pub fn tradeoff(p: &PrivacyReport, u: &UtilityReport) -> Vec<(String, f64, f64)> {
    u.rows
        .iter()
        .filter_map(|row| {
            mean_top1(p, &row.condition, Order::Paper, "nearest").map(|t| (row.condition.clone(), t, row.metrics.ap))
        })
        .collect()
}

/// Writes report.md (all three evaluations) and tradeoff.svg.
pub fn write_summary(p: &PrivacyReport, u: &UtilityReport, q: &QualityReport, dir: &Path) -> Result<()> {
    let points = tradeoff(p, u);
    let series: Vec<Series> =
        points.iter().map(|(n, x, y)| Series { name: n.clone(), points: vec![(100.0 * x, *y)] }).collect();
    let svg = chart(
        "Privacy vs utility (cf. the paper's Figure 10)",
        "face identification top-1 (%), lower = more private",
        "person AP",
        &series,
        Style::Points,
        Some((0.0, 100.0)),
        None,
    );
    write_atomic(&dir.join("tradeoff.svg"), svg.as_bytes())?;
    let mut s = String::from("# campro evaluation\n\n## Privacy vs utility\n\n| image type | top-1 (%, mean over models) | person AP |\n|---|---|---|\n");
    for (n, x, y) in &points {
        let _ = writeln!(s, "| {n} | {:.2} | {:.3} |", 100.0 * x, y);
    }
    s.push_str("\n![trade-off](tradeoff.svg)\n\n");
    for part in [privacy_markdown(p), utility_markdown_from(dir)?, quality_markdown_from(dir)?] {
        s.push_str(&part.replacen("# ", "## ", 1).replace("\n## Verification", "\n### Verification"));
        s.push('\n');
    }
    let _ = q;
    write_atomic(&dir.join("report.md"), s.as_bytes())
}

fn utility_markdown_from(dir: &Path) -> Result<String> {
    let p = dir.join("utility.md");
    std::fs::read_to_string(&p).map_err(EvalError::io(p))
}

fn quality_markdown_from(dir: &Path) -> Result<String> {
    let p = dir.join("quality.md");
    std::fs::read_to_string(&p).map_err(EvalError::io(p))
}

/// Writes frontier.svg and frontier.md of measured points ([`crate::frontier`]).
pub fn write_frontier(points: &[crate::frontier::Point], dir: &Path) -> Result<()> {
    let (svg, table) = crate::frontier::render(points);
    write_atomic(&dir.join("frontier.svg"), svg.as_bytes())?;
    let md = format!(
        "# Privacy vs utility across runs\n\nx: the worst top-1 over the face models, classifiers and attacks measured; y: person AP of the set's own detector, as % of raw.\n\n![frontier](frontier.svg)\n\n{table}"
    );
    write_atomic(&dir.join("frontier.md"), md.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_names_cannot_break_a_table_or_a_row() {
        assert_eq!(md("a|b"), "a\\|b");
        assert_eq!(md("two\nlines"), "two\\nlines");
        assert_eq!(md("plain"), "plain");
        assert_eq!(csv("a,b"), "\"a,b\"");
        assert_eq!(csv("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(csv("plain"), "plain");
    }
}
