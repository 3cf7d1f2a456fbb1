//! The alternating optimisation of CamPro's Algorithm 1: pretrain the attacker's proxy head
//! on raw faces, then per round m attacker steps (cross-entropy on C(x), camera frozen, F and
//! H updated by SGD) and n protector steps: `L_ns + ω·L_det`, the non-saturating privacy loss
//! `−log(1 − p_y)` through the frozen attacker plus the detection loss of the person detector
//! P on C(COCO people) ([`crate::detection::utility_loss`]; `detector.distill` adds a
//! distillation term from the unchanged detector on the raw people), into the camera (Adam,
//! then the CCM and curve projected into their ranges) and into P (Adam, fine-tuned
//! jointly). ω = 0 trains the privacy player alone and never loads P.

use crate::camera::Camera;
use crate::config::{Config, Head};
use crate::error::TrainError;
use crate::faces::{FaceSet, Selection};
use crate::log::LogRow;
use crate::persons::PersonSet;
use campro_nn::mobilefacenet::{l2_normalise, normalise_unit, MobileFaceNet};
use campro_nn::yolox::Yolox;
use candle_core::{DType, Tensor, Var, D};
use candle_nn::{AdamW, Optimizer, ParamsAdamW, SGD};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::collections::HashMap;

/// Where checkpoints go, and which one to resume from.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Written every `budget.checkpoint_every` rounds and at the end.
    pub checkpoints: Option<std::path::PathBuf>,
    pub resume: Option<std::path::PathBuf>,
    /// Start the camera here instead of at the identity (`campro train --init`); a resumed
    /// run takes its camera from the checkpoint instead.
    pub init: Option<Initial>,
    /// Where it computes (default: the CPU).
    pub ctx: campro_nn::Context,
}

/// A camera to start from: a learnt set continued with another configuration (another ω,
/// a distilling detector).
#[derive(Debug, Clone)]
pub struct Initial {
    /// CCM rows.
    pub ccm: [[f64; 3]; 3],
    /// Curve outputs at evenly spaced knots, `camera.knots` of them: one row (a shared
    /// curve) or three (red, green, blue).
    pub curves: Vec<Vec<f64>>,
    /// Degamma exponent: must be `camera.gamma`.
    pub gamma: f64,
    /// Where it came from, for the provenance (a file name).
    pub origin: String,
}

/// The learnt camera (campro's parameter model is built from it by the caller, which keeps
/// this crate independent of the core) and how it was learnt.
pub struct Outcome {
    /// Row-major CCM, entries in [−5, 5].
    pub ccm: [[f64; 3]; 3],
    /// Curve outputs at evenly spaced inputs, in [0, 1]: one row, or three (red, green,
    /// blue).
    pub curves: Vec<Vec<f64>>,
    pub gamma: f64,
    /// Config, data, seed, rounds, final losses, time.
    pub provenance: serde_json::Map<String, serde_json::Value>,
    /// The whole run's log, earlier resumed parts included.
    pub log: Vec<LogRow>,
    /// Training time of the whole run, earlier resumed parts included (s).
    pub seconds: f64,
    pub classes: usize,
    pub train_faces: usize,
    pub check_faces: usize,
    /// The fine-tuned person detector (ω > 0), to write as ONNX beside the parameters.
    pub detector: Option<Yolox>,
}

impl Initial {
    /// The camera of a parameter set, to continue from; `origin` names it in the
    /// provenance. The optimiser's curve has evenly spaced knots.
    pub fn from_params(params: &campro::Params, origin: &str) -> Result<Self, TrainError> {
        let c = &params.tone_curves;
        if !c.is_uniform() || c.each().iter().any(|t| t.len() != c.knots()) {
            return Err(TrainError::Unsupported(format!(
                "{origin}: tone_curve: the optimiser's camera needs evenly spaced knots, as many on every channel"
            )));
        }
        let curves = match c.shared() {
            Some(t) => vec![t.y().to_vec()],
            None => c.each().iter().map(|t| t.y().to_vec()).collect(),
        };
        Ok(Self { ccm: params.ccm, curves, gamma: params.degamma, origin: origin.into() })
    }
}

impl Outcome {
    /// The learnt camera as a parameter set called `name`, described by the run's
    /// configuration (`config_name`: the file it was read from) and carrying the run's
    /// provenance.
    pub fn params(&self, cfg: &Config, name: &str, config_name: &str) -> Result<campro::Params, TrainError> {
        let invalid = |e: campro::ValidationError| TrainError::Unsupported(format!("the learnt camera: {e}"));
        let curve = |y: &[f64]| campro::ToneCurve::uniform(y.to_vec()).map_err(invalid);
        let curves = match self.curves.as_slice() {
            [one] => campro::ToneCurves::Shared(curve(one)?),
            [r, g, b] => campro::ToneCurves::per_channel([curve(r)?, curve(g)?, curve(b)?]),
            rows => return Err(TrainError::Unsupported(format!("the learnt camera: {} curves", rows.len()))),
        };
        let mut params = campro::Params::new(self.ccm, curves, self.gamma).map_err(invalid)?;
        params.name = name.into();
        params.description = format!(
            "learnt by campro train from {config_name} ({}{}{})",
            if cfg.protector.omega > 0.0 {
                format!("privacy and utility players, omega {}", cfg.protector.omega)
            } else {
                "privacy player".into()
            },
            if cfg.protector.protector_only { ", protector only" } else { "" },
            if cfg.protector.grey > 0.0 { format!(", grey term {}", cfg.protector.grey) } else { String::new() }
        );
        params.provenance = self.provenance.clone();
        Ok(params)
    }
}

