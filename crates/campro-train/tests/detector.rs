//! The utility player against independent implementations: YOLOX-Nano interpreted by candle
//! against the same ONNX file run by tract (forward, and after an edit written back as ONNX),
//! the detection loss's assignment and IoU by hand.

use campro_testkit as shared;

use campro_eval::manifest::Manifest;
use campro_eval::model::Model;
use campro_nn::yolox::Yolox;
use candle_core::{Device, Tensor};
use std::path::Path;

const MANIFEST: &str = include_str!("../../campro-eval/models/yolox_nano.json");

/// A real COCO image letterboxed to 416 (the evaluation's own preprocessing), as tract's
/// input tensor and as candle's.
fn canvas(img: &Path) -> image::RgbImage {
    let img = campro_eval::data::read_rgb8(img).unwrap();
    let s = (416.0 / img.width() as f64).min(416.0 / img.height() as f64);
    campro_eval::geometry::letterbox(&img, 416, 416, s, 114)
}

fn bgr_tensor(c: &image::RgbImage) -> Tensor {
    let (w, h) = (c.width() as usize, c.height() as usize);
    let mut v = vec![0f32; 3 * h * w];
    for (i, p) in c.pixels().enumerate() {
        for ch in 0..3 {
            v[ch * h * w + i] = p.0[2 - ch] as f32;
        }
    }
    Tensor::from_vec(v, (1, 3, h, w), &Device::Cpu).unwrap()
}

fn tract_head(onnx: &Path, models: &Path, c: &image::RgbImage) -> Vec<f32> {
    let mut m = Manifest::parse(MANIFEST, Path::new("yolox_nano.json"), models).unwrap();
    m.file = onnx.to_path_buf();
    Model::load(m).unwrap().run(c).unwrap().any("output").unwrap().to_vec()
}

/// The raw head of `net` on `x`, flattened.
fn head_of(net: &Yolox, x: &Tensor) -> Vec<f32> {
    net.forward(x).unwrap().flatten_all().unwrap().to_vec1().unwrap()
}

/// max |a − b|.
fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max)
}

#[test]
fn yolox_matches_tract_and_round_trips_through_onnx() {
    let Some(onnx) = shared::shared("models/yolox_nano.onnx") else { return };
    let Some(img) = shared::shared("data/coco-person/images/000000000139.jpg") else { return };
    let models = onnx.parent().unwrap().to_path_buf();
    let c = canvas(&img);
    let net = Yolox::load(&onnx, &Device::Cpu).unwrap();
    let ours: Vec<f32> = head_of(&net, &bgr_tensor(&c));
    let theirs = tract_head(&onnx, &models, &c);
    assert_eq!(ours.len(), theirs.len());
    assert_eq!(ours.len(), 3549 * 85);
    let worst = max_diff(&ours, &theirs);
    assert!(worst < 2e-3, "max |candle − tract| = {worst}");
    // Edit a weight of the objectness conv, write ONNX, and tract sees the edit.
    let bias = net.vars().into_iter().find(|v| v.dims() == [1]).unwrap();
    bias.set(&(bias.as_tensor() + 1.0).unwrap()).unwrap();
    let edited: Vec<f32> = head_of(&net, &bgr_tensor(&c));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("edited.onnx");
    net.save_onnx(&out).unwrap();
    let back = tract_head(&out, &models, &c);
    let worst = max_diff(&edited, &back);
    let moved = max_diff(&edited, &ours);
    assert!(moved > 0.01, "the edit changed nothing ({moved})");
    assert!(worst < 2e-3, "written ONNX differs from candle by {worst}");
}

#[test]
fn iou_by_hand() {
    use campro_train::detection::iou_cxcywh;
    // [0,2]² and [1,3]²: intersection 1, union 7.
    assert!((iou_cxcywh([1.0, 1.0, 2.0, 2.0], [2.0, 2.0, 2.0, 2.0]) - 1.0 / 7.0).abs() < 1e-7);
    assert_eq!(iou_cxcywh([0.0, 0.0, 1.0, 1.0], [5.0, 5.0, 1.0, 1.0]), 0.0);
    assert!((iou_cxcywh([3.0, 4.0, 2.0, 6.0], [3.0, 4.0, 2.0, 6.0]) - 1.0).abs() < 1e-7);
}

