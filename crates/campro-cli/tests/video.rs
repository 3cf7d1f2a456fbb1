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

/// The video stream decoded to packed RGB of `pix_fmt` (rgb24, rgb48le), frame after
/// frame, as stored (not rotated).
fn decoded(path: &Path, pix_fmt: &str) -> Vec<u8> {
    let mut args: Vec<&str> = vec!["-autorotate", "0", "-i", path.to_str().unwrap()];
    args.extend("-map 0:v:0 -fps_mode passthrough -f rawvideo -pix_fmt".split_whitespace());
    args.extend([pix_fmt, "-"]);
    ffmpeg(&args)
}

/// [`decoded`] as 8-bit RGB.
fn rgb_frames(path: &Path) -> Vec<u8> {
    decoded(path, "rgb24")
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

/// The video stream's presentation timestamps, seconds, in order.
fn timestamps(path: &Path) -> Vec<f64> {
    let out = Command::new("ffprobe")
        .args(["-v", "error", "-select_streams", "v:0", "-show_entries", "packet=pts_time", "-of", "csv=p=0"])
        .arg(path)
        .output()
        .unwrap();
    let mut t: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.trim().trim_end_matches(',').parse().ok())
        .collect();
    t.sort_by(f64::total_cmp);
    t
}

/// Makes `path` with ffmpeg from `args` (whitespace-separated, none holding a space).
fn make(path: &Path, args: &str) {
    let mut all: Vec<&str> = args.split_whitespace().collect();
    all.push(path.to_str().unwrap());
    ffmpeg(&all);
}

/// A stream's duration, seconds.
fn duration(path: &Path, stream: &str) -> f64 {
    probe(path, stream, "stream=duration").parse().unwrap()
}

#[test]
fn variable_frame_rate_keeps_every_timestamp_and_stays_with_its_audio() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("vfr.mp4");
    // 20 frames at 30 fps, then 22 frames at 10 fps (2.8 s of video), over 2.8 s of tone.
    make(
        &input,
        "-f lavfi -i testsrc2=size=160x120:rate=30 -f lavfi -i sine=frequency=440:sample_rate=48000 -t 2.8 \
         -vf setpts='if(lt(N,20),N/30,20/30+(N-20)/10)/TB' -fps_mode vfr -c:v libx264 -c:a aac -shortest",
    );
    let want = timestamps(&input);
    assert!(want.len() > 30, "{want:?}");
    let steps: Vec<f64> = want.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(steps.iter().any(|&s| (s - 1.0 / 30.0).abs() < 1e-3) && steps.iter().any(|&s| (s - 0.1).abs() < 1e-3));
    let out = dir.path().join("out");
    let run = campro()
        .arg("simulate")
        .arg(bundled("campro-omega-0.5.json"))
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let output = out.join("vfr.mp4");
    let got = timestamps(&output);
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 1e-3, "a frame at {w} s came out at {g} s");
    }
    // The video still spans what the audio spans (a constant-rate output would end at 42/30 s).
    assert!((duration(&output, "v:0") - duration(&input, "v:0")).abs() < 0.05);
    assert!((duration(&output, "a:0") - duration(&input, "a:0")).abs() < 1e-6);
}