/// The proxy head H: a linear layer (softmax) or cosine logits with an angular margin
/// (ArcFace), over L2-normalised embeddings.
struct ProxyHead {
    w: Var,
    b: Option<Var>,
    kind: Head,
}

impl ProxyHead {
    const SCALE: f64 = 16.0;

    /// Starts from the scaled class means of the raw embeddings (a nearest-mean classifier).
    fn from_means(means: &Tensor, kind: Head) -> candle_core::Result<Self> {
        let w = Var::from_tensor(&(l2_normalise(means)? * Self::SCALE)?)?;
        let b = match kind {
            Head::Softmax => Some(Var::from_tensor(&Tensor::zeros(means.dim(0)?, DType::F32, means.device())?)?),
            Head::Arcface => None,
        };
        Ok(Self { w, b, kind })
    }

    fn vars(&self) -> Vec<Var> {
        let mut v = vec![self.w.clone()];
        v.extend(self.b.clone());
        v
    }

    /// Logits (B, classes); with labels, ArcFace adds its margin to the true class.
    fn logits(&self, e: &Tensor, labels: Option<&Tensor>) -> candle_core::Result<Tensor> {
        match self.kind {
            Head::Softmax => e.matmul(&self.w.t()?)?.broadcast_add(self.b.as_ref().expect("softmax head has a bias")),
            Head::Arcface => {
                let cos = e.matmul(&l2_normalise(&self.w)?.t()?)?.clamp(-1f32 + 1e-6, 1f32 - 1e-6)?;
                let Some(y) = labels else { return cos * 64.0 };
                // cos(θ + m) on the true class, m = 0.5.
                let (m_cos, m_sin) = (0.5f64.cos(), 0.5f64.sin());
                let sin = (1.0 - cos.sqr()?)?.sqrt()?;
                let with_margin = ((&cos * m_cos)? - (sin * m_sin)?)?;
                let onehot = candle_nn::encoding::one_hot(y.clone(), cos.dim(1)?, 1f32, 0f32)?;
                let mixed = (onehot.mul(&with_margin)? + (1.0 - &onehot)?.mul(&cos)?)?;
                mixed * 64.0
            }
        }
    }
}

