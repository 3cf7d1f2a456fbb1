//! `simulate` on photos: folders, depths, formats, sidecars, EXIF orientation and metadata, `--record`.

use super::*;

fn write_png8(path: &Path, w: u32, h: u32, data: &[u8]) {
    image::save_buffer(path, data, w, h, image::ExtendedColorType::Rgb8).unwrap();
}

#[test]
fn simulate_folders_depths_and_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    let px: Vec<u8> = (0..4 * 3 * 3).map(|i| (i * 7 % 256) as u8).collect();
    write_png8(&input.join("a.png"), 4, 3, &px);
    image::save_buffer(input.join("sub/b.jpg"), &px, 4, 3, image::ExtendedColorType::Rgb8).unwrap();
    let px16: Vec<u16> = (0..4 * 3 * 3).map(|i| (i * 1777 % 65536) as u16).collect();
    image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(4, 3, px16.clone())
        .unwrap()
        .save(input.join("sub/c.tif"))
        .unwrap();
    std::fs::write(input.join("notes.txt"), "hello").unwrap();
    std::fs::write(input.join("broken.png"), b"\x89PNG\r\n\x1a\n garbage").unwrap();
    let out = dir.path().join("out");
    let params = bundled("color-inversion.json");

    let run = campro()
        .arg("simulate")
        .arg(&params)
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .args(["--bit-depth", "16"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "a corrupt image makes the run fail");
    assert!(err.contains("notes.txt") && err.contains("warning"), "{err}");
    assert!(err.contains("broken.png") && !err.contains("panicked"), "{err}");
    // Each keeps its format, but a JPEG asked for 16 bits becomes a PNG (JPEG has no 16 bits).
    assert_eq!(files_in(&out), vec!["a.png", "sub/b.png", "sub/c.tif"], "the good images are written, nothing partial");

    // 16-bit output of an 8-bit PNG: each channel within 0.5 LSB of the f64 pipeline.
    let p = Params::from_file(&params).unwrap();
    let got = image::open(out.join("a.png")).unwrap().into_rgb16().into_raw();
    for (s, d) in px.chunks(3).zip(got.chunks(3)) {
        let want = campro::pipeline::process_f64(&p, [s[0] as f64 / 255.0, s[1] as f64 / 255.0, s[2] as f64 / 255.0]);
        for k in 0..3 {
            assert!((d[k] as f64 - want[k] * 65535.0).abs() <= 0.5 + 1e-9);
        }
    }
    // 16-bit TIFF input is read at 16 bits and written as a 16-bit TIFF.
    let tiff = image::open(out.join("sub/c.tif")).unwrap();
    assert_eq!(tiff.color(), image::ColorType::Rgb16);
    let got = tiff.into_rgb16().into_raw();
    for (s, d) in px16.chunks(3).zip(got.chunks(3)) {
        let want =
            campro::pipeline::process_f64(&p, [s[0] as f64 / 65535.0, s[1] as f64 / 65535.0, s[2] as f64 / 65535.0]);
        for k in 0..3 {
            assert!((d[k] as f64 - want[k] * 65535.0).abs() <= 0.5 + 1e-9);
        }
    }

    // Existing outputs are kept without --force, replaced with it.
    std::fs::remove_file(input.join("broken.png")).unwrap();
    let before = std::fs::read(out.join("a.png")).unwrap();
    fails_with(campro().arg("simulate").arg(&params).arg(input.join("a.png")).arg("-o").arg(&out), "exists");
    assert_eq!(std::fs::read(out.join("a.png")).unwrap(), before);
    campro()
        .arg("simulate")
        .arg(&params)
        .arg(input.join("a.png"))
        .arg("-o")
        .arg(&out)
        .arg("--force")
        .assert()
        .success();
    let eight = image::open(out.join("a.png")).unwrap();
    assert_eq!(eight.color(), image::ColorType::Rgb8);
    assert_eq!(files_in(&out), vec!["a.png", "sub/b.png", "sub/c.tif"]);
}

