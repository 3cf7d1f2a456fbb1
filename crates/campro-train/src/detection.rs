//! The utility player's loss L_det: YOLOX's own training loss restricted to the person class
//! (the only labelled class of the shared COCO set).
//!
//! Assignment is YOLOX's SimOTA (Ge et al. 2021, as in Megvii's `yolo_head.py` v0.1):
//! candidate anchors are those whose centre lies in a ground-truth box or within 2.5 strides
//! of its centre; the cost is `−log √(cls·obj) + 3·(−log IoU) + 10⁵·[not in box and centre]`;
//! each box takes its `k` cheapest candidates, `k = max(1, ⌊Σ top-10 IoU⌋)`, and an anchor
//! claimed twice stays with its cheapest box. The loss, per batch, is
//! `(5·Σ_fg (1 − IoU²) + Σ_all BCE(obj, fg) + Σ_fg BCE(cls_person, IoU)) / max(1, #fg)`.
//! Crowd regions are left out of the targets (YOLOX ignores them too). Assignment runs on
//! detached predictions; the loss is differentiable in the head.

use crate::persons::{detector_input, PersonBatch};
use campro_nn::yolox::{anchors, decode_boxes, Yolox};
use candle_core::{Result, Tensor, D};

/// A positive anchor: which anchor, which box, and the IoU of its prediction with the box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Positive {
    pub anchor: usize,
    pub gt: usize,
    pub iou: f32,
}

/// The loss and its parts (each already divided by the number of positives).
#[derive(Debug, Clone, Copy, Default)]
pub struct DetLoss {
    pub iou: f64,
    pub obj: f64,
    pub cls: f64,
    pub positives: usize,
    /// The distillation term before its weight ([`utility_loss`]; 0 without a teacher).
    pub kd: f64,
}

/// IoU of two (cx, cy, w, h) boxes.
pub fn iou_cxcywh(a: [f32; 4], b: [f32; 4]) -> f32 {
    let ix = ((a[0] + a[2] / 2.0).min(b[0] + b[2] / 2.0) - (a[0] - a[2] / 2.0).max(b[0] - b[2] / 2.0)).max(0.0);
    let iy = ((a[1] + a[3] / 2.0).min(b[1] + b[3] / 2.0) - (a[1] - a[3] / 2.0).max(b[1] - b[3] / 2.0)).max(0.0);
    let inter = ix * iy;
    inter / (a[2] * a[3] + b[2] * b[3] - inter + 1e-16)
}

/// SimOTA for one image. `anchors`: (column, row, stride) per anchor; `boxes`: predicted
/// (cx, cy, w, h); `obj`, `cls`: predicted probabilities; `gts`: (cx, cy, w, h) boxes.
pub fn simota(
    anchors: &[(f32, f32, f32)],
    boxes: &[[f32; 4]],
    obj: &[f32],
    cls: &[f32],
    gts: &[[f32; 4]],
) -> Vec<Positive> {
    const RADIUS: f32 = 2.5;
    let n = anchors.len();
    // Geometry: in box, in centre area, per (gt, anchor).
    let inside = |g: &[f32; 4], i: usize| -> (bool, bool) {
        let (c, r, s) = anchors[i];
        let (x, y) = ((c + 0.5) * s, (r + 0.5) * s);
        let in_box = (x - (g[0] - g[2] / 2.0))
            .min(g[0] + g[2] / 2.0 - x)
            .min(y - (g[1] - g[3] / 2.0))
            .min(g[1] + g[3] / 2.0 - y)
            > 0.0;
        let in_centre = (x - g[0]).abs() < RADIUS * s && (y - g[1]).abs() < RADIUS * s;
        (in_box, in_centre)
    };
    let candidate: Vec<bool> =
        (0..n).map(|i| gts.iter().any(|g| matches!(inside(g, i), (true, _) | (_, true)))).collect();
    let cands: Vec<usize> = (0..n).filter(|&i| candidate[i]).collect();
    if cands.is_empty() {
        return Vec::new();
    }
    // Per gt: (cost, iou) over the candidates; the chosen anchors.
    let mut best: Vec<Option<(f32, usize, f32)>> = vec![None; n];
    for (gi, g) in gts.iter().enumerate() {
        let scored: Vec<(f32, f32, usize)> = cands
            .iter()
            .map(|&i| {
                let iou = iou_cxcywh(boxes[i], *g);
                let p = (cls[i] * obj[i]).sqrt().clamp(1e-7, 1.0);
                let (in_box, in_centre) = inside(g, i);
                let cost = -p.ln() + 3.0 * -(iou + 1e-8).ln() + if in_box && in_centre { 0.0 } else { 1e5 };
                (cost, iou, i)
            })
            .collect();
        let mut ious: Vec<f32> = scored.iter().map(|s| s.1).collect();
        ious.sort_by(|a, b| b.total_cmp(a));
        let k = (ious.iter().take(10).sum::<f32>() as usize).max(1).min(scored.len());
        let mut by_cost = scored;
        by_cost.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
        for &(cost, iou, i) in &by_cost[..k] {
            if best[i].is_none_or(|(c, _, _)| cost < c) {
                best[i] = Some((cost, gi, iou));
            }
        }
    }
    best.iter().enumerate().filter_map(|(anchor, b)| b.map(|(_, gt, iou)| Positive { anchor, gt, iou })).collect()
}