/// The next `n` of `pool`, drawn epoch by epoch: `order` holds what is left of the current
/// shuffled epochs and is refilled with a fresh shuffle of `pool` when it runs short.
pub(crate) fn draw(order: &mut Vec<usize>, pool: &[usize], n: usize, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<usize> {
    if order.len() < n {
        let mut fresh = pool.to_vec();
        fresh.shuffle(rng);
        order.extend(fresh);
    }
    order.drain(..n.min(order.len())).collect()
}

/// The camera a run starts from: the identity, or `init` (its knots and degamma must be
/// the configuration's).
fn start_camera(cfg: &Config, init: Option<&Initial>, dev: &candle_core::Device) -> Result<Camera, TrainError> {
    let per_channel = cfg.camera.per_channel;
    let Some(i) = init else { return Ok(Camera::identity(cfg.camera.knots, per_channel, cfg.camera.gamma, dev)?) };
    let knots = i.curves.first().map_or(0, Vec::len);
    let Some(refined) = refine_knots(&i.curves, cfg.camera.knots) else {
        return Err(TrainError::Unsupported(format!(
            "--init {}: {knots} curve knots, but camera.knots is {} (a set continues on its own knots or on a grid that holds them: (k - 1)·m + 1)",
            i.origin, cfg.camera.knots
        )));
    };
    if i.curves.len() == 3 && !per_channel {
        return Err(TrainError::Unsupported(format!(
            "--init {}: a curve per channel, but camera.per_channel is false",
            i.origin
        )));
    }
    if i.gamma != cfg.camera.gamma {
        return Err(TrainError::Unsupported(format!(
            "--init {}: degamma {}, but camera.gamma is {}",
            i.origin, i.gamma, cfg.camera.gamma
        )));
    }
    // A shared curve continues as three equal ones where the configuration trains one per
    // channel.
    let curves = if per_channel && refined.len() == 1 { vec![refined[0].clone(); 3] } else { refined };
    let c = Camera::from_values(i.ccm, &curves, i.gamma, dev)?;
    c.project()?;
    Ok(c)
}

/// Evenly spaced curves of k knots on a grid of `knots` = (k - 1)·m + 1 knots that holds
/// every old one (each segment cut into m by linear interpolation): the same functions,
/// so a set continues exactly on a finer grid (32 knots on 63: the finest that, with the
/// point a range scale folds in, fits Camera2's 64). `None` for any other count.
pub fn refine_knots(curves: &[Vec<f64>], knots: usize) -> Option<Vec<Vec<f64>>> {
    let k = curves.first()?.len();
    if k < 2 || knots < k || !(knots - 1).is_multiple_of(k - 1) {
        return None;
    }
    let m = (knots - 1) / (k - 1);
    let refine = |y: &Vec<f64>| -> Vec<f64> {
        (0..knots)
            .map(|j| {
                let (i, r) = (j / m, j % m);
                if r == 0 {
                    y[i]
                } else {
                    let a = r as f64 / m as f64;
                    y[i] + a * (y[i + 1] - y[i])
                }
            })
            .collect()
    };
    Some(curves.iter().map(refine).collect())
}

/// The utility player (the person images and the detector the camera must keep working),
/// when the configuration weighs utility (`protector.omega > 0`).
fn utility_player(cfg: &Config, dev: &candle_core::Device) -> Result<Option<(PersonSet, Yolox)>, TrainError> {
    if cfg.protector.omega <= 0.0 {
        return Ok(None);
    }
    let set = PersonSet::open(&cfg.detector.data, cfg.detector.size, cfg.detector.max_images)?;
    if set.is_empty() {
        return Err(TrainError::Unsupported(format!("{}: no person images", cfg.detector.data.display())));
    }
    Ok(Some((set, crate::detection::student(&cfg.detector, cfg.seed, dev)?)))
}

/// How many of the `people` person training images the validation sets aside (the last
/// `validation.images`), refusing a count that would leave none to train on.
fn people_set_aside(v: &crate::config::ValidationConfig, people: usize, utility: bool) -> Result<usize, TrainError> {
    if v.every == 0 || !utility {
        return Ok(0);
    }
    if v.images >= people {
        return Err(TrainError::Unsupported(format!(
            "validation.images: {} of the {people} person training images would leave none to train on",
            v.images
        )));
    }
    Ok(v.images)
}

/// Where a run starts: round 1 with an empty log, or a checkpoint's next round.
struct Resumed {
    first_round: usize,
    log: Vec<LogRow>,
    earlier_seconds: f64,
    best: Option<crate::validation::Best>,
    best_tensors: Option<HashMap<String, Tensor>>,
}

impl Default for Resumed {
    fn default() -> Self {
        Resumed { first_round: 1, log: Vec::new(), earlier_seconds: 0.0, best: None, best_tensors: None }
    }
}

/// Loads the checkpoint in `dir` into the run's variables `named` (the face set and seed
/// must be the configuration's) and, with validation on, the best camera's tensors `best`.
fn resume(
    dir: &std::path::Path,
    cfg: &Config,
    classes: &[String],
    named: &[(String, Var)],
    best_names: &[String],
    dev: &candle_core::Device,
) -> Result<Resumed, TrainError> {
    // The tensors this run's checkpoint may hold: its variables, and the best camera's.
    let mut expected: crate::checkpoint::Expected = named.iter().map(|(n, v)| (n.clone(), v.dims().to_vec())).collect();
    for name in best_names {
        if let Some((_, v)) = named.iter().find(|(n, _)| n == name) {
            expected.insert(format!("best.{name}"), v.dims().to_vec());
        }
    }
    let (tensors, state) = crate::checkpoint::load::<crate::checkpoint::State>(dir, &expected, dev)?;
    crate::checkpoint::within_budget(dir, ("round", state.round), ("budget.rounds", cfg.budget.rounds))?;
    if state.classes != classes || state.seed != cfg.seed {
        return Err(TrainError::Unsupported(format!(
            "{}: checkpoint of another face set or seed: resume with its own configuration",
            dir.display()
        )));
    }
    let missing =
        |name: &str| TrainError::Unsupported(format!("{}: {name} missing from the checkpoint", dir.display()));
    for (name, var) in named {
        var.set(tensors.get(name).ok_or_else(|| missing(name))?)?;
    }
    // A resume without validation continues to its budget and writes its last camera.
    let best = state.best.filter(|_| cfg.validation.every > 0);
    let best_tensors = match best {
        Some(_) => Some(
            best_names
                .iter()
                .map(|name| {
                    let key = format!("best.{name}");
                    Ok((name.clone(), tensors.get(&key).ok_or_else(|| missing(&key))?.clone()))
                })
                .collect::<Result<_, TrainError>>()?,
        ),
        None => None,
    };
    Ok(Resumed {
        first_round: state.round + 1,
        earlier_seconds: state.log.last().map_or(0.0, |r| r.seconds),
        log: state.log,
        best,
        best_tensors,
    })
}

/// What a learnt parameter set records of its run: the configuration, the data, the rounds,
/// the final log line and the validation's rule and outcome.
#[allow(clippy::too_many_arguments)]
fn provenance(
    cfg: &Config,
    opts: &RunOptions,
    faces: &FaceSet,
    (train_faces, check_faces): (usize, usize),
    person_images: Option<usize>,
    (best, stopped_early, set_aside): (Option<crate::validation::Best>, bool, usize),
    log: &[LogRow],
    seconds: f64,
) -> serde_json::Map<String, serde_json::Value> {
    let v = &cfg.validation;
    let validation = (v.every > 0).then(|| {
        serde_json::json!({
            "rule": format!(
                "every {} rounds: the pretrained model's nearest-class-mean top-1 on the held-aside photos of training identities, and person AP on the last {} COCO training images (set aside); the best camera is the most useful within top-1 <= {}, else the most private; stop after {} validations without a better one (0: never)",
                v.every, set_aside, v.max_top1, v.patience
            ),
            "best_round": best.map(|b| b.round),
            "best": best.map(|b| b.scores),
            "stopped_early": stopped_early,
            "person_images_set_aside": set_aside,
        })
    });
    let prov = serde_json::json!({
        "optimiser": "campro-train",
        "config": cfg,
        "data": { "classes": faces.classes.len(), "train_faces": train_faces, "check_faces": check_faces, "skipped_no_face": faces.skipped, "validation_identities": faces.validation,
                  "person_images": person_images,
                  "person_images_held_out": format!("COCO id % {} == 0 (never trained on)", campro_eval::data::HOLDOUT_EVERY) },
        "init": opts.init.as_ref().map(|i| i.origin.clone()),
        "rounds": log.last().map_or(0, |r| r.round),
        "final": log.last(),
        "seconds": seconds,
        "validation": validation,
    });
    let serde_json::Value::Object(provenance) = prov else { unreachable!("a JSON object") };
    provenance
}

/// Stops a diverging run at the first non-finite loss, before it reaches the parameters.
fn finite(what: &str, v: f64) -> Result<(), TrainError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(TrainError::Diverged(format!(
            "{what} is {v}: lower attacker.backbone_lr / attacker.lr or camera.lr (the last checkpoint is intact)"
        )))
    }
}

