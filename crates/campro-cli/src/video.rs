//! Video through `campro simulate`: ffmpeg decodes (a process, raw RGB on a pipe, each
//! frame's timestamp beside it), every frame goes through the exact pipeline on all cores,
//! ffmpeg encodes (the frames and their timestamps in on a pipe, as IVF), and a file
//! input's audio is copied, with its metadata, subtitles and chapters as `--metadata` says
//! ([`metadata_args`]); data streams (GPS telemetry) and attached pictures never. Frames
//! stream through: memory holds a few frames whatever the length.
//!
//! What is kept: the frame size (an odd size is padded by one edge-replicated row or column
//! for 4:2:0 codecs, with a warning; `ffv1` keeps it exactly), every frame's timestamp (so
//! variable-frame-rate video keeps its timing and stays in step with its audio), the bit
//! depth (input of more than 8 bits goes through the 16-bit path and is encoded with 10
//! bits, or 16 with `ffv1`), the rotation (display matrix), the audio. HDR transfer curves
//! are noted: the camera model is SDR.
//!
//! Sources: a file, standard input (`-`: any container ffmpeg reads from a pipe, or raw
//! RGB frames of a given size), a live V4L2 camera (`/dev/videoN`). Sinks: a file (written
//! beside its destination and renamed when ffmpeg has finished, under the usual overwrite
//! rules), standard output (`-`: Matroska, or raw RGB with `--codec rawvideo`), a V4L2
//! output device (v4l2loopback).

use crate::capture::Capture;
use crate::metadata::Policy;
use anyhow::{anyhow, bail, Context, Result};
use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;

/// Frames in flight between the decoder, the camera and the encoder (at least).
const IN_FLIGHT: usize = 4;

/// Frames in flight around a camera stage that takes `batch` at once.
fn in_flight(batch: usize) -> usize {
    IN_FLIGHT.max(batch + 2)
}

/// What a video holds from the process's budget, bytes, with `batch` frames of
/// `frame_bytes` enhanced at once: the frames in flight (the pool, the outputs, 16-bit
/// scratch), the decoder's pump, and each enhanced frame's own `work` (the network and the
/// face guard's pyramid: `Capture::work`). Saturating.
fn held_bytes(frame_bytes: u64, work: u64, sixteen: bool, batch: usize) -> u64 {
    frame_bytes
        .saturating_mul((in_flight(batch) + batch) as u64 + if sixteen { 2 } else { 0 })
        .saturating_add((PUMP_CHUNKS * PUMP_CHUNK) as u64)
        .saturating_add(work.saturating_mul(batch as u64))
}

/// Frames enhanced at once: as many as there are `threads` (at least one) whose memory,
/// `held(frames)` bytes, fits in `total`; one when none does (the caller's lease then
/// refuses the video by its size).
fn frames_at_once(threads: usize, total: u64, held: impl Fn(usize) -> u64) -> usize {
    (1..=threads.max(1)).rev().find(|&b| held(b) <= total).unwrap_or(1)
}

/// The decoder's frames are read off its stdout as they come, whatever else waits, in
/// chunks of this many bytes, at most [`PUMP_CHUNKS`] of them ahead of the frame loop.
const PUMP_CHUNK: usize = 1 << 20;
/// Chunks the pump may hold ahead (64 MiB): ffmpeg may write several frames before the
/// timestamp lines of its second output, and a full stdout pipe then blocks it for good.
const PUMP_CHUNKS: usize = 64;
/// Bytes of an ffmpeg's error output kept (the rest is read and dropped).
const STDERR_KEPT: usize = 64 << 10;
/// Longest line read from the decoder's timestamp stream, bytes.
const LINE_MAX: u64 = 4096;
/// Largest frame side, pixels.
const MAX_SIDE: u32 = 16384;

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
fn spawn(cmd: &mut Command, what: &str) -> Result<Reaped> {
    let child = cmd.spawn().with_context(|| format!("starting ffmpeg to {what}"))?;
    CHILDREN.lock().unwrap_or_else(|p| p.into_inner()).push(child.id());
    Ok(Reaped(Some(child)))
}

/// A running ffmpeg that is killed and reaped when dropped before [`Reaped::wait`]: every
/// way out of a run (a refusal after the start, an error, a panic unwinding) ends it, and
/// leaves neither a zombie nor an orphan writing on.
struct Reaped(Option<std::process::Child>);

impl Reaped {
    /// Waits for it to end (after its input closed, or a kill) and forgets it.
    fn wait(mut self) -> Result<std::process::ExitStatus> {
        let mut child = self.0.take().expect("running until waited for");
        wait(&mut child)
    }
}

impl std::ops::Deref for Reaped {
    type Target = std::process::Child;
    fn deref(&self) -> &std::process::Child {
        self.0.as_ref().expect("running until waited for")
    }
}

impl std::ops::DerefMut for Reaped {
    fn deref_mut(&mut self) -> &mut std::process::Child {
        self.0.as_mut().expect("running until waited for")
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        if let Some(mut child) = self.0.take() {
            let _ = child.kill();
            let _ = wait(&mut child);
        }
    }
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

/// Network schemes read as live sources (passed to ffmpeg as they are).
pub const URL_SCHEMES: &[&str] = &["rtsp", "rtsps", "rtmp", "rtmps", "http", "https", "srt", "udp", "tcp", "rtp"];

/// The scheme of an input that names a network stream (`rtsp://camera/1`, `https://…/a.mp4`),
/// lower-cased; None for anything else (file names, `-`, devices).
pub fn url_scheme(input: &Path) -> Option<String> {
    let s = input.to_str()?;
    let (scheme, rest) = s.split_once("://")?;
    let scheme = scheme.to_ascii_lowercase();
    (URL_SCHEMES.contains(&scheme.as_str()) && !rest.is_empty()).then_some(scheme)
}

/// The input protocols `ffmpeg -protocols` lists (its "Input:" section).
pub fn input_protocols(listing: &str) -> Vec<String> {
    listing
        .lines()
        .skip_while(|l| l.trim() != "Input:")
        .skip(1)
        .take_while(|l| l.trim() != "Output:")
        .map(|l| l.trim().to_ascii_lowercase())
        .filter(|l| !l.is_empty())
        .collect()
}

/// The demuxers `ffmpeg -demuxers` lists (lines `` D  name  description``; `D` or `DE`).
pub fn demuxers(listing: &str) -> Vec<String> {
    listing
        .lines()
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            let flags = w.next()?;
            (flags.starts_with('D') && flags.chars().all(|c| c == 'D' || c == 'E')).then(|| w.next()).flatten()
        })
        .flat_map(|names| names.split(',').map(str::to_ascii_lowercase).collect::<Vec<_>>())
        .collect()
}

/// What ffmpeg needs to read `scheme`: a demuxer for RTSP (which is a demuxer there, not a
/// protocol; `rtsps` also needs TLS), an input protocol for every other scheme.
fn needs(scheme: &str) -> (&'static str, &str) {
    match scheme {
        "rtsp" | "rtsps" => ("demuxer", "rtsp"),
        s => ("protocol", s),
    }
}

