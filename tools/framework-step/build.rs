//! Generates burn modules from the two shared ONNX files (YOLOX-Nano; MobileFaceNet, the
//! batch-norm folded export of the training checkpoint), upgraded to opset 16 by
//! `upgrade_opset.py` into `$ONNX16_DIR` (burn-import reads opset ≥ 16 only).
fn main() {
    println!("cargo:rerun-if-env-changed=ONNX16_DIR");
    let dir = std::env::var("ONNX16_DIR").expect("set ONNX16_DIR to the output folder of upgrade_opset.py");
    for m in ["yolox_nano.onnx", "mobilefacenet_casia.onnx"] {
        let p = format!("{dir}/{m}");
        println!("cargo:rerun-if-changed={p}");
        burn_import::onnx::ModelGen::new().input(&p).out_dir("model/").run_from_script();
    }
}