/// A 32x32 input: 16 + 4 + 1 anchors. One person box [8, 16]² (centre (12, 12)); the
/// anchor at stride 8, column 1, row 1 (index 5) predicts it exactly, every other anchor a
/// far-away dot. Σ top-10 IoU = 1, so k = 1 and SimOTA picks anchor 5 alone; the loss is
/// then (5·0 + Σ BCE(obj, [i = 5]) + BCE(cls_5, 1)) / 1, computed here by hand.
#[test]
fn simota_and_loss_by_hand() {
    use campro_nn::yolox::anchors;
    use campro_train::detection::{simota, yolox_loss, Positive};
    let a = anchors(32, 32);
    assert_eq!(a.len(), 21);
    assert_eq!(a[5], (1.0, 1.0, 8.0));
    let mut head = vec![0f32; 21 * 85];
    let (mut obj, mut cls) = (vec![0f32; 21], vec![0f32; 21]);
    for i in 0..21 {
        let r = &mut head[i * 85..(i + 1) * 85];
        // Far dot: centre (col + 100)·s, size e^-5·s.
        r[..4].copy_from_slice(&[100.0, 100.0, -5.0, -5.0]);
        obj[i] = 0.1 + 0.01 * i as f32;
        cls[i] = 0.3;
        r[4] = obj[i];
        r[5] = cls[i];
    }
    // Anchor 5: centre (0.5 + 1)·8 = 12, size e^0·8 = 8.
    head[5 * 85..5 * 85 + 4].copy_from_slice(&[0.5, 0.5, 0.0, 0.0]);
    cls[5] = 0.8;
    head[5 * 85 + 5] = 0.8;
    let gt = [12.0f32, 12.0, 8.0, 8.0];
    let boxes: Vec<[f32; 4]> = (0..21).map(|i| if i == 5 { gt } else { [0.0; 4] }).collect();
    assert_eq!(simota(&a, &boxes, &obj, &cls, &[gt]), vec![Positive { anchor: 5, gt: 0, iou: 1.0 }]);
    let t = Tensor::from_vec(head, (1, 21, 85), &Device::Cpu).unwrap();
    let (loss, parts) = yolox_loss(&t, 32, 32, &[vec![gt]]).unwrap();
    let bce = |p: f64, y: f64| -(y * p.ln() + (1.0 - y) * (1.0 - p).ln());
    let obj_sum: f64 = (0..21).map(|i| bce(obj[i] as f64, if i == 5 { 1.0 } else { 0.0 })).sum();
    let want = obj_sum + bce(0.8, 1.0);
    assert_eq!(parts.positives, 1);
    assert!(parts.iou.abs() < 1e-6, "{}", parts.iou);
    let got = loss.to_scalar::<f32>().unwrap() as f64;
    assert!((got - want).abs() < 1e-4, "{got} vs {want}");
    // No people: only objectness, all negative, normalised by 1.
    let (loss, parts) = yolox_loss(&t, 32, 32, &[vec![]]).unwrap();
    let want: f64 = (0..21).map(|i| bce(obj[i] as f64, 0.0)).sum();
    assert_eq!(parts.positives, 0);
    assert!((loss.to_scalar::<f32>().unwrap() as f64 - want).abs() < 1e-4);
}