#[test]
fn photos_keep_their_format_and_one_input_may_name_its_output() {
    let dir = tempfile::tempdir().unwrap();
    // A smooth 64 x 48 photo (JPEG compresses it well) as a JPEG at quality 100.
    let (w, h) = (64u32, 48u32);
    let px: Vec<u8> = (0..w * h)
        .flat_map(|i| {
            let (x, y) = (i % w, i / w);
            [(x * 4) as u8, (y * 5) as u8, ((x + y) * 2) as u8]
        })
        .collect();
    let photo = dir.path().join("photo.jpg");
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 100)
        .encode(&px, w, h, image::ExtendedColorType::Rgb8)
        .unwrap();
    std::fs::write(&photo, &jpeg).unwrap();
    let params = bundled("campro-omega-0.5.json");
    let p = Params::from_file(&params).unwrap();
    let decoded = image::open(&photo).unwrap().into_rgb8().into_raw();
    let mut want = vec![0u8; decoded.len()];
    campro::pipeline::fast::Exact8::new(&p).run(&decoded, &mut want);
    let mean_error =
        |got: &[u8]| got.iter().zip(&want).map(|(&g, &w)| (g as f64 - w as f64).abs()).sum::<f64>() / got.len() as f64;
    let simulate_into = |out: &Path, flags: &[&str]| {
        campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(out).args(flags).assert().success();
    };
    // Into a folder: photo.jpg stays photo.jpg, a JPEG, at the quality asked.
    let mut sizes = Vec::new();
    for q in [95, 30] {
        let out = dir.path().join(format!("q{q}"));
        simulate_into(&out, &["--quality", &q.to_string()]);
        assert_eq!(files_in(&out), vec!["photo.jpg"]);
        let bytes = std::fs::read(out.join("photo.jpg")).unwrap();
        assert_eq!(image::guess_format(&bytes).unwrap(), image::ImageFormat::Jpeg);
        let got = image::load_from_memory(&bytes).unwrap().into_rgb8().into_raw();
        sizes.push((bytes.len(), mean_error(&got)));
    }
    // Lower quality: a smaller file further from the exact output (which the higher one is near).
    assert!(sizes[1].0 < sizes[0].0 && sizes[1].1 > sizes[0].1, "{sizes:?}");
    assert!(sizes[0].1 < 3.0, "quality 95 is within 3 levels on average: {sizes:?}");

    // --image-format png: the folder gets photo.png, the exact path bit for bit.
    let out = dir.path().join("png");
    simulate_into(&out, &["--image-format", "png"]);
    assert_eq!(files_in(&out), vec!["photo.png"]);
    assert_eq!(image::open(out.join("photo.png")).unwrap().into_rgb8().into_raw(), want);

    // One input and an output with an image ending: that file, in the format it names.
    let named = dir.path().join("protected.png");
    campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(&named).assert().success();
    let img = image::open(&named).unwrap();
    assert_eq!(img.into_rgb8().into_raw(), want, "PNG out of a JPEG: the exact path, bit for bit");
    fails_with(campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(&named), "exists");
    fails_with(campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(dir.path().join("x.mp4")), "an image");
    fails_with(campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(&photo), "replace");
    fails_with(
        campro().arg("simulate").arg(&params).arg(&photo).arg("-o").arg(dir.path().join("q")).args(["--quality", "0"]),
        "--quality",
    );
}

