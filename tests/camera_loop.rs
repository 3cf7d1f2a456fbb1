//! The camera loop: skipped updates stay within the stated bound, recomputed ones equal
//! the one-shot conversion, and the counters say what was saved.

use campro::ccm::{self, Mat3};
use campro::color_temp::{CtCcm, DngCalibration};
use campro::emulate::{DeviceModel, Emulator};
use campro::pipeline::from_linear;
use campro::targets::camera2::{convert, Camera2Values, Options};
use campro::targets::camera2::{Camera2Loop, DEFAULT_TOLERANCE};
use campro::{Params, ToneCurve};

const PHONE: Mat3 = [[1.78, -0.62, -0.16], [-0.28, 1.62, -0.34], [0.02, -0.71, 1.69]];

fn params() -> Params {
    let ccm = [[1.2101, 0.0430, -0.6679], [-4.3933, 1.1114, -2.2755], [0.2930, 1.3570, 1.3287]];
    Params::new(ccm, ToneCurve::from_fn(32, |t| (7.0 * t).sin() * 0.5 + 0.5), 2.2).unwrap()
}

fn nudge(m: &Mat3, eps: f64) -> Mat3 {
    let mut out = *m;
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v += eps * (((i * 3 + j) as f64 * 2.399).sin());
        }
    }
    out
}

/// Largest |device - desktop| over a grid of sensor RGB in [0, 1]^3, for a device that
/// received `values` while its true transform is `device`.
fn measured(p: &Params, device: &Mat3, values: &Camera2Values) -> f64 {
    let dev = campro::targets::camera2::device(values.matrix(), values.curves(), &DeviceModel::default());
    let mut worst: f64 = 0.0;
    let n = 24;
    for r in 0..=n {
        for g in 0..=n {
            for b in 0..=n {
                let s = [r as f64 / n as f64, g as f64 / n as f64, b as f64 / n as f64];
                let got = dev.sensor_to_output(s);
                let want = from_linear(p, ccm::apply(device, s));
                for k in 0..3 {
                    worst = worst.max((got[k] - want[k]).abs());
                }
            }
        }
    }
    worst
}

#[test]
fn unchanged_scene_costs_no_recompute() {
    let mut l = Camera2Loop::new(params(), Options::default(), DEFAULT_TOLERANCE).unwrap();
    let first = l.update(&PHONE).unwrap();
    assert!(first.recomputed);
    let (v1, b1) = (first.values.clone(), first.bound);
    let again = l.update(&PHONE).unwrap();
    assert!(!again.recomputed);
    assert_eq!(again.values, &v1);
    assert_eq!(again.bound, b1);
    assert_eq!(l.stats().updates, 2);
    assert_eq!(l.stats().recomputes, 1);
}

#[test]
fn recomputed_values_equal_the_one_shot_conversion() {
    let p = params();
    let mut l = Camera2Loop::new(p.clone(), Options::default(), 0.0).unwrap();
    let mut scales = Vec::new();
    for k in 0..40 {
        // Half the scenes only move the in-range entries: the range scale stays.
        let dev = if k % 2 == 0 { nudge(&PHONE, 0.02 * k as f64) } else { nudge(&PHONE, 1e-3 * k as f64) };
        let u = l.update(&dev).unwrap();
        assert!(u.recomputed, "tolerance 0 and a moving scene recompute every time");
        assert_eq!(u.values, &convert(&p, &dev, &Options::default()).unwrap());
        if scales.last() != Some(&u.values.scale) {
            scales.push(u.values.scale);
        }
    }
    // The curve half is refitted only when the range scale changes, not per update.
    let s = l.stats();
    assert_eq!(s.recomputes, 40);
    assert_eq!(s.curve_fits, scales.len() as u64, "{s:?}");

    // In-range compositions (scale 1): one fit for any number of scenes.
    let mild = Params::new(ccm::IDENTITY, p.tone_curves.channel(0).clone(), 2.2).unwrap();
    let mut l = Camera2Loop::new(mild.clone(), Options::default(), 0.0).unwrap();
    for k in 0..10 {
        let dev = nudge(&PHONE, 0.01 * k as f64);
        assert_eq!(l.update(&dev).unwrap().values, &convert(&mild, &dev, &Options::default()).unwrap());
    }
    assert_eq!((l.stats().recomputes, l.stats().curve_fits), (10, 1));
}

