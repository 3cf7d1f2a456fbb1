//! Report files: CSV tables laid out like the paper's (Table I privacy, Table III utility,
//! Table IV quality), the full results as JSON, SVG plots (CMC curves, the privacy-utility
//! trade-off of the paper's Figure 10) and one Markdown report per evaluation. Every file
//! is written to a temporary file and renamed, so a failed run leaves no partial output.

use crate::error::{EvalError, Result};
use crate::plot::{chart, Series, Style};
use crate::privacy::{Enrolment, Order, PrivacyReport};
use crate::quality::QualityReport;
use crate::scene::Scene;
use crate::table::{Cell, Column, Table};
use crate::utility::UtilityReport;
use std::fmt::Write as _;
use std::path::Path;

/// Writes (or replaces) one report file through [`campro::file::atomic::write`].
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    campro::file::atomic::write(path, bytes, true).map_err(EvalError::io(path))
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

/// The privacy table, like the paper's Table I: one row per protection order x image type
/// x classifier, one column per model (top-1 %, mean ± std over runs) and their average;
/// people also see, after each end-to-end image type, how often the face detector found
/// the face.
pub fn privacy_table(r: &PrivacyReport) -> Table {
    let models = models_of(r);
    let mut t = Table::new(
        [Column::new("dataset", "dataset", 0), Column::new("order", "order", 0)]
            .into_iter()
            .chain([Column::new("image type", "image_type", 0), Column::new("classifier", "classifier", 0)])
            .chain(models.iter().map(|m| Column::new(m.as_str(), m.as_str(), 2)))
            .chain([Column::new("average", "average", 2)]),
    );
    for order in [Order::Paper, Order::EndToEnd] {
        for cond in conditions_of(r.identification.iter().map(|x| &x.condition)) {
            for cls in ["nearest", "linear"] {
                let rows: Vec<_> = models
                    .iter()
                    .map(|m| {
                        r.identification
                            .iter()
                            .find(|x| x.order == order && x.condition == cond && x.classifier == cls && &x.model == m)
                    })
                    .collect();
                let note = rows
                    .iter()
                    .flatten()
                    .next()
                    .and_then(|x| x.detection_rate)
                    .map(|d| format!("faces found: {:.1}%", 100.0 * d));
                let mut cells = vec![
                    Cell::text(dataset(r)),
                    Cell::text(order.name()),
                    Cell::Text { text: cond.clone(), note },
                    Cell::text(cls),
                ];
                cells.extend(rows.iter().map(|x| match x {
                    Some(x) => Cell::MeanStd(100.0 * x.top1_mean, 100.0 * x.top1_std),
                    None => Cell::Num(f64::NAN),
                }));
                let avg = rows.iter().map(|x| x.map_or(f64::NAN, |x| 100.0 * x.top1_mean)).sum::<f64>()
                    / rows.len().max(1) as f64;
                cells.push(Cell::Num(avg));
                t.push(cells);
            }
        }
    }
    t
}

/// The verification table: per image type and model, 10-fold accuracy and TAR at FAR 1e-3.
pub fn verification_table(r: &PrivacyReport) -> Table {
    let mut t = Table::new([
        Column::new("dataset", "dataset", 0),
        Column::new("image type", "image_type", 0),
        Column::new("model", "model", 0),
        Column::new("10-fold accuracy", "accuracy_mean", 4),
        Column::new("std", "accuracy_std", 4),
        Column::new("TAR @ FAR 1e-3", "tar_at_far_1e-3", 4),
        Column::new("pairs", "pairs", 0),
    ]);
    for x in &r.verification {
        t.push(vec![
            dataset(r).into(),
            x.condition.as_str().into(),
            x.model.as_str().into(),
            x.accuracy_mean.into(),
            x.accuracy_std.into(),
            x.tar_at_far_1e3.into(),
            x.pairs.into(),
        ]);
    }
    t
}

