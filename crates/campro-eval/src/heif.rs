//! HEIC/HEIF photos (every iPhone's, many Android phones') through the system's libheif,
//! loaded at run time: a machine without it reads everything else and says, in one line,
//! what to install. Nothing is linked, so the binary starts everywhere.
//!
//! The picture comes out as libheif displays it: its rotation and mirroring (`irot`,
//! `imir`) applied, which HEIF makes authoritative over the EXIF orientation; 8-bit RGB (a
//! 10-bit photo is rounded by libheif). Its size is read from the header and checked
//! against the caller's memory budget before anything is decoded.

use crate::error::{EvalError, Result};
use std::ffi::{c_char, c_int, c_void, CStr};
use std::path::Path;
use std::sync::OnceLock;

/// The libheif file names tried, in order.
const LIBRARY: &[&str] = &["libheif.so.1", "libheif.so", "libheif.1.dylib", "libheif.dylib", "heif.dll"];

/// What to do without libheif.
pub const MISSING: &str = "HEIC needs the system's libheif, which is not on this machine (Debian/Ubuntu: apt install libheif1; macOS: brew install libheif), or convert it first (heif-convert IMG.HEIC IMG.jpg)";

/// Bytes a pixel of a HEIC photo holds while it is decoded and handed over: libheif's
/// Y'CbCr planes (at most 3, 4:4:4) and its RGB picture (3), and the copy returned (3).
pub const DECODE_BYTES_PER_PIXEL: u64 = 9;

fn image_error(path: &Path, message: impl Into<String>) -> EvalError {
    EvalError::Image { path: path.into(), message: message.into() }
}

/// libheif's `enum heif_colorspace`: `heif_colorspace_RGB`.
const COLORSPACE_RGB: c_int = 1;
/// `enum heif_chroma`: `heif_chroma_interleaved_RGB`.
const CHROMA_INTERLEAVED_RGB: c_int = 10;
/// `enum heif_channel`: `heif_channel_interleaved`.
const CHANNEL_INTERLEAVED: c_int = 10;

/// libheif's `struct heif_error`, returned by value.
#[repr(C)]
struct HeifError {
    code: c_int,
    subcode: c_int,
    message: *const c_char,
}

type Ctx = c_void;
type Handle = c_void;
type Image = c_void;

/// The functions used, resolved once.
struct Api {
    context_alloc: unsafe extern "C" fn() -> *mut Ctx,
    context_free: unsafe extern "C" fn(*mut Ctx),
    read_from_memory: unsafe extern "C" fn(*mut Ctx, *const c_void, usize, *const c_void) -> HeifError,
    primary_handle: unsafe extern "C" fn(*mut Ctx, *mut *mut Handle) -> HeifError,
    handle_release: unsafe extern "C" fn(*const Handle),
    handle_width: unsafe extern "C" fn(*const Handle) -> c_int,
    handle_height: unsafe extern "C" fn(*const Handle) -> c_int,
    handle_has_alpha: unsafe extern "C" fn(*const Handle) -> c_int,
    decode_image: unsafe extern "C" fn(*const Handle, *mut *mut Image, c_int, c_int, *const c_void) -> HeifError,
    image_release: unsafe extern "C" fn(*const Image),
    plane: unsafe extern "C" fn(*const Image, c_int, *mut c_int) -> *const u8,
    image_width: unsafe extern "C" fn(*const Image, c_int) -> c_int,
    image_height: unsafe extern "C" fn(*const Image, c_int) -> c_int,
    metadata_count: unsafe extern "C" fn(*const Handle, *const c_char) -> c_int,
    metadata_ids: unsafe extern "C" fn(*const Handle, *const c_char, *mut u32, c_int) -> c_int,
    metadata_size: unsafe extern "C" fn(*const Handle, u32) -> usize,
    metadata: unsafe extern "C" fn(*const Handle, u32, *mut c_void) -> HeifError,
    profile_size: unsafe extern "C" fn(*const Handle) -> usize,
    profile: unsafe extern "C" fn(*const Handle, *mut c_void) -> HeifError,
    /// Kept so that the functions stay valid.
    _lib: libloading::Library,
}

