//! The ops against independent implementations, on every device (burn's backend-tests
//! pattern: each test is a function of the device, instantiated once per device below):
//! the depthwise convolution against candle's grouped convolution; the dense convolution,
//! batch norm, PReLU, SiLU and the per-channel ops against candle's generic ops (one and
//! several threads); every op against its generic fallback, values and gradients; the
//! patched backward's sums. On the CPU the ops are the fast custom ops; elsewhere they are
//! the fallbacks, and these tests hold them to the same references.

use campro_nn::activation::prelu;
use campro_nn::conv::conv2d;
use campro_nn::depthwise::depthwise;
use candle_core::{Device, Tensor, Var};

/// Instantiates each test function once per device: the CPU always; CUDA where this build of
/// candle has it and a GPU is present (otherwise each says why it skipped).
macro_rules! per_device {
    ($($name:ident),* $(,)?) => {
        mod cpu {
            $(#[test]
            fn $name() {
                super::$name(&candle_core::Device::Cpu)
            })*
        }
        mod cuda {
            $(#[test]
            fn $name() {
                // (The driver is looked for first: cudarc panics where it cannot load it.)
                match campro_nn::context::device("cuda") {
                    Ok(d) => super::$name(&d),
                    Err(e) => eprintln!("skipped: {e}"),
                }
            })*
        }
    };
}

per_device!(
    depthwise_matches_grouped_convolution,
    depthwise_gradients_match_grouped_convolution,
    fused_batch_norm_matches_generic_ops,
    dense_matches_candle_convolution,
    channel_affine_matches_generic_ops,
    conv2d_matches_candle_forward_and_backward,
    conv2d_skips_gradients_nobody_reads,
    prelu_matches_candle_and_finite_differences,
    relu_matches_candles_with_its_gradient,
    silu_and_channel_bias_match_generic_ops,
    candle_backward_sums_every_use_of_a_tensor,
    every_op_equals_its_generic_fallback,
    batch_norm_statistics_by_hand,
);

