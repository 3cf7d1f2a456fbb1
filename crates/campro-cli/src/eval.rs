//! `campro eval privacy|utility|quality|all`: the paper's evaluation with real models
//! (campro-eval), with CamPro parameter sets run through the exact 8-bit pipeline.

use crate::args::{AttackArg, Common, EnrolArg, EvalCmd, PrivacyArgs, UtilityArgs};
use crate::models::{load, manifest};
use crate::say;
use anyhow::{anyhow, bail, Context, Result};
use campro::pipeline::fast::Exact8;
use campro::Params;
use campro_eval::baselines::Baseline;
use campro_eval::face::{Embedder, FaceDetector};
use campro_eval::person::PersonDetector;
use campro_eval::privacy::{Enrolment, FaceModels, PrivacyOptions};
use campro_eval::scene::Scene;
use campro_eval::utility::UtilityOptions;
use campro_eval::{data, privacy, quality, report, utility, Condition};
use image::RgbImage;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The first error an enhancer met inside an evaluation (protections cannot fail, so an
/// enhanced condition records it here and passes the captured image on; the evaluation is
/// then refused).
#[derive(Clone, Default)]
pub(crate) struct Failures(std::sync::Arc<std::sync::Mutex<Option<String>>>);

impl Failures {
    pub(crate) fn record(&self, what: String) {
        self.0.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(what);
    }

    /// An error if any enhancement failed.
    pub(crate) fn check(&self) -> Result<()> {
        match self.0.lock().unwrap_or_else(|p| p.into_inner()).as_ref() {
            Some(e) => bail!("{e}"),
            None => Ok(()),
        }
    }
}

impl Common {
    /// Refuses an output folder that already holds files, unless --force: a quick look
    /// must not replace the reports of a long run.
    fn check_output(&self) -> Result<()> {
        crate::check_output_folder(&self.output, self.force, "--output")
    }
}

impl Common {
    fn shared(&self) -> PathBuf {
        self.data.shared_dir()
    }

    fn models_dir(&self) -> PathBuf {
        self.data.models_dir()
    }

    /// Raw, then each parameter set (and, with --enhanced, its enhanced images), then the
    /// baselines; enhancement errors are recorded in `failures`.
    fn conditions(&self, failures: &Failures) -> Result<Vec<Condition>> {
        let mut c = vec![Condition::raw()];
        for path in &self.params {
            let p = crate::load_params(path)?;
            let name = set_name(path);
            if c.iter().any(|x| x.name == name) {
                bail!("{}: two parameter sets are named {name:?}", crate::shown(path));
            }
            c.push(params_condition(name, p));
        }
        if self.enhanced {
            c = with_networks(self, &c, crate::capture::Network::Enhancer, "enhanced", failures)?;
        }
        let mut b = self.baselines.clone();
        if self.paper_baselines {
            b.extend(Baseline::paper());
        }
        for x in b {
            if !c.iter().any(|y| y.name == x.to_string()) {
                c.push(Condition::baseline(x));
            }
        }
        Ok(c)
    }
}

/// A parameter file's image-type name in the reports: its file stem.
fn set_name(path: &Path) -> String {
    if let Some(preset) = crate::presets::named(path) {
        return preset.name.to_string();
    }
    path.file_stem().map_or("params".into(), |s| s.to_string_lossy().into_owned())
}

/// A parameter set as a protection: the exact 8-bit desktop pipeline (bit-identical to the
/// f64 reference rounded to 8 bits).
pub fn params_condition(name: String, p: Params) -> Condition {
    let p: &'static Params = Box::leak(Box::new(p));
    let fast = Exact8::new(p);
    Condition::new(name, move |img: &RgbImage| {
        let mut out = RgbImage::new(img.width(), img.height());
        fast.run(img.as_raw(), &mut out);
        out
    })
}

fn face_detector(a: &PrivacyArgs, models: &Path) -> Result<FaceDetector> {
    Ok(FaceDetector::new(load(&a.face_detector, models)?)?)
}

fn face_models(a: &PrivacyArgs, models: &Path) -> Result<FaceModels> {
    Ok(FaceModels {
        detector: face_detector(a, models)?,
        embedders: a.face_models.iter().map(|n| Ok(Embedder::new(load(n, models)?)?)).collect::<Result<_>>()?,
    })
}

/// The typed provenance of a parameter file's JSON `text` (read without the rest of the
/// file's rules: an identity list or a detector is all that is wanted of it).
fn provenance_of(path: &Path, text: &str) -> Result<campro::provenance::Provenance> {
    let v: serde_json::Value = serde_json::from_str(text).with_context(|| path.display().to_string())?;
    let empty = serde_json::Map::new();
    let m = match v.get("provenance") {
        None | Some(serde_json::Value::Null) => &empty,
        Some(serde_json::Value::Object(m)) => m,
        Some(_) => bail!("{}: provenance: must be an object", crate::shown(path)),
    };
    campro::provenance::Provenance::read(m).map_err(|e| anyhow!("{}: {e}", crate::shown(path)))
}

/// Identity names from a trained parameter file (held-out identities) or a list file.
fn read_identities(path: &Path) -> Result<Vec<String>> {
    let text = match crate::presets::named(path) {
        Some(preset) => preset.json.to_string(),
        None => campro::file::read_text_capped(path, 16 << 20, "an identity list (--identities)")?,
    };
    let names: Vec<String> = if text.trim_start().starts_with('{') {
        provenance_of(path, &text)?.validation_identities.ok_or_else(|| {
            anyhow!(
                "{}: provenance.data.validation_identities: missing (not a parameter file from campro train)",
                path.display()
            )
        })?
    } else {
        text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).map(str::to_string).collect()
    };
    if names.is_empty() {
        bail!("{}: no identities", crate::shown(path));
    }
    Ok(names)
}

