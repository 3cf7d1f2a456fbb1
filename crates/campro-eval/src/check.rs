//! `campro check`: could a face-recognition system link the faces in a user's own photos to
//! what a camera makes of them?
//!
//! For every face the detector finds in a raw photo, the raw face and each *view* of it (as
//! captured, as a person is shown it, after the attacker's restorations) are embedded by
//! every face model, and two attacks are scored:
//! - **verification**: the cosine similarity of raw and view against the model's threshold at
//!   a false-accept rate (FAR) of 1e-3 and 1e-2 ([`Thresholds`], calibrated on LFW by
//!   [`calibrate`]); above it, a system would say "same person": the face is *linkable*;
//! - **re-identification**: the view is searched in a gallery of the raw faces of every
//!   person checked (plus LFW distractors), and the rank of the true person is reported
//!   (1: found first).
//!
//! A view is embedded where the raw face was (the attacker knows where it is, as a tracker
//! would) and, where the detector finds the face in the view too (box IoU ≥ [`FOUND_IOU`]),
//! where it found it; the higher similarity counts (the worst case for the user). A face the
//! detector no longer finds in a view is still scored at its raw position, and said.

use crate::data::{read_rgb8, Lfw};
use crate::error::{EvalError, Result};
use crate::face::{central_face, cosine, Embedder, Face, FaceDetector};
use crate::manifest::Thresholds;
use crate::Condition;
use image::RgbImage;
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The false-accept rates reported, most demanding first.
pub const FARS: [f64; 2] = [1e-3, 1e-2];

/// The least box IoU at which a face found in a view is taken to be the raw face.
pub const FOUND_IOU: f32 = 0.3;

/// The largest per-pixel channel spread of a picture taken as grey-scale (8-bit levels).
pub const GREY_SPREAD: u8 = 2;

impl Thresholds {
    /// The threshold at `far` (one of [`FARS`]).
    pub fn at(&self, far: f64) -> f32 {
        if far <= FARS[0] {
            self.far_1e3
        } else {
            self.far_1e2
        }
    }
}

/// The threshold at which at most `far` of `impostors` score **above** it: the
/// `⌊far·n⌋ + 1`-th highest score. Ties at the threshold do not pass, so the share above it
/// never exceeds `far`. `impostors` is sorted in place (descending). Needs at least one score.
pub fn threshold_above(impostors: &mut [f32], far: f64) -> Option<f32> {
    if impostors.is_empty() || !(0.0..1.0).contains(&far) {
        return None;
    }
    impostors.sort_unstable_by(|a, b| b.total_cmp(a));
    let k = ((far * impostors.len() as f64).floor() as usize).min(impostors.len() - 1);
    Some(impostors[k])
}

/// What [`calibrate`] measured for one model.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    pub model: String,
    pub thresholds: Thresholds,
    /// Images of the folds' pairs whose face was found and embedded.
    pub images: usize,
    /// Share of the folds' same-person pairs above each threshold (the genuine accept rate:
    /// the model still links the same person), in [`FARS`] order.
    pub genuine_accept: [f64; 2],
    pub same_pairs: usize,
}

