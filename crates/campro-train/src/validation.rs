//! The validation-driven stop of `campro train` (`[validation]` in the configuration): the
//! scores of a camera on data training never draws, which camera of a run is the best, and
//! when to stop.
//!
//! - **Privacy**: [`nearest_top1`], the paper's nearest classifier with the *pretrained*
//!   face model (not the attacker co-trained in the run, whose head follows the camera): the
//!   held-aside photo of each training identity (never trained on) through the camera,
//!   matched by cosine to the identities' raw class means. Lower is more private; chance is
//!   one over the classes.
//! - **Utility**: [`person_ap`], COCO person AP (as `campro eval utility`, with
//!   `campro_eval::ap`) of the run's detector on the camera's output of COCO training images
//!   set aside for it (never drawn for training; the evaluation's held-out images are never
//!   among them). Crowd regions are not in the training annotations here, so a detection on
//!   one counts as a false positive: the AP is a little below the evaluation's.
//! - **Best**: [`better`], a constraint rather than a weighted sum: under the privacy bound
//!   `max_top1` the more useful camera wins; above it, the more private one.
//!
//! The evaluation's held-out identities and images are never read here: a stop chosen on
//! them would leak the test into the run.

use campro_eval::ap::{GroundTruth, Scored};
use serde::{Deserialize, Serialize};

/// One validation of a camera.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    /// Validation top-1 of the pretrained model's nearest class mean (0..1).
    pub top1: f64,
    /// Validation person AP (0..1); None without a utility player (ω = 0).
    pub ap: Option<f64>,
}

/// Whether `a` is a better camera than `b` under the privacy bound `max_top1`: one within
/// the bound beats one above it; two within it, the higher AP (then the lower top-1); two
/// above it, the lower top-1 (then the higher AP). Equal scores are not better, so the
/// earlier camera stays the best.
pub fn better(a: &Scores, b: &Scores, max_top1: f64) -> bool {
    let (ina, inb) = (a.top1 <= max_top1, b.top1 <= max_top1);
    let ap = |s: &Scores| s.ap.unwrap_or(0.0);
    match (ina, inb) {
        (true, false) => true,
        (false, true) => false,
        (true, true) => ap(a) > ap(b) || (ap(a) == ap(b) && a.top1 < b.top1),
        (false, false) => a.top1 < b.top1 || (a.top1 == b.top1 && ap(a) > ap(b)),
    }
}

/// The best validation so far and how many validations since it brought nothing better.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Best {
    /// The round whose camera it is.
    pub round: usize,
    pub scores: Scores,
    /// Validations after `round` that were not better.
    pub stale: usize,
}

/// Offers the validation of `round` to `best`: true when it is the new best (the caller keeps
/// its camera), false when it only adds to the staleness.
pub fn offer(best: &mut Option<Best>, round: usize, scores: Scores, max_top1: f64) -> bool {
    match best {
        Some(b) if !better(&scores, &b.scores, max_top1) => {
            b.stale += 1;
            false
        }
        _ => {
            *best = Some(Best { round, scores, stale: 0 });
            true
        }
    }
}

/// Whether a run with `patience` (0: never stop early) stops after this validation.
pub fn should_stop(best: &Option<Best>, patience: usize) -> bool {
    patience > 0 && best.is_some_and(|b| b.stale >= patience)
}

