//! The TOML configuration: defaults are the paper's, unknown keys and broken rules are
//! refused with the key named.

use campro_train::config::{Config, ConfigError, Head};

#[test]
fn empty_file_gives_the_paper_settings() {
    let c = Config::parse("", "c.toml").unwrap();
    assert_eq!((c.camera.knots, c.camera.gamma, c.camera.lr), (32, 2.2, 1e-3));
    assert_eq!((c.attacker.lr, c.attacker.head), (0.1, Head::Softmax));
    assert_eq!(c.protector.omega, 0.2);
    assert!(!c.protector.protector_only);
}

#[test]
fn a_full_file_round_trips() {
    let mut c = Config { seed: 7, ..Config::default() };
    c.protector.omega = 5.0;
    c.protector.protector_only = true;
    c.attacker.head = Head::Arcface;
    c.data.max_identities = Some(10);
    let text = toml::to_string(&c).unwrap();
    assert_eq!(Config::parse(&text, "c.toml").unwrap(), c);
}

fn rule(text: &str) -> (String, String) {
    match Config::parse(text, "c.toml") {
        Err(ConfigError::Rule { key, rule, .. }) => (key, rule),
        other => panic!("expected a rule error, got {other:?}"),
    }
}

#[test]
fn bad_values_name_the_key() {
    assert_eq!(rule("[camera]\nknots = 1").0, "camera.knots");
    assert_eq!(rule("[camera]\nlr = nan").0, "camera.lr");
    assert_eq!(rule("[camera]\nlr = inf").0, "camera.lr");
    assert_eq!(rule("[protector]\nomega = -1.0").0, "protector.omega");
    assert_eq!(rule("[attacker]\nsteps_per_round = 0").0, "attacker.steps_per_round");
    // ... which protector-only allows.
    assert!(Config::parse("[attacker]\nsteps_per_round = 0\n[protector]\nprotector_only = true", "c.toml").is_ok());
    assert_eq!(rule("[data]\nvalidation_identities = 1.0").0, "data.validation_identities");
    assert_eq!(rule("[budget]\nseconds = 0.0").0, "budget.seconds");
    assert_eq!(rule("[detector]\nsize = 100").0, "detector.size");
    assert_eq!(rule("[detector]\nlr = -1.0").0, "detector.lr");
    assert_eq!(rule("[detector]\ndistill = -0.5").0, "detector.distill");
    assert_eq!(rule("[detector]\ndistill = nan").0, "detector.distill");
    assert_eq!(rule("[detector]\nadapter = 100000").0, "detector.adapter");
    assert_eq!(rule("[detector]\nadapter = 16\nadapter_lr = -1e-3").0, "detector.adapter_lr");
    assert_eq!(rule("[detector]\nadapter_fit = 10").0, "detector.adapter_fit");
    assert_eq!(rule("[validation]\npatience = 3").0, "validation.patience");
    assert_eq!(rule("[validation]\nevery = 25\nimages = 0").0, "validation.images");
    assert_eq!(rule("[validation]\nmax_top1 = 1.5").0, "validation.max_top1");
    assert!(Config::parse("[validation]\nevery = 25\npatience = 4\nmax_top1 = 0.01", "c.toml").is_ok());
}

#[test]
fn malformed_files_and_unknown_keys_are_refused() {
    for (text, needle) in [
        ("[camera]\nknotz = 3", "unknown field `knotz`"),
        ("[camera]\nknots = \"many\"", "invalid type"),
        ("[camera\nknots = 3", "line 1"),
        ("seed = -1", "invalid value"),
        ("[attacker]\nhead = \"cosface\"", "unknown variant"),
    ] {
        match Config::parse(text, "c.toml") {
            Err(ConfigError::Parse { message, .. }) => assert!(message.contains(needle), "{text:?}: {message}"),
            other => panic!("{text:?}: {other:?}"),
        }
    }
}