/// Sidecars beside photos (`a.txt` by `a.png`, Lightroom's `IMG_1.xmp`, `x.webp.txt`) are
/// skipped with a warning each and never collide with the outputs: the photos are written.
#[test]
fn sidecars_are_skipped_not_a_collision() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    for name in ["a", "IMG_1", "x"] {
        image::RgbImage::from_pixel(16, 12, image::Rgb([200, 120, 90]))
            .save(photos.join(format!("{name}.png")))
            .unwrap();
    }
    for side in ["a.txt", "IMG_1.xmp", "x.webp.txt"] {
        std::fs::write(photos.join(side), b"sidecar").unwrap();
    }
    let out = dir.path().join("out");
    let run = campro()
        .arg("simulate")
        .arg(bundled("campro-omega-0.5.json"))
        .arg(&photos)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    for name in ["a.png", "IMG_1.png", "x.png"] {
        assert!(out.join(name).is_file(), "{name} not written: {err}");
    }
    for side in ["a.txt", "IMG_1.xmp", "x.webp.txt"] {
        assert!(
            err.contains(&format!(
                "skipping {}: not a PNG, JPEG, TIFF, WebP or video file",
                photos.join(side).display()
            )),
            "{err}"
        );
        assert!(!out.join(side).exists());
    }
    assert!(!err.contains("would both be written"), "{err}");
}

/// `img` as a JPEG, and the same JPEG stored "sideways": an APP1 Exif block (a
/// little-endian TIFF header and one IFD entry, Orientation (0x0112) = 6) after its SOI.
fn sideways_jpeg(img: &image::RgbImage) -> (Vec<u8>, Vec<u8>) {
    let mut plain = Vec::new();
    img.write_to(&mut std::io::Cursor::new(&mut plain), image::ImageFormat::Jpeg).unwrap();
    let mut exif = b"Exif\0\0II*\0\x08\0\0\0\x01\0".to_vec();
    exif.extend_from_slice(&[0x12, 0x01, 3, 0, 1, 0, 0, 0, 6, 0, 0, 0, 0, 0, 0, 0]);
    let mut tagged = plain[..2].to_vec();
    tagged.extend_from_slice(&[0xff, 0xe1]);
    tagged.extend_from_slice(&((exif.len() + 2) as u16).to_be_bytes());
    tagged.extend_from_slice(&exif);
    tagged.extend_from_slice(&plain[2..]);
    (plain, tagged)
}

/// A phone's folder in one run: an iPhone's HEIC photo (the eval crate's fixture:
/// orientation 6 as a HEIF rotation), a JPEG stored sideways with EXIF orientation 6, a
/// WebP, and sidecars (Lightroom's `.xmp`, a `notes.txt`). The HEIC is read through libheif
/// and written as an upright JPEG (without libheif: skipped with the one line that says
/// what to install), the JPEG comes out turned, the WebP stays a WebP, the sidecars are
/// skipped with a warning each, and the run succeeds.
#[test]
fn a_phone_folder_goes_through_upright_in_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    let fixture = campro_testkit::workspace_root().join("crates/campro-eval/tests/data/quadrants-exif6.heic");
    std::fs::copy(fixture, photos.join("IMG_0001.HEIC")).unwrap();
    let img = image::RgbImage::from_fn(20, 10, |x, y| image::Rgb([(x * 12) as u8, (y * 20) as u8, 120]));
    std::fs::write(photos.join("IMG_0002.JPG"), sideways_jpeg(&img).1).unwrap();
    image::RgbImage::from_fn(12, 8, |x, y| image::Rgb([90, (x * 20) as u8, (y * 30) as u8]))
        .save(photos.join("IMG_0003.webp"))
        .unwrap();
    std::fs::write(photos.join("IMG_0002.xmp"), b"<x:xmpmeta/>").unwrap();
    std::fs::write(photos.join("notes.txt"), b"holiday").unwrap();
    let out = dir.path().join("out");
    // --allow-grey: the HEIC fixture's five flat colours each sit at a brightness of their
    // own, which the grey measure rightly calls a function of brightness.
    let run = campro()
        .arg("simulate")
        .arg("campro-omega-0.5")
        .arg(&photos)
        .arg("-o")
        .arg(&out)
        .arg("--allow-grey")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    let jpeg = image::open(out.join("IMG_0002.JPG")).unwrap_or_else(|e| panic!("{e}: {err}"));
    assert_eq!((jpeg.width(), jpeg.height()), (10, 20), "turned by its EXIF orientation");
    assert_eq!(image::open(out.join("IMG_0003.webp")).unwrap().width(), 12);
    for side in ["IMG_0002.xmp", "notes.txt"] {
        assert!(err.contains(&format!("skipping {}", photos.join(side).display())), "{err}");
        assert!(!out.join(side).exists());
    }
    if campro_eval::heif::available() {
        let img = image::open(out.join("IMG_0001.jpg")).unwrap_or_else(|e| panic!("{e}: {err}"));
        assert_eq!((img.width(), img.height()), (48, 64), "upright, as the rotation says");
        assert!(!err.contains("libheif"), "{err}");
    } else {
        assert!(std::env::var("CI").as_deref() != Ok("true"), "CI=true but libheif is missing");
        assert!(err.contains("IMG_0001.HEIC: HEIC needs the system's libheif"), "{err}");
        assert!(!out.join("IMG_0001.jpg").exists());
    }
}

