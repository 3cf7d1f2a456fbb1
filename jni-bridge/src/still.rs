//! Protected stills: a verified frame's pixels as a JPEG whose only metadata is its
//! orientation.
//!
//! A phone's own JPEG is never used (its still request is not the verified stream, and the
//! camera stack writes location, time and maker notes into it): the app's still is encoded
//! here from the pixels of a frame whose `CaptureResult` verified. The EXIF block holds one
//! tag, `Orientation`; nothing else (no GPS, no time, no device) is written.
//!
//! Colour: Camera2's `YUV_420_888` buffers are JFIF YCbCr (full-range BT.601, the HAL3
//! contract), converted to RGB with the JFIF equations; `image`'s encoder converts back to
//! JFIF YCbCr with 4:2:2 chroma. The round trip adds at most 1 code per channel on flat
//! areas (tested), on top of JPEG's quantisation.

use crate::BridgeError;
use image::codecs::jpeg::JpegEncoder;
use image::{ExtendedColorType, ImageEncoder};

/// Largest side of a still, pixels: beyond every phone sensor (200 MP is 16320 wide).
pub const MAX_SIDE: u32 = 16_384;
/// Largest still, pixels: 64 MP, so the RGB copy stays under 200 MB.
pub const MAX_PIXELS: u64 = 64 << 20;

/// TIFF and EXIF constants of the one-tag block [`exif_orientation`] writes.
mod tiff {
    /// Little-endian byte order mark, "II".
    pub const LITTLE_ENDIAN: [u8; 2] = *b"II";
    /// TIFF's magic number.
    pub const MAGIC: u16 = 42;
    /// Offset of IFD0 from the TIFF header's start: right after the 8-byte header.
    pub const IFD0_OFFSET: u32 = 8;
    /// `Orientation`'s tag.
    pub const TAG_ORIENTATION: u16 = 0x0112;
    /// Field type SHORT (16-bit unsigned).
    pub const TYPE_SHORT: u16 = 3;
}

/// One verified `YUV_420_888` frame's planes, as `Image.getPlanes()` gives them: Y with its
/// row stride (pixel stride 1, the format's rule), U and V with a shared row and pixel
/// stride (1: planar I420, 2: semi-planar NV12/NV21 views of one buffer).
pub struct Yuv420<'a> {
    pub width: u32,
    pub height: u32,
    pub y: &'a [u8],
    pub y_row_stride: usize,
    pub u: &'a [u8],
    pub v: &'a [u8],
    pub uv_row_stride: usize,
    pub uv_pixel_stride: usize,
}

fn check_size(width: u32, height: u32) -> Result<(), BridgeError> {
    if width == 0
        || height == 0
        || width > MAX_SIDE
        || height > MAX_SIDE
        || u64::from(width) * u64::from(height) > MAX_PIXELS
    {
        return Err(BridgeError::Argument(format!(
            "width x height: must be 1..={MAX_SIDE} a side and at most {MAX_PIXELS} pixels, got {width} x {height}"
        )));
    }
    Ok(())
}

/// The last byte index a plane must hold for `rows` rows of `cols` samples.
fn plane_need(rows: usize, cols: usize, row_stride: usize, pixel_stride: usize) -> usize {
    (rows - 1) * row_stride + (cols - 1) * pixel_stride + 1
}

fn check_plane(
    name: &str,
    plane: &[u8],
    rows: usize,
    cols: usize,
    row_stride: usize,
    pixel_stride: usize,
) -> Result<(), BridgeError> {
    if pixel_stride == 0 || row_stride < (cols - 1) * pixel_stride + 1 {
        return Err(BridgeError::Argument(format!(
            "{name}: row stride {row_stride} and pixel stride {pixel_stride} do not hold {cols} samples a row"
        )));
    }
    let need = plane_need(rows, cols, row_stride, pixel_stride);
    if plane.len() < need {
        return Err(BridgeError::Argument(format!(
            "{name}: holds {} bytes, {rows} rows of {cols} samples at these strides need {need}",
            plane.len()
        )));
    }
    Ok(())
}

