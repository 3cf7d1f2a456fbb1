//! Reading image files, the one way every command reads them: a regular file only, a byte
//! cap enforced while reading ([`campro::file::read_capped`]), headers parsed under a small
//! allocation cap (an inflated ICC profile or text chunk cannot grow past it), and the
//! pixels decoded only after their peak memory has been taken from the process's one
//! [`Budget`]. A decompression bomb is refused by its header, several large images wait
//! for each other instead of adding up, and a grey or 16-bit image is counted by what it
//! becomes (RGB, 16 bits a sample in the pipeline), not by its smaller file form.

use crate::error::{EvalError, Result};
use std::path::Path;
use std::sync::{Condvar, Mutex, OnceLock};

/// Largest image file read, bytes.
pub const MAX_FILE_BYTES: u64 = 256 << 20;
/// Memory all decoding jobs of the process together may hold by default, bytes;
/// [`MEMORY_ENV`] sets another.
pub const DECODE_BUDGET: u64 = 768 << 20;
/// The environment variable that sets the process's budget, in MiB (64..=1048576).
pub const MEMORY_ENV: &str = "CAMPRO_MEMORY_MIB";

/// The budget [`MEMORY_ENV`] asks for, bytes ([`DECODE_BUDGET`] when it is not set), or the
/// one line saying what is wrong with it. Commands check it once at start.
pub fn budget_from_env() -> std::result::Result<u64, String> {
    match std::env::var(MEMORY_ENV) {
        Err(std::env::VarError::NotPresent) => Ok(DECODE_BUDGET),
        Err(_) => Err(format!("{MEMORY_ENV}: must be a whole number of MiB in 64..=1048576")),
        Ok(v) => match v.trim().parse::<u64>() {
            Ok(n @ 64..=1_048_576) => Ok(n << 20),
            _ => Err(format!("{MEMORY_ENV}: must be a whole number of MiB in 64..=1048576, got {v:?}")),
        },
    }
}
/// What a header (ICC profile, text chunks, EXIF) may allocate before any pixel, bytes.
pub const HEADER_ALLOC: u64 = 16 << 20;
/// Peak bytes a job holds per pixel besides the decoded image: the RGB input and output
/// buffers of the pipeline (16 bits a sample: 6 bytes each) and the PNG being written (6).
pub const PEAK_BYTES_PER_PIXEL: u64 = 18;
/// [`PEAK_BYTES_PER_PIXEL`] of an 8-bit image: an RGB output buffer (3 bytes: `simulate`
/// captures in place, so its input is the decoded image, and with `--enhance` the enhanced
/// image is this buffer) and the file being written (at most 3). An 8160 x 6120 JPEG (50
/// megapixels) peaked at 176 MB through `simulate`, 3.5 bytes a pixel with its decoded
/// image. A caller that widens an 8-bit image to 16 bits, or holds more copies, adds the
/// difference to its own work.
pub const PEAK_BYTES_PER_PIXEL_8: u64 = 6;

/// A counting semaphore of bytes.
pub struct Budget {
    total: u64,
    free: Mutex<u64>,
    freed: Condvar,
}

impl Budget {
    /// A budget of `bytes`.
    pub fn new(bytes: u64) -> Self {
        Self { total: bytes, free: Mutex::new(bytes), freed: Condvar::new() }
    }

    /// The process's budget ([`budget_from_env`], else [`DECODE_BUDGET`]): every image
    /// read draws from it.
    pub fn global() -> &'static Budget {
        static B: OnceLock<Budget> = OnceLock::new();
        B.get_or_init(|| Budget::new(budget_from_env().unwrap_or(DECODE_BUDGET)))
    }

    /// The whole budget, bytes.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// Bytes free now.
    pub fn free(&self) -> u64 {
        *self.free.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Waits until `n` bytes are free and takes them; `None` when `n` exceeds the whole
    /// budget (it would wait for ever).
    pub fn take(&self, n: u64) -> Option<Lease<'_>> {
        if n > self.total {
            return None;
        }
        let mut free = self.free.lock().unwrap_or_else(|p| p.into_inner());
        while *free < n {
            free = self.freed.wait(free).unwrap_or_else(|p| p.into_inner());
        }
        *free -= n;
        Some(Lease { budget: self, n })
    }
}