/// The worst top-1 (%) of each image type in each report (one a scene, as measured):
/// the highest mean over models, classifiers and protection orders, and the worst over
/// the scenes.
pub fn conditions_table(reports: &[PrivacyReport]) -> Table {
    let mut t = Table::new(
        [Column::new("image type", "image_type", 0)]
            .into_iter()
            .chain(reports.iter().map(|r| Column::new(r.options.scene.name(), r.options.scene.name(), 2)))
            .chain([Column::new("worst", "worst", 2)]),
    );
    let names = conditions_of(reports.iter().flat_map(|r| r.identification.iter().map(|x| &x.condition)));
    for cond in names {
        let worst_in = |r: &PrivacyReport| {
            r.identification
                .iter()
                .filter(|x| x.condition == cond)
                .map(|x| 100.0 * x.top1_mean)
                .fold(f64::NAN, f64::max)
        };
        let per: Vec<f64> = reports.iter().map(worst_in).collect();
        let mut cells = vec![Cell::text(cond.as_str())];
        cells.extend(per.iter().map(|&v| Cell::Num(v)));
        cells.push(Cell::Num(per.iter().copied().fold(f64::NAN, f64::max)));
        t.push(cells);
    }
    t
}

/// Writes conditions.md and conditions.csv ([`conditions_table`]) into `dir`.
pub fn write_conditions(reports: &[PrivacyReport], dir: &Path) -> Result<()> {
    let t = conditions_table(reports);
    write_atomic(&dir.join("conditions.csv"), t.csv().as_bytes())?;
    let mut s = String::from(
        "# Privacy under each condition: the worst top-1

",
    );
    let _ = writeln!(
        s,
        "Top-1 identification in % on LFW, each condition's highest mean over face models, classifiers (nearest, linear) and orders (paper, end-to-end); each condition's full report is privacy.md in its folder (colour's beside this file). Lower is better protection.\n"
    );
    s += &t.markdown();
    write_atomic(&dir.join("conditions.md"), s.as_bytes())
}

/// The dataset column: LFW, and its scene unless colour.
fn dataset(r: &PrivacyReport) -> String {
    match r.options.scene {
        Scene::Colour => "LFW".into(),
        s => format!("LFW {}", s.name()),
    }
}

/// What the scene did to the probes, for the report (empty for colour).
fn scene_note(r: &PrivacyReport) -> String {
    use crate::place::{GROUP_CANVAS, GROUP_WIDTHS, SMALL_CANVAS, SMALL_WIDTHS};
    let placed = "The gallery is the raw photos; the camera sees the whole picture and the attacker crops, aligns and upsamples the face after it: in the paper order on the face's raw landmarks (it knows where the face is), end to end where its detector finds a face on the placed one (box IoU ≥ 0.3).";
    match r.options.scene {
        Scene::Colour => String::new(),
        Scene::Grey => "Grey: every photo (gallery, probes, pairs) made black-and-white (BT.601 luma) before the camera.\n\n".into(),
        Scene::Small => format!(
            "Small: each probe's face {}–{} px wide, pasted into a {} x {} held-out COCO scene. {placed}\n\n",
            SMALL_WIDTHS.0, SMALL_WIDTHS.1, SMALL_CANVAS.0, SMALL_CANVAS.1
        ),
        Scene::Group => format!(
            "Group: each probe's face beside {} other people's (LFW people with one photo), {}–{} px wide, in a {} x {} held-out COCO scene. {placed}\n\n",
            crate::place::COMPANIONS, GROUP_WIDTHS.0, GROUP_WIDTHS.1, GROUP_CANVAS.0, GROUP_CANVAS.1
        ),
        Scene::Pose => format!(
            "Pose: each identity's most frontal photo is its gallery photo and its most turned ones (turn ≥ {}: yaw in eye distances, or twice the pitch ratio's offset) the probes; identities without such a photo are left out. Median probe turn {:.2}. No verification (the pairs are colour's).\n\n",
            crate::privacy::MIN_TURN,
            r.probe_turn.unwrap_or(f64::NAN)
        ),
    }
}

