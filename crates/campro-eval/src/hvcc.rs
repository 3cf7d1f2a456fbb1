//! The picture sizes a HEIF file's HEVC streams really code, read before libheif decodes
//! anything: libheif (1.15, Debian's) checks only the size the file *declares* (`ispe`), so a
//! file declaring 64 x 64 whose SPS codes 60000 x 60000 pictures would have its decoder
//! allocate gigabytes (libheif's open issue #1220). Walks `meta` → `iprp` → `ipco`, and of
//! each `hvcC` (ISO/IEC 14496-15 §8.3.3) reads its sequence parameter sets (H.265 §7.3.2.2)
//! as far as `pic_width_in_luma_samples` and `pic_height_in_luma_samples`.
//!
//! Bounds: only those three boxes are entered (no recursion beyond), at most
//! [`MAX_PROPERTIES`] properties and [`MAX_NALS`] parameter sets are read, every length is
//! checked against what is left, and a parameter set is read bit by bit without copying more
//! than its own bytes. Anything malformed is a one-line reason, never a panic.

/// Properties of `ipco` read, at most.
pub const MAX_PROPERTIES: usize = 4096;
/// Parameter sets of all `hvcC`s read, at most.
pub const MAX_NALS: usize = 1024;
/// HEVC's `nal_unit_type` of a sequence parameter set.
const SPS: u8 = 33;

/// What the file declares (`ispe`) and what its HEVC streams code (each SPS), pixels.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Sizes {
    /// Every `ispe` (image spatial extents) property: width, height.
    pub declared: Vec<(u32, u32)>,
    /// Every SPS of every `hvcC`: `pic_width_in_luma_samples`, `pic_height_in_luma_samples`.
    pub coded: Vec<(u32, u32)>,
}

impl Sizes {
    /// The largest declared extent in each direction (0 when none).
    pub fn declared_max(&self) -> (u32, u32) {
        self.declared.iter().fold((0, 0), |(w, h), &(a, b)| (w.max(a), h.max(b)))
    }

    /// Why the coded pictures are not what the file declares, or `None` when each coded
    /// picture fits its largest declaration plus one coding tree block (64 pixels: coded
    /// sizes are whole blocks, cropped by the conformance window).
    pub fn mismatch(&self) -> Option<String> {
        let (w, h) = self.declared_max();
        self.coded.iter().find(|&&(cw, ch)| u64::from(cw) > u64::from(w) + 64 || u64::from(ch) > u64::from(h) + 64).map(
            |(cw, ch)| {
                format!("its HEVC stream codes {cw} x {ch} pictures, more than the {w} x {h} it declares (ispe): refused as a decompression bomb")
            },
        )
    }
}

fn be32(b: &[u8], at: usize) -> Option<u32> {
    b.get(at..at + 4).map(|s| u32::from_be_bytes([s[0], s[1], s[2], s[3]]))
}

fn be16(b: &[u8], at: usize) -> Option<usize> {
    b.get(at..at + 2).map(|s| usize::from(u16::from_be_bytes([s[0], s[1]])))
}

/// A container's boxes: (type, payload), in order.
type Boxes<'a> = Vec<([u8; 4], &'a [u8])>;

/// The boxes in `b` (a container's payload); a box whose size overruns its container is an error.
fn boxes(b: &[u8]) -> Result<Boxes<'_>, String> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while at + 8 <= b.len() {
        let size = be32(b, at).ok_or("a box header is cut short")? as u64;
        let kind: [u8; 4] = b[at + 4..at + 8].try_into().expect("four bytes");
        let (header, size) = match size {
            0 => (8u64, (b.len() - at) as u64),
            1 => (
                16,
                b.get(at + 8..at + 16)
                    .map(|s| u64::from_be_bytes(s.try_into().expect("eight bytes")))
                    .ok_or("a large box's size is cut short")?,
            ),
            s => (8, s),
        };
        if size < header || size > (b.len() - at) as u64 {
            return Err(format!(
                "box '{}' claims {size} bytes, more than its container holds",
                String::from_utf8_lossy(&kind)
            ));
        }
        out.push((kind, &b[at + header as usize..at + size as usize]));
        if out.len() > MAX_PROPERTIES {
            return Err(format!("more than {MAX_PROPERTIES} boxes in one container"));
        }
        at += size as usize;
    }
    Ok(out)
}

fn child<'a>(list: &[([u8; 4], &'a [u8])], kind: &[u8; 4]) -> Option<&'a [u8]> {
    list.iter().find(|(k, _)| k == kind).map(|(_, p)| *p)
}

