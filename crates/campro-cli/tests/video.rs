//! `campro simulate` on video: with a lossless codec every decoded output frame equals the
//! exact 8-bit pipeline on the same decoded input frame, bit for bit; frame count, frame
//! rate, rotation and the audio stream are kept. The videos are made here with ffmpeg
//! (skipped with a message where ffmpeg is missing, except under `CI=true`).

mod common;

use campro::pipeline::fast::Exact8;
use campro::Params;
use common::{bundled, campro, fails_with, ffmpeg_present};
use std::path::Path;
use std::process::Command;

fn ffmpeg(args: &[&str]) -> Vec<u8> {
    let out = Command::new("ffmpeg").args(["-hide_banner", "-v", "error", "-nostdin"]).args(args).output().unwrap();
    assert!(out.status.success(), "ffmpeg {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    out.stdout
}

fn probe(path: &Path, streams: &str, entries: &str) -> String {
    let out = Command::new("ffprobe")
        .args([
            "-v",
            "error",
            "-count_frames",
            "-select_streams",
            streams,
            "-of",
            "compact=p=0:nk=1",
            "-show_entries",
            entries,
        ])
        .arg(path)
        .output()
        .unwrap();
    // compact: one line per section, fields split by '|'; the values alone, one a line.
    let text = String::from_utf8_lossy(&out.stdout).replace('|', "\n");
    text.lines().filter(|l| !l.trim().is_empty()).collect::<Vec<_>>().join("\n")
}

/// The video stream decoded to packed RGB, frame after frame, as stored (not rotated).
fn rgb_frames(path: &Path) -> Vec<u8> {
    ffmpeg(&[
        "-autorotate",
        "0",
        "-i",
        path.to_str().unwrap(),
        "-map",
        "0:v:0",
        "-fps_mode",
        "passthrough",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-",
    ])
}

#[test]
fn lossless_video_equals_the_exact_path_frame_by_frame_and_keeps_its_streams() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("clip.mp4");
    // 1.2 s of a moving test pattern at 25 fps in H.264 (lossy, 4:2:0) with a tone in AAC,
    // rotated 90 degrees by its display matrix.
    let plain = dir.path().join("plain.mp4");
    ffmpeg(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=192x108:rate=25",
        "-f",
        "lavfi",
        "-i",
        "sine=frequency=440:sample_rate=48000",
        "-t",
        "1.2",
        "-c:v",
        "libx264",
        "-pix_fmt",
        "yuv420p",
        "-c:a",
        "aac",
        "-shortest",
        plain.to_str().unwrap(),
    ]);
    ffmpeg(&["-i", plain.to_str().unwrap(), "-c", "copy", "-metadata:s:v:0", "rotate=90", input.to_str().unwrap()]);
    let preset = bundled("campro-omega-0.5.json");
    let out_dir = dir.path().join("out");
    let run = campro()
        .arg("simulate")
        .arg(&preset)
        .arg(&input)
        .arg("-o")
        .arg(&out_dir)
        .args(["--codec", "ffv1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    // ffv1 needs Matroska: the ending changes, and stderr says so.
    let output = out_dir.join("clip.mkv");
    assert!(err.contains("is written as") && err.contains("clip.mkv"), "{err}");
    assert!(output.is_file() && !out_dir.join("clip.mp4").exists());

    // Every frame: the exact 8-bit path on the decoded input frame, bit for bit.
    let p = Params::from_file(&preset).unwrap();
    let exact = Exact8::new(&p);
    let src = rgb_frames(&input);
    let got = rgb_frames(&output);
    let frame = 192 * 108 * 3;
    assert_eq!(src.len() % frame, 0);
    assert_eq!(got.len(), src.len(), "frame count: {} in, {} out", src.len() / frame, got.len() / frame);
    let mut want = vec![0u8; src.len()];
    exact.run(&src, &mut want);
    let first_bad = got.chunks(frame).zip(want.chunks(frame)).position(|(g, w)| g != w);
    assert_eq!(first_bad, None, "frame {first_bad:?} differs from the exact path");
    assert!(got != src, "the camera changed the frames");

    // The streams and what describes them.
    assert_eq!(probe(&output, "v:0", "stream=nb_read_frames"), "30");
    assert_eq!(probe(&input, "v:0", "stream=nb_read_frames"), "30");
    assert_eq!(probe(&output, "v:0", "stream=r_frame_rate"), "25/1");
    assert_eq!(probe(&output, "v:0", "stream=codec_name"), "ffv1");
    assert_eq!(probe(&output, "a:0", "stream=codec_name"), "aac");
    assert_eq!(probe(&input, "v:0", "stream_side_data=rotation").as_str(), "90");
    // Matroska holds no rotation in ffmpeg 5: said on stderr (newer ffmpeg keeps it).
    let kept = probe(&output, "v:0", "stream_side_data=rotation");
    assert!(kept == "90" || err.contains("cannot hold its rotation (90 degrees)"), "{kept:?} {err}");
    let audio = |f: &Path| ffmpeg(&["-i", f.to_str().unwrap(), "-map", "0:a", "-c", "copy", "-f", "md5", "-"]);
    assert_eq!(audio(&output), audio(&input), "the audio packets are copied unchanged");

    // The default (H.264, CRF 18) keeps the container, the frame count and the rotation.
    let run = campro().arg("simulate").arg(&preset).arg(&input).arg("-o").arg(&out_dir).output().unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let h264 = out_dir.join("clip.mp4");
    assert_eq!(probe(&h264, "v:0", "stream_side_data=rotation"), "90");
    assert_eq!(probe(&h264, "v:0", "stream=codec_name"), "h264");
    assert_eq!(probe(&h264, "a:0", "stream=codec_name"), "aac");
    assert_eq!(rgb_frames(&h264).len(), src.len());
    // The usual rules: no overwrite without --force.
    fails_with(campro().arg("simulate").arg(&preset).arg(&input).arg("-o").arg(&out_dir), "exists (use --force");
}

#[test]
fn a_missing_ffmpeg_says_how_to_install_it() {
    let dir = tempfile::tempdir().unwrap();
    let video = dir.path().join("v.mp4");
    std::fs::write(&video, b"not really a video").unwrap();
    let empty = dir.path().join("no-tools");
    std::fs::create_dir(&empty).unwrap();
    fails_with(
        campro()
            .env("PATH", &empty)
            .arg("simulate")
            .arg(bundled("identity.json"))
            .arg(&video)
            .arg("-o")
            .arg(dir.path().join("o")),
        "ffprobe is not installed; video needs ffmpeg and ffprobe on PATH (Debian/Ubuntu: apt-get install ffmpeg",
    );
}

#[test]
fn a_broken_video_is_one_named_error() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let video = dir.path().join("broken.mkv");
    std::fs::write(&video, b"\x1a\x45\xdf\xa3 this is not matroska").unwrap();
    fails_with(
        campro().arg("simulate").arg(bundled("identity.json")).arg(&video).arg("-o").arg(dir.path().join("o")),
        "broken.mkv",
    );
    assert!(!dir.path().join("o/broken.mkv").exists());
}
