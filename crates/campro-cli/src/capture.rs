//! What a camera shows: the exact 8-bit pipeline on a frame, then, with `--enhance`, the
//! preset's image enhancer; and the networks a parameter set names beside it (its
//! enhancer, an attacker's restoration network). Shared by `simulate` (images and video),
//! `inspect` and `eval`.

use crate::args::EnhanceArgs;
use anyhow::{anyhow, bail, Result};
use campro::pipeline::fast::Exact8;
use campro::pipeline::{Depth, Prepared};
use campro::Params;
use campro_eval::guard::{FaceGuard, GuardedEnhancer, Hide};
use rayon::prelude::*;
use std::path::Path;

/// Largest image the enhancer runs on (pixels): the face guard's
/// ([`campro_eval::guard::MAX_PIXELS`], 16384 x 12288: a 200-megapixel phone photo fits).
/// The enhancer works on strips and the guard on tiles, so memory is a few bytes a pixel
/// (the budget decides); this bounds the time.
pub const MAX_ENHANCE_PIXELS: u64 = campro_eval::guard::MAX_PIXELS;

/// Longest side the enhancer runs on (pixels): a 200-megapixel photo's 16320 fits; a
/// strip of 1 x 1,000,000 does not.
pub const MAX_ENHANCE_SIDE: u32 = 16384;

/// What `simulate` does to a frame: the camera (exact, on every core), then, with
/// `--enhance`, the preset's enhancer (tract, one thread a frame).
pub(crate) struct Capture<'a, 'p> {
    /// The exact 8-bit path.
    pub fast8: &'a Exact8<'p>,
    /// The reference path tabulated for 8-bit input (also the params).
    pub p8: &'a Prepared<'p>,
    /// The same for 16-bit input: its 65,536-entry degamma table is built on first use.
    pub p16: &'a std::sync::OnceLock<Prepared<'p>>,
    pub enhancer: Option<&'a GuardedEnhancer>,
    /// What happens to grey input.
    pub grey: &'a GreyPolicy,
}

/// What `simulate` does with a grey or near-grey picture ([`campro::chroma`]), where a
/// global matrix and curve protect little: refused unless the preset is rated for grey or
/// the user allowed it (`--allow-grey`), in which case it is counted and said.
#[derive(Debug, Default)]
pub struct GreyPolicy {
    /// The preset is rated for grey input ([`Params::rated_for_grey`]): nothing to check.
    pub rated: bool,
    /// `--allow-grey`: process grey input anyway, with a warning.
    pub allow: bool,
    /// Grey frames and images processed under `allow`.
    pub allowed: std::sync::atomic::AtomicU64,
    /// Where a photo's faces are looked at when most of it has no colour
    /// ([`GreyPolicy::check_picture`]); None: the whole frame only.
    pub faces: Option<FaceLook>,
}

/// Share of a photo's mid-tones that are neutral ([`campro::chroma::neutral_share`]) from
/// which its faces are looked at for colour: selective-colour photos measured 0.79 to 0.96,
/// snow and overcast scenes 0.77 to 0.90 (their faces are in colour); no LFW photo is over
/// 0.47, and 2 colour photos of 300 from COCO are over it (0.76 and 0.81).
pub const SUSPECT_NEUTRAL_SHARE: f64 = 0.75;

/// Longest side (pixels) a suspect photo is searched for faces at: one detector run of at
/// most 1280 x 1280, faces from about 16 pixels there.
pub const FACE_LOOK_SIDE: u32 = 1280;

/// Smallest face box (pixels a side, at [`FACE_LOOK_SIDE`]) whose colour is judged.
pub const FACE_LOOK_MIN: u32 = 16;

/// Share of a face's mid-tones that are neutral ([`campro::chroma::neutral_share`] of its
/// centre) from which the face is grey: skin under common light differs between its red and
/// blue by more than [`campro::chroma::NEUTRAL_RANGE`]. Measured with every photo looked
/// at: 271 faces of 225 LFW photos at most 0.22, 196 faces of 285 COCO photos at most 0.49;
/// the faces of selective-colour photos (grey but for one object) 1.00.
pub const FACE_NEUTRAL_SHARE: f64 = 0.8;