/// Two boxes whose candidate areas overlap: an anchor claimed by both stays with the box it
/// costs less for.
#[test]
fn simota_resolves_conflicts_by_cost() {
    use campro_nn::yolox::anchors;
    use campro_train::detection::simota;
    let a = anchors(64, 64);
    let n = a.len();
    // Every anchor predicts box A = [16, 32]²  centre (24, 24) side 16, with equal scores.
    let ga = [24.0f32, 24.0, 16.0, 16.0];
    let gb = [28.0f32, 24.0, 16.0, 16.0];
    let boxes = vec![ga; n];
    let (obj, cls) = (vec![0.5f32; n], vec![0.5f32; n]);
    let pos = simota(&a, &boxes, &obj, &cls, &[ga, gb]);
    // IoU with A is 1 everywhere, with B 12·16/(2·256 − 192) = 0.6: A costs less on every shared anchor.
    let iou_b = 12.0 * 16.0 / (2.0 * 256.0 - 192.0);
    for p in &pos {
        let want = if p.gt == 0 { 1.0 } else { iou_b };
        assert!((p.iou - want).abs() < 1e-6, "{p:?}");
    }
    let mut anchors_seen: Vec<usize> = pos.iter().map(|p| p.anchor).collect();
    anchors_seen.dedup();
    assert_eq!(anchors_seen.len(), pos.len(), "an anchor assigned twice");
    // k_A = min(10, candidates) IoUs of 1 → 10 anchors, all with both geometry terms.
    assert_eq!(pos.iter().filter(|p| p.gt == 0).count(), 10);
}

#[test]
fn distillation_by_hand() {
    use campro_train::detection::distill_loss;
    // Two anchors. Anchor 0: the student's box, objectness and person score differ from the
    // teacher's; anchor 1: identical (its teacher objectness 0.7 only raises the normaliser).
    let row = |b: [f32; 4], obj: f32, person: f32| -> Vec<f32> {
        let mut r = vec![0.5f32; 85];
        r[..4].copy_from_slice(&b);
        r[4] = obj;
        r[5] = person;
        r
    };
    let head = |rows: Vec<Vec<f32>>| Tensor::from_vec(rows.concat(), (1, 2, 85), &Device::Cpu).unwrap();
    let teacher = head(vec![row([0.5, 0.2, 0.1, -0.3], 0.8, 0.9), row([1.0, 2.0, 0.0, 0.0], 0.7, 0.3)]);
    let student = head(vec![row([0.1, 0.2, 0.1, 0.3], 0.4, 0.6), row([1.0, 2.0, 0.0, 0.0], 0.7, 0.3)]);
    let kl = |t: f64, s: f64| t * (t / s).ln() + (1.0 - t) * ((1.0 - t) / (1.0 - s)).ln();
    let boxes = 0.4f64 * 0.4 + 0.6 * 0.6;
    let want = (kl(0.8, 0.4) + 0.8 * (kl(0.9, 0.6) + boxes)) / 1.5;
    let got = distill_loss(&student, &teacher).unwrap().to_scalar::<f32>().unwrap() as f64;
    assert!((got - want).abs() < 1e-5, "{got} vs {want}");
    // Agreeing heads cost nothing; a teacher with almost no objects is not divided by < 1.
    assert!(distill_loss(&teacher, &teacher).unwrap().to_scalar::<f32>().unwrap().abs() < 1e-6);
    let faint = head(vec![row([0.5, 0.2, 0.1, -0.3], 0.2, 0.9), row([1.0, 2.0, 0.0, 0.0], 0.1, 0.3)]);
    let s2 = head(vec![row([0.1, 0.2, 0.1, 0.3], 0.2, 0.9), row([1.0, 2.0, 0.0, 0.0], 0.1, 0.3)]);
    let got = distill_loss(&s2, &faint).unwrap().to_scalar::<f32>().unwrap() as f64;
    assert!((got - 0.2 * boxes).abs() < 1e-5, "{got}");
    // Heads of different shapes are an error, not a broadcast.
    assert!(distill_loss(&student.narrow(1, 0, 1).unwrap(), &teacher).is_err());
}