/// Row-wise log Σ exp, stable.
fn logsumexp(z: &Tensor) -> candle_core::Result<Tensor> {
    let m = z.max_keepdim(D::Minus1)?.detach();
    (z.broadcast_sub(&m)?.exp()?.sum_keepdim(D::Minus1)?.log()? + m)?.squeeze(D::Minus1)
}

/// The paper's non-saturating privacy loss `−log(1 − p_y)`, batch mean, computed as
/// `LSE(z) − LSE(z without the true class)`: exact where `1 − p_y` underflows in f32 (a
/// confident attacker is where the protector starts).
pub fn non_saturating_loss(logits: &Tensor, y: &Tensor) -> candle_core::Result<Tensor> {
    let onehot = candle_nn::encoding::one_hot(y.clone(), logits.dim(1)?, 1f32, 0f32)?;
    let others = (logits - (onehot * 1e4)?)?;
    (logsumexp(logits)? - logsumexp(&others)?)?.mean_all()
}

fn accuracy(logits: &Tensor, y: &Tensor) -> candle_core::Result<f64> {
    let hit = logits.argmax(D::Minus1)?.eq(y)?.to_dtype(DType::F32)?.mean_all()?;
    Ok(hit.to_scalar::<f32>()? as f64)
}

/// Runs the optimisation described by `cfg`; `on_row` sees every log line as it happens.
pub fn run(cfg: &Config, opts: &RunOptions, mut on_row: impl FnMut(&LogRow)) -> Result<Outcome, TrainError> {
    crate::cost::check(&crate::cost::train_step(cfg), cfg.budget.memory)?;
    // Each input named, before any is read: one line for the first that is not there.
    if let Some((key, path)) = cfg.inputs().into_iter().find(|(_, p)| !p.exists()) {
        return Err(TrainError::Missing { key, path: path.display().to_string() });
    }
    let start = std::time::Instant::now();
    let game = Game::new(cfg, opts)?;
    let Resumed { first_round, mut log, earlier_seconds, best, best_tensors } = match &opts.resume {
        Some(dir) => resume(dir, cfg, &game.faces.classes, &game.named(), &game.kept_names(), &game.dev)?,
        None => Resumed::default(),
    };
    let mut kept = Kept { best, tensors: best_tensors };
    let seconds = || earlier_seconds + start.elapsed().as_secs_f64();
    let mut opt = Optimisers::new(&game)?;
    // Reseeded from the round on resume (see `checkpoint`).
    let mut draws = Draws {
        rng: rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ ((first_round as u64 - 1) << 32)),
        faces: Vec::new(),
        people: Vec::new(),
    };
    let validating = cfg.validation.every > 0;

    // Pretraining on raw faces until the head reaches the threshold (or the step budget).
    let (mut ce, mut acc) = (f64::NAN, 0.0);
    let pretrain = if first_round == 1 { cfg.attacker.pretrain_steps } else { 0 };
    for _ in 0..pretrain {
        let (x, y) = game.faces.batch(&draws.faces(&game), &game.dev)?;
        (ce, acc) = game.attacker_step(&x, &y, &mut opt)?;
        if acc >= cfg.attacker.pretrain_accuracy {
            break;
        }
    }
    // Round 0, or the resumed camera's check (logged only when the checkpoint had no log).
    // A fresh run validates the camera it starts from, so a run that never improves on it
    // keeps it.
    let first = if validating && first_round == 1 { Some(game.judge(0, &mut kept)?) } else { None };
    let row = LogRow {
        round: first_round - 1,
        seconds: seconds(),
        attacker_ce: ce,
        attacker_accuracy: acc,
        privacy_loss: f64::NAN,
        detection_loss: f64::NAN,
        check_accuracy: Some(game.check_accuracy(first_round > 1)?),
        validation_top1: first.map(|s| s.top1),
        validation_ap: first.and_then(|s| s.ap),
    };
    on_row(&row);
    if log.is_empty() {
        log.push(row);
    }
    let m = if cfg.protector.protector_only { 0 } else { cfg.attacker.steps_per_round };
    let mut stopped_early = false;
    for round in first_round..=cfg.budget.rounds {
        // The time budget is checked inside the round too: a round of many steps
        // (`attacker.steps_per_round`, `protector.steps_per_round`) stops at it.
        let over = || start.elapsed().as_secs_f64() >= cfg.budget.seconds;
        for _ in 0..m {
            if over() {
                break;
            }
            let (x, y) = game.faces.batch(&draws.faces(&game), &game.dev)?;
            let (x, y) = game.with_grey(x, y)?;
            (ce, acc) = game.attacker_step(&game.cam.forward(&x)?.detach(), &y, &mut opt)?;
        }
        let (mut lns, mut ldet) = (f64::NAN, f64::NAN);
        for k in 0..cfg.protector.steps_per_round {
            // At least one protector step a round, so that a round always moves the camera.
            if k > 0 && over() {
                break;
            }
            (lns, ldet) = game.protector_step(&mut draws, &mut opt)?;
        }
        let spent = round == cfg.budget.rounds || start.elapsed().as_secs_f64() >= cfg.budget.seconds;
        let validated = if validating && (round % cfg.validation.every == 0 || spent) {
            Some(game.judge(round, &mut kept)?)
        } else {
            None
        };
        stopped_early = !spent && crate::validation::should_stop(&kept.best, cfg.validation.patience);
        let last = spent || stopped_early;
        let checkpoint = round % cfg.budget.checkpoint_every == 0 || last;
        let check_acc = if checkpoint { Some(game.check_accuracy(true)?) } else { None };
        let row = LogRow {
            round,
            seconds: seconds(),
            attacker_ce: ce,
            attacker_accuracy: acc,
            privacy_loss: lns,
            detection_loss: ldet,
            check_accuracy: check_acc,
            validation_top1: validated.map(|s| s.top1),
            validation_ap: validated.and_then(|s| s.ap),
        };
        on_row(&row);
        log.push(row);
        if let (true, Some(dir)) = (checkpoint, &opts.checkpoints) {
            game.save(dir, round, &log, &kept)?;
        }
        if last {
            break;
        }
    }
    game.finish(opts, kept, stopped_early, log, seconds())
}

