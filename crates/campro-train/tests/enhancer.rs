//! The image enhancer: the U-Net trained by candle against the same ONNX file run by tract,
//! its size formulas against hand counts, the losses against hand values, the face boxes
//! against hand geometry, and learning on a fixed batch.

use campro_eval::enhance::Enhancer;
use campro_eval::restore::{Binning, Table};
use campro_train::config::{EnhancerConfig, FaceTarget, PixelLoss, UnetConfig};
use campro_train::scenes::{enlarge, Scene};
use campro_train::unet::{enhancer_loss, face_l1, gate_loss, macs_per_pixel, masked_l1, parameter_count, Unet};
use candle_core::{Device, Tensor};
use image::RgbImage;
use std::path::Path;

fn noise(shape: &[usize], seed: u64, scale: f32) -> Tensor {
    let n: usize = shape.iter().product();
    let mut s = seed;
    let v: Vec<f32> = (0..n)
        .map(|_| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0) * scale
        })
        .collect();
    Tensor::from_vec(v, shape, &Device::Cpu).unwrap()
}

fn test_image(w: u32, h: u32) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7 + y * 3) as u8, (x * x + 5 * y) as u8, (200 - x - y) as u8]))
}

/// A U-Net with every weight drawn at random (the output convolution too, which starts at zero).
fn shape(widths: &[usize], stem: usize) -> UnetConfig {
    UnetConfig { widths: widths.to_vec(), stem, restorer: false, face_gate: false, gate_blocks: 0 }
}

fn random_unet(shape: &UnetConfig) -> Unet {
    let u = Unet::new(shape, 3, &Device::Cpu).unwrap();
    for (i, (_, v)) in u.named_vars().into_iter().enumerate() {
        let scale =
            if v.dims().len() == 4 { (2.0 / (v.dims()[1] * v.dims()[2] * v.dims()[3]) as f32).sqrt() } else { 0.05 };
        v.set(&noise(v.dims(), 100 + i as u64, scale)).unwrap();
    }
    u
}

#[test]
fn candle_and_tract_agree_on_the_written_onnx() {
    for stem in [0, 6] {
        let u = random_unet(&shape(&[4, 8, 16], stem));
        let tract = Enhancer::from_bytes(&u.onnx_bytes().unwrap(), Path::new("test")).unwrap();
        assert_eq!(tract.multiple(), 4);
        // A size that is a multiple, and one that needs padding.
        for (w, h) in [(56, 40), (53, 37)] {
            let img = test_image(w, h);
            let a = campro_train::enhancer::enhance(&u, &img, &img, &Device::Cpu).unwrap();
            let b = tract.enhance(&img).unwrap();
            let worst = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
            assert!(worst <= 1, "{w}x{h}: candle and tract differ by {worst} LSB");
            // The network changes the image (else the comparison above proves nothing).
            let moved = a.as_raw().iter().zip(img.as_raw()).filter(|(x, y)| x.abs_diff(**y) > 4).count();
            assert!(moved > a.as_raw().len() / 4, "{w}x{h}: only {moved} samples changed");
        }
    }
}

#[test]
fn the_restoration_stage_in_onnx_is_the_table_lookup() {
    // A table that scrambles colours (entry = a hash of the bin), on uneven bins.
    let table = scrambled(|b| [(b * 7) as u8, (b / 3) as u8, (b >> 10) as u8 ^ 0x5a]);
    assert_ne!(table.binning, Binning::uniform());
    let u = random_unet(&shape(&[4, 8, 16], 0));
    let tract = Enhancer::from_bytes(&u.onnx_bytes_with_table(&table).unwrap(), Path::new("test")).unwrap();
    let img = test_image(53, 37);
    let restored = table.apply(&img);
    let a = campro_train::enhancer::enhance(&u, &restored, &img, &Device::Cpu).unwrap();
    let b = tract.enhance(&img).unwrap();
    let worst = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
    assert!(worst <= 1, "candle on the looked-up image and tract on the captured one differ by {worst} LSB");
    // A fresh U-Net behind the stage is the lookup itself, bit for bit.
    let fresh = Unet::new(&shape(&[4, 8], 0), 1, &Device::Cpu).unwrap();
    let tract = Enhancer::from_bytes(&fresh.onnx_bytes_with_table(&table).unwrap(), Path::new("test")).unwrap();
    assert_eq!(tract.enhance(&img).unwrap(), restored);
    let short = Table { entries: table.entries[1..].to_vec(), ..table };
    assert!(u.onnx_bytes_with_table(&short).is_err());
}

