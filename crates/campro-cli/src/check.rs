//! `campro check`: does a preset protect the user's own photos? The models, photos and views
//! are gathered here; the scoring is `campro_eval::check`; the report (lines, JSON, CSV and
//! an HTML page with the face crops) is written here.

use crate::args::{CheckArgs, Report, ViewArg};
use crate::page::{self, href, html_escape};
use crate::{escape, say, write_atomic};
use anyhow::{anyhow, bail, Context, Result};
use campro_eval::check::{self, FaceCheck, Judge, PhotoCheck, FARS};
use campro_eval::face::{Embedder, FaceDetector};
use campro_eval::image_file::Budget;
use campro_eval::Condition;
use image::RgbImage;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The exit status when a face is linkable at `--fail-above`.
pub const LINKABLE_EXIT: i32 = 3;

/// A photo to check and the person it shows (`None`: loose).
struct Photo {
    path: PathBuf,
    person: Option<String>,
}

/// Every photo of `a`: files and folders given (recursive, each face its own identity),
/// `--people` folders (each subfolder one person) and `--person NAME=DIR`.
fn photos_of(a: &CheckArgs, out: &Path) -> Result<Vec<Photo>> {
    let which =
        crate::simulate::Reads { reads: &crate::simulate::is_image, otherwise: "not a PNG, JPEG, TIFF or WebP file" };
    let list = |inputs: &[PathBuf]| -> Result<Vec<PathBuf>> {
        let found = crate::simulate::collect_inputs(inputs, out, &|p| p.to_path_buf(), &which)?;
        for (i, why) in &found.skipped {
            eprintln!("warning: skipping {}: {why}", crate::shown(i));
        }
        Ok(found.jobs.into_iter().map(|(i, _)| i).collect())
    };
    let mut photos: Vec<Photo> = list(&a.photos)?.into_iter().map(|path| Photo { path, person: None }).collect();
    for people in &a.people {
        if !people.is_dir() {
            bail!(
                "--people {}: not a folder (a folder whose subfolders hold one person's photos each)",
                crate::shown(people)
            );
        }
        let mut dirs: Vec<PathBuf> = std::fs::read_dir(people)
            .with_context(|| crate::shown(people))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_dir())
            .collect();
        dirs.sort();
        if dirs.is_empty() {
            bail!("--people {}: no subfolder (each subfolder is one person's photos)", crate::shown(people));
        }
        for d in dirs {
            let name = d.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            photos.extend(
                list(std::slice::from_ref(&d))?.into_iter().map(|path| Photo { path, person: Some(name.clone()) }),
            );
        }
    }
    for (name, dir) in &a.persons {
        if !dir.is_dir() {
            bail!("--person {name}={}: not a folder", crate::shown(dir));
        }
        photos.extend(
            list(std::slice::from_ref(dir))?.into_iter().map(|path| Photo { path, person: Some(name.clone()) }),
        );
    }
    if photos.is_empty() {
        bail!("no PNG, JPEG, TIFF or WebP photo among the inputs: nothing to check");
    }
    Ok(photos)
}

/// The views of `a` (default: every one the preset has), as conditions on a raw photo.
fn views_of(
    a: &CheckArgs,
    params: &Path,
    p: &campro::Params,
    models: &Path,
    photos: &[Photo],
    notes: &mut Vec<String>,
    failures: &crate::eval::Failures,
) -> Result<Vec<Condition>> {
    let asked = !a.views.is_empty();
    let wanted = |v: ViewArg| !asked || a.views.contains(&v);
    let on_device = a.device.capture_result.is_some()
        || a.device.device_ccm.is_some()
        || a.device.ct.is_some()
        || a.matrix_frac_bits.is_some()
        || a.lut_size.is_some();
    let captured = if on_device {
        let (c, note) = device_condition(p, a)?;
        notes.push(note);
        c
    } else {
        crate::eval::params_condition("captured".into(), p.clone())
    };
    let protect = captured.protect.clone().ok_or_else(|| anyhow!("the captured view has no camera"))?;
    let mut views = Vec::new();
    if wanted(ViewArg::Captured) {
        views.push(captured.clone());
    }
    if wanted(ViewArg::Enhanced) {
        match crate::capture::enhancer_of(params, p, a.scale, models) {
            Ok(e) => {
                let (pr, f) = (protect.clone(), failures.clone());
                let e = std::sync::Arc::new(e);
                // A view cannot fail inside the scoring: an enhancement that fails is recorded
                // (the check is then refused) and the captured picture passed on.
                views.push(Condition::new("enhanced", move |img: &RgbImage| {
                    let c = pr(img);
                    crate::capture::enhance(&e, &c).unwrap_or_else(|err| {
                        f.record(format!("the enhanced view: {}", crate::one_line(&err)));
                        c
                    })
                }));
            }
            Err(e) if !asked => notes.push(format!("enhanced view left out: {}", crate::one_line(&e))),
            Err(e) => return Err(e.context("--view enhanced")),
        }
    }
    if wanted(ViewArg::Restored) {
        let dir = a.restore_prior.clone().unwrap_or_else(|| a.data.shared_dir().join("data/coco-person/images"));
        let mut prior_paths: Vec<PathBuf> = if dir.is_dir() || a.restore_prior.is_some() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
                .with_context(|| format!("--restore-prior {}", crate::shown(&dir)))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| crate::simulate::is_image(p))
                .collect();
            v.sort();
            notes.push(format!("restoration fitted on {} images of {}", v.len().min(200), crate::shown(&dir)));
            v
        } else {
            notes.push(
                "restoration fitted on the photos checked themselves (no COCO prior): the strongest attacker".into(),
            );
            photos.iter().map(|p| p.path.clone()).collect()
        };
        prior_paths.truncate(200);
        let prior = prior_paths
            .iter()
            .map(|p| campro_eval::data::read_rgb8(p).map_err(anyhow::Error::from))
            .collect::<Result<Vec<_>>>()?;
        if prior.is_empty() {
            bail!("--restore-prior {}: no images", crate::shown(&dir));
        }
        let r = campro_eval::restore::Restorer::fit(protect.as_ref(), &prior)?;
        let pr = protect.clone();
        views.push(Condition::new("restored", move |img: &RgbImage| r.apply(&pr(img))));
    }
    if wanted(ViewArg::RestoreNet) {
        match crate::capture::network_of(params, p, crate::capture::Network::Restorer) {
            Ok(net) => {
                let net = net.with_scale(a.scale.enhance_scale);
                let (pr, f) = (protect.clone(), failures.clone());
                views.push(Condition::new("restore-net", move |img: &RgbImage| {
                    let c = pr(img);
                    net.enhance(&c).unwrap_or_else(|err| {
                        f.record(format!("the restore-net view: {err}"));
                        c
                    })
                }));
            }
            Err(e) if !asked => notes.push(format!("restore-net view left out: {}", crate::one_line(&e))),
            Err(e) => return Err(e.context("--view restore-net")),
        }
    }
    Ok(views)
}

