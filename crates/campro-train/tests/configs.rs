//! The bundled training configurations parse and pass their rules, and the GPU pack's reads
//! only what `docs/scripts/gpu-pack.sh` packs (every input under `gpu-pack/shared/`, the
//! files that script copies), so a lent GPU machine needs nothing else.

use campro_train::config::Config;
use std::path::Path;

fn configs() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("configs")
}

#[test]
fn every_camera_configuration_parses() {
    let mut n = 0;
    for e in std::fs::read_dir(configs()).unwrap() {
        let path = e.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.starts_with("omega-") || name == "gpu-pack.toml" || name == "privacy-player.toml" {
            Config::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
            n += 1;
        }
    }
    assert!(n >= 8, "only {n} configurations");
}

#[test]
fn the_gpu_pack_reads_only_what_it_packs() {
    let c = Config::load(&configs().join("gpu-pack.toml")).unwrap();
    let script = std::fs::read_to_string(campro_testkit::workspace_root().join("docs/scripts/gpu-pack.sh")).unwrap();
    for (key, path) in c.inputs() {
        let rel = path
            .strip_prefix("gpu-pack/shared")
            .unwrap_or_else(|_| panic!("{key}: {} is outside the pack", path.display()));
        // A model file is one the script copies; a folder one it makes.
        let name = rel.file_name().unwrap().to_string_lossy();
        assert!(script.contains(&*name), "{key}: the pack script does not copy {name}");
    }
    assert!(c.budget.seconds <= 300.0, "a device session is minutes long");
}