/// A WebP photo is read and written back as a lossless WebP: its pixels are the camera's
/// output of the same picture given as a PNG (both lossless, so every code must match).
#[test]
fn a_webp_photo_stays_a_lossless_webp_with_the_cameras_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let img =
        image::RgbImage::from_fn(24, 16, |x, y| image::Rgb([(x * 10) as u8, (y * 15) as u8, ((x + y) * 5) as u8]));
    let (webp, png) = (dir.path().join("w/p.webp"), dir.path().join("p/p.png"));
    for f in [&webp, &png] {
        std::fs::create_dir_all(f.parent().unwrap()).unwrap();
    }
    let mut bytes = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut bytes)
        .encode(img.as_raw(), 24, 16, image::ExtendedColorType::Rgb8)
        .unwrap();
    std::fs::write(&webp, bytes).unwrap();
    img.save(&png).unwrap();
    for (input, out) in [(&webp, "ow"), (&png, "op")] {
        campro()
            .arg("simulate")
            .arg(bundled("campro-omega-0.5.json"))
            .arg(input.parent().unwrap())
            .arg("-o")
            .arg(dir.path().join(out))
            .assert()
            .success();
    }
    let written = dir.path().join("ow/p.webp");
    assert_eq!(image::ImageFormat::from_path(&written).unwrap(), image::ImageFormat::WebP);
    let from_webp = image::open(&written).unwrap().into_rgb8();
    let from_png = image::open(dir.path().join("op/p.png")).unwrap().into_rgb8();
    assert_eq!(from_webp, from_png);
    assert_ne!(from_webp, img, "the camera changed nothing");
}

/// The EXIF fields of an image file's block, as (tag, value) text; none without a block.
fn exif_fields(path: &Path) -> Vec<(String, String)> {
    use image::ImageDecoder;
    let bytes = std::fs::read(path).unwrap();
    let mut d =
        image::ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format().unwrap().into_decoder().unwrap();
    let Some(block) = d.exif_metadata().unwrap() else { return Vec::new() };
    let e = exif::Reader::new().read_raw(block).unwrap();
    e.fields().map(|f| (f.tag.to_string(), f.display_value().to_string())).collect()
}