#[test]
fn odd_sizes_are_padded_for_4_2_0_and_kept_exactly_by_ffv1() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("odd.mkv");
    make(&input, "-f lavfi -i testsrc=size=321x241:rate=25 -t 0.4 -c:v ffv1");
    let preset = bundled("campro-omega-0.5.json");
    let run =
        campro().arg("simulate").arg(&preset).arg(&input).arg("-o").arg(dir.path().join("h264")).output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("321 x 241") && err.contains("written as 322 x 242"), "{err}");
    let h264 = dir.path().join("h264/odd.mkv");
    assert_eq!(probe(&h264, "v:0", "stream=width,height"), "322\n242");
    assert_eq!(probe(&h264, "v:0", "stream=nb_read_frames"), "10");
    // The added column repeats the last one (within the codec's error), not black.
    let frame = rgb_frames(&h264);
    let (w, row) = (322usize, 322 * 3);
    let (mut diff, mut n) = (0.0, 0.0);
    for y in 0..241 {
        for c in 0..3 {
            diff += (frame[y * row + (w - 1) * 3 + c] as f64 - frame[y * row + (w - 2) * 3 + c] as f64).abs();
            n += 1.0;
        }
    }
    assert!(diff / n < 12.0, "mean difference of the padded column to its neighbour: {}", diff / n);

    let run = campro()
        .arg("simulate")
        .arg(&preset)
        .arg(&input)
        .arg("-o")
        .arg(dir.path().join("ffv1"))
        .args(["--codec", "ffv1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success() && !err.contains("even sizes"), "{err}");
    let lossless = dir.path().join("ffv1/odd.mkv");
    let src = rgb_frames(&input);
    let mut want = vec![0u8; src.len()];
    Exact8::new(&Params::from_file(&preset).unwrap()).run(&src, &mut want);
    assert_eq!(rgb_frames(&lossless), want, "321 x 241 kept, every frame the exact path");
}

/// [`decoded`] as 16-bit RGB.
fn rgb48_frames(path: &Path) -> Vec<u16> {
    decoded(path, "rgb48le").chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect()
}

#[test]
fn ten_bit_video_goes_through_the_16_bit_path_and_stays_ten_bit() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("ten.mp4");
    make(&input, "-f lavfi -i testsrc2=size=128x96:rate=25 -t 0.4 -c:v libx264 -pix_fmt yuv420p10le");
    let preset = bundled("campro-omega-0.5.json");
    for codec in ["ffv1", "libx264"] {
        let run = campro()
            .arg("simulate")
            .arg(&preset)
            .arg(&input)
            .arg("-o")
            .arg(dir.path().join(codec))
            .args(["--codec", codec])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success() && err.contains("16-bit frames"), "{err}");
    }
    assert_eq!(probe(&dir.path().join("libx264/ten.mp4"), "v:0", "stream=pix_fmt"), "yuv420p10le");
    assert_eq!(probe(&dir.path().join("ffv1/ten.mkv"), "v:0", "stream=pix_fmt"), "gbrp16le");
    // Lossless: each frame is the 16-bit reference path on the decoded 16-bit input frame.
    let p = Params::from_file(&preset).unwrap();
    let prep = campro::pipeline::Prepared::new(&p, campro::pipeline::Depth::Sixteen);
    let src = rgb48_frames(&input);
    let mut want = vec![0u16; src.len()];
    prep.run(&src, &mut want, campro::pipeline::Depth::Sixteen);
    let got = rgb48_frames(&dir.path().join("ffv1/ten.mkv"));
    assert_eq!(got.len(), src.len());
    assert!(got == want, "the 16-bit frames differ from the 16-bit path");
    // More than 8 bits survive: 10-bit input gives more than 256 levels a channel.
    let levels: std::collections::BTreeSet<u16> = got.iter().step_by(3).copied().collect();
    assert!(levels.len() > 256, "{} levels of red", levels.len());
}

/// How long one piped campro run may take before the test kills it and fails: a stalled
/// pipe is a failure with its stderr, never a CI run that never ends.
const PIPED_LIMIT: std::time::Duration = std::time::Duration::from_secs(180);

/// Waits for `child` (stdout and stderr piped) at most [`PIPED_LIMIT`]; past it, kills it
/// (and `also`, its source) and fails the test with the stderr it printed so far.
fn finish(mut child: std::process::Child, also: Option<&mut std::process::Child>) -> std::process::Output {
    use std::io::Read;
    use std::sync::{Arc, Mutex};
    // Read as it comes, so that a stopped run still shows what it said.
    fn drain(r: Option<impl Read + Send + 'static>, into: Arc<Mutex<Vec<u8>>>) -> std::thread::JoinHandle<()> {
        std::thread::spawn(move || {
            let Some(mut r) = r else { return };
            let mut buf = [0u8; 65536];
            while let Ok(n @ 1..) = r.read(&mut buf) {
                into.lock().unwrap().extend_from_slice(&buf[..n]);
            }
        })
    }
    let (out, err) = (Arc::new(Mutex::new(Vec::new())), Arc::new(Mutex::new(Vec::new())));
    let readers = [drain(child.stdout.take(), out.clone()), drain(child.stderr.take(), err.clone())];
    let began = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if began.elapsed() > PIPED_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            if let Some(a) = also {
                let _ = a.kill();
                let _ = a.wait();
            }
            // The pipes may be held by a stalled grandchild: the readers are not waited for.
            let said = String::from_utf8_lossy(&err.lock().unwrap()).into_owned();
            panic!("campro ran over {} s and was stopped; its stderr so far:\n{said}", PIPED_LIMIT.as_secs());
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    for r in readers {
        r.join().unwrap();
    }
    let take = |v: Arc<Mutex<Vec<u8>>>| std::mem::take(&mut *v.lock().unwrap());
    std::process::Output { status, stdout: take(out), stderr: take(err) }
}

