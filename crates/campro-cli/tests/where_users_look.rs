//! Privacy where users look: grey pictures are refused unless allowed (and then said), and
//! the enhanced view is never shown without its face guard. One scenario a test.

mod common;
use common::{campro, fails_with};
use std::path::Path;

/// A grey gradient with some scene in it (not a flat fill).
fn grey(dir: &Path) -> std::path::PathBuf {
    let p = dir.join("grey.png");
    image::RgbImage::from_fn(32, 24, |x, y| {
        let v = (x * 7 + y * 3) as u8;
        image::Rgb([v, v, v])
    })
    .save(&p)
    .unwrap();
    p
}

/// A colour gradient (red across, green down).
fn colour(dir: &Path) -> std::path::PathBuf {
    let p = dir.join("c.png");
    image::RgbImage::from_fn(32, 24, |x, y| image::Rgb([(x * 7) as u8, (y * 9) as u8, 90])).save(&p).unwrap();
    p
}

#[test]
fn a_grey_picture_is_refused_by_a_preset_not_rated_for_grey() {
    let dir = tempfile::tempdir().unwrap();
    let img = grey(dir.path());
    fails_with(
        campro().arg("simulate").arg("campro-omega-0.5").arg(&img).arg("-o").arg(dir.path().join("out")),
        "does not protect grey pictures",
    );
    assert!(!dir.path().join("out/grey.png").exists());
}

#[test]
fn allow_grey_writes_it_and_says_so_on_stderr_and_in_the_json() {
    let dir = tempfile::tempdir().unwrap();
    let img = grey(dir.path());
    let out = campro()
        .arg("simulate")
        .arg("campro-omega-0.5")
        .arg(&img)
        .arg("-o")
        .arg(dir.path().join("out"))
        .args(["--allow-grey", "--format", "json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not protected"));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let warning = v["files"][0]["warnings"][0].as_str().unwrap();
    assert!(warning.contains("--allow-grey") && warning.contains("not rated for grey"), "{warning}");
    assert!(dir.path().join("out/grey.png").is_file());
}

#[test]
fn a_grey_video_frame_is_refused_too() {
    if std::process::Command::new("ffmpeg").arg("-version").output().is_err() {
        assert!(std::env::var_os("CI").is_none(), "ffmpeg is needed under CI");
        eprintln!("skipped: no ffmpeg");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("grey.mp4");
    let made = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-f", "lavfi", "-i", "testsrc2=size=64x48:rate=5:duration=1", "-vf", "format=gray"])
        .args(["-pix_fmt", "yuv420p", "-c:v", "libx264"])
        .arg(&clip)
        .status()
        .unwrap();
    assert!(made.success());
    fails_with(
        campro().arg("simulate").arg("campro-omega-0.5").arg(&clip).arg("-o").arg(dir.path().join("out")),
        "does not protect grey pictures",
    );
    assert!(!dir.path().join("out/grey.mp4").exists());
}

#[test]
fn a_colour_picture_is_not_called_grey() {
    let dir = tempfile::tempdir().unwrap();
    let img = colour(dir.path());
    campro().arg("simulate").arg("campro-omega-0.5").arg(&img).arg("-o").arg(dir.path().join("out")).assert().success();
}

#[test]
fn the_enhanced_view_is_not_shown_without_its_face_guard() {
    let dir = tempfile::tempdir().unwrap();
    let img = colour(dir.path());
    std::fs::create_dir(dir.path().join("empty")).unwrap();
    let mut c = campro();
    c.arg("simulate").arg("campro-omega-0.5").arg(&img).arg("-o").arg(dir.path().join("out")).arg("--enhance");
    c.arg("--models").arg(dir.path().join("empty"));
    fails_with(&mut c, "nothing is enhanced without it");
    assert!(!dir.path().join("out").exists());
}

/// An LFW portrait (250 x 250, one face in the middle) made grey but for what `keep` says,
/// with a vivid striped patch in its bottom-left corner: a selective-colour photo.
fn selective(dir: &Path, shared: &Path, name: &str, keep: impl Fn(u32, u32) -> bool) -> std::path::PathBuf {
    let face = shared.join("data/lfw/images_deepfunneled/Aaron_Peirsol/Aaron_Peirsol_0001.jpg");
    let img = image::open(face).unwrap().into_rgb8();
    let out = image::RgbImage::from_fn(img.width(), img.height(), |x, y| {
        if x < 80 && y >= 170 {
            return if (x / 8) % 2 == 0 { image::Rgb([220, 30, 40]) } else { image::Rgb([30, 160, 60]) };
        }
        let p = *img.get_pixel(x, y);
        if keep(x, y) {
            return p;
        }
        let l = campro::chroma::luma(p.0);
        image::Rgb([l, l, l])
    });
    let p = dir.join(name);
    out.save(&p).unwrap();
    p
}

/// A photo grey but for one object passes the whole-frame measure (its colour spread is
/// above 4), and its grey face would be restored: its faces are looked at, and a grey face
/// is refused as a grey photo is; the same photo with its face in colour (a grey scene
/// around a colour face, as snow or overcast is) goes through; with no face detector to
/// look, a mostly colourless photo is refused (fail closed).
#[test]
fn a_selective_colour_photo_is_judged_by_its_faces() {
    let Some(shared) = campro_testkit::shared_root(&["models/yunet_s_640_640.onnx", "data/lfw/images_deepfunneled"])
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let grey_face = selective(dir.path(), &shared, "bw.png", |_, _| false);
    let px = image::open(&grey_face).unwrap().into_rgb8().into_raw();
    let (spread, share) = (campro::chroma::measure(&px).spread, campro::chroma::neutral_share(&px));
    assert!(spread >= campro::chroma::GREY_SPREAD && share >= 0.6, "spread {spread}, neutral share {share}");
    let simulate = |input: &Path, out: &str, extra: &[&str]| {
        let mut c = campro();
        c.args(["simulate", "campro-omega-0.5"]).arg(input).arg("-o").arg(dir.path().join(out)).args(extra);
        c
    };
    let models = shared.join("models");
    let with_models = ["--models", models.to_str().unwrap()];
    fails_with(&mut simulate(&grey_face, "a.png", &with_models), "a face in the picture is black and white");
    assert!(!dir.path().join("a.png").exists());
    // --allow-grey writes it and says so.
    let allowed = simulate(&grey_face, "b.png", &[&with_models[..], &["--allow-grey"]].concat()).output().unwrap();
    assert!(allowed.status.success() && String::from_utf8_lossy(&allowed.stderr).contains("--allow-grey"));
    // The face in colour, the scene around it grey: looked at, and let through.
    let colour_face =
        selective(dir.path(), &shared, "face.png", |x, y| (95..155).contains(&x) && (90..170).contains(&y));
    let share = campro::chroma::neutral_share(&image::open(&colour_face).unwrap().into_rgb8().into_raw());
    assert!(share >= 0.6, "not looked at: neutral share {share}");
    let ok = simulate(&colour_face, "c.png", &with_models).output().unwrap();
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    // No detector to look with: refused, naming why.
    let empty = dir.path().join("no-models");
    std::fs::create_dir(&empty).unwrap();
    fails_with(
        &mut simulate(&grey_face, "d.png", &["--models", empty.to_str().unwrap()]),
        "no face detector could be loaded",
    );
}
