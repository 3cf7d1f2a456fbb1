//! Video through `campro simulate`: ffmpeg decodes (a process, raw RGB on a pipe), every
//! frame goes through the exact 8-bit path on all cores, ffmpeg encodes (raw RGB in on a
//! pipe), and the input's audio, subtitle and data streams and metadata are copied. Frames
//! stream through: memory holds a few frames whatever the length.
//!
//! What is kept: the frame size, the frame count, the frame rate (the stream's
//! `r_frame_rate`; the output is constant-rate), the rotation (display matrix), every other
//! stream, the container metadata. The output is written to a temporary file beside its
//! destination and renamed when ffmpeg has finished, under the usual overwrite rules.

use anyhow::{anyhow, bail, Context, Result};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Frames in flight between the decoder, the camera and the encoder.
const IN_FLIGHT: usize = 4;
/// Bytes of an ffmpeg's error output kept (the rest is read and dropped).
const STDERR_KEPT: usize = 64 << 10;

/// `path` as ffmpeg's `file:` URL of its absolute form: a name such as `-report:x.mp4`
/// or `pipe:0.mp4` is then never read as an option or a protocol.
pub(crate) fn file_url(path: &Path) -> Result<std::ffi::OsString> {
    let abs = std::path::absolute(path).with_context(|| campro::file::shown(path))?;
    let mut url = std::ffi::OsString::from("file:");
    url.push(abs.as_os_str());
    Ok(url)
}

/// Reads a child's stderr on its own thread to the end, keeping the first [`STDERR_KEPT`]
/// bytes: a child that prints more than a pipe holds never blocks on it.
fn drain(stderr: Option<std::process::ChildStderr>) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut kept = Vec::new();
        if let Some(mut e) = stderr {
            let mut buf = [0u8; 8192];
            loop {
                match e.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => {
                        let room = STDERR_KEPT.saturating_sub(kept.len());
                        kept.extend_from_slice(&buf[..n.min(room)]);
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
        }
        kept
    })
}

/// The ffmpeg processes running now, for [`kill_children`].
static CHILDREN: std::sync::Mutex<Vec<u32>> = std::sync::Mutex::new(Vec::new());

/// Ends every ffmpeg this process started and has not waited for (SIGINT/SIGTERM
/// handler: an orphaned encoder would go on writing its output after we are gone).
pub fn kill_children() {
    let pids = std::mem::take(&mut *CHILDREN.lock().unwrap_or_else(|p| p.into_inner()));
    #[cfg(unix)]
    for pid in pids {
        if let Ok(pid) = i32::try_from(pid) {
            // SAFETY: kill(2) with a pid we spawned and a valid signal has no memory effects.
            unsafe {
                libc::kill(pid, libc::SIGKILL);
            }
        }
    }
    #[cfg(not(unix))]
    drop(pids);
}

/// Spawns `cmd`, registering it for [`kill_children`].
fn spawn(cmd: &mut Command, what: &str) -> Result<std::process::Child> {
    let child = cmd.spawn().with_context(|| format!("starting ffmpeg to {what}"))?;
    CHILDREN.lock().unwrap_or_else(|p| p.into_inner()).push(child.id());
    Ok(child)
}

/// Waits for `child` and forgets it.
fn wait(child: &mut std::process::Child) -> Result<std::process::ExitStatus> {
    let status = child.wait()?;
    CHILDREN.lock().unwrap_or_else(|p| p.into_inner()).retain(|&p| p != child.id());
    Ok(status)
}

/// File endings read as video.
pub const VIDEO_EXTENSIONS: &[&str] = &["mp4", "m4v", "mov", "mkv", "webm", "avi"];