/// Runs campro with `stdin` on standard input; returns its stdout and stderr.
fn piped(args: &[&std::ffi::OsStr], stdin: Vec<u8>) -> (bool, Vec<u8>, String) {
    let mut child = std::process::Command::new(assert_cmd::cargo::cargo_bin("campro"))
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut sin = child.stdin.take().unwrap();
    let feeder = std::thread::spawn(move || {
        use std::io::Write;
        let _ = sin.write_all(&stdin);
    });
    let out = finish(child, None);
    feeder.join().unwrap();
    (out.status.success(), out.stdout, String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn standard_input_and_output_carry_containers_and_raw_frames() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let preset = bundled("campro-omega-0.5.json");
    let params = Params::from_file(&preset).unwrap();
    let exact = Exact8::new(&params);
    let os = |s: &str| std::ffi::OsString::from(s);
    // A Matroska stream in, a lossless Matroska stream out: every frame the exact path.
    let mkv = ffmpeg(&[
        "-f",
        "lavfi",
        "-i",
        "testsrc2=size=96x64:rate=20",
        "-t",
        "0.5",
        "-c:v",
        "ffv1",
        "-f",
        "matroska",
        "-",
    ]);
    let input = dir.path().join("in.mkv");
    std::fs::write(&input, &mkv).unwrap();
    let args = [os("simulate"), preset.clone().into_os_string(), os("-"), os("-o"), os("-"), os("--codec"), os("ffv1")];
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (ok, out, err) = piped(&args, mkv.clone());
    assert!(ok, "{err}");
    assert!(err.contains("simulated 10 frames of standard input into standard output"), "{err}");
    let output = dir.path().join("out.mkv");
    std::fs::write(&output, &out).unwrap();
    let src = rgb_frames(&input);
    let mut want = vec![0u8; src.len()];
    exact.run(&src, &mut want);
    assert_eq!(rgb_frames(&output), want);
    assert_eq!(timestamps(&output), timestamps(&input));

    // Raw RGB in (--size, --rate), raw RGB out, and --frames stops early.
    let raw: Vec<u8> = (0..5 * 32 * 24 * 3).map(|i| (i * 37 % 251) as u8).collect();
    let args = [
        os("simulate"),
        preset.clone().into_os_string(),
        os("-"),
        os("--size"),
        os("32x24"),
        os("--rate"),
        os("30000/1001"),
        os("-o"),
        os("-"),
        os("--codec"),
        os("rawvideo"),
        os("--frames"),
        os("3"),
    ];
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (ok, out, err) = piped(&args, raw.clone());
    assert!(ok, "{err}");
    let frame = 32 * 24 * 3;
    let mut want = vec![0u8; 3 * frame];
    exact.run(&raw[..3 * frame], &mut want);
    assert_eq!(out, want, "three raw frames out, each the exact path");
    assert!(err.contains("the source's 30.0") || err.contains("the source's 29.9"), "{err}");

    // Standard input into a named file, then the usual rules.
    let named = dir.path().join("named.mkv");
    let args = [os("simulate"), preset.clone().into_os_string(), os("-"), os("-o"), named.clone().into_os_string()];
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (ok, _, err) = piped(&args, mkv.clone());
    assert!(ok && named.is_file(), "{err}");
    let (ok, _, err) = piped(&args, mkv);
    assert!(!ok && err.contains("exists"), "{err}");

    // What ffmpeg cannot read from a pipe gets the reason and the ways out, in one line.
    let mp4 = dir.path().join("clip.mp4");
    make(&mp4, "-f lavfi -i testsrc2=size=64x48:rate=10 -t 0.5 -c:v libx264");
    let args = [os("simulate"), preset.clone().into_os_string(), os("-"), os("-o"), os("-")];
    let args: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_os_str()).collect();
    let (ok, _, err) = piped(&args, b"not a video at all".repeat(100));
    assert!(!ok && err.contains("faststart") && err.contains("--size") && err.lines().count() == 1, "{err}");
    // Refusals by name.
    fails_with(campro().arg("simulate").arg(&preset).arg("-").arg(&mp4).arg("-o").arg("-"), "one input only");
    fails_with(
        campro().arg("simulate").arg(&preset).arg(&mp4).arg("-o").arg(dir.path().join("o")).args(["--size", "2x2"]),
        "--size",
    );
    fails_with(campro().arg("simulate").arg(&preset).arg("-").arg("-o").arg(dir.path()), "video file name");
    fails_with(
        campro()
            .arg("simulate")
            .arg(&preset)
            .arg(&mp4)
            .arg("-o")
            .arg(dir.path().join("r"))
            .args(["--codec", "rawvideo"]),
        "rawvideo",
    );
    fails_with(campro().arg("simulate").arg(&preset).arg("-").args(["--rate", "0", "-o", "-"]), "--rate");
    fails_with(campro().arg("simulate").arg(&preset).arg("-").args(["--size", "3x", "-o", "-"]), "--size");
}

