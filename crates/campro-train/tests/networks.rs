//! The trainable networks against independent implementations: MobileFaceNet from its
//! PyTorch checkpoint against the ONNX export run by tract; the depthwise convolution
//! against candle's grouped convolution; the dense convolution, PReLU, SiLU and the
//! per-channel ops against candle's generic ops (one and several threads); the camera against
//! campro's f64 pipeline.

use campro_testkit as shared;

use campro_train::camera::Camera;
use campro_train::conv::{conv2d, prelu};
use campro_train::mobilefacenet::{depthwise, normalise_unit, MobileFaceNet};
use candle_core::{DType, Device, Tensor, Var};
use std::path::Path;

fn rng_tensor(shape: &[usize], seed: u64) -> Tensor {
    let n: usize = shape.iter().product();
    let mut s = seed;
    let v: Vec<f32> = (0..n)
        .map(|_| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect();
    Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
}

fn max_abs(a: &Tensor, b: &Tensor) -> f32 {
    (a - b).unwrap().abs().unwrap().flatten_all().unwrap().max(0).unwrap().to_scalar().unwrap()
}

#[test]
fn depthwise_matches_grouped_convolution() {
    // Odd and even sizes, strides 1 to 3, padding below and at k/2 (the phase planes).
    let cases =
        [(9, 7, 1, 3, 1), (10, 8, 2, 3, 1), (9, 9, 2, 3, 1), (7, 6, 1, 1, 0), (11, 8, 2, 5, 2), (8, 7, 2, 3, 0)];
    for (h, w, stride, k, pad) in cases.into_iter().chain([(13, 10, 3, 5, 1), (6, 6, 1, 5, 2)]) {
        let x = rng_tensor(&[2, 5, h, w], 1);
        let wt = rng_tensor(&[5, 1, k, k], 2);
        let want = x.conv2d(&wt, pad, stride, 1, 5).unwrap();
        let got = depthwise(&x, &wt, stride, pad).unwrap();
        assert_eq!(got.dims(), want.dims(), "{h}x{w} stride {stride}");
        assert!(max_abs(&got, &want) < 1e-5, "{h}x{w} stride {stride}: {}", max_abs(&got, &want));
    }
    // The 7x6 "linear" depthwise of MobileFaceNet: a per-channel weighted sum.
    let x = rng_tensor(&[1, 4, 7, 6], 3);
    let wt = rng_tensor(&[4, 1, 7, 6], 4);
    let got = depthwise(&x, &wt, 1, 0).unwrap();
    let want = x.broadcast_mul(&wt.reshape((1, 4, 7, 6)).unwrap()).unwrap().sum((2, 3)).unwrap();
    assert!(max_abs(&got.flatten_from(1).unwrap(), &want) < 1e-5);
}

#[test]
fn depthwise_gradients_match_grouped_convolution() {
    use candle_core::Var;
    for (h, w, stride, k, pad) in
        [(9, 7, 1, 3, 1), (10, 8, 2, 3, 1), (9, 9, 2, 3, 1), (12, 10, 2, 5, 2), (8, 8, 2, 3, 0)]
    {
        let x = Var::from_tensor(&rng_tensor(&[2, 4, h, w], 11)).unwrap();
        let wt = Var::from_tensor(&rng_tensor(&[4, 1, k, k], 12)).unwrap();
        let r = rng_tensor(&[2, 4, (h + 2 * pad - k) / stride + 1, (w + 2 * pad - k) / stride + 1], 13);
        let ours = depthwise(&x, &wt, stride, pad).unwrap().mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
        let theirs = x.conv2d(&wt, pad, stride, 1, 4).unwrap().mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
        for v in [x.as_tensor(), wt.as_tensor()] {
            let (a, b) = (ours.get(v).unwrap(), theirs.get(v).unwrap());
            assert!(max_abs(a, b) < 1e-4, "{h}x{w} stride {stride}: {}", max_abs(a, b));
        }
    }
    // The 7x6 kernel over a 7x6 input (no padding): gradients of a per-channel weighted sum.
    let x = Var::from_tensor(&rng_tensor(&[2, 3, 7, 6], 14)).unwrap();
    let wt = Var::from_tensor(&rng_tensor(&[3, 1, 7, 6], 15)).unwrap();
    let r = rng_tensor(&[2, 3], 16);
    let ours = depthwise(&x, &wt, 1, 0).unwrap().flatten_from(1).unwrap().mul(&r).unwrap().sum_all().unwrap();
    let theirs = x.broadcast_mul(&wt.reshape((1, 3, 7, 6)).unwrap()).unwrap().sum((2, 3)).unwrap();
    let (g1, g2) = (ours.backward().unwrap(), theirs.mul(&r).unwrap().sum_all().unwrap().backward().unwrap());
    for v in [x.as_tensor(), wt.as_tensor()] {
        assert!(max_abs(g1.get(v).unwrap(), g2.get(v).unwrap()) < 1e-4);
    }
}

#[test]
fn fused_batch_norm_matches_generic_ops() {
    use candle_core::Var;
    let x = Var::from_tensor(&rng_tensor(&[3, 4, 5, 6], 21).affine(3.0, 1.0).unwrap()).unwrap();
    let g = Var::from_tensor(&rng_tensor(&[4], 22)).unwrap();
    let b = Var::from_tensor(&rng_tensor(&[4], 23)).unwrap();
    let a = Var::from_tensor(&rng_tensor(&[4], 25).affine(0.5, 0.1).unwrap()).unwrap();
    let r = rng_tensor(&[3, 4, 5, 6], 24);
    // The textbook expression in generic candle ops.
    let mean = x.mean_keepdim((0, 2, 3)).unwrap();
    let c = x.broadcast_sub(&mean).unwrap();
    let var = c.sqr().unwrap().mean_keepdim((0, 2, 3)).unwrap();
    let want = c
        .broadcast_div(&(var.clone() + 1e-5).unwrap().sqrt().unwrap())
        .unwrap()
        .broadcast_mul(&g.reshape((1, 4, 1, 1)).unwrap())
        .unwrap()
        .broadcast_add(&b.reshape((1, 4, 1, 1)).unwrap())
        .unwrap();
    // PReLU as max(z, 0) + a·min(z, 0).
    let slope = a.reshape((1, 4, 1, 1)).unwrap();
    let want_prelu = (want.relu().unwrap() + want.minimum(0f32).unwrap().broadcast_mul(&slope).unwrap()).unwrap();
    for (prelu, want) in [(None, &want), (Some(a.as_tensor()), &want_prelu)] {
        let (y, stats) = campro_train::batchnorm::batch_norm_train(&x, &g, &b, 1e-5, prelu).unwrap();
        assert!(max_abs(&y, want) < 1e-5);
        assert!(max_abs(&stats.get(0).unwrap(), &mean.flatten_all().unwrap()) < 1e-5);
        assert!(max_abs(&stats.get(1).unwrap(), &var.flatten_all().unwrap()) < 1e-4);
        let ours = y.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
        let theirs = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
        let vars = [x.as_tensor(), g.as_tensor(), b.as_tensor()].into_iter().chain(prelu);
        for v in vars {
            let (a, e) = (ours.get(v).unwrap(), theirs.get(v).unwrap());
            assert!(max_abs(a, e) < 1e-4, "{}", max_abs(a, e));
        }
        assert_eq!(prelu.is_some(), ours.get(a.as_tensor()).is_some());
    }
}

#[test]
fn dense_matches_candle_convolution() {
    for (h, w, stride, k, pad) in [(9, 7, 1, 3, 1), (10, 8, 2, 3, 1), (9, 9, 2, 3, 1), (7, 6, 1, 1, 0), (8, 8, 1, 3, 0)]
    {
        let x = rng_tensor(&[2, 3, h, w], 5);
        let wt = rng_tensor(&[4, 3, k, k], 6);
        let want = x.conv2d(&wt, pad, stride, 1, 1).unwrap();
        let got = campro_train::conv::conv2d_generic(&x, &wt, stride, pad).unwrap();
        assert_eq!(got.dims(), want.dims(), "{h}x{w} stride {stride}");
        assert!(max_abs(&got, &want) < 1e-5, "{h}x{w} stride {stride}: {}", max_abs(&got, &want));
    }
}

#[test]
fn camera_matches_the_desktop_pipeline() {
    let params =
        campro::Params::from_file(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../params/color-inversion.json"))
            .unwrap();
    // A CCM with negative and > 1 entries, so the clip is exercised.
    let ccm = [[1.4, -0.3, -0.1], [-0.2, 1.3, -0.1], [0.05, -0.5, 1.45]];
    let curve: Vec<f64> = params.tone_curve.y().to_vec();
    let cam = Camera::from_values(ccm, &curve, 2.2, &Device::Cpu).unwrap();
    let mut p = params.clone();
    p.ccm = ccm;
    let x = ((rng_tensor(&[1, 3, 40, 50], 7) + 1.0).unwrap() * 0.5).unwrap();
    let got: Vec<f32> = cam.forward(&x).unwrap().flatten_all().unwrap().to_vec1().unwrap();
    let xs: Vec<f32> = x.flatten_all().unwrap().to_vec1().unwrap();
    let n = 40 * 50;
    let mut worst = 0f64;
    for i in 0..n {
        let rgb = [xs[i] as f64, xs[n + i] as f64, xs[2 * n + i] as f64];
        let want = campro::pipeline::process_f64(&p, rgb);
        for c in 0..3 {
            worst = worst.max((got[c * n + i] as f64 - want[c]).abs());
        }
    }
    // f32 throughout: a few ulps of 1 after pow, a 3-term dot product and the interpolation.
    assert!(worst < 2e-6, "worst {worst}");
}

#[test]
fn camera_gradients_by_hand() {
    // One pixel, identity CCM, k = 5 knots: linear value 0.3 sits in segment 1 (0.25..0.5)
    // at fraction 0.2, so d out / d curve = (0, 0.8, 0.2, 0, 0) and d out / d y = 4·(c2 − c1).
    let dev = Device::Cpu;
    let curve = [0.0, 0.1, 0.9, 0.95, 1.0];
    let cam = Camera::from_values([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], &curve, 2.2, &dev).unwrap();
    let lin = Tensor::new(&[0.3f32, 0.3, 0.3], &dev).unwrap().reshape((1, 3, 1, 1)).unwrap();
    let out = cam.forward_linear(&lin).unwrap();
    let r: Vec<f32> = out.flatten_all().unwrap().to_vec1().unwrap();
    assert!((r[0] - (0.8 * 0.1 + 0.2 * 0.9)).abs() < 1e-6);
    // Loss = red output only.
    let loss = out.narrow(1, 0, 1).unwrap().sum_all().unwrap();
    let g = loss.backward().unwrap();
    let gc: Vec<f32> = g.get(cam.curve.as_tensor()).unwrap().to_vec1().unwrap();
    for (a, b) in gc.iter().zip([0.0, 0.8, 0.2, 0.0, 0.0]) {
        assert!((a - b).abs() < 1e-6, "{gc:?}");
    }
    // d red / d ccm[0][j] = slope · lin[j] = 4·(0.9 − 0.1)·0.3 for every j; other rows 0.
    let gm: Vec<Vec<f32>> = g.get(cam.ccm.as_tensor()).unwrap().to_vec2().unwrap();
    for j in 0..3 {
        assert!((gm[0][j] - 4.0 * 0.8 * 0.3).abs() < 1e-5, "{gm:?}");
        assert_eq!(gm[1][j], 0.0);
    }
    // A clipped value passes no gradient to the CCM.
    let lin = Tensor::new(&[1.0f32, 1.0, 1.0], &dev).unwrap().reshape((1, 3, 1, 1)).unwrap();
    let cam2 = Camera::from_values([[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], &curve, 2.2, &dev).unwrap();
    let g = cam2.forward_linear(&lin).unwrap().narrow(1, 0, 1).unwrap().sum_all().unwrap().backward().unwrap();
    let gm: Vec<Vec<f32>> = g.get(cam2.ccm.as_tensor()).unwrap().to_vec2().unwrap();
    assert_eq!(gm[0], vec![0.0; 3]);
    // project() clamps into the ranges.
    let cam3 = Camera::from_values([[9.0, -7.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], &[-0.5, 0.5, 1.5], 2.2, &dev)
        .unwrap();
    cam3.project().unwrap();
    assert_eq!(cam3.ccm_values().unwrap()[0], [5.0, -5.0, 0.0]);
    assert_eq!(cam3.curve_values().unwrap(), vec![0.0, 0.5, 1.0]);
}

#[test]
fn mobilefacenet_checkpoint_matches_the_onnx_export() {
    let Some(ckpt) = shared::shared("models/mobilefacenet_casia_068.ckpt") else { return };
    let Some(face) = shared::shared("data/lfw/images_deepfunneled/Colin_Powell/Colin_Powell_0001.jpg") else { return };
    let models = ckpt.parent().unwrap();
    let (net, vars) = MobileFaceNet::from_checkpoint(&ckpt, &Device::Cpu).unwrap();
    // Every float tensor of the checkpoint is a variable of the network, and nothing else.
    let sd = campro_train::torch_legacy::read_state_dict(&ckpt, Some("net_state_dict")).unwrap();
    assert_eq!(vars.all_vars().len(), sd.len());
    // The optimiser never sees the running statistics (an SGD step on a running variance
    // once made it negative and the network NaN).
    let trainable = MobileFaceNet::trainable(&vars);
    let stats = sd.keys().filter(|k| k.contains("running_")).count();
    // 50 batch norms (conv1, dw_conv1, 3 in each of 15 bottlenecks, conv2, linear7, linear1).
    assert!(stats == 2 * 50 && trainable.len() == sd.len() - stats);
    // Align with the evaluation's own detector and template, then embed both ways.
    let manifests = Path::new(env!("CARGO_MANIFEST_DIR")).join("../campro-eval/models");
    let load = |n: &str| {
        campro_eval::model::Model::load(campro_eval::manifest::Manifest::load(&manifests.join(n), models).unwrap())
            .unwrap()
    };
    let det = campro_eval::face::FaceDetector::new(load("yunet.json")).unwrap();
    let emb = campro_eval::face::Embedder::new(load("mobilefacenet_casia.json")).unwrap();
    let img = campro_eval::data::read_rgb8(&face).unwrap();
    let f = campro_eval::face::central_face(&det.detect(&img).unwrap(), 250, 250).unwrap();
    let crop = emb.align(&img, &f.landmarks);
    let want = emb.embed(&crop).unwrap();
    let x = Tensor::from_vec(
        crop.as_raw().iter().map(|&v| v as f32 / 255.0).collect::<Vec<_>>(),
        (1, 112, 96, 3),
        &Device::Cpu,
    )
    .unwrap()
    .permute((0, 3, 1, 2))
    .unwrap();
    let e = net.forward_t(&normalise_unit(&x).unwrap(), false).unwrap();
    let e = campro_train::mobilefacenet::l2_normalise(&e).unwrap();
    let got: Vec<f32> = e.flatten_all().unwrap().to_vec1().unwrap();
    let cos: f32 = got.iter().zip(&want).map(|(a, b)| a * b).sum();
    let worst = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    // Batch norm folded into the ONNX convolutions changes only float rounding.
    assert!(cos > 0.99999 && worst < 1e-3, "cosine {cos}, worst {worst}");
    assert_eq!(e.dtype(), DType::F32);
}

#[test]
fn non_saturating_loss_by_hand_and_its_gradient_flows() {
    use candle_core::Var;
    // Logits (2, 0, 0), true class 0: p = e²/(e² + 2), −log(1 − p) = log((e² + 2) / 2).
    let z = Var::from_tensor(&Tensor::new(&[[2f32, 0., 0.]], &Device::Cpu).unwrap()).unwrap();
    let y = Tensor::new(&[0u32], &Device::Cpu).unwrap();
    let l = campro_train::train::non_saturating_loss(&z, &y).unwrap();
    let want = ((2f64.exp() + 2.0) / 2.0).ln();
    assert!((l.to_scalar::<f32>().unwrap() as f64 - want).abs() < 1e-5);
    // d/dz = softmax(z) − softmax(z without y): for y: p_y; others: p_j − 1/2.
    let g = l.backward().unwrap();
    let gz: Vec<Vec<f32>> = g.get(z.as_tensor()).unwrap().to_vec2().unwrap();
    let p = 2f64.exp() / (2f64.exp() + 2.0);
    let q = 1.0 / (2f64.exp() + 2.0);
    assert!((gz[0][0] as f64 - p).abs() < 1e-5 && (gz[0][1] as f64 - (q - 0.5)).abs() < 1e-5, "{gz:?}");
    // A confident attacker (p_y = 1 − 1e-13 in f64) still gives a finite loss and gradient.
    let z = Var::from_tensor(&Tensor::new(&[[40f32, 10., 10.]], &Device::Cpu).unwrap()).unwrap();
    let l = campro_train::train::non_saturating_loss(&z, &y).unwrap();
    assert!((l.to_scalar::<f32>().unwrap() - (30.0 - 2f32.ln())).abs() < 1e-3);
    assert!(l.backward().unwrap().get(z.as_tensor()).is_some());
}

#[test]
fn channel_affine_matches_generic_ops() {
    use candle_core::Var;
    let x = Var::from_tensor(&rng_tensor(&[3, 4, 5, 3], 21)).unwrap();
    let a = Var::from_tensor(&rng_tensor(&[4], 22)).unwrap();
    let b = Var::from_tensor(&rng_tensor(&[4], 23)).unwrap();
    let r = rng_tensor(&[3, 4, 5, 3], 24);
    let ours = campro_train::batchnorm::channel_affine(&x, &a, &b).unwrap();
    let want = x
        .broadcast_mul(&a.reshape((1, 4, 1, 1)).unwrap())
        .unwrap()
        .broadcast_add(&b.reshape((1, 4, 1, 1)).unwrap())
        .unwrap();
    assert!(max_abs(&ours, &want) < 1e-6);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [x.as_tensor(), a.as_tensor(), b.as_tensor()] {
        assert!(max_abs(g1.get(v).unwrap(), g2.get(v).unwrap()) < 1e-5);
    }
}

/// Forward against candle's conv2d, and both gradients of `sum(conv(x, w) · r)` against the
/// same convolution built from candle's generic ops (`mobilefacenet::dense`: one product per
/// tap on shifted copies, then subsampling). candle's own conv2d backward is not the reference:
/// for stride 2 on odd sizes its input gradient comes out a column short.
fn check_conv(x: &[usize], w: &[usize], stride: usize, pad: usize) {
    let xv = Var::from_tensor(&rng_tensor(x, 1)).unwrap();
    let wv = Var::from_tensor(&rng_tensor(w, 2)).unwrap();
    let ours = conv2d(xv.as_tensor(), wv.as_tensor(), stride, pad).unwrap();
    let reference = xv.as_tensor().conv2d(wv.as_tensor(), pad, stride, 1, 1).unwrap();
    assert_eq!(ours.dims(), reference.dims(), "x {x:?} w {w:?} s {stride} p {pad}");
    assert!(max_abs(&ours, &reference) < 1e-5, "forward x {x:?} w {w:?}");
    let r = rng_tensor(ours.dims(), 3);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let generic = campro_train::conv::conv2d_generic(xv.as_tensor(), wv.as_tensor(), stride, pad).unwrap();
    assert!(max_abs(&generic, &reference) < 1e-5);
    let g2 = generic.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&xv, &wv] {
        let (a, b) = (g1.get(v.as_tensor()).unwrap(), g2.get(v.as_tensor()).unwrap());
        assert!(max_abs(a, b) < 1e-4, "gradient x {x:?} w {w:?} s {stride} p {pad}: {}", max_abs(a, b));
    }
}

#[test]
fn conv2d_matches_candle_forward_and_backward() {
    for threads in [1, 3] {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| {
            check_conv(&[2, 3, 7, 6], &[4, 3, 3, 3], 1, 1);
            check_conv(&[2, 3, 7, 6], &[4, 3, 3, 3], 2, 1);
            check_conv(&[3, 5, 8, 9], &[6, 5, 1, 1], 1, 0);
            check_conv(&[1, 5, 8, 9], &[6, 5, 1, 1], 2, 0);
            check_conv(&[1, 2, 5, 5], &[3, 2, 5, 3], 1, 2);
            check_conv(&[4, 3, 6, 6], &[2, 3, 2, 2], 2, 0);
        });
    }
}

#[test]
fn conv2d_skips_gradients_nobody_reads() {
    // A frozen weight (not a variable): only the input's gradient exists, and it equals the
    // tracked case's.
    let x = Var::from_tensor(&rng_tensor(&[2, 3, 6, 5], 4)).unwrap();
    let w = rng_tensor(&[4, 3, 3, 3], 5);
    let g = conv2d(x.as_tensor(), &w, 1, 1).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(g.get(&w).is_none());
    let wv = Var::from_tensor(&w).unwrap();
    let g2 = conv2d(x.as_tensor(), wv.as_tensor(), 1, 1).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(max_abs(g.get(x.as_tensor()).unwrap(), g2.get(x.as_tensor()).unwrap()) == 0.0);
    assert!(conv2d(&rng_tensor(&[1, 3, 2, 2], 1), &rng_tensor(&[1, 4, 3, 3], 1), 1, 0).is_err());
}

#[test]
fn prelu_matches_candle_and_finite_differences() {
    let x = Var::from_tensor(&rng_tensor(&[3, 4, 5, 2], 6)).unwrap();
    let a = Var::from_tensor(&(rng_tensor(&[4], 7) * 0.5).unwrap()).unwrap();
    let ours = prelu(x.as_tensor(), a.as_tensor()).unwrap();
    let ab = a.as_tensor().reshape((1, 4, 1, 1)).unwrap();
    let reference = (x.as_tensor().relu().unwrap()
        - x.as_tensor().neg().unwrap().relu().unwrap().broadcast_mul(&ab).unwrap())
    .unwrap();
    assert!(max_abs(&ours, &reference) < 1e-7);
    let r = rng_tensor(ours.dims(), 8);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = reference.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&x, &a] {
        assert!(max_abs(g1.get(v.as_tensor()).unwrap(), g2.get(v.as_tensor()).unwrap()) < 1e-5);
    }
    // Finite differences on the slopes (the loss is linear in each slope: exact up to f32).
    let f =
        |a: &Tensor| prelu(x.as_tensor(), a).unwrap().mul(&r).unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap();
    let da = g1.get(a.as_tensor()).unwrap().to_vec1::<f32>().unwrap();
    for c in 0..4 {
        let mut e = vec![0f32; 4];
        e[c] = 1e-2;
        let step = Tensor::from_vec(e, 4, &Device::Cpu).unwrap();
        let fd = (f(&(a.as_tensor() + &step).unwrap()) - f(&(a.as_tensor() - &step).unwrap())) / 2e-2;
        assert!((fd - da[c]).abs() < 2e-3, "slope {c}: {fd} vs {}", da[c]);
    }
}

#[test]
fn relu_matches_candles_with_its_gradient() {
    use campro_train::conv::relu;
    // A transposed (strided) input.
    let x = Var::from_tensor(&(rng_tensor(&[2, 3, 5, 4], 12) * 3.0).unwrap()).unwrap();
    let xt = x.as_tensor().transpose(2, 3).unwrap();
    let r = rng_tensor(&[2, 3, 4, 5], 13);
    let ours = relu(&xt).unwrap();
    let want = xt.relu().unwrap();
    assert_eq!(max_abs(&ours, &want), 0.0);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    assert_eq!(max_abs(g1.get(x.as_tensor()).unwrap(), g2.get(x.as_tensor()).unwrap()), 0.0);
    // Zero where the input is negative.
    let neg = Var::from_tensor(&(rng_tensor(&[7], 14).abs().unwrap() * -1.0).unwrap()).unwrap();
    let g = relu(neg.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap();
    assert_eq!(g.get(neg.as_tensor()).unwrap().abs().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap(), 0.0);
}

#[test]
fn silu_and_channel_bias_match_generic_ops() {
    use campro_train::conv::{channel_bias, silu};
    let x = Var::from_tensor(&(rng_tensor(&[2, 3, 4, 5], 9) * 6.0).unwrap()).unwrap();
    let b = Var::from_tensor(&rng_tensor(&[3], 10)).unwrap();
    let r = rng_tensor(&[2, 3, 4, 5], 11);
    // SiLU against Sigmoid then Mul, as the ONNX graph has it.
    let ours = silu(x.as_tensor()).unwrap();
    let want = x.as_tensor().mul(&candle_nn::ops::sigmoid(x.as_tensor()).unwrap()).unwrap();
    assert!(max_abs(&ours, &want) < 1e-5);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(max_abs(g1.get(x.as_tensor()).unwrap(), g2.get(x.as_tensor()).unwrap()) < 1e-5);
    // The bias against a broadcast add.
    let ours = channel_bias(x.as_tensor(), b.as_tensor()).unwrap();
    let want = x.as_tensor().broadcast_add(&b.as_tensor().reshape((1, 3, 1, 1)).unwrap()).unwrap();
    assert!(max_abs(&ours, &want) == 0.0);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&x, &b] {
        assert!(max_abs(g1.get(v.as_tensor()).unwrap(), g2.get(v.as_tensor()).unwrap()) < 1e-5);
    }
}

/// The patched backward (vendor/candle-core: a node's first gradient stored as it is, not
/// added to zeros) still sums every use of a tensor: y = Σ (x·x + x + relu(x)·x) has
/// dy/dx = 2x + 1 + 2·relu(x), and a broadcast weight's gradient is the sum over the batch.
#[test]
fn candle_backward_sums_every_use_of_a_tensor() {
    let x = Var::from_tensor(&rng_tensor(&[3, 4], 31)).unwrap();
    let w = Var::from_tensor(&rng_tensor(&[4], 32)).unwrap();
    let xt = x.as_tensor();
    let y = ((xt * xt).unwrap() + xt).unwrap();
    let y = (y + (xt.relu().unwrap() * xt).unwrap()).unwrap();
    let y = (y.sum_all().unwrap() + xt.broadcast_mul(w.as_tensor()).unwrap().sum_all().unwrap()).unwrap();
    let g = y.backward().unwrap();
    let xv: Vec<f32> = xt.flatten_all().unwrap().to_vec1().unwrap();
    let wv: Vec<f32> = w.as_tensor().to_vec1().unwrap();
    let gx: Vec<f32> = g.get(xt).unwrap().flatten_all().unwrap().to_vec1().unwrap();
    for (i, (&v, &d)) in xv.iter().zip(&gx).enumerate() {
        let want = 2.0 * v + 1.0 + 2.0 * v.max(0.0) + wv[i % 4];
        assert!((d - want).abs() < 1e-5, "x {v}: {d} against {want}");
    }
    let gw: Vec<f32> = g.get(w.as_tensor()).unwrap().to_vec1().unwrap();
    for (j, &d) in gw.iter().enumerate() {
        let want: f32 = (0..3).map(|r| xv[r * 4 + j]).sum();
        assert!((d - want).abs() < 1e-5, "w {j}: {d} against {want}");
    }
}
