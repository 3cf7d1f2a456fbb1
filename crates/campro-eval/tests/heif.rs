//! HEIC through the system's libheif (`campro_eval::heif`), on `tests/data/quadrants-exif6.heic`
//! (1.5 KB): a 64x48 picture of four coloured quadrants with a grey centre, stored losslessly
//! at 4:4:4 by pillow-heif 1.9.0 (libheif 1.23) with EXIF orientation 6, which it wrote as a
//! HEIF rotation (`irot`). Made with:
//! `im.save("q.heic", quality=-1, chroma=444, exif=exif_with_orientation_6)`.

use campro_eval::heif;
use campro_eval::image_file::{self, Budget};
use std::path::Path;

const FIXTURE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/quadrants-exif6.heic");

/// libheif, or a skip (a failure under `CI=true`, where .ci/run installs libheif1).
fn libheif() -> bool {
    if heif::available() {
        return true;
    }
    assert!(std::env::var("CI").as_deref() != Ok("true"), "CI=true but libheif is missing (.ci/run installs libheif1)");
    eprintln!("SKIP: {}", heif::MISSING);
    false
}

/// The picture as it was drawn: 64x48, red | green over blue | yellow, a grey 8x8 centre.
fn drawn(x: u32, y: u32) -> [u8; 3] {
    if (28..36).contains(&x) && (20..28).contains(&y) {
        return [128, 128, 128];
    }
    match (x < 32, y < 24) {
        (true, true) => [220, 40, 40],
        (false, true) => [40, 200, 60],
        (true, false) => [30, 60, 210],
        (false, false) => [230, 230, 40],
    }
}

#[test]
fn a_heic_photo_is_read_upright_as_its_rotation_says() {
    if !libheif() {
        return;
    }
    let budget = Budget::new(64 << 20);
    let (img, _lease, meta) = image_file::read_with_metadata(Path::new(FIXTURE), &budget, &image_file::no_work, &|w| {
        panic!("no warning expected: {w}")
    })
    .unwrap();
    let img = img.into_rgb8();
    // Turned a quarter clockwise (orientation 6): 48 wide, 64 high; the displayed (x, y)
    // shows the drawn (y, 47 - x). Lossless 4:4:4, so only the colour conversion's rounding.
    assert_eq!(img.dimensions(), (48, 64));
    for (x, y, p) in img.enumerate_pixels() {
        let want = drawn(y, 47 - x);
        for c in 0..3 {
            assert!(p.0[c].abs_diff(want[c]) <= 2, "({x}, {y}): {:?} against {want:?}", p.0);
        }
    }
    // The EXIF block, TIFF-structured (big-endian here), as metadata policies read it.
    let exif = meta.exif.expect("the EXIF block");
    assert!(exif.starts_with(b"MM\0*"), "{:?}", &exif[..8.min(exif.len())]);
    assert_eq!(image_file::dimensions(Path::new(FIXTURE)).unwrap(), (48, 64));
}

#[test]
fn a_heic_too_large_for_the_budget_is_refused_before_decoding() {
    if !libheif() {
        return;
    }
    let bytes = std::fs::read(FIXTURE).unwrap();
    let small = Budget::new(1000);
    let Err(e) = image_file::decode(Path::new("big.heic"), &bytes, &small, &image_file::no_work, &|_| {}) else {
        panic!("decoded under a 1000-byte budget")
    };
    assert!(e.to_string().contains("48 x 64 pixels, needing"), "{e}");
    assert_eq!(small.free(), 1000, "nothing taken");
}

#[test]
fn broken_heic_files_get_one_line_not_a_crash() {
    if !libheif() {
        return;
    }
    let bytes = std::fs::read(FIXTURE).unwrap();
    let budget = Budget::new(64 << 20);
    let header_only = [&[0, 0, 0, 24][..], b"ftypheic", &[0; 12]].concat();
    for (name, b) in [("cut.heic", bytes[..bytes.len() / 2].to_vec()), ("header.heic", header_only)] {
        let Err(e) = image_file::decode(Path::new(name), &b, &budget, &image_file::no_work, &|_| {}) else {
            panic!("{name} decoded")
        };
        let line = e.to_string();
        assert!(line.contains(name) && !line.contains('\n'), "{line}");
    }
    // Flipped bytes all through the file: an error or a picture, never a crash.
    for k in (16..bytes.len()).step_by(37) {
        let mut b = bytes.clone();
        b[k] ^= 0x5a;
        let _ = image_file::decode(Path::new("flipped.heic"), &b, &budget, &image_file::no_work, &|_| {});
    }
    assert_eq!(budget.free(), budget.total(), "every lease given back");
}

/// The fixture's HEVC stream codes the 64 x 64 its `ispe` declares (its `clap` then crops it to
/// 64 x 48): it reads; a file cut short gets a reason.
#[test]
fn the_coded_size_is_read_before_decoding() {
    let bytes = std::fs::read(FIXTURE).unwrap();
    let sizes = campro_eval::hvcc::sizes(&bytes).unwrap();
    assert_eq!(sizes.declared, [(64, 64)]);
    assert_eq!(sizes.coded, [(64, 64)]);
    assert_eq!(sizes.mismatch(), None);
    let mut cut = bytes.clone();
    cut.truncate(300);
    let e = heif::open(Path::new("cut.heic"), &cut).map(|_| ()).unwrap_err().to_string();
    assert!(e.contains("HEIF boxes do not read"), "{e}");
}