/// The best validated camera (and detector) so far: its round and scores, and its tensors by
/// name (without the `best.` prefix), what the parameter set and detector are written from.
struct Kept {
    best: Option<crate::validation::Best>,
    tensors: Option<HashMap<String, Tensor>>,
}

/// The optimisers of one run: SGD for the attacker's head H (at `attacker.lr`) and backbone F
/// (at `attacker.backbone_lr`), Adam for the camera C and the detector P, and the colour
/// adapter's fit (`detector.adapter_lr`).
struct Optimisers {
    head: SGD,
    backbone: SGD,
    camera: AdamW,
    detector: Option<crate::detection::DetectorAdam>,
    adapter: Option<crate::detection::AdapterFit>,
}

impl Optimisers {
    fn new(game: &Game) -> Result<Self, TrainError> {
        let cfg = game.cfg;
        let head = SGD::new(game.head.vars(), cfg.attacker.lr)?;
        let backbone = SGD::new(MobileFaceNet::trainable(&game.net_vars), cfg.attacker.backbone_lr)?;
        let camera =
            AdamW::new(game.cam.vars(), ParamsAdamW { lr: cfg.camera.lr, weight_decay: 0.0, ..Default::default() })?;
        let detector = match &game.utility {
            Some((_, det)) if cfg.detector.lr > 0.0 => Some(crate::detection::DetectorAdam::new(det, &cfg.detector)?),
            _ => None,
        };
        // A colour adapter in P (`detector.adapter`) is fitted to undo the camera, one step
        // per protector step.
        let adapter = match &game.utility {
            Some((_, det)) if cfg.detector.adapter_lr > 0.0 => {
                crate::detection::AdapterFit::new(det, cfg.detector.adapter_lr)?
            }
            _ => None,
        };
        Ok(Self { head, backbone, camera, detector, adapter })
    }
}