/// The camera one device runs (`--capture-result` and the HAL flags): CamPro's Camera2
/// values for its transform, as its HAL treats them ([`campro::targets::camera2::device`]),
/// on 8-bit sRGB photos fed as `campro compare` feeds them (each pixel turned into the
/// sensor RGB the device would have seen, `M_dev^-1 · degamma(pixel)`), rounded to 8 bits;
/// and a note with the values' stated bound against the ideal preset.
fn device_condition(p: &campro::Params, a: &CheckArgs) -> Result<(Condition, String)> {
    use campro::targets::Target;
    let (m, options) = crate::convert::device_setup(p, &a.device)?;
    let model =
        campro::emulate::DeviceModel { matrix_frac_bits: a.matrix_frac_bits, lut_size: a.lut_size.map(|n| n as usize) };
    let cam = campro::targets::camera2::Camera2::new(m, options, model);
    let bytes = cam.export(p, None)?;
    let (matrix, curve, _) = campro::targets::camera2::values_from_json(&bytes)?;
    let bound = cam.emulate(p, &bytes, None)?.first().and_then(|c| c.bound);
    let isp = campro::targets::camera2::device(matrix, curve, &model);
    let inv = campro::ccm::inverse(&m)
        .ok_or_else(|| anyhow!("the device's transform is singular: no sensor RGB can be synthesised from a photo"))?;
    let table: Vec<f64> = (0..=255).map(|c| campro::pipeline::degamma(c as f64 / 255.0, p.degamma)).collect();
    let note = format!(
        "captured as the device would: its transform and HAL emulated ({}; values' bound against the ideal preset {})",
        [
            a.device.capture_result.as_ref().map(|f| format!("capture result {}", crate::shown(f))),
            a.matrix_frac_bits.map(|b| format!("matrix to {b} fractional bits")),
            a.lut_size.map(|n| format!("a {n}-entry curve LUT")),
        ]
        .into_iter()
        .flatten()
        .collect::<Vec<_>>()
        .join(", "),
        bound.map_or("not stated".into(), |b| format!("{:.3} LSB", b * 255.0))
    );
    let c = Condition::new("captured", move |img: &RgbImage| {
        use campro::emulate::Emulator;
        let mut out = img.clone();
        out.as_mut().par_chunks_mut(3 * 1024).for_each(|chunk| {
            for px in chunk.chunks_exact_mut(3) {
                let sensor =
                    campro::ccm::apply(&inv, [table[px[0] as usize], table[px[1] as usize], table[px[2] as usize]]);
                let o = isp.sensor_to_output(sensor);
                for (d, v) in px.iter_mut().zip(o) {
                    *d = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                }
            }
        });
        out
    });
    Ok((c, note))
}

/// The whole check, as `--format json` prints it and check.json holds.
#[derive(Serialize)]
struct CheckReport<'a> {
    params: String,
    /// The face detector that found the faces (its manifest's name).
    face_detector: &'a str,
    models: Vec<ModelRow>,
    views: Vec<String>,
    /// Identities in the re-identification gallery (persons or loose faces, and distractors).
    gallery: usize,
    distractors: usize,
    notes: &'a [String],
    photos: &'a [PhotoCheck],
    failed: Vec<Failed>,
    summary: Summary,
    /// The sentence printed first: safe to share or not, and what to do ([`verdict`]).
    verdict: String,
    /// What it counts.
    verdict_counts: VerdictCounts,
    seconds: f64,
}

#[derive(Serialize)]
struct ModelRow {
    name: String,
    thresholds: campro_eval::manifest::Thresholds,
}

#[derive(Serialize)]
struct Failed {
    path: String,
    error: String,
}

/// The summary line's numbers.
#[derive(Serialize)]
struct Summary {
    photos: usize,
    faces: usize,
    /// Faces linkable by any model under any view, at FAR 1e-3 and 1e-2.
    linkable: [usize; 2],
    /// Of those, the faces whose similarity is also above every stranger's in that view
    /// (campro_eval::check::ViewCheck::strangers): linked to the person, not to any face.
    linkable_specifically: [usize; 2],
    /// The highest similarity − threshold (FAR 1e-3) over every face, view and model.
    worst_margin: Option<f32>,
    worst_similarity: Option<f32>,
    worst_threshold: Option<f32>,
    worst_model: Option<String>,
    worst_view: Option<String>,
    /// The best rank of a true person over every face, view and model (1: found first).
    worst_rank: Option<usize>,
    /// Faces found in raw and lost by the detector in at least one view.
    lost_by_detector: usize,
    /// Faces cut by the photo's edge (listed, not scored: campro_eval::check::MIN_INSIDE).
    at_edge: usize,
    photos_without_faces: usize,
    grey_photos: usize,
}