/// Whether `path` names a video by its ending.
pub fn is_video(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| VIDEO_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// How to encode.
#[derive(Debug, Clone)]
pub struct Encoding {
    /// ffmpeg encoder name (`libx264`, `ffv1`, `libvpx-vp9`, ...).
    pub codec: String,
    /// Constant quality (`-crf`), when no bitrate is given.
    pub crf: Option<u32>,
    /// Target bitrate (`-b:v`, e.g. `8M`).
    pub bitrate: Option<String>,
    /// Encoder preset (`-preset`), for encoders that have one.
    pub preset: Option<String>,
}

impl Encoding {
    /// Whether the codec is lossless (output frames decode to exactly what was encoded).
    pub fn lossless(&self) -> bool {
        self.codec == "ffv1"
    }

    /// The output path for `wanted`: a lossless codec needs a container that holds it
    /// (Matroska); the ending is changed, and the caller says so.
    pub fn output_path(&self, wanted: &Path) -> PathBuf {
        let ext = wanted.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        if self.lossless() && !matches!(ext.as_str(), "mkv" | "avi") {
            return wanted.with_extension("mkv");
        }
        wanted.to_path_buf()
    }
}

/// The first video stream, as ffprobe reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// `r_frame_rate`, as ffmpeg writes it (`30000/1001`).
    pub rate: String,
    /// Frames, when the container says (`nb_frames`).
    pub frames: Option<u64>,
    /// Rotation from the display matrix, degrees.
    pub rotation: Option<i64>,
}

/// Fails with a message saying how to install ffmpeg when `name` cannot be run.
fn installed(name: &str) -> Result<()> {
    match Command::new(name).arg("-version").stdout(Stdio::null()).stderr(Stdio::null()).status() {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "{name} is not installed; video needs ffmpeg and ffprobe on PATH (Debian/Ubuntu: apt-get install ffmpeg; macOS: brew install ffmpeg)"
        ),
        Err(e) => bail!("{name}: {e}"),
    }
}

/// `ffmpeg`, quiet but for errors, never reading the terminal.
fn ffmpeg() -> Result<Command> {
    installed("ffmpeg")?;
    let mut c = Command::new("ffmpeg");
    c.args(["-hide_banner", "-v", "error", "-nostdin"]);
    Ok(c)
}

/// Reads the first video stream's size, rate, frame count and rotation.
pub fn probe(input: &Path) -> Result<Probe> {
    installed("ffprobe")?;
    let out = Command::new("ffprobe")
        .args(["-hide_banner", "-v", "error", "-select_streams", "v:0", "-of", "json", "-show_entries"])
        .arg("stream=width,height,r_frame_rate,nb_frames:stream_side_data=rotation")
        .arg(file_url(input)?)
        .stdin(Stdio::null())
        .output()?;
    if !out.status.success() {
        bail!("ffprobe: {}", first_line(&out.stderr));
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).context("ffprobe printed no JSON")?;
    let s = v.pointer("/streams/0").ok_or_else(|| anyhow!("no video stream"))?;
    let dim = |k: &str| s.get(k).and_then(|x| x.as_u64()).filter(|&d| (1..=16384).contains(&d)).map(|d| d as u32);
    let (width, height) =
        dim("width").zip(dim("height")).ok_or_else(|| anyhow!("the video's size is missing or over 16384"))?;
    let rate = s.get("r_frame_rate").and_then(|r| r.as_str()).unwrap_or("").to_string();
    let ok = rate
        .split_once('/')
        .is_some_and(|(n, d)| n.parse::<u32>().is_ok_and(|n| n > 0) && d.parse::<u32>().is_ok_and(|d| d > 0));
    if !ok {
        bail!("the video's frame rate {rate:?} is not a positive fraction");
    }
    let frames = s.get("nb_frames").and_then(|n| n.as_str()).and_then(|n| n.parse().ok());
    let rotation = s
        .get("side_data_list")
        .and_then(|l| l.as_array())
        .and_then(|l| l.iter().find_map(|d| d.get("rotation").and_then(|r| r.as_i64())));
    Ok(Probe { width, height, rate, frames, rotation })
}