/// Checks that this machine's ffmpeg reads `scheme`: one line naming it when not.
pub fn check_protocol(scheme: &str) -> Result<()> {
    let listing = |flag: &str| -> Result<String> {
        let out = ffmpeg()?.args(["-hide_banner", flag]).stdin(Stdio::null()).output()?;
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let (kind, name) = needs(scheme);
    let mut has = if kind == "demuxer" {
        demuxers(&listing("-demuxers")?).iter().any(|d| d == name)
    } else {
        input_protocols(&listing("-protocols")?).iter().any(|p| p == name)
    };
    if scheme == "rtsps" {
        has &= input_protocols(&listing("-protocols")?).iter().any(|p| p == "tls");
    }
    if !has {
        bail!("{scheme}://: this machine's ffmpeg does not read that (ffmpeg -demuxers and -protocols list what it reads)")
    }
    Ok(())
}

/// Whether `path` is a character device (a V4L2 camera or loopback output), Unix only.
pub fn is_device(path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        std::fs::metadata(path).is_ok_and(|m| m.file_type().is_char_device())
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        false
    }
}

/// How to encode.
#[derive(Debug, Clone)]
pub struct Encoding {
    /// ffmpeg encoder name (`libx264`, `ffv1`, `libvpx-vp9`, ...; `rawvideo` on standard
    /// output writes raw RGB frames).
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

    /// Whether the codec is one whose frames campro stores as 4:2:0 (even sizes only).
    fn subsampled(&self) -> bool {
        self.codec.starts_with("libx26") || self.codec.starts_with("libvpx")
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

/// Raw RGB frames: their size and rate (`--size`, `--rate`), for raw standard input; the
/// size and rate asked of a camera.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FrameFormat {
    /// Width and height, pixels.
    pub size: Option<(u32, u32)>,
    /// Frames a second, as ffmpeg reads it (`30`, `30000/1001`).
    pub rate: Option<String>,
    /// Seconds a live source may go without a frame before the run stops with an error
    /// (`--stall`); `None`: a camera gets [`CAMERA_STALL_S`], standard input waits for its
    /// producer as long as it is open.
    pub stall: Option<u32>,
}

/// Seconds a camera may go without a frame (the first one included) before `simulate`
/// stops: a camera that is busy elsewhere or has stopped never hangs the run.
pub const CAMERA_STALL_S: u32 = 10;

/// Where frames come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Source {
    /// A video file: its other streams, metadata and rotation are kept.
    File(PathBuf),
    /// Standard input: a container ffmpeg reads from a pipe, or raw 8-bit RGB frames when
    /// the format gives a size. Audio from a pipe is not kept.
    Stdin(FrameFormat),
    /// A live V4L2 camera (`/dev/videoN`), at the size and rate asked, if any.
    Camera(PathBuf, FrameFormat),
    /// A network stream (`rtsp://`, `http(s)://`, `srt://`, …; [`URL_SCHEMES`]), read as a
    /// live source: its audio is not kept.
    Url(String, FrameFormat),
}

impl Source {
    /// How the source is named in messages.
    pub fn shown(&self) -> String {
        match self {
            Source::File(p) | Source::Camera(p, _) => crate::shown(p),
            Source::Stdin(_) => "standard input".into(),
            Source::Url(u, _) => crate::escape(u),
        }
    }

    fn live(&self) -> bool {
        !matches!(self, Source::File(_))
    }

    /// How long the run waits for this source's next frame: `--stall`, or a camera's
    /// [`CAMERA_STALL_S`]; a file and plain standard input wait as long as the decoder runs.
    fn stall(&self) -> Option<std::time::Duration> {
        let seconds = match self {
            Source::File(_) => None,
            Source::Stdin(f) => f.stall,
            Source::Camera(_, f) | Source::Url(_, f) => Some(f.stall.unwrap_or(CAMERA_STALL_S)),
        };
        seconds.map(|s| std::time::Duration::from_secs(s.into()))
    }
}

/// Where the protected video goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Sink {
    /// A file, replaced atomically (only with `--force` when it exists).
    File(PathBuf),
    /// Standard output: Matroska, or raw RGB frames with `--codec rawvideo`.
    Stdout,
    /// A V4L2 output device (v4l2loopback), raw YUV 4:2:0.
    Device(PathBuf),
}

/// The first video stream that is not an attached picture (cover art), as ffprobe reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Its index among the file's video streams (`0:v:N`): cover art stored before the
    /// video is a video stream too, and is never the one protected.
    pub stream: usize,
    /// Frame width, pixels.
    pub width: u32,
    /// Frame height, pixels.
    pub height: u32,
    /// Frames, when the container says (`nb_frames`).
    pub frames: Option<u64>,
    /// Rotation from the display matrix, degrees.
    pub rotation: Option<i64>,
    /// Bits a sample, when more than 8 (`bits_per_raw_sample`, or the pixel format's).
    pub deep: bool,
    /// The transfer curve, when the stream names one (`smpte2084`, `arib-std-b67`, ...).
    pub transfer: Option<String>,
    /// The container's tags `keep-safe` keeps ([`safe_of`]).
    pub safe_tags: Vec<(String, String)>,
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

/// Whether an ffmpeg pixel format holds more than 8 bits a sample (`yuv420p10le`,
/// `p010le`, `rgb48le`, `gbrp12le`, ...).
pub fn deep_pixel_format(name: &str) -> bool {
    let Some(stem) = name.strip_suffix("le").or_else(|| name.strip_suffix("be")) else {
        return false;
    };
    let digits: String = stem.chars().rev().take_while(|c| c.is_ascii_digit()).collect();
    let bits: u32 = digits.chars().rev().collect::<String>().parse().unwrap_or(0);
    // Packed formats name their bits a pixel (rgb48, rgba64, bgr565); planar ones a sample
    // (yuv420p10, gbrp16, p010).
    match bits {
        9..=16 => !stem.starts_with("rgb") && !stem.starts_with("bgr") || bits == 16 && stem.starts_with("gray"),
        48 | 64 => true,
        _ => false,
    }
}

/// Reads the first video stream's size, frame count, rotation, depth and transfer, skipping
/// attached pictures (an MP4's cover art can come before its video).
pub fn probe(input: &Path) -> Result<Probe> {
    installed("ffprobe")?;
    // ffprobe decodes a frame to learn the stream's format: the same pixel limit as the
    // decoder's bounds that too.
    let max_pixels = max_decoded_pixels(campro_eval::image_file::Budget::global().total());
    let out = Command::new("ffprobe")
        .args(["-hide_banner", "-v", "error", "-max_pixels", &max_pixels.to_string()])
        .args(["-select_streams", "v", "-of", "json", "-show_entries"])
        .arg("stream=width,height,nb_frames,pix_fmt,bits_per_raw_sample,color_transfer:stream_disposition=attached_pic:stream_side_data=rotation:format_tags")
        .arg(file_url(input)?)
        .stdin(Stdio::null())
        .output()?;
    if !out.status.success() {
        if String::from_utf8_lossy(&out.stderr).contains("max pixel count") {
            bail!(
                "its frames are larger than {max_pixels} pixels, what the {} MiB memory limit lets the decoder hold ({} raises it)",
                campro_eval::image_file::Budget::global().total() >> 20,
                campro_eval::image_file::MEMORY_ENV
            );
        }
        bail!("ffprobe: {}", first_line(&out.stderr));
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).context("ffprobe printed no JSON")?;
    let (stream, s) = protected_stream(&v)?;
    let dim =
        |k: &str| s.get(k).and_then(|x| x.as_u64()).filter(|&d| (1..=MAX_SIDE as u64).contains(&d)).map(|d| d as u32);
    let (width, height) =
        dim("width").zip(dim("height")).ok_or_else(|| anyhow!("the video's size is missing or over {MAX_SIDE}"))?;
    let text = |k: &str| s.get(k).and_then(|n| n.as_str()).map(str::to_string);
    let frames = text("nb_frames").and_then(|n| n.parse().ok());
    let rotation = s
        .get("side_data_list")
        .and_then(|l| l.as_array())
        .and_then(|l| l.iter().find_map(|d| d.get("rotation").and_then(|r| r.as_i64())));
    let bits = text("bits_per_raw_sample").and_then(|b| b.parse::<u32>().ok());
    let deep = bits.is_some_and(|b| b > 8) || text("pix_fmt").is_some_and(|f| deep_pixel_format(&f));
    let transfer = text("color_transfer").filter(|t| t != "unknown");
    let safe_tags = safe_of(v.pointer("/format/tags"));
    Ok(Probe { stream, width, height, frames, rotation, deep, transfer, safe_tags })
}

