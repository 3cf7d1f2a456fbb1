//! The tool as a library, for front ends other than the command line (the Python wheel,
//! `crates/campro-py`): the same parameter sets, camera, readers and writers as `campro
//! simulate`, as functions on plain data, so that a Python loop over a photo library writes
//! what `simulate` writes. Nothing here prints; every error is the command's one line.

use crate::capture::{Capture, GreyPolicy};
use crate::simulate::{ImageFormat, Samples};
use anyhow::{anyhow, bail, Result};
use campro::pipeline::fast::Exact8;
use campro::pipeline::{Depth, Prepared};
use campro::Params;
use campro_eval::guard::GuardedEnhancer;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

pub use crate::capture::{Frame, Pixels};
pub use crate::metadata::Policy;
pub use crate::simulate::ImageFormat as Format;
pub use campro::pipeline::Depth as BitDepth;

pub use crate::presets::{infos as presets, PresetInfo};

/// Where a camera's parameter set came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Source {
    /// A bundled preset's name, or a parameter file's path: as the commands take them.
    Path(PathBuf),
    /// Parameter-file JSON given as text: no file lies beside it, so no enhancer.
    Json(String),
}

/// The tables of the camera, built once from its parameter set.
struct Tables<'p> {
    fast8: Exact8<'p>,
    p8: Prepared<'p>,
    /// The 16-bit degamma table (65,536 powers) is built on the first 16-bit frame.
    p16: OnceLock<Prepared<'p>>,
}

self_cell::self_cell!(
    /// A parameter set and the tables built from it.
    struct Built {
        owner: Params,
        #[not_covariant]
        dependent: Tables,
    }
);

/// A camera with one parameter set: what `simulate` does to a photo, on pixels in memory.
/// Shared between threads: every call takes `&self`.
pub struct Camera {
    source: Source,
    /// SHA-256 of the parameter file's bytes (a bundled preset's built-in JSON, JSON text's
    /// UTF-8): what records name it by.
    preset_sha256: String,
    built: Built,
    grey: GreyPolicy,
    /// The guarded enhancer, loaded on the first [`Camera::enhance`] (or its error).
    enhancer: OnceLock<std::result::Result<GuardedEnhancer, String>>,
    /// SHA-256 of the enhancer's file, for records: read and hashed once, not per photo.
    enhancer_sha256: OnceLock<std::result::Result<String, String>>,
}

impl Camera {
    /// The camera of `spec`: parameter-file JSON (text starting with `{`), a bundled
    /// preset's name, or a parameter file's path. `allow_grey`: grey pictures are captured
    /// (not protected, as `simulate --allow-grey`) instead of refused.
    pub fn new(spec: &str, allow_grey: bool) -> Result<Self> {
        let (source, params, bytes) = if spec.trim_start().starts_with('{') {
            if spec.len() > campro::params::MAX_JSON_BYTES {
                bail!("the parameter JSON is {} bytes; at most {}", spec.len(), campro::params::MAX_JSON_BYTES);
            }
            let p = Params::from_json(spec).map_err(|e| anyhow!("the parameter JSON: {e}"))?;
            (Source::Json(spec.to_string()), p, spec.as_bytes().to_vec())
        } else {
            let path = PathBuf::from(spec);
            let p = crate::load_params(&path)?;
            let bytes = crate::record::preset_bytes(&path)?;
            (Source::Path(path), p, bytes)
        };
        let preset_sha256 = crate::record::sha256(&bytes);
        // As `simulate`: a mostly colourless photo's faces are looked at with the face
        // detectors of the commands' models folder.
        let grey = GreyPolicy::new(&params, allow_grey).with_faces(&models_folder(None));
        let built = Built::new(params, |p| Tables {
            fast8: Exact8::new(p),
            p8: Prepared::new(p, Depth::Eight),
            p16: OnceLock::new(),
        });
        Ok(Self { source, preset_sha256, built, grey, enhancer: OnceLock::new(), enhancer_sha256: OnceLock::new() })
    }

    /// Where the parameter set came from.
    pub fn source(&self) -> &Source {
        &self.source
    }

    /// SHA-256 of the parameter file's bytes, as records name it.
    pub fn preset_sha256(&self) -> &str {
        &self.preset_sha256
    }

    /// The parameter set.
    pub fn params(&self) -> &Params {
        self.built.borrow_owner()
    }