/// Top-1 of the nearest class mean by cosine: `embeddings[i]` (any length-d vector) of a
/// face of class `labels[i]`, `means[c]` class c's mean (or sum: only its direction counts).
/// A zero vector matches nothing better than any other; ties go to the lower class.
pub fn nearest_top1(embeddings: &[Vec<f32>], labels: &[u32], means: &[Vec<f32>]) -> f64 {
    if embeddings.is_empty() {
        return 0.0;
    }
    let unit = |v: &[f32]| -> Vec<f64> {
        let n = v.iter().map(|&x| (x as f64) * (x as f64)).sum::<f64>().sqrt();
        v.iter().map(|&x| if n > 0.0 { x as f64 / n } else { 0.0 }).collect()
    };
    let m: Vec<Vec<f64>> = means.iter().map(|v| unit(v)).collect();
    let hits = embeddings
        .iter()
        .zip(labels)
        .filter(|(e, &y)| {
            let e = unit(e);
            let cos = |c: &Vec<f64>| c.iter().zip(&e).map(|(a, b)| a * b).sum::<f64>();
            let mut best = (0usize, f64::NEG_INFINITY);
            for (c, v) in m.iter().enumerate() {
                let s = cos(v);
                if s > best.1 {
                    best = (c, s);
                }
            }
            best.0 == y as usize
        })
        .count();
    hits as f64 / embeddings.len() as f64
}

/// YOLOX's evaluation settings for the utility score: the bundled manifest's (score ≥
/// 0.001, NMS at IoU 0.65, 100 detections an image).
const SCORE_THRESHOLD: f32 = 0.001;
const NMS_IOU: f32 = 0.65;
const MAX_DETECTIONS: usize = 100;