fn run_privacy(
    c: &Common,
    a: &PrivacyArgs,
    conds: &[Condition],
    failures: &Failures,
) -> Result<Vec<privacy::PrivacyReport>> {
    let start = std::time::Instant::now();
    let retrain = a.attacks.contains(&AttackArg::Retrain);
    if retrain && a.identities.is_none() {
        bail!("--attack retrain needs --identities: the probed identities, which re-training must never see");
    }
    // The attackers' networks first: a missing one is named before any data is read.
    let attacked;
    let conds = if a.attacks.contains(&AttackArg::RestoreNet) {
        attacked = with_networks(c, conds, crate::capture::Network::Restorer, "restore-net", failures)?;
        &attacked[..]
    } else {
        conds
    };
    let lfw_dir = a.lfw.clone().unwrap_or_else(|| c.shared().join("data/lfw"));
    if !lfw_dir.is_dir() {
        bail!("{}: no such folder (--lfw); {DATA_HELP}", crate::shown(&lfw_dir));
    }
    let lfw = data::Lfw::open(&lfw_dir).with_context(|| "reading LFW (set --lfw or --shared)")?;
    let identities = a.identities.as_deref().map(read_identities).transpose()?;
    if let (Some(names), Some(file)) = (&identities, &a.identities) {
        privacy::check_identities(&lfw, names).with_context(|| file.display().to_string())?;
    }

    let fm = face_models(a, &c.models_dir())?;
    let o = PrivacyOptions {
        runs: a.runs as usize,
        seed: a.seed,
        pool: a.pool,
        limit: c.limit,
        identities,
        distractors: a.distractors,
        verification: !a.no_verification,
        pairs_per_fold: a.pairs_per_fold.or(c.limit.map(|l| l.div_ceil(10).max(1))),
        enrolment: match a.enrol {
            EnrolArg::Raw => Enrolment::Raw,
            EnrolArg::Camera => Enrolment::Camera,
        },
        backdrops: Some(a.backdrops.clone().unwrap_or_else(|| c.shared().join("data/coco-person"))),
        ..Default::default()
    };
    let mut scenes: Vec<Scene> = a.conditions.iter().map(|&c| c.into()).collect();
    if scenes.is_empty() {
        scenes = Scene::ALL.to_vec();
    }
    scenes.sort_by_key(|s| Scene::ALL.iter().position(|x| x == s));
    scenes.dedup();
    let mut reports = Vec::with_capacity(scenes.len());
    let last = scenes.len() - 1;
    for (i, scene) in scenes.into_iter().enumerate() {
        let o = PrivacyOptions { scene, ..o.clone() };
        // The restoration attacker fits its table on the scene it attacks (a grey camera's
        // attacker knows it is grey).
        let restored;
        let conds = if a.restore {
            restored = with_restorations(c, a, conds, scene)?;
            &restored[..]
        } else {
            conds
        };
        // A condition with nothing to measure (pose on a few identities, none turned) is
        // said and left out while another condition has measured or still may.
        let mut r = match privacy::evaluate(&lfw, &fm, conds, &o) {
            Err(campro_eval::EvalError::NoIdentities(why)) if i < last || !reports.is_empty() => {
                eprintln!("warning: {why}: the {} condition is left out", scene.name());
                continue;
            }
            r => r?,
        };
        // Re-training attacks the colour scene (its cost is a training run).
        if let (true, Some(probed), Scene::Colour) = (retrain, &o.identities, scene) {
            let models = c.models_dir();
            let manifests = a.face_models.iter().map(|n| manifest(n, &models)).collect::<Result<Vec<_>>>()?;
            let sets: Vec<String> = c.params.iter().map(|p| set_name(p)).collect();
            let detector = || face_detector(a, &models);
            let rows =
                crate::retrain::attack(&lfw, probed, conds, &sets, &manifests, detector, &a.retrain, &o, &c.output)?;
            r.identification.extend(rows);
            r.seconds = start.elapsed().as_secs_f64();
        }
        let dir = if scene == Scene::Colour { c.output.clone() } else { c.output.join(scene.name()) };
        std::fs::create_dir_all(&dir).with_context(|| crate::shown(&dir))?;
        report::write_privacy(&r, &dir)?;
        eprintln!(
            "privacy ({}): {} identities, {:.0} s -> {}",
            scene.name(),
            r.identities,
            r.seconds,
            crate::shown(&dir.join("privacy.md"))
        );
        reports.push(r);
    }
    if reports.len() > 1 {
        report::write_conditions(&reports, &c.output)?;
    }
    Ok(reports)
}