/// Bytes taken from a [`Budget`], given back on drop.
pub struct Lease<'a> {
    budget: &'a Budget,
    n: u64,
}

impl Lease<'_> {
    /// Bytes held.
    pub fn bytes(&self) -> u64 {
        self.n
    }
}

impl Drop for Lease<'_> {
    fn drop(&mut self) {
        *self.budget.free.lock().unwrap_or_else(|p| p.into_inner()) += self.n;
        self.budget.freed.notify_all();
    }
}

fn image_error(path: &Path, message: impl Into<String>) -> EvalError {
    EvalError::Image { path: path.into(), message: message.into() }
}

/// Peak bytes a `w` x `h` image of `decoded` bytes holds while it is processed: the
/// pipeline's [`PEAK_BYTES_PER_PIXEL`] and the caller's own `work` bytes for an image of
/// that size (the enhancer's, [`crate::enhance::Enhancer::work_bytes`]), saturating.
pub fn peak_bytes(w: u32, h: u32, decoded: u64, work: u64) -> u64 {
    peak_bytes_at(w, h, decoded, work, PEAK_BYTES_PER_PIXEL)
}

/// [`peak_bytes`] with the pipeline's `per_pixel` bytes ([`PEAK_BYTES_PER_PIXEL`] or
/// [`PEAK_BYTES_PER_PIXEL_8`]).
pub fn peak_bytes_at(w: u32, h: u32, decoded: u64, work: u64, per_pixel: u64) -> u64 {
    (w as u64).saturating_mul(h as u64).saturating_mul(per_pixel).saturating_add(work).saturating_add(decoded).max(1)
}

/// What a caller holds for an image besides the pipeline, bytes, by its size (read from
/// the header before anything is decoded).
pub type Work<'a> = &'a (dyn Fn(u32, u32) -> u64 + Sync);

/// No work beside the pipeline.
pub fn no_work(_: u32, _: u32) -> u64 {
    0
}

/// Reads and decodes the image file at `path`, its memory (with the `work` bytes that the
/// caller will hold for it besides the pipeline) taken from `budget` and held until the
/// returned lease drops. `warn` hears what is kept from the user: frames past the first, a
/// dropped alpha channel, a truncated JPEG.
pub fn read<'b>(
    path: &Path,
    budget: &'b Budget,
    work: Work,
    warn: &dyn Fn(&str),
) -> Result<(image::DynamicImage, Lease<'b>)> {
    let bytes = campro::file::read_capped(path, MAX_FILE_BYTES, "an image")?;
    decode(path, &bytes, budget, work, warn)
}

/// The width and height the header of the image file at `path` gives (a regular file of
/// at most [`MAX_FILE_BYTES`]), nothing decoded: what a caller sizes its memory by first.
pub fn dimensions(path: &Path) -> Result<(u32, u32)> {
    let bytes = campro::file::read_capped(path, MAX_FILE_BYTES, "an image")?;
    if crate::heif::is_heif(&bytes) {
        return crate::heif::open(path, &bytes).map(|h| h.size);
    }
    header_reader(path, &bytes)?.into_dimensions().map_err(|e| image_error(path, header_message(&e)))
}

/// A reader of `bytes` by their guessed format whose header (ICC profile, text, EXIF) may
/// allocate [`HEADER_ALLOC`] at most: what is read before any pixel.
fn header_reader<'a>(path: &Path, bytes: &'a [u8]) -> Result<image::ImageReader<std::io::Cursor<&'a [u8]>>> {
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(HEADER_ALLOC);
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| image_error(path, e.to_string()))?;
    reader.limits(limits);
    Ok(reader)
}