/// Of `faces`, the one whose view and model come closest to (or furthest past) the threshold
/// at FAR 1e-3, with that (view, model, similarity − threshold).
fn worst_face<'f>(
    faces: impl Iterator<Item = &'f FaceCheck>,
    judges: &[Judge],
) -> Option<(&'f FaceCheck, (usize, usize, f32))> {
    faces.filter_map(|f| f.worst(judges, FARS[0]).map(|w| (f, w))).max_by(|a, b| a.1 .2.total_cmp(&b.1 .2))
}

fn summary(photos: &[PhotoCheck], judges: &[Judge], views: &[Condition]) -> Summary {
    let faces: Vec<&FaceCheck> = photos.iter().flat_map(|p| &p.faces).collect();
    let linkable = FARS.map(|far| faces.iter().filter(|f| f.linkable(judges, far)).count());
    let linkable_specifically = FARS.map(|far| faces.iter().filter(|f| f.linkable_specifically(judges, far)).count());
    let worst = worst_face(faces.iter().copied(), judges);
    Summary {
        photos: photos.len(),
        faces: faces.len(),
        linkable,
        linkable_specifically,
        worst_margin: worst.map(|w| w.1 .2),
        worst_similarity: worst.map(|(f, (v, m, _))| f.views[v].similarity[m]),
        worst_threshold: worst.map(|(_, (_, m, _))| judges[m].thresholds.far_1e3),
        worst_model: worst.map(|(_, (_, m, _))| judges[m].embedder.name().to_string()),
        worst_view: worst.map(|(_, (v, _, _))| views[v].name.clone()),
        worst_rank: faces.iter().filter_map(|f| f.best_rank()).min(),
        lost_by_detector: faces.iter().filter(|f| !f.at_edge && f.views.iter().any(|v| !v.found)).count(),
        at_edge: faces.iter().filter(|f| f.at_edge).count(),
        photos_without_faces: photos.iter().filter(|p| p.faces.is_empty()).count(),
        grey_photos: photos.iter().filter(|p| p.grey).count(),
    }
}

/// What the verdict sentence counts: faces as a person would sort them (matched to their own
/// person, matched no better than to a stranger, set apart with grey photos `simulate`
/// refuses), at FAR 1e-3.
#[derive(Debug, Default, Clone, Serialize, PartialEq, Eq)]
struct VerdictCounts {
    photos: usize,
    /// Faces scored outside the refused grey photos (faces at a photo's edge are not scored).
    scored: usize,
    /// Of those, linkable by a similarity above every stranger's: matched to their own person.
    matched: usize,
    /// Linkable, but no more similar to their own raw face than to a stranger's: low-quality faces.
    stranger_like: usize,
    /// Grey photos `simulate` refuses with this preset (it is not rated for grey), and their faces.
    grey_photos_refused: usize,
    grey_faces_refused: usize,
    /// Identities in the gallery a rank is out of.
    gallery: usize,
}

/// `refused`: per photo, whether `simulate` refuses it as grey with this preset.
fn verdict_counts(photos: &[PhotoCheck], refused: &[bool], judges: &[Judge], gallery: usize) -> VerdictCounts {
    let apart: Vec<&PhotoCheck> = photos.iter().zip(refused).filter(|(_, &r)| r).map(|(p, _)| p).collect();
    let kept: Vec<&FaceCheck> =
        photos.iter().zip(refused).filter(|(_, &r)| !r).flat_map(|(p, _)| &p.faces).filter(|f| !f.at_edge).collect();
    let matched = kept.iter().filter(|f| f.linkable_specifically(judges, FARS[0])).count();
    let linkable = kept.iter().filter(|f| f.linkable(judges, FARS[0])).count();
    VerdictCounts {
        photos: photos.len(),
        scored: kept.len(),
        matched,
        stranger_like: linkable - matched,
        grey_photos_refused: apart.len(),
        grey_faces_refused: apart.iter().flat_map(|p| &p.faces).filter(|f| !f.at_edge).count(),
        gallery,
    }
}

/// The one sentence a person can act on, printed first: are these photos safe to share
/// through this preset, which are not, and what to do. Real links, low-quality matches and
/// refused grey photos are kept apart; a rank is put beside its chance level.
fn verdict(c: &VerdictCounts) -> String {
    let plural = |n: usize, one: &str, many: &str| if n == 1 { format!("{n} {one}") } else { format!("{n} {many}") };
    let mut v = if c.scored == 0 && c.grey_photos_refused == 0 {
        format!("No face to check: none was found in {}.", plural(c.photos, "photo", "photos"))
    } else if c.matched == 0 {
        format!(
            "None of the {} could be matched to its own person (at a false-match rate of 1 in 1,000): as far as these face-recognition models can tell, the photos are safe to share through this preset.",
            plural(c.scored, "face", "faces")
        )
    } else {
        format!(
            "{} of {} could be matched to their own person (at a false-match rate of 1 in 1,000): do not share the photos whose lines say LINKABLE as they are; `campro simulate --enhance` (it hides every face its guard finds) or a stronger preset such as campro-omega-0.5-hour protects them.",
            c.matched,
            plural(c.scored, "face", "faces")
        )
    };
    if c.stranger_like > 0 {
        let _ = write!(
            v,
            " {} matched a stranger just as well as their own person: low-quality faces (small, blurred or dark), not a link to anyone.",
            if c.stranger_like == 1 { "1 more face".to_string() } else { format!("{} more faces", c.stranger_like) }
        );
    }
    if c.grey_photos_refused > 0 {
        let _ = write!(
            v,
            " {} ({}) set apart: `campro simulate` refuses black-and-white photos with this preset, so they cannot be shared through it.",
            plural(c.grey_photos_refused, "black-and-white photo", "black-and-white photos"),
            plural(c.grey_faces_refused, "face", "faces")
        );
    }
    if c.gallery > 1 && c.scored > 0 {
        let _ = write!(v, " Ranks are out of {} identities: rank 1 by chance is 1 in {}.", c.gallery, c.gallery);
    }
    v
}