/// The run's draws: the seeded stream and what is left of the current shuffled epochs of the
/// training faces and of the people (see [`draw`]).
struct Draws {
    rng: rand_chacha::ChaCha8Rng,
    faces: Vec<usize>,
    people: Vec<usize>,
}

impl Draws {
    /// The next batch of training faces.
    fn faces(&mut self, game: &Game) -> Vec<usize> {
        draw(&mut self.faces, &game.train, game.cfg.data.batch, &mut self.rng)
    }

    /// The next batch of people (those not set aside for validation).
    fn people(&mut self, game: &Game) -> Vec<usize> {
        draw(&mut self.people, &game.drawn_people, game.cfg.detector.batch, &mut self.rng)
    }
}

/// The players of one run and the data they play on: the attacker (F and H), the camera C,
/// the utility player (COCO people and the detector P), and the validation's pretrained model.
struct Game<'a> {
    cfg: &'a Config,
    dev: candle_core::Device,
    faces: FaceSet,
    /// Indices into `faces`: trained on, and the check set.
    train: Vec<usize>,
    check: Vec<usize>,
    /// The attacker's backbone F (trained) and its variables by name.
    net: MobileFaceNet,
    net_vars: candle_nn::VarMap,
    /// The protector's view of the attacker: the same weights, no gradient computed for them.
    frozen: MobileFaceNet,
    head: ProxyHead,
    cam: Camera,
    /// COCO people and the detector P, when ω > 0.
    utility: Option<(PersonSet, Yolox)>,
    /// The unchanged detector the distillation term learns from (`detector.distill`).
    teacher: Option<Yolox>,
    /// The last `set_aside` people validate; the others (`drawn_people`) are drawn.
    set_aside: usize,
    drawn_people: Vec<usize>,
    /// The validation-driven stop (`crate::validation`): the pretrained face model scores
    /// privacy with the nearest of the raw class means (as rows).
    pretrained: Option<MobileFaceNet>,
    mean_rows: Vec<Vec<f32>>,
}

impl<'a> Game<'a> {
    fn new(cfg: &'a Config, opts: &RunOptions) -> Result<Self, TrainError> {
        let dev = opts.ctx.device.clone();
        let sel = Selection {
            lfw: cfg.data.lfw.clone(),
            min_images: cfg.data.min_images,
            validation_identities: cfg.data.validation_identities,
            max_identities: cfg.data.max_identities,
            seed: cfg.seed,
            exclude: Vec::new(),
        };
        let faces = FaceSet::load_or_build(&sel, &cfg.data.models, &cfg.data.cache)?;
        // The crops are held through the run: with one step they must fit the budget before
        // any network or batch is allocated.
        let mut cost = crate::cost::train_step(cfg);
        cost.bytes += faces.crops.len() as f64;
        cost.fields.push(format!("{} face crops (data.min_images, data.max_identities)", faces.labels.len()));
        crate::cost::check(&cost, cfg.budget.memory)?;
        let (train, check) = faces.split();
        let (net, net_vars) = MobileFaceNet::from_checkpoint(&cfg.attacker.checkpoint, &dev)?;
        let frozen = net.frozen();
        let cam = start_camera(cfg, opts.init.as_ref(), &dev)?;
        let utility = utility_player(cfg, &dev)?;
        let teacher = if utility.is_some() { crate::detection::teacher(&cfg.detector, &dev)? } else { None };
        let v = &cfg.validation;
        let people = utility.as_ref().map_or(0, |(set, _)| set.len());
        let set_aside = people_set_aside(v, people, utility.is_some())?;
        let pretrained =
            if v.every > 0 { Some(MobileFaceNet::from_checkpoint(&cfg.attacker.checkpoint, &dev)?.0) } else { None };
        // H from the class means of the raw training embeddings, through the frozen copy (the
        // same weights, no graph: the variables' graph kept every activation of a 64-face
        // batch, 1 GB and more).
        let embed = |x: &Tensor| frozen.embed(x, false);
        let means = faces.class_means(&train, &sel, &cfg.attacker.checkpoint, &cfg.data.cache, embed, &dev)?;
        let head = ProxyHead::from_means(&means, cfg.attacker.head)?;
        let mean_rows: Vec<Vec<f32>> = if v.every > 0 { means.to_vec2()? } else { Vec::new() };
        Ok(Self {
            cfg,
            dev,
            faces,
            train,
            check,
            net,
            net_vars,
            frozen,
            head,
            cam,
            utility,
            teacher,
            set_aside,
            drawn_people: (0..people - set_aside).collect(),
            pretrained,
            mean_rows,
        })
    }

