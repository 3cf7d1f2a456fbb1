//! Utility: person detection on raw and protected COCO images (COCO AP, AP@0.5, AP@0.75,
//! precision / recall / F1 at a stated confidence).

use crate::ap::{self, GroundTruth, Metrics, Scored};
use crate::data::{read_rgb8, CocoImage};
use crate::error::Result;
use crate::person::PersonDetector;
use crate::Condition;
use serde::Serialize;

#[derive(Debug, Clone, Serialize)]
pub struct UtilityOptions {
    /// Use only the first N images (by COCO id).
    pub limit: Option<usize>,
    /// Confidence at which precision, recall and F1 are reported.
    pub confidence: f64,
    /// Only the images held out of detector fine-tuning ([`crate::data::detector_held_out`]),
    /// before `limit`.
    pub held_out: bool,
}

impl Default for UtilityOptions {
    fn default() -> Self {
        Self { limit: None, confidence: 0.25, held_out: false }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct UtilityRow {
    pub condition: String,
    #[serde(flatten)]
    pub metrics: Metrics,
}

#[derive(Debug, Clone, Serialize)]
pub struct UtilityReport {
    pub options: UtilityOptions,
    pub detector: String,
    pub images: usize,
    pub rows: Vec<UtilityRow>,
    pub seconds: f64,
}

/// Detects people in every image under every condition and scores them.
pub fn evaluate(
    images: &[CocoImage],
    detector: &PersonDetector,
    name: &str,
    conds: &[Condition],
    o: &UtilityOptions,
) -> Result<UtilityReport> {
    let start = std::time::Instant::now();
    let kept: Vec<&CocoImage> =
        images.iter().filter(|im| !o.held_out || crate::data::detector_held_out(im.id)).collect();
    let images = &kept[..o.limit.unwrap_or(kept.len()).min(kept.len())];
    // dets[i][c]: detections of image i under condition c, as COCO [x, y, w, h].
    let dets: Vec<Vec<Vec<Scored>>> = crate::par_map_progress(images, "utility: detecting people", |im| {
        let img = read_rgb8(&im.path)?;
        conds
            .iter()
            .map(|c| {
                let d = detector.detect(&c.apply(&img))?;
                Ok(d.iter()
                    .map(|d| Scored {
                        bbox: [d.bbox[0], d.bbox[1], d.bbox[2] - d.bbox[0], d.bbox[3] - d.bbox[1]],
                        score: d.score,
                    })
                    .collect())
            })
            .collect::<Result<Vec<_>>>()
    })?;
    let rows = conds
        .iter()
        .enumerate()
        .map(|(c, cond)| {
            let per: Vec<(Vec<GroundTruth>, Vec<Scored>)> =
                images.iter().zip(&dets).map(|(im, d)| (im.gts.clone(), d[c].clone())).collect();
            UtilityRow { condition: cond.name.clone(), metrics: ap::evaluate(&per, o.confidence) }
        })
        .collect();
    Ok(UtilityReport {
        options: o.clone(),
        detector: name.to_string(),
        images: images.len(),
        rows,
        seconds: start.elapsed().as_secs_f64(),
    })
}