fn rng_tensor(shape: &[usize], seed: u64, dev: &Device) -> Tensor {
    let n: usize = shape.iter().product();
    let mut s = seed;
    let v: Vec<f32> = (0..n)
        .map(|_| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect();
    Tensor::from_vec(v, shape, dev).unwrap()
}

fn max_abs(a: &Tensor, b: &Tensor) -> f32 {
    (a - b).unwrap().abs().unwrap().flatten_all().unwrap().max(0).unwrap().to_scalar().unwrap()
}

/// Values and the gradients of `sum(y · r)` for every variable, of `f` and of `g` on the same
/// inputs: the largest difference of each.
fn compare(vars: &[&Var], r: &Tensor, f: impl Fn() -> Tensor, g: impl Fn() -> Tensor) -> (f32, f32) {
    let (a, b) = (f(), g());
    let value = max_abs(&a, &b);
    let ga = a.mul(r).unwrap().sum_all().unwrap().backward().unwrap();
    let gb = b.mul(r).unwrap().sum_all().unwrap().backward().unwrap();
    let grad = vars
        .iter()
        .map(|v| max_abs(ga.get(v.as_tensor()).unwrap(), gb.get(v.as_tensor()).unwrap()))
        .fold(0f32, f32::max);
    (value, grad)
}

/// Each op's dispatched form (the fast custom op on the CPU) against the generic fallback
/// that runs on other devices: values and both gradients, strided and padded shapes.
fn every_op_equals_its_generic_fallback(dev: &Device) {
    use campro_nn::{activation as act, batch_norm as bn, channel as ch, conv as cv, depthwise as dw};
    let var = |shape: &[usize], seed| Var::from_tensor(&rng_tensor(shape, seed, dev)).unwrap();
    let (x, r) = (var(&[2, 4, 9, 7], 1), rng_tensor(&[2, 4, 9, 7], 2, dev));
    let (a, b) = (var(&[4], 3), var(&[4], 4));
    let xt = x.as_tensor();
    let (wd, rd) = (var(&[4, 1, 3, 3], 5), rng_tensor(&[2, 4, 5, 4], 6, dev));
    let (wc, rc) = (var(&[3, 4, 3, 3], 7), rng_tensor(&[2, 3, 5, 4], 8, dev));
    let worst = [
        ("prelu", compare(&[&x, &a], &r, || act::prelu(xt, &a).unwrap(), || act::prelu_generic(xt, &a).unwrap())),
        ("silu", compare(&[&x], &r, || act::silu(xt).unwrap(), || act::silu_generic(xt).unwrap())),
        ("relu", compare(&[&x], &r, || act::relu(xt).unwrap(), || act::relu_generic(xt).unwrap())),
        (
            "channel bias",
            compare(&[&x, &b], &r, || ch::channel_bias(xt, &b).unwrap(), || ch::channel_bias_generic(xt, &b).unwrap()),
        ),
        (
            "channel affine",
            compare(
                &[&x, &a, &b],
                &r,
                || ch::channel_affine(xt, &a, &b).unwrap(),
                || ch::channel_affine_generic(xt, &a, &b).unwrap(),
            ),
        ),
        (
            "batch norm + prelu",
            compare(
                &[&x, &a, &b],
                &r,
                || bn::batch_norm_train(xt, &a, &b, 1e-5, Some(&b)).unwrap().0,
                || bn::batch_norm_train_generic(xt, &a, &b, 1e-5, Some(&b)).unwrap().0,
            ),
        ),
        (
            "depthwise s2",
            compare(
                &[&x, &wd],
                &rd,
                || dw::depthwise(xt, &wd, 2, 1).unwrap(),
                || dw::depthwise_generic(xt, &wd, 2, 1).unwrap(),
            ),
        ),
        (
            "conv s2",
            compare(
                &[&x, &wc],
                &rc,
                || cv::conv2d(xt, &wc, 2, 1).unwrap(),
                || cv::conv2d_generic(xt, &wc, 2, 1).unwrap(),
            ),
        ),
    ];
    for (op, (value, grad)) in worst {
        assert!(value < 1e-5 && grad < 1e-4, "{op} on {dev:?}: values differ by {value}, gradients by {grad}");
    }
}

/// Batch statistics by hand: one channel holding 1, 2, 3, 4 over a batch of two has mean 2.5
/// and biased variance 1.25; with weight 2 and bias 1 the outputs are 1 + 2·(v − 2.5)/sqrt(1.25).
fn batch_norm_statistics_by_hand(dev: &Device) {
    let x = Tensor::from_vec(vec![1f32, 2., 3., 4.], (2, 1, 1, 2), dev).unwrap();
    let (w, b) = (Tensor::new(&[2f32], dev).unwrap(), Tensor::new(&[1f32], dev).unwrap());
    for f in [campro_nn::batch_norm::batch_norm_train, campro_nn::batch_norm::batch_norm_train_generic] {
        let (y, stats) = f(&x, &w, &b, 0.0, None).unwrap();
        assert_eq!(stats.flatten_all().unwrap().to_vec1::<f32>().unwrap(), [2.5, 1.25]);
        let want = [1.0, 2.0, 3.0, 4.0].map(|v: f32| 1.0 + 2.0 * (v - 2.5) / 1.25f32.sqrt());
        let got = y.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert!(got.iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-6), "{got:?}");
    }
}

