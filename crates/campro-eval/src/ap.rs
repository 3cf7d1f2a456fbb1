//! COCO detection metrics for one category, as pycocotools' `COCOeval` (bbox, area "all",
//! maxDets 100): AP over IoU 0.50:0.05:0.95 with 101-point interpolated precision, AP@0.5,
//! AP@0.75; plus precision, recall and F1 at a stated confidence and IoU 0.5.

/// A ground-truth box `[x, y, w, h]` (pixels); crowd regions are matched but never counted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundTruth {
    pub bbox: [f32; 4],
    pub crowd: bool,
}

/// A detection `[x, y, w, h]` with its score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scored {
    pub bbox: [f32; 4],
    pub score: f32,
}

/// The metrics of one evaluation. APs are −1 when there is no (non-crowd) ground truth.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Metrics {
    pub ap: f64,
    pub ap50: f64,
    pub ap75: f64,
    /// At `confidence`, IoU 0.5.
    pub precision: f64,
    pub recall: f64,
    pub f1: f64,
    pub confidence: f64,
    pub ground_truths: usize,
    pub detections: usize,
}

/// COCO's IoU of a detection with a ground truth (`[x, y, w, h]`; for a crowd region the
/// union is the detection's own area).
pub fn coco_iou(d: [f32; 4], g: [f32; 4], crowd: bool) -> f64 {
    let (d, g) = (d.map(f64::from), g.map(f64::from));
    let iw = ((d[0] + d[2]).min(g[0] + g[2]) - d[0].max(g[0])).max(0.0);
    let ih = ((d[1] + d[3]).min(g[1] + g[3]) - d[1].max(g[1])).max(0.0);
    let inter = iw * ih;
    let union = if crowd { d[2] * d[3] } else { d[2] * d[3] + g[2] * g[3] - inter };
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// IoU thresholds 0.50, 0.55, ..., 0.95 (computed as numpy's `linspace` does).
pub fn iou_thresholds() -> [f64; 10] {
    std::array::from_fn(|i| 0.5 + 0.45 * i as f64 / 9.0)
}

/// Per image: for each threshold, each detection's state (matched, ignored), in score order.
fn match_image(gts: &[GroundTruth], dets: &[Scored], t: f64) -> Vec<(bool, bool)> {
    // Ground truths: non-crowd first (pycocotools sorts by the ignore flag, stably).
    let mut g: Vec<&GroundTruth> = gts.iter().filter(|g| !g.crowd).collect();
    g.extend(gts.iter().filter(|g| g.crowd));
    let mut taken = vec![false; g.len()];
    dets.iter()
        .map(|d| {
            let mut best = t.min(1.0 - 1e-10);
            let mut m: Option<usize> = None;
            for (j, gt) in g.iter().enumerate() {
                if taken[j] && !gt.crowd {
                    continue;
                }
                if let Some(mj) = m {
                    if !g[mj].crowd && gt.crowd {
                        break;
                    }
                }
                let iou = coco_iou(d.bbox, gt.bbox, gt.crowd);
                if iou < best {
                    continue;
                }
                best = iou;
                m = Some(j);
            }
            match m {
                Some(j) => {
                    taken[j] = true;
                    (true, g[j].crowd)
                }
                None => (false, false),
            }
        })
        .collect()
}

/// Evaluates detections against ground truths, image by image (`images[i] = (gts, dets)`).
/// Detections beyond the 100 best of an image are dropped, as `maxDets = 100`.
pub fn evaluate(images: &[(Vec<GroundTruth>, Vec<Scored>)], confidence: f64) -> Metrics {
    let thresholds = iou_thresholds();
    let npig: usize = images.iter().map(|(g, _)| g.iter().filter(|g| !g.crowd).count()).sum();
    // (score, per-threshold (matched, ignored)) for every kept detection, image order.
    let mut all: Vec<(f32, Vec<(bool, bool)>)> = Vec::new();
    for (gts, dets) in images {
        let mut d: Vec<Scored> = dets.clone();
        d.sort_by(|a, b| b.score.total_cmp(&a.score)); // stable, as numpy's mergesort
        d.truncate(100);
        let per_t: Vec<Vec<(bool, bool)>> = thresholds.iter().map(|&t| match_image(gts, &d, t)).collect();
        for (k, det) in d.iter().enumerate() {
            all.push((det.score, per_t.iter().map(|v| v[k]).collect()));
        }
    }
    all.sort_by(|a, b| b.0.total_cmp(&a.0));
    let detections = all.len();
    let ap_at: Vec<f64> = (0..thresholds.len()).map(|ti| interpolated_ap(&all, ti, npig)).collect();
    let mean = |v: &[f64]| if npig == 0 { -1.0 } else { v.iter().sum::<f64>() / v.len() as f64 };
    // Precision / recall / F1 at the confidence, IoU 0.5 (index 0).
    let (mut tp, mut fp) = (0usize, 0usize);
    for (s, st) in &all {
        if (*s as f64) < confidence {
            break;
        }
        match st[0] {
            (_, true) => {}
            (true, false) => tp += 1,
            (false, _) => fp += 1,
        }
    }
    let precision = if tp + fp > 0 { tp as f64 / (tp + fp) as f64 } else { 0.0 };
    let recall = if npig > 0 { tp as f64 / npig as f64 } else { 0.0 };
    let f1 = if precision + recall > 0.0 { 2.0 * precision * recall / (precision + recall) } else { 0.0 };
    Metrics {
        ap: mean(&ap_at),
        ap50: if npig == 0 { -1.0 } else { ap_at[0] },
        ap75: if npig == 0 { -1.0 } else { ap_at[5] },
        precision,
        recall,
        f1,
        confidence,
        ground_truths: npig,
        detections,
    }
}

/// 101-point interpolated AP at threshold index `ti` (pycocotools' `accumulate`).
fn interpolated_ap(all: &[(f32, Vec<(bool, bool)>)], ti: usize, npig: usize) -> f64 {
    if npig == 0 {
        return 0.0;
    }
    let (mut tp, mut fp) = (0.0f64, 0.0f64);
    let mut rc = Vec::new();
    let mut pr = Vec::new();
    for (_, st) in all {
        match st[ti] {
            (_, true) => continue, // ignored detections do not enter the curve
            (true, false) => tp += 1.0,
            (false, _) => fp += 1.0,
        }
        rc.push(tp / npig as f64);
        pr.push(tp / (tp + fp + f64::EPSILON));
    }
    for i in (1..pr.len()).rev() {
        if pr[i] > pr[i - 1] {
            pr[i - 1] = pr[i];
        }
    }
    let mut sum = 0.0;
    for r in 0..=100 {
        let thr = r as f64 / 100.0;
        let i = rc.partition_point(|&x| x < thr); // searchsorted, side = left
        if i < pr.len() {
            sum += pr[i];
        }
    }
    sum / 101.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crowd_iou_uses_the_detection_area() {
        // A 2x2 detection inside a 10x10 crowd region: IoU 1; as a normal box 4/100.
        assert_eq!(coco_iou([1., 1., 2., 2.], [0., 0., 10., 10.], true), 1.0);
        assert!((coco_iou([1., 1., 2., 2.], [0., 0., 10., 10.], false) - 0.04).abs() < 1e-12);
    }
}
