//! What a protected photo keeps of its input's metadata (`simulate --metadata`).
//!
//! The camera protects pixels; metadata can give the same person away (where: GPS; who:
//! serial numbers, owner names; and the face itself: an EXIF thumbnail or a maker note's
//! preview is the *unprotected* picture, small). So:
//! - `keep-safe` (the default) keeps the date and time, the camera and lens make and model,
//!   the exposure settings and the colour space, and the ICC colour profile's colour; it
//!   drops GPS, maker notes, serial numbers, owner names, comments, unique ids, XMP and
//!   thumbnails. A field is kept only with the type and size the EXIF standard gives its tag
//!   (a date field holding a picture is dropped).
//! - `keep` keeps every field of the main image directory that EXIF defines (GPS too), of a
//!   standard type and at most [`MAX_FIELD_BYTES`]; still never the thumbnail, a maker note
//!   or a container (XMP, IPTC, Photoshop's resources, another profile, private tags), which
//!   can hold the unprotected picture.
//! - `strip` keeps nothing.
//!
//! The ICC profile is never copied: it is rebuilt from its colour-defining tags alone
//! ([`crate::icc`]), and dropped with a warning when it is not a profile that can be.
//!
//! The pixels are turned by the input's orientation when read, so every output says
//! orientation 1. EXIF is read with `kamadak-exif`: the fields it can read are kept even when
//! the block's structure is off (a writer such as Python's piexif leaves no next-directory
//! pointer after the Exif directory), an unreadable or oversized block is dropped with a
//! warning, never failing the image; the fields are written back as a fresh TIFF block.

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

/// Fields never written, whatever the policy: they can hold the unprotected picture or any
/// data (the maker note; the containers of XMP, IPTC, Photoshop's image resources, an ICC
/// profile and the printer's private data; the user comment's free bytes), or are rewritten
/// (orientation).
const NEVER: &[u16] = &[
    0x927C, // MakerNote
    0x0112, // Orientation
    0x02BC, // XMP
    0x83BB, // IPTC-NAA
    0x8649, // Photoshop image resources
    0x8773, // InterColorProfile
    0xC4A5, // PrintImageMatching
    0xC634, // DNGPrivateData
    0x9286, // UserComment
    0x9C9B, 0x9C9C, 0x9C9D, 0x9C9E, 0x9C9F, // Windows XP title, comment, author, keywords, subject
];

/// The largest field `keep` keeps (bytes of its value): text and number fields are short;
/// anything larger is a container.
pub const MAX_FIELD_BYTES: usize = 1024;

/// What EXIF says a `keep-safe` field is: its type, and how many values (at most).
fn safe_shape(tag: Tag, value: &Value) -> bool {
    let ascii = |max: usize| matches!(value, Value::Ascii(v) if v.len() == 1 && v[0].len() <= max && v[0].iter().all(|&c| (0x20..0x7F).contains(&c)));
    let date = matches!(value, Value::Ascii(v) if v.len() == 1 && v[0].len() == 19 && v[0].iter().all(|&c| c.is_ascii_digit() || c == b':' || c == b' '));
    let one_rational = matches!(value, Value::Rational(v) if v.len() == 1);
    let shorts = |max: usize| matches!(value, Value::Short(v) if !v.is_empty() && v.len() <= max);
    match tag {
        Tag::Make | Tag::Model | Tag::LensMake | Tag::LensModel => ascii(64),
        Tag::DateTime | Tag::DateTimeOriginal | Tag::DateTimeDigitized => date,
        Tag::OffsetTime | Tag::OffsetTimeOriginal | Tag::OffsetTimeDigitized => ascii(6),
        Tag::SubSecTime | Tag::SubSecTimeOriginal | Tag::SubSecTimeDigitized => {
            matches!(value, Value::Ascii(v) if v.len() == 1 && v[0].len() <= 9 && v[0].iter().all(|c| c.is_ascii_digit() || *c == b' '))
        }
        Tag::ExposureTime | Tag::FNumber | Tag::FocalLength => one_rational,
        Tag::ExposureBiasValue => matches!(value, Value::SRational(v) if v.len() == 1),
        Tag::PhotographicSensitivity => shorts(2) || matches!(value, Value::Long(v) if v.len() == 1),
        Tag::FocalLengthIn35mmFilm | Tag::Flash | Tag::ColorSpace => shorts(1),
        _ => false,
    }
}