/// Binary cross-entropy of probabilities `p` against targets `t`, summed.
fn bce_sum(p: &Tensor, t: &Tensor) -> Result<Tensor> {
    let p = p.clamp(1e-7f32, 1.0 - 1e-7)?;
    let pos = t.mul(&p.log()?)?;
    let neg = (1.0 - t)?.mul(&(1.0 - &p)?.log()?)?;
    (pos + neg)?.sum_all()?.neg()
}

/// IoU of matched (P, 4) (cx, cy, w, h) boxes, differentiable in `a`.
fn iou_rows(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let half = |t: &Tensor| -> Result<(Tensor, Tensor)> {
        let c = t.narrow(1, 0, 2)?;
        let h = (t.narrow(1, 2, 2)? * 0.5)?;
        Ok(((&c - &h)?, (c + h)?))
    };
    let ((a0, a1), (b0, b1)) = (half(a)?, half(b)?);
    let wh = (a1.minimum(&b1)? - a0.maximum(&b0)?)?.relu()?;
    let inter = (wh.narrow(1, 0, 1)? * wh.narrow(1, 1, 1)?)?;
    let area = |t: &Tensor| -> Result<Tensor> { t.narrow(1, 2, 1)? * t.narrow(1, 3, 1)? };
    let union = ((area(a)? + area(b)?)? - &inter)?;
    (inter / (union + 1e-16)?)?.squeeze(1)
}

/// Distillation from a frozen teacher: how far the student's raw head (B, N, 85), run on the
/// camera's output, is from the teacher's head on the same images unprotected. Per anchor,
/// weighted by the teacher's objectness `t_obj`: the KL divergence of the student's objectness
/// from the teacher's (every anchor, unweighted), of its 80 class probabilities (each a
/// Bernoulli) and the squared error of its box (x, y, log w, log h, in strides); the sum is
/// divided by `max(1, Σ t_obj)`, the teacher's soft count of objects. Zero when the heads
/// agree. Unlike [`yolox_loss`] on person-only labels it asks for every class the detector
/// knew, so it keeps what the bundled model learnt instead of overwriting it (see the
/// README's detector section).
pub fn distill_loss(student: &Tensor, teacher: &Tensor) -> Result<Tensor> {
    if student.dims() != teacher.dims() {
        candle_core::bail!("student head {:?} and teacher head {:?} differ", student.dims(), teacher.dims());
    }
    let t = teacher.detach();
    let t_obj = t.narrow(D::Minus1, 4, 1)?;
    let norm = t_obj.sum_all()?.to_scalar::<f32>()?.max(1.0) as f64;
    // KL(t ‖ s) of Bernoulli probabilities, element-wise.
    let kl = |s: &Tensor, t: &Tensor| -> Result<Tensor> {
        let (s, t) = (s.clamp(1e-7f32, 1.0 - 1e-7)?, t.clamp(1e-7f32, 1.0 - 1e-7)?);
        let pos = t.mul(&(t.log()? - s.log()?)?)?;
        let neg = (1.0 - &t)?.mul(&((1.0 - &t)?.log()? - (1.0 - &s)?.log()?)?)?;
        pos + neg
    };
    let obj = kl(&student.narrow(D::Minus1, 4, 1)?, &t_obj)?.sum_all()?;
    let cls = kl(&student.narrow(D::Minus1, 5, 80)?, &t.narrow(D::Minus1, 5, 80)?)?.sum_keepdim(D::Minus1)?;
    let boxes = (student.narrow(D::Minus1, 0, 4)? - t.narrow(D::Minus1, 0, 4)?)?.sqr()?.sum_keepdim(D::Minus1)?;
    let weighted = (cls + boxes)?.mul(&t_obj)?.sum_all()?;
    (obj + weighted)? / norm
}