/// JFIF (full-range BT.601) YCbCr to 8-bit RGB, rounded and clamped.
pub fn jfif_to_rgb(y: u8, cb: u8, cr: u8) -> [u8; 3] {
    let (y, cb, cr) = (f32::from(y), f32::from(cb) - 128.0, f32::from(cr) - 128.0);
    let to = |v: f32| v.round().clamp(0.0, 255.0) as u8;
    [to(y + 1.402 * cr), to(y - 0.344_136 * cb - 0.714_136 * cr), to(y + 1.772 * cb)]
}

/// The frame as interleaved 8-bit RGB. Each chroma sample covers the 2 x 2 pixels it was
/// taken from (odd sizes: the last row and column use the last sample).
pub fn yuv420_to_rgb(f: &Yuv420) -> Result<Vec<u8>, BridgeError> {
    check_size(f.width, f.height)?;
    let (w, h) = (f.width as usize, f.height as usize);
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    check_plane("y", f.y, h, w, f.y_row_stride, 1)?;
    check_plane("u", f.u, ch, cw, f.uv_row_stride, f.uv_pixel_stride)?;
    check_plane("v", f.v, ch, cw, f.uv_row_stride, f.uv_pixel_stride)?;
    let mut rgb = vec![0u8; 3 * w * h];
    for (row, out) in rgb.chunks_exact_mut(3 * w).enumerate() {
        let yrow = &f.y[row * f.y_row_stride..];
        let c0 = (row / 2) * f.uv_row_stride;
        for (col, px) in out.chunks_exact_mut(3).enumerate() {
            let c = c0 + (col / 2) * f.uv_pixel_stride;
            px.copy_from_slice(&jfif_to_rgb(yrow[col], f.u[c], f.v[c]));
        }
    }
    Ok(rgb)
}

/// The EXIF block (TIFF header and IFD0) holding only `Orientation` = `value`, as the
/// payload of an APP1 segment after its "Exif\0\0" header.
pub fn exif_orientation(value: u16) -> Vec<u8> {
    let mut e = Vec::with_capacity(26);
    e.extend_from_slice(&tiff::LITTLE_ENDIAN);
    e.extend_from_slice(&tiff::MAGIC.to_le_bytes());
    e.extend_from_slice(&tiff::IFD0_OFFSET.to_le_bytes());
    e.extend_from_slice(&1u16.to_le_bytes()); // one entry
    e.extend_from_slice(&tiff::TAG_ORIENTATION.to_le_bytes());
    e.extend_from_slice(&tiff::TYPE_SHORT.to_le_bytes());
    e.extend_from_slice(&1u32.to_le_bytes()); // one value, stored in the entry
    e.extend_from_slice(&value.to_le_bytes());
    e.extend_from_slice(&[0, 0]); // the value field's unused half
    e.extend_from_slice(&0u32.to_le_bytes()); // no next IFD
    e
}