/// Two decimals without the leading zero, as similarities are usually written (.21).
fn sim(v: f32) -> String {
    let s = format!("{v:.2}");
    s.replacen("0.", ".", 1)
}

/// The verdict line of one photo.
fn photo_line(p: &PhotoCheck, judges: &[Judge], views: &[Condition], gallery: usize) -> String {
    let name = escape(&p.path.display().to_string());
    let who = p.person.as_ref().map(|n| format!(" ({})", escape(n))).unwrap_or_default();
    let grey = if p.grey { " [grey-scale photo: CamPro protects grey scenes less than colour ones]" } else { "" };
    if p.faces.is_empty() {
        return format!("{name}{who}: no face found{grey}");
    }
    let n = p.faces.len();
    let link: Vec<usize> = FARS.iter().map(|&far| p.faces.iter().filter(|f| f.linkable(judges, far)).count()).collect();
    let specific = p.faces.iter().filter(|f| f.linkable_specifically(judges, FARS[0])).count();
    let faces = if n == 1 { "face" } else { "faces" };
    let verdict = match (link[0], link[1]) {
        (0, 0) => format!("{n} {faces}, none linkable at FAR 1e-2"),
        (0, l) => format!("{n} {faces}, none linkable at FAR 1e-3, {l} at 1e-2"),
        (l, _) if specific < l => {
            format!("{n} {faces}, {l} LINKABLE at FAR 1e-3 ({} no more than to strangers)", l - specific)
        }
        (l, _) => format!("{n} {faces}, {l} LINKABLE at FAR 1e-3"),
    };
    let worst = worst_face(p.faces.iter(), judges);
    let mut line = format!("{name}{who}: {verdict}");
    if let Some((f, (v, m, _))) = worst {
        let _ = write!(
            line,
            " (worst similarity {} against {}, {}, {})",
            sim(f.views[v].similarity[m]),
            sim(judges[m].thresholds.far_1e3),
            judges[m].embedder.name(),
            views[v].name
        );
    }
    if let Some(r) = p.faces.iter().filter_map(|f| f.best_rank()).min() {
        let _ = write!(line, "; worst rank {r} of {gallery}");
    }
    let scored: Vec<&FaceCheck> = p.faces.iter().filter(|f| !f.at_edge).collect();
    let lost = scored.iter().filter(|f| f.views.iter().any(|v| !v.found)).count();
    if lost > 0 {
        let _ = write!(line, "; {lost} of {} not found by the detector in some view", scored.len());
    }
    let edge = p.faces.len() - scored.len();
    if edge > 0 {
        let _ = write!(line, "; {edge} at the photo's edge, not scored");
    }
    line + grey
}

fn summary_line(s: &Summary, judges: &[Judge], gallery: usize) -> String {
    let mut line = format!(
        "{} of {} faces linkable at FAR 1e-3 ({} at 1e-2) on {} model{}",
        s.linkable[0],
        s.faces - s.at_edge,
        s.linkable[1],
        judges.len(),
        if judges.len() == 1 { "" } else { "s" }
    );
    if s.linkable[0] > s.linkable_specifically[0] {
        let _ = write!(
            line,
            " ({} of them no more similar to their own raw face than to a stranger's: low-quality faces)",
            s.linkable[0] - s.linkable_specifically[0]
        );
    }
    if let (Some(v), Some(t)) = (s.worst_similarity, s.worst_threshold) {
        let _ = write!(line, "; worst similarity {} against threshold {}", sim(v), sim(t));
    }
    if let Some(r) = s.worst_rank {
        let _ = write!(line, "; worst rank {r} of {gallery} (chance 1 in {gallery})");
    }
    if s.at_edge > 0 {
        let _ = write!(line, "; {} faces at a photo's edge not scored", s.at_edge);
    }
    if s.photos_without_faces > 0 {
        let _ = write!(line, "; {} of {} photos without a face", s.photos_without_faces, s.photos);
    }
    line
}

