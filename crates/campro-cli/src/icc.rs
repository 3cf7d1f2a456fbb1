//! ICC colour profiles as a protected output keeps them: rebuilt from their colour-defining
//! tags alone. A profile is a tag table that can hold any text and any data (a name, a
//! copyright line, a private tag with the raw picture's thumbnail), so it is never passed
//! through: its header is checked (size, `acsp`, class, colour space), and only the tags
//! that define colour (primaries, white and black points, adaptation, tone curves and
//! colour look-up tables), of the numeric types the ICC specification gives them, are
//! copied into a new profile with a description of our own. Anything else (an unknown
//! class or tag type, a tag outside the file, a table too large) drops the profile.

/// The largest profile read (bytes): real camera and display profiles are 0.5–60 KB, and
/// printer profiles with large look-up tables a few MB.
pub const MAX_PROFILE_BYTES: usize = 4 << 20;
/// The most tags a profile may list.
const MAX_TAGS: usize = 100;
/// The header's length (bytes).
const HEADER: usize = 128;

/// Tags that define colour, kept when their type is one of [`NUMERIC_TYPES`]: the red,
/// green and blue primaries and tone curves, the grey curve, the media white and black
/// points, the chromatic adaptation, the colorant chromaticities, and the colour look-up
/// tables of each rendering intent.
const COLOUR_TAGS: [&[u8; 4]; 17] = [
    b"rXYZ", b"gXYZ", b"bXYZ", b"rTRC", b"gTRC", b"bTRC", b"kTRC", b"wtpt", b"bkpt", b"chad", b"chrm", b"A2B0",
    b"A2B1", b"A2B2", b"B2A0", b"B2A1", b"B2A2",
];

/// Tag types that hold numbers only: XYZ, curves, parametric curves, s15Fixed16 arrays,
/// chromaticities and the look-up-table types.
const NUMERIC_TYPES: [&[u8; 4]; 9] = [b"XYZ ", b"curv", b"para", b"sf32", b"chrm", b"mft1", b"mft2", b"mAB ", b"mBA "];

/// Profile classes kept: input (scanner, camera), display, output and colour space.
const CLASSES: [&[u8; 4]; 4] = [b"scnr", b"mntr", b"prtr", b"spac"];
/// Colour spaces kept: the outputs are RGB (a grey profile is kept for a grey photo).
const SPACES: [&[u8; 4]; 2] = [b"RGB ", b"GRAY"];
/// The description written into every rebuilt profile.
pub const DESCRIPTION: &str = "campro: colour tags of the input's profile";

fn be32(b: &[u8], at: usize) -> usize {
    u32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]) as usize
}

/// The profile `icc` rebuilt from its colour-defining tags, or why it is dropped.
pub fn rebuilt(icc: &[u8]) -> Result<Vec<u8>, String> {
    if icc.len() > MAX_PROFILE_BYTES {
        return Err(format!("{} bytes, more than {MAX_PROFILE_BYTES}", icc.len()));
    }
    if icc.len() < HEADER + 4 || be32(icc, 0) != icc.len() || &icc[36..40] != b"acsp" {
        return Err("not an ICC profile (its size field or `acsp` signature does not match)".into());
    }
    let (class, space, pcs) = (&icc[12..16], &icc[16..20], &icc[20..24]);
    if !CLASSES.iter().any(|c| c[..] == *class) || !SPACES.iter().any(|s| s[..] == *space) {
        return Err(format!(
            "a profile of class {:?} for colour space {:?}, not an RGB or grey input, display, output or colour-space profile",
            String::from_utf8_lossy(class),
            String::from_utf8_lossy(space)
        ));
    }
    if pcs != b"XYZ " && pcs != b"Lab " {
        return Err("its connection space is neither XYZ nor Lab".into());
    }
    let count = be32(icc, HEADER);
    if count > MAX_TAGS || HEADER + 4 + 12 * count > icc.len() {
        return Err(format!("a tag table of {count} tags that does not fit the profile"));
    }
    // (signature, its data's range in `icc`) of each kept tag.
    let mut kept: Vec<([u8; 4], std::ops::Range<usize>)> = Vec::new();
    for i in 0..count {
        let e = HEADER + 4 + 12 * i;
        let sig: [u8; 4] = icc[e..e + 4].try_into().expect("4 bytes");
        let (offset, size) = (be32(icc, e + 4), be32(icc, e + 8));
        if !COLOUR_TAGS.iter().any(|t| **t == sig) {
            continue;
        }
        let range = offset
            .checked_add(size)
            .filter(|&end| offset >= HEADER + 4 + 12 * count && end <= icc.len() && size >= 8)
            .map(|end| offset..end)
            .ok_or_else(|| format!("tag {:?} lies outside the profile", String::from_utf8_lossy(&sig)))?;
        let typ = &icc[range.start..range.start + 4];
        if !NUMERIC_TYPES.iter().any(|t| t[..] == *typ) {
            return Err(format!(
                "tag {:?} is of type {:?}, not a colour type",
                String::from_utf8_lossy(&sig),
                String::from_utf8_lossy(typ)
            ));
        }
        if kept.iter().any(|(s, _)| *s == sig) {
            return Err(format!("tag {:?} is listed twice", String::from_utf8_lossy(&sig)));
        }
        kept.push((sig, range));
    }
    if kept.is_empty() {
        return Err("it has no colour-defining tag".into());
    }
    let desc = description(icc[8] >= 4);
    // The new tag table (the kept tags, then our description), then each tag's data at a
    // 4-byte boundary; tags that shared one block of data (rTRC = gTRC = bTRC) share it again.
    let tags: Vec<([u8; 4], &[u8], Option<usize>)> = kept
        .iter()
        .map(|(sig, r)| (*sig, &icc[r.clone()], Some(r.start)))
        .chain(std::iter::once((*b"desc", &desc[..], None)))
        .collect();
    let table = HEADER + 4 + 12 * tags.len();
    let mut out = icc[..HEADER].to_vec();
    out.extend_from_slice(&(tags.len() as u32).to_be_bytes());
    out.resize(table, 0);
    // (the source's offset and size, where the data was written)
    let mut placed: Vec<((usize, usize), usize)> = Vec::new();
    for (i, (sig, data, from)) in tags.iter().enumerate() {
        let shared = from.and_then(|f| placed.iter().find(|(k, _)| *k == (f, data.len())).map(|(_, at)| *at));
        let offset = match shared {
            Some(at) => at,
            None => {
                out.resize(out.len().next_multiple_of(4), 0);
                let at = out.len();
                out.extend_from_slice(data);
                if let Some(f) = from {
                    placed.push(((*f, data.len()), at));
                }
                at
            }
        };
        let e = HEADER + 4 + 12 * i;
        out[e..e + 4].copy_from_slice(sig);
        out[e + 4..e + 8].copy_from_slice(&(offset as u32).to_be_bytes());
        out[e + 8..e + 12].copy_from_slice(&(data.len() as u32).to_be_bytes());
    }
    out.resize(out.len().next_multiple_of(4), 0);
    let size = out.len() as u32;
    out[0..4].copy_from_slice(&size.to_be_bytes());
    // The profile id (an MD5 of the old content) is no longer right: zero says "not computed".
    out[84..100].fill(0);
    Ok(out)
}