impl Api {
    /// Opens libheif and resolves every function (and initialises its plugins where the
    /// version has `heif_init`).
    fn open() -> std::result::Result<Api, String> {
        // SAFETY: loading libheif runs its initialisers, which have no preconditions.
        let lib = LIBRARY
            .iter()
            .find_map(|name| unsafe { libloading::Library::new(name) }.ok())
            .ok_or_else(|| MISSING.to_string())?;
        macro_rules! f {
            ($name:literal) => {
                // SAFETY: the type given is the function's C signature in libheif's
                // heif.h (1.7 onwards), and `lib` outlives the pointer (kept in `Api`).
                *unsafe { lib.get(concat!($name, "\0").as_bytes()) }
                    .map_err(|e| format!("libheif lacks {}: {e} (libheif 1.7 or newer is needed)", $name))?
            };
        }
        // SAFETY: `heif_init(NULL)` takes the default parameters (libheif 1.13 onwards).
        if let Ok(init) = unsafe { lib.get::<unsafe extern "C" fn(*const c_void) -> HeifError>(b"heif_init\0") } {
            let e = unsafe { init(std::ptr::null()) };
            if e.code != 0 {
                return Err(format!("libheif did not start: {}", message(&e)));
            }
        }
        Ok(Api {
            context_alloc: f!("heif_context_alloc"),
            context_free: f!("heif_context_free"),
            read_from_memory: f!("heif_context_read_from_memory_without_copy"),
            primary_handle: f!("heif_context_get_primary_image_handle"),
            handle_release: f!("heif_image_handle_release"),
            handle_width: f!("heif_image_handle_get_width"),
            handle_height: f!("heif_image_handle_get_height"),
            handle_has_alpha: f!("heif_image_handle_has_alpha_channel"),
            decode_image: f!("heif_decode_image"),
            image_release: f!("heif_image_release"),
            plane: f!("heif_image_get_plane_readonly"),
            image_width: f!("heif_image_get_width"),
            image_height: f!("heif_image_get_height"),
            metadata_count: f!("heif_image_handle_get_number_of_metadata_blocks"),
            metadata_ids: f!("heif_image_handle_get_list_of_metadata_block_IDs"),
            metadata_size: f!("heif_image_handle_get_metadata_size"),
            metadata: f!("heif_image_handle_get_metadata"),
            profile_size: f!("heif_image_handle_get_raw_color_profile_size"),
            profile: f!("heif_image_handle_get_raw_color_profile"),
            _lib: lib,
        })
    }
}

/// libheif, opened on first use; the line saying why not where it cannot be.
fn api() -> std::result::Result<&'static Api, &'static str> {
    static API: OnceLock<std::result::Result<Api, String>> = OnceLock::new();
    API.get_or_init(Api::open).as_ref().map_err(String::as_str)
}

/// Whether this machine reads HEIC (libheif found and complete).
pub fn available() -> bool {
    api().is_ok()
}

/// Whether `bytes` start as a HEIF file: an `ftyp` box whose major brand is one of HEIF's
/// still-image brands (HEVC-coded `heic`/`heix`, their sequences, or the generic `mif1`).
pub fn is_heif(bytes: &[u8]) -> bool {
    bytes.len() >= 12
        && &bytes[4..8] == b"ftyp"
        && matches!(&bytes[8..12], b"heic" | b"heix" | b"heim" | b"heis" | b"hevc" | b"hevx" | b"mif1" | b"msf1")
}

/// A file name's ending says HEIC/HEIF.
pub fn named_heif(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("heic") || e.eq_ignore_ascii_case("heif"))
}

fn message(e: &HeifError) -> String {
    if e.message.is_null() {
        format!("libheif error {}.{}", e.code, e.subcode)
    } else {
        // SAFETY: libheif's messages are NUL-terminated static strings. Some end in a
        // newline: said as one line.
        let text = unsafe { CStr::from_ptr(e.message) }.to_string_lossy().into_owned();
        text.split_whitespace().collect::<Vec<_>>().join(" ")
    }
}

/// Frees what it holds when dropped, on every path out.
struct Owned<'a> {
    api: &'static Api,
    ctx: *mut Ctx,
    handle: *mut Handle,
    image: *mut Image,
    /// The file's bytes, which the context reads from without a copy.
    _bytes: std::marker::PhantomData<&'a [u8]>,
}