/// A live source at its own pace (ffmpeg's `-re` on a generated pattern, piped in as a
/// camera would stream): the run keeps up and says the rate it sustained. A real V4L2
/// camera (`/dev/videoN`) goes through the same code with ffmpeg's v4l2 input; it is not
/// run here (a machine's device may never deliver a frame: `simulate` then stops at its
/// first-frame limit, which `a_source_that_gives_no_frame_is_stopped_by_its_limit` tests).
#[test]
fn a_live_source_is_processed_at_its_pace_and_the_rate_reported() {
    if !ffmpeg_present() {
        return;
    }
    let preset = bundled("campro-omega-0.5.json");
    let mut source = Command::new("ffmpeg")
        .args(["-hide_banner", "-v", "error", "-nostdin", "-re", "-f", "lavfi", "-i", "testsrc2=size=320x240:rate=30"])
        .args(["-t", "1.5", "-c:v", "rawvideo", "-pix_fmt", "rgb24", "-f", "nut", "-"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let run = Command::new(assert_cmd::cargo::cargo_bin("campro"))
        .arg("simulate")
        .arg(&preset)
        .args(["-", "-o", "-", "--codec", "rawvideo"])
        .stdin(source.stdout.take().unwrap())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let run = finish(run, Some(&mut source));
    // The source ends by itself once campro has read (or dropped) its pipe.
    let began = std::time::Instant::now();
    while source.try_wait().unwrap().is_none() {
        if began.elapsed() > PIPED_LIMIT {
            let _ = source.kill();
            panic!("the source ffmpeg did not end");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert_eq!(run.stdout.len(), 45 * 320 * 240 * 3, "{err}");
    // "simulated 45 frames ... (N frames a second, the camera stage alone C; the source's
    // 30.0)": a camera stage slower than the source is said to drop frames.
    let summary = err.lines().find(|l| l.starts_with("simulated")).unwrap();
    let capacity: f64 =
        summary.split("stage alone ").nth(1).and_then(|s| s.split(';').next()).unwrap().parse().unwrap();
    eprintln!("live 320x240 at 30 fps: the camera stage does {capacity:.1} frames a second");
    assert!(summary.contains("the source's 30.0") && capacity > 0.0, "{err}");
    assert_eq!(capacity < 28.5, err.contains("drops frames"), "{err}");
}

/// A live source that stops giving frames (its pipe open, nothing on it) ends the run with
/// one line after `--stall` seconds, before its first frame and after some; the decoder is
/// stopped with it (no process is left behind holding the pipe).
#[test]
fn a_source_that_gives_no_frame_is_stopped_by_its_limit() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let preset = bundled("campro-omega-0.5.json");
    let clip = dir.path().join("clip.nut");
    // 40 frames of 320 x 240 (9 MB): past the 5 MB ffmpeg reads of a pipe before its first
    // frame, so that the frames are given and the silence comes after them.
    let pattern = "testsrc2=size=320x240:rate=30";
    let nut = ffmpeg(&[
        "-f",
        "lavfi",
        "-i",
        pattern,
        "-frames:v",
        "40",
        "-c:v",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-f",
        "nut",
        "-",
    ]);
    std::fs::write(&clip, nut).unwrap();
    for (producer, said) in [
        ("exec sleep 60".to_string(), "standard input gave no frame in 3 s (--stall)"),
        (format!("cat '{}'; exec sleep 60", clip.display()), "standard input gave no frame for 3 s after frame "),
    ] {
        let mut source =
            Command::new("sh").args(["-c", &producer]).stdout(std::process::Stdio::piped()).spawn().unwrap();
        let began = std::time::Instant::now();
        let run = Command::new(assert_cmd::cargo::cargo_bin("campro"))
            .arg("simulate")
            .arg(&preset)
            .args(["-", "-o", "-", "--codec", "rawvideo", "--stall", "3"])
            .stdin(source.stdout.take().unwrap())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let run = finish(run, Some(&mut source));
        let took = began.elapsed().as_secs_f64();
        let _ = source.kill();
        let _ = source.wait();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success() && err.contains(said), "{producer}: {err}");
        assert_eq!(err.lines().filter(|l| l.starts_with("error")).count(), 1, "{err}");
        assert!(took < 30.0, "{producer}: stopped after {took:.1} s");
        // After frames: how many came through (ffmpeg may hold the last few back).
        if let Some(n) = err.split("after frame ").nth(1) {
            let n: u64 = n.split(' ').next().unwrap().parse().unwrap();
            assert!((1..=40).contains(&n), "{err}");
            assert_eq!(run.stdout.len() as u64, n * 320 * 240 * 3, "the frames before the stall are written");
        }
    }
    fails_with(
        campro().arg("simulate").arg(&preset).arg(&clip).args(["--stall", "5", "-o"]).arg(dir.path().join("o.mkv")),
        "--stall",
    );
    fails_with(campro().arg("simulate").arg(&preset).arg("-").args(["--stall", "0", "-o", "-"]), "--stall");
}

/// A network stream (here `http://127.0.0.1:PORT/…`, served by the test) is read as a live
/// source: every frame comes out through the camera, the run says no audio is kept; a
/// scheme this ffmpeg does not read would be one line, and a URL with no host is not a URL.
#[test]
fn a_network_stream_is_a_live_source() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src.mkv");
    make(&src, "-f lavfi -i testsrc2=size=64x48:rate=10 -t 1 -c:v ffv1");
    let body = std::fs::read(&src).unwrap();
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    // One HTTP/1.0 answer for each connection ffmpeg opens (it may probe and reopen).
    std::thread::spawn(move || {
        use std::io::{Read, Write};
        for conn in listener.incoming() {
            let Ok(mut c) = conn else { return };
            let mut req = [0u8; 4096];
            let _ = c.read(&mut req);
            let head =
                format!("HTTP/1.0 200 OK\r\nContent-Type: video/x-matroska\r\nContent-Length: {}\r\n\r\n", body.len());
            let _ = c.write_all(head.as_bytes());
            let _ = c.write_all(&body);
        }
    });
    let out = dir.path().join("out.mkv");
    let child = std::process::Command::new(assert_cmd::cargo::cargo_bin("campro"))
        .arg("simulate")
        .arg(bundled("campro-omega-0.5.json"))
        .arg(format!("http://127.0.0.1:{port}/src.mkv"))
        .arg("-o")
        .arg(&out)
        .args(["--codec", "ffv1"])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let run = finish(child, None);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("a live network stream: its video only (no audio is kept)"), "{err}");
    // Ten frames in, ten out, each the exact path's output of its input frame.
    let (input, output) = (rgb_frames(&src), rgb_frames(&out));
    assert_eq!(input.len(), 10 * 64 * 48 * 3);
    let params = Params::from_file(&bundled("campro-omega-0.5.json")).unwrap();
    let mut want = vec![0u8; input.len()];
    Exact8::new(&params).run(&input, &mut want);
    assert_eq!(output, want);
    fails_with(
        campro().arg("simulate").arg("identity").arg("http://").arg("-o").arg(dir.path().join("o.mkv")),
        "http://",
    );
}