/// The video stream `simulate` protects among ffprobe's `streams` (JSON of `-select_streams
/// v` with `stream_disposition=attached_pic`): the first that is not an attached picture, and
/// its index among the video streams.
fn protected_stream(v: &serde_json::Value) -> Result<(usize, &serde_json::Value)> {
    let streams = v.pointer("/streams").and_then(|s| s.as_array()).map(Vec::as_slice).unwrap_or_default();
    let cover = |s: &serde_json::Value| s.pointer("/disposition/attached_pic").and_then(|a| a.as_i64()) == Some(1);
    streams.iter().enumerate().find(|(_, s)| !cover(s)).ok_or_else(|| {
        if streams.is_empty() {
            anyhow!("no video stream")
        } else {
            anyhow!("no video stream: its {} video stream(s) are attached pictures (cover art)", streams.len())
        }
    })
}

/// What a video run did.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Frames written.
    pub frames: u64,
    /// Frames a second the whole run sustained (decode, camera, encode), first frame to last.
    pub fps: f64,
    /// Frames a second the camera stage alone can do (its busy time): what a live source
    /// must not outrun.
    pub capacity: f64,
    /// Frames a second of the source, from its first and last timestamps (two frames or more).
    pub source_fps: Option<f64>,
    /// Whether the 16-bit path ran.
    pub sixteen: bool,
}

/// One video run.
pub struct Job<'a, 'c, 'p> {
    pub capture: &'a Capture<'c, 'p>,
    pub enc: &'a Encoding,
    /// Replace an existing output file.
    pub force: bool,
    /// Frames of 16 bits even from an 8-bit source (`--bit-depth 16`).
    pub sixteen: bool,
    /// Stop after this many frames (`--frames`).
    pub max_frames: Option<u64>,
    /// What the output keeps of a video file's metadata ([`metadata_args`]).
    pub metadata: crate::metadata::Policy,
}

/// The decoder's timestamp stream (`framecrc` on its stderr): its header, then a
/// presentation timestamp a frame.
enum Clock {
    /// The time base (numerator, denominator) and the frame size.
    Header { tb: (u64, u64), width: u32, height: u32 },
    /// The next frame's presentation timestamp, in the time base.
    Pts(i64),
}

/// Reads the decoder's stderr: `framecrc` lines become [`Clock`] events, other lines (its
/// errors) are kept, at most [`STDERR_KEPT`] bytes.
fn clock(stderr: std::process::ChildStderr, tx: mpsc::Sender<Clock>) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut r = std::io::BufReader::new(stderr);
        let mut kept = Vec::new();
        let mut tb = None;
        let mut line = Vec::new();
        loop {
            line.clear();
            match r.by_ref().take(LINE_MAX).read_until(b'\n', &mut line) {
                Ok(0) | Err(_) => break,
                Ok(_) => {}
            }
            let text = String::from_utf8_lossy(&line);
            let text = text.trim_end();
            let event = if let Some(v) = text.strip_prefix("#tb 0: ") {
                tb = v.split_once('/').and_then(|(n, d)| Some((n.parse::<u64>().ok()?, d.parse::<u64>().ok()?)));
                tb.filter(|&(n, d)| n > 0 && d > 0).map(|_| None)
            } else if let Some(v) = text.strip_prefix("#dimensions 0: ") {
                let size = v.split_once('x').and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)));
                match (tb, size) {
                    (Some(tb), Some((width, height))) => Some(Some(Clock::Header { tb, width, height })),
                    _ => None,
                }
            } else if text.starts_with('#') {
                Some(None)
            } else {
                let f: Vec<&str> = text.split(',').map(str::trim).collect();
                match (f.len(), f.first(), f.get(2).and_then(|p| p.parse::<i64>().ok())) {
                    (6, Some(&"0"), Some(pts)) => Some(Some(Clock::Pts(pts))),
                    _ => None,
                }
            };
            match event {
                Some(Some(e)) => {
                    let _ = tx.send(e);
                }
                Some(None) => {}
                None => {
                    let room = STDERR_KEPT.saturating_sub(kept.len());
                    kept.extend_from_slice(&line[..line.len().min(room)]);
                }
            }
        }
        kept
    })
}

