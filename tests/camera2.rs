//! Camera2 mapping: the range-scaling proof, emulated device vs desktop pipeline against
//! the stated bound, colour-temperature deployment, capture results.

use campro::ccm::{self, Mat3};
use campro::color_temp::{self, CtCcm, DngCalibration};
use campro::compare::{code_cube, deployment_vs_desktop, grey_levels, random_pixels};
use campro::emulate::DeviceModel;
use campro::pipeline::{clip01, from_linear};
use campro::targets::camera2::Camera2;
use campro::targets::camera2::{self, convert, Options, RationalMode, MATRIX_RANGE};
use campro::targets::Target;
use campro::{Params, ToneCurve};

/// A typical phone sensor -> sRGB matrix (rows sum to 1, strong off-diagonals).
const PHONE: Mat3 = [[1.78, -0.62, -0.16], [-0.28, 1.62, -0.34], [0.02, -0.71, 1.69]];

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

fn random_params(rng: &mut Lcg, ccm_mag: f64, knots: usize) -> Params {
    let ccm = [[0.0; 3]; 3].map(|r: [f64; 3]| r.map(|_| rng.range(-ccm_mag, ccm_mag)));
    let y = (0..knots).map(|_| rng.next()).collect();
    Params::new(ccm, ToneCurve::uniform(y).unwrap(), 2.2).unwrap()
}

/// Dividing the matrix by s and folding s into the curve changes nothing: with the
/// unrounded scaled matrix and folded curve, the device equals the desktop pipeline on
/// every input (to f64 rounding), for matrices far outside Camera2's range.
#[test]
fn range_scaling_is_exact() {
    let mut rng = Lcg(3);
    let mut scaled = 0;
    for _ in 0..200 {
        let p = random_params(&mut rng, 5.0, 32);
        let dev = if rng.next() < 0.5 { ccm::IDENTITY } else { PHONE };
        let v = convert(&p, &dev, &Options::default()).unwrap();
        let (lo, hi) = ccm::min_max(&v.matrix());
        assert!(lo >= MATRIX_RANGE.0 && hi <= MATRIX_RANGE.1, "sent matrix in range");
        let s = v.scale;
        scaled += (s > 1.0) as usize;
        let m = ccm::scale(&v.composed, 1.0 / s);
        let folded = p.tone_curves.channel(0).fold_scale(s);
        let inv = ccm::inverse(&dev).unwrap();
        for _ in 0..500 {
            let lin = [rng.next(), rng.next(), rng.next()];
            let sensor = ccm::apply(&inv, lin);
            let device = clip01(ccm::apply(&m, sensor)).map(|t| folded.eval(t));
            let desktop = from_linear(&p, lin);
            for k in 0..3 {
                assert!(
                    (device[k] - desktop[k]).abs() < 1e-9 * s * p.tone_curves.channel(0).max_slope().max(1.0),
                    "s={s} {device:?} vs {desktop:?}"
                );
            }
        }
    }
    assert!(scaled > 150, "most random ±5 matrices need scaling ({scaled})");
}

/// The fixtures' test images (random RGB, gradient), when ../shared is present.
fn fixture_pixels() -> Vec<[u8; 3]> {
    let mut px = Vec::new();
    for name in ["image_random.npy", "image_gradient.npy"] {
        if let Some(path) = campro_testkit::shared(&format!("fixtures/campro-pt/{name}")) {
            px.extend(campro_testkit::npy(&path).1.chunks(3).map(|c| [c[0] as u8, c[1] as u8, c[2] as u8]));
        }
    }
    px
}