/// Whether `keep` keeps a field: a tag EXIF defines, of a standard type (no undefined bytes
/// but the short version and setting fields), at most [`MAX_FIELD_BYTES`] of value.
fn keep_shape(f: &Field) -> bool {
    let bytes = match &f.value {
        Value::Byte(v) => v.len(),
        Value::SByte(v) => v.len(),
        // Text: UTF-8 (what cameras write beyond ASCII) without control characters.
        Value::Ascii(v) if v.iter().all(|s| std::str::from_utf8(s).is_ok_and(|t| !t.chars().any(char::is_control))) => {
            v.iter().map(|s| s.len() + 1).sum()
        }
        Value::Ascii(_) => return false,
        Value::Short(v) => 2 * v.len(),
        Value::SShort(v) => 2 * v.len(),
        Value::Long(v) => 4 * v.len(),
        Value::SLong(v) => 4 * v.len(),
        Value::Rational(v) => 8 * v.len(),
        Value::SRational(v) => 8 * v.len(),
        Value::Float(v) => 4 * v.len(),
        Value::Double(v) => 8 * v.len(),
        // Short version and setting fields (ExifVersion, SceneType …): 4 bytes at most.
        Value::Undefined(v, _) if v.len() <= 4 => v.len(),
        Value::Undefined(..) | Value::Unknown(..) => return false,
    };
    f.tag.description().is_some() && bytes <= MAX_FIELD_BYTES
}

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
    let exif = exif.and_then(|raw| match filtered(policy, raw, warn) {
        Ok(v) => v,
        Err(e) => {
            warn(&format!("its EXIF block is dropped ({e})"));
            None
        }
    });
    let icc = icc.and_then(|p| match crate::icc::rebuilt(&p) {
        Ok(p) => Some(p),
        Err(e) => {
            warn(&format!("its ICC profile is dropped ({e})"));
            None
        }
    });
    Kept { exif, icc }
}