/// Writes privacy.json, privacy.csv, verification.csv, cmc.svg and privacy.md into `dir`.
pub fn write_privacy(r: &PrivacyReport, dir: &Path) -> Result<()> {
    write_atomic(&dir.join("privacy.json"), &json(r))?;
    write_atomic(&dir.join("privacy.csv"), privacy_table(r).csv().as_bytes())?;
    write_atomic(&dir.join("verification.csv"), verification_table(r).csv().as_bytes())?;
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
    let mut s = format!("# Privacy: face identification on {}\n\n", dataset(r));
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
    s += &scene_note(r);
    s += &privacy_table(r).markdown();
    if !r.verification.is_empty() {
        let _ = writeln!(
            s,
            "\n## Verification (pairs.txt, first photo {}, second under the image type)\n\n{} pairs used; {} skipped (image absent from this copy), {} skipped (no face in a raw photo).\n",
            if camera { "through the camera too" } else { "raw" },
            r.verification.first().map_or(0, |v| v.pairs),
            r.pairs_skipped_absent,
            r.pairs_skipped_undetected
        );
        s += &verification_table(r).markdown();
    }
    let _ = writeln!(s, "\n![CMC](cmc.svg)\n\nRun time: {:.0} s.", r.seconds);
    s
}

/// The utility table, the paper's Table III columns (precision, recall and F1 at the
/// report's confidence and IoU 0.5).
pub fn utility_table(r: &UtilityReport) -> Table {
    let mut t = Table::new([
        Column::new("image type", "image_type", 0),
        Column::new("AP", "AP", 3),
        Column::new("AP@0.5", "AP50", 3),
        Column::new("AP@0.75", "AP75", 3),
        Column::new("precision", "precision", 3),
        Column::new("recall", "recall", 3),
        Column::new("F1", "F1", 3),
        Column::new("ground truths", "ground_truths", 0),
        Column::new("detections", "detections", 0),
    ]);
    for x in &r.rows {
        let m = &x.metrics;
        t.push(vec![
            x.condition.as_str().into(),
            m.ap.into(),
            m.ap50.into(),
            m.ap75.into(),
            m.precision.into(),
            m.recall.into(),
            m.f1.into(),
            m.ground_truths.into(),
            m.detections.into(),
        ]);
    }
    t
}

/// The utility report as Markdown.
pub fn utility_markdown(r: &UtilityReport) -> String {
    format!(
        "# Utility: person detection ({}) on COCO\n\n{} images{}; precision, recall and F1 at confidence {} and IoU 0.5.\n\n{}\nRun time: {:.0} s.\n",
        crate::table::md_text(&r.detector),
        r.images,
        if r.options.held_out { format!(" (those held out of detector fine-tuning: COCO id % {} == 0)", crate::data::HOLDOUT_EVERY) } else { String::new() },
        r.options.confidence,
        utility_table(r).markdown(),
        r.seconds
    )
}

/// Writes utility.json, utility.csv (the paper's Table III columns) and utility.md.
pub fn write_utility(r: &UtilityReport, dir: &Path) -> Result<()> {
    write_atomic(&dir.join("utility.json"), &json(r))?;
    write_atomic(&dir.join("utility.csv"), utility_table(r).csv().as_bytes())?;
    write_atomic(&dir.join("utility.md"), utility_markdown(r).as_bytes())
}

/// The quality table, the paper's Table IV columns.
pub fn quality_table(r: &QualityReport) -> Table {
    let mut t = Table::new([
        Column::new("image type", "image_type", 0),
        Column::new("RMSE", "RMSE", 2),
        Column::new("PSNR (dB)", "PSNR", 2),
        Column::new("SSIM", "SSIM", 3),
        Column::new("MS-SSIM", "MS-SSIM", 3),
        Column::new("ΔE00 outside faces", "delta_e", 2),
        Column::new("ΔE00 p95", "delta_e_p95", 2),
        Column::new("share ΔE00 > 5", "delta_e_over5", 3),
        Column::new("images", "images", 0),
        Column::new("MS-SSIM images", "ms_ssim_images", 0),
    ]);
    for x in &r.rows {
        t.push(vec![
            x.condition.as_str().into(),
            x.rmse.into(),
            x.psnr.into(),
            x.ssim.into(),
            x.ms_ssim.into(),
            x.delta_e.into(),
            x.delta_e_p95.into(),
            x.delta_e_over5.into(),
            x.images.into(),
            x.ms_ssim_images.into(),
        ]);
    }
    t
}