/// The face detectors a suspect photo's faces are found with (the face guard's), loaded
/// on first need from `models`.
pub struct FaceLook {
    models: std::path::PathBuf,
    detectors: std::sync::OnceLock<std::result::Result<Vec<campro_eval::face::FaceDetector>, String>>,
}

impl std::fmt::Debug for FaceLook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaceLook").field("models", &self.models).finish_non_exhaustive()
    }
}

impl FaceLook {
    /// Faces found with the detectors of `models`, loaded when first asked.
    pub fn new(models: &Path) -> Self {
        Self { models: models.to_path_buf(), detectors: Default::default() }
    }

    /// The colour spread (8-bit codes, [`campro::chroma::measure`]) of the greyest face
    /// found in the `w` x `h` RGB picture `rgb` whose centre is grey ([`FACE_NEUTRAL_SHARE`]),
    /// else None; an error naming why no detector could look.
    pub fn grey_face(&self, rgb: &[u8], w: u32, h: u32) -> std::result::Result<Option<f64>, String> {
        let detectors = self
            .detectors
            .get_or_init(|| crate::models::face_guard_detectors(&self.models).map_err(|e| format!("{e:#}")))
            .as_ref()
            .map_err(Clone::clone)?;
        // Nearest samples at the look's scale: the detector sees the scene, not its grain.
        let s = (f64::from(FACE_LOOK_SIDE) / f64::from(w.max(h))).min(1.0);
        let (sw, sh) = (((w as f64 * s).round() as u32).max(1), ((h as f64 * s).round() as u32).max(1));
        let small = image::RgbImage::from_fn(sw, sh, |x, y| {
            let (sx, sy) = ((((x as f64 + 0.5) / s) as u32).min(w - 1), (((y as f64 + 0.5) / s) as u32).min(h - 1));
            let i = 3 * (sy as usize * w as usize + sx as usize);
            image::Rgb([rgb[i], rgb[i + 1], rgb[i + 2]])
        });
        let mut greyest: Option<f64> = None;
        for d in detectors {
            let found = d.detect_region(&small, [0, 0, sw, sh], d.threshold()).map_err(|e| format!("{e:#}"))?;
            for f in d.suppressed(found) {
                // The face's centre half a side (its cheeks, eyes, nose and mouth): a box's
                // edges hold hair, background and the coloured object beside the face.
                let (bw, bh) = (f.bbox[2] - f.bbox[0], f.bbox[3] - f.bbox[1]);
                let clip = |v: f32, hi: u32| (v.max(0.0) as u32).min(hi);
                let (x0, x1) = (clip(f.bbox[0] + bw / 4.0, sw), clip(f.bbox[2] - bw / 4.0, sw));
                let (y0, y1) = (clip(f.bbox[1] + bh / 4.0, sh), clip(f.bbox[3] - bh / 4.0, sh));
                if x1 < x0 + FACE_LOOK_MIN / 2 || y1 < y0 + FACE_LOOK_MIN / 2 {
                    continue;
                }
                let core: Vec<u8> = (y0..y1)
                    .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                    .flat_map(|(x, y)| small.get_pixel(x, y).0)
                    .collect();
                let share = campro::chroma::neutral_share(&core);
                if share >= FACE_NEUTRAL_SHARE {
                    let spread = campro::chroma::measure(&core).spread;
                    greyest = Some(greyest.map_or(spread, |g| g.min(spread)));
                }
            }
        }
        Ok(greyest)
    }
}

impl GreyPolicy {
    /// The policy for `p` and the `--allow-grey` flag (the whole frame only; see
    /// [`GreyPolicy::with_faces`]).
    pub fn new(p: &Params, allow: bool) -> Self {
        Self { rated: p.rated_for_grey(), allow, allowed: Default::default(), faces: None }
    }

    /// The policy also looking at the faces of photos that are mostly without colour, with
    /// the detectors of `models`.
    pub fn with_faces(mut self, models: &Path) -> Self {
        self.faces = Some(FaceLook::new(models));
        self
    }