#[test]
fn skipped_updates_stay_within_their_stated_bound() {
    let p = params();
    let mut l = Camera2Loop::new(p.clone(), Options::default(), 1.0 / 255.0).unwrap();
    l.update(&PHONE).unwrap();
    let mut skipped = 0;
    for k in 1..30 {
        let dev = nudge(&PHONE, 2e-5 * k as f64);
        let u = l.update(&dev).unwrap();
        let (values, bound, recomputed) = (u.values.clone(), u.bound, u.recomputed);
        skipped += !recomputed as usize;
        let fresh = convert(&p, &dev, &Options::default()).unwrap().report.bound;
        // What skipping allows: no more than the tolerance over a fresh conversion
        // (up to the difference between the two fresh bounds, both tiny here).
        assert!(bound <= fresh + 1.0 / 255.0 + 1e-6, "k={k}: {bound} vs fresh {fresh}");
        let got = measured(&p, &dev, &values);
        assert!(got <= bound + 1e-12, "k={k}: measured {got} > bound {bound}");
    }
    assert!(skipped > 0 && skipped < 29, "some updates skipped, some not: {skipped}");
}

#[test]
fn a_new_curve_budget_recomputes() {
    let mut p = params();
    p.tone_curves = ToneCurve::from_fn(100, |t| (9.0 * t).sin() * 0.5 + 0.5).into();
    let mut l = Camera2Loop::new(p, Options::default(), DEFAULT_TOLERANCE).unwrap();
    let first = l.update(&PHONE).unwrap().values.report.clone();
    assert!(first.curve_simplified && first.curve_points == 64, "{first:?}");
    l.set_max_curve_points(16).unwrap();
    let u = l.update(&PHONE).unwrap();
    assert!(u.recomputed);
    assert_eq!(u.values.report.curve_points, 16);
    assert!(l.set_max_curve_points(1).is_err());
}

#[test]
fn colour_temperature_sources() {
    let p = params();
    let mut l = Camera2Loop::new(p.clone(), Options::default(), 0.0).unwrap();
    let e = l.update_ct(5000.0).unwrap_err().to_string();
    assert!(e.contains("ct_calibration"), "{e}");

    // The parameter set's calibration: linear in CT.
    let mut pc = p.clone();
    pc.ct_calibration =
        vec![CtCcm { ct_kelvin: 2856.0, ccm: PHONE }, CtCcm { ct_kelvin: 6504.0, ccm: nudge(&PHONE, 0.1) }];
    let mut l2 = Camera2Loop::new(pc.clone(), Options::default(), 0.0).unwrap();
    let dev = campro::color_temp::interpolate(&pc.ct_calibration, 4000.0).unwrap();
    assert_eq!(l2.update_ct(4000.0).unwrap().values, &convert(&pc, &dev, &Options::default()).unwrap());

    // Android's: linear in inverse CT over forward matrices.
    let fm = [[0.6, 0.3, 0.06], [0.25, 0.7, 0.05], [0.03, 0.1, 0.7]];
    let cal =
        DngCalibration { illuminant1: 17, forward_matrix1: fm, illuminant2: 21, forward_matrix2: nudge(&fm, 0.05) };
    l.set_dng_calibration(cal.clone()).unwrap();
    let dev = cal.device_transform(4000.0).unwrap();
    assert_eq!(l.update_ct(4000.0).unwrap().values, &convert(&p, &dev, &Options::default()).unwrap());
    assert!(l.update_ct(f64::NAN).is_err());
    assert!(l.set_dng_calibration(DngCalibration { illuminant1: 99, ..cal }).is_err());
}

#[test]
fn bad_inputs_are_named() {
    assert!(Camera2Loop::new(params(), Options::default(), f64::NAN)
        .unwrap_err()
        .to_string()
        .contains("skip_tolerance"));
    assert!(Camera2Loop::new(params(), Options { max_curve_points: 0, ..Options::default() }, 0.0).is_err());
    let mut l = Camera2Loop::new(params(), Options::default(), 0.0).unwrap();
    let mut dev = PHONE;
    dev[2][0] = f64::INFINITY;
    assert!(l.update(&dev).unwrap_err().to_string().contains("device_ccm[2][0]"));
    assert_eq!(l.stats().updates, 0, "a rejected update is not counted");
}