impl Drop for Owned<'_> {
    fn drop(&mut self) {
        // SAFETY: each pointer is null or was returned by libheif and is released once.
        unsafe {
            if !self.image.is_null() {
                (self.api.image_release)(self.image);
            }
            if !self.handle.is_null() {
                (self.api.handle_release)(self.handle);
            }
            if !self.ctx.is_null() {
                (self.api.context_free)(self.ctx);
            }
        }
    }
}

/// A HEIF file read up to its primary picture, nothing decoded yet: its size (as displayed,
/// after rotation), alpha, EXIF and ICC, then [`Heif::decode`]. Borrows the file's bytes,
/// which libheif reads without a copy.
pub struct Heif<'a> {
    o: Owned<'a>,
    path: &'a Path,
    /// Width and height as displayed, pixels.
    pub size: (u32, u32),
}

/// Reads `bytes` (the file `path`, named in errors) up to its primary picture.
pub fn open<'a>(path: &'a Path, bytes: &'a [u8]) -> Result<Heif<'a>> {
    // What the HEVC streams code, checked against what the file declares before libheif,
    // which trusts the declaration, decodes anything (crate::hvcc).
    let sizes = crate::hvcc::sizes(bytes).map_err(|e| image_error(path, format!("its HEIF boxes do not read: {e}")))?;
    if let Some(why) = sizes.mismatch() {
        return Err(image_error(path, why));
    }
    let api = api().map_err(|e| image_error(path, e))?;
    let fail = |what: &str, e: &HeifError| image_error(path, format!("{what}: {}", message(e)));
    // SAFETY: every call follows heif.h: the context outlives the handle and image (`Owned`
    // drops them in order), and `bytes` outlives every read of the context (`Heif` borrows
    // it for as long as `Owned` lives).
    unsafe {
        let mut o = Owned {
            api,
            ctx: (api.context_alloc)(),
            handle: std::ptr::null_mut(),
            image: std::ptr::null_mut(),
            _bytes: std::marker::PhantomData,
        };
        if o.ctx.is_null() {
            return Err(image_error(path, "libheif could not allocate a context"));
        }
        let e = (api.read_from_memory)(o.ctx, bytes.as_ptr().cast(), bytes.len(), std::ptr::null());
        if e.code != 0 {
            return Err(fail("not a HEIF file libheif reads", &e));
        }
        let e = (api.primary_handle)(o.ctx, &mut o.handle);
        if e.code != 0 {
            return Err(fail("no primary picture", &e));
        }
        let (w, h) = ((api.handle_width)(o.handle), (api.handle_height)(o.handle));
        if w <= 0 || h <= 0 {
            return Err(image_error(path, format!("the picture is {w} x {h} pixels")));
        }
        Ok(Heif { o, path, size: (w as u32, h as u32) })
    }
}