/// The declared and coded sizes of a HEIF file (`bytes` whole); an error names what is malformed.
pub fn sizes(bytes: &[u8]) -> Result<Sizes, String> {
    let top = boxes(bytes)?;
    let meta = child(&top, b"meta").ok_or("no 'meta' box")?;
    // `meta` is a full box: version and flags come first.
    let meta = boxes(meta.get(4..).ok_or("'meta' is cut short")?)?;
    let Some(iprp) = child(&meta, b"iprp") else { return Ok(Sizes::default()) };
    let iprp = boxes(iprp)?;
    let Some(ipco) = child(&iprp, b"ipco") else { return Ok(Sizes::default()) };
    let mut s = Sizes::default();
    let mut nals = 0usize;
    for (kind, p) in boxes(ipco)? {
        match &kind {
            b"ispe" => {
                // Full box, then width and height.
                let (w, h) = (be32(p, 4).ok_or("'ispe' is cut short")?, be32(p, 8).ok_or("'ispe' is cut short")?);
                s.declared.push((w, h));
            }
            b"hvcC" => {
                for sps in parameter_sets(p, &mut nals)? {
                    s.coded.push(coded_size(&sps)?);
                }
            }
            _ => {}
        }
    }
    Ok(s)
}

/// The SPS NAL units of an `hvcC` payload (their bytes after the two-byte NAL header, with
/// emulation-prevention bytes removed).
fn parameter_sets(p: &[u8], nals: &mut usize) -> Result<Vec<Vec<u8>>, String> {
    const HEADER: usize = 23;
    let arrays = *p.get(HEADER - 1).ok_or("'hvcC' is cut short")? as usize;
    let mut at = HEADER;
    let mut out = Vec::new();
    for _ in 0..arrays {
        let kind = p.get(at).ok_or("an 'hvcC' array is cut short")? & 0x3f;
        let count = be16(p, at + 1).ok_or("an 'hvcC' array is cut short")?;
        at += 3;
        for _ in 0..count {
            *nals += 1;
            if *nals > MAX_NALS {
                return Err(format!("more than {MAX_NALS} parameter sets"));
            }
            let len = be16(p, at).ok_or("an 'hvcC' parameter set is cut short")?;
            let nal = p.get(at + 2..at + 2 + len).ok_or("an 'hvcC' parameter set runs past its box")?;
            at += 2 + len;
            if kind == SPS {
                out.push(unescape(nal.get(2..).ok_or("an SPS without its header")?));
            }
        }
    }
    Ok(out)
}

/// The RBSP of a NAL payload: every `00 00 03` loses its `03` (H.265 §7.4.2).
fn unescape(b: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(b.len());
    let mut zeros = 0;
    for &x in b {
        if zeros >= 2 && x == 3 {
            zeros = 0;
            continue;
        }
        zeros = if x == 0 { zeros + 1 } else { 0 };
        out.push(x);
    }
    out
}

/// Reads bits, most significant first.
struct Bits<'a> {
    b: &'a [u8],
    at: usize,
}

impl Bits<'_> {
    fn u(&mut self, n: u32) -> Result<u32, String> {
        let mut v = 0u32;
        for _ in 0..n {
            let byte = *self.b.get(self.at / 8).ok_or("the SPS ends early")?;
            v = (v << 1) | u32::from((byte >> (7 - self.at % 8)) & 1);
            self.at += 1;
        }
        Ok(v)
    }

    fn skip(&mut self, n: usize) -> Result<(), String> {
        self.at += n;
        if self.at > 8 * self.b.len() {
            return Err("the SPS ends early".into());
        }
        Ok(())
    }

    /// An unsigned Exp-Golomb code (at most 32 leading zeros: a value that fits in u32).
    fn ue(&mut self) -> Result<u32, String> {
        let mut zeros = 0;
        while self.u(1)? == 0 {
            zeros += 1;
            if zeros > 31 {
                return Err("an SPS code longer than 32 bits".into());
            }
        }
        Ok(((1u64 << zeros) - 1 + u64::from(self.u(zeros)?)) as u32)
    }
}

