//! What a protected photo keeps of its input's metadata (`simulate --metadata`).
//!
//! The camera protects pixels; metadata can give the same person away (where: GPS; who:
//! serial numbers, owner names; and the face itself: an EXIF thumbnail or a maker note's
//! preview is the *unprotected* picture, small). So:
//! - `keep-safe` (the default) keeps the date and time, the camera and lens make and model,
//!   the exposure settings and the colour space, and the ICC colour profile; it drops GPS,
//!   maker notes, serial numbers, owner names, comments, unique ids, XMP and thumbnails.
//! - `keep` keeps every field of the main image directory (GPS too), still never the
//!   thumbnail or a maker note, which can hold the unprotected picture.
//! - `strip` keeps nothing.
//!
//! The pixels are turned by the input's orientation when read, so every output says
//! orientation 1. EXIF is read with `kamadak-exif` (a bad or oversized block is dropped with
//! a warning, never failing the image) and written back as a fresh TIFF block.

use exif::{Field, In, Tag, Value};

/// Largest EXIF block read (JPEG's APP1 holds 64 KiB; other containers are capped here).
pub const MAX_EXIF_BYTES: usize = 1 << 20;

/// The `--metadata` policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Policy {
    /// Nothing of the input's metadata.
    Strip,
    /// Date, camera, lens, exposure, colour space and colour profile; no GPS, maker notes,
    /// serial numbers, names, comments or thumbnails.
    #[default]
    KeepSafe,
    /// Every field of the main image (GPS too), but never a thumbnail or maker note.
    Keep,
}

/// Fields `keep-safe` keeps.
const SAFE: &[Tag] = &[
    Tag::Make,
    Tag::Model,
    Tag::DateTime,
    Tag::DateTimeOriginal,
    Tag::DateTimeDigitized,
    Tag::OffsetTime,
    Tag::OffsetTimeOriginal,
    Tag::OffsetTimeDigitized,
    Tag::SubSecTime,
    Tag::SubSecTimeOriginal,
    Tag::SubSecTimeDigitized,
    Tag::LensMake,
    Tag::LensModel,
    Tag::ExposureTime,
    Tag::FNumber,
    Tag::PhotographicSensitivity,
    Tag::ExposureBiasValue,
    Tag::FocalLength,
    Tag::FocalLengthIn35mmFilm,
    Tag::Flash,
    Tag::ColorSpace,
];

/// Fields never written, whatever the policy: they can hold the unprotected picture.
const NEVER: &[Tag] = &[Tag::MakerNote, Tag::Orientation];

/// What an output keeps of its input's metadata.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Kept {
    /// A TIFF-structured EXIF block (no `Exif\0\0` prefix), as the image encoders take it.
    pub exif: Option<Vec<u8>>,
    /// The ICC colour profile.
    pub icc: Option<Vec<u8>>,
}

/// The metadata an output keeps under `policy`, from the input's EXIF block and ICC profile;
/// `warn` hears about an EXIF block that could not be read (it is then dropped).
pub fn kept(policy: Policy, exif: Option<&[u8]>, icc: Option<Vec<u8>>, warn: &dyn Fn(&str)) -> Kept {
    if policy == Policy::Strip {
        return Kept::default();
    }
    let exif = exif.and_then(|raw| match filtered(policy, raw) {
        Ok(v) => v,
        Err(e) => {
            warn(&format!("its EXIF block is dropped ({e})"));
            None
        }
    });
    Kept { exif, icc }
}

