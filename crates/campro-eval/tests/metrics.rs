//! The metric code against hand-derived values and independent reference implementations
//! (values printed by `tools/reference_values.py`).

use campro_eval::ap::{evaluate, GroundTruth, Scored};
use campro_eval::quality::{ms_ssim, psnr, rmse, ssim};
use image::RgbImage;

fn gt(b: [f32; 4], crowd: bool) -> GroundTruth {
    GroundTruth { bbox: b, crowd }
}
fn det(b: [f32; 4], score: f32) -> Scored {
    Scored { bbox: b, score }
}

/// Two images, three people and a crowd region. IoUs: d1 1, d2 0.62, d3 0, d4 0.81, d5 1
/// (a duplicate of d4's person), d6 inside the crowd region.
///
/// By hand, in score order d4 .95, d1 .9, d6 .85 (ignored: crowd), d2 .8, d3 .7, d5 .6:
/// - t ≤ 0.60: TP TP TP FP FP, precision 1 up to recall 1: AP 1.
/// - 0.65 ≤ t ≤ 0.80: d2 misses: TP TP FP FP FP, precision 1 up to recall 2/3, then none:
///   67 of the 101 recall points (0.00..0.66) score 1: 67/101.
/// - t ≥ 0.85: d4 misses, so d5 takes its person: FP TP FP FP TP; interpolated precision
///   0.5 up to recall 1/3 (34 points), 0.4 up to 2/3 (33 points): 30.2/101.
/// - AP = (3 + 4·67/101 + 3·30.2/101) / 10 = 0.6550495..., AP50 = 1, AP75 = 67/101.
///
/// pycocotools 2.0 prints AP 0.655049504950, AP50 1.000000000000, AP75 0.663366336634.
#[test]
fn coco_ap_matches_the_hand_derivation_and_pycocotools() {
    let images = vec![
        (
            vec![gt([0., 0., 10., 10.], false), gt([20., 20., 10., 10.], false)],
            vec![det([0., 0., 10., 10.], 0.9), det([20., 20., 10., 6.2], 0.8), det([50., 50., 10., 10.], 0.7)],
        ),
        (
            vec![gt([0., 0., 20., 20.], false), gt([40., 40., 30., 30.], true)],
            vec![det([0., 0., 20., 16.2], 0.95), det([0., 0., 20., 20.], 0.6), det([45., 45., 10., 10.], 0.85)],
        ),
    ];
    let m = evaluate(&images, 0.25);
    let by_hand = (3.0 + 4.0 * 67.0 / 101.0 + 3.0 * 30.2 / 101.0) / 10.0;
    assert!((m.ap - by_hand).abs() < 1e-12, "AP {} vs {by_hand}", m.ap);
    assert!((m.ap - 0.655049504950).abs() < 1e-11);
    assert_eq!(m.ap50, 1.0);
    assert!((m.ap75 - 67.0 / 101.0).abs() < 1e-12 && (m.ap75 - 0.663366336634).abs() < 1e-11);
    // At confidence 0.25, IoU 0.5: TP d4 d1 d2, FP d3 d5, d6 ignored; 3 people.
    assert_eq!(m.ground_truths, 3);
    assert!((m.precision - 0.6).abs() < 1e-12 && m.recall == 1.0 && (m.f1 - 0.75).abs() < 1e-12);
    // A higher confidence keeps only d4 and d1.
    let m = evaluate(&images, 0.88);
    assert!(m.precision == 1.0 && (m.recall - 2.0 / 3.0).abs() < 1e-12);
}

