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