/// Encodes interleaved 8-bit RGB as a baseline JPEG at `quality` (1..=100) whose only
/// metadata is EXIF `Orientation` = `exif_orientation_value` (1..=8: 1 as stored, 6 turned
/// 90 degrees clockwise to view, 3 turned 180, 8 turned 270).
pub fn jpeg(
    rgb: &[u8],
    width: u32,
    height: u32,
    exif_orientation_value: u16,
    quality: u8,
) -> Result<Vec<u8>, BridgeError> {
    check_size(width, height)?;
    if !(1..=8).contains(&exif_orientation_value) {
        return Err(BridgeError::Argument(format!(
            "orientation: must be an EXIF orientation 1..=8, got {exif_orientation_value}"
        )));
    }
    if !(1..=100).contains(&quality) {
        return Err(BridgeError::Argument(format!("quality: must be 1..=100, got {quality}")));
    }
    let need = 3 * width as usize * height as usize;
    if rgb.len() != need {
        return Err(BridgeError::Argument(format!(
            "rgb: must hold 3 bytes a pixel ({need} for {width} x {height}), got {}",
            rgb.len()
        )));
    }
    let mut out = Vec::with_capacity(need / 4);
    let mut enc = JpegEncoder::new_with_quality(&mut out, quality);
    enc.set_exif_metadata(exif_orientation(exif_orientation_value))
        .map_err(|e| BridgeError::State(format!("jpeg: {e}")))?;
    enc.write_image(rgb, width, height, ExtendedColorType::Rgb8)
        .map_err(|e| BridgeError::State(format!("jpeg: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jfif_equations_at_hand_derived_points() {
        // Grey: no chroma, RGB = Y.
        assert_eq!(jfif_to_rgb(77, 128, 128), [77, 77, 77]);
        // JFIF of pure red (255, 0, 0): Y = 76.245, Cb = 84.97, Cr = 255.5 -> (76, 85, 255).
        let [r, g, b] = jfif_to_rgb(76, 85, 255);
        assert!(r >= 254 && g <= 1 && b <= 1, "{r} {g} {b}");
        // Saturation clamps, never wraps.
        // G = 255 - 0.344136 * 127 - 0.714136 * 127 = 120.6.
        assert_eq!(jfif_to_rgb(255, 255, 255), [255, 121, 255]);
    }

    /// NV21-style planes (V and U interleaved, pixel stride 2) and padded rows read the same
    /// pixels as tightly packed I420.
    #[test]
    fn strides_and_layouts_agree() {
        let (w, h) = (5u32, 3u32);
        let y: Vec<u8> = (0..15).map(|i| 20 + 10 * i as u8).collect();
        let (cw, ch) = (3, 2);
        let u: Vec<u8> = (0..cw * ch).map(|i| 100 + 7 * i as u8).collect();
        let v: Vec<u8> = (0..cw * ch).map(|i| 160 - 9 * i as u8).collect();
        let packed = yuv420_to_rgb(&Yuv420 {
            width: w,
            height: h,
            y: &y,
            y_row_stride: 5,
            u: &u,
            v: &v,
            uv_row_stride: 3,
            uv_pixel_stride: 1,
        })
        .unwrap();
        // Y rows padded to 8; chroma interleaved VU with rows padded to 8.
        let mut ypad = vec![0u8; 8 * 3];
        for r in 0..3 {
            ypad[8 * r..8 * r + 5].copy_from_slice(&y[5 * r..5 * r + 5]);
        }
        let mut vu = vec![0u8; 8 * 2];
        for r in 0..2 {
            for c in 0..3 {
                vu[8 * r + 2 * c] = v[3 * r + c];
                vu[8 * r + 2 * c + 1] = u[3 * r + c];
            }
        }
        let nv21 = yuv420_to_rgb(&Yuv420 {
            width: w,
            height: h,
            y: &ypad,
            y_row_stride: 8,
            u: &vu[1..],
            v: &vu,
            uv_row_stride: 8,
            uv_pixel_stride: 2,
        })
        .unwrap();
        assert_eq!(packed, nv21);
        // Pixel (4, 2) takes chroma sample (2, 1).
        let k = 3 * (2 * 5 + 4);
        assert_eq!(&packed[k..k + 3], &jfif_to_rgb(y[14], u[5], v[5]));
    }

    #[test]
    fn short_planes_and_bad_strides_are_refused_by_name() {
        let y = [0u8; 16];
        let c = [0u8; 4];
        let e = yuv420_to_rgb(&Yuv420 {
            width: 4,
            height: 4,
            y: &y[..15],
            y_row_stride: 4,
            u: &c,
            v: &c,
            uv_row_stride: 2,
            uv_pixel_stride: 1,
        })
        .unwrap_err();
        assert!(e.to_string().starts_with("y: holds 15 bytes"), "{e}");
        let e = yuv420_to_rgb(&Yuv420 {
            width: 4,
            height: 4,
            y: &y,
            y_row_stride: 4,
            u: &c,
            v: &c,
            uv_row_stride: 2,
            uv_pixel_stride: 2,
        })
        .unwrap_err();
        assert!(e.to_string().starts_with("u: row stride 2 and pixel stride 2"), "{e}");
        let e = yuv420_to_rgb(&Yuv420 {
            width: 0,
            height: 4,
            y: &y,
            y_row_stride: 4,
            u: &c,
            v: &c,
            uv_row_stride: 2,
            uv_pixel_stride: 1,
        })
        .unwrap_err();
        assert!(e.to_string().starts_with("width x height"), "{e}");
        let e = yuv420_to_rgb(&Yuv420 {
            width: MAX_SIDE,
            height: MAX_SIDE,
            y: &y,
            y_row_stride: 4,
            u: &c,
            v: &c,
            uv_row_stride: 2,
            uv_pixel_stride: 1,
        })
        .unwrap_err();
        assert!(e.to_string().contains("at most"), "{e}");
    }

    /// The EXIF block read by a second implementation (kamadak-exif): Orientation and
    /// nothing else, in IFD0.
    #[test]
    fn exif_holds_the_orientation_alone() {
        for v in 1..=8u16 {
            let exif = exif::Reader::new().read_raw(exif_orientation(v)).unwrap();
            let fields: Vec<_> = exif.fields().collect();
            assert_eq!(fields.len(), 1);
            assert_eq!(fields[0].tag, exif::Tag::Orientation);
            assert_eq!(fields[0].ifd_num, exif::In::PRIMARY);
            assert_eq!(fields[0].value.get_uint(0), Some(u32::from(v)));
        }
    }

    /// A still of flat 8 x 8 blocks decodes (zune-jpeg, through `image`) within 2 codes of
    /// its RGB at quality 100, carries the orientation, and holds no GPS.
    #[test]
    fn a_still_round_trips_with_its_orientation() {
        let (w, h) = (64u32, 48u32);
        let mut rgb = vec![0u8; 3 * (w * h) as usize];
        for yy in 0..h {
            for xx in 0..w {
                let blk = (yy / 8) * (w / 8) + xx / 8;
                let k = 3 * (yy * w + xx) as usize;
                rgb[k..k + 3].copy_from_slice(&[
                    (blk * 37 % 256) as u8,
                    (blk * 91 % 256) as u8,
                    (blk * 53 % 256) as u8,
                ]);
            }
        }
        // EXIF 6: turned 90 degrees clockwise to view (Kotlin's Orientation.exifOrientation(90)).
        let bytes = jpeg(&rgb, w, h, 6, 100).unwrap();
        let exif = exif::Reader::new().read_from_container(&mut std::io::Cursor::new(&bytes)).unwrap();
        assert_eq!(exif.get_field(exif::Tag::Orientation, exif::In::PRIMARY).unwrap().value.get_uint(0), Some(6));
        assert!(exif.fields().all(|f| f.tag == exif::Tag::Orientation), "only the orientation is written");
        let back = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg).unwrap().to_rgb8();
        assert_eq!((back.width(), back.height()), (w, h), "pixels are stored unrotated");
        let worst = back.as_raw().iter().zip(&rgb).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        assert!(worst <= 2, "worst {worst}");
    }

    #[test]
    fn bad_encoder_arguments_are_refused_by_name() {
        let rgb = [0u8; 12];
        assert!(jpeg(&rgb, 2, 2, 0, 90).unwrap_err().to_string().starts_with("orientation:"));
        assert!(jpeg(&rgb, 2, 2, 1, 0).unwrap_err().to_string().starts_with("quality:"));
        assert!(jpeg(&rgb[..11], 2, 2, 1, 90).unwrap_err().to_string().starts_with("rgb:"));
    }
}