/// The decoder's command: `source`'s video stream `stream` (`0:v:N`) as raw RGB (`rgb24`, or
/// `rgb48le` when `sixteen`) on stdout and each frame's timestamp as `framecrc` on stderr.
fn decoder(source: &Source, sixteen: bool, stream: usize, max_pixels: u64) -> Result<Command> {
    let mut c = ffmpeg()?;
    // The decoder refuses frames larger than the budget holds before allocating them.
    c.args(["-max_pixels", &max_pixels.to_string()]);
    match source {
        Source::File(path) => {
            // Original timestamps, so that the encoder's copy of the other streams lines up.
            c.args(["-copyts", "-autorotate", "0", "-i"]).arg(file_url(path)?);
        }
        Source::Stdin(fmt) => {
            if let Some((w, h)) = fmt.size {
                c.args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-video_size", &format!("{w}x{h}")]);
                c.args(["-framerate", fmt.rate.as_deref().unwrap_or("30")]);
            }
            c.args(["-i", "pipe:0"]).stdin(Stdio::inherit());
        }
        Source::Camera(dev, fmt) => {
            c.args(["-f", "v4l2"]);
            if let Some((w, h)) = fmt.size {
                c.args(["-video_size", &format!("{w}x{h}")]);
            }
            if let Some(r) = &fmt.rate {
                c.args(["-framerate", r]);
            }
            c.arg("-i").arg(dev);
        }
        Source::Url(url, _) => {
            c.arg("-i").arg(url);
        }
    }
    if !matches!(source, Source::Stdin(_)) {
        c.stdin(Stdio::null());
    }
    let pix = if sixteen { "rgb48le" } else { "rgb24" };
    let map = format!("0:v:{stream}");
    c.args(["-map", &map, "-fps_mode", "passthrough", "-flush_packets", "1", "-f", "rawvideo", "-pix_fmt", pix])
        .arg("pipe:1")
        .args(["-map", &map, "-fps_mode", "passthrough", "-enc_time_base", "-1", "-c:v", "wrapped_avframe"])
        .args(["-flush_packets", "1", "-f", "framecrc", "pipe:2"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    Ok(c)
}

/// Format tags `keep-safe` keeps of a video (lower-case keys): the creation time, and the
/// camera's make and model as QuickTime, Android and plain containers name them.
const SAFE_TAGS: [&str; 7] = [
    "creation_time",
    "make",
    "model",
    "com.apple.quicktime.make",
    "com.apple.quicktime.model",
    "com.android.manufacturer",
    "com.android.model",
];

/// The longest tag value `keep-safe` keeps (characters): a date, a make or a model.
const MAX_SAFE_TAG: usize = 64;

/// The format tags `keep-safe` keeps of ffprobe's `format.tags` object: [`SAFE_TAGS`] whose
/// value is printable text of at most [`MAX_SAFE_TAG`] characters (a creation time: digits
/// and `-:.TZ+`).
fn safe_of(tags: Option<&serde_json::Value>) -> Vec<(String, String)> {
    let Some(tags) = tags.and_then(|t| t.as_object()) else { return Vec::new() };
    let mut kept: Vec<(String, String)> = Vec::new();
    for (k, v) in tags {
        let key = k.to_ascii_lowercase();
        let Some(v) = v.as_str() else { continue };
        let fits = v.chars().count() <= MAX_SAFE_TAG
            && if key == "creation_time" {
                !v.is_empty() && v.chars().all(|c| c.is_ascii_digit() || "-:.TZ+ ".contains(c))
            } else {
                v.chars().all(|c| !c.is_control())
            };
        if SAFE_TAGS.contains(&key.as_str()) && fits && !kept.iter().any(|(k, _)| *k == key) {
            kept.push((key, v.to_string()));
        }
    }
    kept
}

/// The encoder's streams and metadata from the source file (input 1) under `policy`:
/// - every policy: the protected video (input 0) and the audio; never a data stream (GPS
///   telemetry such as GoPro's) or an attached picture (cover art, a thumbnail);
/// - `strip`: no global, stream or chapter metadata, no subtitles;
/// - `keep-safe`: only `safe` (the creation time, make and model), no subtitles or chapters
///   (their text can name people); `mov` outputs write them as QuickTime metadata keys;
/// - `keep`: the global metadata, the chapters and the subtitles too.
fn metadata_args(policy: Policy, safe: &[(String, String)], mov: bool) -> Vec<String> {
    let mut a: Vec<String> = ["-map", "0:v", "-map", "1:a?", "-c:a", "copy"].map(String::from).to_vec();
    match policy {
        Policy::Keep => {
            a.extend(["-map", "1:s?", "-c:s", "copy", "-map_metadata", "1", "-map_chapters", "1"].map(String::from));
        }
        Policy::KeepSafe | Policy::Strip => {
            a.extend(["-map_metadata", "-1", "-map_chapters", "-1"].map(String::from));
            if policy == Policy::KeepSafe {
                for (k, v) in safe {
                    a.push("-metadata".into());
                    a.push(format!("{k}={v}"));
                }
                if mov && !safe.is_empty() {
                    a.extend(["-movflags", "+use_metadata_tags"].map(String::from));
                }
            }
        }
    }
    a
}

/// Bytes a pixel that ffmpeg's decoder may hold at most (its reference frames: H.264 and
/// HEVC keep up to 16 of 1.5 bytes a pixel, and the converted RGB frame), the ratio that
/// sets its pixel limit from the budget.
const DECODER_BYTES_PER_PIXEL: u64 = 24;

/// The largest frame (pixels) the decoder is let decode within a budget of `total` bytes:
/// about 33 million (8K UHD) at the default 768 MiB. A stream whose frames are larger is
/// refused by ffmpeg itself before it allocates them (`-max_pixels`), whatever its header
/// declared.
fn max_decoded_pixels(total: u64) -> u64 {
    (total / DECODER_BYTES_PER_PIXEL).clamp(1, MAX_SIDE as u64 * MAX_SIDE as u64)
}

/// The encoder's command: IVF frames (raw RGB with timestamps) on stdin, `source`'s other
/// streams beside them when it is a file (with its probed `safe` tags), into `target`.
fn encoder(
    job: &Job,
    source: &Source,
    safe: &[(String, String)],
    sink: &Sink,
    target: Option<&Path>,
    size: (u32, u32),
    sixteen: bool,
) -> Result<Command> {
    let enc = job.enc;
    let mut c = ffmpeg()?;
    c.arg("-y");
    if matches!(source, Source::File(_)) {
        c.arg("-copyts");
    }
    c.args(["-f", "ivf", "-c:v", "rawvideo", "-i", "pipe:0"]);
    if let Source::File(path) = source {
        c.arg("-i").arg(file_url(path)?);
        let safe = if job.metadata == Policy::KeepSafe { safe } else { &[] };
        let mov = target
            .and_then(|t| t.extension())
            .and_then(|e| e.to_str())
            .is_some_and(|e| ["mp4", "mov", "m4v"].contains(&e.to_ascii_lowercase().as_str()));
        c.args(metadata_args(job.metadata, safe, mov));
    } else {
        c.args(["-map", "0:v"]);
    }
    c.args(["-fps_mode", "passthrough", "-enc_time_base", "-1"]);
    let device = matches!(sink, Sink::Device(_));
    let subsampled = device || enc.subsampled();
    if subsampled && (size.0 % 2 == 1 || size.1 % 2 == 1) {
        // 4:2:0 holds even sizes only: one more column or row, a copy of the last one.
        let (right, bottom) = (size.0 % 2, size.1 % 2);
        c.args(["-vf", &format!("pad=iw+{right}:ih+{bottom},fillborders=right={right}:bottom={bottom}:mode=smear")]);
    }
    if device {
        c.args(["-c:v", "rawvideo", "-pix_fmt", "yuv420p", "-f", "v4l2"]);
    } else {
        c.args(["-c:v", &enc.codec]);
        if enc.lossless() {
            c.args(["-pix_fmt", if sixteen { "gbrp16le" } else { "gbrp" }, "-level", "3"]);
        } else if subsampled {
            c.args(["-pix_fmt", if sixteen { "yuv420p10le" } else { "yuv420p" }]);
        }
        match (&enc.bitrate, enc.crf) {
            (Some(b), _) => {
                c.args(["-b:v", b]);
            }
            (None, Some(q)) if !enc.lossless() => {
                c.args(["-crf", &q.to_string()]);
                if enc.codec.starts_with("libvpx") {
                    c.args(["-b:v", "0"]);
                }
            }
            _ => {}
        }
        if let Some(pr) = &enc.preset {
            c.args(["-preset", pr]);
        }
    }
    match (sink, target) {
        (Sink::Stdout, _) => {
            c.args(["-f", "matroska", "pipe:1"]).stdout(Stdio::inherit());
        }
        (Sink::Device(dev), _) => {
            c.arg(dev);
        }
        (Sink::File(_), Some(t)) => {
            c.arg(file_url(t)?);
        }
        (Sink::File(p), None) => bail!("{}: no temporary file to write", crate::shown(p)),
    }
    c.stdin(Stdio::piped()).stderr(Stdio::piped());
    Ok(c)
}

/// The 32-byte IVF file header for raw frames of `size` (fourcc `RGB` and the bits a
/// pixel, ffmpeg's raw tag) in time base `tb`.
fn ivf_header(size: (u32, u32), sixteen: bool, tb: (u64, u64)) -> Result<[u8; 32]> {
    let side = |v: u32| u16::try_from(v).map_err(|_| anyhow!("a frame side of {v} pixels is over 65535"));
    let base =
        |v: u64| u32::try_from(v).map_err(|_| anyhow!("the decoder's time base {}/{} does not fit IVF", tb.0, tb.1));
    let mut h = [0u8; 32];
    h[..4].copy_from_slice(b"DKIF");
    h[6..8].copy_from_slice(&32u16.to_le_bytes());
    h[8..12].copy_from_slice(&[b'R', b'G', b'B', if sixteen { 48 } else { 24 }]);
    h[12..14].copy_from_slice(&side(size.0)?.to_le_bytes());
    h[14..16].copy_from_slice(&side(size.1)?.to_le_bytes());
    h[16..20].copy_from_slice(&base(tb.1)?.to_le_bytes());
    h[20..24].copy_from_slice(&base(tb.0)?.to_le_bytes());
    Ok(h)
}

/// A frame's 12-byte IVF header: its size in bytes and its timestamp.
fn ivf_frame_header(len: usize, pts: i64) -> Result<[u8; 12]> {
    let mut h = [0u8; 12];
    h[..4].copy_from_slice(
        &u32::try_from(len).map_err(|_| anyhow!("a frame of {len} bytes does not fit IVF"))?.to_le_bytes(),
    );
    h[4..].copy_from_slice(&pts.to_le_bytes());
    Ok(h)
}

/// A frame and its presentation timestamp.
struct Frame {
    data: Vec<u8>,
    pts: i64,
}

/// A decoder running: ffmpeg (ended when dropped), the frame timestamps its stderr gives
/// (the header already read), what it printed, its frames as they are pumped from its
/// stdout, and the first frame's time base and size.
struct Decoding {
    child: Reaped,
    clock: mpsc::Receiver<Clock>,
    stderr: std::thread::JoinHandle<Vec<u8>>,
    frames: Pumped,
    pumping: std::thread::JoinHandle<()>,
    tb: (u64, u64),
    width: u32,
    height: u32,
}

/// Starts decoding `source`'s video stream `stream` (16-bit samples when `sixteen`) and waits for its first frame's
/// header, at most the source's stall limit: one line when it gives none, cannot be
/// decoded, or is larger than [`MAX_SIDE`] a side (the decoder then ended and reaped).
fn start_decoding(source: &Source, sixteen: bool, stream: usize, max_pixels: u64) -> Result<Decoding> {
    let mut decode = spawn(&mut decoder(source, sixteen, stream, max_pixels)?, "decode")?;
    let (clock_tx, clock_rx) = mpsc::channel();
    let dec_err = clock(decode.stderr.take().expect("piped"), clock_tx);
    // Stdout is drained from now on, before the first timestamp: see `pump`.
    let (chunks, pumping) = pump(decode.stdout.take().expect("piped"));
    let from = Pumped { rx: chunks, chunk: Vec::new(), at: 0 };
    // The size and time base arrive with the first decoded frame.
    let stall = source.stall();
    let first = match stall {
        Some(limit) => clock_rx.recv_timeout(limit).map_err(|e| e == mpsc::RecvTimeoutError::Timeout),
        None => clock_rx.recv().map_err(|_| false),
    };
    let (tb, width, height) = match first {
        Ok(Clock::Header { tb, width, height }) => (tb, width, height),
        Err(true) => {
            drop(decode);
            bail!("{} gave no frame in {} s (--stall)", source.shown(), stall.unwrap_or_default().as_secs());
        }
        _ => {
            // Ended (killed and reaped) before its stderr is read to its end.
            drop(decode);
            let err = dec_err.join().unwrap_or_default();
            let hint = match source {
                Source::Stdin(_) => " (from a pipe, MP4 and MOV need their index first, ffmpeg -movflags +faststart; Matroska, WebM, MPEG-TS and NUT stream as they are; raw frames need --size)",
                _ => "",
            };
            bail!("ffmpeg could not decode it: {}{hint}", first_line(&err));
        }
    };
    if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
        bail!("the video is {width} x {height} pixels; at most {MAX_SIDE} a side");
    }
    Ok(Decoding { child: decode, clock: clock_rx, stderr: dec_err, frames: from, pumping, tb, width, height })
}

/// An encoder running (none where raw frames go to standard output): ffmpeg (ended when
/// dropped), where the frames are written, what it prints, and the temporary file beside the
/// output that it writes (persisted when the run succeeds) with the output's ending.
struct Encoder {
    child: Option<Reaped>,
    to: Box<dyn Write + Send>,
    stderr: std::thread::JoinHandle<Vec<u8>>,
    tmp: Option<campro::file::atomic::Temporary>,
    ext: String,
}

/// Starts the encoder of `width` x `height` frames for `sink` (`raw_out`: none, the frames
/// go to standard output as they are); says when 4:2:0 pads an odd size.
fn start_encoder(
    job: &Job,
    source: &Source,
    safe: &[(String, String)],
    sink: &Sink,
    (width, height): (u32, u32),
    sixteen: bool,
    raw_out: bool,
    warn: &dyn Fn(&str),
) -> Result<Encoder> {
    let padded = (job.enc.subsampled() && !raw_out) || matches!(sink, Sink::Device(_));
    if padded && (width % 2 == 1 || height % 2 == 1) {
        warn(&format!(
            "{width} x {height}: 4:2:0 video holds even sizes only; written as {} x {} (the last column or row repeated); --codec ffv1 keeps the size",
            width + width % 2,
            height + height % 2
        ));
    }
    let ext = match sink {
        Sink::File(o) => o.extension().and_then(|e| e.to_str()).unwrap_or("mkv").to_string(),
        _ => "mkv".into(),
    };
    let tmp = match sink {
        Sink::File(o) => Some(
            campro::file::atomic::temporary_beside(o, &format!(".{ext}")).with_context(|| o.display().to_string())?,
        ),
        _ => None,
    };
    let mut encode = if raw_out {
        None
    } else {
        let mut cmd = encoder(job, source, safe, sink, tmp.as_ref().map(|t| t.path()), (width, height), sixteen)?;
        Some(spawn(&mut cmd, "encode")?)
    };
    let to: Box<dyn Write + Send> = match &mut encode {
        Some(e) => Box::new(e.stdin.take().expect("piped")),
        None => Box::new(std::io::stdout()),
    };
    let enc_err = drain(encode.as_mut().and_then(|e| e.stderr.take()));
    Ok(Encoder { child: encode, to, stderr: enc_err, tmp, ext })
}

/// Simulates the camera on `source` into `sink` (an output file the caller checked).
pub fn simulate(job: &Job, source: &Source, sink: &Sink, warn: &dyn Fn(&str)) -> Result<Outcome> {
    let grey_before = job.capture.grey.allowed.load(std::sync::atomic::Ordering::Relaxed);
    let probe = match source {
        Source::File(path) => Some(probe(path)?),
        _ => None,
    };
    let sixteen = job.sixteen || probe.as_ref().is_some_and(|p| p.deep);
    let sixteen = if sixteen && job.capture.enhancer.is_some() {
        warn("--enhance: read as 8 bits (the enhancer takes the camera's 8-bit output)");
        false
    } else {
        sixteen
    };
    if let Some(t) = probe.as_ref().and_then(|p| p.transfer.as_deref()) {
        if matches!(t, "smpte2084" | "arib-std-b67") {
            warn(&format!(
                "HDR ({t}): the camera model is SDR; the decoded code values go through the preset as they are and the output is not tagged HDR"
            ));
        }
    }
    let raw_out = *sink == Sink::Stdout && job.enc.codec == "rawvideo";
    if raw_out && sixteen {
        warn("--codec rawvideo writes 16-bit frames as rgb48le");
    }
    let started = std::time::Instant::now();
    let budget = campro_eval::image_file::Budget::global();
    let bytes_per = if sixteen { 6 } else { 3 };
    // Frames in one batch and the bytes held for a `width` x `height` video: the enhancer
    // runs a frame a core where the budget holds that many (720p and 1080p on two cores; 4K
    // one at a time, its pyramid and planes spread over the cores instead), the camera
    // alone one frame on every core.
    let plan = |width: u32, height: u32| {
        let work = job.capture.work(width, height);
        let held =
            |batch: usize| held_bytes((bytes_per * width as usize * height as usize) as u64, work, sixteen, batch);
        let batch_max = if job.capture.enhancer.is_some() && !sixteen {
            frames_at_once(rayon::current_num_threads(), budget.total(), held)
        } else {
            1
        };
        (batch_max, held(batch_max), work)
    };
    let lease = |(width, height): (u32, u32)| {
        let (batch_max, held, work) = plan(width, height);
        budget.take(held).map(|l| (l, batch_max)).ok_or_else(|| {
            anyhow!(
                "the video is {width} x {height} pixels; its {} frames in flight{} need {} MiB, over the {} MiB limit ({} raises it)",
                in_flight(batch_max) + batch_max,
                if work > 0 { " and the enhancer's work" } else { "" },
                held >> 20,
                budget.total() >> 20,
                campro_eval::image_file::MEMORY_ENV
            )
        })
    };
    // A file's size is known from its header: the lease is taken before anything is
    // decoded, and frames of another size are refused (a header that lies).
    let declared = probe.as_ref().map(|p| (p.width, p.height));
    let early = declared.map(lease).transpose()?;
    let Decoding { child: mut decode, clock: clock_rx, stderr: dec_err, frames: from, pumping, tb, width, height } =
        start_decoding(source, sixteen, probe.as_ref().map_or(0, |p| p.stream), max_decoded_pixels(budget.total()))?;
    if declared.is_some_and(|d| d != (width, height)) {
        let (w, h) = declared.expect("checked");
        drop(decode);
        bail!("its frames are {width} x {height} pixels, not the {w} x {h} its header declares");
    }
    let frame_bytes = bytes_per * width as usize * height as usize;
    let (_lease, batch_max) = match early {
        Some(l) => l,
        None => lease((width, height))?,
    };
    let in_flight = in_flight(batch_max);
    let Encoder { child: encode, to, stderr: enc_err, tmp, ext } = start_encoder(
        job,
        source,
        probe.as_ref().map_or(&[][..], |p| &p.safe_tags),
        sink,
        (width, height),
        sixteen,
        raw_out,
        warn,
    )?;
    let bar = match probe.as_ref().and_then(|p| p.frames) {
        Some(n) => indicatif::ProgressBar::new(job.max_frames.map_or(n, |m| m.min(n))),
        None => indicatif::ProgressBar::no_length(),
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} frames {rate} eta {eta}")
            .expect("valid template")
            // indicatif's own {per_sec} prints four decimals ("47.7022/s").
            .with_key("rate", |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.1}/s", s.per_sec());
            }),
    );
    bar.set_message(match source {
        Source::File(p) => p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        other => other.shown(),
    });
    let frame_loop =
        FrameLoop { job, source, sixteen, raw_out, size: (width, height), frame_bytes, batch: batch_max, in_flight };
    let (Looped { frames, first_pts, last_pts, busy }, result) =
        frame_loop.run(&mut decode, from, clock_rx, to, ivf_header((width, height), sixteen, tb)?, &bar);
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    // A failed or stopped run leaves the decoder blocked on a full pipe: stop it.
    let stopped_early = job.max_frames.is_some_and(|m| frames >= m);
    if result.is_err() || stopped_early {
        let _ = decode.kill();
    }
    let dec = decode.wait()?;
    let enc_status = encode.map(Reaped::wait).transpose()?;
    let dec_stderr = dec_err.join().unwrap_or_default();
    let _ = pumping.join();
    let enc_stderr = enc_err.join().unwrap_or_default();
    result?;
    if !dec.success() && !stopped_early {
        bail!("ffmpeg could not decode it: {}", first_line(&dec_stderr));
    }
    if enc_status.is_some_and(|s| !s.success()) {
        bail!("ffmpeg could not encode it: {}", first_line(&enc_stderr));
    }
    if let Some(n) = probe.as_ref().and_then(|p| p.frames).filter(|&n| n != frames && !stopped_early) {
        warn(&format!("the container says {n} frames; {frames} were decoded and written"));
    }
    // Rates between the first frame and the last, so that start-up does not count.
    let source_fps = match (first_pts, last_pts) {
        (Some((a, _)), Some((b, _))) if b > a && frames > 1 => {
            Some((frames - 1) as f64 * tb.1 as f64 / (tb.0 as f64 * (b - a) as f64))
        }
        _ => None,
    };
    let fps = match (first_pts, last_pts) {
        (Some((_, a)), Some((_, b))) if frames > 1 && b > a => (frames - 1) as f64 / (b - a).as_secs_f64(),
        _ => frames as f64 / seconds.max(1e-9),
    };
    let capacity = frames as f64 / busy.as_secs_f64().max(1e-9);
    if source.live() && source_fps.is_some_and(|s| capacity < 0.95 * s) {
        warn(&format!(
            "the camera stage does {capacity:.1} frames a second, slower than the source's {:.1}: a live source drops frames",
            source_fps.unwrap_or(0.0)
        ));
    }
    let grey = job.capture.grey.allowed.load(std::sync::atomic::Ordering::Relaxed) - grey_before;
    if grey > 0 {
        warn(&format!("{grey} of {frames} frames grey: {}", crate::capture::GREY_ALLOWED));
    }
    if let (Sink::File(output), Some(tmp)) = (sink, tmp) {
        let tmp = match probe.as_ref().and_then(|p| p.rotation).filter(|&r| r.rem_euclid(360) != 0) {
            None => tmp,
            Some(r) => rotated(tmp, output, &ext, r, warn)?,
        };
        crate::output_result(output, campro::file::atomic::persist(tmp, output, job.force))?;
    }
    Ok(Outcome { frames, fps, capacity, source_fps, sixteen })
}