impl Heif<'_> {
    /// Whether the picture has an alpha channel (dropped by [`Heif::decode`]).
    pub fn has_alpha(&self) -> bool {
        // SAFETY: the handle is valid while `self` lives.
        unsafe { (self.o.api.handle_has_alpha)(self.o.handle) != 0 }
    }

    /// The first EXIF block, TIFF-structured (at most 1 MiB; None where there is none).
    pub fn exif(&self) -> Option<Vec<u8>> {
        // SAFETY: the handle is valid while `self` lives.
        unsafe { exif(self.o.api, self.o.handle) }
    }

    /// The raw ICC profile (at most 1 MiB; None for an nclx colour description).
    pub fn icc(&self) -> Option<Vec<u8>> {
        // SAFETY: the handle is valid while `self` lives.
        unsafe { icc(self.o.api, self.o.handle) }
    }

    /// The picture as 8-bit RGB with libheif's transformations applied: about
    /// [`DECODE_BYTES_PER_PIXEL`] bytes a pixel at its peak, which the caller has checked.
    pub fn decode(mut self) -> Result<image::RgbImage> {
        let (api, path, (w, h)) = (self.o.api, self.path, self.size);
        // SAFETY: the handle is valid; the plane is read within the stride and size libheif
        // gives, checked against the handle's.
        unsafe {
            let e = (api.decode_image)(
                self.o.handle,
                &mut self.o.image,
                COLORSPACE_RGB,
                CHROMA_INTERLEAVED_RGB,
                std::ptr::null(),
            );
            if e.code != 0 {
                return Err(image_error(path, format!("its picture could not be decoded: {}", message(&e))));
            }
            let (iw, ih) = (
                (api.image_width)(self.o.image, CHANNEL_INTERLEAVED),
                (api.image_height)(self.o.image, CHANNEL_INTERLEAVED),
            );
            let mut stride: c_int = 0;
            let plane = (api.plane)(self.o.image, CHANNEL_INTERLEAVED, &mut stride);
            if plane.is_null() || iw as u32 != w || ih as u32 != h || (stride as i64) < 3 * w as i64 {
                return Err(image_error(
                    path,
                    format!("libheif gave a {iw} x {ih} picture (stride {stride}) for a {w} x {h} one"),
                ));
            }
            let row = 3 * w as usize;
            let mut rgb = Vec::with_capacity(row * h as usize);
            for y in 0..h as usize {
                rgb.extend_from_slice(std::slice::from_raw_parts(plane.add(y * stride as usize), row));
            }
            Ok(image::RgbImage::from_raw(w, h, rgb).expect("w x h x 3 bytes"))
        }
    }
}

/// At most this many bytes of EXIF or ICC are read (a phone's are tens of kilobytes).
const MAX_BLOCK: usize = 1 << 20;

/// The first EXIF block of `handle`, TIFF-structured: libheif's block starts with a
/// 4-byte big-endian offset to the TIFF header (which some writers put after `Exif\0\0`).
unsafe fn exif(api: &Api, handle: *const Handle) -> Option<Vec<u8>> {
    let kind = c"Exif".as_ptr();
    if (api.metadata_count)(handle, kind) < 1 {
        return None;
    }
    let mut id = 0u32;
    if (api.metadata_ids)(handle, kind, &mut id, 1) < 1 {
        return None;
    }
    let size = (api.metadata_size)(handle, id);
    if !(4..=MAX_BLOCK).contains(&size) {
        return None;
    }
    let mut block = vec![0u8; size];
    if (api.metadata)(handle, id, block.as_mut_ptr().cast()).code != 0 {
        return None;
    }
    let offset = u32::from_be_bytes([block[0], block[1], block[2], block[3]]) as usize;
    let tiff = block.get(4 + offset..)?;
    // Some writers keep JPEG's "Exif\0\0" before the TIFF header (offset 0).
    Some(tiff.strip_prefix(b"Exif\0\0").unwrap_or(tiff).to_vec())
}

/// The raw ICC profile of `handle` (none for an nclx colour description).
unsafe fn icc(api: &Api, handle: *const Handle) -> Option<Vec<u8>> {
    let size = (api.profile_size)(handle);
    if size == 0 || size > MAX_BLOCK {
        return None;
    }
    let mut p = vec![0u8; size];
    ((api.profile)(handle, p.as_mut_ptr().cast()).code == 0).then_some(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file that declares 64 x 64 and codes 60000 x 60000 is refused by name before libheif
    /// (which trusts the declaration) is asked for anything: no libheif needed.
    #[test]
    fn a_lying_declaration_is_refused_before_libheif() {
        let bomb = crate::hvcc::tests::heif_declaring((64, 64), (60000, 60000));
        let e = open(Path::new("bomb.heic"), &bomb).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("codes 60000 x 60000 pictures, more than the 64 x 64 it declares"), "{e}");
    }

    #[test]
    fn heif_files_are_told_by_their_brand() {
        let ftyp = |brand: &[u8; 4]| [&[0, 0, 0, 24][..], b"ftyp", brand, &[0; 12]].concat();
        assert!(is_heif(&ftyp(b"heic")) && is_heif(&ftyp(b"mif1")));
        assert!(!is_heif(&ftyp(b"isom")) && !is_heif(&ftyp(b"avif")) && !is_heif(b"\x89PNG\r\n\x1a\n"));
        assert!(named_heif(Path::new("IMG_1.HEIC")) && !named_heif(Path::new("a.jpg")));
    }
}