    /// Whether grey pictures are let through.
    pub fn allows_grey(&self) -> bool {
        self.grey.allow
    }

    /// The `w` x `h` RGB frame `src` through the camera at output `depth`, bit for bit what
    /// `simulate --bit-depth` writes for a photo with these pixels. Also whether it was a
    /// grey picture let through; a grey one is refused unless allowed. The rows run on the
    /// calling thread's rayon pool (every core).
    pub fn capture(&self, src: Frame, w: u32, h: u32, depth: Depth) -> Result<(Pixels, bool)> {
        let len = match src {
            Frame::Eight(s) => s.len(),
            Frame::Sixteen(s) => s.len(),
        };
        whole(w, h, &[len])?;
        self.with_capture(None, |capture| capture.picture(src, w, h, depth, &|_| {}))
    }

    /// [`Camera::capture`] of an 8-bit frame at 8 bits, written into `dst` (as long as
    /// `src`): the same exact path, no allocation. A grey picture is refused unless allowed.
    pub fn capture_into(&self, src: &[u8], dst: &mut [u8], w: u32, h: u32) -> Result<()> {
        whole(w, h, &[src.len(), dst.len()])?;
        self.with_capture(None, |capture| capture.run(src, dst, w, h)).map(drop)
    }

    /// `f` on the camera's [`Capture`] (with `enhancer`, if any).
    fn with_capture<R>(&self, enhancer: Option<&GuardedEnhancer>, f: impl FnOnce(&Capture<'_, '_>) -> R) -> R {
        self.built
            .with_dependent(|_, t| f(&Capture { fast8: &t.fast8, p8: &t.p8, p16: &t.p16, enhancer, grey: &self.grey }))
    }

    /// The photo `bytes` (the file `input`) through the camera into the file `output`, as
    /// `simulate` writes it: decoded, turned upright and refused when grey as `simulate`
    /// does, encoded in `output`'s format with `job`'s metadata policy and quality,
    /// atomically; with `job.record` its record beside it (`NAME.EXT.campro.json`), the
    /// input described by `bytes`. Ok(true) when it was grey and let through.
    ///
    /// An existing `output` is replaced only with `job.force`; without it, an output that
    /// holds exactly the bytes this call makes is kept and only its record written (a run
    /// stopped between an output and its record resumes), anything else is refused.
    pub fn protect(&self, input: &Path, bytes: &[u8], output: &Path, job: &Job) -> Result<bool> {
        let enhancer = if job.enhance { Some(self.guarded(job.models.as_deref())?) } else { None };
        let (file, grey) = self.with_capture(enhancer, |capture| {
            let paths = crate::simulate::Paths {
                capture,
                budget: campro_eval::image_file::Budget::global(),
                depth: job.depth,
                force: job.force,
                quality: job.quality,
                metadata: job.metadata,
            };
            paths.encoded(input, bytes, output, &|_| {})
        })?;
        let ours = !job.force
            && output.is_file()
            && campro::file::read_capped(output, campro_eval::image_file::MAX_FILE_BYTES, "an output")
                .is_ok_and(|there| there == file);
        if !ours {
            crate::write_atomic(output, &file, job.force)?;
        }
        if job.record {
            let jpeg = (Format::of(output) == Some(Format::Jpeg)).then_some(job.quality);
            self.run_record(job)?.write_for(
                crate::record::bytes_record(input, bytes),
                output,
                jpeg,
                job.force || ours,
            )?;
        }
        Ok(grey)
    }

    /// What every record of `job` shares.
    fn run_record(&self, job: &Job) -> Result<crate::record::RunRecord> {
        let enhancer = if job.enhance { Some(self.enhancer_sha256()?) } else { None };
        let given = match &self.source {
            Source::Path(path) => path.display().to_string(),
            Source::Json(_) => "JSON text".to_string(),
        };
        crate::record::RunRecord::new(
            given,
            self.params(),
            self.preset_sha256.clone(),
            enhancer,
            job.depth,
            job.metadata,
        )
    }

    /// SHA-256 of the enhancer's file (hashed on first use).
    fn enhancer_sha256(&self) -> Result<String> {
        let sha = self.enhancer_sha256.get_or_init(|| {
            let Source::Path(path) = &self.source else {
                return Err("enhance: a parameter set given as JSON text has no enhancer".to_string());
            };
            crate::record::enhancer_bytes(path, self.params())
                .map(|b| crate::record::sha256(&b))
                .map_err(|e| crate::one_line(&e))
        });
        sha.clone().map_err(|line| anyhow!("{line}"))
    }