/// A restoration table of `entry(bin)` on uneven bins: equal mass under a histogram with a
/// heavy level on each channel and a dense run on blue.
fn scrambled(entry: impl Fn(usize) -> [u8; 3]) -> Table {
    let mut h = [[1u64; 256]; 3];
    h[0][40] = 5000;
    h[1][200] = 3000;
    h[2][..50].fill(100);
    Table { binning: Binning::equal_mass(&h), entries: (0..1usize << 18).map(entry).collect() }
}

#[test]
fn a_fresh_enhancer_returns_the_captured_image() {
    let u = Unet::new(&shape(&[4, 8], 0), 1, &Device::Cpu).unwrap();
    let tract = Enhancer::from_bytes(&u.onnx_bytes().unwrap(), Path::new("test")).unwrap();
    let img = test_image(31, 17);
    assert_eq!(tract.enhance(&img).unwrap(), img);
}

#[test]
fn size_formulas_match_hand_counts() {
    // [8, 16]: 3→8 (224), 8→8 (584), 8→16 s2 (1168), 16→16 (2320), decoder 16→8 (1160),
    // 16→8 (1160), output 8→3 1x1 (27).
    assert_eq!(parameter_count(&shape(&[8, 16], 0)), 6643);
    let u = Unet::new(&shape(&[8, 16], 0), 1, &Device::Cpu).unwrap();
    let counted: usize = u.vars().iter().map(|v| v.elem_count()).sum();
    assert_eq!(counted, 6643);
    for s in [shape(&[16, 32, 64, 128], 0), shape(&[8, 16, 32], 12)] {
        let n = Unet::new(&s, 1, &Device::Cpu).unwrap().vars().iter().map(|v| v.elem_count()).sum::<usize>();
        assert_eq!(parameter_count(&s), n, "{s:?}");
    }
    // Level 0: 216 + 576 + 24; level 1 at a quarter: (1152 + 2304 + 1152) / 4; the decoder's
    // second convolution at level 0: 1152.
    assert_eq!(macs_per_pixel(&shape(&[8, 16], 0)), 816.0 + 864.0 + 288.0 + 1152.0);
    // A stem of 4: 3·4 + 4·4 per pixel, and the first convolution reads 4 channels, not 3.
    assert_eq!(macs_per_pixel(&shape(&[8, 16], 4)), 3120.0 + 12.0 + 16.0 + (4.0 - 3.0) * 8.0 * 9.0);
    assert_eq!(u.multiple(), 2);
}

#[test]
fn losses_match_hand_values() {
    let dev = Device::Cpu;
    let t = |v: &[f32], c: usize| Tensor::from_vec(v.to_vec(), (1, c, 1, 2), &dev).unwrap();
    // Two pixels, three channels; the second pixel is a face.
    let raw = t(&[0.5, 0.5, 0.2, 0.2, 1.0, 1.0], 3);
    let cap = t(&[0.1, 0.9, 0.6, 0.6, 0.0, 0.4], 3);
    let keep = t(&[1.0, 0.0], 1);
    let pred = t(&[0.4, 0.5, 0.5, 0.2, 0.7, 1.0], 3);
    let v = |x: Tensor| x.to_scalar::<f32>().unwrap();
    // |pred − raw| = [.1, 0, .3, 0, .3, 0]; masked: first pixel only: (.1 + .3 + .3) / 6.
    assert!((v(masked_l1(&pred, &raw, &keep).unwrap()) - 0.7 / 6.0).abs() < 1e-6);
    // Face L1: the second pixel's channels: (0 + 0 + 0) / 3.
    assert_eq!(face_l1(&pred, &raw, &keep).unwrap(), Some(0.0));
    // Input target: the face pixel against the input: |.5−.9| + |.2−.6| + |1−.4| = 1.4.
    let l = v(enhancer_loss(&pred, &raw, &cap, &keep, FaceTarget::Input, PixelLoss::L1).unwrap());
    assert!((l - (0.7 + 1.4) / 6.0).abs() < 1e-6, "{l}");
    let free = v(enhancer_loss(&pred, &raw, &cap, &keep, FaceTarget::Free, PixelLoss::L1).unwrap());
    assert!((free - 0.7 / 6.0).abs() < 1e-6);
    // Squared: (.01 + .09 + .09) / 6 masked; the face against the input adds .16 + .16 + .36.
    let l2 = v(enhancer_loss(&pred, &raw, &cap, &keep, FaceTarget::Free, PixelLoss::L2).unwrap());
    assert!((l2 - 0.19 / 6.0).abs() < 1e-6, "{l2}");
    let l2 = v(enhancer_loss(&pred, &raw, &cap, &keep, FaceTarget::Input, PixelLoss::L2).unwrap());
    assert!((l2 - (0.19 + 0.68) / 6.0).abs() < 1e-6, "{l2}");
    // No face: None.
    assert_eq!(face_l1(&pred, &raw, &t(&[1.0, 1.0], 1)).unwrap(), None);
}