/// The frame loop of [`simulate`]: what it runs and how many frames at once.
struct FrameLoop<'r, 'a, 'c, 'p> {
    job: &'r Job<'a, 'c, 'p>,
    source: &'r Source,
    sixteen: bool,
    /// Raw frames to standard output: no IVF headers.
    raw_out: bool,
    size: (u32, u32),
    /// Bytes of one frame (3 or 6 a pixel).
    frame_bytes: usize,
    /// Frames the camera stage takes at once ([`frames_at_once`]).
    batch: usize,
    /// Frame buffers circulating ([`in_flight`]).
    in_flight: usize,
}

/// What the frame loop did: frames written, the first and last frame's timestamp with
/// when each was done, and the time the camera stage was busy.
struct Looped {
    frames: u64,
    first_pts: Option<(i64, std::time::Instant)>,
    last_pts: Option<(i64, std::time::Instant)>,
    busy: std::time::Duration,
}

impl FrameLoop<'_, '_, '_, '_> {
    /// Runs the three overlapping stages: a reader thread fills frames from the decoder
    /// (`from`, with their timestamps from `clock_rx`), this thread runs the camera (and the
    /// enhancer) on every core, a writer thread feeds the encoder (`to`, after `header`).
    /// Frames circulate through a fixed pool of buffers, so memory stays bounded whatever
    /// the length. A failed run, or one that reached `--frames`, kills the decoder (`decode`
    /// is reaped by the caller).
    fn run(
        self,
        decode: &mut Reaped,
        mut from: Pumped,
        clock_rx: mpsc::Receiver<Clock>,
        mut to: Box<dyn Write + Send>,
        header: [u8; 32],
        bar: &indicatif::ProgressBar,
    ) -> (Looped, Result<()>) {
        let FrameLoop {
            job,
            source,
            sixteen,
            raw_out,
            size: (width, height),
            frame_bytes,
            batch: batch_max,
            in_flight,
        } = self;
        let stall = source.stall();
        let mut frames = 0u64;
        let mut busy = std::time::Duration::ZERO;
        let (mut first_pts, mut last_pts) = (None, None);
        let (free_tx, free_rx) = mpsc::sync_channel::<Vec<u8>>(in_flight);
        let (full_tx, full_rx) = mpsc::sync_channel::<Frame>(in_flight);
        let (done_tx, done_rx) = mpsc::sync_channel::<Frame>(in_flight);
        for _ in 0..in_flight {
            free_tx.send(vec![0u8; frame_bytes]).expect("room for the pool");
        }
        let result = std::thread::scope(|scope| {
            let reader = scope.spawn(move || -> Result<()> {
                while let Ok(mut data) = free_rx.recv() {
                    if !read_frame(&mut from, &mut data)? {
                        return Ok(());
                    }
                    let pts = loop {
                        match clock_rx.recv() {
                            Ok(Clock::Pts(p)) => break p,
                            Ok(Clock::Header { .. }) => {}
                            Err(_) => bail!("the decoder gave a frame without its timestamp"),
                        }
                    };
                    if full_tx.send(Frame { data, pts }).is_err() {
                        return Ok(());
                    }
                }
                Ok(())
            });
            let writer = scope.spawn(move || -> Result<()> {
                let stopped = |e: std::io::Error| anyhow!("the encoder stopped: {e}");
                if !raw_out {
                    to.write_all(&header).map_err(stopped)?;
                }
                for f in done_rx {
                    if !raw_out {
                        to.write_all(&ivf_frame_header(f.data.len(), f.pts)?).map_err(stopped)?;
                    }
                    to.write_all(&f.data).map_err(stopped)?;
                    // After the last frame the reader is gone and takes no buffer back; the
                    // frames still queued must be written all the same.
                    let _ = free_tx.send(f.data);
                }
                to.flush().map_err(stopped)?;
                Ok(())
            });
            // The enhancer runs several frames at once, one core each (tract spreads one frame
            // over cores only partly); the camera alone is one frame on every core.
            let mut outs: Vec<Vec<u8>> = (0..batch_max).map(|_| vec![0u8; frame_bytes]).collect();
            let (mut s16, mut d16) = if sixteen {
                (vec![0u16; frame_bytes / 2], vec![0u16; frame_bytes / 2])
            } else {
                (Vec::new(), Vec::new())
            };
            let mut failure = None;
            'frames: loop {
                let first = match stall {
                    Some(limit) => match full_rx.recv_timeout(limit) {
                        Ok(f) => f,
                        Err(mpsc::RecvTimeoutError::Timeout) => {
                            failure = Some(anyhow!(
                                "{} gave no frame for {} s after frame {frames} (--stall)",
                                source.shown(),
                                limit.as_secs()
                            ));
                            break;
                        }
                        Err(mpsc::RecvTimeoutError::Disconnected) => break,
                    },
                    None => match full_rx.recv() {
                        Ok(f) => f,
                        Err(_) => break,
                    },
                };
                let mut batch = vec![first];
                while batch.len() < batch_max {
                    match full_rx.try_recv() {
                        Ok(f) => batch.push(f),
                        Err(_) => break,
                    }
                }
                if let Some(m) = job.max_frames {
                    batch.truncate(m.saturating_sub(frames) as usize);
                }
                if batch.is_empty() {
                    break;
                }
                let began = std::time::Instant::now();
                let ran = if sixteen {
                    let (src, out) = (&batch[0], &mut outs[0]);
                    for (v, b) in s16.iter_mut().zip(src.data.chunks_exact(2)) {
                        *v = u16::from_le_bytes([b[0], b[1]]);
                    }
                    job.capture.run16(&s16, &mut d16, width).map(|_| {
                        for (b, v) in out.chunks_exact_mut(2).zip(&d16) {
                            b.copy_from_slice(&v.to_le_bytes());
                        }
                    })
                } else if batch.len() == 1 {
                    // One frame: the enhancer spreads it over the pool's cores as it can.
                    let threads = rayon::current_num_threads();
                    let (src, out) = (&batch[0], &mut outs[0]);
                    job.capture.run_on(&src.data, out, width, height, threads).map(drop)
                } else {
                    use rayon::prelude::*;
                    batch
                        .par_iter()
                        .zip(outs.par_iter_mut())
                        .try_for_each(|(src, out)| job.capture.run(&src.data, out, width, height).map(drop))
                };
                busy += began.elapsed();
                if let Err(e) = ran {
                    failure = Some(e);
                    break;
                }
                for (src, out) in batch.into_iter().zip(outs.iter_mut()) {
                    first_pts.get_or_insert((src.pts, std::time::Instant::now()));
                    last_pts = Some((src.pts, std::time::Instant::now()));
                    // The processed frame goes to the writer; its input buffer becomes the next output.
                    let processed = std::mem::replace(out, src.data);
                    if done_tx.send(Frame { data: processed, pts: src.pts }).is_err() {
                        break 'frames;
                    }
                    frames += 1;
                    bar.inc(1);
                }
            }
            drop(done_tx);
            // Unblock a reader waiting for a free buffer if the writer quit early or we stopped,
            // and one waiting on a silent source: a failed run ends the decoder now.
            drop(full_rx);
            if failure.is_some() || job.max_frames.is_some_and(|m| frames >= m) {
                let _ = decode.kill();
            }
            let w = writer.join().unwrap_or_else(|_| Err(anyhow!("the writer thread panicked")));
            let r = reader.join().unwrap_or_else(|_| Err(anyhow!("the reader thread panicked")));
            match failure {
                Some(e) => Err(e),
                None => r.and(w),
            }
        });
        (Looped { frames, first_pts, last_pts, busy }, result)
    }
}

