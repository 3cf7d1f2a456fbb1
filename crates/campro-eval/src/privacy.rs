//! Privacy: closed-set face identification (the paper's protocol, Sec. VI-A) and LFW
//! verification, raw against protected, for each face-recognition model.
//!
//! Identification: identities with ≥ 2 images; per run one random gallery image and a
//! different random probe image per identity. The gallery (the adversary's) is raw (see
//! Enrolment below), the probes are protected. Top-1 and CMC with (a) the nearest gallery
//! embedding by cosine and (b) a softmax linear classifier trained on the adversary's raw
//! images (every pool image of each identity except the probe). Two protection orders:
//! - `paper`: landmarks from the raw photo, the aligned crop is protected (the paper's order);
//! - `end-to-end`: the whole photo is protected, then the attacker detects and aligns; a
//!   face not found is not identified, and the detection rate is reported.
//!
//! Images whose raw photo has no detectable face are left out (counted), since neither
//! order can align them.
//!
//! Distractors: by default the gallery holds exactly the evaluated identities. With
//! `distractors`, other LFW identities with ≥ 2 photos join the gallery (and the linear
//! classifier's classes) with raw photos only, while probes still come from the evaluated
//! identities alone: the paper's closed set over every subject (1,680 in full LFW) with
//! the score kept to identities an optimiser never trained on.
//!
//! Enrolment: by default the adversary enrolled its gallery (and trained its linear
//! classifier) on raw photos, as the paper does. With `Enrolment::Camera` it enrolled them
//! through the same camera instead (each condition's own protected photos, aligned on the
//! raw landmarks, distractors too): the re-enrolment attacker, who matches protected to
//! protected and so wins whenever the camera keeps identities apart, even if it moves every
//! face far from its raw embedding. Verification then compares two protected photos.

use crate::data::{read_rgb8, Lfw};
use crate::error::{EvalError, Result};
use crate::face::{central_face, cosine, Embedder, Face, FaceDetector};
use crate::linear::{self, LinearOptions};
use crate::place::Stage;
use crate::scene::Scene;
use crate::Condition;
use image::RgbImage;
use indicatif::{ProgressBar, ProgressStyle};
use ndarray::Array2;
use rand::seq::{IndexedRandom, SliceRandom};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Settings of a privacy evaluation.
#[derive(Debug, Clone, Serialize)]
pub struct PrivacyOptions {
    /// Protocol repetitions (the paper: 10).
    pub runs: usize,
    /// Seed of the seeded choices (identities, images kept); run `r` draws its gallery and
    /// probes from `seed + 1 + r`.
    pub seed: u64,
    /// Images kept per identity (drawn once, seeded); gallery, probe and the linear
    /// classifier's training images come from this pool. At least 2.
    pub pool: usize,
    /// Use only this many identities (seeded choice), for quick looks.
    pub limit: Option<usize>,
    /// Use only these identities (LFW folder names), e.g. those an optimiser held out of
    /// training; applied before `limit`. A name LFW lacks is an error.
    pub identities: Option<Vec<String>>,
    /// Add up to this many other identities with ≥ 2 photos (seeded choice; `usize::MAX`:
    /// all of them) to the gallery as distractors, raw only; they are never probed.
    pub distractors: usize,
    /// Ranks reported on the CMC curve.
    pub cmc_ranks: usize,
    pub linear: LinearOptions,
    /// Run LFW verification on `pairs.txt`.
    pub verification: bool,
    /// Use at most this many pairs of each kind per fold.
    pub pairs_per_fold: Option<usize>,
    /// How the adversary's gallery and classifier photos were taken.
    pub enrolment: Enrolment,
    /// What the camera is pointed at ([`Scene`]).
    pub scene: Scene,
    /// The COCO person folder whose held-out images the small and group scenes paste faces
    /// into ([`crate::place::Stage`]); needed by those scenes only.
    pub backdrops: Option<PathBuf>,
}

/// How the adversary enrolled its gallery (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Enrolment {
    /// Raw photos (the paper's protocol).
    #[default]
    Raw,
    /// Photos through the same camera as the probes (paper order).
    Camera,
}

impl Default for PrivacyOptions {
    fn default() -> Self {
        Self {
            runs: 10,
            seed: 0,
            pool: 6,
            limit: None,
            identities: None,
            distractors: 0,
            cmc_ranks: 20,
            linear: LinearOptions::default(),
            verification: true,
            pairs_per_fold: None,
            enrolment: Enrolment::Raw,
            scene: Scene::Colour,
            backdrops: None,
        }
    }
}

/// Protection order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Order {
    Paper,
    EndToEnd,
}

impl Order {
    pub fn name(self) -> &'static str {
        match self {
            Order::Paper => "paper",
            Order::EndToEnd => "end-to-end",
        }
    }
}