/// The `desc` tag of a rebuilt profile: `textDescriptionType` (version 2) or
/// `multiLocalizedUnicodeType` (version 4), saying [`DESCRIPTION`].
fn description(version4: bool) -> Vec<u8> {
    let text = DESCRIPTION.as_bytes();
    let mut d = Vec::new();
    if version4 {
        d.extend_from_slice(b"mluc\0\0\0\0");
        d.extend_from_slice(&1u32.to_be_bytes()); // one record
        d.extend_from_slice(&12u32.to_be_bytes()); // of 12 bytes
        d.extend_from_slice(b"enUS");
        d.extend_from_slice(&(2 * text.len() as u32).to_be_bytes());
        d.extend_from_slice(&28u32.to_be_bytes()); // the string right after the record
        for &c in text {
            d.extend_from_slice(&[0, c]);
        }
    } else {
        d.extend_from_slice(b"desc\0\0\0\0");
        d.extend_from_slice(&(text.len() as u32 + 1).to_be_bytes());
        d.extend_from_slice(text);
        d.push(0);
        d.extend_from_slice(&[0; 8]); // no Unicode description
        d.extend_from_slice(&[0; 3]); // no ScriptCode description
        d.extend_from_slice(&[0; 67]);
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A profile: header (version `v`, class `mntr`, RGB, XYZ), then `tags` in order, each
    /// its (signature, data).
    fn profile(v: u8, tags: &[(&[u8; 4], Vec<u8>)]) -> Vec<u8> {
        let mut h = vec![0u8; HEADER];
        h[8] = v;
        h[12..16].copy_from_slice(b"mntr");
        h[16..20].copy_from_slice(b"RGB ");
        h[20..24].copy_from_slice(b"XYZ ");
        h[36..40].copy_from_slice(b"acsp");
        h[84..100].fill(9);
        h.extend_from_slice(&(tags.len() as u32).to_be_bytes());
        let mut at = HEADER + 4 + 12 * tags.len();
        let mut table = Vec::new();
        let mut data = Vec::new();
        for (sig, d) in tags {
            table.extend_from_slice(&sig[..]);
            table.extend_from_slice(&(at as u32).to_be_bytes());
            table.extend_from_slice(&(d.len() as u32).to_be_bytes());
            data.extend_from_slice(d);
            at += d.len();
        }
        h.extend(table);
        h.extend(data);
        let n = h.len() as u32;
        h[0..4].copy_from_slice(&n.to_be_bytes());
        h
    }

    fn xyz(x: i32) -> Vec<u8> {
        let mut d = b"XYZ \0\0\0\0".to_vec();
        for v in [x, x + 1, x + 2] {
            d.extend_from_slice(&v.to_be_bytes());
        }
        d
    }

    fn curve(gamma: u16) -> Vec<u8> {
        let mut d = b"curv\0\0\0\0".to_vec();
        d.extend_from_slice(&1u32.to_be_bytes());
        d.extend_from_slice(&gamma.to_be_bytes());
        d
    }

    /// Reads a rebuilt profile's tags back: (signature, data).
    fn tags_of(icc: &[u8]) -> Vec<([u8; 4], Vec<u8>)> {
        (0..be32(icc, HEADER))
            .map(|i| {
                let e = HEADER + 4 + 12 * i;
                let (o, n) = (be32(icc, e + 4), be32(icc, e + 8));
                (icc[e..e + 4].try_into().unwrap(), icc[o..o + n].to_vec())
            })
            .collect()
    }

    fn text(s: &str) -> Vec<u8> {
        let mut d = b"text\0\0\0\0".to_vec();
        d.extend_from_slice(s.as_bytes());
        d
    }

    #[test]
    fn the_colour_tags_are_kept_and_everything_else_is_gone() {
        let jpeg = [&[0xFF, 0xD8, 0xFF, 0xE0][..], b"JFIF thumbnail of the raw picture"].concat();
        let icc = profile(
            2,
            &[
                (b"desc", text("Alice Example's camera")),
                (b"rXYZ", xyz(1)),
                (b"gXYZ", xyz(10)),
                (b"bXYZ", xyz(20)),
                (b"wtpt", xyz(30)),
                (b"rTRC", curve(0x0233)),
                (b"cprt", text("(c) Alice Example")),
                (b"zzzz", [&b"zzzz\0\0\0\0"[..], &jpeg].concat()),
                (b"gTRC", curve(0x0233)),
                (b"bTRC", curve(0x0233)),
            ],
        );
        let out = rebuilt(&icc).unwrap();
        // Header kept but for the size and the profile id.
        assert_eq!(be32(&out, 0), out.len());
        assert_eq!(&out[4..84], &icc[4..84]);
        assert_eq!(&out[84..100], &[0; 16]);
        let tags = tags_of(&out);
        let sigs: Vec<&[u8; 4]> = tags.iter().map(|t| &t.0).collect();
        assert_eq!(sigs, [b"rXYZ", b"gXYZ", b"bXYZ", b"wtpt", b"rTRC", b"gTRC", b"bTRC", b"desc"]);
        // Each kept tag's data is the input's, byte for byte.
        assert_eq!(tags[0].1, xyz(1));
        assert_eq!(tags[4].1, curve(0x0233));
        // No name, copyright or picture survives anywhere in the file.
        for gone in [&b"Alice"[..], b"JFIF", &[0xFF, 0xD8]] {
            assert!(!out.windows(gone.len()).any(|w| w == gone), "{:?} kept", String::from_utf8_lossy(gone));
        }
        // The description is ours; version 4 gets an mluc one.
        assert!(tags[7].1.starts_with(b"desc") && tags[7].1.windows(6).any(|w| w == b"campro"));
        let v4 = rebuilt(&profile(4, &[(b"rXYZ", xyz(1)), (b"desc", text("Bob"))])).unwrap();
        let d = &tags_of(&v4)[1].1;
        assert!(d.starts_with(b"mluc") && !v4.windows(3).any(|w| w == b"Bob"));
        assert_eq!(d.len(), 28 + 2 * DESCRIPTION.len());
    }

    #[test]
    fn a_profile_that_hides_data_in_a_colour_tag_or_lies_is_dropped() {
        // A colour tag of a text type (a name where a curve should be).
        let e = rebuilt(&profile(2, &[(b"rTRC", text("Alice"))])).unwrap_err();
        assert!(e.contains("not a colour type"), "{e}");
        // The size field lies.
        let mut icc = profile(2, &[(b"rXYZ", xyz(1))]);
        icc.push(0);
        assert!(rebuilt(&icc).unwrap_err().contains("not an ICC profile"));
        // A tag pointing past the end.
        let mut icc = profile(2, &[(b"rXYZ", xyz(1))]);
        let e = HEADER + 4 + 8;
        icc[e..e + 4].copy_from_slice(&4000u32.to_be_bytes());
        assert!(rebuilt(&icc).unwrap_err().contains("outside the profile"));
        // A CMYK or an abstract profile, or one with no colour tag.
        let mut icc = profile(2, &[(b"rXYZ", xyz(1))]);
        icc[16..20].copy_from_slice(b"CMYK");
        assert!(rebuilt(&icc).unwrap_err().contains("colour space"));
        assert!(rebuilt(&profile(2, &[(b"desc", text("x"))])).unwrap_err().contains("no colour-defining tag"));
        // Too many tags for the file, and a truncated header.
        let mut icc = profile(2, &[(b"rXYZ", xyz(1))]);
        icc[HEADER..HEADER + 4].copy_from_slice(&99u32.to_be_bytes());
        assert!(rebuilt(&icc).unwrap_err().contains("does not fit"));
        assert!(rebuilt(&[0; 40]).is_err());
    }
}