/// Camera2 through the same path as every target: export, read back, emulate, compare.
fn check_bound(p: &Params, dev: &Mat3, opts: &Options, model: &DeviceModel) -> (f64, f64) {
    let t = Camera2::new(*dev, *opts, *model);
    let exported = t.export(p, None).unwrap();
    let conditions = t.emulate(p, &exported, None).unwrap();
    let [c] = &conditions[..] else { panic!("camera2 is checked under one condition") };
    let bound = c.bound.expect("camera2 states a bound");
    let mut worst = 0.0f64;
    for px in [grey_levels(), code_cube(15), random_pixels(20_000, 9), fixture_pixels()] {
        let s = deployment_vs_desktop(p, &c.feed, c.emulator.as_ref(), &px).unwrap();
        // 1e-12: f64 rounding when synthesising sensor RGB through the inverse matrix.
        assert!(s.max_abs <= bound + 1e-12, "{}: measured {} > bound {}", p.name, s.max_abs, bound);
        worst = worst.max(s.max_abs);
    }
    (worst * 255.0, bound * 255.0)
}

/// Default settings: every bundled set and every fixture checkpoint, on an identity and
/// a phone-like device, stays within its bound and within 0.5 LSB.
#[test]
fn default_settings_stay_within_half_an_lsb() {
    let dir = campro_testkit::workspace_root().join("params");
    // The parameter files (an enhancer's ONNX file may sit beside its preset).
    let mut sets: Vec<Params> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .map(|p| Params::from_file(&p).unwrap())
        .collect();
    if let Some(fx) = campro_testkit::shared("fixtures/campro-pt") {
        for e in std::fs::read_dir(fx).unwrap() {
            let path = e.unwrap().path();
            if path.extension().is_some_and(|x| x == "pt") {
                sets.push(campro::import_pt::read_checkpoint(&path).unwrap());
            }
        }
    }
    for p in &sets {
        for dev in [ccm::IDENTITY, PHONE] {
            let (max, bound) = check_bound(p, &dev, &Options::default(), &DeviceModel::default());
            eprintln!("{:<28} max {max:.2e} LSB, bound {bound:.2e} LSB", p.name);
            assert!(max <= 0.5, "{}: {max} LSB", p.name);
        }
    }
}

/// Coarser settings (fixed denominators, HAL rounding, small LUTs, few curve points)
/// make larger errors, and the bound still holds.
#[test]
fn bound_holds_for_coarse_devices() {
    let mut rng = Lcg(11);
    for i in 0..24 {
        let p = random_params(&mut rng, if i % 2 == 0 { 1.5 } else { 5.0 }, 32);
        let opts = Options {
            max_curve_points: [64, 16, 8][i % 3],
            rational: if i % 4 < 2 {
                RationalMode::Fixed { denominator: 1024 }
            } else {
                RationalMode::Best { max_denominator: 100 }
            },
        };
        let model = DeviceModel {
            matrix_frac_bits: [None, Some(10), Some(7)][i % 3],
            lut_size: [None, Some(256), Some(64), Some(1024)][i % 4],
        };
        let (max, bound) = check_bound(&p, &PHONE, &opts, &model);
        assert!(max > 0.0 && bound >= max);
    }
}

#[test]
fn fixed_denominators_cost_more_than_best_rationals() {
    let p = Params::new(
        [[1.3137, -0.2071, -0.1066], [-0.1777, 1.4131, -0.2365], [0.0123, -0.4567, 1.4444]],
        ToneCurve::from_fn(32, |t| t.powf(0.45)),
        2.2,
    )
    .unwrap();
    let best = convert(&p, &PHONE, &Options::default()).unwrap();
    let fixed =
        convert(&p, &PHONE, &Options { rational: RationalMode::Fixed { denominator: 1024 }, ..Options::default() })
            .unwrap();
    assert!(best.report.matrix_max_abs <= 0.5 / camera2::DEFAULT_MAX_DENOMINATOR as f64);
    assert!(fixed.report.matrix_max_abs <= 0.5 / 1024.0);
    assert!(fixed.report.matrix_max_abs > 10.0 * best.report.matrix_max_abs);
    assert!(fixed.report.bound > best.report.bound);
}