fn depthwise_matches_grouped_convolution(dev: &Device) {
    // Odd and even sizes, strides 1 to 3, padding below and at k/2 (the phase planes).
    let cases =
        [(9, 7, 1, 3, 1), (10, 8, 2, 3, 1), (9, 9, 2, 3, 1), (7, 6, 1, 1, 0), (11, 8, 2, 5, 2), (8, 7, 2, 3, 0)];
    for (h, w, stride, k, pad) in cases.into_iter().chain([(13, 10, 3, 5, 1), (6, 6, 1, 5, 2)]) {
        let x = rng_tensor(&[2, 5, h, w], 1, dev);
        let wt = rng_tensor(&[5, 1, k, k], 2, dev);
        let want = x.conv2d(&wt, pad, stride, 1, 5).unwrap();
        let got = depthwise(&x, &wt, stride, pad).unwrap();
        assert_eq!(got.dims(), want.dims(), "{h}x{w} stride {stride}");
        assert!(max_abs(&got, &want) < 1e-5, "{h}x{w} stride {stride}: {}", max_abs(&got, &want));
    }
    // The 7x6 "linear" depthwise of MobileFaceNet: a per-channel weighted sum.
    let x = rng_tensor(&[1, 4, 7, 6], 3, dev);
    let wt = rng_tensor(&[4, 1, 7, 6], 4, dev);
    let got = depthwise(&x, &wt, 1, 0).unwrap();
    let want = x.broadcast_mul(&wt.reshape((1, 4, 7, 6)).unwrap()).unwrap().sum((2, 3)).unwrap();
    assert!(max_abs(&got.flatten_from(1).unwrap(), &want) < 1e-5);
}

fn depthwise_gradients_match_grouped_convolution(dev: &Device) {
    use candle_core::Var;
    for (h, w, stride, k, pad) in
        [(9, 7, 1, 3, 1), (10, 8, 2, 3, 1), (9, 9, 2, 3, 1), (12, 10, 2, 5, 2), (8, 8, 2, 3, 0)]
    {
        let x = Var::from_tensor(&rng_tensor(&[2, 4, h, w], 11, dev)).unwrap();
        let wt = Var::from_tensor(&rng_tensor(&[4, 1, k, k], 12, dev)).unwrap();
        let r = rng_tensor(&[2, 4, (h + 2 * pad - k) / stride + 1, (w + 2 * pad - k) / stride + 1], 13, dev);
        let ours = depthwise(&x, &wt, stride, pad).unwrap().mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
        let theirs = x.conv2d(&wt, pad, stride, 1, 4).unwrap().mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
        for v in [x.as_tensor(), wt.as_tensor()] {
            let (a, b) = (ours.get(v).unwrap(), theirs.get(v).unwrap());
            assert!(max_abs(a, b) < 1e-4, "{h}x{w} stride {stride}: {}", max_abs(a, b));
        }
    }
    // The 7x6 kernel over a 7x6 input (no padding): gradients of a per-channel weighted sum.
    let x = Var::from_tensor(&rng_tensor(&[2, 3, 7, 6], 14, dev)).unwrap();
    let wt = Var::from_tensor(&rng_tensor(&[3, 1, 7, 6], 15, dev)).unwrap();
    let r = rng_tensor(&[2, 3], 16, dev);
    let ours = depthwise(&x, &wt, 1, 0).unwrap().flatten_from(1).unwrap().mul(&r).unwrap().sum_all().unwrap();
    let theirs = x.broadcast_mul(&wt.reshape((1, 3, 7, 6)).unwrap()).unwrap().sum((2, 3)).unwrap();
    let (g1, g2) = (ours.backward().unwrap(), theirs.mul(&r).unwrap().sum_all().unwrap().backward().unwrap());
    for v in [x.as_tensor(), wt.as_tensor()] {
        assert!(max_abs(g1.get(v).unwrap(), g2.get(v).unwrap()) < 1e-4);
    }
}