/// `campro check --record RECORD FILE`: FILE is the output its record names (same
/// SHA-256), or its raw input (then the camera runs again with the record's settings and the
/// new output's SHA-256 must be the record's). 0 when it verifies, [`LINKABLE_EXIT`] when not.
///
/// What each proves, said in the output: a hash match proves only that FILE is the file the
/// record names; how it was made (the preset, the path) is the record's word, unproven, since
/// anyone can write a record. Only the raw input run through the camera again proves it. A
/// record whose bundled preset's SHA-256 is not that preset's is refused as edited.
fn verify_record(a: &CheckArgs, record: &Path) -> Result<i32> {
    let files: Vec<&PathBuf> = a.params.iter().chain(&a.photos).collect();
    let [file] = files[..] else {
        bail!("--record: give one file to verify (the output or its raw input), got {}", files.len())
    };
    let r = crate::record::read(record)?;
    // A bundled preset is known here: its name and SHA-256 must be its own.
    if let Some(preset) = crate::presets::named(Path::new(&r.preset.given)) {
        if crate::record::sha256(preset.json.as_bytes()) != r.preset.sha256 {
            bail!(
                "{}: preset.sha256: is not the SHA-256 of the bundled preset {} that preset.given names (an edited or forged record)",
                crate::shown(record),
                preset.name
            );
        }
        let name = crate::load_params(Path::new(&r.preset.given))?.name;
        if name != r.preset.name {
            bail!(
                "{}: preset.name: {} is not the name of the bundled preset {} (an edited or forged record)",
                crate::shown(record),
                escape(&r.preset.name),
                escape(&name)
            );
        }
    }
    let (h, _) = crate::record::sha256_file(file)?;
    let what = format!(
        "preset {} (SHA-256 {}), campro {}, path {}, {}-bit, bound {} LSB",
        escape(&r.preset.name),
        &r.preset.sha256[..12],
        escape(&r.campro_version),
        escape(&r.path),
        r.bit_depth,
        r.bound_lsb
    );
    let what = match &r.device {
        Some(d) => format!(
            "{what}; camera {} sent its values ({} curve points; reported within {:.3} LSB of them)",
            escape(&d.camera_id),
            d.curve_points,
            d.worst_reported_deviation_lsb
        ),
        None => what,
    };
    if h == r.output.sha256 {
        let prove = match &r.input {
            Some(i) => format!("give its raw input ({}) to run the camera again", escape(&i.name)),
            None => "a phone's raw never leaves the camera: only the camera's own record vouches for it".into(),
        };
        say!(
            "{}: the output its record names (the same SHA-256). That proves which file it is, not how it was made: the record says {what}, unproven ({prove})",
            crate::shown(file)
        );
        return Ok(0);
    }
    if r.input.as_ref().is_none_or(|i| i.sha256 != h) {
        let raw = match &r.input {
            Some(i) => format!("nor the input's ({})", escape(&i.name)),
            None => "and the record names no raw input (a phone's capture: the raw never left the camera)".into(),
        };
        say!(
            "{}: NOT what its record names: its SHA-256 is not the output's ({}) {raw}",
            crate::shown(file),
            escape(&r.output.name)
        );
        return Ok(LINKABLE_EXIT);
    }
    // The raw input: the camera again, as recorded.
    let given = PathBuf::from(&r.preset.given);
    let bytes = crate::record::preset_bytes(&given)
        .with_context(|| format!("the record's preset {}", escape(&r.preset.given)))?;
    if crate::record::sha256(&bytes) != r.preset.sha256 {
        bail!(
            "the record's preset {}: its SHA-256 is not the record's (the preset changed since): nothing to compare",
            escape(&r.preset.given)
        );
    }
    let p = crate::load_params(&given)?;
    let enhancer = if r.enhancer_sha256.is_some() {
        let e = crate::record::enhancer_bytes(&given, &p)?;
        if r.enhancer_sha256.as_deref() != Some(crate::record::sha256(&e).as_str()) {
            bail!("the record's enhancer: its SHA-256 is not the record's (the enhancer changed since)");
        }
        Some(crate::capture::enhancer_of(&given, &p, a.scale, &a.data.models_dir())?)
    } else {
        None
    };
    let metadata = match r.metadata.as_str() {
        "strip" => crate::metadata::Policy::Strip,
        "keep" => crate::metadata::Policy::Keep,
        "keep-safe" => crate::metadata::Policy::KeepSafe,
        other => bail!("{}: metadata: must be strip, keep-safe or keep, got {}", crate::shown(record), escape(other)),
    };
    let dir = tempfile::tempdir()?;
    let out = dir.path().join(
        Path::new(&r.output.name)
            .file_name()
            .ok_or_else(|| anyhow!("{}: output.name: must be a file name", crate::shown(record)))?,
    );
    let enc = crate::video::Encoding { codec: "libx264".into(), crf: Some(18), bitrate: None, preset: None };
    let o = crate::simulate::Options {
        depth: if r.bit_depth == 16 { campro::pipeline::Depth::Sixteen } else { campro::pipeline::Depth::Eight },
        existing: crate::simulate::Existing::Refuse,
        jobs: None,
        enc: &enc,
        enhancer: enhancer.as_ref(),
        json: false,
        quality: r.jpeg_quality.unwrap_or(95),
        image_format: crate::simulate::ImageFormat::of(&out),
        frames: crate::video::FrameFormat { size: None, rate: None, stall: None },
        max_frames: None,
        // Grey input is written as it was: the output's bytes are what is compared.
        allow_grey: true,
        models: None,
        metadata,
        record: None,
    };
    crate::simulate::simulate(&p, std::slice::from_ref(file), &out, &o)?;
    let (again, _) = crate::record::sha256_file(&out)?;
    if again == r.output.sha256 {
        say!(
            "{}: its raw input; run again it gives the output its record names ({}): {what}",
            crate::shown(file),
            escape(&r.output.name)
        );
        Ok(0)
    } else {
        say!(
            "{}: its raw input; run again it does NOT give the recorded output {} (SHA-256 {} instead of {}): {what}",
            crate::shown(file),
            escape(&r.output.name),
            &again[..12],
            &r.output.sha256[..12]
        );
        Ok(LINKABLE_EXIT)
    }
}

/// The bundled face recognition models `check` runs by default.
const DEFAULT_FACE_MODELS: [&str; 2] = ["faceplugin", "mobilefacenet-casia"];

/// The face models to run: those asked for (each must load), else every default one the
/// models folder holds, each missing one said in `notes` with how to get it (none at all:
/// an error naming the command).
fn face_models_of(asked: &[String], models: &Path, notes: &mut Vec<String>) -> Result<Vec<String>> {
    if !asked.is_empty() {
        return Ok(asked.to_vec());
    }
    let mut found = Vec::new();
    for name in DEFAULT_FACE_MODELS {
        let pin = crate::models::pin(name).expect("a bundled model");
        if models.join(pin.file).is_file() {
            found.push(name.to_string());
        } else {
            notes.push(format!("checked without {name}: {}", crate::models::how_to_get(pin, models)));
        }
    }
    if found.is_empty() {
        bail!(
            "no face recognition model: {}",
            crate::models::how_to_get(crate::models::pin("faceplugin").expect("bundled"), models)
        );
    }
    Ok(found)
}