/// A parameter set's network on a captured image.
type NetworkFn = dyn Fn(&RgbImage) -> campro_eval::Result<RgbImage> + Send + Sync;

/// `conds` with a "NAME SUFFIX" condition after each parameter set's: its network `which`
/// on the set's captured images (errors recorded in `failures`).
fn with_networks(
    c: &Common,
    conds: &[Condition],
    which: crate::capture::Network,
    suffix: &str,
    failures: &Failures,
) -> Result<Vec<Condition>> {
    let mut out = Vec::with_capacity(conds.len() * 2);
    for x in conds {
        out.push(x.clone());
        let Some(path) = c.params.iter().find(|p| set_name(p) == x.name) else { continue };
        let Some(protect) = x.protect.clone() else { continue };
        let net =
            crate::capture::network_of(path, &crate::load_params(path)?, which)?.with_scale(c.scale.enhance_scale);
        // What a person is shown passes the face guard; the attacker's restorer does not.
        let net: Box<NetworkFn> = match which {
            crate::capture::Network::Enhancer => {
                let guarded = campro_eval::guard::GuardedEnhancer {
                    enhancer: net,
                    guard: crate::capture::face_guard(&c.models_dir(), c.scale.faces.into())?,
                };
                Box::new(move |i| guarded.enhance(i))
            }
            crate::capture::Network::Restorer => Box::new(move |i| net.enhance(i)),
        };
        let (f, shown) = (failures.clone(), path.display().to_string());
        let key = which.key();
        out.push(Condition::new(format!("{} {suffix}", x.name), move |img: &RgbImage| {
            let captured = protect(img);
            net(&captured).unwrap_or_else(|err| {
                f.record(format!("{shown}: the {key}: {err}"));
                captured
            })
        }));
    }
    Ok(out)
}