    /// Whether `output` already is the protected output of the input `bytes` made by this
    /// camera: its record beside it reads, names this preset (its SHA-256), the input's bytes
    /// and the output file as it is now. What a rerun skips.
    pub fn verified(&self, bytes: &[u8], output: &Path) -> bool {
        let Ok(r) = crate::record::read(&crate::record::path_of(output)) else { return false };
        let Some(input) = &r.input else { return false };
        if r.preset.sha256 != self.preset_sha256 || input.sha256 != crate::record::sha256(bytes) {
            return false;
        }
        crate::record::sha256_file(output).is_ok_and(|(sha, n)| sha == r.output.sha256 && n == r.output.bytes)
    }

    /// The preset's enhancer behind the face guard (models from `models`, else the folder
    /// the commands use) on a captured 8-bit `w` x `h` RGB frame: what `simulate --enhance`
    /// shows a person. The enhancer and the guard's detector load on the first call.
    pub fn enhance(&self, captured: Vec<u8>, w: u32, h: u32, models: Option<&Path>) -> Result<Vec<u8>> {
        let e = self.guarded(models)?;
        let img = image::RgbImage::from_raw(w, h, captured)
            .ok_or_else(|| anyhow!("a {w} x {h} RGB frame holds {} samples", 3 * w as usize * h as usize))?;
        Ok(crate::capture::enhance(e, &img)?.into_raw())
    }

    /// The guarded enhancer, loaded on first use (its error kept).
    fn guarded(&self, models: Option<&Path>) -> Result<&GuardedEnhancer> {
        let e = self.enhancer.get_or_init(|| self.load_enhancer(models).map_err(|e| crate::one_line(&e)));
        e.as_ref().map_err(|line| anyhow!("{line}"))
    }

    fn load_enhancer(&self, models: Option<&Path>) -> Result<GuardedEnhancer> {
        let Source::Path(path) = &self.source else {
            bail!("enhance: a parameter set given as JSON text names no enhancer file beside it; give its path or a preset's name")
        };
        let models = models_folder(models);
        let scale = crate::args::EnhanceArgs {
            enhance_scale: campro_eval::enhance::Scale::Auto,
            faces: crate::args::FacesArg::Pixelate,
        };
        crate::capture::enhancer_of(path, self.params(), scale, &models)
    }

    /// The Camera2 values (`campro convert PRESET --target camera2 --format json`) for a
    /// phone whose auto-mode `CaptureResult` is `capture_result` (JSON text, as docs/commands.md
    /// saves it), or for an identity device without one.
    pub fn camera2(&self, capture_result: Option<&str>) -> Result<String> {
        use campro::targets::camera2;
        let p = self.params();
        let (m, gains) = match capture_result {
            Some(text) => (
                camera2::device_transform_from_capture_result(text).map_err(|e| anyhow!("capture_result: {e}"))?,
                camera2::gains_from_capture_result(text).map_err(|e| anyhow!("capture_result: {e}"))?,
            ),
            None => (campro::ccm::IDENTITY, None),
        };
        if campro::ccm::inverse(&m).is_none() {
            bail!("capture_result: the device transform is singular: no camera applies it");
        }
        let v = camera2::convert(p, &m, &Default::default()).map_err(|e| anyhow!("{e}"))?;
        Ok(serde_json::to_string(&crate::convert::camera2_json(&v, gains))?)
    }
}

/// Refuses buffers (of `lens` samples) that are not one whole `w` x `h` RGB frame each.
fn whole(w: u32, h: u32, lens: &[usize]) -> Result<()> {
    let n = 3 * w as usize * h as usize;
    if w == 0 || h == 0 || lens.iter().any(|&l| l != n) {
        bail!("a {w} x {h} RGB frame holds {n} samples, got {lens:?}");
    }
    Ok(())
}

/// How [`Camera::protect`] writes: `simulate`'s flags.
#[derive(Debug, Clone)]
pub struct Job {
    /// `--bit-depth`.
    pub depth: Depth,
    /// `--quality` (JPEG outputs), 1..=100.
    pub quality: u8,
    /// `--metadata`.
    pub metadata: Policy,
    /// `--enhance`, its face guard's models from `models` (else the commands' folder).
    pub enhance: bool,
    pub models: Option<PathBuf>,
    /// `--record`.
    pub record: bool,
    /// `--force`: replace an existing output (and record).
    pub force: bool,
}

