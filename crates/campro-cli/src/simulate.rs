//! `campro simulate`: the desktop pipeline on image files and folders, into PNGs.
//!
//! Hostile input is normal input here: inputs are regular files read with a byte cap;
//! links, FIFOs and devices inside folders are skipped with a warning; an output folder
//! inside an input folder is never read back; an output that would replace an input is
//! refused; every decode draws its memory from one budget shared by all jobs, so a
//! decompression bomb is refused by its header and several large images wait for each
//! other instead of adding up.

use crate::capture::Capture;
use crate::video::{self, Encoding};
use crate::write_atomic;
use anyhow::{anyhow, bail, Result};
use campro::pipeline::fast::Exact8;
use campro::pipeline::{Depth, Prepared};
use campro::Params;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};

/// The file endings read as images.
const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "tif", "tiff"];
/// Largest image file read (bytes).
const MAX_FILE_BYTES: u64 = 256 << 20;
/// Memory all decoding jobs together may hold (bytes): each job reserves its image's
/// decoded size times [`BYTES_PER_SAMPLE_PEAK`] before decoding.
pub const DECODE_BUDGET: u64 = 768 << 20;
/// Peak bytes a job holds per decoded byte of its image, counted by buffer: the decoded
/// image, the RGB input and output buffers and the PNG being written, each at most the
/// decoded size.
const BYTES_PER_SAMPLE_PEAK: u64 = 4;

/// A counting semaphore of bytes.
pub(crate) struct Budget {
    free: Mutex<u64>,
    freed: Condvar,
}

impl Budget {
    pub(crate) fn new(bytes: u64) -> Self {
        Self { free: Mutex::new(bytes), freed: Condvar::new() }
    }

    /// Waits until `n` bytes are free and takes them (`n` at most the whole budget).
    fn take(&self, n: u64) -> Lease<'_> {
        let mut free = self.free.lock().unwrap_or_else(|p| p.into_inner());
        while *free < n {
            free = self.freed.wait(free).unwrap_or_else(|p| p.into_inner());
        }
        *free -= n;
        Lease { budget: self, n }
    }
}

/// Bytes taken from a [`Budget`], given back on drop.
pub(crate) struct Lease<'a> {
    budget: &'a Budget,
    n: u64,
}

impl Drop for Lease<'_> {
    fn drop(&mut self) {
        *self.budget.free.lock().unwrap_or_else(|p| p.into_inner()) += self.n;
        self.budget.freed.notify_all();
    }
}

/// What a walk over the inputs found.
pub(crate) struct Inputs {
    /// (input file, output file).
    pub jobs: Vec<(PathBuf, PathBuf)>,
    /// Entries passed over, with why.
    pub skipped: Vec<(PathBuf, &'static str)>,
}

/// A path made absolute and, where it exists, with links resolved (for comparing).
fn resolved(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).or_else(|_| std::path::absolute(p)).unwrap_or_else(|_| p.to_path_buf())
}

/// Every (input file, output file) pair: folders are walked recursively and mirrored.
pub(crate) fn collect_inputs(inputs: &[PathBuf], out: &Path) -> Result<Inputs> {
    let out_abs = resolved(out);
    let mut found = Inputs { jobs: Vec::new(), skipped: Vec::new() };
    for input in inputs {
        let meta = std::fs::metadata(input).map_err(|e| anyhow!("{}: {e}", input.display()))?;
        if meta.is_dir() {
            if resolved(input) == out_abs {
                bail!("--output {}: is the input folder itself; outputs would replace inputs", out.display());
            }
            // Never descend into the output folder: what this run writes is not an input.
            let walk = walkdir::WalkDir::new(input).sort_by_file_name().into_iter();
            for entry in walk.filter_entry(|e| !(e.file_type().is_dir() && resolved(e.path()) == out_abs)) {
                let entry = entry?;
                let t = entry.file_type();
                if t.is_dir() {
                    continue;
                }
                if t.is_symlink() {
                    found
                        .skipped
                        .push((entry.path().to_path_buf(), "a symbolic link (links inside folders are not followed)"));
                    continue;
                }
                if !t.is_file() {
                    found.skipped.push((entry.path().to_path_buf(), "not a regular file"));
                    continue;
                }
                let rel = entry.path().strip_prefix(input).expect("walkdir yields paths under its root");
                found.jobs.push((entry.path().to_path_buf(), output_for(&out.join(rel))));
            }
        } else if meta.is_file() {
            let name = input.file_name().ok_or_else(|| anyhow!("{}: not a file name", input.display()))?;
            found.jobs.push((input.clone(), output_for(&out.join(Path::new(name)))));
        } else {
            bail!("{}: is not a regular file or folder", input.display());
        }
    }
    let mut seen = std::collections::HashSet::new();
    let sources: std::collections::HashSet<PathBuf> = found.jobs.iter().map(|(i, _)| resolved(i)).collect();
    for (i, o) in &found.jobs {
        if !seen.insert(o.clone()) {
            bail!("two inputs would both be written to {} (the second is {})", o.display(), i.display());
        }
        if sources.contains(&resolved(o)) {
            bail!("--output: writing {} would replace an input; choose another output folder", o.display());
        }
    }
    Ok(found)
}