/// The quality report as Markdown.
pub fn quality_markdown(r: &QualityReport) -> String {
    format!(
        "# Image quality against the raw images\n\n{} images (RMSE on 0..255; MS-SSIM over images ≥ 176 px a side).\n\n{}\nRun time: {:.0} s.\n",
        r.images,
        quality_table(r).markdown(),
        r.seconds
    )
}

/// Writes quality.json, quality.csv (the paper's Table IV columns) and quality.md.
pub fn write_quality(r: &QualityReport, dir: &Path) -> Result<()> {
    write_atomic(&dir.join("quality.json"), &json(r))?;
    write_atomic(&dir.join("quality.csv"), quality_table(r).csv().as_bytes())?;
    write_atomic(&dir.join("quality.md"), quality_markdown(r).as_bytes())
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

/// Writes report.md (all three evaluations, rendered from the reports themselves) and
/// tradeoff.svg. `privacy` holds one report a condition (colour first): the trade-off and
/// the privacy section are the first's; with more, each image type's worst over them follows.
pub fn write_summary(privacy: &[PrivacyReport], u: &UtilityReport, q: &QualityReport, dir: &Path) -> Result<()> {
    let p = privacy.first().ok_or_else(|| EvalError::Invalid("report: no privacy report".into()))?;
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
    let mut t = Table::new([
        Column::new("image type", "image_type", 0),
        Column::new("top-1 (%, mean over models)", "top1", 2),
        Column::new("person AP", "AP", 3),
    ]);
    for (n, x, y) in &points {
        t.push(vec![n.as_str().into(), (100.0 * x).into(), (*y).into()]);
    }
    let mut s = format!("# campro evaluation\n\n## Privacy vs utility\n\n{}", t.markdown());
    s.push_str("\n![trade-off](tradeoff.svg)\n\n");
    if privacy.len() > 1 {
        let _ = writeln!(
            s,
            "## Privacy under each condition\n\nEach image type's worst top-1 (%) over models, classifiers and orders ([conditions.md](conditions.md)).\n\n{}",
            conditions_table(privacy).markdown()
        );
    }
    for part in [privacy_markdown(p), utility_markdown(u), quality_markdown(q)] {
        s.push_str(&part.replacen("# ", "## ", 1).replace("\n## Verification", "\n### Verification"));
        s.push('\n');
    }
    write_atomic(&dir.join("report.md"), s.as_bytes())
}

/// Writes frontier.svg and frontier.md of measured points ([`crate::frontier`]).
pub fn write_frontier(points: &[crate::frontier::Point], dir: &Path) -> Result<()> {
    let (svg, table) = crate::frontier::render(points);
    write_atomic(&dir.join("frontier.svg"), svg.as_bytes())?;
    let md = format!(
        "# Privacy vs utility across runs\n\nx: the worst top-1 over the face models, classifiers and attacks measured; y: person AP of the set's own detector, as % of raw.\n\n![frontier](frontier.svg)\n\n{}",
        table.markdown()
    );
    write_atomic(&dir.join("frontier.md"), md.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quality::QualityRow;

    #[test]
    fn quality_renders_one_table_three_ways() {
        let r = QualityReport {
            rows: vec![QualityRow {
                condition: "a|b".into(),
                rmse: 1.234,
                psnr: 40.0,
                ssim: 0.98765,
                ms_ssim: 0.5,
                delta_e: 2.5,
                delta_e_p95: 6.25,
                delta_e_over5: 0.125,
                images: 3,
                ms_ssim_images: 2,
            }],
            images: 3,
            seconds: 1.0,
        };
        let t = quality_table(&r);
        assert_eq!(
            t.csv(),
            "image_type,RMSE,PSNR,SSIM,MS-SSIM,delta_e,delta_e_p95,delta_e_over5,images,ms_ssim_images\na|b,1.234,40,0.98765,0.5,2.5,6.25,0.125,3,2\n"
        );
        assert!(
            quality_markdown(&r).contains("| a\\|b | 1.23 | 40.00 | 0.988 | 0.500 | 2.50 | 6.25 | 0.125 | 3 | 2 |\n")
        );
        assert_eq!(t.json()[0]["SSIM"], 0.98765);
    }
}