/// Calibrates `embedder`'s thresholds on LFW: the images of `pairs.txt`'s first `folds`
/// folds (each photo's central face), every pair of them of different people as impostors.
/// Deterministic for a given copy of LFW.
pub fn calibrate(lfw: &Lfw, detector: &FaceDetector, embedder: &Embedder, folds: usize) -> Result<Calibration> {
    if !(1..=10).contains(&folds) {
        return Err(EvalError::Invalid(format!("thresholds: --folds must be in 1..=10, got {folds}")));
    }
    let (pairs, _) = lfw.pairs()?;
    let pairs: Vec<_> = pairs.into_iter().filter(|p| p.fold < folds).collect();
    let mut paths: Vec<PathBuf> = pairs.iter().flat_map(|p| [p.a.clone(), p.b.clone()]).collect();
    paths.sort();
    paths.dedup();
    let embedded: Vec<Option<Vec<f32>>> = paths
        .par_iter()
        .map(|p| {
            let img = read_rgb8(p)?;
            let Some(face) = central_face(&detector.detect(&img)?, img.width(), img.height()) else { return Ok(None) };
            embedder.embed(&embedder.align(&img, &face.landmarks)).map(Some)
        })
        .collect::<Result<_>>()?;
    let person = |p: &Path| p.parent().and_then(|d| d.file_name()).map(|n| n.to_string_lossy().into_owned());
    let found: Vec<(Option<String>, &Vec<f32>)> =
        paths.iter().zip(&embedded).filter_map(|(p, e)| e.as_ref().map(|e| (person(p), e))).collect();
    let mut impostors: Vec<f32> = (0..found.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            let found = &found;
            (i + 1..found.len()).filter(move |&j| found[i].0 != found[j].0).map(move |j| cosine(found[i].1, found[j].1))
        })
        .collect();
    let impostor_pairs = impostors.len();
    let none = || EvalError::Invalid("thresholds: no pair of different people with faces found".into());
    let far_1e3 = threshold_above(&mut impostors, FARS[0]).ok_or_else(none)?;
    let far_1e2 = threshold_above(&mut impostors, FARS[1]).ok_or_else(none)?;
    let thresholds = Thresholds { far_1e3, far_1e2, impostor_pairs, folds };
    let index = |p: &PathBuf| paths.binary_search(p).ok().and_then(|i| embedded[i].as_ref());
    let same: Vec<f32> =
        pairs.iter().filter(|p| p.same).filter_map(|p| Some(cosine(index(&p.a)?, index(&p.b)?))).collect();
    let share = |t: f32| same.iter().filter(|&&s| s > t).count() as f64 / same.len().max(1) as f64;
    Ok(Calibration {
        model: embedder.name().to_string(),
        thresholds,
        images: found.len(),
        genuine_accept: [share(far_1e3), share(far_1e2)],
        same_pairs: same.len(),
    })
}

/// A face model with its thresholds.
pub struct Judge<'a> {
    pub embedder: &'a Embedder,
    pub thresholds: Thresholds,
}

impl<'a> Judge<'a> {
    /// `embedder` with the thresholds of its manifest; an error names the model and the
    /// command that calibrates it.
    pub fn new(embedder: &'a Embedder) -> Result<Self> {
        let thresholds = embedder.thresholds().ok_or_else(|| {
            EvalError::Invalid(format!(
                "face model {}: its manifest has no task.thresholds (calibrate them: campro eval thresholds --face-model MANIFEST)",
                embedder.name()
            ))
        })?;
        Ok(Self { embedder, thresholds })
    }
}

/// One face of a photo under one view.
#[derive(Debug, Clone, Serialize)]
pub struct ViewCheck {
    /// The view's name (`captured`, `enhanced`, `restored`, `restore-net`).
    pub view: String,
    /// Whether the detector found the face in this view.
    pub found: bool,
    /// Cosine similarity of raw and view, per model (in the models' order).
    pub similarity: Vec<f32>,
    /// Rank of the true person in the gallery, per model (1: first); `None` before [`rank_all`].
    pub rank: Vec<Option<usize>>,
    /// Per model, the highest similarity of this raw face with *other* people's faces in
    /// the same view (`None`: no other face checked). A low-quality raw face (blurred, a
    /// bystander far away) can score above the threshold with anything the camera makes;
    /// a similarity not above this says nothing about the person. Set by [`rank_all`].
    pub strangers: Vec<Option<f32>>,
    /// The view's aligned crop for the first model (for the report).
    #[serde(skip)]
    pub crop: RgbImage,
    /// The view's embedding per model (the one that gave the similarity).
    #[serde(skip)]
    pub(crate) embeddings: Vec<Vec<f32>>,
}

/// The least share of a face's box inside the photo for it to be scored: a face cut by the
/// edge is aligned onto a crop filled with black where the photo ends, and the models match
/// that black (a bystander half out of an LFW photo scored .92 raw against captured with
/// the face itself unrecognisable).
pub const MIN_INSIDE: f32 = 0.9;