/// Where an input goes: images become PNGs, videos keep their container.
fn output_for(path: &Path) -> PathBuf {
    if video::is_video(path) {
        path.to_path_buf()
    } else {
        path.with_extension("png")
    }
}

pub(crate) fn is_image(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        .unwrap_or(false)
}

/// Runs `p` over every image and video under `inputs` into PNGs and videos under `out`.
pub fn simulate(
    p: &Params,
    inputs: &[PathBuf],
    out: &Path,
    depth: Depth,
    force: bool,
    jobs: Option<usize>,
    enc: &Encoding,
    enhancer: Option<&campro_eval::enhance::Enhancer>,
) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = match jobs {
        Some(j) if j > cores => {
            eprintln!("warning: --jobs {j} is more than the {cores} cores; using {cores}");
            cores
        }
        Some(j) => j,
        None => cores,
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let found = collect_inputs(inputs, out)?;
    for (i, why) in &found.skipped {
        eprintln!("warning: skipping {}: {why}", crate::escape(&i.display().to_string()));
    }
    let (videos, rest): (Vec<_>, Vec<_>) = found.jobs.into_iter().partition(|(i, _)| video::is_video(i));
    let (images, others): (Vec<_>, Vec<_>) = rest.into_iter().partition(|(i, _)| is_image(i));
    for (i, _) in &others {
        eprintln!(
            "warning: skipping {} (not a PNG, JPEG, TIFF or video file)",
            crate::escape(&i.display().to_string())
        );
    }
    if images.is_empty() && videos.is_empty() {
        bail!("no PNG, JPEG, TIFF or video file among the inputs: nothing to do");
    }
    let bar = if images.len() > 4 {
        indicatif::ProgressBar::new(images.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {elapsed_precise} eta {eta}")
            .expect("valid template"),
    );
    // The 16-bit degamma table (65536 powers) is built only if a 16-bit image turns up.
    let prepared8 = Prepared::new(p, Depth::Eight);
    let fast8 = Exact8::new(p);
    let prepared16 = std::sync::OnceLock::new();
    let budget = Budget::new(DECODE_BUDGET);
    let failed = AtomicUsize::new(0);
    let capture = Capture { fast8: &fast8, enhancer };
    let paths = Paths { capture: &capture, p8: &prepared8, p16: &prepared16, budget: &budget, depth, force };
    pool.install(|| {
        images.par_iter().for_each(|(i, o)| {
            let r = if !force && o.exists() {
                Err(anyhow!("{} exists (use --force to overwrite)", o.display()))
            } else {
                paths.one(i, o, &|w| bar.suspend(|| eprintln!("warning: {}: {w}", i.display())))
            };
            if let Err(e) = r {
                bar.suspend(|| eprintln!("error: {}: {}", i.display(), crate::one_line(&e)));
                failed.fetch_add(1, Ordering::Relaxed);
            }
            bar.inc(1);
        })
    });
    bar.finish_and_clear();
    let mut failed = failed.into_inner();
    if !images.is_empty() {
        eprintln!("simulated {} of {} images into {}", images.len() - failed, images.len(), out.display());
    }
    // Videos one after another, each frame on every core.
    for (i, wanted) in &videos {
        let o = enc.output_path(wanted);
        if &o != wanted {
            eprintln!("note: {} is written as {} ({} needs Matroska)", wanted.display(), o.display(), enc.codec);
        }
        let warn = |w: &str| eprintln!("warning: {}: {w}", i.display());
        let r = if !force && o.exists() {
            Err(anyhow!("{} exists (use --force to overwrite)", o.display()))
        } else {
            pool.install(|| video::simulate(&capture, i, &o, enc, force, &warn))
        };
        match r {
            Ok(n) => eprintln!("simulated {n} frames of {} into {}", i.display(), o.display()),
            Err(e) => {
                eprintln!("error: {}: {}", i.display(), crate::one_line(&e));
                failed += 1;
            }
        }
    }
    if failed > 0 {
        bail!("{failed} input(s) failed");
    }
    Ok(())
}

/// What every job shares.
struct Paths<'a, 'p> {
    capture: &'a Capture<'a, 'p>,
    p8: &'a Prepared<'p>,
    p16: &'a std::sync::OnceLock<Prepared<'p>>,
    budget: &'a Budget,
    depth: Depth,
    force: bool,
}

impl Paths<'_, '_> {
    fn one(&self, input: &Path, output: &Path, warn: &dyn Fn(&str)) -> Result<()> {
        let (img, _lease) = decode(input, self.budget, warn)?;
        let (w, h) = (img.width(), img.height());
        let sixteen = matches!(img.color().bytes_per_pixel() / img.color().channel_count(), 2 | 4);
        let row = 3 * w as usize;
        if self.capture.enhancer.is_some() || (!sixteen && self.depth == Depth::Eight) {
            // 8 bits in and out: the exact path (AVX-512 blocks where the CPU has them),
            // bit-identical to the reference; the enhancer reads what an 8-bit camera gives.
            if sixteen {
                warn("--enhance: read as 8 bits (the enhancer takes the camera's 8-bit output)");
            }
            let src = img.into_rgb8().into_raw();
            let mut dst = vec![0u8; src.len()];
            self.capture.run(&src, &mut dst, w, h)?;
            drop(src);
            return write_atomic(output, &encode_png8(&dst, w, h)?, self.force);
        }
        let (src, prep): (Vec<u16>, &Prepared) = if sixteen {
            (img.into_rgb16().into_raw(), self.p16.get_or_init(|| Prepared::new(self.p8.params(), Depth::Sixteen)))
        } else {
            (img.into_rgb8().into_raw().into_iter().map(u16::from).collect(), self.p8)
        };
        let mut dst = vec![0u16; src.len()];
        src.par_chunks(row * 16).zip(dst.par_chunks_mut(row * 16)).for_each(|(s, d)| prep.run(s, d, self.depth));
        drop(src);
        let png = encode_png(&dst, w, h, self.depth)?;
        write_atomic(output, &png, self.force)
    }
}

/// Reads and decodes one image file: capped read, a warning for extra frames and alpha,
/// and the decoded size (times [`BYTES_PER_SAMPLE_PEAK`]) taken from `budget` before
/// decoding, held until the returned lease drops. A decompression bomb is refused by its
/// header.
pub(crate) fn decode<'b>(
    input: &Path,
    budget: &'b Budget,
    warn: &dyn Fn(&str),
) -> Result<(image::DynamicImage, Lease<'b>)> {
    use image::ImageDecoder;
    let bytes = campro::file::read_capped(input, MAX_FILE_BYTES, "an image")?;
    if let Some(n) = extra_frames(&bytes) {
        warn(&format!("{n}; only the first is simulated"));
    }
    let mut decoder = image::ImageReader::new(std::io::Cursor::new(&bytes)).with_guessed_format()?.into_decoder()?;
    let (w, h) = decoder.dimensions();
    let need = decoder.total_bytes().saturating_mul(BYTES_PER_SAMPLE_PEAK).max(1);
    if need > DECODE_BUDGET {
        bail!(
            "the image is {w} x {h} ({} decoded bytes); the limit is {} (a decompression bomb, or split it)",
            decoder.total_bytes(),
            DECODE_BUDGET / BYTES_PER_SAMPLE_PEAK
        );
    }
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(need);
    decoder.set_limits(limits)?;
    if decoder.color_type().has_alpha() {
        warn("its alpha channel is dropped (the output is RGB)");
    }
    let lease = budget.take(need);
    Ok((image::DynamicImage::from_decoder(decoder)?, lease))
}