    /// Everything a checkpoint holds, by name.
    fn named(&self) -> Vec<(String, Var)> {
        let mut v: Vec<(String, Var)> = self
            .net_vars
            .data()
            .lock()
            .expect("var map lock")
            .iter()
            .map(|(k, v)| (format!("attacker.{k}"), v.clone()))
            .collect();
        v.push(("camera.ccm".into(), self.cam.ccm.clone()));
        v.push(("camera.curve".into(), self.cam.curve.clone()));
        v.push(("head.w".into(), self.head.w.clone()));
        v.extend(self.head.b.clone().map(|b| ("head.b".to_string(), b)));
        if let Some((_, det)) = &self.utility {
            v.extend(det.named_vars().into_iter().map(|(k, var)| (format!("detector.{k}"), var)));
        }
        v
    }

    /// The variables a [`Kept`] holds: the camera's and the detector's.
    fn kept(&self) -> impl Iterator<Item = (String, Var)> {
        self.named().into_iter().filter(|(k, _)| k.starts_with("camera.") || k.starts_with("detector."))
    }

    fn kept_names(&self) -> Vec<String> {
        self.kept().map(|(k, _)| k).collect()
    }

    /// Writes the checkpoint of `round` to `dir`; the best validated camera travels in the
    /// same tensor file, as `best.NAME`.
    fn save(&self, dir: &std::path::Path, round: usize, log: &[LogRow], kept: &Kept) -> Result<(), TrainError> {
        let mut tensors: HashMap<String, Tensor> =
            self.named().into_iter().map(|(k, v)| (k, v.as_tensor().clone())).collect();
        if let Some(b) = &kept.tensors {
            tensors.extend(b.iter().map(|(k, t)| (format!("best.{k}"), t.clone())));
        }
        crate::checkpoint::save(
            dir,
            &tensors,
            &crate::checkpoint::State {
                round,
                seed: self.cfg.seed,
                classes: self.faces.classes.clone(),
                log: log.to_vec(),
                best: kept.best,
            },
        )?;
        Ok(())
    }

    /// The attacker's top-1 on the check faces, raw or through the camera.
    fn check_accuracy(&self, through_camera: bool) -> candle_core::Result<f64> {
        let mut hits = 0.0;
        for chunk in self.check.chunks(64) {
            let (x, y) = self.faces.batch(chunk, &self.dev)?;
            // Detached camera and frozen backbone: no graph is kept for a measurement.
            let x = if through_camera { self.cam.forward(&x)?.detach() } else { x };
            let e = self.frozen.embed(&x, false)?.detach();
            hits += accuracy(&self.head.logits(&e, None)?, &y)? * chunk.len() as f64;
        }
        Ok(hits / self.check.len().max(1) as f64)
    }

    /// One validation of the current camera (and detector): see `crate::validation`.
    fn validate(&self) -> Result<crate::validation::Scores, TrainError> {
        let net = self.pretrained.as_ref().expect("validating loads the pretrained model");
        let (mut emb, mut labels) = (Vec::new(), Vec::new());
        for chunk in self.check.chunks(64) {
            let (x, _) = self.faces.batch(chunk, &self.dev)?;
            let e: Vec<Vec<f32>> =
                net.forward_t(&normalise_unit(&self.cam.forward(&x)?.detach())?, false)?.to_vec2()?;
            emb.extend(e);
            labels.extend(chunk.iter().map(|&i| self.faces.labels[i]));
        }
        let top1 = crate::validation::nearest_top1(&emb, &labels, &self.mean_rows);
        let ap = match &self.utility {
            Some((set, det)) if self.set_aside > 0 => {
                let (mut heads, mut boxes) = (Vec::new(), Vec::new());
                let idx: Vec<usize> = (set.len() - self.set_aside..set.len()).collect();
                for chunk in idx.chunks(self.cfg.detector.batch) {
                    let pb = set.batch(chunk, &self.dev)?;
                    let out = self.cam.forward(&pb.x)?.detach();
                    let head = det.forward(&crate::persons::detector_input(&out, &pb.mask)?)?.detach();
                    heads.extend(head.flatten_from(1)?.to_vec2::<f32>()?);
                    boxes.extend(pb.boxes);
                }
                Some(crate::validation::person_ap(&heads, self.cfg.detector.size, &boxes)?)
            }
            _ => None,
        };
        Ok(crate::validation::Scores { top1, ap })
    }