/// The report folder is never a photo folder nor inside one, `--force` or not: the next run
/// would read the report's face crops as a person's photos.
fn outside_the_photos(out: &Path, photos: &[PathBuf]) -> Result<()> {
    // Where `out` is or would be: the folder resolved (links and `..`), its name appended.
    let resolved = |p: &Path| -> Option<PathBuf> {
        if let Ok(c) = std::fs::canonicalize(p) {
            return Some(c);
        }
        let parent = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        Some(std::fs::canonicalize(parent).ok()?.join(p.file_name()?))
    };
    let Some(at) = resolved(out) else { return Ok(()) };
    for photos in photos.iter().filter(|p| p.is_dir()) {
        if let Ok(folder) = std::fs::canonicalize(photos) {
            if at.starts_with(&folder) {
                bail!(
                    "--output {}: is inside the photo folder {}; the next check would read the report's face crops as photos: write it elsewhere",
                    crate::shown(out),
                    crate::shown(photos)
                );
            }
        }
    }
    Ok(())
}

/// `campro check`.
pub fn run(a: CheckArgs) -> Result<i32> {
    if let Some(record) = &a.record {
        return verify_record(&a, record);
    }
    let start = std::time::Instant::now();
    let params = a.params.clone().ok_or_else(|| anyhow!("PARAMS: required"))?;
    let p = crate::load_params(&params)?;
    if let Some(out) = &a.output {
        let folders: Vec<PathBuf> =
            a.photos.iter().chain(&a.people).chain(a.persons.iter().map(|(_, d)| d)).cloned().collect();
        outside_the_photos(out, &folders)?;
        crate::check_output_folder(out, a.force, "--output")?;
    }
    let out_for_inputs = a.output.clone().unwrap_or_else(|| PathBuf::from(".campro-check-no-output"));
    let photos = photos_of(&a, &out_for_inputs)?;
    let models = a.data.models_dir();
    if !models.is_dir() {
        bail!(
            "the models folder {}: no such folder; `campro models fetch` installs the models a registry has (`campro models list` says where the others come from), or pass --models DIR, --shared DIR or set CAMPRO_SHARED",
            crate::shown(&models)
        );
    }
    let detector =
        FaceDetector::new(crate::models::load(crate::models::face_detector(&a.face_detector, &models), &models)?)?;
    let mut notes = Vec::new();
    let face_models = face_models_of(&a.face_models, &models, &mut notes)?;
    let embedders: Vec<Embedder> =
        face_models.iter().map(|n| Ok(Embedder::new(crate::models::load(n, &models)?)?)).collect::<Result<_>>()?;
    let judges: Vec<Judge> = embedders.iter().map(Judge::new).collect::<campro_eval::Result<_>>()?;
    let failures = crate::eval::Failures::default();
    let views = views_of(&a, &params, &p, &models, &photos, &mut notes, &failures)?;
    if views.is_empty() {
        bail!("--view: no view to check");
    }
    let budget = Budget::global();
    // What `simulate` refuses as grey (the whole photo, or its faces when it is mostly
    // colourless): those photos are set apart in the verdict.
    let grey = crate::capture::GreyPolicy::new(&p, false).with_faces(&models);
    let bar = crate::output::count_bar("check", photos.len() as u64);
    let results: Vec<Result<(PhotoCheck, bool)>> = photos
        .par_iter()
        .map(|ph| {
            let warn = |w: &str| bar.suspend(|| eprintln!("warning: {}: {w}", crate::shown(&ph.path)));
            // Each view of the photo (captured, enhanced, restored: 3 bytes a pixel each).
            let views_bytes = |w: u32, h: u32| w as u64 * h as u64 * 3 * views.len() as u64;
            let r = campro_eval::image_file::read(&ph.path, budget, &views_bytes, &warn)
                .map_err(anyhow::Error::from)
                .and_then(|(img, _lease)| {
                    let img = img.into_rgb8();
                    let refused = grey.check_picture(img.as_raw(), img.width(), img.height()).is_err();
                    Ok((check::check_photo(&ph.path, ph.person.clone(), &img, &detector, &judges, &views)?, refused))
                });
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    // A view that failed on a photo scored another picture under its name: no report.
    failures.check()?;
    let (mut checked, mut refused) = (Vec::new(), Vec::new());
    let mut failed = Vec::new();
    for (ph, r) in photos.iter().zip(results) {
        match r {
            Ok((c, r)) => {
                checked.push(c);
                refused.push(r);
            }
            Err(e) => {
                let line = crate::about(&ph.path, &e);
                eprintln!("error: {line}");
                failed.push(Failed { path: ph.path.display().to_string(), error: line });
            }
        }
    }
    // Distractors: LFW identities none of the persons checked is named after.
    let mut distractors = Vec::new();
    if a.distractors > 0 {
        let dir = a.lfw.clone().unwrap_or_else(|| a.data.shared_dir().join("data/lfw"));
        match campro_eval::data::Lfw::open(&dir) {
            Ok(lfw) => {
                let names: Vec<String> = checked.iter().filter_map(|p| p.person.clone()).collect();
                distractors = check::lfw_distractors(&lfw, a.distractors, &names, &detector, &judges)?;
            }
            Err(e) if a.lfw.is_none() => notes.push(format!(
                "no LFW distractors ({}): the gallery holds only the photos checked",
                crate::one_line(&e.into())
            )),
            Err(e) => return Err(anyhow::Error::from(e).context("--lfw")),
        }
    }
    let gallery = check::rank_all(&mut checked, &distractors, judges.len());
    let s = summary(&checked, &judges, &views);
    let counts = verdict_counts(&checked, &refused, &judges, gallery);
    let report = CheckReport {
        params: format!("{} ({})", crate::shown(&params), p.name),
        face_detector: detector.name(),
        models: judges
            .iter()
            .map(|j| ModelRow { name: j.embedder.name().to_string(), thresholds: j.thresholds })
            .collect(),
        views: views.iter().map(|v| v.name.clone()).collect(),
        gallery,
        distractors: distractors.len(),
        notes: &notes,
        photos: &checked,
        failed,
        summary: s,
        verdict: verdict(&counts),
        verdict_counts: counts,
        seconds: start.elapsed().as_secs_f64(),
    };
    if let Some(out) = &a.output {
        write_report(out, &report, &judges, &views)?;
    }
    if a.format == Report::Json {
        say!("{}", serde_json::to_string(&report)?);
    } else {
        for n in &notes {
            eprintln!("note: {n}");
        }
        say!("{}", report.verdict);
        for ph in &checked {
            say!("{}", photo_line(ph, &judges, &views, gallery));
        }
        say!("{}", summary_line(&report.summary, &judges, gallery));
        if let Some(out) = &a.output {
            eprintln!("report: {}", crate::shown(&out.join("index.html")));
        }
    }
    if !report.failed.is_empty() {
        bail!("{} of {} photos could not be checked", report.failed.len(), photos.len());
    }
    let linkable = match a.fail_above {
        Some(far) if far <= FARS[0] => report.summary.linkable[0],
        Some(_) => report.summary.linkable[1],
        None => 0,
    };
    Ok(if linkable > 0 { LINKABLE_EXIT } else { 0 })
}

/// The crop file of face `k` of photo `i` under `view` (`raw` for the raw face).
fn crop_name(i: usize, k: usize, view: &str) -> String {
    format!("faces/photo{:04}-face{}-{view}.png", i + 1, k + 1)
}

fn png(img: &RgbImage) -> Result<Vec<u8>> {
    let mut v = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut v), image::ImageFormat::Png)?;
    Ok(v)
}