/// What an image file says about itself besides its pixels, as read (no policy applied).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Metadata {
    /// The EXIF block, TIFF-structured (no `Exif\0\0` prefix).
    pub exif: Option<Vec<u8>>,
    /// The ICC colour profile.
    pub icc: Option<Vec<u8>>,
}

/// [`read`] that also returns the file's [`Metadata`].
pub fn read_with_metadata<'b>(
    path: &Path,
    budget: &'b Budget,
    work: Work,
    warn: &dyn Fn(&str),
) -> Result<(image::DynamicImage, Lease<'b>, Metadata)> {
    let bytes = campro::file::read_capped(path, MAX_FILE_BYTES, "an image")?;
    decode_with_metadata(path, &bytes, budget, work, warn)
}

/// [`read_with_metadata`] on bytes already read (`path` names them in errors).
pub fn decode_with_metadata<'b>(
    path: &Path,
    bytes: &[u8],
    budget: &'b Budget,
    work: Work,
    warn: &dyn Fn(&str),
) -> Result<(image::DynamicImage, Lease<'b>, Metadata)> {
    decoded(path, bytes, budget, work, warn, true)
}

/// [`read`] on bytes already read (`path` names them in errors).
pub fn decode<'b>(
    path: &Path,
    bytes: &[u8],
    budget: &'b Budget,
    work: Work,
    warn: &dyn Fn(&str),
) -> Result<(image::DynamicImage, Lease<'b>)> {
    decoded(path, bytes, budget, work, warn, false).map(|(img, lease, _)| (img, lease))
}

/// [`decode`], and the file's [`Metadata`] when `metadata` asks for it (read within the
/// header's allocation limit; a block the decoder cannot read is left out). Without it no
/// header is parsed twice (JPEG's EXIF and ICC are read by a second header pass).
fn decoded<'b>(
    path: &Path,
    bytes: &[u8],
    budget: &'b Budget,
    work: Work,
    warn: &dyn Fn(&str),
    metadata: bool,
) -> Result<(image::DynamicImage, Lease<'b>, Metadata)> {
    use image::ImageDecoder;
    if crate::heif::is_heif(bytes) {
        return heif_decoded(path, bytes, budget, work, warn, metadata);
    }
    if let Some(n) = extra_frames(bytes) {
        warn(&format!("{n}; only the first is read"));
    }
    if bytes.starts_with(b"\xff\xd8") && !jpeg_has_end(bytes) {
        warn("the JPEG is truncated (no end-of-image marker): rows past the end are filled in");
    }
    let mut decoder = header_reader(path, bytes)?.into_decoder().map_err(|e| image_error(path, header_message(&e)))?;
    let (w, h) = decoder.dimensions();
    // 8-bit samples go through the 8-bit pipeline unless the caller widens them (its work).
    let ct = decoder.color_type();
    let eight = ct.bytes_per_pixel() as u64 <= ct.channel_count() as u64;
    let per_pixel = if eight { PEAK_BYTES_PER_PIXEL_8 } else { PEAK_BYTES_PER_PIXEL };
    let need = peak_bytes_at(w, h, decoder.total_bytes(), work(w, h), per_pixel);
    if need > budget.total() {
        return Err(too_large(path, w, h, need, budget));
    }
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(need);
    decoder.set_limits(limits).map_err(|e| image_error(path, e.to_string()))?;
    if decoder.color_type().has_alpha() {
        warn("its alpha channel is dropped (the output is RGB)");
    }
    // Phones store the picture as the sensor read it and say how to turn it (EXIF
    // orientation): the pixels are turned here, so every output stands as the photo was
    // taken (and says orientation 1). The turned copy fits `need` (18 bytes a pixel against
    // 6 for two 8-bit RGB copies).
    let meta = if metadata {
        Metadata { exif: decoder.exif_metadata().ok().flatten(), icc: decoder.icc_profile().ok().flatten() }
    } else {
        Metadata::default()
    };
    let orientation = decoder.orientation().unwrap_or(image::metadata::Orientation::NoTransforms);
    let lease = budget.take(need).expect("need is within the budget");
    let mut img = image::DynamicImage::from_decoder(decoder).map_err(|e| image_error(path, e.to_string()))?;
    img.apply_orientation(orientation);
    Ok((img, lease, meta))
}