/// A phone's JPEG with the date, the camera, GPS, a serial number, a maker note and
/// orientation 6: by default the output keeps date and camera, drops the rest and says
/// orientation 1; `--metadata keep` keeps GPS too (never the maker note); `strip` nothing.
/// The colour profile travels with keep-safe and keep.
#[test]
fn metadata_policy_keeps_the_date_and_camera_and_drops_gps() {
    use exif::{Field, In, Tag, Value};
    use image::ImageEncoder;
    let dir = tempfile::tempdir().unwrap();
    let fields = [
        Field { tag: Tag::Make, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"Phone".to_vec()]) },
        Field { tag: Tag::Model, ifd_num: In::PRIMARY, value: Value::Ascii(vec![b"X1".to_vec()]) },
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
    ];
    let mut w = exif::experimental::Writer::new();
    fields.iter().for_each(|f| w.push_field(f));
    let mut block = std::io::Cursor::new(Vec::new());
    w.write(&mut block, true).unwrap();
    let img = image::RgbImage::from_fn(24, 16, |x, y| image::Rgb([(x * 9) as u8, (y * 14) as u8, 90]));
    let mut jpeg = Vec::new();
    let mut enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 95);
    enc.set_exif_metadata(block.into_inner()).unwrap();
    let srgb: Vec<u8> =
        (0..SRGB_ICC.len()).step_by(2).map(|i| u8::from_str_radix(&SRGB_ICC[i..i + 2], 16).unwrap()).collect();
    enc.set_icc_profile(srgb.clone()).unwrap();
    enc.write_image(img.as_raw(), 24, 16, image::ExtendedColorType::Rgb8).unwrap();
    let input = dir.path().join("IMG_1.jpg");
    std::fs::write(&input, jpeg).unwrap();
    let run = |policy: Option<&str>, out: &str| {
        let mut c = campro();
        c.arg("simulate").arg(bundled("campro-omega-0.5.json")).arg(&input).arg("-o").arg(dir.path().join(out));
        if let Some(p) = policy {
            c.args(["--metadata", p]);
        }
        c.assert().success();
        exif_fields(&dir.path().join(out))
    };
    let has = |f: &[(String, String)], tag: &str| f.iter().any(|(t, _)| t == tag);
    let safe = run(None, "safe.jpg");
    assert!(has(&safe, "Make") && has(&safe, "Model") && has(&safe, "DateTimeOriginal"), "{safe:?}");
    for gone in ["GPSLatitude", "BodySerialNumber", "MakerNote"] {
        assert!(!has(&safe, gone), "{gone} kept: {safe:?}");
    }
    assert!(safe.iter().any(|(t, v)| t == "Orientation" && v.contains("row 0 at top")), "{safe:?}");
    // The pixels were turned: 16 wide, 24 tall.
    assert_eq!(image::image_dimensions(dir.path().join("safe.jpg")).unwrap(), (16, 24));
    let keep = run(Some("keep"), "keep.jpg");
    assert!(has(&keep, "GPSLatitude") && has(&keep, "BodySerialNumber") && !has(&keep, "MakerNote"), "{keep:?}");
    assert!(run(Some("strip"), "strip.jpg").is_empty());
    let icc = |name: &str| {
        use image::ImageDecoder;
        let bytes = std::fs::read(dir.path().join(name)).unwrap();
        image::codecs::jpeg::JpegDecoder::new(std::io::Cursor::new(bytes)).unwrap().icc_profile().unwrap()
    };
    // The profile is rebuilt from its colour tags: each of lcms's colour tags is there with
    // its data, its copyright line is not, and the description is campro's.
    let tags = |p: &[u8]| -> Vec<(String, Vec<u8>)> {
        let be = |at: usize| u32::from_be_bytes(p[at..at + 4].try_into().unwrap()) as usize;
        (0..be(128))
            .map(|i| {
                let e = 132 + 12 * i;
                (String::from_utf8_lossy(&p[e..e + 4]).into_owned(), p[be(e + 4)..be(e + 4) + be(e + 8)].to_vec())
            })
            .collect()
    };
    let (given, out) = (tags(&srgb), tags(&icc("safe.jpg").unwrap()));
    let names: Vec<&str> = out.iter().map(|t| t.0.as_str()).collect();
    assert_eq!(names, ["wtpt", "chad", "rXYZ", "bXYZ", "gXYZ", "rTRC", "gTRC", "bTRC", "chrm", "desc"]);
    for (name, data) in &out[..9] {
        assert_eq!(Some(data), given.iter().find(|t| &t.0 == name).map(|t| &t.1), "{name}");
    }
    assert!(!icc("safe.jpg").unwrap().windows(6).any(|w| w == b"N\0o\0 \0c"), "lcms's copyright line is gone");
    assert_eq!(icc("keep.jpg"), icc("safe.jpg"));
    assert_eq!(icc("strip.jpg"), None);
}