fn fused_batch_norm_matches_generic_ops(dev: &Device) {
    use candle_core::Var;
    let x = Var::from_tensor(&rng_tensor(&[3, 4, 5, 6], 21, dev).affine(3.0, 1.0).unwrap()).unwrap();
    let g = Var::from_tensor(&rng_tensor(&[4], 22, dev)).unwrap();
    let b = Var::from_tensor(&rng_tensor(&[4], 23, dev)).unwrap();
    let a = Var::from_tensor(&rng_tensor(&[4], 25, dev).affine(0.5, 0.1).unwrap()).unwrap();
    let r = rng_tensor(&[3, 4, 5, 6], 24, dev);
    // The textbook expression in candle's generic ops (the fallback on other devices).
    let generic = |prelu| campro_nn::batch_norm::batch_norm_train_generic(&x, &g, &b, 1e-5, prelu).unwrap();
    let ((want, want_stats), (want_prelu, _)) = (generic(None), generic(Some(a.as_tensor())));
    let (mean, var) = (want_stats.get(0).unwrap(), want_stats.get(1).unwrap());
    for (prelu, want) in [(None, &want), (Some(a.as_tensor()), &want_prelu)] {
        let (y, stats) = campro_nn::batch_norm::batch_norm_train(&x, &g, &b, 1e-5, prelu).unwrap();
        assert!(max_abs(&y, want) < 1e-5);
        assert!(max_abs(&stats.get(0).unwrap(), &mean) < 1e-5);
        assert!(max_abs(&stats.get(1).unwrap(), &var) < 1e-4);
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

fn dense_matches_candle_convolution(dev: &Device) {
    for (h, w, stride, k, pad) in [(9, 7, 1, 3, 1), (10, 8, 2, 3, 1), (9, 9, 2, 3, 1), (7, 6, 1, 1, 0), (8, 8, 1, 3, 0)]
    {
        let x = rng_tensor(&[2, 3, h, w], 5, dev);
        let wt = rng_tensor(&[4, 3, k, k], 6, dev);
        let want = x.conv2d(&wt, pad, stride, 1, 1).unwrap();
        let got = campro_nn::conv::conv2d_generic(&x, &wt, stride, pad).unwrap();
        assert_eq!(got.dims(), want.dims(), "{h}x{w} stride {stride}");
        assert!(max_abs(&got, &want) < 1e-5, "{h}x{w} stride {stride}: {}", max_abs(&got, &want));
    }
}

fn channel_affine_matches_generic_ops(dev: &Device) {
    use candle_core::Var;
    let x = Var::from_tensor(&rng_tensor(&[3, 4, 5, 3], 21, dev)).unwrap();
    let a = Var::from_tensor(&rng_tensor(&[4], 22, dev)).unwrap();
    let b = Var::from_tensor(&rng_tensor(&[4], 23, dev)).unwrap();
    let r = rng_tensor(&[3, 4, 5, 3], 24, dev);
    let ours = campro_nn::channel::channel_affine(&x, &a, &b).unwrap();
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
fn check_conv(dev: &Device, x: &[usize], w: &[usize], stride: usize, pad: usize) {
    let xv = Var::from_tensor(&rng_tensor(x, 1, dev)).unwrap();
    let wv = Var::from_tensor(&rng_tensor(w, 2, dev)).unwrap();
    let ours = conv2d(xv.as_tensor(), wv.as_tensor(), stride, pad).unwrap();
    let reference = xv.as_tensor().conv2d(wv.as_tensor(), pad, stride, 1, 1).unwrap();
    assert_eq!(ours.dims(), reference.dims(), "x {x:?} w {w:?} s {stride} p {pad}");
    assert!(max_abs(&ours, &reference) < 1e-5, "forward x {x:?} w {w:?}");
    let r = rng_tensor(ours.dims(), 3, dev);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let generic = campro_nn::conv::conv2d_generic(xv.as_tensor(), wv.as_tensor(), stride, pad).unwrap();
    assert!(max_abs(&generic, &reference) < 1e-5);
    let g2 = generic.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&xv, &wv] {
        let (a, b) = (g1.get(v.as_tensor()).unwrap(), g2.get(v.as_tensor()).unwrap());
        assert!(max_abs(a, b) < 1e-4, "gradient x {x:?} w {w:?} s {stride} p {pad}: {}", max_abs(a, b));
    }
}

fn conv2d_matches_candle_forward_and_backward(dev: &Device) {
    for threads in [1, 3] {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| {
            check_conv(dev, &[2, 3, 7, 6], &[4, 3, 3, 3], 1, 1);
            check_conv(dev, &[2, 3, 7, 6], &[4, 3, 3, 3], 2, 1);
            check_conv(dev, &[3, 5, 8, 9], &[6, 5, 1, 1], 1, 0);
            check_conv(dev, &[1, 5, 8, 9], &[6, 5, 1, 1], 2, 0);
            check_conv(dev, &[1, 2, 5, 5], &[3, 2, 5, 3], 1, 2);
            check_conv(dev, &[4, 3, 6, 6], &[2, 3, 2, 2], 2, 0);
        });
    }
}

fn conv2d_skips_gradients_nobody_reads(dev: &Device) {
    // A frozen weight (not a variable): only the input's gradient exists, and it equals the
    // tracked case's.
    let x = Var::from_tensor(&rng_tensor(&[2, 3, 6, 5], 4, dev)).unwrap();
    let w = rng_tensor(&[4, 3, 3, 3], 5, dev);
    let g = conv2d(x.as_tensor(), &w, 1, 1).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(g.get(&w).is_none());
    let wv = Var::from_tensor(&w).unwrap();
    let g2 = conv2d(x.as_tensor(), wv.as_tensor(), 1, 1).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(max_abs(g.get(x.as_tensor()).unwrap(), g2.get(x.as_tensor()).unwrap()) == 0.0);
    assert!(conv2d(&rng_tensor(&[1, 3, 2, 2], 1, dev), &rng_tensor(&[1, 4, 3, 3], 1, dev), 1, 0).is_err());
}

fn prelu_matches_candle_and_finite_differences(dev: &Device) {
    let x = Var::from_tensor(&rng_tensor(&[3, 4, 5, 2], 6, dev)).unwrap();
    let a = Var::from_tensor(&(rng_tensor(&[4], 7, dev) * 0.5).unwrap()).unwrap();
    let ours = prelu(x.as_tensor(), a.as_tensor()).unwrap();
    let ab = a.as_tensor().reshape((1, 4, 1, 1)).unwrap();
    let reference = (x.as_tensor().relu().unwrap()
        - x.as_tensor().neg().unwrap().relu().unwrap().broadcast_mul(&ab).unwrap())
    .unwrap();
    assert!(max_abs(&ours, &reference) < 1e-7);
    let r = rng_tensor(ours.dims(), 8, dev);
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
        let step = Tensor::from_vec(e, 4, dev).unwrap();
        let fd = (f(&(a.as_tensor() + &step).unwrap()) - f(&(a.as_tensor() - &step).unwrap())) / 2e-2;
        assert!((fd - da[c]).abs() < 2e-3, "slope {c}: {fd} vs {}", da[c]);
    }
}

