//! The fused convolution and PReLU ops against candle's generic ops (a second
//! implementation): forward values and both gradients, on small odd shapes, strides 1 and 2,
//! with and without padding, one thread and several.

use campro_train::conv::{conv2d, prelu};
use candle_core::{Device, Tensor, Var};

fn rand(shape: &[usize], seed: u64) -> Tensor {
    // A small LCG: reproducible values in [-1, 1).
    let n: usize = shape.iter().product();
    let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    let v: Vec<f32> = (0..n)
        .map(|_| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect();
    Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
}

fn max_diff(a: &Tensor, b: &Tensor) -> f32 {
    a.sub(b).unwrap().abs().unwrap().flatten_all().unwrap().max(0).unwrap().to_scalar::<f32>().unwrap()
}

/// Forward against candle's conv2d, and both gradients of `sum(conv(x, w) · r)` against the
/// same convolution built from candle's generic ops (`mobilefacenet::dense`: one product per
/// tap on shifted copies, then subsampling). candle's own conv2d backward is not the reference:
/// for stride 2 on odd sizes its input gradient comes out a column short.
fn check_conv(x: &[usize], w: &[usize], stride: usize, pad: usize) {
    let xv = Var::from_tensor(&rand(x, 1)).unwrap();
    let wv = Var::from_tensor(&rand(w, 2)).unwrap();
    let ours = conv2d(xv.as_tensor(), wv.as_tensor(), stride, pad).unwrap();
    let reference = xv.as_tensor().conv2d(wv.as_tensor(), pad, stride, 1, 1).unwrap();
    assert_eq!(ours.dims(), reference.dims(), "x {x:?} w {w:?} s {stride} p {pad}");
    assert!(max_diff(&ours, &reference) < 1e-5, "forward x {x:?} w {w:?}");
    let r = rand(ours.dims(), 3);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let generic = campro_train::conv::conv2d_generic(xv.as_tensor(), wv.as_tensor(), stride, pad).unwrap();
    assert!(max_diff(&generic, &reference) < 1e-5);
    let g2 = generic.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&xv, &wv] {
        let (a, b) = (g1.get(v.as_tensor()).unwrap(), g2.get(v.as_tensor()).unwrap());
        assert!(max_diff(a, b) < 1e-4, "gradient x {x:?} w {w:?} s {stride} p {pad}: {}", max_diff(a, b));
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
    let x = Var::from_tensor(&rand(&[2, 3, 6, 5], 4)).unwrap();
    let w = rand(&[4, 3, 3, 3], 5);
    let g = conv2d(x.as_tensor(), &w, 1, 1).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(g.get(&w).is_none());
    let wv = Var::from_tensor(&w).unwrap();
    let g2 = conv2d(x.as_tensor(), wv.as_tensor(), 1, 1).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(max_diff(g.get(x.as_tensor()).unwrap(), g2.get(x.as_tensor()).unwrap()) == 0.0);
    assert!(conv2d(&rand(&[1, 3, 2, 2], 1), &rand(&[1, 4, 3, 3], 1), 1, 0).is_err());
}

#[test]
fn prelu_matches_candle_and_finite_differences() {
    let x = Var::from_tensor(&rand(&[3, 4, 5, 2], 6)).unwrap();
    let a = Var::from_tensor(&(rand(&[4], 7) * 0.5).unwrap()).unwrap();
    let ours = prelu(x.as_tensor(), a.as_tensor()).unwrap();
    let ab = a.as_tensor().reshape((1, 4, 1, 1)).unwrap();
    let reference = (x.as_tensor().relu().unwrap()
        - x.as_tensor().neg().unwrap().relu().unwrap().broadcast_mul(&ab).unwrap())
    .unwrap();
    assert!(max_diff(&ours, &reference) < 1e-7);
    let r = rand(ours.dims(), 8);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = reference.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&x, &a] {
        assert!(max_diff(g1.get(v.as_tensor()).unwrap(), g2.get(v.as_tensor()).unwrap()) < 1e-5);
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
fn silu_and_channel_bias_match_generic_ops() {
    use campro_train::conv::{channel_bias, silu};
    let x = Var::from_tensor(&(rand(&[2, 3, 4, 5], 9) * 6.0).unwrap()).unwrap();
    let b = Var::from_tensor(&rand(&[3], 10)).unwrap();
    let r = rand(&[2, 3, 4, 5], 11);
    // SiLU against Sigmoid then Mul, as the ONNX graph has it.
    let ours = silu(x.as_tensor()).unwrap();
    let want = x.as_tensor().mul(&candle_nn::ops::sigmoid(x.as_tensor()).unwrap()).unwrap();
    assert!(max_diff(&ours, &want) < 1e-5);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    assert!(max_diff(g1.get(x.as_tensor()).unwrap(), g2.get(x.as_tensor()).unwrap()) < 1e-5);
    // The bias against a broadcast add.
    let ours = channel_bias(x.as_tensor(), b.as_tensor()).unwrap();
    let want = x.as_tensor().broadcast_add(&b.as_tensor().reshape((1, 3, 1, 1)).unwrap()).unwrap();
    assert!(max_diff(&ours, &want) == 0.0);
    let g1 = ours.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    let g2 = want.mul(&r).unwrap().sum_all().unwrap().backward().unwrap();
    for v in [&x, &b] {
        assert!(max_diff(g1.get(v.as_tensor()).unwrap(), g2.get(v.as_tensor()).unwrap()) < 1e-5);
    }
}