/// `--metadata` on video, a container of each kind with every kind of field: the global
/// tags (title, artist, comment, location, make and model, creation time), a subtitle
/// track naming a person, chapter titles, a data track (a timecode), cover art stored before
/// the video. `strip` keeps nothing, `keep-safe` the creation time, make and model, `keep`
/// the rest but never the data track or the cover; the file's bytes are searched too.
#[test]
fn metadata_policy_applies_to_video_containers() {
    if !ffmpeg_present() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    std::fs::write(d("s.srt"), "1\n00:00:00,000 --> 00:00:00,900\nAlice Example waves\n").unwrap();
    std::fs::write(d("ch.txt"), ";FFMETADATA1\n[CHAPTER]\nTIMEBASE=1/1000\nSTART=0\nEND=500\ntitle=Alice at home\n")
        .unwrap();
    let cover = d("cover.png");
    ffmpeg(&["-f", "lavfi", "-i", "color=c=red:size=32x32", "-frames:v", "1", &cover]);
    let tags = [
        "title=Alice's birthday",
        "artist=Alice Example",
        "comment=at Alice's home",
        "location=+48.8577+002.2950/",
        "creation_time=2026-05-01T10:11:12Z",
    ];
    let base = |out: &str, extra: &str| {
        let mut a: Vec<String> = "-f lavfi -i testsrc=size=64x48:rate=10:duration=1 -f lavfi -i sine=duration=1"
            .split(' ')
            .map(String::from)
            .collect();
        a.extend(["-i".into(), d("s.srt"), "-i".into(), d("ch.txt"), "-i".into(), cover.clone()]);
        a.extend(extra.split(' ').map(String::from));
        for t in tags {
            a.extend(["-metadata".into(), t.into()]);
        }
        a.push(d(out));
        ffmpeg(&a.iter().map(String::as_str).collect::<Vec<_>>());
    };
    // MP4: cover art first, then the video, audio and a subtitle track.
    base("in.mp4", "-map 4 -map 0 -map 1 -map 2 -map_chapters 3 -c:v:0 png -disposition:v:0 attached_pic -c:v:1 libx264 -c:a aac -c:s mov_text");
    // MOV: QuickTime make and model keys, and a timecode data track.
    base("in.mov", "-map 0 -map 1 -map_chapters 3 -c:v libx264 -c:a aac -timecode 00:00:10:00 -movflags use_metadata_tags -metadata com.apple.quicktime.make=Apple -metadata com.apple.quicktime.model=iPhone15");
    // MKV: free-form make and model, a subtitle track, the cover as a second video stream.
    base("in.mkv", "-map 0 -map 1 -map 2 -map 4 -map_chapters 3 -c:v:0 libx264 -c:v:1 png -disposition:v:1 attached_pic -c:a aac -c:s srt -metadata make=Google -metadata model=Pixel9");
    let fields = |f: &str| -> String {
        let out = Command::new("ffprobe")
            .args([
                "-v",
                "error",
                "-of",
                "json",
                "-show_entries",
                "format_tags:stream=codec_type,disposition:chapter_tags",
            ])
            .arg(d(f))
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).to_lowercase()
    };
    for ext in ["mp4", "mov", "mkv"] {
        let input = format!("in.{ext}");
        let given = fields(&input);
        for t in ["alice example", "48.8577", "alice at home", "2026-05-01"] {
            assert!(given.contains(t), "{ext}: the input lacks {t}: {given}");
        }
        for policy in ["strip", "keep-safe", "keep"] {
            let out = format!("{policy}.{ext}");
            let run = campro()
                .args(["simulate", "identity", &d(&input), "-o", &d(&out), "--metadata", policy])
                .output()
                .unwrap();
            assert!(run.status.success(), "{ext} {policy}: {}", String::from_utf8_lossy(&run.stderr));
            let got = fields(&out);
            let bytes = std::fs::read(d(&out)).unwrap();
            let holds = |t: &str| bytes.windows(t.len()).any(|w| w.eq_ignore_ascii_case(t.as_bytes()));
            let streams = |kind: &str| got.matches(&format!("\"codec_type\": \"{kind}\"")).count();
            // Never the cover (one video stream) nor the input's timecode data track.
            assert_eq!(streams("video"), 1, "{ext} {policy}: {got}");
            assert_eq!(streams("audio"), 1, "{ext} {policy}: {got}");
            let names = ["alice's birthday", "alice example", "48.8577", "alice at home", "at alice's home"];
            match policy {
                "strip" | "keep-safe" => {
                    for t in names {
                        assert!(!got.contains(t) && !holds(t), "{ext} {policy} keeps {t}: {got}");
                    }
                    assert_eq!(streams("subtitle") + streams("data"), 0, "{ext} {policy}: {got}");
                    let dated = got.contains("2026-05-01");
                    assert_eq!(dated, policy == "keep-safe", "{ext} {policy}: the creation time: {got}");
                    let camera = got.contains("iphone15") || got.contains("pixel9");
                    assert_eq!(camera, policy == "keep-safe" && ext != "mp4", "{ext} {policy}: make and model: {got}");
                }
                _ => {
                    for t in ["alice example", "alice's birthday"] {
                        assert!(got.contains(t), "{ext} keep lost {t}: {got}");
                    }
                    assert!(got.contains("alice at home"), "{ext} keep lost the chapters: {got}");
                    if ext != "mov" {
                        assert_eq!(streams("subtitle"), 1, "{ext} keep lost the subtitles: {got}");
                    }
                }
            }
        }
    }
}