/// L_det for a raw head (B, N, 85) of an `h` x `w` input and each image's person boxes
/// (cx, cy, w, h) in input pixels; returns the loss tensor and its parts.
pub fn yolox_loss(head: &Tensor, h: usize, w: usize, gts: &[Vec<[f32; 4]>]) -> Result<(Tensor, DetLoss)> {
    let (b, n, _) = head.dims3()?;
    if gts.len() != b {
        candle_core::bail!("{} images but {} box lists", b, gts.len());
    }
    let dev = head.device();
    let boxes = decode_boxes(head, h, w)?;
    let obj = head.narrow(D::Minus1, 4, 1)?.squeeze(D::Minus1)?;
    let cls = head.narrow(D::Minus1, 5, 1)?.squeeze(D::Minus1)?;
    let a = anchors(h, w);
    // Per image: boxes, objectness, class scores.
    type PerImage = (Vec<Vec<[f32; 4]>>, Vec<Vec<f32>>, Vec<Vec<f32>>);
    let (bv, ov, cv): PerImage = {
        let raw: Vec<Vec<Vec<f32>>> = boxes.detach().to_vec3()?;
        (
            raw.into_iter().map(|img| img.into_iter().map(|r| [r[0], r[1], r[2], r[3]]).collect()).collect(),
            obj.detach().to_vec2()?,
            cls.detach().to_vec2()?,
        )
    };
    let (mut fg, mut gt_rows, mut iou_t) = (Vec::<u32>::new(), Vec::<f32>::new(), Vec::<f32>::new());
    let mut obj_t = vec![0f32; b * n];
    for i in 0..b {
        for p in simota(&a, &bv[i], &ov[i], &cv[i], &gts[i]) {
            let k = i * n + p.anchor;
            fg.push(k as u32);
            obj_t[k] = 1.0;
            gt_rows.extend_from_slice(&gts[i][p.gt]);
            iou_t.push(p.iou);
        }
    }
    let np = fg.len();
    let norm = np.max(1) as f64;
    let obj_loss = (bce_sum(&obj.flatten_all()?, &Tensor::from_vec(obj_t, b * n, dev)?)? / norm)?;
    let (loss, parts) = if np == 0 {
        let o = obj_loss.to_scalar::<f32>()? as f64;
        (obj_loss, DetLoss { obj: o, ..Default::default() })
    } else {
        let idx = Tensor::from_vec(fg, np, dev)?;
        let pred = boxes.flatten_to(1)?.index_select(&idx, 0)?;
        let gt = Tensor::from_vec(gt_rows, (np, 4), dev)?;
        let iou = iou_rows(&pred, &gt)?;
        let iou_loss = ((1.0 - iou.sqr()?)?.sum_all()? / norm)?;
        let cls_fg = cls.flatten_all()?.index_select(&idx, 0)?;
        let cls_loss = (bce_sum(&cls_fg, &Tensor::from_vec(iou_t, np, dev)?)? / norm)?;
        let parts = DetLoss {
            iou: iou_loss.to_scalar::<f32>()? as f64,
            obj: obj_loss.to_scalar::<f32>()? as f64,
            cls: cls_loss.to_scalar::<f32>()? as f64,
            positives: np,
            kd: 0.0,
        };
        (((iou_loss * 5.0)? + obj_loss)?.add(&cls_loss)?, parts)
    };
    Ok((loss, parts))
}

/// The detector's optimiser: Adam at `cfg.lr`, with the colour adapter's tensors (if any)
/// in a group of their own at `cfg.adapter_lr`.
pub struct DetectorAdam {
    groups: Vec<candle_nn::AdamW>,
}

impl DetectorAdam {
    pub fn new(det: &Yolox, cfg: &crate::config::DetectorConfig) -> Result<Self> {
        use candle_nn::{AdamW, Optimizer, ParamsAdamW};
        let adam = |vars: Vec<candle_core::Var>, lr: f64| {
            AdamW::new(vars, ParamsAdamW { lr, weight_decay: 0.0, ..Default::default() })
        };
        let (adapter, rest) = det.adapter_and_rest();
        let mut groups = vec![adam(rest, cfg.lr)?];
        if !adapter.is_empty() {
            groups.push(adam(adapter, cfg.adapter_lr)?);
        }
        Ok(Self { groups })
    }