/// Paper appendix: composing every calibrated CCM with CamPro's, then interpolating, is
/// the same as interpolating, then composing, at any colour temperature.
#[test]
fn calibrated_ccm_deployment_agrees_with_runtime_composition() {
    let mut rng = Lcg(5);
    let cal: Vec<CtCcm> = [2300.0, 2856.0, 4150.0, 5000.0, 6504.0, 7500.0]
        .iter()
        .map(|&ct| CtCcm { ct_kelvin: ct, ccm: [[0.0; 3]; 3].map(|r: [f64; 3]| r.map(|_| rng.range(-1.0, 2.0))) })
        .collect();
    let opt = random_params(&mut rng, 3.0, 32).ccm;
    let composed = color_temp::compose_calibration(&cal, &opt);
    for ct in [1000.0, 2300.0, 2500.0, 2856.0, 3500.0, 5000.0, 6000.0, 7499.0, 7500.0, 12000.0] {
        let a = color_temp::interpolate(&composed, ct).unwrap();
        let b = ccm::mul(&opt, &color_temp::interpolate(&cal, ct).unwrap());
        assert!(ccm::max_abs_diff(&a, &b) < 1e-12, "ct {ct}");
    }
}

#[test]
fn dng_two_illuminant_device_transform() {
    // Forward matrices: equal ones must give XYZ_D50_TO_SRGB · FM at any CT.
    let fm = [[0.6, 0.3, 0.1], [0.25, 0.7, 0.05], [0.05, 0.1, 0.7]];
    let cal = DngCalibration { illuminant1: 17, forward_matrix1: fm, illuminant2: 21, forward_matrix2: fm };
    let m = cal.device_transform(4000.0).unwrap();
    assert!(ccm::max_abs_diff(&m, &ccm::mul(&color_temp::XYZ_D50_TO_SRGB, &fm)) < 1e-15);
    // Different ones: at the illuminants' own CTs, each one alone.
    let fm2 = ccm::scale(&fm, 1.1);
    let cal = DngCalibration { forward_matrix2: fm2, ..cal };
    assert!(
        ccm::max_abs_diff(&cal.device_transform(2850.0).unwrap(), &ccm::mul(&color_temp::XYZ_D50_TO_SRGB, &fm)) < 1e-15
    );
    assert!(
        ccm::max_abs_diff(&cal.device_transform(6500.0).unwrap(), &ccm::mul(&color_temp::XYZ_D50_TO_SRGB, &fm2))
            < 1e-15
    );
    assert!(DngCalibration { illuminant1: 99, ..cal.clone() }.device_transform(5000.0).is_err());
}

#[test]
fn capture_result_forms() {
    let m = camera2::device_transform_from_capture_result(r#"{"android.colorCorrection.transform": [178,100,-62,100,-16,100,-28,100,162,100,-34,100,2,100,-71,100,169,100]}"#).unwrap();
    assert!(ccm::max_abs_diff(&m, &PHONE) < 1e-15);
    let m = camera2::device_transform_from_capture_result(
        r#"{"colorCorrectionTransform": [[1.78,-0.62,-0.16],[-0.28,1.62,-0.34],[0.02,-0.71,1.69]]}"#,
    )
    .unwrap();
    assert_eq!(m, PHONE);
    for bad in [
        r#"{}"#,
        r#"{"colorCorrectionTransform": [1, 2]}"#,
        r#"{"colorCorrectionTransform": [1,0,0,1,0,1,0,1,1,1,0,1,0,1,0,1,1,0]}"#,
        "not json",
    ] {
        assert!(camera2::device_transform_from_capture_result(bad).is_err(), "{bad}");
    }
}

#[test]
fn singular_device_matrix_cannot_be_compared() {
    let p = Params::identity_curve(32);
    let sing = [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
    let t = Camera2::new(sing, Options::default(), DeviceModel::default());
    let conditions = t.emulate(&p, &t.export(&p, None).unwrap(), None).unwrap();
    assert_eq!(conditions[0].bound, None, "no bound without sensor RGB to synthesise");
    let c = &conditions[0];
    let e = deployment_vs_desktop(&p, &c.feed, c.emulator.as_ref(), &grey_levels()).unwrap_err();
    assert_eq!(e.field(), "device_ccm");
}