#[test]
fn face_boxes_grow_and_mask_by_hand() {
    // A 10 x 20 box at (20, 40), margin 0.5: 5 px left and right, 10 below, 20 above.
    assert_eq!(enlarge([20.0, 40.0, 30.0, 60.0], 0.5, 100, 100), [15, 20, 35, 70]);
    // Clipped to the image.
    assert_eq!(enlarge([2.0, 2.0, 12.0, 12.0], 0.5, 14, 14), [0, 0, 14, 14]);
    let sc =
        Scene { raw: RgbImage::new(6, 4), captured: RgbImage::new(6, 4), restored: None, faces: vec![[1, 1, 3, 2]] };
    let k = sc.keep(0, 0, 6, 4);
    let zeros: Vec<usize> = (0..k.len()).filter(|&i| k[i] == 0.0).collect();
    assert_eq!(zeros, vec![7, 8]);
    // A crop from (2, 1): the box's column 2 lands at column 0.
    assert_eq!(sc.keep(2, 1, 3, 2), vec![0.0, 1.0, 1.0, 1.0, 1.0, 1.0]);
}

#[test]
fn training_on_a_fixed_batch_lowers_the_loss() {
    use candle_nn::{AdamW, Optimizer, ParamsAdamW};
    let u = Unet::new(&shape(&[4, 8], 0), 5, &Device::Cpu).unwrap();
    let raw = (noise(&[2, 3, 16, 16], 7, 0.5) + 0.5).unwrap();
    // A colour map to undo: each channel inverted.
    let cap = (1.0 - &raw).unwrap();
    let keep = Tensor::ones((2, 1, 16, 16), candle_core::DType::F32, &Device::Cpu).unwrap();
    let mut adam = AdamW::new(u.vars(), ParamsAdamW { lr: 1e-2, weight_decay: 0.0, ..Default::default() }).unwrap();
    let loss = |u: &Unet| masked_l1(&u.forward(&cap).unwrap(), &raw, &keep).unwrap();
    let first = loss(&u).to_scalar::<f32>().unwrap();
    for _ in 0..100 {
        adam.step(&loss(&u).backward().unwrap()).unwrap();
    }
    let last = loss(&u).to_scalar::<f32>().unwrap();
    assert!(last < 0.5 * first, "L1 {first} -> {last}");
}

