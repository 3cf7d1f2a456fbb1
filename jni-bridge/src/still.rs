//! Protected stills: a verified frame's pixels as a JPEG whose only metadata is its
//! orientation.
//!
//! A phone's own JPEG is never used (its still request is not the verified stream, and the
//! camera stack writes location, time and maker notes into it): the app's still is encoded
//! here from the pixels of a frame whose `CaptureResult` verified. The EXIF block holds one
//! tag, `Orientation`; nothing else (no GPS, no time, no device) is written.
//!
//! Colour: Camera2's `YUV_420_888` buffers are JFIF YCbCr (full-range BT.601, the HAL3
//! contract), which is what a JPEG stores: the planes go to the encoder (`jpeg-encoder`,
//! 4:2:0, each chroma sample taken as it is) with no colour conversion, so JPEG's
//! quantisation is the only error.

use crate::BridgeError;
use jpeg_encoder::{ColorType, Encoder, ImageBuffer, JpegColorType, SamplingFactor};

/// Largest side of a still, pixels: beyond every phone sensor (200 MP is 16320 wide).
pub const MAX_SIDE: u32 = 16_384; // and JPEG's 65535
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

/// Rows of the frame for the encoder: Y, Cb, Cr per pixel, each chroma sample standing for
/// the 2 x 2 pixels it was taken from (odd sizes: the last row and column use the last one).
struct Planes<'a, 'b>(&'b Yuv420<'a>);

impl ImageBuffer for Planes<'_, '_> {
    fn get_jpeg_color_type(&self) -> JpegColorType {
        JpegColorType::Ycbcr
    }

    fn width(&self) -> u16 {
        self.0.width as u16 // checked <= MAX_SIDE < 65536
    }

    fn height(&self) -> u16 {
        self.0.height as u16
    }

    fn fill_buffers(&self, row: u16, buffers: &mut [Vec<u8>; 4]) {
        let f = self.0;
        let row = usize::from(row);
        let y0 = row * f.y_row_stride;
        let c0 = (row / 2) * f.uv_row_stride;
        for col in 0..f.width as usize {
            let c = c0 + (col / 2) * f.uv_pixel_stride;
            buffers[0].push(f.y[y0 + col]);
            buffers[1].push(f.u[c]);
            buffers[2].push(f.v[c]);
        }
    }
}

/// Checks a frame's planes against its size and strides (before any byte is read).
fn check_frame(f: &Yuv420) -> Result<(), BridgeError> {
    check_size(f.width, f.height)?;
    let (w, h) = (f.width as usize, f.height as usize);
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    check_plane("y", f.y, h, w, f.y_row_stride, 1)?;
    check_plane("u", f.u, ch, cw, f.uv_row_stride, f.uv_pixel_stride)?;
    check_plane("v", f.v, ch, cw, f.uv_row_stride, f.uv_pixel_stride)
}

/// An EXIF orientation (1..=8), checked: the one rule for every caller.
pub fn orientation(v: i64) -> Result<u16, BridgeError> {
    u16::try_from(v)
        .ok()
        .filter(|o| (1..=8).contains(o))
        .ok_or_else(|| BridgeError::Argument(format!("orientation: must be an EXIF orientation 1..=8, got {v}")))
}

/// A JPEG quality (1..=100), checked: the one rule for every caller.
pub fn quality(v: i64) -> Result<u8, BridgeError> {
    u8::try_from(v)
        .ok()
        .filter(|q| (1..=100).contains(q))
        .ok_or_else(|| BridgeError::Argument(format!("quality: must be 1..=100, got {v}")))
}

fn encoder(
    out: &mut Vec<u8>,
    exif_orientation_value: u16,
    quality_value: u8,
) -> Result<Encoder<&mut Vec<u8>>, BridgeError> {
    let exif_orientation_value = orientation(exif_orientation_value.into())?;
    let quality = quality(quality_value.into())?;
    let mut enc = Encoder::new(out, quality);
    let mut app1 = EXIF_HEADER.to_vec();
    app1.extend_from_slice(&exif_orientation(exif_orientation_value));
    enc.add_app_segment(1, app1).map_err(|e| BridgeError::State(format!("jpeg: {e}")))?;
    Ok(enc)
}