#[test]
fn colour_adapter_starts_as_the_identity_and_round_trips_through_onnx() {
    let Some(onnx) = shared::shared("models/yolox_nano.onnx") else { return };
    let Some(img) = shared::shared("data/coco-person/images/000000000139.jpg") else { return };
    let models = onnx.parent().unwrap().to_path_buf();
    let c = canvas(&img);
    let x = bgr_tensor(&c);
    let dev = Device::Cpu;
    let plain = Yolox::load(&onnx, &dev).unwrap();
    let want: Vec<f32> = head_of(&plain, &x);
    let net = Yolox::load(&onnx, &dev).unwrap().with_adapter(4, 7, &dev).unwrap();
    let (adapter, rest) = net.adapter_and_rest();
    assert_eq!(
        adapter.iter().map(|v| v.dims().to_vec()).collect::<Vec<_>>(),
        [vec![4, 3, 1, 1], vec![4], vec![3, 4, 1, 1], vec![3]]
    );
    assert_eq!(rest.len(), plain.vars().len());
    assert!(plain.adapter_and_rest().0.is_empty());
    let start: Vec<f32> = head_of(&net, &x);
    assert_eq!(start, want, "a fresh adapter must leave the detector unchanged");
    assert!(Yolox::load(&onnx, &dev).unwrap().with_adapter(0, 7, &dev).is_err());
    // Weights changed before the adapter is added are kept.
    let edited = Yolox::load(&onnx, &dev).unwrap();
    let bias = edited.vars().into_iter().find(|v| v.dims() == [1]).unwrap();
    bias.set(&(bias.as_tensor() + 1.0).unwrap()).unwrap();
    let before: Vec<f32> = head_of(&edited, &x);
    let after: Vec<f32> = head_of(&edited.with_adapter(2, 1, &dev).unwrap(), &x);
    assert_eq!(before, after);
    assert_ne!(before, want);
    // Give it a colour map by hand: w1 = unit rows on B, G, R and one more, b1 = 0, w2 sends
    // unit 0 to channel 2 (R) with weight −2 and b2 = (0, 0, 1): R' = R + 255·(1 − 2·SiLU(B/255)).
    let (w1, b1, w2, b2) = (&adapter[0], &adapter[1], &adapter[2], &adapter[3]);
    let rows: Vec<f32> = [[1., 0., 0.], [0., 1., 0.], [0., 0., 1.], [1., 1., 1.]].concat();
    w1.set(&Tensor::from_vec(rows, (4, 3, 1, 1), &dev).unwrap()).unwrap();
    b1.set(&Tensor::zeros(4, candle_core::DType::F32, &dev).unwrap()).unwrap();
    let mut m = vec![0f32; 12];
    m[2 * 4] = -2.0;
    w2.set(&Tensor::from_vec(m, (3, 4, 1, 1), &dev).unwrap()).unwrap();
    b2.set(&Tensor::from_vec(vec![0f32, 0., 1.], 3, &dev).unwrap()).unwrap();
    // The same detector run on the colour-mapped image by hand, without an adapter.
    let silu = |v: f32| v / (1.0 + (-v).exp());
    let (w, h) = (c.width() as usize, c.height() as usize);
    let mut v: Vec<f32> = x.flatten_all().unwrap().to_vec1().unwrap();
    for i in 0..h * w {
        v[2 * h * w + i] += 255.0 * (1.0 - 2.0 * silu(v[i] / 255.0));
    }
    let by_hand: Vec<f32> = head_of(&plain, &Tensor::from_vec(v, (1, 3, h, w), &dev).unwrap());
    let ours: Vec<f32> = head_of(&net, &x);
    let worst = max_diff(&ours, &by_hand);
    assert!(worst < 2e-3, "adapter vs the map by hand: {worst}");
    let moved = max_diff(&ours, &want);
    assert!(moved > 0.1, "the map changed nothing ({moved})");
    // Written as ONNX, tract runs the adapter too.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("adapted.onnx");
    net.save_onnx(&out).unwrap();
    let back = tract_head(&out, &models, &c);
    let worst = max_diff(&ours, &back);
    assert!(worst < 2e-3, "written ONNX differs from candle by {worst}");
    // Our own loader reads the written file back, adapter included, and refuses a second.
    let again = Yolox::load(&out, &dev).unwrap();
    assert_eq!(again.adapter_and_rest().0.len(), 4);
    assert!(again.with_adapter(4, 7, &dev).is_err());
}