#[test]
fn the_enhancer_configuration_names_its_broken_rule() {
    let bad = |text: &str, key: &str| {
        let e = campro_train::config::parse::<EnhancerConfig>(text, "t.toml").unwrap_err().to_string();
        assert!(e.contains(key), "{text:?}: {e}");
    };
    bad("[model]\nwidths = []\n", "model.widths");
    bad("[model]\nwidths = [8, 16, 32, 64]\n[data]\ncrop = 100\n", "data.crop");
    bad("[data]\nfaces = \"blur\"\n", "unknown variant");
    bad("[data]\nmax_images = 0\n", "data.max_images");
    bad("[optimiser]\nlr = -1.0\n", "optimiser.lr");
    bad("colour = 1\n", "unknown field");
    bad("[privacy]\nweight = -1.0\n", "privacy.weight");
    bad("[privacy]\nweight = 1.0\nfaces = 0\n", "privacy.faces");
    bad("[privacy]\nmin_images = 1\n", "privacy.min_images");
    bad("[privacy]\nmax_identities = 1\n", "privacy.max_identities");
    bad("[privacy]\nmargin = -0.1\n", "privacy.margin");
    bad("[model]\nface_gate = true\n", "model.face_gate");
    bad("[data]\nfaces = \"captured\"\n", "data.faces");
    bad("gate_weight = -1.0\n[model]\nface_gate = true\n[data]\nfaces = \"captured\"\n", "gate_weight");
    bad("gate_background = 0.0\n", "gate_background");
    bad("ssim_weight = -0.5\n", "ssim_weight");
    bad("ssim_weight = 1.0\n[data]\nfaces = \"free\"\n", "ssim_weight");
    let pix = "[model]\nface_gate = true\ngate_blocks = 16\n[data]\nfaces = \"pixelated\"\n";
    bad(&pix.replace("16", "12"), "model.gate_blocks");
    bad(&pix.replace("pixelated", "captured"), "model.gate_blocks");
    bad(&pix.replace("face_gate = true", "face_gate = false"), "data.faces");
    bad(&format!("{pix}crop = 120\n"), "data.crop");
    let pixelated: EnhancerConfig = campro_train::config::parse(pix, "t.toml").unwrap();
    assert_eq!((pixelated.model.gate_blocks, pixelated.data.faces), (16, FaceTarget::Pixelated));
    let gated: EnhancerConfig =
        campro_train::config::parse("[model]\nface_gate = true\n[data]\nfaces = \"captured\"\n", "t.toml").unwrap();
    assert_eq!((gated.model.face_gate, gated.gate_weight), (true, 1.0));
    let ok: EnhancerConfig = campro_train::config::parse("[data]\nfaces = \"restore\"\n", "t.toml").unwrap();
    assert_eq!(ok.data.faces, FaceTarget::Restore);
    assert_eq!((ok.optimiser.lr, ok.optimiser.weight_decay), (3e-4, 1e-2));
    // The face-privacy term is off unless asked for.
    assert_eq!(ok.privacy.weight, 0.0);
}

#[test]
fn a_damaged_enhancer_file_is_refused_by_name() {
    let u = Unet::new(&shape(&[4, 8], 0), 1, &Device::Cpu).unwrap();
    let bytes = u.onnx_bytes().unwrap();
    for cut in [0, 10, bytes.len() / 2] {
        let e = Enhancer::from_bytes(&bytes[..cut], Path::new("bad.onnx")).err().expect("refused");
        assert!(e.to_string().contains("bad.onnx"), "{e}");
    }
    // A valid ONNX file that is not an enhancer (no multiple entry).
    let e = Enhancer::from_bytes(b"", Path::new("empty.onnx")).err().expect("refused").to_string();
    assert!(e.contains("empty.onnx"), "{e}");
}

#[test]
fn every_level_gets_the_gradient_finite_differences_give() {
    // The deep levels reach the output only through Resize and Concat: their weights'
    // gradients against central differences (f32, so a loose tolerance). The biases are
    // moved to [0.05, 0.15]: where a 3x3 patch is all zeros after a ReLU, the next
    // pre-activation is its bias exactly, and a bias within the step of zero puts a kink of
    // the loss inside the difference (a seed did: slopes 6.60 left, 6.16 right).
    let u = random_unet(&shape(&[2, 4, 8], 0));
    for (i, (_, v)) in u.named_vars().into_iter().enumerate().filter(|(_, (_, v))| v.dims().len() == 1) {
        v.set(&(noise(v.dims(), 300 + i as u64, 0.05) + 0.1).unwrap()).unwrap();
    }
    let x = (noise(&[1, 3, 16, 16], 11, 0.5) + 0.5).unwrap();
    let g = noise(&[1, 3, 16, 16], 12, 1.0);
    let loss = |u: &Unet| (u.forward(&x).unwrap() * &g).unwrap().sum_all().unwrap();
    let grads = loss(&u).backward().unwrap();
    for name in
        ["enc2.conv1.w", "enc2.conv1.b", "dec1.conv0.w", "enc1.conv0.b", "dec0.conv1.w", "dec0.conv1.b", "out.w"]
    {
        let var = u.named_vars().into_iter().find(|(n, _)| n == name).unwrap().1;
        let analytic: Vec<f32> = grads.get(var.as_tensor()).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let w0: Vec<f32> = var.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
        let eps = 1e-3f32;
        let mut checked = 0;
        for k in 0..w0.len() {
            let at = |d: f32| {
                let mut w = w0.clone();
                w[k] += d;
                var.set(&Tensor::from_vec(w, var.dims(), &Device::Cpu).unwrap()).unwrap();
                loss(&u).to_scalar::<f32>().unwrap() as f64
            };
            let (l0, lp, lm) = (at(0.0), at(eps), at(-eps));
            var.set(&Tensor::from_vec(w0.clone(), var.dims(), &Device::Cpu).unwrap()).unwrap();
            // A ReLU pre-activation within the step of zero is a kink: then the one-sided
            // difference on the other side is the derivative autograd takes.
            let differences = [(lp - lm) / (2.0 * eps as f64), (lp - l0) / eps as f64, (l0 - lm) / eps as f64];
            let a = analytic[k] as f64;
            assert!(
                differences.iter().any(|d| (a - d).abs() <= 0.02 * d.abs().max(a.abs()) + 2e-2),
                "{name}[{k}]: autograd {a}, differences (central, right, left) {differences:?}"
            );
            checked += 1;
        }
        assert!(checked >= 2 && analytic.iter().any(|v| v.abs() > 1e-3), "{name}: {analytic:?}");
    }
}

