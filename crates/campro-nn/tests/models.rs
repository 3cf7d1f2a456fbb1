//! The networks against independent implementations: MobileFaceNet from its PyTorch
//! checkpoint against the ONNX export run by tract.

use campro_nn::mobilefacenet::{normalise_unit, MobileFaceNet};
use campro_testkit as shared;
use candle_core::{DType, Device, Tensor};
use std::path::Path;

#[test]
fn mobilefacenet_checkpoint_matches_the_onnx_export() {
    let Some(ckpt) = shared::shared("models/mobilefacenet_casia_068.ckpt") else { return };
    let Some(face) = shared::shared("data/lfw/images_deepfunneled/Colin_Powell/Colin_Powell_0001.jpg") else { return };
    let models = ckpt.parent().unwrap();
    let (net, vars) = MobileFaceNet::from_checkpoint(&ckpt, &Device::Cpu).unwrap();
    // Every float tensor of the checkpoint is a variable of the network, and nothing else.
    let sd = campro_nn::torch_legacy::read_state_dict(&ckpt, Some("net_state_dict"), &Device::Cpu).unwrap();
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
    let e = campro_nn::mobilefacenet::l2_normalise(&e).unwrap();
    let got: Vec<f32> = e.flatten_all().unwrap().to_vec1().unwrap();
    let cos: f32 = got.iter().zip(&want).map(|(a, b)| a * b).sum();
    let worst = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    // Batch norm folded into the ONNX convolutions changes only float rounding.
    assert!(cos > 0.99999 && worst < 1e-3, "cosine {cos}, worst {worst}");
    assert_eq!(e.dtype(), DType::F32);
}