    /// [`Self::check`] of a `w` x `h` photo, and where most of its mid-tones have no colour
    /// ([`SUSPECT_NEUTRAL_SHARE`]), of its faces: a selective-colour photo (grey but for one
    /// object) passes the whole-frame measure while its grey faces would be restored. A
    /// grey face is refused as a grey photo is; when no detector can look, the photo is
    /// refused too (fail closed) unless `allow`.
    pub fn check_picture(&self, rgb: &[u8], w: u32, h: u32) -> Result<bool> {
        if self.rated {
            return Ok(false);
        }
        let m = campro::chroma::measure(rgb);
        if m.is_grey() {
            return self.refused_unless_allowed(GreyRefused { spread: m.spread, faces: false }.into());
        }
        let Some(look) = &self.faces else { return Ok(false) };
        // Too small or too flat to show a face, as for the whole-frame measure.
        if m.pixels < campro::chroma::MIN_PIXELS || m.detail < campro::chroma::FLAT_DETAIL {
            return Ok(false);
        }
        let share = campro::chroma::neutral_share(rgb);
        if share < SUSPECT_NEUTRAL_SHARE {
            return Ok(false);
        }
        let refused = match look.grey_face(rgb, w, h) {
            Ok(None) => return Ok(false),
            Ok(Some(spread)) => anyhow::Error::from(GreyRefused { spread, faces: true }),
            Err(why) => anyhow!(
                "{:.0}% of the picture's mid-tones have no colour and no face detector could be loaded to see whether its faces do ({why}); --allow-grey writes it anyway, unprotected",
                100.0 * share
            ),
        };
        self.refused_unless_allowed(refused)
    }

    /// Ok(true) for a grey picture let through (`allow`), Ok(false) for a colour one or a
    /// preset rated for grey, an error for a grey one otherwise. `rgb`: 8-bit RGB pixels.
    pub fn check(&self, rgb: &[u8]) -> Result<bool> {
        if self.rated {
            return Ok(false);
        }
        let m = campro::chroma::measure(rgb);
        if !m.is_grey() {
            return Ok(false);
        }
        self.refused_unless_allowed(GreyRefused { spread: m.spread, faces: false }.into())
    }

    /// `refused` as the error, or under `allow` Ok(true), counted.
    fn refused_unless_allowed(&self, refused: anyhow::Error) -> Result<bool> {
        if !self.allow {
            return Err(refused);
        }
        self.allowed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok(true)
    }

    /// [`Self::check`] on 16-bit RGB pixels (their high bytes, sampled).
    pub fn check16(&self, rgb: &[u16]) -> Result<bool> {
        if self.rated {
            return Ok(false);
        }
        let step = (rgb.len() / 3).div_ceil(campro::chroma::MAX_SAMPLES).max(1);
        let sample: Vec<u8> =
            rgb.chunks_exact(3).step_by(step).flat_map(|p| [p[0], p[1], p[2]].map(|v| (v >> 8) as u8)).collect();
        self.check(&sample)
    }
}

/// The refusal of a grey picture ([`GreyPolicy::check`]), typed so that a caller can tell
/// it from a failure (the Python API's "refused" rows).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GreyRefused {
    /// The colour spread of the picture, or of its greyest face, 8-bit codes.
    pub spread: f64,
    /// Whether it was a face that was grey in a picture with colour elsewhere.
    pub faces: bool,
}

impl std::fmt::Display for GreyRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.faces {
            return write!(
                f,
                "a face in the picture is black and white (its colours differ from grey by {:.1} levels out of 255 on average, under the {} that protection needs) though the picture has colour elsewhere, as a selective-colour photo does; this preset does not protect grey faces: a restoration that knows the camera gives them back (--allow-grey writes it anyway, unprotected)",
                self.spread,
                campro::chroma::GREY_SPREAD
            );
        }
        f.write_str(&grey_message(self.spread))
    }
}

impl std::error::Error for GreyRefused {}

/// Why a grey picture is refused (colour `spread` in 8-bit codes).
pub fn grey_message(spread: f64) -> String {
    format!(
        "the picture is black and white or nearly so (its colours differ from grey by {spread:.1} levels out of 255 on average, under the {} that protection needs), and this preset does not protect grey pictures: a restoration that knows the camera gives grey faces back (--allow-grey writes it anyway, unprotected)",
        campro::chroma::GREY_SPREAD
    )
}