/// The fields of `raw` that `policy` keeps, with orientation 1, as a new block; None when
/// none is kept. A block whose structure is off keeps the fields that could be read
/// (`warn` hears what was wrong).
fn filtered(policy: Policy, raw: &[u8], warn: &dyn Fn(&str)) -> Result<Option<Vec<u8>>, String> {
    if raw.len() > MAX_EXIF_BYTES {
        return Err(format!("{} bytes, more than {MAX_EXIF_BYTES}", raw.len()));
    }
    let (exif, errors) = match exif::Reader::new().continue_on_error(true).read_raw(raw.to_vec()) {
        Ok(exif) => (exif, Vec::new()),
        Err(e) => {
            let mut said = Vec::new();
            let exif = e
                .distill_partial_result(|errors| said = errors.iter().map(|e| e.to_string()).collect())
                .map_err(|e| e.to_string())?;
            (exif, said)
        }
    };
    if !errors.is_empty() {
        if exif.fields().next().is_none() {
            return Err(errors.join("; "));
        }
        warn(&format!("its EXIF block is read in part ({})", errors.join("; ")));
    }
    let keep = |f: &&Field| {
        f.ifd_num == In::PRIMARY
            && !NEVER.contains(&f.tag.number())
            && match policy {
                Policy::KeepSafe => SAFE.contains(&f.tag) && safe_shape(f.tag, &f.value),
                Policy::Keep => keep_shape(f) && (!SAFE.contains(&f.tag) || safe_shape(f.tag, &f.value)),
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
        let k = kept(Policy::KeepSafe, Some(&sample()), None, &|w| panic!("{w}"));
        let t = tags(k.exif.as_deref().unwrap());
        let names: Vec<Tag> = t.iter().map(|x| x.0).collect();
        assert!(names.contains(&Tag::Make) && names.contains(&Tag::DateTimeOriginal), "{t:?}");
        for gone in [Tag::GPSLatitude, Tag::BodySerialNumber, Tag::MakerNote, Tag::ImageDescription] {
            assert!(!names.contains(&gone), "{gone} kept: {t:?}");
        }
        assert!(t.iter().all(|x| x.1 == In::PRIMARY), "no thumbnail directory: {t:?}");
        assert!(t.contains(&(Tag::Orientation, In::PRIMARY, "row 0 at top and column 0 at left".into())), "{t:?}");
        // A profile that is not one is dropped, with a warning.
        let said = std::cell::RefCell::new(Vec::new());
        let k = kept(Policy::KeepSafe, None, Some(vec![1, 2, 3]), &|w| said.borrow_mut().push(w.to_string()));
        assert_eq!(k.icc, None);
        assert!(said.borrow()[0].starts_with("its ICC profile is dropped"), "{:?}", said.borrow());
    }

    #[test]
    fn keep_keeps_gps_but_never_the_maker_note_or_thumbnail() {
        let t = tags(kept(Policy::Keep, Some(&sample()), None, &|w| panic!("{w}")).exif.as_deref().unwrap());
        let names: Vec<Tag> = t.iter().map(|x| x.0).collect();
        assert!(names.contains(&Tag::GPSLatitude) && names.contains(&Tag::BodySerialNumber), "{t:?}");
        assert!(!names.contains(&Tag::MakerNote) && !names.contains(&Tag::ImageDescription), "{t:?}");
        assert_eq!(t.iter().filter(|x| x.0 == Tag::Orientation).count(), 1);
    }

    /// What Python's piexif 1.1.3 writes for `{"0th": {Make: "Canon", Model: "EOS",
    /// DateTime}, "Exif": {DateTimeOriginal}, "GPS": {GPSLatitudeRef: "N", GPSLatitude:
    /// 48/1 51/1 0/1}}` (`piexif.dump`, the `Exif\0\0` prefix cut): its Exif and GPS
    /// directories have no next-directory pointer (their values follow at once), which
    /// kamadak-exif reads as "Unexpected next IFD".
    const PIEXIF: &str = "4d4d002a000000080005010f0002000000060000004a0110000200000004454f53000132000200000014000000508769000400000001000000648825000400000001000000860000000043616e6f6e00323032343a30353a30312031303a31313a3132000001900300020000001400000072323032343a30353a30312031303a31313a313200000200010002000000024e0000000002000500000003000000a0000000300000000100000033000000010000000000000001";

    fn unhex(s: &str) -> Vec<u8> {
        (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap()).collect()
    }

    #[test]
    fn piexif_written_exif_keeps_its_readable_fields() {
        let said = std::cell::RefCell::new(Vec::new());
        let warn = |w: &str| said.borrow_mut().push(w.to_string());
        let k = kept(Policy::KeepSafe, Some(&unhex(PIEXIF)), None, &warn);
        let t = tags(k.exif.as_deref().expect("the block is kept"));
        let value = |tag: Tag| t.iter().find(|x| x.0 == tag).map(|x| x.2.clone());
        assert_eq!(value(Tag::DateTimeOriginal).as_deref(), Some("2024-05-01 10:11:12"), "{t:?}");
        assert_eq!(value(Tag::DateTime).as_deref(), Some("2024-05-01 10:11:12"));
        assert_eq!(value(Tag::Make).as_deref(), Some("\"Canon\""));
        assert_eq!(value(Tag::GPSLatitude), None, "keep-safe never keeps GPS");
        assert!(said.borrow().iter().any(|w| w.contains("read in part")), "{:?}", said.borrow());
        let k = kept(Policy::Keep, Some(&unhex(PIEXIF)), None, &warn);
        assert!(tags(k.exif.as_deref().unwrap()).iter().any(|x| x.0 == Tag::GPSLatitude));
    }

    #[test]
    fn a_field_is_kept_only_with_the_type_and_size_its_tag_has() {
        let jpeg = [&[0xFF, 0xD8, 0xFF, 0xE0][..], &[7; 600]].concat();
        let fields = [
            // A date field holding a picture, a make of 3 KB, a flash of the wrong type.
            Field { tag: Tag::DateTimeOriginal, ifd_num: In::PRIMARY, value: Value::Ascii(vec![jpeg.clone()]) },
            Field { tag: Tag::Make, ifd_num: In::PRIMARY, value: Value::Ascii(vec![vec![b'A'; 3000]]) },
            Field { tag: Tag::Flash, ifd_num: In::PRIMARY, value: Value::Undefined(jpeg.clone(), 0) },
            // Containers and a private tag: XMP, Photoshop resources, tag 0xABCD.
            Field { tag: Tag(exif::Context::Tiff, 0x02BC), ifd_num: In::PRIMARY, value: Value::Byte(jpeg.clone()) },
            Field { tag: Tag(exif::Context::Tiff, 0x8649), ifd_num: In::PRIMARY, value: Value::Byte(jpeg.clone()) },
            Field {
                tag: Tag(exif::Context::Tiff, 0xABCD),
                ifd_num: In::PRIMARY,
                value: Value::Ascii(vec![b"Alice".to_vec()]),
            },
            // Well-formed ones.
            Field { tag: Tag::Model, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"Phone 9".to_vec()]) },
            Field { tag: Tag::Artist, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"Alice".to_vec()]) },
        ];
        let mut w = exif::experimental::Writer::new();
        fields.iter().for_each(|f| w.push_field(f));
        let mut block = std::io::Cursor::new(Vec::new());
        w.write(&mut block, false).unwrap();
        let block = block.into_inner();
        let no = |w: &str| panic!("{w}");
        let safe: Vec<Tag> = tags(kept(Policy::KeepSafe, Some(&block), None, &no).exif.as_deref().unwrap())
            .iter()
            .map(|x| x.0)
            .collect();
        assert_eq!(safe, [Tag::Model, Tag::Orientation]);
        let all = kept(Policy::Keep, Some(&block), None, &no).exif.unwrap();
        let kept_tags: Vec<Tag> = tags(&all).iter().map(|x| x.0).collect();
        assert_eq!(
            kept_tags,
            [Tag::Model, Tag::Orientation, Tag::Artist],
            "no container, no private tag, no oversized or mistyped field"
        );
        assert!(!all.windows(2).any(|w| w == [0xFF, 0xD8]), "no picture in the block");
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