/// [`decoded`] for a HEIC/HEIF file, through the system's libheif ([`crate::heif`]): its
/// size read first and its memory taken from `budget` before anything is decoded; the
/// picture as libheif displays it (its rotation applied, so no EXIF orientation is).
fn heif_decoded<'b>(
    path: &Path,
    bytes: &[u8],
    budget: &'b Budget,
    work: Work,
    warn: &dyn Fn(&str),
    metadata: bool,
) -> Result<(image::DynamicImage, Lease<'b>, Metadata)> {
    let heif = crate::heif::open(path, bytes)?;
    let (w, h) = heif.size;
    let decoded = (w as u64 * h as u64).saturating_mul(crate::heif::DECODE_BYTES_PER_PIXEL);
    // libheif hands the picture over in 8 bits.
    let need = peak_bytes_at(w, h, decoded, work(w, h), PEAK_BYTES_PER_PIXEL_8);
    let lease = budget.take(need).ok_or_else(|| too_large(path, w, h, need, budget))?;
    if heif.has_alpha() {
        warn("its alpha channel is dropped (the output is RGB)");
    }
    let meta = if metadata { Metadata { exif: heif.exif(), icc: heif.icc() } } else { Metadata::default() };
    Ok((image::DynamicImage::ImageRgb8(heif.decode()?), lease, meta))
}

/// The refusal of an image needing `need` bytes, more than `budget` holds.
fn too_large(path: &Path, w: u32, h: u32, need: u64, budget: &Budget) -> EvalError {
    image_error(
        path,
        format!(
            "the image is {w} x {h} pixels, needing {} MiB to process; the limit is {} MiB (a decompression bomb? {MEMORY_ENV} raises the limit)",
            need >> 20,
            budget.total() >> 20
        ),
    )
}

/// A header error in words: the image crate's limit errors say "limits exceeded".
fn header_message(e: &image::ImageError) -> String {
    match e {
        image::ImageError::Limits(_) => {
            format!("its header (ICC profile, text or EXIF chunks) needs more than {} MiB", HEADER_ALLOC >> 20)
        }
        e => e.to_string(),
    }
}

/// Whether a JPEG ends with its end-of-image marker (trailing bytes some cameras append
/// after it are allowed: the marker anywhere in the last 64 KiB counts).
fn jpeg_has_end(bytes: &[u8]) -> bool {
    let tail = &bytes[bytes.len().saturating_sub(64 << 10)..];
    tail.windows(2).any(|w| w == [0xff, 0xd9])
}