/// One face found in a raw photo.
#[derive(Debug, Clone, Serialize)]
pub struct FaceCheck {
    /// Its box in the raw photo, pixels `[x0, y0, x1, y1]`.
    pub bbox: [f32; 4],
    /// The detector's score on the raw photo (0..1).
    pub score: f32,
    /// Less than [`MIN_INSIDE`] of its box lies inside the photo: listed, not scored.
    pub at_edge: bool,
    /// The face of the photo's person (its largest), when photos are grouped by person;
    /// other faces are bystanders, each its own identity.
    pub is_person: bool,
    pub views: Vec<ViewCheck>,
    /// The raw aligned crop for the first model (for the report).
    #[serde(skip)]
    pub crop: RgbImage,
    #[serde(skip)]
    pub(crate) raw: Vec<Vec<f32>>,
}

impl FaceCheck {
    /// Whether any view is linkable by any model at `far` (a face at the edge never is: it
    /// is not scored).
    pub fn linkable(&self, judges: &[Judge], far: f64) -> bool {
        !self.at_edge
            && self.views.iter().any(|v| v.similarity.iter().zip(judges).any(|(s, j)| *s > j.thresholds.at(far)))
    }

    /// Whether it is linkable at `far` by a similarity also above every stranger's in that
    /// view ([`ViewCheck::strangers`]): the link is to this person, not to any face.
    pub fn linkable_specifically(&self, judges: &[Judge], far: f64) -> bool {
        !self.at_edge
            && self.views.iter().any(|v| {
                v.similarity
                    .iter()
                    .zip(judges)
                    .zip(&v.strangers)
                    .any(|((s, j), st)| *s > j.thresholds.at(far) && st.is_none_or(|x| *s > x))
            })
    }

    /// The view and model with the highest similarity above (or least below) its threshold
    /// at `far`: (view index, model index, similarity − threshold).
    pub fn worst(&self, judges: &[Judge], far: f64) -> Option<(usize, usize, f32)> {
        if self.at_edge {
            return None;
        }
        let mut best: Option<(usize, usize, f32)> = None;
        for (vi, v) in self.views.iter().enumerate() {
            for (mi, (s, j)) in v.similarity.iter().zip(judges).enumerate() {
                let m = s - j.thresholds.at(far);
                if best.is_none_or(|b| m > b.2) {
                    best = Some((vi, mi, m));
                }
            }
        }
        best
    }

    /// The best (lowest) rank of the true person over views and models.
    pub fn best_rank(&self) -> Option<usize> {
        if self.at_edge {
            return None;
        }
        self.views.iter().flat_map(|v| v.rank.iter().flatten().copied()).min()
    }
}

/// One photo checked.
#[derive(Debug, Clone, Serialize)]
pub struct PhotoCheck {
    pub path: PathBuf,
    /// The person it shows (`None`: photos not grouped; each face is then its own person).
    pub person: Option<String>,
    pub width: u32,
    pub height: u32,
    /// Every pixel's channels within [`GREY_SPREAD`]: a grey-scale photo.
    pub grey: bool,
    pub faces: Vec<FaceCheck>,
}

/// Whether every pixel of `img` is grey within [`GREY_SPREAD`].
pub fn is_grey(img: &RgbImage) -> bool {
    img.pixels().all(|p| p.0.iter().max().unwrap_or(&0) - p.0.iter().min().unwrap_or(&0) <= GREY_SPREAD)
}