/// Says how many frames or pages past the first a PNG (APNG) or TIFF holds, if any.
fn extra_frames(bytes: &[u8]) -> Option<String> {
    if let Some(chunks) = bytes.strip_prefix(b"\x89PNG\r\n\x1a\n") {
        // acTL (before the image data) says how many frames an animated PNG has.
        let mut at = 0usize;
        while let Some(head) = chunks.get(at..at + 8) {
            let len = u32::from_be_bytes(head[..4].try_into().expect("4 bytes")) as usize;
            match &head[4..8] {
                b"acTL" => {
                    let n = chunks.get(at + 8..at + 12).map(|b| u32::from_be_bytes(b.try_into().expect("4 bytes")))?;
                    return (n > 1).then(|| format!("an animated PNG of {n} frames"));
                }
                b"IDAT" | b"IEND" => return None,
                _ => at = at.checked_add(12)?.checked_add(len)?,
            }
        }
        return None;
    }
    // TIFF: a first IFD that links to a next one holds more than one page.
    let le = match bytes.get(..4)? {
        b"II*\0" => true,
        b"MM\0*" => false,
        _ => return None,
    };
    let u32_at = |i: usize| -> Option<usize> {
        let b: [u8; 4] = bytes.get(i..i + 4)?.try_into().ok()?;
        Some(if le { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) } as usize)
    };
    let ifd = u32_at(4)?;
    let b: [u8; 2] = bytes.get(ifd..ifd + 2)?.try_into().ok()?;
    let n = if le { u16::from_le_bytes(b) } else { u16::from_be_bytes(b) } as usize;
    let next = u32_at(ifd + 2 + 12 * n)?;
    (next != 0).then(|| "a TIFF of several pages".to_string())
}