/// Encodes a verified `YUV_420_888` frame as a baseline JPEG (4:2:0, the frame's own chroma)
/// at `quality` (1..=100) whose only metadata is EXIF `Orientation` = `exif_orientation_value`
/// (1..=8: 1 as stored, 6 turned 90 degrees clockwise to view, 3 turned 180, 8 turned 270).
pub fn jpeg_from_yuv420(f: &Yuv420, exif_orientation_value: u16, quality: u8) -> Result<Vec<u8>, BridgeError> {
    check_frame(f)?;
    let mut out = Vec::with_capacity(f.y.len() / 4);
    let mut enc = encoder(&mut out, exif_orientation_value, quality)?;
    enc.set_sampling_factor(SamplingFactor::F_2_2);
    enc.encode_image(Planes(f)).map_err(|e| BridgeError::State(format!("jpeg: {e}")))?;
    Ok(out)
}

/// An EXIF APP1 segment's identifier, before the TIFF data.
const EXIF_HEADER: &[u8; 6] = b"Exif\0\0";

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

/// Encodes interleaved 8-bit RGB as a baseline JPEG (4:4:4 from quality 90, 4:2:0 below)
/// whose only metadata is EXIF `Orientation` = `exif_orientation_value` (1..=8).
pub fn jpeg_from_rgb(
    rgb: &[u8],
    width: u32,
    height: u32,
    exif_orientation_value: u16,
    quality: u8,
) -> Result<Vec<u8>, BridgeError> {
    check_size(width, height)?;
    let need = 3 * width as usize * height as usize;
    if rgb.len() != need {
        return Err(BridgeError::Argument(format!(
            "rgb: must hold 3 bytes a pixel ({need} for {width} x {height}), got {}",
            rgb.len()
        )));
    }
    let mut out = Vec::with_capacity(need / 4);
    let enc = encoder(&mut out, exif_orientation_value, quality)?;
    enc.encode(rgb, width as u16, height as u16, ColorType::Rgb)
        .map_err(|e| BridgeError::State(format!("jpeg: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The JFIF decoding equations (a second implementation of what a viewer shows).
    fn jfif_to_rgb(y: u8, cb: u8, cr: u8) -> [u8; 3] {
        let (y, cb, cr) = (f64::from(y), f64::from(cb) - 128.0, f64::from(cr) - 128.0);
        let to = |v: f64| v.round().clamp(0.0, 255.0) as u8;
        [to(y + 1.402 * cr), to(y - 0.344_136 * cb - 0.714_136 * cr), to(y + 1.772 * cb)]
    }

    /// I420 planes of `w` x `h` pixels in flat 8 x 8 blocks (chroma in 4 x 4 blocks).
    fn blocks(w: usize, h: usize) -> (Vec<u8>, Vec<u8>, Vec<u8>) {
        let y = (0..w * h).map(|k| (30 + 17 * ((k % w) / 8) + 41 * ((k / w) / 8)) as u8).collect();
        let (cw, ch) = (w / 2, h / 2);
        let u = (0..cw * ch).map(|k| (70 + 23 * ((k % cw) / 4) + 9 * ((k / cw) / 4)) as u8).collect();
        let v = (0..cw * ch).map(|k| (200 - 19 * ((k % cw) / 4) - 7 * ((k / cw) / 4)) as u8).collect();
        (y, u, v)
    }

    fn decode(bytes: &[u8]) -> image::RgbImage {
        image::load_from_memory_with_format(bytes, image::ImageFormat::Jpeg).unwrap().to_rgb8()
    }

    /// The pixels away from block edges (a decoder's chroma upsampling blends neighbours there).
    fn interior(x: u32, y: u32) -> bool {
        (2..6).contains(&(x % 8)) && (2..6).contains(&(y % 8))
    }

    /// A frame of flat blocks decodes (zune-jpeg, through `image`) to its JFIF colours within
    /// 2 codes at quality 100, stored unrotated, with the orientation in its EXIF.
    #[test]
    fn a_yuv_still_round_trips_with_its_orientation() {
        let (w, h) = (64usize, 48usize);
        let (y, u, v) = blocks(w, h);
        let f = Yuv420 {
            width: 64,
            height: 48,
            y: &y,
            y_row_stride: w,
            u: &u,
            v: &v,
            uv_row_stride: w / 2,
            uv_pixel_stride: 1,
        };
        // EXIF 6: turned 90 degrees clockwise to view (Kotlin's Orientation.exifOrientation(90)).
        let bytes = jpeg_from_yuv420(&f, 6, 100).unwrap();
        let exif = exif::Reader::new().read_from_container(&mut std::io::Cursor::new(&bytes)).unwrap();
        assert_eq!(exif.get_field(exif::Tag::Orientation, exif::In::PRIMARY).unwrap().value.get_uint(0), Some(6));
        assert!(exif.fields().all(|f| f.tag == exif::Tag::Orientation), "only the orientation is written");
        let back = decode(&bytes);
        assert_eq!((back.width(), back.height()), (64, 48), "pixels are stored unrotated");
        let mut worst = 0;
        for (x, yy, px) in back.enumerate_pixels().filter(|(x, y, _)| interior(*x, *y)) {
            let (x, yy) = (x as usize, yy as usize);
            let c = (yy / 2) * (w / 2) + x / 2;
            let want = jfif_to_rgb(y[yy * w + x], u[c], v[c]);
            worst = worst.max((0..3).map(|k| px[k].abs_diff(want[k])).max().unwrap());
        }
        assert!(worst <= 2, "worst {worst}");
    }

    /// NV21 planes (V and U interleaved, pixel stride 2) with padded rows give the very same
    /// JPEG as tightly packed I420: the same samples reach the encoder.
    #[test]
    fn strides_and_layouts_agree() {
        let (w, h) = (16usize, 10usize);
        let (y, u, v) = blocks(w, h);
        let (cw, ch) = (w / 2, h / 2);
        let packed = jpeg_from_yuv420(
            &Yuv420 {
                width: 16,
                height: 10,
                y: &y,
                y_row_stride: w,
                u: &u,
                v: &v,
                uv_row_stride: cw,
                uv_pixel_stride: 1,
            },
            1,
            90,
        )
        .unwrap();
        let mut ypad = vec![0u8; 24 * h];
        for r in 0..h {
            ypad[24 * r..24 * r + w].copy_from_slice(&y[w * r..w * r + w]);
        }
        let mut vu = vec![0u8; 24 * ch];
        for r in 0..ch {
            for c in 0..cw {
                vu[24 * r + 2 * c] = v[cw * r + c];
                vu[24 * r + 2 * c + 1] = u[cw * r + c];
            }
        }
        let nv21 = jpeg_from_yuv420(
            &Yuv420 {
                width: 16,
                height: 10,
                y: &ypad,
                y_row_stride: 24,
                u: &vu[1..],
                v: &vu,
                uv_row_stride: 24,
                uv_pixel_stride: 2,
            },
            1,
            90,
        )
        .unwrap();
        assert_eq!(packed, nv21);
    }

    #[test]
    fn short_planes_and_bad_strides_are_refused_by_name() {
        let y = [0u8; 16];
        let c = [0u8; 4];
        // A 4 x 4 frame with these changes, refused: the message.
        let refused = |y: &[u8], width: u32, uv_pixel_stride: usize, orientation: u16| {
            let f = Yuv420 { width, height: 4, y, y_row_stride: 4, u: &c, v: &c, uv_row_stride: 2, uv_pixel_stride };
            jpeg_from_yuv420(&f, orientation, 90).unwrap_err().to_string()
        };
        let cases = [
            (refused(&y[..15], 4, 1, 1), "y: holds 15 bytes"),
            (refused(&y, 4, 2, 1), "u: row stride 2 and pixel stride 2"),
            (refused(&y, 0, 1, 1), "width x height"),
            (refused(&y, MAX_SIDE + 1, 1, 1), "width x height"),
            (refused(&y, 4, 1, 9), "orientation:"),
        ];
        for (said, want) in cases {
            assert!(said.starts_with(want), "{said}");
        }
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

    /// RGB of flat 8 x 8 blocks at quality 100 (4:4:4) decodes within 2 codes everywhere.
    #[test]
    fn an_rgb_still_round_trips() {
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
        let back = decode(&jpeg_from_rgb(&rgb, w, h, 1, 100).unwrap());
        let worst = back.as_raw().iter().zip(&rgb).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        assert!(worst <= 2, "worst {worst}");
    }

    #[test]
    fn bad_encoder_arguments_are_refused_by_name() {
        let rgb = [0u8; 12];
        assert!(jpeg_from_rgb(&rgb, 2, 2, 0, 90).unwrap_err().to_string().starts_with("orientation:"));
        assert!(jpeg_from_rgb(&rgb, 2, 2, 1, 0).unwrap_err().to_string().starts_with("quality:"));
        assert!(jpeg_from_rgb(&rgb[..11], 2, 2, 1, 90).unwrap_err().to_string().starts_with("rgb:"));
    }
}