/// index.html, check.json, check.csv and the crops, each written atomically.
fn write_report(out: &Path, r: &CheckReport, judges: &[Judge], views: &[Condition]) -> Result<()> {
    for (i, p) in r.photos.iter().enumerate() {
        for (k, f) in p.faces.iter().enumerate() {
            write_atomic(&out.join(crop_name(i, k, "raw")), &png(&f.crop)?, true)?;
            for v in &f.views {
                write_atomic(&out.join(crop_name(i, k, &v.view)), &png(&v.crop)?, true)?;
            }
        }
    }
    write_atomic(&out.join("check.json"), (serde_json::to_string_pretty(r)? + "\n").as_bytes(), true)?;
    use campro_eval::table::{Cell, Column, Table};
    let mut t = Table::new(
        [
            ("photo", 0),
            ("person", 0),
            ("face", 0),
            ("view", 0),
            ("model", 0),
            ("similarity", 4),
            ("threshold_far_1e-3", 4),
            ("threshold_far_1e-2", 4),
            ("linkable_far_1e-3", 0),
            ("linkable_far_1e-2", 0),
            ("found_by_detector", 0),
            ("rank", 0),
            ("gallery", 0),
        ]
        .map(|(k, d)| Column::new(k, k, d)),
    );
    for p in r.photos {
        for (k, f) in p.faces.iter().enumerate() {
            for v in &f.views {
                for (m, j) in judges.iter().enumerate() {
                    let s = v.similarity[m];
                    t.push(vec![
                        Cell::text(p.path.display().to_string()),
                        Cell::text(p.person.clone().unwrap_or_default()),
                        ((k + 1) as f64).into(),
                        Cell::text(&v.view),
                        Cell::text(j.embedder.name()),
                        f64::from(s).into(),
                        f64::from(j.thresholds.far_1e3).into(),
                        f64::from(j.thresholds.far_1e2).into(),
                        Cell::text((s > j.thresholds.far_1e3).to_string()),
                        Cell::text((s > j.thresholds.far_1e2).to_string()),
                        Cell::text(v.found.to_string()),
                        Cell::opt(v.rank[m].map(|x| x as f64)),
                        (r.gallery as f64).into(),
                    ]);
                }
            }
        }
    }
    write_atomic(&out.join("check.csv"), t.csv().as_bytes(), true)?;
    write_atomic(&out.join("index.html"), index_html(r, judges, views, out).as_bytes(), true)?;
    Ok(())
}