/// A gated U-Net of `widths` with random weights, the gate's scaled up so that it spans
/// (0, 1) on the test image, and the gate's bias set; `blocks`: its pixelation (0: none).
fn random_gated(widths: &[usize], gate_bias: f32, blocks: usize) -> Unet {
    let u = random_unet(&UnetConfig { face_gate: true, gate_blocks: blocks, ..shape(widths, 0) });
    let var = |name: &str| u.named_vars().into_iter().find(|(n, _)| n == name).expect(name).1;
    for (name, seed, scale) in [("gate.fine.w", 77, 40.0), ("gate.low.w", 78, 1.0)] {
        let w = var(name);
        w.set(&noise(w.dims(), seed, scale)).unwrap();
    }
    var("gate.low.b").set(&Tensor::new(&[gate_bias], &Device::Cpu).unwrap()).unwrap();
    u
}

/// Both files of `u` (behind `table`, and alone) run by tract on `img` agree with candle on
/// the same input within 1 LSB, and carry `u`'s multiple.
fn files_agree_with_candle(u: &Unet, table: &Table, img: &RgbImage) {
    let restored = table.apply(img);
    for (bytes, input) in [(u.onnx_bytes_with_table(table).unwrap(), &restored), (u.onnx_bytes().unwrap(), img)] {
        let tract = Enhancer::from_bytes(&bytes, Path::new("test")).unwrap();
        assert_eq!(tract.multiple(), u.multiple());
        let a = campro_train::enhancer::enhance(u, input, img, &Device::Cpu).unwrap();
        let b = tract.enhance(img).unwrap();
        let worst = a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
        assert!(worst <= 1, "candle and tract differ by {worst} LSB");
    }
}

/// The gate's last convolutions' weights at zero: the gate is sigmoid(bias) everywhere.
fn silence(u: &Unet) {
    for (n, w) in u.named_vars() {
        if n == "gate.fine.w" || n == "gate.low.w" {
            w.set(&w.as_tensor().zeros_like().unwrap()).unwrap();
        }
    }
}

#[test]
fn the_face_gate_blends_in_onnx_as_in_candle() {
    let table = scrambled(|b| [(b * 7) as u8, (b / 3) as u8, (b >> 10) as u8 ^ 0x5a]);
    let img = test_image(53, 37);
    let restored = table.apply(&img);
    let u = random_gated(&[4, 8, 16], -2.0, 0);
    // The gate is neither off nor on everywhere, so both sides of the blend are in play.
    let (_, gate) = campro_train::enhancer::enhance_gated(&u, &restored, &img, &Device::Cpu).unwrap();
    let gate = gate.expect("a gate map");
    assert_eq!(gate.len(), 53 * 37);
    let (lo, hi) = gate.iter().fold((1f32, 0f32), |(a, b), &g| (a.min(g), b.max(g)));
    assert!(lo < 0.3 && hi > 0.7, "gate in [{lo}, {hi}]");
    files_agree_with_candle(&u, &table, &img);
    // A gate on everywhere (sigmoid(30) = 1 in f32, the last convolutions' weights at zero)
    // gives back the captured image exactly, restoration stage or not; off, the U-Net's own
    // output.
    let on = random_gated(&[4, 8], 30.0, 0);
    silence(&on);
    let tract = Enhancer::from_bytes(&on.onnx_bytes_with_table(&table).unwrap(), Path::new("test")).unwrap();
    assert_eq!(tract.enhance(&img).unwrap(), img);
    let off = random_gated(&[4, 8], -30.0, 0);
    silence(&off);
    let (data, pw, ph) = campro_eval::enhance::padded_chw(&img, off.multiple());
    let ungated = off.forward(&Tensor::from_vec(data, (1, 3, ph, pw), &Device::Cpu).unwrap()).unwrap();
    let ungated =
        campro_eval::enhance::cropped_rgb8(&ungated.flatten_all().unwrap().to_vec1().unwrap(), pw, ph, 53, 37);
    let tract = Enhancer::from_bytes(&off.onnx_bytes().unwrap(), Path::new("test")).unwrap();
    assert_eq!(tract.enhance(&img).unwrap(), ungated);
    assert_ne!(ungated, img);
    // The gate's parameters by hand for [8, 16]: 16→16 3x3 (2320), 16→16 3x3 (2320), 16→1
    // 1x1 (17), 8→1 1x1 (9); its extra MACs per pixel: the deep branch at a quarter of the
    // pixels, (2304 + 2304 + 16) / 4, and 8 at full resolution.
    let fresh = UnetConfig { face_gate: true, ..shape(&[8, 16], 0) };
    assert_eq!(parameter_count(&fresh), 6643 + 4666);
    let counted = Unet::new(&fresh, 1, &Device::Cpu).unwrap().vars().iter().map(|v| v.elem_count()).sum::<usize>();
    assert_eq!(counted, 6643 + 4666);
    assert_eq!(macs_per_pixel(&fresh) - macs_per_pixel(&shape(&[8, 16], 0)), 4624.0 / 4.0 + 8.0);
}