    /// One step of every group on `grads`.
    pub fn step(&mut self, grads: &candle_core::backprop::GradStore) -> Result<()> {
        use candle_nn::Optimizer;
        self.groups.iter_mut().try_for_each(|g| g.step(grads))
    }
}

/// Fits the detector's colour adapter ([`Yolox::with_adapter`]) to undo a camera pixel by
/// pixel: Adam on the adapter alone, minimising the mean squared error (in 0..1 units) of
/// `adapter(C(x))` against `x` over a person batch's pixels, padding included (which the
/// camera leaves alone). No detector pass is needed.
pub struct AdapterFit {
    adam: candle_nn::AdamW,
}

impl AdapterFit {
    /// Adam at `lr` on `det`'s adapter; None when it has none.
    pub fn new(det: &Yolox, lr: f64) -> Result<Option<Self>> {
        use candle_nn::Optimizer;
        let (vars, _) = det.adapter_and_rest();
        if vars.is_empty() {
            return Ok(None);
        }
        let adam = candle_nn::AdamW::new(vars, candle_nn::ParamsAdamW { lr, weight_decay: 0.0, ..Default::default() })?;
        Ok(Some(Self { adam }))
    }

    /// One step on batch `b` seen through the camera as `seen` (detached here); returns the
    /// error before the step.
    pub fn step(&mut self, det: &Yolox, seen: &Tensor, b: &PersonBatch) -> Result<f64> {
        use candle_nn::Optimizer;
        let want = detector_input(&b.x, &b.mask)?;
        let mse = ((det.adapt(&detector_input(&seen.detach(), &b.mask)?)? - want)? / 255.0)?.sqr()?.mean_all()?;
        let e = mse.to_scalar::<f32>()? as f64;
        self.adam.step(&mse.backward()?)?;
        Ok(e)
    }
}

/// The detector `cfg` trains: `cfg.model`, with a colour adapter of `cfg.adapter` units
/// (seeded by `seed`) when that is not 0.
pub fn student(
    cfg: &crate::config::DetectorConfig,
    seed: u64,
    dev: &candle_core::Device,
) -> std::result::Result<Yolox, campro_nn::onnx_net::GraphError> {
    let det = Yolox::load(&cfg.model, dev)?;
    if cfg.adapter > 0 {
        det.with_adapter(cfg.adapter, seed, dev)
    } else {
        Ok(det)
    }
}

/// The frozen teacher of `cfg.distill`: `cfg.model` as loaded, never updated; None when
/// distillation is off.
pub fn teacher(
    cfg: &crate::config::DetectorConfig,
    dev: &candle_core::Device,
) -> std::result::Result<Option<Yolox>, campro_nn::onnx_net::GraphError> {
    if cfg.distill > 0.0 {
        Yolox::load(&cfg.model, dev).map(Some)
    } else {
        Ok(None)
    }
}

/// The utility player's loss as the optimiser and the fine-tuning both use it: `det` on the
/// camera's output `camera_out` of person batch `b` (canvas side `cfg.size`), [`yolox_loss`]
/// against its boxes, plus `cfg.distill` times [`distill_loss`] against `teacher` run on the
/// unprotected batch when a teacher is given. Returns the loss and its parts.
pub fn utility_loss(
    det: &Yolox,
    teacher: Option<&Yolox>,
    cfg: &crate::config::DetectorConfig,
    camera_out: &Tensor,
    b: &PersonBatch,
) -> Result<(Tensor, DetLoss)> {
    let head = det.forward(&detector_input(camera_out, &b.mask)?)?;
    let (loss, mut parts) = yolox_loss(&head, cfg.size, cfg.size, &b.boxes)?;
    match teacher {
        Some(t) if cfg.distill > 0.0 => {
            let kd = distill_loss(&head, &t.forward(&detector_input(&b.x, &b.mask)?)?.detach())?;
            parts.kd = kd.to_scalar::<f32>()? as f64;
            Ok(((loss + (kd * cfg.distill)?)?, parts))
        }
        _ => Ok((loss, parts)),
    }
}