/// Says how many frames or pages past the first a PNG (APNG) or TIFF holds, if any.
pub fn extra_frames(bytes: &[u8]) -> Option<String> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A PNG chunk: length, type, data, CRC.
    fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
        let mut c = (data.len() as u32).to_be_bytes().to_vec();
        c.extend(kind);
        c.extend(data);
        let mut h = crc32fast::Hasher::new();
        h.update(kind);
        h.update(data);
        c.extend(h.finalize().to_be_bytes());
        c
    }

    fn zlib(data: &[u8]) -> Vec<u8> {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        z.write_all(data).unwrap();
        z.finish().unwrap()
    }

    /// A PNG of `w` x `h` (colour type `ct`, depth `depth`) whose rows are all zero,
    /// with `extra` chunks before the data.
    fn png(w: u32, h: u32, ct: u8, depth: u8, extra: &[Vec<u8>], rows: Option<usize>) -> Vec<u8> {
        let mut ihdr = w.to_be_bytes().to_vec();
        ihdr.extend(h.to_be_bytes());
        ihdr.extend([depth, ct, 0, 0, 0]);
        let mut b = b"\x89PNG\r\n\x1a\n".to_vec();
        b.extend(chunk(b"IHDR", &ihdr));
        for e in extra {
            b.extend(e);
        }
        let channels = match ct {
            0 => 1,
            2 => 3,
            _ => 4,
        };
        let row = 1 + (w as usize * channels * depth as usize).div_ceil(8);
        let raw = vec![0u8; row * rows.unwrap_or(h as usize)];
        b.extend(chunk(b"IDAT", &zlib(&raw)));
        b.extend(chunk(b"IEND", &[]));
        b
    }

    fn no_warn(_: &str) {}

    #[test]
    fn a_small_image_is_read_and_its_memory_given_back() {
        let b = Budget::new(1 << 20);
        let bytes = png(16, 8, 2, 8, &[], None);
        let (img, lease) = decode(Path::new("t.png"), &bytes, &b, &no_work, &no_warn).unwrap();
        assert_eq!((img.width(), img.height()), (16, 8));
        // 16 x 8 pixels of 8 bits: 6 bytes each plus the 384 decoded bytes.
        assert_eq!(lease.bytes(), 16 * 8 * 6 + 384);
        assert_eq!(b.free(), (1 << 20) - lease.bytes());
        drop(lease);
        assert_eq!(b.free(), 1 << 20);
    }

    #[test]
    fn grey_and_16_bit_images_count_as_what_they_become() {
        // A 1-byte-per-pixel grey image becomes RGB8 in the 8-bit pipeline (6 bytes a pixel
        // beside its own: the RGB buffer and the file); an 8-byte RGBA16 one of the same
        // size goes through the RGB16 buffers (18).
        let b = Budget::new(64 << 20);
        let (_, grey) = decode(Path::new("g.png"), &png(100, 10, 0, 8, &[], None), &b, &no_work, &no_warn).unwrap();
        assert_eq!(grey.bytes(), 1000 * 6 + 1000);
        drop(grey);
        let warned = std::cell::RefCell::new(Vec::new());
        let w = |m: &str| warned.borrow_mut().push(m.to_string());
        let (_, deep) = decode(Path::new("d.png"), &png(100, 10, 6, 16, &[], None), &b, &no_work, &w).unwrap();
        assert_eq!(deep.bytes(), 1000 * 18 + 8000);
        assert!(warned.borrow()[0].contains("alpha"), "{:?}", warned.borrow());
    }

    #[test]
    fn a_small_file_of_a_huge_grey_image_is_refused_by_its_header() {
        // 14000 x 14000 grey: a few hundred KB compressed, 3.7 GB to process.
        let bytes = png(14000, 14000, 0, 8, &[], Some(1));
        assert!(bytes.len() < 100_000);
        let b = Budget::new(DECODE_BUDGET);
        let e = decode(Path::new("bomb.png"), &bytes, &b, &no_work, &no_warn).err().unwrap().to_string();
        assert!(e.contains("14000 x 14000") && e.contains("limit is 768 MiB"), "{e}");
        assert_eq!(b.free(), DECODE_BUDGET, "nothing taken");
        // The PNG's own limit: 2^31 - 1 on each side, refused with a plain line, no abort.
        let bytes = png(i32::MAX as u32, i32::MAX as u32, 2, 8, &[], Some(0));
        let e = decode(Path::new("huge.png"), &bytes, &b, &no_work, &no_warn).err().unwrap().to_string();
        assert!(e.starts_with("image huge.png: ") && !e.contains("panicked"), "{e}");
    }

    /// Peak resident memory of this process so far, KiB (Linux).
    fn peak_kib() -> Option<u64> {
        let s = std::fs::read_to_string("/proc/self/status").ok()?;
        s.lines().find(|l| l.starts_with("VmHWM:"))?.split_whitespace().nth(1)?.parse().ok()
    }

    #[test]
    fn an_inflated_icc_profile_stays_within_the_header_cap() {
        // 256 MiB of profile from a few hundred KB of zlib: the header cap (16 MiB) stops
        // the inflation; the profile is dropped or the file refused, never held whole.
        let mut iccp = b"bomb\0\0".to_vec();
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        let block = vec![0u8; 1 << 20];
        for _ in 0..256 {
            z.write_all(&block).unwrap();
        }
        iccp.extend(z.finish().unwrap());
        let bytes = png(4, 4, 2, 8, &[chunk(b"iCCP", &iccp)], None);
        assert!(bytes.len() < 4_000_000, "{}", bytes.len());
        let before = peak_kib();
        let budget = Budget::new(DECODE_BUDGET);
        let r = decode(Path::new("icc.png"), &bytes, &budget, &no_work, &no_warn);
        if let Err(e) = &r {
            assert!(e.to_string().starts_with("image icc.png: "), "{e}");
        }
        if let (Some(a), Some(b)) = (before, peak_kib()) {
            assert!(b - a < 128 << 10, "peak grew by {} MiB", (b - a) >> 10);
        }
    }

    #[test]
    fn a_truncated_jpeg_is_warned() {
        let img = image::RgbImage::from_fn(32, 32, |x, y| image::Rgb([x as u8 * 8, y as u8 * 8, 128]));
        let mut jpg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new(&mut jpg).encode_image(&img).unwrap();
        let warned = std::cell::RefCell::new(Vec::<String>::new());
        let w = |m: &str| warned.borrow_mut().push(m.to_string());
        let b = Budget::new(DECODE_BUDGET);
        decode(Path::new("ok.jpg"), &jpg, &b, &no_work, &w).unwrap();
        assert!(warned.borrow().is_empty());
        let cut = &jpg[..jpg.len() * 2 / 3];
        let _ = decode(Path::new("cut.jpg"), cut, &b, &no_work, &w);
        assert!(warned.borrow().iter().any(|m| m.contains("truncated")), "{:?}", warned.borrow());
    }

    #[cfg(unix)]
    #[test]
    fn fifos_and_devices_named_like_images_are_refused_without_reading() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("x.png");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let e = read(&fifo, Budget::global(), &no_work, &no_warn).err().unwrap().to_string();
        assert!(e.ends_with("is a FIFO; only regular files are read"), "{e}");
        let link = dir.path().join("random.png");
        std::os::unix::fs::symlink("/dev/urandom", &link).unwrap();
        let e = read(&link, Budget::global(), &no_work, &no_warn).err().unwrap().to_string();
        assert!(e.ends_with("is a device; only regular files are read"), "{e}");
    }

    #[test]
    fn a_request_larger_than_the_budget_is_refused_not_waited_for() {
        let b = Budget::new(10);
        assert!(b.take(11).is_none());
        let a = b.take(6).unwrap();
        assert_eq!(b.free(), 4);
        drop(a);
        assert_eq!(b.free(), 10);
    }

    #[test]
    fn a_phone_photo_is_enhanced_under_the_budget_one_at_a_time() {
        // A 12-megapixel 8-bit photo with the enhancer's work fits the budget, two do not:
        // they wait for each other instead of adding up.
        // Its enhancer work at the automatic scale (a quarter a side, padded to 16):
        // the network on 1008 x 768 pixels, the full-resolution planes on 4032 x 3024.
        use crate::enhance::NET_BYTES_PER_PIXEL;
        let work = 1008 * 768 * NET_BYTES_PER_PIXEL + 4032 * 3024 * 30;
        let one = peak_bytes_at(4032, 3024, 4032 * 3024 * 3, work, PEAK_BYTES_PER_PIXEL_8);
        assert!(one <= DECODE_BUDGET && 2 * one > DECODE_BUDGET, "{one}");
        // A UHD frame with the network at full resolution (3840 x 2160 x 170 bytes) does not.
        assert!(peak_bytes(3840, 2160, 3840 * 2160 * 3, 3840 * 2160 * NET_BYTES_PER_PIXEL) > DECODE_BUDGET);
        // The pipeline's bytes a pixel, the caller's work and the decoded image.
        assert_eq!(peak_bytes(10, 10, 300, 30), 10 * 10 * PEAK_BYTES_PER_PIXEL + 30 + 300);
    }
}