#[test]
fn pixelated_faces_are_block_means_in_onnx_as_in_candle() {
    // By hand: 2 x 2 blocks of a 2 x 4 plane.
    let x = Tensor::from_vec((1..=8).map(|v| v as f32).collect(), (1, 1, 2, 4), &Device::Cpu).unwrap();
    let p = campro_train::unet::pixelate(&x, 2).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    assert_eq!(p, [3.5, 3.5, 5.5, 5.5, 3.5, 3.5, 5.5, 5.5]);
    // Blocks of 8 behind a two-level U-Net (multiple 2): the file's multiple is the blocks.
    let table = scrambled(|b| [(b * 5) as u8, (b / 7) as u8, (b >> 9) as u8]);
    let img = test_image(53, 37);
    let u = random_gated(&[4, 8], -2.0, 8);
    assert_eq!(u.multiple(), 8);
    files_agree_with_candle(&u, &table, &img);
    // A gate on everywhere: the U-Net's own output averaged over each 8 x 8 block of the
    // padded image (56 x 40), summed here in f64, then cropped.
    let on = random_gated(&[4, 8], 30.0, 8);
    silence(&on);
    let (data, pw, ph) = campro_eval::enhance::padded_chw(&img, 8);
    assert_eq!((pw, ph), (56, 40));
    let out = on.forward(&Tensor::from_vec(data, (1, 3, ph, pw), &Device::Cpu).unwrap()).unwrap();
    let out = out.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let mut hand = vec![0f32; out.len()];
    for c in 0..3 {
        for by in (0..ph).step_by(8) {
            for bx in (0..pw).step_by(8) {
                let at = |y: usize, x: usize| c * ph * pw + (by + y) * pw + bx + x;
                let mean = (0..64).map(|i| out[at(i / 8, i % 8)] as f64).sum::<f64>() / 64.0;
                (0..64).for_each(|i| hand[at(i / 8, i % 8)] = mean as f32);
            }
        }
    }
    let hand = campro_eval::enhance::cropped_rgb8(&hand, pw, ph, 53, 37);
    let tract = Enhancer::from_bytes(&on.onnx_bytes().unwrap(), Path::new("test")).unwrap().enhance(&img).unwrap();
    let worst = hand.as_raw().iter().zip(tract.as_raw()).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
    assert!(worst <= 1, "pixelation differs from the block means by {worst} LSB");
    // Not the captured image, and flat over a block.
    assert_ne!(tract, img);
    assert_eq!(tract.get_pixel(8, 8), tract.get_pixel(15, 15));
}