/// The warning for grey pictures written under `--allow-grey`.
pub const GREY_ALLOWED: &str =
    "--allow-grey: grey input written; this preset is not rated for grey, so the output is not protected against a restoration that knows the camera";

impl<'p> Capture<'_, 'p> {
    /// Bytes this capture holds for a `w` x `h` image besides the pipeline's (the guarded
    /// enhancer's, [`GuardedEnhancer::work_bytes`]), for the memory budget images are read
    /// under.
    pub fn work(&self, w: u32, h: u32) -> u64 {
        self.enhancer.map_or(0, |e| e.work_bytes(w, h))
    }

    /// The reference path for 16-bit input.
    pub fn prepared16(&self) -> &Prepared<'p> {
        self.p16.get_or_init(|| Prepared::new(self.p8.params(), Depth::Sixteen))
    }

    /// `dst` = the 16-bit capture of the `w`-pixel-wide 16-bit RGB frame `src` (the exact
    /// reference path on every core; no enhancer: it takes 8 bits).
    /// Returns whether the frame was grey and let through ([`GreyPolicy::check`]).
    pub fn run16(&self, src: &[u16], dst: &mut [u16], w: u32) -> Result<bool> {
        let grey = self.grey.check16(src)?;
        let prep = self.prepared16();
        let row = 3 * w as usize;
        src.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| prep.run(s, d, Depth::Sixteen));
        Ok(grey)
    }

    /// `dst` = the capture of the `w` x `h` RGB photo `src`; returns whether it was grey
    /// and let through ([`GreyPolicy::check_picture`]: its faces looked at when it is mostly
    /// colourless). The enhancer, if any, on this thread.
    pub fn run(&self, src: &[u8], dst: &mut [u8], w: u32, h: u32) -> Result<bool> {
        let grey = self.grey.check_picture(src, w, h)?;
        self.camera(src, dst, w, h, 1)?;
        Ok(grey)
    }

    /// [`Capture::run`] of a video frame, with the enhancer's network on `threads` threads
    /// (one frame at a time): grey judged on the whole frame ([`GreyPolicy::check`]).
    pub fn run_on(&self, src: &[u8], dst: &mut [u8], w: u32, h: u32, threads: usize) -> Result<bool> {
        let grey = self.grey.check(src)?;
        self.camera(src, dst, w, h, threads)?;
        Ok(grey)
    }

    /// `dst` = the camera's (and the enhancer's, if any) picture of `src`.
    fn camera(&self, src: &[u8], dst: &mut [u8], w: u32, h: u32, threads: usize) -> Result<()> {
        let row = 3 * w as usize;
        src.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| {
            self.fast8.run(s, d);
        });
        if let Some(e) = self.enhancer {
            let captured = image::RgbImage::from_raw(w, h, dst.to_vec()).expect("a whole frame");
            dst.copy_from_slice(enhance_on(e, &captured, threads)?.as_raw());
        }
        Ok(())
    }
}

/// A frame's RGB samples as read: 8 or 16 bits a sample, interleaved, rows top to bottom.
#[derive(Debug, Clone, Copy)]
pub enum Frame<'a> {
    Eight(&'a [u8]),
    Sixteen(&'a [u16]),
}

/// Whether a decoded image holds 16-bit samples (taken as [`Frame::Sixteen`]), else 8.
pub fn sixteen_bit(img: &image::DynamicImage) -> bool {
    matches!(img.color().bytes_per_pixel() / img.color().channel_count(), 2 | 4)
}

/// What the camera gives for a [`Frame`]: 8-bit or 16-bit samples (codes of the output depth).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Pixels {
    Eight(Vec<u8>),
    Sixteen(Vec<u16>),
}

