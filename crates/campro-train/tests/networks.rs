//! The differentiable camera against campro's f64 pipeline and by hand, and the privacy
//! loss by hand. (The ops and networks are tested in campro-nn.)

use campro_train::camera::Camera;
use candle_core::{Device, Tensor};
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

#[test]
fn camera_matches_the_desktop_pipeline() {
    let params =
        campro::Params::from_file(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../params/color-inversion.json"))
            .unwrap();
    let curve: Vec<f64> = params.tone_curves.channel(0).y().to_vec();
    matches_the_desktop_pipeline(&params, &[curve]);
}

#[test]
fn camera_with_a_curve_per_channel_matches_the_desktop_pipeline() {
    // Three different 32-knot curves: inverted, a sine, a square root.
    let k = 32;
    let rows: Vec<Vec<f64>> = [
        Box::new(|t: f64| 1.0 - t) as Box<dyn Fn(f64) -> f64>,
        Box::new(|t: f64| (7.0 * t).sin() * 0.5 + 0.5),
        Box::new(|t: f64| t.sqrt()),
    ]
    .iter()
    .map(|f| (0..k).map(|i| f(i as f64 / (k - 1) as f64)).collect())
    .collect();
    let curve = |y: &Vec<f64>| campro::ToneCurve::uniform(y.clone()).unwrap();
    let curves = campro::ToneCurves::per_channel([curve(&rows[0]), curve(&rows[1]), curve(&rows[2])]);
    assert!(curves.shared().is_none());
    let params = campro::Params::new(campro::ccm::IDENTITY, curves, 2.2).unwrap();
    matches_the_desktop_pipeline(&params, &rows);
}

/// The camera with `params`' curves (`rows`: one, or three) and a CCM with negative and
/// > 1 entries, so the clip is exercised, against the f64 pipeline.
fn matches_the_desktop_pipeline(params: &campro::Params, rows: &[Vec<f64>]) {
    let ccm = [[1.4, -0.3, -0.1], [-0.2, 1.3, -0.1], [0.05, -0.5, 1.45]];
    let cam = Camera::from_values(ccm, rows, 2.2, &Device::Cpu).unwrap();
    assert_eq!(cam.per_channel(), rows.len() == 3);
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
    let curve = vec![vec![0.0, 0.1, 0.9, 0.95, 1.0]];
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
    let cam3 =
        Camera::from_values([[9.0, -7.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], &[vec![-0.5, 0.5, 1.5]], 2.2, &dev)
            .unwrap();
    cam3.project().unwrap();
    assert_eq!(cam3.ccm_values().unwrap()[0], [5.0, -5.0, 0.0]);
    assert_eq!(cam3.curve_values().unwrap(), vec![vec![0.0, 0.5, 1.0]]);
}

#[test]
fn a_set_continues_exactly_on_a_grid_that_holds_its_knots() {
    use campro_train::train::refine_knots;
    // By hand: 3 knots on 5.
    assert_eq!(refine_knots(&[vec![0.0, 1.0, 0.0]], 5), Some(vec![vec![0.0, 0.5, 1.0, 0.5, 0.0]]));
    // 32 knots on 63 (and on themselves): the same function at any input; other counts refused.
    let y: Vec<f64> = (0..32).map(|i| ((i * 7) % 32) as f64 / 31.0).collect();
    let old = campro::ToneCurve::uniform(y.clone()).unwrap();
    for knots in [32, 63, 94] {
        let fine = refine_knots(&[y.clone(), y.clone(), y.clone()], knots).unwrap();
        assert_eq!(fine.len(), 3);
        let new = campro::ToneCurve::uniform(fine[1].clone()).unwrap();
        assert_eq!(new.len(), knots);
        assert!(new.max_abs_diff(&old) < 1e-15, "{knots}: {}", new.max_abs_diff(&old));
    }
    for knots in [2, 31, 64, 65] {
        assert_eq!(refine_knots(std::slice::from_ref(&y), knots), None, "{knots}");
    }
}

#[test]
fn a_curve_per_channel_takes_only_its_channels_gradient() {
    // Three 5-knot curves, identity CCM; linear (0.3, 0.6, 0.9): red in segment 1 at
    // fraction 0.2, green in segment 2 at 0.4, blue in segment 3 at 0.6. A loss of
    // red + 2 green reaches only red's knots 1, 2 and green's knots 2, 3 (twice); blue's
    // row gets nothing.
    let dev = Device::Cpu;
    let rows = vec![vec![0.0, 0.1, 0.9, 0.95, 1.0], vec![1.0, 0.8, 0.5, 0.2, 0.0], vec![0.0, 0.25, 0.5, 0.75, 1.0]];
    let cam = Camera::from_values(campro::ccm::IDENTITY, &rows, 2.2, &dev).unwrap();
    let lin = Tensor::new(&[0.3f32, 0.6, 0.9], &dev).unwrap().reshape((1, 3, 1, 1)).unwrap();
    let out = cam.forward_linear(&lin).unwrap();
    let r: Vec<f32> = out.flatten_all().unwrap().to_vec1().unwrap();
    let want = [0.8 * 0.1 + 0.2 * 0.9, 0.6 * 0.5 + 0.4 * 0.2, 0.4 * 0.75 + 0.6 * 1.0];
    for c in 0..3 {
        assert!((r[c] as f64 - want[c]).abs() < 1e-6, "{r:?}");
    }
    let weights = Tensor::new(&[1f32, 2.0, 0.0], &dev).unwrap().reshape((1, 3, 1, 1)).unwrap();
    let g = out.mul(&weights).unwrap().sum_all().unwrap().backward().unwrap();
    let gc: Vec<Vec<f32>> = g.get(cam.curve.as_tensor()).unwrap().to_vec2().unwrap();
    let expect = [[0.0, 0.8, 0.2, 0.0, 0.0], [0.0, 0.0, 1.2, 0.8, 0.0], [0.0; 5]];
    for c in 0..3 {
        for i in 0..5 {
            assert!((gc[c][i] as f64 - expect[c][i]).abs() < 1e-6, "{gc:?}");
        }
    }
    assert!(Camera::from_values(campro::ccm::IDENTITY, &rows[..2], 2.2, &dev).is_err());
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