/// `conds` with a "NAME restored" condition after each parameter set's (`--restore`).
fn with_restorations(c: &Common, a: &PrivacyArgs, conds: &[Condition], scene: Scene) -> Result<Vec<Condition>> {
    let dir = a.restore_prior.clone().unwrap_or_else(|| c.shared().join("data/coco-person/images"));
    let mut paths = list_images(&dir).context("--restore-prior")?;
    paths.truncate(200);
    let prior =
        paths.iter().map(|p| data::read_rgb8(p).map(|i| scene.apply(i))).collect::<campro_eval::Result<Vec<_>>>()?;
    let sets: Vec<String> = c.params.iter().map(|p| set_name(p)).collect();
    let mut out = Vec::with_capacity(conds.len() * 2);
    for x in conds {
        out.push(x.clone());
        if let (Some(p), true) = (&x.protect, sets.contains(&x.name)) {
            let r = campro_eval::restore::Restorer::fit(p.as_ref(), &prior)?;
            let p = p.clone();
            out.push(Condition::new(format!("{} restored", x.name), move |img: &RgbImage| r.apply(&p(img))));
        }
    }
    eprintln!("restoration prior: {} {} images from {}", prior.len(), scene.name(), crate::shown(&dir));
    Ok(out)
}

fn run_utility(c: &Common, a: &UtilityArgs, conds: &[Condition]) -> Result<utility::UtilityReport> {
    let coco_dir = a.coco.clone().unwrap_or_else(|| c.shared().join("data/coco-person"));
    let images =
        data::coco_person(&coco_dir).with_context(|| "reading the COCO person set (set --coco or --shared)")?;
    let model = load(&a.person_detector, &c.models_dir())?;
    let name = model.manifest.name.clone();
    let det = PersonDetector::new(model)?;
    let o = UtilityOptions { limit: c.limit, confidence: a.confidence, held_out: a.held_out || a.own_detector };
    let own = if a.own_detector { own_detectors(&c.params)? } else { HashMap::new() };
    let shared: Vec<Condition> = conds.iter().filter(|x| !own.contains_key(&x.name)).cloned().collect();
    let mut r = utility::evaluate(&images, &det, &name, &shared, &o)?;
    // Each set's captured images with its own detector, and its enhanced ones with both.
    let mut order: Vec<String> = Vec::new();
    for x in conds {
        order.push(x.name.clone());
        let base = x.name.strip_suffix(" enhanced").unwrap_or(&x.name);
        let Some(detector) = own.get(base) else { continue };
        let m = detector.load(&c.models_dir())?;
        let mut y = x.clone();
        if base != x.name {
            y.name = format!("{} (own detector)", x.name);
            order.push(y.name.clone());
        }
        let rx = utility::evaluate(&images, &PersonDetector::new(m)?, &y.name, std::slice::from_ref(&y), &o)?;
        r.rows.extend(rx.rows);
        r.seconds += rx.seconds;
    }
    if !own.is_empty() {
        r.rows.sort_by_key(|row| order.iter().position(|n| *n == row.condition));
        let mut names: Vec<&String> = own.keys().collect();
        names.sort();
        r.detector = format!(
            "{name}; {} each with its own fine-tuned detector",
            names.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    report::write_utility(&r, &c.output)?;
    eprintln!("utility: {} images, {:.0} s -> {}", r.images, r.seconds, crate::shown(&c.output.join("utility.md")));
    Ok(r)
}

/// A parameter set's own fine-tuned person detector.
pub(crate) enum OwnDetector {
    /// The manifest file its provenance names (`provenance.detector.manifest`).
    Manifest(PathBuf),
    /// YOLOX-Nano's bundled manifest with the set's network: the file its provenance names
    /// (`provenance.detector.onnx`), or the one built into the binary with a bundled preset.
    Yolox { set: String, file: PathBuf, built_in: Option<&'static [u8]> },
}

impl OwnDetector {
    /// The file it is read from (a built-in one's name).
    fn file(&self) -> &Path {
        match self {
            OwnDetector::Manifest(m) => m,
            OwnDetector::Yolox { file, .. } => file,
        }
    }

    /// The detector, loaded (and said on stderr).
    pub(crate) fn load(&self, models: &Path) -> Result<campro_eval::model::Model> {
        match self {
            OwnDetector::Manifest(m) => crate::models::load(&m.to_string_lossy(), models),
            OwnDetector::Yolox { set, file, built_in } => {
                let mut m = crate::models::manifest("yolox-nano", models)?;
                m.name = crate::models::fine_tuned_name(set);
                m.file = file.clone();
                match built_in {
                    Some(bytes) => {
                        eprintln!("loading {} (built in)", m.name);
                        Ok(campro_eval::model::Model::from_bytes(m, bytes)?)
                    }
                    None => {
                        eprintln!("loading {} ({})", m.name, crate::shown(&m.file));
                        Ok(campro_eval::model::Model::load(m)?)
                    }
                }
            }
        }
    }
}

/// Parameter set name → the detector fine-tuned with it, for the sets whose provenance
/// names one (a bundled preset's is built in).
pub(crate) fn own_detectors(params: &[PathBuf]) -> Result<HashMap<String, OwnDetector>> {
    let mut own = HashMap::new();
    for path in params {
        let preset = crate::presets::named(path);
        if let Some(p) = preset {
            if let Some(bytes) = p.detector {
                let file = PathBuf::from(format!("{}.detector.onnx", p.name));
                own.insert(set_name(path), OwnDetector::Yolox { set: p.name.into(), file, built_in: Some(bytes) });
                continue;
            }
        }
        let text = match preset {
            Some(preset) => preset.json.to_string(),
            None => campro::file::read_text_capped(path, campro::params::MAX_JSON_BYTES as u64, "a parameter file")?,
        };
        let Some(d) = provenance_of(path, &text)?.detector else { continue };
        let detector = match &d.manifest {
            Some(m) => OwnDetector::Manifest(crate::capture::beside(path, "provenance.detector.manifest", m)?),
            None => OwnDetector::Yolox {
                set: set_name(path),
                file: crate::capture::beside(path, "provenance.detector.onnx", &d.onnx)?,
                built_in: None,
            },
        };
        if !detector.file().is_file() {
            let field = if d.manifest.is_some() { "manifest" } else { "onnx" };
            bail!("{}: provenance.detector.{field}: {} not found", crate::shown(path), crate::shown(detector.file()));
        }
        own.insert(set_name(path), detector);
    }
    Ok(own)
}

/// Where the evaluation's data comes from, for a message about a missing data folder.
pub(crate) const DATA_HELP: &str = "the evaluation reads COCO's people photos (DIR/data/coco-person: COCO 2017 val images with people, YOLO labels and instances_person.json; cocodataset.org, annotations CC BY 4.0) and LFW (DIR/data/lfw/images_deepfunneled: vis-www.cs.umass.edu/lfw) from a shared data folder DIR: pass --shared DIR or set CAMPRO_SHARED (docs/evaluation.md)";

/// The JPEG and PNG files of `dir`, sorted by name; none is an error.
fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    if !dir.is_dir() {
        bail!("{}: no such folder; {DATA_HELP}", crate::shown(dir));
    }
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list images", crate::shown(dir)))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| ["jpg", "jpeg", "png"].iter().any(|e| x.eq_ignore_ascii_case(e))))
        .collect();
    paths.sort();
    if paths.is_empty() {
        bail!("{}: no JPEG or PNG images", crate::shown(dir));
    }
    Ok(paths)
}

fn run_quality(
    c: &Common,
    images: Option<&Path>,
    held_out: bool,
    conds: &[Condition],
) -> Result<quality::QualityReport> {
    let dir = images.map(Path::to_path_buf).unwrap_or_else(|| c.shared().join("data/coco-person/images"));
    let mut paths = list_images(&dir)?;
    if held_out {
        // COCO files are named by their id.
        paths.retain(|p| {
            p.file_stem()
                .and_then(|s| s.to_str())
                .and_then(|s| s.parse::<u64>().ok())
                .is_some_and(data::detector_held_out)
        });
        if paths.is_empty() {
            bail!("--held-out: no image of {} is named by a held-out COCO id", crate::shown(&dir));
        }
    }
    // With the enhanced view, colour fidelity leaves out the faces the face guard's
    // detectors find in the raw image (widened as the guard widens them): the enhanced
    // view pixelates them on purpose.
    let guard = if c.enhanced {
        Some(crate::capture::face_guard(&c.models_dir(), campro_eval::guard::Hide::Pixelate)?)
    } else {
        None
    };
    let faces = |img: &image::RgbImage| -> campro_eval::Result<Vec<[u32; 4]>> {
        let found = guard.as_ref().map(|g| g.find(img)).transpose()?.unwrap_or_default();
        Ok(found.iter().filter_map(|f| campro_eval::guard::widened(f.bbox, img.width(), img.height())).collect())
    };
    let r = quality::evaluate(&paths, conds, c.limit, guard.as_ref().map(|_| &faces as &quality::FacesFn<'_>))?;
    report::write_quality(&r, &c.output)?;
    eprintln!("quality: {} images, {:.0} s -> {}", r.images, r.seconds, crate::shown(&c.output.join("quality.md")));
    Ok(r)
}

pub fn run(cmd: EvalCmd) -> Result<()> {
    let common = match &cmd {
        EvalCmd::Frontier { points, output, force } => return run_frontier(points, output, *force),
        EvalCmd::Thresholds { data, lfw, face_detector, face_models, folds } => {
            return run_thresholds(data, lfw.as_deref(), face_detector, face_models, *folds as usize)
        }
        EvalCmd::Privacy { common, .. }
        | EvalCmd::Utility { common, .. }
        | EvalCmd::Quality { common, .. }
        | EvalCmd::All { common, .. } => common,
    };
    common.check_output()?;
    let f = Failures::default();
    match cmd {
        EvalCmd::Privacy { common, p } => {
            run_privacy(&common, &p, &common.conditions(&f)?, &f).map(drop).and(f.check())
        }
        EvalCmd::Utility { common, u } => run_utility(&common, &u, &common.conditions(&f)?).and(f.check()),
        EvalCmd::Quality { common, images, held_out } => {
            run_quality(&common, images.as_deref(), held_out, &common.conditions(&f)?).and(f.check())
        }
        EvalCmd::All { common, p, u } => {
            let conds = common.conditions(&f)?;
            let q = run_quality(&common, None, u.held_out || u.own_detector, &conds)?;
            let ur = run_utility(&common, &u, &conds)?;
            let pr = run_privacy(&common, &p, &conds, &f)?;
            f.check()?;
            report::write_summary(&pr, &ur, &q, &common.output)?;
            eprintln!("report: {}", crate::shown(&common.output.join("report.md")));
            Ok(())
        }
        EvalCmd::Frontier { .. } | EvalCmd::Thresholds { .. } => unreachable!("returned above"),
    }
}

/// `eval thresholds`: each model's calibration as a JSON line on stdout (its `thresholds`
/// object is what the manifest's task.thresholds holds).
fn run_thresholds(
    data: &crate::args::DataArgs,
    lfw: Option<&Path>,
    detector: &str,
    models: &[String],
    folds: usize,
) -> Result<()> {
    let lfw_dir = lfw.map(Path::to_path_buf).unwrap_or_else(|| data.shared_dir().join("data/lfw"));
    if !lfw_dir.is_dir() {
        bail!("{}: no such folder (--lfw); {DATA_HELP}", crate::shown(&lfw_dir));
    }
    let lfw = data::Lfw::open(&lfw_dir).with_context(|| "reading LFW (set --lfw or --shared)")?;
    let dir = data.models_dir();
    let det = FaceDetector::new(load(detector, &dir)?)?;
    for name in models {
        let e = Embedder::new(load(name, &dir)?)?;
        let start = std::time::Instant::now();
        let c = campro_eval::check::calibrate(&lfw, &det, &e, folds)?;
        eprintln!(
            "{}: {} images, {} pairs of different people, {:.0} s; genuine pairs accepted {:.3} at FAR 1e-3, {:.3} at 1e-2",
            c.model,
            c.images,
            c.thresholds.impostor_pairs,
            start.elapsed().as_secs_f64(),
            c.genuine_accept[0],
            c.genuine_accept[1]
        );
        say!("{}", serde_json::to_string(&c)?);
    }
    Ok(())
}

/// `eval frontier`: the plot and table of measured points.
fn run_frontier(points: &Path, output: &Path, force: bool) -> Result<()> {
    crate::check_output_folder(output, force, "--output")?;
    let bytes = campro::file::read_capped(points, 1 << 20, "the frontier points")?;
    let text = String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", crate::shown(points)))?;
    let p = campro_eval::frontier::parse(&text).with_context(|| points.display().to_string())?;
    // The report writers create the folder (campro::file::atomic).
    report::write_frontier(&p, output)?;
    eprintln!("frontier: {} points -> {}", p.len(), crate::shown(&output.join("frontier.md")));
    Ok(())
}