#[test]
fn shipped_configs_parse() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut omegas = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let path = e.unwrap().path();
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        if stem.starts_with("enhancer") || stem == "restorer" {
            // `campro train-enhancer`'s, with its own keys; the name says the loss, and
            // whether faces are restored (the attacker's network) or held to the input.
            let c: campro_train::config::EnhancerConfig = campro_train::config::load(&path).unwrap();
            assert_eq!((c.model.widths.as_slice(), c.model.restorer), (&[8, 16, 32, 64][..], true));
            assert_eq!(c.loss == campro_train::config::PixelLoss::L2, stem.contains("l2"), "{stem}");
            assert_eq!(c.privacy.weight > 0.0, stem.ends_with("private"), "{stem}");
            assert_eq!(c.model.face_gate, stem.contains("gate"), "{stem}");
            assert_eq!(c.model.gate_blocks > 0, stem.contains("pixelate"), "{stem}");
            assert_eq!(c.ssim_weight > 0.0, stem.contains("ssim"), "{stem}");
            // The table alone: a fresh U-Net trained for no steps.
            assert_eq!(c.budget.steps == 0, stem == "enhancer-table", "{stem}");
            let restore = c.data.faces == campro_train::config::FaceTarget::Restore;
            assert_eq!(restore, stem == "restorer", "{stem}");
            // Every shipped run fits its own memory budget.
            let cost = campro_train::cost::enhancer_step(&c);
            eprintln!("{stem}: {} MiB, {:.1} s a step (budget.memory {})", cost.mib(), cost.seconds, c.budget.memory);
            campro_train::cost::check(&cost, c.budget.memory).unwrap();
            continue;
        }
        let c = Config::load(&path).unwrap();
        // The file name says what it trains.
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        if let Some(w) = name.strip_prefix("omega-") {
            assert_eq!(c.protector.omega, w.split('-').next().unwrap().parse::<f64>().unwrap(), "{name}");
        }
        assert_eq!(c.protector.protector_only, name == "protector-only", "{name}");
        assert_eq!(c.protector.grey > 0.0, name.ends_with("grey"), "{name}");
        // Adapter configurations distil too.
        assert_eq!(c.detector.adapter > 0, name.contains("adapter"), "{name}");
        assert_eq!(c.detector.distill > 0.0, name.ends_with("distill") || name.contains("adapter"), "{name}");
        let cost = match name.starts_with("finetune") {
            true => campro_train::cost::detector_step(&c.detector),
            false => campro_train::cost::train_step(&c),
        };
        eprintln!("{name}: {} MiB, {:.1} s a step (budget.memory {})", cost.mib(), cost.seconds, c.budget.memory);
        campro_train::cost::check(&cost, c.budget.memory).unwrap();
        if name.starts_with("finetune") {
            continue; // read for its seed and [detector] only
        }
        // Only the validated run stops on validation; the name says a curve per channel.
        assert_eq!(c.validation.every > 0, name.ends_with("validated"), "{name}");
        assert_eq!(c.camera.per_channel, name.contains("per-channel"), "{name}");
        assert_eq!(c.camera.knots, if name.contains("-63-") { 63 } else { 32 }, "{name}");
        omegas.push(c.protector.omega);
    }
    omegas.sort_by(f64::total_cmp);
    // (gpu-pack.toml is omega-0.5.toml on the GPU pack's data.)
    assert_eq!(
        omegas,
        [0.0, 0.2, 0.2, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 5.0]
    );
}

/// The GPU pack's configuration reads only what `docs/scripts/gpu-pack.sh` packs (every
/// input under `gpu-pack/shared/`, each a file or folder the script copies or makes), so a
/// lent GPU machine needs nothing else, and it fits a device session.
#[test]
fn the_gpu_pack_reads_only_what_it_packs() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let c = Config::load(&dir.join("gpu-pack.toml")).unwrap();
    let script = std::fs::read_to_string(campro_testkit::workspace_root().join("docs/scripts/gpu-pack.sh")).unwrap();
    for (key, path) in c.inputs() {
        let rel = path
            .strip_prefix("gpu-pack/shared")
            .unwrap_or_else(|_| panic!("{key}: {} is outside the pack", path.display()));
        let name = rel.file_name().unwrap().to_string_lossy();
        assert!(script.contains(&*name), "{key}: the pack script does not copy {name}");
    }
    assert!(c.budget.seconds <= 300.0, "a device session is minutes long");
}

/// The step's cost by hand, from the coefficients' definitions (docs: campro_train::cost):
/// the paper's defaults (faces 16, people 4 x 320²) cost BASE 160 MiB plus the larger of the
/// attacker's 16 x 56 MiB and the protector's 16 x 40 MiB + 4 x 320² x 1,400 bytes
/// (546.875 MiB): 160 + 1,186.875, 1,347 MiB rounded up; a fine-tuning step is BASE and
/// the detector's part, 707 MiB; the enhancer's default U-Net (8, 16, 32, 64: 15 channels
/// at full resolution) on 8 crops of 128² costs 160 + 131,072 x 15 x 84 bytes (157.5 MiB),
/// 318 MiB. Every field of the product moves it.
#[test]
fn a_steps_cost_is_its_fields_together() {
    use campro_train::cost::{check, detector_step, enhancer_step, train_step};
    let c = Config::default();
    assert_eq!(train_step(&c).mib(), 1347);
    assert_eq!(detector_step(&c.detector).mib(), 707);
    let e = campro_train::config::EnhancerConfig::default();
    assert_eq!(enhancer_step(&e).mib(), 318);
    // The protector-only game has no attacker step; without omega no detector in it.
    let mut p = Config::default();
    p.protector.omega = 0.0;
    assert_eq!(train_step(&p).mib(), 160 + 896, "the attacker's step is then the larger");
    p.protector.protector_only = true;
    p.data.batch = 1;
    assert_eq!(train_step(&p).mib(), 707, "the detector step alone (the adapter's fit and P)");
    // Within the budget passes; over it names the fields and the figure.
    let mut big = Config::default();
    big.detector.size = 1024;
    big.detector.batch = 256;
    let cost = train_step(&big);
    assert!(cost.mib() > 100_000, "{}", cost.mib());
    let e = check(&cost, 1024).unwrap_err().to_string();
    assert!(e.starts_with("budget.memory: one step needs about") && e.contains("detector.size 1024"), "{e}");
    check(&train_step(&c), 1347).unwrap();
    assert!(check(&train_step(&c), 1346).is_err());
}