/// One row of identification results.
#[derive(Debug, Clone, Serialize)]
pub struct IdentRow {
    pub condition: String,
    pub order: Order,
    pub model: String,
    pub classifier: &'static str,
    pub top1_mean: f64,
    pub top1_std: f64,
    /// Mean over runs of P(rank ≤ k), k = 1..=cmc_ranks.
    pub cmc: Vec<f64>,
    /// End-to-end only: share of probe photos in which the attacker found a face.
    pub detection_rate: Option<f64>,
}

/// One row of verification results.
#[derive(Debug, Clone, Serialize)]
pub struct VerifRow {
    pub condition: String,
    pub model: String,
    /// 10-fold accuracy (threshold chosen on the other nine folds).
    pub accuracy_mean: f64,
    pub accuracy_std: f64,
    /// True accepts at the threshold where at most 1e-3 of the different pairs pass (pooled;
    /// with fewer than 1000 different pairs that is no false accept at all).
    pub tar_at_far_1e3: f64,
    pub pairs: usize,
}

/// Everything a privacy evaluation measured.
#[derive(Debug, Clone, Serialize)]
pub struct PrivacyReport {
    pub options: PrivacyOptions,
    /// Identities probed.
    pub identities: usize,
    /// Identities in the gallery: those probed plus the distractors (chance is 1 / this).
    pub gallery: usize,
    pub images: usize,
    /// Pool images left out because no face was found in the raw photo.
    pub raw_undetected: usize,
    pub pairs_skipped_absent: usize,
    pub pairs_skipped_undetected: usize,
    pub identification: Vec<IdentRow>,
    pub verification: Vec<VerifRow>,
    /// Pose only: the median turn of the probe photos ([`crate::place::turn`]: yaw in eye
    /// distances, or twice the pitch ratio's offset; 0 frontal, about 0.5 in profile).
    pub probe_turn: Option<f64>,
    pub seconds: f64,
}

/// The face models of an evaluation.
pub struct FaceModels {
    pub detector: FaceDetector,
    pub embedders: Vec<Embedder>,
}

/// Per image, per condition: the probe embeddings per model for each order.
#[derive(Default, Clone)]
struct Protected {
    paper: Vec<Vec<f32>>,
    /// None when the attacker found no face in the protected photo.
    e2e: Option<Vec<Vec<f32>>>,
}

struct Record {
    raw: Vec<Vec<f32>>,
    prot: Vec<Protected>,
}

fn progress(len: usize, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len as u64);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {elapsed_precise} eta {eta}")
            .unwrap()
            .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

/// What a photo is embedded for, least to most.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Need {
    /// A distractor's: raw only.
    Raw,
    /// Verification: raw and protected in the paper's order.
    Paper,
    /// A probed identity's: both orders.
    EndToEnd,
}

/// Embeds one photo raw and, unless only the raw embedding is needed, under every
/// condition. Returns None when the raw photo has no face.
///
/// In a placed scene (`stage`: small, group) the camera sees the probe's face placed in
/// another picture ([`crate::place`]): the raw condition is that picture unprotected, and
/// the paper order aligns the protected picture on the placed face's raw landmarks (the
/// attacker knows where the face is, as a tracker would), while end-to-end detects faces
/// in the protected picture and takes the one on the placed face (box IoU ≥
/// [`PLACED_IOU`]).
fn embed_photo(
    path: &Path,
    m: &FaceModels,
    conds: &[Condition],
    need: Need,
    scene: Scene,
    stage: Option<&Stage>,
) -> Result<Option<Record>> {
    let (conds, e2e) = match need {
        Need::Raw => (&[][..], false),
        Need::Paper => (conds, false),
        Need::EndToEnd => (conds, true),
    };
    let img = scene.apply(read_rgb8(path)?);
    let Some(face) = central_face(&m.detector.detect(&img)?, img.width(), img.height()) else { return Ok(None) };
    let crops: Vec<_> = m.embedders.iter().map(|e| e.align(&img, &face.landmarks)).collect();
    let raw: Vec<Vec<f32>> = m.embedders.iter().zip(&crops).map(|(e, c)| e.embed(c)).collect::<Result<_>>()?;
    let placed = match (stage, scene) {
        (_, _) if conds.is_empty() => None,
        (Some(st), Scene::Small) => Some(st.small(path, &img, &face)?),
        (Some(st), Scene::Group) => Some(st.group(path, &img, &face, &m.detector)?),
        (None, s) if s.placed() => {
            return Err(EvalError::Invalid(format!("privacy: the {} condition needs its scenes", s.name())))
        }
        _ => None,
    };
    let embed_at = |pic: &RgbImage, lm: &[[f32; 2]; 5]| -> Result<Vec<Vec<f32>>> {
        m.embedders.iter().map(|e| e.embed(&e.align(pic, lm))).collect()
    };
    let mut prot = Vec::with_capacity(conds.len());
    for c in conds {
        if let Some(pl) = &placed {
            let pic = c.apply(&pl.image);
            let paper = embed_at(&pic, &pl.face.landmarks)?;
            let found = if e2e { on_placed(&m.detector.detect(&pic)?, &pl.face.bbox) } else { None };
            let e2e = found.map(|f| embed_at(&pic, &f.landmarks)).transpose()?;
            prot.push(Protected { paper, e2e });
            continue;
        }
        let Some(p) = &c.protect else {
            prot.push(Protected { paper: raw.clone(), e2e: Some(raw.clone()) });
            continue;
        };
        let paper = m.embedders.iter().zip(&crops).map(|(e, crop)| e.embed(&p(crop))).collect::<Result<_>>()?;
        let e2e = if e2e {
            let pimg = p(&img);
            let found: Option<Face> = central_face(&m.detector.detect(&pimg)?, pimg.width(), pimg.height());
            found.map(|f| embed_at(&pimg, &f.landmarks)).transpose()?
        } else {
            None
        };
        prot.push(Protected { paper, e2e });
    }
    Ok(Some(Record { raw, prot }))
}