impl<'p> Capture<'_, 'p> {
    /// The `w` x `h` frame `src` through the camera, at `depth`, as `simulate` writes a
    /// photo: 8 bits in and out (or 8 bits in with the enhancer) on the exact path
    /// (bit-identical to the reference), anything else on the reference path tabulated for
    /// the input's depth. Also whether the picture was grey and let through
    /// ([`GreyPolicy::check`]); `warn` hears what the user should know.
    pub fn picture(&self, src: Frame, w: u32, h: u32, depth: Depth, warn: &dyn Fn(&str)) -> Result<(Pixels, bool)> {
        let row = 3 * w as usize;
        let (pixels, grey) = match src {
            Frame::Eight(s) if self.enhancer.is_some() || depth == Depth::Eight => {
                return self.picture8(s.to_vec(), w, h, depth, warn);
            }
            // The enhancer reads what an 8-bit camera gives: the caller converts first.
            Frame::Sixteen(_) if self.enhancer.is_some() => bail!("the enhancer takes 8-bit frames"),
            Frame::Sixteen(s) => {
                let grey = self.grey.check16(s)?;
                let prep = self.prepared16();
                let mut dst = vec![0u16; s.len()];
                s.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| prep.run(s, d, depth));
                (Self::at(dst, depth), grey)
            }
            Frame::Eight(s) => {
                let grey = self.grey.check_picture(s, w, h)?;
                let wide: Vec<u16> = s.iter().map(|&v| u16::from(v)).collect();
                let mut dst = vec![0u16; wide.len()];
                wide.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| self.p8.run(s, d, depth));
                (Self::at(dst, depth), grey)
            }
        };
        if grey {
            warn(GREY_ALLOWED);
        }
        Ok((pixels, grey))
    }

    /// [`Capture::picture`] of an 8-bit frame it owns: the camera runs in place (16 rows
    /// copied aside at a time) so `src` becomes the capture, and `src` is gone before the
    /// enhanced image is made: with `--enhance` a picture holds two full-resolution images
    /// (the capture, which the face guard searches, and the enhanced one), not four.
    pub fn picture8(
        &self,
        mut src: Vec<u8>,
        w: u32,
        h: u32,
        depth: Depth,
        warn: &dyn Fn(&str),
    ) -> Result<(Pixels, bool)> {
        if self.enhancer.is_none() && depth != Depth::Eight {
            return self.picture(Frame::Eight(&src), w, h, depth, warn);
        }
        let grey = self.grey.check_picture(&src, w, h)?;
        src.par_chunks_mut(3 * w as usize * 16).for_each(|rows| {
            let raw = rows.to_vec();
            self.fast8.run(&raw, rows);
        });
        let out = match self.enhancer {
            Some(e) => {
                let captured = image::RgbImage::from_raw(w, h, src).ok_or_else(|| anyhow!("not a {w} x {h} frame"))?;
                enhance(e, &captured)?.into_raw()
            }
            None => src,
        };
        if grey {
            warn(GREY_ALLOWED);
        }
        Ok((Pixels::Eight(out), grey))
    }

    /// Reference-path codes of `depth` as [`Pixels`].
    fn at(codes: Vec<u16>, depth: Depth) -> Pixels {
        match depth {
            Depth::Eight => Pixels::Eight(codes.into_iter().map(|v| v as u8).collect()),
            Depth::Sixteen => Pixels::Sixteen(codes),
        }
    }
}

/// The guarded enhancer `e` on a captured image (every face its guard finds hidden),
/// refused over [`MAX_ENHANCE_PIXELS`] (padded) or [`MAX_ENHANCE_SIDE`].
pub fn enhance(e: &GuardedEnhancer, captured: &image::RgbImage) -> Result<image::RgbImage> {
    enhance_on(e, captured, 1)
}

/// [`enhance`] with the network on `threads` threads.
pub fn enhance_on(e: &GuardedEnhancer, captured: &image::RgbImage, threads: usize) -> Result<image::RgbImage> {
    let (w, h) = captured.dimensions();
    // What the network holds is the padded image's (a thin picture is padded to the
    // network's multiple: 1 x 1,000,000 becomes 16 x 1,000,000), and the face guard's work
    // grows with the longer side (its tiles): both are bounded before anything runs.
    let (m, padded) = (e.enhancer.multiple(), e.enhancer.padded_pixels(w as usize, h as usize));
    if padded > MAX_ENHANCE_PIXELS || w.max(h) > MAX_ENHANCE_SIDE {
        bail!(
            "--enhance: the image is {w} x {h} ({padded} pixels padded to the network's multiple of {m}); the enhancer runs on at most {MAX_ENHANCE_PIXELS} pixels and {MAX_ENHANCE_SIDE} a side"
        );
    }
    // A frame of a video does not come through the image reader's budget: its own check.
    let work = e.work_bytes(w, h);
    let budget = campro_eval::image_file::Budget::global().total();
    if work > budget {
        bail!(
            "--enhance: the image is {w} x {h}; at this --enhance-scale the enhancer would hold {} MiB for it (at most {} MiB): use --enhance-scale auto, 2, 4 or 8",
            work >> 20,
            budget >> 20
        );
    }
    Ok(e.enhance_on(captured, threads)?)
}