/// The sRGB profile lcms 2 writes (Pillow's `ImageCms.createProfile("sRGB")`, 588 bytes):
/// desc and cprt (mluc text), wtpt, chad, the primaries, one parametric curve shared by the
/// three channels, chrm.
const SRGB_ICC: &str = "0000024c6c636d73044000006d6e74725247422058595a2007ea000c0007001200020011616373704150504c0000000000000000000000000000000000000000000000000000f6d6000100000000d32d6c636d7300000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000b64657363000001080000003663707274000001400000004c777470740000018c0000001463686164000001a00000002c7258595a000001cc000000146258595a000001e0000000146758595a000001f4000000147254524300000208000000206754524300000208000000206254524300000208000000206368726d00000228000000246d6c756300000000000000010000000c656e55530000001a0000001c00730052004700420020006200750069006c0074002d0069006e00006d6c756300000000000000010000000c656e5553000000300000001c004e006f00200063006f0070007900720069006700680074002c002000750073006500200066007200650065006c007958595a20000000000000f6d6000100000000d32d736633320000000000010c42000005defffff325000007930000fd90fffffba1fffffda2000003dc0000c06e58595a200000000000006fa0000038f50000039058595a20000000000000249f00000f840000b6c358595a2000000000000062970000b787000018d9706172610000000000030000000266660000f2a700000d59000013d000000a5b6368726d00000000000300000000a3d70000547b00004ccd0000999a0000266600000f5c";

/// A phone JPEG stored sideways with EXIF orientation 6 (turn 90° clockwise to show) comes
/// out turned: the output is as tall as the stored picture is wide, and each pixel is the
/// untagged copy's pixel at the turned place (the same decoded pixel through the camera).
#[test]
fn exif_orientation_turns_the_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (20u32, 10u32);
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        if x < w / 2 {
            image::Rgb([220, 40, 30])
        } else {
            image::Rgb([30, 60, (y * 20) as u8])
        }
    });
    let (plain, tagged) = sideways_jpeg(&img);
    let (a, b) = (dir.path().join("plain.jpg"), dir.path().join("turned.jpg"));
    std::fs::write(&a, &plain).unwrap();
    std::fs::write(&b, &tagged).unwrap();
    let out = dir.path().join("out");
    let preset = bundled("campro-omega-0.5.json");
    for (input, name) in [(&a, "plain.png"), (&b, "turned.png")] {
        let run = campro()
            .arg("simulate")
            .arg(&preset)
            .arg(input)
            .arg("-o")
            .arg(out.join(name))
            .args(["--image-format", "png"])
            .output()
            .unwrap();
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    }
    let p = image::open(out.join("plain.png")).unwrap().to_rgb8();
    let t = image::open(out.join("turned.png")).unwrap().to_rgb8();
    assert_eq!((p.width(), p.height()), (w, h));
    assert_eq!((t.width(), t.height()), (h, w), "turned: as tall as the stored picture is wide");
    // Turning 90° clockwise moves the stored (x, y) to (h - 1 - y, x).
    for y in 0..h {
        for x in 0..w {
            assert_eq!(p.get_pixel(x, y), t.get_pixel(h - 1 - y, x), "stored ({x}, {y})");
        }
    }
}

/// `--record` hashes its input file: a stream (standard input here) has none, so the run is
/// refused in one line before anything is read, rather than written without its record.
#[test]
fn a_record_of_a_stream_is_refused_not_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("live.mkv");
    fails_with(
        campro().args(["simulate", "campro-omega-0.5", "-", "-o"]).arg(&out).arg("--record").write_stdin(Vec::new()),
        "--record: a record holds its input's hash",
    );
    assert!(!out.exists());
}

#[test]
fn photos_given_where_the_preset_goes_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    for command in ["simulate", "inspect"] {
        let out = campro().arg(command).arg(&photos).arg("-o").arg(dir.path().join("out")).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("photos: is not a preset; the parameter set comes first"), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    // A preset with its photos missing keeps clap's own line.
    let out = campro().args(["simulate", "campro-omega-0.5", "-o"]).arg(dir.path().join("out")).output().unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("required"), "{}", String::from_utf8_lossy(&out.stderr));
}