    /// Validates the camera of `round` and keeps it (and the detector) if it is the new best.
    fn judge(&self, round: usize, kept: &mut Kept) -> Result<crate::validation::Scores, TrainError> {
        let s = self.validate()?;
        if crate::validation::offer(&mut kept.best, round, s, self.cfg.validation.max_top1) {
            kept.tensors =
                Some(self.kept().map(|(k, v)| Ok((k, v.as_tensor().copy()?))).collect::<candle_core::Result<_>>()?);
        }
        Ok(s)
    }

    /// The faces `x` (labels `y`) and, with the grey term on, the same faces grey after them.
    fn with_grey(&self, x: Tensor, y: Tensor) -> candle_core::Result<(Tensor, Tensor)> {
        if self.cfg.protector.grey > 0.0 {
            let g = crate::faces::grey(&x)?;
            Ok((Tensor::cat(&[&x, &g], 0)?, Tensor::cat(&[&y, &y], 0)?))
        } else {
            Ok((x, y))
        }
    }

    /// One attacker step on faces `x` with labels `y`: cross-entropy into H and F by SGD.
    /// Returns the loss and the batch's accuracy.
    fn attacker_step(&self, x: &Tensor, y: &Tensor, opt: &mut Optimisers) -> Result<(f64, f64), TrainError> {
        let logits = self.head.logits(&self.net.embed(x, self.cfg.attacker.train_batch_norm)?, Some(y))?;
        let ce = candle_nn::loss::cross_entropy(&logits, y)?;
        let loss = ce.to_scalar::<f32>()? as f64;
        finite("attacker cross-entropy", loss)?;
        let grads = ce.backward()?;
        opt.head.step(&grads)?;
        opt.backbone.step(&grads)?;
        Ok((loss, accuracy(&logits, y)?))
    }

    /// One protector step: `L_ns` through the frozen attacker on a batch of faces, plus
    /// ω·`L_det` on a batch of people when P plays, into the camera (then projected) and P;
    /// the adapter follows on the same people. Returns the two losses (NaN when absent).
    fn protector_step(&self, draws: &mut Draws, opt: &mut Optimisers) -> Result<(f64, f64), TrainError> {
        let cfg = self.cfg;
        let (x, y) = self.faces.batch(&draws.faces(self), &self.dev)?;
        let logits = self.head.logits(&self.frozen.embed(&self.cam.forward(&x)?, false)?, None)?;
        let mut loss = non_saturating_loss(&logits, &y)?;
        if cfg.protector.grey > 0.0 {
            let g = crate::faces::grey(&x)?;
            let logits = self.head.logits(&self.frozen.embed(&self.cam.forward(&g)?, false)?, None)?;
            loss = (loss + (non_saturating_loss(&logits, &y)? * cfg.protector.grey)?)?;
        }
        let lns = loss.to_scalar::<f32>()? as f64;
        finite("privacy loss", lns)?;
        let (mut ldet, mut seen) = (f64::NAN, None);
        if let Some((set, det)) = &self.utility {
            let pb = set.batch(&draws.people(self), &self.dev)?;
            let out = self.cam.forward(&pb.x)?;
            let (l, _) = crate::detection::utility_loss(det, self.teacher.as_ref(), &cfg.detector, &out, &pb)?;
            ldet = l.to_scalar::<f32>()? as f64;
            finite("detection loss", ldet)?;
            loss = (loss + (l * cfg.protector.omega)?)?;
            seen = Some((out.detach(), pb));
        }
        let grads = loss.backward()?;
        opt.camera.step(&grads)?;
        if let Some(a) = opt.detector.as_mut() {
            a.step(&grads)?;
        }
        if let (Some(f), Some((_, det)), Some((out, pb))) = (opt.adapter.as_mut(), &self.utility, &seen) {
            f.step(det, out, pb)?;
        }
        self.cam.project()?;
        Ok((lns, ldet))
    }

    /// The outcome: the best validated camera (and detector) loaded back, or the last.
    fn finish(
        self,
        opts: &RunOptions,
        kept: Kept,
        stopped_early: bool,
        log: Vec<LogRow>,
        seconds: f64,
    ) -> Result<Outcome, TrainError> {
        if let Some(b) = &kept.tensors {
            for (name, var) in self.named() {
                if let Some(t) = b.get(&name) {
                    var.set(t)?;
                }
            }
        }
        let provenance = provenance(
            self.cfg,
            opts,
            &self.faces,
            (self.train.len(), self.check.len()),
            self.utility.as_ref().map(|(set, _)| set.len()),
            (kept.best, stopped_early, self.set_aside),
            &log,
            seconds,
        );
        Ok(Outcome {
            ccm: self.cam.ccm_values()?,
            curves: self.cam.curve_values()?,
            gamma: self.cfg.camera.gamma,
            provenance,
            log,
            seconds,
            classes: self.faces.classes.len(),
            train_faces: self.train.len(),
            check_faces: self.check.len(),
            detector: self.utility.map(|(_, d)| d),
        })
    }
}