/// COCO person AP of YOLOX heads: `heads[i]` the detector's output for image i (anchors x
/// (5 + classes), probabilities, as `Yolox::forward` gives it) on a `size` x `size` canvas,
/// `boxes[i]` its people (cx, cy, w, h) in canvas pixels. Detected and scored as
/// `campro eval utility` does (`campro_eval::person::detections`, `campro_eval::ap`).
pub fn person_ap(heads: &[Vec<f32>], size: usize, boxes: &[Vec<[f32; 4]>]) -> campro_eval::Result<f64> {
    let mut images = Vec::with_capacity(heads.len());
    for (head, people) in heads.iter().zip(boxes) {
        let kept: Vec<Scored> = campro_eval::person::detections(
            head,
            size,
            size,
            &[8, 16, 32],
            0,
            SCORE_THRESHOLD,
            NMS_IOU,
            MAX_DETECTIONS,
        )?
        .into_iter()
        .map(|d| {
            let [x0, y0, x1, y1] = d.bbox;
            Scored { bbox: [x0, y0, x1 - x0, y1 - y0], score: d.score }
        })
        .collect();
        let gts = people
            .iter()
            .map(|&[cx, cy, w, h]| GroundTruth { bbox: [cx - w / 2.0, cy - h / 2.0, w, h], crowd: false })
            .collect();
        images.push((gts, kept));
    }
    Ok(campro_eval::ap::evaluate(&images, 0.25).ap.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOUND: f64 = 0.02;
    fn s(top1: f64, ap: f64) -> Scores {
        Scores { top1, ap: Some(ap) }
    }

    #[test]
    fn within_the_bound_utility_wins_above_it_privacy_wins() {
        // Both private enough: the more useful one.
        assert!(better(&s(0.02, 0.30), &s(0.0, 0.29), BOUND));
        assert!(!better(&s(0.0, 0.29), &s(0.02, 0.30), BOUND));
        // One within the bound beats any above it, however useful.
        assert!(better(&s(0.01, 0.05), &s(0.03, 0.90), BOUND));
        assert!(!better(&s(0.03, 0.90), &s(0.01, 0.05), BOUND));
        // Both above: the more private one, whatever its AP.
        assert!(better(&s(0.10, 0.0), &s(0.50, 0.9), BOUND));
        // Ties: the second key decides; equal scores are not better.
        assert!(better(&s(0.0, 0.3), &s(0.01, 0.3), BOUND));
        assert!(better(&s(0.5, 0.4), &s(0.5, 0.3), BOUND));
        assert!(!better(&s(0.5, 0.3), &s(0.5, 0.3), BOUND));
        // Without a utility player only privacy counts.
        let p = |t| Scores { top1: t, ap: None };
        assert!(better(&p(0.0), &p(0.01), BOUND) && !better(&p(0.01), &p(0.0), BOUND));
    }

    #[test]
    fn the_best_is_kept_and_patience_counts_validations_without_a_better_one() {
        let mut best = None;
        // Round 25: the first validation is the best. 50: above the bound, but more private.
        assert!(offer(&mut best, 25, s(0.5, 0.3), BOUND));
        assert!(offer(&mut best, 50, s(0.1, 0.2), BOUND));
        // 75: within the bound; 100 within it but less useful; 125 above it again.
        assert!(offer(&mut best, 75, s(0.02, 0.25), BOUND));
        assert!(!offer(&mut best, 100, s(0.0, 0.24), BOUND));
        assert!(!should_stop(&best, 2));
        assert!(!offer(&mut best, 125, s(0.04, 0.40), BOUND));
        assert_eq!(best, Some(Best { round: 75, scores: s(0.02, 0.25), stale: 2 }));
        assert!(should_stop(&best, 2) && !should_stop(&best, 3) && !should_stop(&best, 0));
        // A better one resets the count.
        assert!(offer(&mut best, 150, s(0.01, 0.26), BOUND));
        assert_eq!(best.unwrap().stale, 0);
        assert!(!should_stop(&None, 1));
    }

    #[test]
    fn nearest_class_mean_by_cosine() {
        // Two classes along x and y; means given as sums (length does not count).
        let means = vec![vec![10.0, 0.0], vec![0.0, 0.5]];
        let e = vec![vec![1.0, 0.2], vec![0.1, 3.0], vec![2.0, 1.0], vec![0.0, 0.0]];
        // Hits: face 0 (class 0), face 1 (class 1); face 2 (class 1) is nearer class 0;
        // the zero vector scores 0 against both and goes to class 0, its label 1: a miss.
        assert_eq!(nearest_top1(&e, &[0, 1, 1, 1], &means), 0.5);
        assert_eq!(nearest_top1(&[], &[], &means), 0.0);
    }

    /// A head of a 64 x 64 canvas (84 anchors: 8x8 at stride 8, 4x4 at 16, 2x2 at 32) with
    /// one confident box (cx, cy, w, h) put at the stride-8 anchor (col, row).
    fn head_with(col: usize, row: usize, bx: [f32; 4], score: f32) -> Vec<f32> {
        let mut h = vec![0f32; 84 * 6];
        let a = row * 8 + col;
        let r = &mut h[a * 6..(a + 1) * 6];
        r[0] = bx[0] / 8.0 - col as f32;
        r[1] = bx[1] / 8.0 - row as f32;
        r[2] = (bx[2] / 8.0).ln();
        r[3] = (bx[3] / 8.0).ln();
        r[4] = score.sqrt();
        r[5] = score.sqrt();
        h
    }

    #[test]
    fn person_ap_of_a_perfect_a_missed_and_a_shifted_detection() {
        let gt = [20.0, 28.0, 16.0, 24.0];
        // Exactly on the person: AP 1 at every IoU threshold.
        let ap = person_ap(&[head_with(2, 3, gt, 0.9)], 64, &[vec![gt]]).unwrap();
        assert!((ap - 1.0).abs() < 1e-9, "{ap}");
        // Nothing detected: AP 0.
        assert_eq!(person_ap(&[vec![0f32; 84 * 6]], 64, &[vec![gt]]).unwrap(), 0.0);
        // Shifted 3 px right: IoU = (13·24)/(2·16·24 − 13·24) = 0.684, a match at the IoU
        // thresholds 0.50 to 0.65 only: AP 4/10.
        let shifted = [23.0, 28.0, 16.0, 24.0];
        let ap = person_ap(&[head_with(2, 3, shifted, 0.9)], 64, &[vec![gt]]).unwrap();
        assert!((ap - 0.4).abs() < 1e-9, "{ap}");
    }
}