/// Simulates `params`' camera on `input` into `output` (which the caller checked).
pub fn simulate(
    capture: &crate::capture::Capture,
    input: &Path,
    output: &Path,
    enc: &Encoding,
    force: bool,
    warn: &dyn Fn(&str),
) -> Result<u64> {
    let p = probe(input)?;
    let frame_bytes = 3 * p.width as usize * p.height as usize;
    // The frames in flight (the pool, the output frame) come from the process's budget.
    let held = (frame_bytes as u64).saturating_mul(IN_FLIGHT as u64 + 1);
    let budget = campro_eval::image_file::Budget::global();
    let Some(_lease) = budget.take(held) else {
        bail!(
            "the video is {} x {} pixels; its {} frames in flight need {} MiB, over the {} MiB limit",
            p.width,
            p.height,
            IN_FLIGHT + 1,
            held >> 20,
            budget.total() >> 20
        );
    };
    let mut decode = ffmpeg()?;
    let decode = decode
        .args(["-autorotate", "0", "-i"])
        .arg(file_url(input)?)
        .args(["-map", "0:v:0", "-fps_mode", "passthrough", "-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut decode = spawn(decode, "decode")?;
    let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("mkv");
    let tmp = campro_eval::atomic::temporary_beside(output, &format!(".{ext}"))
        .with_context(|| output.display().to_string())?;
    let mut cmd = ffmpeg()?;
    cmd.args(["-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", &format!("{}x{}", p.width, p.height)])
        .args(["-framerate", &p.rate, "-i", "-", "-i"])
        .arg(file_url(input)?)
        .args(["-map", "0:v", "-map", "1:a?", "-map", "1:s?", "-map", "1:d?", "-map_metadata", "1"])
        .args(["-fps_mode", "passthrough", "-c:a", "copy", "-c:s", "copy", "-c:d", "copy", "-c:v", &enc.codec]);
    if enc.lossless() {
        cmd.args(["-pix_fmt", "gbrp", "-level", "3"]);
    } else if enc.codec.starts_with("libx26") || enc.codec.starts_with("libvpx") {
        cmd.args(["-pix_fmt", "yuv420p"]);
    }
    match (&enc.bitrate, enc.crf) {
        (Some(b), _) => {
            cmd.args(["-b:v", b]);
        }
        (None, Some(q)) if !enc.lossless() => {
            cmd.args(["-crf", &q.to_string()]);
            if enc.codec.starts_with("libvpx") {
                cmd.args(["-b:v", "0"]);
            }
        }
        _ => {}
    }
    if let Some(pr) = &enc.preset {
        cmd.args(["-preset", pr]);
    }
    cmd.arg(file_url(tmp.path())?).stdin(Stdio::piped()).stderr(Stdio::piped());
    let mut encode = spawn(&mut cmd, "encode")?;
    let bar = match p.frames {
        Some(n) => indicatif::ProgressBar::new(n),
        None => indicatif::ProgressBar::no_length(),
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} frames {per_sec} eta {eta}")
            .expect("valid template"),
    );
    bar.set_message(input.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default());
    // Three stages overlap: a reader thread fills frames from the decoder, this thread runs
    // the camera on every core, a writer thread feeds the encoder. Frames circulate through
    // a fixed pool of IN_FLIGHT buffers, so memory stays bounded whatever the length.
    let mut frames = 0u64;
    let mut from = decode.stdout.take().expect("piped");
    let mut to = encode.stdin.take().expect("piped");
    let dec_err = drain(decode.stderr.take());
    let enc_err = drain(encode.stderr.take());
    let (free_tx, free_rx) = std::sync::mpsc::sync_channel::<Vec<u8>>(IN_FLIGHT);
    let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<Vec<u8>>(IN_FLIGHT);
    let (done_tx, done_rx) = std::sync::mpsc::sync_channel::<Vec<u8>>(IN_FLIGHT);
    for _ in 0..IN_FLIGHT {
        free_tx.send(vec![0u8; frame_bytes]).expect("room for the pool");
    }
    let result = std::thread::scope(|scope| {
        let reader = scope.spawn(move || -> Result<()> {
            while let Ok(mut buf) = free_rx.recv() {
                if !read_frame(&mut from, &mut buf)? {
                    return Ok(());
                }
                if full_tx.send(buf).is_err() {
                    return Ok(());
                }
            }
            Ok(())
        });
        let writer = scope.spawn(move || -> Result<()> {
            for buf in done_rx {
                to.write_all(&buf).map_err(|e| anyhow!("the encoder stopped: {e}"))?;
                // After the last frame the reader is gone and takes no buffer back; the
                // frames still queued must be written all the same.
                let _ = free_tx.send(buf);
            }
            Ok(())
        });
        let mut out = vec![0u8; frame_bytes];
        let mut failure = None;
        for src in full_rx.iter() {
            if let Err(e) = capture.run(&src, &mut out, p.width, p.height) {
                failure = Some(e);
                break;
            }
            // The processed frame goes to the writer; its input buffer becomes the next output.
            let processed = std::mem::replace(&mut out, src);
            if done_tx.send(processed).is_err() {
                break;
            }
            frames += 1;
            bar.inc(1);
        }
        drop(done_tx);
        // Unblock a reader waiting for a free buffer if the writer quit early.
        drop(full_rx);
        let w = writer.join().unwrap_or_else(|_| Err(anyhow!("the writer thread panicked")));
        let r = reader.join().unwrap_or_else(|_| Err(anyhow!("the reader thread panicked")));
        match failure {
            Some(e) => Err(e),
            None => r.and(w),
        }
    });
    bar.finish_and_clear();
    // A failed run leaves the decoder blocked on a full pipe: stop it.
    if result.is_err() {
        let _ = decode.kill();
    }
    let dec = wait(&mut decode)?;
    let enc_status = wait(&mut encode)?;
    let dec_stderr = dec_err.join().unwrap_or_default();
    let enc_stderr = enc_err.join().unwrap_or_default();
    result?;
    if !dec.success() {
        bail!("ffmpeg could not decode it: {}", first_line(&dec_stderr));
    }
    if !enc_status.success() {
        bail!("ffmpeg could not encode it: {}", first_line(&enc_stderr));
    }
    if let Some(n) = p.frames.filter(|&n| n != frames) {
        warn(&format!("the container says {n} frames; {frames} were decoded and written"));
    }
    // The rotation (display matrix): ffmpeg sets it only when copying streams, so a
    // rotated input's output is remuxed once with it (frames themselves are not rotated).
    let tmp = match p.rotation.filter(|&r| r.rem_euclid(360) != 0) {
        None => tmp,
        Some(r) => {
            let rotated = campro_eval::atomic::temporary_beside(output, &format!(".{ext}"))?;
            let out = ffmpeg()?
                .args(["-y", "-i"])
                .arg(file_url(tmp.path())?)
                .args(["-map", "0", "-c", "copy", "-map_metadata", "0", "-metadata:s:v:0"])
                .arg(format!("rotate={}", r.rem_euclid(360)))
                .arg(file_url(rotated.path())?)
                .output()?;
            if !out.status.success() {
                bail!("ffmpeg could not set the rotation: {}", first_line(&out.stderr));
            }
            if probe(rotated.path())?.rotation != Some(r) {
                warn(&format!("the {ext} container cannot hold its rotation ({r} degrees) with this ffmpeg; frames are kept as stored"));
            }
            rotated
        }
    };
    crate::output_result(output, campro_eval::atomic::persist(tmp, output, force))?;
    Ok(frames)
}

/// Fills `buf` with the next frame; false at a clean end of stream.
fn read_frame(r: &mut impl Read, buf: &mut [u8]) -> Result<bool> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) if got == 0 => return Ok(false),
            Ok(0) => bail!("the decoder stopped inside a frame"),
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e.into()),
        }
    }
    Ok(true)
}

fn first_line(stderr: &[u8]) -> String {
    crate::escape(String::from_utf8_lossy(stderr).lines().next().unwrap_or("no message"))
}