/// The models folder: `given`, else the commands' default (`$CAMPRO_SHARED`'s, the data
/// folder `campro models fetch` fills, or `../shared/models`).
fn models_folder(given: Option<&Path>) -> PathBuf {
    crate::models::folder(given, crate::args::named_shared_dir(None).as_deref())
}

/// Where `simulate` writes the input at `input` (a path relative to the input folder, or
/// a file name): its format kept, or `format`; HEIC becomes JPEG; 16 bits become PNG.
pub fn output_name(input: &Path, depth: Depth, format: Option<Format>) -> PathBuf {
    crate::simulate::output_for(input, depth, format)
}

/// A photo as read: upright (its EXIF orientation applied), RGB, 8 or 16 bits a sample.
pub struct Photo {
    pub width: u32,
    pub height: u32,
    pub pixels: Pixels,
}

/// Reads the photo at `path` (PNG, JPEG, TIFF, WebP, HEIC) as `simulate` does: a regular
/// file within the tool's size cap, decoded within its memory budget, turned upright.
pub fn read(path: &Path) -> Result<Photo> {
    let (img, _lease) = campro_eval::image_file::read(
        path,
        campro_eval::image_file::Budget::global(),
        &campro_eval::image_file::no_work,
        &|_| {},
    )?;
    let (width, height) = (img.width(), img.height());
    let sixteen = crate::capture::sixteen_bit(&img);
    let pixels =
        if sixteen { Pixels::Sixteen(img.into_rgb16().into_raw()) } else { Pixels::Eight(img.into_rgb8().into_raw()) };
    Ok(Photo { width, height, pixels })
}

/// What [`write`] does besides the pixels.
pub struct Write<'a> {
    /// The photo whose metadata the output keeps under `metadata` (none without it).
    pub like: Option<&'a Path>,
    pub metadata: Policy,
    /// JPEG quality, 1..=100.
    pub quality: u8,
    /// Replace an existing file.
    pub force: bool,
}

/// Writes `pixels` (`w` x `h` RGB) to `path` in the format its extension names (PNG, JPEG,
/// TIFF, WebP; 16 bits to PNG and TIFF only), atomically, with what `simulate` keeps of
/// `like`'s metadata: the bytes `simulate` writes for the same pixels and input.
pub fn write(path: &Path, pixels: &Pixels, w: u32, h: u32, o: &Write) -> Result<()> {
    let format = ImageFormat::of(path).ok_or_else(|| {
        anyhow!("{}: the extension names no format written (.png, .jpg, .jpeg, .tif, .tiff, .webp)", crate::shown(path))
    })?;
    if !(1..=100).contains(&o.quality) {
        bail!("quality must be 1..=100, got {}", o.quality);
    }
    let samples = pixels.samples();
    whole(
        w,
        h,
        &[match &samples {
            Samples::Eight(s) => s.len(),
            Samples::Sixteen(s) => s.len(),
        }],
    )?;
    if matches!(samples, Samples::Sixteen(_)) && matches!(format, ImageFormat::Jpeg | ImageFormat::Webp) {
        bail!("{}: 16-bit samples are written to PNG or TIFF only", crate::shown(path));
    }
    if let Some(like) = o.like {
        crate::not_an_input("the output", path, &[like])?;
    }
    let kept = match o.like {
        Some(like) if o.metadata != Policy::Strip => {
            let (_img, _lease, meta) = campro_eval::image_file::read_with_metadata(
                like,
                campro_eval::image_file::Budget::global(),
                &campro_eval::image_file::no_work,
                &|_| {},
            )?;
            crate::metadata::kept(o.metadata, meta.exif.as_deref(), meta.icc, &|_| {})
        }
        _ => Default::default(),
    };
    let bytes = crate::simulate::encode(format, samples, w, h, o.quality, &kept)?;
    crate::write_atomic(path, &bytes, o.force)
}

/// An error as the command prints it: one line, its causes joined, escaped and cut.
pub fn error_line(e: &anyhow::Error) -> String {
    crate::one_line(e)
}

/// Whether `e` is the refusal of a grey picture (not a failure: the picture is fine, the
/// preset does not protect it).
pub fn is_grey_refusal(e: &anyhow::Error) -> bool {
    e.downcast_ref::<crate::capture::GreyRefused>().is_some()
}