/// The least box IoU with the placed face at which an end-to-end attacker's detection is
/// taken to be that face.
pub const PLACED_IOU: f32 = 0.3;

/// Of `faces` found in a picture, the one that overlaps the placed face's box `at` most,
/// if that is at least [`PLACED_IOU`].
fn on_placed(faces: &[Face], at: &[f32; 4]) -> Option<Face> {
    faces
        .iter()
        .map(|f| (crate::geometry::iou(f.bbox, *at), f))
        .filter(|(o, _)| *o >= PLACED_IOU)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, f)| *f)
}

/// A photo's embedding by model `mi` as the adversary enrolled it: raw (`None`) or through
/// condition `ci`'s camera in the paper's order (`Some(ci)`).
fn enrolled(r: &Record, mi: usize, view: Option<usize>) -> &[f32] {
    match view {
        None => &r.raw[mi],
        Some(ci) => &r.prot[ci].paper[mi],
    }
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 { v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    (m, var.sqrt())
}

/// Where `truth` stands among `scores`: how many score higher, and how many others tie it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rank {
    pub above: usize,
    pub tied: usize,
}

impl Rank {
    pub fn of(scores: &[f32], truth: usize) -> Rank {
        let t = scores[truth];
        Rank { above: scores.iter().filter(|&&s| s > t).count(), tied: scores.iter().filter(|&&s| s == t).count() - 1 }
    }

    /// P(rank ≤ n) when ties are broken uniformly at random: a camera that makes every
    /// face alike (all scores tied) identifies no better than chance, not perfectly.
    pub fn within(self, n: usize) -> f64 {
        (n.saturating_sub(self.above) as f64 / (self.tied + 1) as f64).min(1.0)
    }
}

/// Every name must be an LFW identity (checked before any model runs).
pub fn check_identities(lfw: &Lfw, names: &[String]) -> Result<()> {
    match names.iter().find(|n| !lfw.people.contains_key(*n)) {
        Some(missing) => Err(EvalError::Invalid(format!("privacy: identity {missing:?} is not in LFW"))),
        None => Ok(()),
    }
}