#[test]
fn coco_ap_edge_cases() {
    // No ground truth: AP undefined (−1), as pycocotools.
    let m = evaluate(&[(vec![], vec![det([0., 0., 5., 5.], 0.9)])], 0.25);
    assert_eq!((m.ap, m.ap50), (-1.0, -1.0));
    // A person and no detection: AP 0, recall 0.
    let m = evaluate(&[(vec![gt([0., 0., 5., 5.], false)], vec![])], 0.25);
    assert_eq!((m.ap, m.recall, m.precision), (0.0, 0.0, 0.0));
    // Only the 100 best detections of an image count: a perfect box ranked 101st is lost.
    let mut dets: Vec<Scored> = (0..100).map(|i| det([100. + i as f32, 0., 1., 1.], 0.9)).collect();
    dets.push(det([0., 0., 5., 5.], 0.1));
    let m = evaluate(&[(vec![gt([0., 0., 5., 5.], false)], dets)], 0.0);
    assert_eq!((m.ap, m.detections), (0.0, 100));
}

/// The integer pattern of `tools/reference_values.py`.
fn pattern(w: u32, h: u32) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| {
        let v = |c: u32| ((x * x * 3 + y * 5 + c * 40 + (x * y) % 17 * 4) % 256) as u8;
        image::Rgb([v(0), v(1), v(2)])
    })
}

/// `pattern` plus LCG noise in [−20, 20], row-major over (y, x, c), clamped.
fn noisy(a: &RgbImage) -> RgbImage {
    let mut out = a.clone();
    let mut state: u64 = 1;
    for v in out.iter_mut() {
        state = (state * 1103515245 + 12345) % (1 << 31);
        *v = (*v as i64 + ((state >> 16) % 41) as i64 - 20).clamp(0, 255) as u8;
    }
    out
}

/// 3/4 contrast, +40, an 8-px checkerboard of 30.
fn restyled(a: &RgbImage) -> RgbImage {
    RgbImage::from_fn(a.width(), a.height(), |x, y| {
        let p = a.get_pixel(x, y).0;
        image::Rgb(p.map(|v| (v as u32 * 3 / 4 + 40 + ((x / 8 + y / 8) % 2) * 30).min(255) as u8))
    })
}

#[test]
fn ssim_matches_scikit_image() {
    // skimage 0.26 structural_similarity(gaussian_weights, sigma 1.5, use_sample_covariance
    // False, data_range 255, channel_axis -1).
    let a = pattern(64, 48);
    for (b, want) in [(noisy(&a), 0.980188616882), (restyled(&a), 0.916366397254)] {
        let got = ssim(&a, &b);
        assert!((got - want).abs() < 1e-9, "SSIM {got} vs skimage {want}");
    }
}

#[test]
fn ms_ssim_matches_tensorflow() {
    // tf.image.ssim_multiscale(max_val 255); 192x176 halves evenly four times. TensorFlow
    // builds its Gaussian window in float32 whatever the image type (its SSIM of the 64x48
    // pairs is 2.3e-7 off skimage's), so the agreement is float32-deep: measured 8.1e-7.
    let a = pattern(192, 176);
    for (b, want) in [(noisy(&a), MS_SSIM_NOISY), (restyled(&a), MS_SSIM_RESTYLED)] {
        let got = ms_ssim(&a, &b).unwrap();
        assert!((got - want).abs() < 2e-6, "MS-SSIM {got} vs TensorFlow {want}");
    }
    // Too small for five scales.
    assert!(ms_ssim(&pattern(175, 200), &pattern(175, 200)).is_none());
}

#[test]
fn rmse_and_psnr_of_the_noisy_pair_by_direct_sum() {
    let a = pattern(64, 48);
    let b = noisy(&a);
    let sq: f64 = a.iter().zip(b.iter()).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum();
    let want = (sq / (64.0 * 48.0 * 3.0)).sqrt();
    assert!((rmse(&a, &b) - want).abs() < 1e-12);
    // Uniform noise on [−20, 20] has RMS sqrt(140) ≈ 11.8 before clamping.
    assert!((9.0..12.5).contains(&want), "rmse {want}");
    assert!((psnr(&a, &b) - 20.0 * (255.0 / want).log10()).abs() < 1e-12);
}

/// tf.image.ssim_multiscale of the two 192x176 pairs (TensorFlow 2.21, float64).
const MS_SSIM_NOISY: f64 = 0.993202269077;
const MS_SSIM_RESTYLED: f64 = 0.811733484268;