#[test]
fn the_gate_loss_is_the_cross_entropy_by_hand() {
    let dev = Device::Cpu;
    // Two pixels: a face where the gate says 0.8, a background where it says 0.1.
    let gate = Tensor::from_vec(vec![0.8f32, 0.1], (1, 1, 1, 2), &dev).unwrap();
    let keep = Tensor::from_vec(vec![0.0f32, 1.0], (1, 1, 1, 2), &dev).unwrap();
    let l = gate_loss(&gate, &keep, 1.0).unwrap().to_scalar::<f32>().unwrap();
    let want = -((0.8f32).ln() + (0.9f32).ln()) / 2.0;
    assert!((l - want).abs() < 1e-6, "{l} against {want}");
    // The background pixel's term weighted 4 times.
    let l = gate_loss(&gate, &keep, 4.0).unwrap().to_scalar::<f32>().unwrap();
    let want = -((0.8f32).ln() + 4.0 * (0.9f32).ln()) / 2.0;
    assert!((l - want).abs() < 1e-6, "{l} against {want}");
    // Certain and right costs (almost) nothing; certain and wrong is capped by the clamp.
    let sure = Tensor::from_vec(vec![1.0f32, 0.0], (1, 1, 1, 2), &dev).unwrap();
    assert!(gate_loss(&sure, &keep, 1.0).unwrap().to_scalar::<f32>().unwrap() < 1e-5);
    let wrong = gate_loss(&sure, &(1.0 - &keep).unwrap(), 1.0).unwrap().to_scalar::<f32>().unwrap();
    assert!((wrong - (1e6f32).ln()).abs() < 0.05, "{wrong}");
    // The captured target: inside the face the loss measures the distance to `held`.
    let t = |v: &[f32]| Tensor::from_vec(v.to_vec(), (1, 3, 1, 2), &dev).unwrap();
    let (pred, raw, held) = (t(&[0.5; 6]), t(&[0.5, 0.0, 0.5, 0.0, 0.5, 0.0]), t(&[0.0, 0.5, 0.0, 0.5, 0.0, 0.5]));
    let l = enhancer_loss(&pred, &raw, &held, &keep, FaceTarget::Captured, PixelLoss::L1).unwrap();
    // Pixel 0 is a face held to 0.0 (|0.5| x 3), pixel 1 background at raw 0.0 (|0.5| x 3).
    assert!((l.to_scalar::<f32>().unwrap() - 0.5).abs() < 1e-6);
}

/// `img` as a (1, 3, H, W) tensor in 0..1.
fn to_tensor(img: &RgbImage) -> Tensor {
    campro_train::scenes::chw_tensor(img, &Device::Cpu).unwrap()
}

#[test]
fn the_ssim_loss_is_the_evaluations_ssim() {
    use campro_train::ssim::ssim;
    // Against the f64 evaluation (a second implementation: loops, not matrix products), on
    // images with structure and noise, square and not, and on a batch (the mean).
    let pair = |w: u32, h: u32, seed: u64| {
        let mut s = seed;
        let a = test_image(w, h);
        let b = RgbImage::from_fn(w, h, |x, y| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let p = a.get_pixel(x, y).0;
            image::Rgb(std::array::from_fn(|c| {
                p[c].saturating_add(((s >> (40 + 8 * c)) % 61) as u8).saturating_sub(30)
            }))
        });
        (a, b)
    };
    for (w, h) in [(11, 11), (40, 29), (64, 64)] {
        let (a, b) = pair(w, h, w as u64);
        let ours = ssim(&to_tensor(&a), &to_tensor(&b)).unwrap().to_scalar::<f32>().unwrap() as f64;
        let eval = campro_eval::quality::ssim(&a, &b);
        assert!((ours - eval).abs() < 1e-4, "{w}x{h}: candle {ours}, evaluation {eval}");
        assert!(eval < 0.9, "{w}x{h}: the pair is too alike to test anything ({eval})");
        let same = ssim(&to_tensor(&a), &to_tensor(&a)).unwrap().to_scalar::<f32>().unwrap();
        assert!((same - 1.0).abs() < 1e-5, "{same}");
    }
    let (p, q) = (pair(32, 24, 1), pair(32, 24, 2));
    let batch = |x: &RgbImage, y: &RgbImage| Tensor::cat(&[to_tensor(x), to_tensor(y)], 0).unwrap();
    let ours = ssim(&batch(&p.0, &q.0), &batch(&p.1, &q.1)).unwrap().to_scalar::<f32>().unwrap() as f64;
    let eval = (campro_eval::quality::ssim(&p.0, &p.1) + campro_eval::quality::ssim(&q.0, &q.1)) / 2.0;
    assert!((ours - eval).abs() < 1e-4, "batch: candle {ours}, evaluation {eval}");
    // By hand: flat images a and b have no variance, so SSIM = (2ab + C1) / (a² + b² + C1).
    // f32's E[x²] − μ² leaves about 3e-8 of variance against C2 = 9e-4: 1e-4 of SSIM here.
    let flat = |v: f32| Tensor::full(v, (1, 3, 12, 12), &Device::Cpu).unwrap();
    let by_hand = (2.0 * 0.2 * 0.6 + 1e-4) / (0.04 + 0.36 + 1e-4);
    let ours = ssim(&flat(0.2), &flat(0.6)).unwrap().to_scalar::<f32>().unwrap() as f64;
    assert!((ours - by_hand).abs() < 1.5e-4, "{ours} against {by_hand}");
    assert!(ssim(&flat(0.2), &Tensor::zeros((1, 3, 10, 12), candle_core::DType::F32, &Device::Cpu).unwrap()).is_err());
}