/// Checks one raw photo under every view (`views`: name and camera; a view applies to the
/// whole photo).
pub fn check_photo(
    path: &Path,
    person: Option<String>,
    img: &RgbImage,
    detector: &FaceDetector,
    judges: &[Judge],
    views: &[Condition],
) -> Result<PhotoCheck> {
    let faces = detector.detect(img)?;
    let embed_at = |pic: &RgbImage, lm: &[[f32; 2]; 5]| -> Result<(Vec<Vec<f32>>, RgbImage)> {
        let crops: Vec<RgbImage> = judges.iter().map(|j| j.embedder.align(pic, lm)).collect();
        let e = judges.iter().zip(&crops).map(|(j, c)| j.embedder.embed(c)).collect::<Result<_>>()?;
        Ok((e, crops.into_iter().next().unwrap_or_default()))
    };
    let area = |b: [f32; 4]| (b[2] - b[0]).max(0.0) * (b[3] - b[1]).max(0.0);
    let inside = |b: [f32; 4]| {
        let c = [b[0].max(0.0), b[1].max(0.0), b[2].min(img.width() as f32), b[3].min(img.height() as f32)];
        area(c) / area(b).max(f32::MIN_POSITIVE)
    };
    let largest = faces.iter().enumerate().max_by(|a, b| area(a.1.bbox).total_cmp(&area(b.1.bbox))).map(|(k, _)| k);
    let mut checks: Vec<FaceCheck> = Vec::with_capacity(faces.len());
    for (k, f) in faces.iter().enumerate() {
        let (raw, crop) = embed_at(img, &f.landmarks)?;
        checks.push(FaceCheck {
            bbox: f.bbox,
            score: f.score,
            at_edge: inside(f.bbox) < MIN_INSIDE,
            is_person: person.is_some() && Some(k) == largest,
            views: Vec::new(),
            crop,
            raw,
        });
    }
    // A photo without a face has nothing to score: no view runs on it.
    for v in views.iter().filter(|_| !faces.is_empty()) {
        let pic = v.apply(img);
        let found_here: Vec<Face> = detector.detect(&pic)?;
        for (f, c) in faces.iter().zip(&mut checks) {
            let found = found_here
                .iter()
                .map(|g| (crate::geometry::iou(g.bbox, f.bbox), g))
                .filter(|(o, _)| *o >= FOUND_IOU)
                .max_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, g)| *g);
            let (at_raw, crop) = embed_at(&pic, &f.landmarks)?;
            let at_found = found.map(|g| embed_at(&pic, &g.landmarks)).transpose()?;
            let mut similarity = Vec::with_capacity(judges.len());
            let mut embeddings = Vec::with_capacity(judges.len());
            for mi in 0..judges.len() {
                let a = cosine(&c.raw[mi], &at_raw[mi]);
                match &at_found {
                    Some((e, _)) if cosine(&c.raw[mi], &e[mi]) > a => {
                        similarity.push(cosine(&c.raw[mi], &e[mi]));
                        embeddings.push(e[mi].clone());
                    }
                    _ => {
                        similarity.push(a);
                        embeddings.push(at_raw[mi].clone());
                    }
                }
            }
            c.views.push(ViewCheck {
                view: v.name.clone(),
                found: found.is_some(),
                similarity,
                rank: vec![None; judges.len()],
                strangers: vec![None; judges.len()],
                crop,
                embeddings,
            });
        }
    }
    Ok(PhotoCheck {
        path: path.to_path_buf(),
        person,
        width: img.width(),
        height: img.height(),
        grey: is_grey(img),
        faces: checks,
    })
}

/// A gallery entry: an identity and its raw embedding per model.
pub struct Entry {
    pub identity: String,
    pub embeddings: Vec<Vec<f32>>,
}

/// The identity a face of `photo` counts as: its person (the photo's largest face, when
/// photos are grouped), else the face itself (a loose photo's face, or a bystander).
fn identity(photo: &PhotoCheck, face: usize) -> String {
    match (&photo.person, photo.faces[face].is_person) {
        (Some(p), true) => format!("person:{p}"),
        _ => format!("face:{}#{face}", photo.path.display()),
    }
}

/// The L2-normalised mean of `v` (an identity's template; `v` non-empty, each normalised).
fn centroid(v: &[&[f32]]) -> Vec<f32> {
    let mut c = vec![0.0f32; v[0].len()];
    for e in v {
        c.iter_mut().zip(e.iter()).for_each(|(a, b)| *a += b);
    }
    let n = c.iter().map(|x| x * x).sum::<f32>().sqrt();
    if n > 0.0 {
        c.iter_mut().for_each(|x| *x /= n);
    }
    c
}