/// The report page: the summary, then per photo its verdict and, per face, the raw crop
/// beside each view's with every model's similarity against its threshold.
fn index_html(r: &CheckReport, judges: &[Judge], views: &[Condition], out: &Path) -> String {
    let mut h = String::new();
    let e = html_escape;
    h.push_str(&page::head(&format!("campro check: {}", r.params)));
    h.push_str("<h1>campro check</h1>\n");
    let alarm =
        if r.summary.linkable.iter().any(|&n| n > 0) { " class=\"alarm verdict\"" } else { " class=\"verdict\"" };
    let _ = writeln!(h, "<p id=\"verdict\"><strong>{}</strong></p>", e(&r.verdict));
    let _ = writeln!(h, "<p id=\"summary\"{alarm}>{}</p>", e(&summary_line(&r.summary, judges, r.gallery)));
    let _ = writeln!(h, "<p id=\"one-story\">{}</p>", e(crate::page::ONE_STORY));
    let _ = writeln!(
        h,
        "<p>Preset {}. A face is <span class=\"link\">linkable</span> when a model's cosine similarity of the raw face and a view is above its threshold at the false-accept rate (FAR): a face-recognition system would then say “same person”. Rank: where the true person comes in a gallery of {} raw identities ({} LFW distractors); 1 is found first.</p>",
        e(&r.params),
        r.gallery,
        r.distractors
    );
    let _ = writeln!(
        h,
        "<table><tr><th>model</th><th>threshold at FAR 1e-3</th><th>at 1e-2</th><th>calibrated on</th></tr>"
    );
    for m in &r.models {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{:.3}</td><td>{:.3}</td><td>{} LFW pairs of different people</td></tr>",
            e(&m.name),
            m.thresholds.far_1e3,
            m.thresholds.far_1e2,
            m.thresholds.impostor_pairs
        );
    }
    h.push_str("</table>\n");
    for n in r.notes {
        let _ = writeln!(h, "<p>Note: {}</p>", e(n));
    }
    for f in &r.failed {
        let _ = writeln!(h, "<p class=\"link\">Not checked: {}</p>", e(&f.error));
    }
    // Photos with a linkable face first (at 1e-3, then 1e-2), then the rest in their order.
    let flag = |p: &PhotoCheck| {
        if p.faces.iter().any(|f| f.linkable(judges, FARS[0])) {
            0
        } else if p.faces.iter().any(|f| f.linkable(judges, FARS[1])) {
            1
        } else {
            2
        }
    };
    let mut order: Vec<usize> = (0..r.photos.len()).collect();
    order.sort_by_key(|&i| flag(&r.photos[i]));
    for i in order {
        let p = &r.photos[i];
        let _ = writeln!(
            h,
            "<section class=\"row{}\" id=\"photo{i}\"><h2>{}</h2>\n<p class=\"verdict\">{}</p>",
            if flag(p) < 2 { " flag" } else { "" },
            e(&p.path.display().to_string()),
            e(&photo_line(p, judges, views, r.gallery))
        );
        for (k, f) in p.faces.iter().enumerate() {
            if f.at_edge {
                let _ = writeln!(h, "<p class=\"lost\">Face {}: cut by the photo's edge, not scored (its alignment is mostly black).</p>", k + 1);
            }
            let zoom = format!("photo{i}face{k}");
            let src = |view: &str| href(&out.join(crop_name(i, k, view)), out);
            let face = format!("face {}{}", k + 1, if f.is_person { " (the person)" } else { "" });
            let _ = write!(
                h,
                "<div class=\"figs\">{}",
                page::crop(&src("raw"), "raw face", &zoom, &format!("{}: raw", e(&face)))
            );
            let mut big = page::big(&src("raw"), "raw face", Some(336));
            for v in &f.views {
                let mut caption = e(&v.view);
                if !v.found {
                    caption.push_str("<br><span class=\"lost\">not found by the detector</span>");
                }
                for (m, j) in judges.iter().enumerate() {
                    let s = v.similarity[m];
                    let class = if s > j.thresholds.far_1e2 { "link" } else { "safe" };
                    let rank = v.rank[m].map(|x| format!(", rank {x}")).unwrap_or_default();
                    let strangers = v.strangers[m].map(|x| format!(", strangers up to {}", sim(x))).unwrap_or_default();
                    let _ = write!(
                        caption,
                        "<br><span class=\"{class}\">{}: {} vs {}{rank}{strangers}</span>",
                        e(j.embedder.name()),
                        sim(s),
                        sim(j.thresholds.far_1e3)
                    );
                }
                h.push_str(&page::crop(&src(&v.view), &v.view, &zoom, &caption));
                big.push_str(&page::big(&src(&v.view), &v.view, Some(336)));
            }
            h.push_str("</div>\n");
            let views: Vec<&str> = f.views.iter().map(|v| v.view.as_str()).collect();
            h.push_str(&page::lightbox(
                &zoom,
                &e(&format!("{face}: raw | {}", views.join(" | "))),
                &big,
                &format!("photo{i}"),
            ));
            h.push('\n');
        }
        h.push_str("</section>\n");
    }
    h.push_str("</body></html>\n");
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(scored: usize, matched: usize, stranger_like: usize, grey: usize) -> VerdictCounts {
        VerdictCounts {
            photos: 25,
            scored,
            matched,
            stranger_like,
            grey_photos_refused: grey,
            grey_faces_refused: 3 * grey,
            gallery: 7,
        }
    }

    /// The four kinds of folder a new user brings, one sentence each.
    #[test]
    fn the_verdict_says_safe_linkable_refused_and_low_quality_apart() {
        let safe = verdict(&counts(98, 0, 0, 0));
        assert!(safe.starts_with("None of the 98 faces could be matched to its own person"), "{safe}");
        assert!(safe.contains("safe to share through this preset") && !safe.contains("LINKABLE"), "{safe}");
        assert!(safe.ends_with("rank 1 by chance is 1 in 7."), "{safe}");

        let linkable = verdict(&counts(98, 5, 0, 0));
        assert!(linkable.starts_with("5 of 98 faces could be matched to their own person"), "{linkable}");
        assert!(
            linkable.contains("do not share the photos whose lines say LINKABLE") && linkable.contains("--enhance"),
            "{linkable}"
        );
        assert!(!linkable.contains("safe to share"), "{linkable}");

        let low = verdict(&counts(98, 0, 31, 0));
        assert!(low.starts_with("None of the 98 faces"), "{low}");
        assert!(
            low.contains("31 more faces matched a stranger just as well as their own person: low-quality faces"),
            "{low}"
        );

        let refused = verdict(&counts(90, 1, 1, 2));
        assert!(refused.contains("1 more face matched a stranger"), "{refused}");
        assert!(
            refused.contains("2 black-and-white photos (6 faces) set apart: `campro simulate` refuses"),
            "{refused}"
        );

        let empty = verdict(&VerdictCounts { photos: 3, ..Default::default() });
        assert_eq!(empty, "No face to check: none was found in 3 photos.");
    }
}