/// The fields of `raw` that `policy` keeps, with orientation 1, as a new block; None when
/// none is kept.
fn filtered(policy: Policy, raw: &[u8]) -> Result<Option<Vec<u8>>, String> {
    if raw.len() > MAX_EXIF_BYTES {
        return Err(format!("{} bytes, more than {MAX_EXIF_BYTES}", raw.len()));
    }
    let exif = exif::Reader::new().read_raw(raw.to_vec()).map_err(|e| e.to_string())?;
    let keep = |f: &&Field| {
        f.ifd_num == In::PRIMARY
            && !NEVER.contains(&f.tag)
            && match policy {
                Policy::KeepSafe => SAFE.contains(&f.tag),
                Policy::Keep => true,
                Policy::Strip => false,
            }
    };
    let fields: Vec<&Field> = exif.fields().filter(keep).collect();
    if fields.is_empty() {
        return Ok(None);
    }
    let upright = Field { tag: Tag::Orientation, ifd_num: In::PRIMARY, value: Value::Short(vec![1]) };
    let mut w = exif::experimental::Writer::new();
    for f in &fields {
        w.push_field(f);
    }
    w.push_field(&upright);
    let mut out = std::io::Cursor::new(Vec::new());
    w.write(&mut out, exif.little_endian()).map_err(|e| e.to_string())?;
    Ok(Some(out.into_inner()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block with a field of each kind: safe (Make, DateTimeOriginal), personal (GPS
    /// latitude, BodySerialNumber), a maker note, orientation 6 and a thumbnail's field.
    fn sample() -> Vec<u8> {
        let fields = [
            Field { tag: Tag::Make, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"Phone".to_vec()]) },
            Field { tag: Tag::Orientation, ifd_num: In::PRIMARY, value: Value::Short(vec![6]) },
            Field {
                tag: Tag::DateTimeOriginal,
                ifd_num: In::PRIMARY,
                value: Value::Ascii(vec![b"2026:12:06 09:00:00".to_vec()]),
            },
            Field { tag: Tag::BodySerialNumber, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"SN123".to_vec()]) },
            Field { tag: Tag::MakerNote, ifd_num: In::PRIMARY, value: Value::Undefined(vec![7; 40], 0) },
            Field {
                tag: Tag::GPSLatitude,
                ifd_num: In::PRIMARY,
                value: Value::Rational(vec![(48, 1).into(), (12, 1).into(), (0, 1).into()]),
            },
            Field { tag: Tag::ImageDescription, ifd_num: In::THUMBNAIL, value: Value::Ascii(vec![b"thumb".to_vec()]) },
        ];
        let mut w = exif::experimental::Writer::new();
        fields.iter().for_each(|f| w.push_field(f));
        let mut out = std::io::Cursor::new(Vec::new());
        w.write(&mut out, false).unwrap();
        out.into_inner()
    }

    fn tags(block: &[u8]) -> Vec<(Tag, In, String)> {
        let e = exif::Reader::new().read_raw(block.to_vec()).unwrap();
        e.fields().map(|f| (f.tag, f.ifd_num, f.display_value().to_string())).collect()
    }

    #[test]
    fn keep_safe_keeps_the_date_and_camera_and_nothing_personal() {
        let k = kept(Policy::KeepSafe, Some(&sample()), Some(vec![1, 2, 3]), &|w| panic!("{w}"));
        let t = tags(k.exif.as_deref().unwrap());
        let names: Vec<Tag> = t.iter().map(|x| x.0).collect();
        assert!(names.contains(&Tag::Make) && names.contains(&Tag::DateTimeOriginal), "{t:?}");
        for gone in [Tag::GPSLatitude, Tag::BodySerialNumber, Tag::MakerNote, Tag::ImageDescription] {
            assert!(!names.contains(&gone), "{gone} kept: {t:?}");
        }
        assert!(t.iter().all(|x| x.1 == In::PRIMARY), "no thumbnail directory: {t:?}");
        assert!(t.contains(&(Tag::Orientation, In::PRIMARY, "row 0 at top and column 0 at left".into())), "{t:?}");
        assert_eq!(k.icc, Some(vec![1, 2, 3]));
    }

    #[test]
    fn keep_keeps_gps_but_never_the_maker_note_or_thumbnail() {
        let t = tags(kept(Policy::Keep, Some(&sample()), None, &|w| panic!("{w}")).exif.as_deref().unwrap());
        let names: Vec<Tag> = t.iter().map(|x| x.0).collect();
        assert!(names.contains(&Tag::GPSLatitude) && names.contains(&Tag::BodySerialNumber), "{t:?}");
        assert!(!names.contains(&Tag::MakerNote) && !names.contains(&Tag::ImageDescription), "{t:?}");
        assert_eq!(t.iter().filter(|x| x.0 == Tag::Orientation).count(), 1);
    }

    #[test]
    fn strip_keeps_nothing_and_a_bad_block_is_dropped_with_a_warning() {
        assert_eq!(kept(Policy::Strip, Some(&sample()), Some(vec![1]), &|_| {}), Kept::default());
        let said = std::cell::RefCell::new(Vec::new());
        let k = kept(Policy::KeepSafe, Some(b"II*\0garbage"), None, &|w| said.borrow_mut().push(w.to_string()));
        assert_eq!(k.exif, None);
        assert!(said.borrow()[0].starts_with("its EXIF block is dropped"), "{:?}", said.borrow());
    }
}