/// What a parameter set's provenance can name beside it: its enhancer (shown to people) or
/// the restoration network trained against it (an attacker's, for `eval privacy --attack
/// restore-net`). Both are written by `campro train-enhancer`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Network {
    Enhancer,
    Restorer,
}

impl Network {
    /// The provenance key, the file suffix (`PARAMS.KEY.onnx`) and the manifest's kind.
    pub fn key(self) -> &'static str {
        match self {
            Network::Enhancer => campro::provenance::ENHANCER,
            Network::Restorer => campro::provenance::RESTORER,
        }
    }
}

/// The enhancer a parameter set names (`provenance.enhancer.onnx`, beside the file at
/// `params_path`), behind the face guard of the detectors in `models`: what a
/// person is shown. Without the detector nothing is enhanced (an error).
pub fn enhancer_of(params_path: &Path, p: &Params, args: EnhanceArgs, models: &Path) -> Result<GuardedEnhancer> {
    let enhancer = network_of(params_path, p, Network::Enhancer)?.with_scale(args.enhance_scale);
    Ok(GuardedEnhancer { enhancer, guard: face_guard(models, args.faces.into())? })
}

/// The enhanced view's face guard: every face detector of `models` that it runs
/// ([`crate::models::face_guard_detectors`]), their finds joined.
pub fn face_guard(models: &Path, hide: Hide) -> Result<FaceGuard> {
    let detectors = crate::models::face_guard_detectors(models).map_err(|e| {
        anyhow!(
            "--enhance: the enhanced view hides every face it finds, and its face detector could not be loaded ({e:#}); nothing is enhanced without it"
        )
    })?;
    Ok(FaceGuard::of(detectors, hide)?)
}

/// The network `which` a parameter set names (`provenance.KEY.onnx`, a file name beside the
/// file at `params_path`).
pub fn network_of(params_path: &Path, p: &Params, which: Network) -> Result<campro_eval::enhance::Enhancer> {
    let key = which.key();
    if let (Some(preset), Network::Enhancer) = (crate::presets::named(params_path), which) {
        let bytes = preset.enhancer.ok_or_else(|| {
            anyhow!("{}: this bundled preset has no enhancer (campro presets says which do)", preset.name)
        })?;
        return Ok(campro_eval::enhance::Enhancer::from_bytes(bytes, params_path)?);
    }
    let fields = p.provenance_fields().map_err(|e| anyhow!("{}: {e}", params_path.display()))?;
    let named = match which {
        Network::Enhancer => fields.enhancer,
        Network::Restorer => fields.restorer,
    };
    let file = named.map(|n| n.onnx).ok_or_else(|| {
        anyhow!(
            "{}: provenance.{key}.onnx: missing (this preset has no {key}; train one with campro train-enhancer{})",
            params_path.display(),
            if which == Network::Restorer { " and data.faces = \"restore\"" } else { "" }
        )
    })?;
    Ok(campro_eval::enhance::Enhancer::load(&beside(params_path, &format!("provenance.{key}.onnx"), &file)?)?)
}

/// The file a preset's provenance names (`field`): a bare file name beside the preset,
/// never a path taken from the file's contents (no folder, no `..`, no absolute path).
pub(crate) fn beside(params_path: &Path, field: &str, file: &str) -> Result<std::path::PathBuf> {
    let name = Path::new(file);
    if name.components().count() != 1 || !matches!(name.components().next(), Some(std::path::Component::Normal(_))) {
        bail!(
            "{}: {field}: must be a file name beside the preset, got {:?}",
            crate::shown(params_path),
            crate::short(file, 120)
        );
    }
    let dir = params_path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    Ok(dir.join(name))
}