fn relu_matches_candles_with_its_gradient(dev: &Device) {
    use campro_nn::activation::relu;
    // A transposed (strided) input.
    let x = Var::from_tensor(&(rng_tensor(&[2, 3, 5, 4], 12, dev) * 3.0).unwrap()).unwrap();
    let xt = x.as_tensor().transpose(2, 3).unwrap();
    let r = rng_tensor(&[2, 3, 4, 5], 13, dev);
    let ours = relu(&xt).unwrap();
    let want = xt.relu().unwrap();
    assert_eq!(max_abs(&ours, &want), 0.0);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    assert_eq!(max_abs(g1.get(x.as_tensor()).unwrap(), g2.get(x.as_tensor()).unwrap()), 0.0);
    // Zero where the input is negative.
    let neg = Var::from_tensor(&(rng_tensor(&[7], 14, dev).abs().unwrap() * -1.0).unwrap()).unwrap();
    let g = relu(neg.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap();
    assert_eq!(g.get(neg.as_tensor()).unwrap().abs().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap(), 0.0);
}

fn silu_and_channel_bias_match_generic_ops(dev: &Device) {
    use campro_nn::activation::silu;
    use campro_nn::channel::channel_bias;
    let x = Var::from_tensor(&(rng_tensor(&[2, 3, 4, 5], 9, dev) * 6.0).unwrap()).unwrap();
    let b = Var::from_tensor(&rng_tensor(&[3], 10, dev)).unwrap();
    let r = rng_tensor(&[2, 3, 4, 5], 11, dev);
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
fn candle_backward_sums_every_use_of_a_tensor(dev: &Device) {
    let x = Var::from_tensor(&rng_tensor(&[3, 4], 31, dev)).unwrap();
    let w = Var::from_tensor(&rng_tensor(&[4], 32, dev)).unwrap();
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
