//! Generates burn modules from the two shared ONNX files (YOLOX-Nano; MobileFaceNet, the
//! batch-norm folded export of the training checkpoint).
fn main() {
    let shared = std::env::var("CAMPRO_SHARED").unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared").into());
    for m in ["yolox_nano.onnx", "mobilefacenet_casia.onnx"] {
        let p = format!("{shared}/models/{m}");
        println!("cargo:rerun-if-changed={p}");
        burn_import::onnx::ModelGen::new().input(&p).out_dir("model/").run_from_script();
    }
}