/// `pic_width_in_luma_samples` and `pic_height_in_luma_samples` of an SPS RBSP.
pub fn coded_size(rbsp: &[u8]) -> Result<(u32, u32), String> {
    let r = &mut Bits { b: rbsp, at: 0 };
    r.skip(4)?; // sps_video_parameter_set_id
    let sub_layers = r.u(3)? as usize; // sps_max_sub_layers_minus1
    r.skip(1)?; // sps_temporal_id_nesting_flag
                // profile_tier_level(1, sps_max_sub_layers_minus1): the general profile, tier and level
                // (96 bits), then which sub-layers carry their own.
    r.skip(96)?;
    let mut present = Vec::with_capacity(sub_layers);
    for _ in 0..sub_layers {
        present.push((r.u(1)? == 1, r.u(1)? == 1));
    }
    if sub_layers > 0 {
        r.skip(2 * (8 - sub_layers))?;
    }
    for (profile, level) in present {
        r.skip(if profile { 88 } else { 0 } + if level { 8 } else { 0 })?;
    }
    r.ue()?; // sps_seq_parameter_set_id
    if r.ue()? == 3 {
        r.skip(1)?; // separate_colour_plane_flag
    }
    Ok((r.ue()?, r.ue()?))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn put(bits: &mut Vec<u8>, v: u64, n: u32) {
        (0..n).rev().for_each(|i| bits.push(((v >> i) & 1) as u8));
    }

    fn ue(bits: &mut Vec<u8>, v: u32) {
        let code = u64::from(v) + 1;
        let n = 64 - code.leading_zeros();
        put(bits, 0, n - 1);
        put(bits, code, n);
    }

    /// An SPS RBSP written by hand: no sub-layers, the given chroma format and size.
    fn sps(chroma: u32, w: u32, h: u32) -> Vec<u8> {
        let mut bits: Vec<u8> = Vec::new();
        put(&mut bits, 0, 4); // vps id
        put(&mut bits, 0, 3); // no sub-layers
        put(&mut bits, 1, 1);
        put(&mut bits, 0x0160_0000, 32); // profile space/tier/idc 1, then the first 24 compatibility bits
        put(&mut bits, 0, 64); // the rest: 8 compatibility bits, 48 constraint bits, the level (8)
        ue(&mut bits, 0); // sps id
        ue(&mut bits, chroma);
        if chroma == 3 {
            bits.push(0);
        }
        ue(&mut bits, w);
        ue(&mut bits, h);
        bits.resize(bits.len().div_ceil(8) * 8, 1);
        bits.chunks(8).map(|c| c.iter().fold(0u8, |a, &b| (a << 1) | b)).collect()
    }

    fn boxed(kind: &[u8; 4], payload: &[u8]) -> Vec<u8> {
        let mut b = ((payload.len() + 8) as u32).to_be_bytes().to_vec();
        b.extend(kind);
        b.extend(payload);
        b
    }

    /// A HEIF skeleton declaring `declared` (ispe) whose hvcC's SPS codes `coded`.
    pub(crate) fn heif_declaring(declared: (u32, u32), coded: (u32, u32)) -> Vec<u8> {
        let mut ispe = vec![0u8; 4];
        ispe.extend(declared.0.to_be_bytes());
        ispe.extend(declared.1.to_be_bytes());
        let mut hvcc = vec![1u8];
        hvcc.extend([0u8; 21]);
        hvcc.push(1); // one array
        let nal: Vec<u8> = [0x42, 0x01].into_iter().chain(sps(1, coded.0, coded.1)).collect();
        hvcc.push(SPS);
        hvcc.extend(1u16.to_be_bytes());
        hvcc.extend((nal.len() as u16).to_be_bytes());
        hvcc.extend(&nal);
        let ipco = boxed(b"ipco", &[boxed(b"hvcC", &hvcc), boxed(b"ispe", &ispe)].concat());
        let meta: Vec<u8> = [0u8; 4].into_iter().chain(boxed(b"iprp", &ipco)).collect();
        [boxed(b"ftyp", b"heic\0\0\0\0mif1heic"), boxed(b"meta", &meta)].concat()
    }

    #[test]
    fn a_file_declaring_less_than_it_codes_is_read_as_such() {
        let s = sizes(&heif_declaring((64, 64), (60000, 60000))).unwrap();
        assert_eq!(s, Sizes { declared: vec![(64, 64)], coded: vec![(60000, 60000)] });
        assert!(s.mismatch().unwrap().contains("decompression bomb"));
        assert_eq!(sizes(&heif_declaring((4032, 3024), (4032, 3072))).unwrap().mismatch(), None);
    }

    #[test]
    fn coded_sizes_by_hand() {
        assert_eq!(coded_size(&sps(1, 4032, 3024)), Ok((4032, 3024)));
        assert_eq!(coded_size(&sps(3, 64, 48)), Ok((64, 48)));
        assert_eq!(coded_size(&sps(1, 60000, 60000)), Ok((60000, 60000)));
        assert!(coded_size(&sps(1, 64, 64)[..12]).is_err(), "cut short");
        // Thirty-three leading zeros: no u32 Exp-Golomb code.
        let mut long = sps(1, 64, 64)[..12].to_vec();
        long.extend([0, 0, 0, 0, 0]);
        assert!(coded_size(&long).is_err());
    }

    #[test]
    fn emulation_prevention_bytes_are_removed() {
        assert_eq!(unescape(&[0, 0, 3, 1, 0, 0, 3, 0, 0, 3]), [0, 0, 1, 0, 0, 0, 0]);
        assert_eq!(unescape(&[3, 0, 3, 0, 0]), [3, 0, 3, 0, 0]);
    }

    #[test]
    fn a_coded_size_beyond_the_declared_one_is_named() {
        let fine = Sizes { declared: vec![(100, 60)], coded: vec![(128, 64)] };
        assert_eq!(fine.mismatch(), None);
        let bomb = Sizes { declared: vec![(64, 64)], coded: vec![(60000, 60000)] };
        let why = bomb.mismatch().unwrap();
        assert!(why.contains("60000 x 60000") && why.contains("64 x 64"), "{why}");
        // Nothing declared: a coded picture past one coding tree block is named.
        assert!(Sizes { declared: vec![], coded: vec![(100, 100)] }.mismatch().is_some());
    }

    #[test]
    fn malformed_boxes_get_a_reason() {
        assert!(sizes(b"").is_err());
        let mut over = 100u32.to_be_bytes().to_vec();
        over.extend(b"meta");
        assert!(sizes(&over).unwrap_err().contains("more than its container holds"));
    }
}