/// Runs the identification protocol (and verification) on LFW.
pub fn evaluate(lfw: &Lfw, models: &FaceModels, conds: &[Condition], o: &PrivacyOptions) -> Result<PrivacyReport> {
    if o.pool < 2 || o.runs == 0 {
        return Err(EvalError::Invalid("privacy: --pool must be ≥ 2 and --runs ≥ 1".into()));
    }
    let start = std::time::Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(o.seed);
    let mut ids: Vec<(&String, &Vec<PathBuf>)> = lfw.people.iter().filter(|(_, v)| v.len() >= 2).collect();
    if let Some(keep) = &o.identities {
        check_identities(lfw, keep)?;
        ids.retain(|(n, _)| keep.contains(n));
        if ids.is_empty() {
            return Err(EvalError::Invalid("privacy: none of the given identities has 2 or more photos".into()));
        }
    }
    if let Some(l) = o.limit {
        ids.shuffle(&mut rng);
        ids.truncate(l);
        ids.sort();
    }
    // Pose: each identity's most frontal photo first (always the gallery), then its most
    // turned ones (the probes); otherwise a seeded draw.
    let mut probe_turn = None;
    let pools: Vec<Vec<PathBuf>> = if o.scene == Scene::Pose {
        let (pools, turn) = pose_pools(&ids, &models.detector, o.pool, &mut rng)?;
        probe_turn = Some(turn);
        pools
    } else {
        ids.iter().map(|(_, v)| v.choose_multiple(&mut rng, o.pool.min(v.len())).cloned().collect()).collect()
    };
    let stage = match (o.scene.placed(), &o.backdrops) {
        (true, Some(dir)) => Some(Stage::new(dir, lfw, o.seed)?),
        (true, None) => {
            return Err(EvalError::Invalid(format!(
                "privacy: the {} condition needs the COCO scenes (--backdrops or --shared)",
                o.scene.name()
            )))
        }
        (false, _) => None,
    };
    // Distractors, drawn after the probed identities' pools so that those stay the same.
    let mut others: Vec<&Vec<PathBuf>> =
        lfw.people.iter().filter(|(n, v)| v.len() >= 2 && !ids.iter().any(|(m, _)| m == n)).map(|(_, v)| v).collect();
    if o.distractors < others.len() {
        others.shuffle(&mut rng);
        others.truncate(o.distractors);
        others.sort();
    }
    let other_pools: Vec<Vec<PathBuf>> =
        others.iter().map(|v| v.choose_multiple(&mut rng, o.pool.min(v.len())).cloned().collect()).collect();
    // Verification pairs (optionally capped per fold and kind).
    // Pose changes which photos are probed, not the pairs: its verification would be colour's.
    let verifying = o.verification && o.scene != Scene::Pose;
    let (mut pairs, absent) = if verifying { lfw.pairs()? } else { (Vec::new(), 0) };
    if let Some(cap) = o.pairs_per_fold {
        let mut seen: HashMap<(usize, bool), usize> = HashMap::new();
        pairs.retain(|p| {
            let n = seen.entry((p.fold, p.same)).or_default();
            *n += 1;
            *n <= cap
        });
    }
    // Every photo to embed, each for the most it is needed for.
    let mut todo: HashMap<PathBuf, Need> = HashMap::new();
    let mut need = |p: &PathBuf, n: Need| {
        let e = todo.entry(p.clone()).or_insert(n);
        *e = (*e).max(n);
    };
    pools.iter().flatten().for_each(|p| need(p, Need::EndToEnd));
    let distractor_need = if o.enrolment == Enrolment::Camera { Need::Paper } else { Need::Raw };
    other_pools.iter().flatten().for_each(|p| need(p, distractor_need));
    for p in &pairs {
        need(&p.a, Need::Paper);
        need(&p.b, Need::Paper);
    }
    let mut todo: Vec<(PathBuf, Need)> = todo.into_iter().collect();
    todo.sort();
    let pb = progress(todo.len(), "privacy: embedding faces");
    let records: Mutex<HashMap<PathBuf, Record>> = Mutex::new(HashMap::new());
    todo.par_iter().try_for_each(|(path, need)| -> Result<()> {
        if let Some(r) = embed_photo(path, models, conds, *need, o.scene, stage.as_ref())? {
            records.lock().unwrap().insert(path.clone(), r);
        }
        pb.inc(1);
        Ok(())
    })?;
    pb.finish_and_clear();
    let records = records.into_inner().unwrap();
    let raw_undetected = pools.iter().flatten().filter(|p| !records.contains_key(*p)).count();
    // Identities usable: ≥ 2 pool images with a raw face.
    let usable: Vec<Vec<&Record>> = pools
        .iter()
        .map(|p| p.iter().filter_map(|x| records.get(x)).collect::<Vec<_>>())
        .filter(|v| v.len() >= 2)
        .collect();
    let classes = usable.len();
    if classes == 0 {
        return Err(EvalError::NoIdentities(format!(
            "privacy ({}): no identity has two photos with a face{}; use more identities (--limit)",
            o.scene.name(),
            if o.scene == Scene::Pose { ", one of them turned by 0.2 or more" } else { "" }
        )));
    }
    // Distractors usable by the same rule; gallery rows and classifier classes after the
    // probed identities'.
    let extra: Vec<Vec<&Record>> = other_pools
        .iter()
        .map(|p| p.iter().filter_map(|x| records.get(x)).collect::<Vec<_>>())
        .filter(|v| v.len() >= 2)
        .collect();
    let gallery_size = classes + extra.len();
    let nm = models.embedders.len();
    let orders = [Order::Paper, Order::EndToEnd];
    // How condition `ci`'s adversary enrolled: through its camera, or raw (always for the
    // raw condition, whose camera is the identity).
    let view = |ci: usize| (o.enrolment == Enrolment::Camera && conds[ci].protect.is_some()).then_some(ci);
    // results[(cond, order, model, classifier)] = per-run (top1, cmc, detection rate)
    type Key = (usize, usize, usize, usize);
    let mut per_run: HashMap<Key, Vec<(f64, Vec<f64>, f64)>> = HashMap::new();
    let pbr = progress(o.runs, "privacy: identification runs");
    for run in 0..o.runs {
        let mut rng = ChaCha8Rng::seed_from_u64(o.seed.wrapping_add(1 + run as u64));
        let picks: Vec<(usize, usize)> = usable
            .iter()
            .map(|v| {
                if o.scene == Scene::Pose {
                    return (0, rand::Rng::random_range(&mut rng, 1..v.len()));
                }
                let g = rand::Rng::random_range(&mut rng, 0..v.len());
                let mut p = rand::Rng::random_range(&mut rng, 0..v.len() - 1);
                if p >= g {
                    p += 1;
                }
                (g, p)
            })
            .collect();
        let extra_picks: Vec<usize> = extra.iter().map(|v| rand::Rng::random_range(&mut rng, 0..v.len())).collect();
        for mi in 0..nm {
            let dim = usable[0][0].raw[mi].len();
            // The adversary's gallery and linear classifier, from raw photos (one for every
            // condition) or through each condition's camera.
            let enrol = |view: Option<usize>| {
                let row = |c: usize| {
                    if c < classes {
                        enrolled(usable[c][picks[c].0], mi, view)
                    } else {
                        enrolled(extra[c - classes][extra_picks[c - classes]], mi, view)
                    }
                };
                let gallery = Array2::from_shape_fn((gallery_size, dim), |(c, k)| row(c)[k]);
                // The linear classifier's training set: every usable image but the probe.
                let mut xs = Vec::new();
                let mut ys = Vec::new();
                for (c, v) in usable.iter().chain(&extra).enumerate() {
                    for (j, r) in v.iter().enumerate() {
                        if c >= classes || j != picks[c].1 {
                            xs.extend_from_slice(enrolled(r, mi, view));
                            ys.push(c);
                        }
                    }
                }
                let x = Array2::from_shape_vec((ys.len(), dim), xs).expect("rows of equal length");
                (gallery, linear::train(&x, &ys, gallery_size, &o.linear))
            };
            let raw_enrolled = enrol(None);
            let camera_enrolled: Vec<_> = (0..conds.len()).map(|ci| view(ci).map(|v| enrol(Some(v)))).collect();
            for (ci, enrolled) in camera_enrolled.iter().enumerate() {
                let (gallery, lin) = enrolled.as_ref().unwrap_or(&raw_enrolled);
                for (oi, &order) in orders.iter().enumerate() {
                    // None: the attacker found no face, so the probe is not identified.
                    let mut ranks: [Vec<Option<Rank>>; 2] = [Vec::new(), Vec::new()];
                    let mut found = 0usize;
                    for c in 0..classes {
                        let rec = usable[c][picks[c].1];
                        let probe = match order {
                            Order::Paper => Some(&rec.prot[ci].paper[mi]),
                            Order::EndToEnd => rec.prot[ci].e2e.as_ref().map(|e| &e[mi]),
                        };
                        let Some(q) = probe else {
                            ranks[0].push(None);
                            ranks[1].push(None);
                            continue;
                        };
                        found += 1;
                        let near: Vec<f32> =
                            gallery.rows().into_iter().map(|g| cosine(g.as_slice().unwrap(), q)).collect();
                        ranks[0].push(Some(Rank::of(&near, c)));
                        ranks[1].push(Some(Rank::of(&lin.scores(q), c)));
                    }
                    for (k, r) in ranks.iter().enumerate() {
                        let cmc: Vec<f64> = (1..=o.cmc_ranks)
                            // `+ 0.0`: an empty float sum is -0.0 (no probe found), shown as "-0.00".
                            .map(|n| r.iter().flatten().map(|x| x.within(n)).sum::<f64>() / classes as f64 + 0.0)
                            .collect();
                        per_run.entry((ci, oi, mi, k)).or_default().push((cmc[0], cmc, found as f64 / classes as f64));
                    }
                }
            }
        }
        pbr.inc(1);
    }
    pbr.finish_and_clear();
    let mut identification = Vec::new();
    for ci in 0..conds.len() {
        for (oi, &order) in orders.iter().enumerate() {
            for (mi, e) in models.embedders.iter().enumerate() {
                for (k, cls) in ["nearest", "linear"].iter().enumerate() {
                    let v = &per_run[&(ci, oi, mi, k)];
                    let (top1_mean, top1_std) = mean_std(&v.iter().map(|r| r.0).collect::<Vec<_>>());
                    let cmc =
                        (0..o.cmc_ranks).map(|i| v.iter().map(|r| r.1[i]).sum::<f64>() / v.len() as f64).collect();
                    let det = v.iter().map(|r| r.2).sum::<f64>() / v.len() as f64;
                    identification.push(IdentRow {
                        condition: conds[ci].name.clone(),
                        order,
                        model: e.name().to_string(),
                        classifier: cls,
                        top1_mean,
                        top1_std,
                        cmc,
                        detection_rate: (order == Order::EndToEnd).then_some(det),
                    });
                }
            }
        }
    }
    // Verification: the first photo as enrolled (raw, or through the camera), the second
    // protected (paper order).
    let mut verification = Vec::new();
    let usable_pairs: Vec<_> =
        pairs.iter().filter(|p| records.contains_key(&p.a) && records.contains_key(&p.b)).collect();
    if verifying {
        for (ci, c) in conds.iter().enumerate() {
            for (mi, e) in models.embedders.iter().enumerate() {
                let scored: Vec<(usize, bool, f32)> = usable_pairs
                    .iter()
                    .map(|p| {
                        (
                            p.fold,
                            p.same,
                            cosine(enrolled(&records[&p.a], mi, view(ci)), &records[&p.b].prot[ci].paper[mi]),
                        )
                    })
                    .collect();
                let (accuracy_mean, accuracy_std) = mean_std(&kfold_accuracy(&scored));
                verification.push(VerifRow {
                    condition: c.name.clone(),
                    model: e.name().to_string(),
                    accuracy_mean,
                    accuracy_std,
                    tar_at_far_1e3: tar_at_far(&scored, 1e-3),
                    pairs: scored.len(),
                });
            }
        }
    }
    Ok(PrivacyReport {
        options: o.clone(),
        identities: classes,
        gallery: gallery_size,
        images: usable.iter().map(Vec::len).sum(),
        raw_undetected,
        pairs_skipped_absent: absent,
        pairs_skipped_undetected: pairs.len() - usable_pairs.len(),
        identification,
        verification,
        probe_turn,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Photos of an identity scored for pose, at most this many (a seeded draw).
const POSE_CANDIDATES: usize = 40;

/// The least turn ([`crate::place::turn`]) of a pose probe: a fifth of the eye distance of
/// yaw (about 20 degrees) or the pitch that moves the nose as far. LFW's photos are mostly
/// frontal: the median of 648 photos of 100 identities turns by 0.10, one in ten by
/// more than 0.23.
pub const MIN_TURN: f32 = 0.2;

/// The pose scene's pools: per identity, its most frontal photo, then its `pool - 1` most
/// turned ([`crate::place::turn`], the frontal pitch being the median over every photo
/// scored) of those turned by at least [`MIN_TURN`]; identities without such a photo are
/// left out. Also returns the median turn of the probes.
fn pose_pools(
    ids: &[(&String, &Vec<PathBuf>)],
    detector: &FaceDetector,
    pool: usize,
    rng: &mut ChaCha8Rng,
) -> Result<(Vec<Vec<PathBuf>>, f64)> {
    let candidates: Vec<Vec<PathBuf>> = ids
        .iter()
        .map(|(_, v)| v.choose_multiple(rng, POSE_CANDIDATES.min(v.len())).cloned().collect::<Vec<_>>())
        .collect();
    let all: Vec<&PathBuf> = candidates.iter().flatten().collect();
    let pb = progress(all.len(), "privacy: scoring poses");
    let found: Vec<Option<[[f32; 2]; 5]>> = all
        .par_iter()
        .map(|p| {
            let img = read_rgb8(p)?;
            pb.inc(1);
            Ok(central_face(&detector.detect(&img)?, img.width(), img.height()).map(|f| f.landmarks))
        })
        .collect::<Result<_>>()?;
    pb.finish_and_clear();
    let landmarks: HashMap<&PathBuf, [[f32; 2]; 5]> =
        all.iter().zip(&found).filter_map(|(p, l)| l.map(|l| (*p, l))).collect();
    let mut pitches: Vec<f32> = landmarks.values().filter_map(crate::place::pose).map(|p| p.1).collect();
    pitches.sort_by(f32::total_cmp);
    let frontal = pitches.get(pitches.len() / 2).copied().unwrap_or(0.5);
    let mut probes = Vec::new();
    let pools = candidates
        .iter()
        .filter_map(|c| {
            let mut scored: Vec<(f32, &PathBuf)> =
                c.iter().filter_map(|p| landmarks.get(p).map(|l| (crate::place::turn(l, frontal), p))).collect();
            if scored.len() < 2 {
                return None;
            }
            scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(b.1)));
            let front = scored.remove(0);
            scored.reverse();
            scored.retain(|s| s.0 >= MIN_TURN);
            scored.truncate(pool - 1);
            if scored.is_empty() {
                return None;
            }
            probes.extend(scored.iter().map(|s| s.0 as f64));
            Some(std::iter::once(front.1).chain(scored.iter().map(|s| s.1)).cloned().collect())
        })
        .collect();
    probes.sort_by(f64::total_cmp);
    Ok((pools, probes.get(probes.len() / 2).copied().unwrap_or(f64::NAN)))
}

/// Accuracy of "same iff score > t" on `pairs`.
fn accuracy_at(pairs: &[&(usize, bool, f32)], t: f32) -> f64 {
    pairs.iter().filter(|p| (p.2 > t) == p.1).count() as f64 / pairs.len().max(1) as f64
}

/// Per-fold accuracies: each fold is scored at the threshold that maximises accuracy on the
/// other folds (candidates: every training score and −∞; among equally good ones the largest).
pub fn kfold_accuracy(scored: &[(usize, bool, f32)]) -> Vec<f64> {
    let mut folds: Vec<usize> = scored.iter().map(|s| s.0).collect();
    folds.sort();
    folds.dedup();
    folds
        .iter()
        .map(|&f| {
            let train: Vec<_> = scored.iter().filter(|s| s.0 != f).collect();
            let test: Vec<_> = scored.iter().filter(|s| s.0 == f).collect();
            let mut cands: Vec<f32> = train.iter().map(|s| s.2).collect();
            cands.push(f32::NEG_INFINITY);
            let best = cands
                .iter()
                .copied()
                .max_by(|&a, &b| accuracy_at(&train, a).total_cmp(&accuracy_at(&train, b)).then(a.total_cmp(&b)))
                .unwrap();
            accuracy_at(&test, best)
        })
        .collect()
}

/// True-accept rate at the smallest threshold where the false-accept share is ≤ `far`.
pub fn tar_at_far(scored: &[(usize, bool, f32)], far: f64) -> f64 {
    let mut neg: Vec<f32> = scored.iter().filter(|s| !s.1).map(|s| s.2).collect();
    let pos: Vec<f32> = scored.iter().filter(|s| s.1).map(|s| s.2).collect();
    if neg.is_empty() || pos.is_empty() {
        return f64::NAN;
    }
    neg.sort_by(|a, b| b.total_cmp(a));
    let allowed = (far * neg.len() as f64).floor() as usize; // false accepts allowed
    let t = neg[allowed.min(neg.len() - 1)];
    pos.iter().filter(|&&s| s > t).count() as f64 / pos.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_by_hand() {
        let r = Rank::of(&[0.1, 0.9, 0.5], 1);
        assert_eq!(r, Rank { above: 0, tied: 0 });
        assert_eq!((r.within(1), r.within(2)), (1.0, 1.0));
        let r = Rank::of(&[0.1, 0.9, 0.5], 0);
        assert_eq!(r, Rank { above: 2, tied: 0 });
        assert_eq!((r.within(1), r.within(2), r.within(3)), (0.0, 0.0, 1.0));
        // Ties are broken at random: the truth and 3 others tie below one better score, so
        // it is at rank 2, 3, 4 or 5 with probability 1/4 each.
        let r = Rank::of(&[0.5, 0.5, 0.9, 0.5, 0.5], 0);
        assert_eq!(r, Rank { above: 1, tied: 3 });
        assert_eq!([1, 2, 3, 4, 5, 6].map(|n| r.within(n)), [0.0, 0.25, 0.5, 0.75, 1.0, 1.0]);
        // Every score alike (a camera that makes all faces the same): chance, 1 / 4.
        assert_eq!(Rank::of(&[0.3; 4], 2).within(1), 0.25);
    }

    #[test]
    fn kfold_and_tar_by_hand() {
        // Two folds. Fold 0: same 0.9, 0.8; different 0.2, 0.85. Fold 1: same 0.7, 0.6;
        // different 0.1, 0.3.
        let s = [
            (0, true, 0.9),
            (0, true, 0.8),
            (0, false, 0.2),
            (0, false, 0.85),
            (1, true, 0.7),
            (1, true, 0.6),
            (1, false, 0.1),
            (1, false, 0.3),
        ];
        // Fold 0 is scored at fold 1's best threshold, 0.3 (the only perfect candidate):
        // 0.9, 0.8 pass, 0.2 is rejected, 0.85 wrongly passes: 3/4.
        // Fold 1 at fold 0's: candidates 0.85 and 0.2 both give 3/4 there; the largest wins,
        // 0.85, which rejects 0.7 and 0.6 wrongly and 0.1, 0.3 rightly: 2/4.
        assert_eq!(kfold_accuracy(&s), vec![0.75, 0.5]);
        // TAR at FAR ≤ 1/4 (4 negatives, 1 allowed): threshold at the 2nd highest negative
        // 0.3 -> positives above: 0.9, 0.8, 0.7, 0.6 = 1.0. At FAR 0: threshold 0.85 -> 1/4.
        assert_eq!(tar_at_far(&s, 0.25), 1.0);
        assert_eq!(tar_at_far(&s, 0.0), 0.25);
    }
}

/// `campro check` against this evaluation's end-to-end attacker on the same faces, with the
/// same models, thresholds and cameras (`../shared`; skipped without it, required under
/// CI=true). The check is meant to be the stronger attacker: for the face the evaluation
/// probes (the central one), the check's raw embedding is the evaluation's bit for bit; its
/// similarity to the protected face is never below the evaluation's end-to-end one (it also
/// tries the raw landmarks), so a face the evaluation could verify at a threshold the check
/// calls linkable; and where it kept the evaluation's very embedding, its rank in a gallery
/// is the one [`Rank::of`] gives for the same scores.
#[cfg(test)]
mod agreement_with_check {
    use super::*;
    use crate::check::{check_photo, rank_all, Judge, FARS};

    fn model(name: &str, models: &Path) -> crate::model::Model {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("models").join(format!("{name}.json"));
        crate::model::Model::load(crate::manifest::Manifest::load(&path, models).unwrap()).unwrap()
    }

    #[test]
    fn check_is_at_least_the_end_to_end_attacker_on_the_same_faces() {
        let Some(shared) = campro_testkit::shared_root(&[
            "models/yunet_s_640_640.onnx",
            "models/faceplugin_fr_feature.onnx",
            "models/mobilefacenet_casia.onnx",
            "data/lfw/pairs.txt",
        ]) else {
            return;
        };
        let models = shared.join("models");
        let fm = FaceModels {
            detector: FaceDetector::new(model("yunet", &models)).unwrap(),
            embedders: vec![
                Embedder::new(model("faceplugin", &models)).unwrap(),
                Embedder::new(model("mobilefacenet_casia", &models)).unwrap(),
            ],
        };
        let judges: Vec<Judge> = fm.embedders.iter().map(|e| Judge::new(e).unwrap()).collect();
        let root = campro_testkit::workspace_root().join("params");
        let mut conds = vec![Condition::raw()];
        for preset in ["campro-omega-0.5", "campro-omega-5"] {
            let p = campro::Params::from_json(&std::fs::read_to_string(root.join(format!("{preset}.json"))).unwrap())
                .unwrap();
            let p: &'static campro::Params = Box::leak(Box::new(p));
            let fast = campro::pipeline::fast::Exact8::new(p);
            conds.push(Condition::new(preset, move |img: &RgbImage| {
                let mut out = RgbImage::new(img.width(), img.height());
                fast.run(img.as_raw(), &mut out);
                out
            }));
        }
        let held_out = campro::Params::from_json(&std::fs::read_to_string(root.join("campro-omega-0.5.json")).unwrap())
            .unwrap()
            .provenance_fields()
            .unwrap()
            .validation_identities
            .unwrap();
        let lfw = Lfw::open(&shared.join("data/lfw")).unwrap();
        let (mut photos, mut records) = (Vec::new(), Vec::new());
        for id in held_out.iter().take(16) {
            let path = &lfw.people[id][0];
            let Some(rec) = embed_photo(path, &fm, &conds, Need::EndToEnd, Scene::Colour, None).unwrap() else {
                continue;
            };
            let img = read_rgb8(path).unwrap();
            let central = central_face(&fm.detector.detect(&img).unwrap(), img.width(), img.height()).unwrap();
            let check = check_photo(path, None, &img, &fm.detector, &judges, &conds).unwrap();
            let k = check.faces.iter().position(|f| f.bbox == central.bbox).expect("the central face is checked");
            for m in 0..judges.len() {
                assert_eq!(check.faces[k].raw[m], rec.raw[m], "{id}: raw embedding, model {m}");
            }
            photos.push((check, k));
            records.push(rec);
        }
        assert!(photos.len() >= 12, "only {} held-out photos with a face", photos.len());
        let mut checks: Vec<_> = photos.iter().map(|(c, _)| c.clone()).collect();
        rank_all(&mut checks, &[], judges.len());
        // The gallery rank_all used: every scored face's raw embedding, one identity each.
        let gallery: Vec<&Vec<Vec<f32>>> =
            checks.iter().flat_map(|c| c.faces.iter().filter(|f| !f.at_edge).map(|f| &f.raw)).collect();
        let (mut compared, mut same_embedding, mut stronger) = (0, 0, 0);
        for ((check, k), rec) in checks.iter().zip(photos.iter().map(|(_, k)| *k)).zip(&records) {
            let face = &check.faces[k];
            for (ci, c) in conds.iter().enumerate() {
                let Some(e2e) = &rec.prot[ci].e2e else { continue };
                let view = &face.views[ci];
                for (m, judge) in judges.iter().enumerate() {
                    let eval_sim = cosine(&rec.raw[m], &e2e[m]);
                    let sim = view.similarity[m];
                    assert!(
                        sim >= eval_sim - 1e-6,
                        "{}: {}: model {m}: check {sim} < eval {eval_sim}",
                        c.name,
                        check.path.display()
                    );
                    for far in FARS {
                        // Linkable: above the model's threshold at that rate (FaceCheck::linkable).
                        let t = judge.thresholds.at(far);
                        assert!(eval_sim <= t || sim > t, "{}: linkable for eval at FAR {far}, not for check", c.name);
                    }
                    compared += 1;
                    if view.embeddings[m] == e2e[m] {
                        same_embedding += 1;
                        let scores: Vec<f32> = gallery.iter().map(|g| cosine(&e2e[m], &g[m])).collect();
                        let truth = gallery.iter().position(|g| std::ptr::eq(*g, &face.raw)).unwrap();
                        let r = Rank::of(&scores, truth);
                        assert_eq!(view.rank[m], Some(1 + r.above), "{}: rank, model {m}", c.name);
                    } else {
                        stronger += 1;
                        assert!(sim > eval_sim, "{}: another embedding kept without a higher similarity", c.name);
                    }
                }
            }
        }
        eprintln!("{compared} face-view-model triples: {same_embedding} the evaluation's embedding, {stronger} a stronger one");
        assert!(
            same_embedding >= photos.len() * judges.len(),
            "the raw view at least keeps the evaluation's embedding"
        );
        // The end-to-end attacker found some protected faces to compare (ω = 5 leaves most).
        assert!(compared > photos.len() * judges.len(), "no protected face compared");
    }
}