/// The rotation (display matrix): ffmpeg sets it only when copying streams, so a rotated
/// input's output is remuxed once with it (frames themselves are not rotated).
fn rotated(
    tmp: campro::file::atomic::Temporary,
    output: &Path,
    ext: &str,
    r: i64,
    warn: &dyn Fn(&str),
) -> Result<campro::file::atomic::Temporary> {
    let rotated = campro::file::atomic::temporary_beside(output, &format!(".{ext}"))?;
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
        warn(&format!(
            "the {ext} container cannot hold its rotation ({r} degrees) with this ffmpeg; frames are kept as stored"
        ));
    }
    Ok(rotated)
}

/// Fills `buf` with the next frame; false at a clean end of stream.
/// Drains `from` (the decoder's stdout) on its own thread into chunks of at most
/// [`PUMP_CHUNK`] bytes, [`PUMP_CHUNKS`] ahead at most; ends at EOF, on an error, or when
/// the receiver is gone. The decoder writes its frames to stdout and their timestamps to
/// stderr in an order of its own: reading one pipe only while waiting on the other would
/// deadlock once the first fills (seen on ffmpeg 5.1 with small frames: several frames
/// before the timestamp header).
fn pump(
    mut from: std::process::ChildStdout,
) -> (mpsc::Receiver<std::io::Result<Vec<u8>>>, std::thread::JoinHandle<()>) {
    let (tx, rx) = mpsc::sync_channel(PUMP_CHUNKS);
    let handle = std::thread::spawn(move || loop {
        let mut chunk = vec![0u8; PUMP_CHUNK];
        match from.read(&mut chunk) {
            Ok(0) => return,
            Ok(n) => {
                chunk.truncate(n);
                if tx.send(Ok(chunk)).is_err() {
                    return;
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                let _ = tx.send(Err(e));
                return;
            }
        }
    });
    (rx, handle)
}

/// The pumped chunks as one byte stream.
struct Pumped {
    rx: mpsc::Receiver<std::io::Result<Vec<u8>>>,
    chunk: Vec<u8>,
    at: usize,
}

impl Read for Pumped {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        while self.at == self.chunk.len() {
            match self.rx.recv() {
                Ok(c) => (self.chunk, self.at) = (c?, 0),
                Err(_) => return Ok(0),
            }
        }
        let n = buf.len().min(self.chunk.len() - self.at);
        buf[..n].copy_from_slice(&self.chunk[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

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

#[cfg(test)]
mod tests {
    /// Cover art stored before the video (an attached picture listed first) is never the
    /// stream protected; a file of cover art alone has no video to protect.
    #[test]
    fn the_protected_stream_skips_attached_pictures() {
        let v = serde_json::json!({"streams": [
            {"width": 600, "height": 600, "disposition": {"attached_pic": 1}},
            {"width": 1920, "height": 1080, "disposition": {"attached_pic": 0}},
            {"width": 640, "height": 360, "disposition": {"attached_pic": 0}},
        ]});
        let (i, s) = super::protected_stream(&v).unwrap();
        assert_eq!((i, s["width"].as_u64()), (1, Some(1920)));
        let plain = serde_json::json!({"streams": [{"width": 8, "height": 8}]});
        assert_eq!(super::protected_stream(&plain).unwrap().0, 0);
        let covers = serde_json::json!({"streams": [{"disposition": {"attached_pic": 1}}]});
        assert!(super::protected_stream(&covers).unwrap_err().to_string().contains("attached pictures"));
        assert_eq!(
            super::protected_stream(&serde_json::json!({"streams": []})).unwrap_err().to_string(),
            "no video stream"
        );
    }

    /// 4K is enhanced a frame at a time and 1080p two at once on two cores, under the
    /// 768 MiB budget (hand-derived: a 4K frame 24,883,200 bytes, its work at auto scale
    /// 170 · 960 · 544 + 30 · 3840 · 2160 = 337,612,800; two at once would hold 891,633,664).
    #[test]
    fn frames_enhanced_at_once_fit_the_budget() {
        let budget = 768u64 << 20;
        let k4 = |b| super::held_bytes(3840 * 2160 * 3, 170 * 960 * 544 + 30 * 3840 * 2160, false, b);
        assert_eq!(k4(2), 891_633_664);
        assert_eq!(super::frames_at_once(2, budget, k4), 1);
        let hd = |b| super::held_bytes(1920 * 1080 * 3, 170 * 960 * 544 + 30 * 1920 * 1080, false, b);
        assert_eq!(super::frames_at_once(2, budget, hd), 2);
        assert_eq!(super::frames_at_once(0, budget, hd), 1);
        // None fits: one, which the lease then refuses by size.
        assert_eq!(super::frames_at_once(4, 1 << 20, hd), 1);
    }

    #[test]
    fn network_inputs_by_scheme_and_the_protocols_ffmpeg_lists() {
        assert_eq!(url_scheme(Path::new("rtsp://cam/1")).as_deref(), Some("rtsp"));
        assert_eq!(url_scheme(Path::new("HTTPS://x/a.mp4")).as_deref(), Some("https"));
        assert_eq!(url_scheme(Path::new("http://")), None); // no host
        assert_eq!(url_scheme(Path::new("file:///a.mp4")), None); // a file is read as a file
        assert_eq!(url_scheme(Path::new("photos/a.jpg")), None);
        assert_eq!(url_scheme(Path::new("-")), None);
        let listing = "Supported file protocols:\nInput:\n  file\n  http\n  rtsp\nOutput:\n  file\n  srt\n";
        assert_eq!(input_protocols(listing), ["file", "http", "rtsp"]);
        // RTSP is a demuxer to ffmpeg (Debian's ffmpeg 5.1 lists no rtsp protocol).
        let listing = "File formats:\n D. = Demuxing supported\n --\n D  rtsp            RTSP input\n DE mov,mp4,m4a   QuickTime / MOV\n  E mp3           MP3\n";
        assert_eq!(demuxers(listing), ["rtsp", "mov", "mp4", "m4a"]);
        assert_eq!(needs("rtsp"), ("demuxer", "rtsp"));
        assert_eq!(needs("srt"), ("protocol", "srt"));
    }

    use super::*;

    #[test]
    #[cfg(unix)]
    fn a_dropped_child_is_killed_and_reaped() {
        let running = spawn(Command::new("sleep").arg("30"), "wait").unwrap();
        let pid = running.id();
        assert!(CHILDREN.lock().unwrap().contains(&pid));
        let began = std::time::Instant::now();
        drop(running);
        // Killed (not waited out) and reaped: no process, no zombie, forgotten.
        assert!(began.elapsed() < std::time::Duration::from_secs(10));
        assert!(!std::path::Path::new(&format!("/proc/{pid}")).exists(), "pid {pid} is still there");
        assert!(!CHILDREN.lock().unwrap().contains(&pid));
        // Waited for, it is not killed: its status comes back.
        let done = spawn(&mut Command::new("true"), "finish").unwrap();
        assert!(done.wait().unwrap().success());
    }

    #[test]
    fn deep_pixel_formats_are_told_from_8_bit_ones() {
        for f in ["yuv420p10le", "yuv422p10be", "p010le", "rgb48le", "gbrp12le", "gray16le", "yuv444p16le", "rgba64be"]
        {
            assert!(deep_pixel_format(f), "{f}");
        }
        for f in ["yuv420p", "rgb24", "nv12", "bgr565le", "rgb555be", "yuvj420p", "gray", "bgr444le"] {
            assert!(!deep_pixel_format(f), "{f}");
        }
    }

    #[test]
    fn ivf_headers_carry_size_fourcc_time_base_and_signed_timestamps() {
        let h = ivf_header((321, 241), true, (1, 90000)).unwrap();
        assert_eq!(&h[..4], b"DKIF");
        assert_eq!(u16::from_le_bytes([h[6], h[7]]), 32);
        assert_eq!(&h[8..12], b"RGB0");
        assert_eq!((u16::from_le_bytes([h[12], h[13]]), u16::from_le_bytes([h[14], h[15]])), (321, 241));
        assert_eq!(u32::from_le_bytes(h[16..20].try_into().unwrap()), 90000);
        assert_eq!(u32::from_le_bytes(h[20..24].try_into().unwrap()), 1);
        let f = ivf_frame_header(10, -1024).unwrap();
        assert_eq!(u32::from_le_bytes(f[..4].try_into().unwrap()), 10);
        assert_eq!(i64::from_le_bytes(f[4..].try_into().unwrap()), -1024);
        assert!(ivf_header((70000, 1), false, (1, 1)).is_err());
        assert!(ivf_header((1, 1), false, (1, 1 << 33)).is_err());
    }
}