/// 8-bit RGB samples as a PNG.
fn encode_png8(samples: &[u8], w: u32, h: u32) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut buf = Vec::new();
    image::codecs::png::PngEncoder::new(&mut buf).write_image(samples, w, h, image::ExtendedColorType::Rgb8)?;
    Ok(buf)
}

/// RGB samples (codes of `depth`) as a PNG of that depth.
pub fn encode_png(samples: &[u16], w: u32, h: u32, depth: Depth) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    match depth {
        Depth::Eight => encode_png8(&samples.iter().map(|&v| v as u8).collect::<Vec<u8>>(), w, h),
        Depth::Sixteen => {
            let mut buf = Vec::new();
            let bytes: Vec<u8> = samples.iter().flat_map(|v| v.to_ne_bytes()).collect();
            image::codecs::png::PngEncoder::new(&mut buf).write_image(&bytes, w, h, image::ExtendedColorType::Rgb16)?;
            Ok(buf)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extra_frames_by_hand() {
        // A PNG whose acTL says 3 frames, then one that says 1.
        let png = |n: u32| {
            let mut b = b"\x89PNG\r\n\x1a\n".to_vec();
            b.extend(13u32.to_be_bytes());
            b.extend(b"IHDR");
            b.extend([0u8; 13 + 4]);
            b.extend(8u32.to_be_bytes());
            b.extend(b"acTL");
            b.extend(n.to_be_bytes());
            b.extend([0u8; 4 + 4]);
            b
        };
        assert_eq!(extra_frames(&png(3)).as_deref(), Some("an animated PNG of 3 frames"));
        assert_eq!(extra_frames(&png(1)), None);
        // Little-endian TIFF: IFD at 8 with 0 entries, next IFD at 14 (a second page).
        let mut tiff = b"II*\0".to_vec();
        tiff.extend(8u32.to_le_bytes());
        tiff.extend(0u16.to_le_bytes());
        tiff.extend(14u32.to_le_bytes());
        assert_eq!(extra_frames(&tiff).as_deref(), Some("a TIFF of several pages"));
        tiff[10..14].copy_from_slice(&0u32.to_le_bytes());
        assert_eq!(extra_frames(&tiff), None);
        assert_eq!(extra_frames(b"\xff\xd8\xff"), None);
    }

    #[test]
    fn the_budget_is_shared_and_given_back() {
        let b = Budget::new(10);
        let a = b.take(6);
        assert_eq!(*b.free.lock().unwrap(), 4);
        drop(a);
        let _c = b.take(10);
        assert_eq!(*b.free.lock().unwrap(), 0);
    }
}