/// Ranks every view of every scored face in a gallery of the raw faces of all `photos`
/// (faces at the edge left out) plus `distractors`; returns the number of identities in the
/// gallery. An identity is represented by the normalised mean of its raw embeddings (so a
/// person with many photos gains no edge from their number); the rank is 1 + the
/// identities more similar to the view than the true one.
pub fn rank_all(photos: &mut [PhotoCheck], distractors: &[Entry], models: usize) -> usize {
    let mut members: std::collections::BTreeMap<String, Vec<&Vec<Vec<f32>>>> = std::collections::BTreeMap::new();
    for p in photos.iter() {
        for (k, f) in p.faces.iter().enumerate().filter(|(_, f)| !f.at_edge) {
            members.entry(identity(p, k)).or_default().push(&f.raw);
        }
    }
    for d in distractors {
        members.entry(format!("distractor:{}", d.identity)).or_default().push(&d.embeddings);
    }
    let names: Vec<String> = members.keys().cloned().collect();
    // templates[m][identity]
    let templates: Vec<Vec<Vec<f32>>> = (0..models)
        .map(|m| members.values().map(|es| centroid(&es.iter().map(|e| e[m].as_slice()).collect::<Vec<_>>())).collect())
        .collect();
    let truth: Vec<Vec<Option<usize>>> = photos
        .iter()
        .map(|p| (0..p.faces.len()).map(|k| names.binary_search(&identity(p, k)).ok()).collect())
        .collect();
    // Strangers: each raw face against every other identity's faces in the same view.
    let scored: Vec<(&Vec<Vec<f32>>, &Vec<ViewCheck>)> =
        photos.iter().flat_map(|p| p.faces.iter().filter(|f| !f.at_edge).map(|f| (&f.raw, &f.views))).collect();
    let slot_of: Vec<usize> = photos
        .iter()
        .zip(&truth)
        .flat_map(|(p, t)| p.faces.iter().zip(t).filter(|(f, _)| !f.at_edge).map(|(_, s)| s.unwrap_or(usize::MAX)))
        .collect();
    let strangers: Vec<Vec<Vec<Option<f32>>>> = scored
        .par_iter()
        .zip(slot_of.par_iter())
        .map(|((raw, views), &me)| {
            (0..views.len())
                .map(|vi| {
                    (0..models)
                        .map(|m| {
                            scored
                                .iter()
                                .zip(&slot_of)
                                .filter(|(_, &s)| s != me)
                                .map(|((_, ov), _)| cosine(&raw[m], &ov[vi].embeddings[m]))
                                .max_by(f32::total_cmp)
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    let mut it = strangers.into_iter();
    for p in photos.iter_mut() {
        for f in p.faces.iter_mut().filter(|f| !f.at_edge) {
            if let Some(st) = it.next() {
                for (v, s) in f.views.iter_mut().zip(st) {
                    v.strangers = s;
                }
            }
        }
    }
    photos.par_iter_mut().zip(truth.par_iter()).for_each(|(p, t)| {
        for (f, &true_slot) in p.faces.iter_mut().zip(t) {
            let Some(true_slot) = true_slot.filter(|_| !f.at_edge) else { continue };
            for v in &mut f.views {
                for (m, e) in v.embeddings.iter().enumerate().take(models) {
                    let scores: Vec<f32> = templates[m].iter().map(|t| cosine(e, t)).collect();
                    let mine = scores[true_slot];
                    v.rank[m] = Some(1 + scores.iter().filter(|&&b| b > mine).count());
                }
            }
        }
    });
    names.len()
}

/// `n` LFW identities (the first in name order that are not `exclude`d, one photo each, its
/// central face) as distractors, embedded by every model. Photos without a face are skipped.
pub fn lfw_distractors(
    lfw: &Lfw,
    n: usize,
    exclude: &[String],
    detector: &FaceDetector,
    judges: &[Judge],
) -> Result<Vec<Entry>> {
    let picked: Vec<(&String, &PathBuf)> = lfw
        .people
        .iter()
        .filter(|(name, _)| !exclude.contains(name))
        .filter_map(|(name, photos)| photos.first().map(|p| (name, p)))
        .take(n)
        .collect();
    let entries: Vec<Option<Entry>> = picked
        .par_iter()
        .map(|(name, path)| {
            let img = read_rgb8(path)?;
            let Some(face) = central_face(&detector.detect(&img)?, img.width(), img.height()) else { return Ok(None) };
            let embeddings = judges
                .iter()
                .map(|j| j.embedder.embed(&j.embedder.align(&img, &face.landmarks)))
                .collect::<Result<_>>()?;
            Ok(Some(Entry { identity: (*name).clone(), embeddings }))
        })
        .collect::<Result<_>>()?;
    Ok(entries.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threshold_lets_at_most_far_above() {
        // 1000 impostor scores 0.000, 0.001, ..., 0.999: at FAR 1e-2 at most 10 may pass.
        let mut s: Vec<f32> = (0..1000).map(|i| i as f32 / 1000.0).collect();
        let t = threshold_above(&mut s, 1e-2).unwrap();
        assert_eq!(t, 0.989);
        assert_eq!(s.iter().filter(|&&x| x > t).count(), 10);
        let t3 = threshold_above(&mut s, 1e-3).unwrap();
        assert_eq!(t3, 0.998);
        assert_eq!(s.iter().filter(|&&x| x > t3).count(), 1);
        // Ties at the threshold do not pass: all equal, nothing above.
        let mut flat = vec![0.5f32; 50];
        let t = threshold_above(&mut flat, 1e-2).unwrap();
        assert_eq!(flat.iter().filter(|&&x| x > t).count(), 0);
        assert!(threshold_above(&mut [], 1e-2).is_none());
        assert!(threshold_above(&mut [0.1], 1.0).is_none());
    }

    #[test]
    fn grey_is_within_the_spread() {
        let mut img = RgbImage::from_pixel(4, 4, image::Rgb([100, 101, 102]));
        assert!(is_grey(&img));
        img.put_pixel(3, 3, image::Rgb([100, 100, 103]));
        assert!(!is_grey(&img));
    }

    fn face(raw: Vec<f32>, views: Vec<Vec<f32>>) -> FaceCheck {
        FaceCheck {
            bbox: [0.0; 4],
            score: 1.0,
            at_edge: false,
            is_person: true,
            crop: RgbImage::new(1, 1),
            raw: vec![raw],
            views: views
                .into_iter()
                .map(|e| ViewCheck {
                    view: "captured".into(),
                    found: true,
                    similarity: vec![0.0],
                    rank: vec![None],
                    strangers: vec![None],
                    crop: RgbImage::new(1, 1),
                    embeddings: vec![e],
                })
                .collect(),
        }
    }

    #[test]
    fn ranks_against_identity_templates() {
        let unit = |a: f32| vec![a.cos(), a.sin()];
        // Two persons, A with two photos, B with one; and a distractor.
        let photo = |path: &str, person: &str, raw: f32, view: f32| PhotoCheck {
            path: path.into(),
            person: Some(person.into()),
            width: 1,
            height: 1,
            grey: false,
            faces: vec![face(unit(raw), vec![unit(view)])],
        };
        let mut photos = vec![photo("a1", "A", 0.0, 1.0), photo("a2", "A", 0.9, 0.9), photo("b1", "B", 1.2, 0.0)];
        let d = [Entry { identity: "D".into(), embeddings: vec![unit(3.0)] }];
        let n = rank_all(&mut photos, &d, 1);
        assert_eq!(n, 3, "A, B and the distractor");
        // A's template is the mean of angles 0 and 0.9 (angle 0.45). a1's view at 1.0: A is
        // 0.55 away, B (1.2) 0.2: A second.
        assert_eq!(photos[0].faces[0].views[0].rank[0], Some(2));
        // a2's view at 0.9: B 0.3, A 0.45 away: second too.
        assert_eq!(photos[1].faces[0].views[0].rank[0], Some(2));
        // b1's view at angle 0: A (0.45) is nearer than B (1.2): B second; the distractor (3.0) last.
        assert_eq!(photos[2].faces[0].views[0].rank[0], Some(2));
        // Strangers: a1's raw (angle 0) against B's view (angle 0): 1.0, above its own view (1.0 away).
        assert_eq!(photos[0].faces[0].views[0].strangers[0], Some(1.0));
        // b1's raw (1.2) against A's views (1.0 and 0.9): cos 0.2.
        assert!((photos[2].faces[0].views[0].strangers[0].unwrap() - 0.2f32.cos()).abs() < 1e-6);
        // A view on its own template is first.
        photos[0].faces[0].views[0].embeddings[0] = unit(0.45);
        rank_all(&mut photos, &d, 1);
        assert_eq!(photos[0].faces[0].views[0].rank[0], Some(1));
        photos[0].faces[0].views[0].embeddings[0] = unit(1.0);
        // Ungrouped: each face is its own identity.
        for p in &mut photos {
            p.person = None;
        }
        assert_eq!(rank_all(&mut photos, &d, 1), 4);
        // a1's view (1.0): a2 (0.9) is nearest, then b1 (1.2), then a1 itself (0.0): rank 3.
        assert_eq!(photos[0].faces[0].views[0].rank[0], Some(3));
    }
}