#[test]
fn the_ssim_gradient_is_what_finite_differences_give() {
    let a = (noise(&[1, 2, 14, 13], 21, 0.4) + 0.5).unwrap();
    let b = (noise(&[1, 2, 14, 13], 22, 0.4) + 0.5).unwrap();
    let var = candle_core::Var::from_tensor(&a).unwrap();
    let grads = campro_train::ssim::ssim(var.as_tensor(), &b).unwrap().backward().unwrap();
    let analytic: Vec<f32> = grads.get(var.as_tensor()).unwrap().flatten_all().unwrap().to_vec1().unwrap();
    let a0: Vec<f32> = a.flatten_all().unwrap().to_vec1().unwrap();
    let at = |k: usize, d: f32| {
        let mut v = a0.clone();
        v[k] += d;
        let t = Tensor::from_vec(v, a.dims(), &Device::Cpu).unwrap();
        campro_train::ssim::ssim(&t, &b).unwrap().to_scalar::<f32>().unwrap() as f64
    };
    let eps = 2e-3f32;
    // Corners (one window), edges and the middle (many), in both channels.
    for k in [0, 6, 12, 91, 95, 181, 182, 200, 270, 363] {
        let d = (at(k, eps) - at(k, -eps)) / (2.0 * eps as f64);
        let g = analytic[k] as f64;
        assert!((g - d).abs() <= 0.03 * d.abs().max(g.abs()) + 3e-4, "pixel {k}: autograd {g}, difference {d}");
    }
    assert!(analytic.iter().any(|g| g.abs() > 1e-3), "no gradient");
}

#[test]
fn an_ssim_term_trains_the_structure_back() {
    // The same fixed batch trained with and without the SSIM term (equal seeds and steps):
    // the step loss falls, and the term leaves a higher SSIM against raw.
    use candle_nn::{AdamW, Optimizer, ParamsAdamW};
    let raw = (noise(&[2, 3, 32, 32], 7, 0.5) + 0.5).unwrap();
    let b = campro_train::scenes::SceneBatch {
        input: (1.0 - &raw).unwrap(),
        captured: (1.0 - &raw).unwrap(),
        raw: raw.clone(),
        keep: Tensor::ones((2, 1, 32, 32), candle_core::DType::F32, &Device::Cpu).unwrap(),
    };
    let train = |ssim_weight: f64| {
        let mut cfg = EnhancerConfig { loss: PixelLoss::L2, ssim_weight, ..Default::default() };
        cfg.model = shape(&[4, 8], 0);
        let u = Unet::new(&cfg.model, 5, &Device::Cpu).unwrap();
        let mut adam = AdamW::new(u.vars(), ParamsAdamW { lr: 1e-2, weight_decay: 0.0, ..Default::default() }).unwrap();
        let first = campro_train::enhancer::step_loss(&u, &cfg, &b).unwrap().0.to_scalar::<f32>().unwrap();
        for _ in 0..60 {
            adam.step(&campro_train::enhancer::step_loss(&u, &cfg, &b).unwrap().0.backward().unwrap()).unwrap();
        }
        let last = campro_train::enhancer::step_loss(&u, &cfg, &b).unwrap().0.to_scalar::<f32>().unwrap();
        assert!(last < 0.5 * first, "ssim_weight {ssim_weight}: loss {first} -> {last}");
        campro_train::ssim::ssim(&u.forward(&b.input).unwrap(), &raw).unwrap().to_scalar::<f32>().unwrap()
    };
    let (plain, with) = (train(0.0), train(1.0));
    assert!(with > plain, "SSIM after training: {plain} with L2 alone, {with} with the term");
}
