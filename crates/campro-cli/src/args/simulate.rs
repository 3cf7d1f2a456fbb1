//! Arguments of `simulate` (images, videos, pipes, cameras) and the enhancer's scale (shared
//! by simulate, inspect and eval).

use super::{Report, PARAMS_HELP};
use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// `campro simulate`.
#[derive(Args)]
pub struct SimulateArgs {
    #[arg(help = PARAMS_HELP)]
    pub params: PathBuf,
    /// Images, videos or folders (recursive); `-` reads one video from standard input
    /// (a container, or raw RGB frames with --size); /dev/videoN a live camera (Linux).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output folder; for one video also a video file name, `-` (standard output,
    /// Matroska) or a V4L2 output device (v4l2loopback).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Output bit depth of images; 16 also gives video 16-bit frames (video of more
    /// than 8 bits gets them anyway).
    #[arg(long, value_enum, default_value_t = BitDepth::Eight)]
    pub bit_depth: BitDepth,
    /// JPEG quality of JPEG outputs (a JPEG input stays JPEG), 1 to 100.
    #[arg(long, default_value_t = 92, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub quality: u8,
    /// Write every image in this format instead of its input's (png for exact work:
    /// a JPEG output is lossy).
    #[arg(long, value_enum)]
    pub image_format: Option<crate::simulate::ImageFormat>,
    /// Raw standard input's frame size (WxH, 8-bit RGB), or the size asked of a camera.
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Raw standard input's frame rate (default 30), or the rate asked of a camera
    /// (frames a second: 30, 29.97 or 30000/1001).
    #[arg(long, value_parser = parse_rate)]
    pub rate: Option<String>,
    /// Seconds a live source may go without a frame before the run stops with an error
    /// (default: 10 for a camera; standard input waits while its producer is open).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=3600))]
    pub stall: Option<u32>,
    /// Stop each video after this many frames (a live camera runs until Ctrl-C without).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub frames: Option<u64>,
    /// Overwrite existing outputs.
    #[arg(long)]
    pub force: bool,
    /// Worker threads (default: all cores; more than the cores is clamped, with a warning).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub jobs: Option<u32>,
    /// Video encoder (ffmpeg's name): libx264, libx265, libvpx-vp9, ffv1 (lossless, in Matroska), ...
    #[arg(long, default_value = "libx264")]
    pub codec: String,
    /// Video constant quality (lower is better; H.264's 18 looks lossless to most).
    #[arg(long, default_value_t = 18, value_parser = clap::value_parser!(u32).range(0..=63), conflicts_with = "bitrate")]
    pub crf: u32,
    /// Video bitrate instead of --crf (ffmpeg's -b:v, e.g. 8M).
    #[arg(long, value_parser = parse_bitrate)]
    pub bitrate: Option<String>,
    /// Video encoder preset (libx264/libx265: ultrafast ... veryslow).
    #[arg(long)]
    pub preset: Option<String>,
    /// Also run the preset's image enhancer (provenance.enhancer, from campro
    /// train-enhancer) on the camera's 8-bit output: what a human viewer is shown.
    #[arg(long, conflicts_with = "bit_depth")]
    pub enhance: bool,
    #[command(flatten)]
    pub scale: EnhanceArgs,
    /// Where the enhancer's face guard finds its face detector (--enhance).
    #[command(flatten)]
    pub data: super::DataArgs,
    /// Write grey and near-grey pictures (black-and-white, infrared, one-coloured light)
    /// although the preset is not rated for grey input. Such pictures are refused by
    /// default: a global matrix and curve cannot fold a single line of colours, so a
    /// restoration that knows the camera gives their faces back. What is let through is
    /// said on stderr and in the JSON record, and is not protected.
    #[arg(long)]
    pub allow_grey: bool,
    /// What outputs keep of their inputs' metadata. Photos: keep-safe: date and time, camera
    /// and lens, exposure, colour space and the colour profile's colour tags; never GPS,
    /// maker notes, serial numbers, names, comments or thumbnails (a thumbnail is the
    /// unprotected picture). keep: every standard field of the main image, GPS too, but
    /// never a thumbnail, maker note or embedded container. Videos: keep-safe: the creation
    /// time, make and model only (no title, artist, location, comment, subtitles or
    /// chapters); keep: the container's metadata, subtitles and chapters. Every policy
    /// drops a video's data streams (GPS telemetry) and attached pictures. strip: nothing.
    /// Pixels are turned by the input's orientation, so photos say orientation 1.
    #[arg(long, value_enum, default_value_t = crate::metadata::Policy::KeepSafe)]
    pub metadata: crate::metadata::Policy,
    /// Leave outputs that exist and skip their inputs (re-runs do only what is missing).
    #[arg(long, conflicts_with = "force")]
    pub skip_existing: bool,
    /// Write NAME.EXT.campro.json beside each output: the preset's name and SHA-256,
    /// campro's version, the path and its error bound, the input's and the output's
    /// SHA-256 (`campro check --record` verifies a file against it).
    #[arg(long)]
    pub record: bool,
    /// Progress on stderr only, or also one JSON object on stdout: each input's output,
    /// status (written, skipped, failed) and time.
    #[arg(long, value_enum, default_value_t = Report::Text)]
    pub format: Report,
}

/// `--bit-depth`.
#[derive(Clone, Copy, ValueEnum)]
pub enum BitDepth {
    #[value(name = "8")]
    Eight,
    #[value(name = "16")]
    Sixteen,
}

/// `--bitrate`: digits with an optional k, M or G (ffmpeg's -b:v).
fn parse_bitrate(s: &str) -> Result<String, String> {
    let digits = s.trim_end_matches(['k', 'K', 'M', 'G']);
    if !digits.is_empty()
        && digits.len() <= 12
        && digits.bytes().all(|b| b.is_ascii_digit())
        && s.len() - digits.len() <= 1
    {
        Ok(s.to_string())
    } else {
        Err(format!("must be a bitrate such as 8M or 2500k, got {}", super::shown_arg(s)))
    }
}

/// `--size`: WxH, each side 1 to 16384 pixels.
fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let side = |v: &str| v.parse::<u32>().ok().filter(|v| (1..=16384).contains(v));
    s.split_once(['x', 'X'])
        .and_then(|(w, h)| Some((side(w)?, side(h)?)))
        .ok_or_else(|| format!("must be WIDTHxHEIGHT with sides of 1 to 16384 pixels, got {}", super::shown_arg(s)))
}

/// `--rate`: frames a second, a positive number (`29.97`) or fraction (`30000/1001`) up to 1000.
fn parse_rate(s: &str) -> Result<String, String> {
    let num = |v: &str| v.parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0);
    let value = match s.split_once('/') {
        Some((n, d)) if n.bytes().all(|b| b.is_ascii_digit()) && d.bytes().all(|b| b.is_ascii_digit()) => {
            num(n).zip(num(d)).map(|(n, d)| n / d)
        }
        Some(_) => None,
        None if s.len() <= 12 && s.bytes().all(|b| b.is_ascii_digit() || b == b'.') => num(s),
        None => None,
    };
    match value {
        Some(v) if v <= 1000.0 => Ok(s.to_string()),
        _ => Err(format!("must be frames a second up to 1000 (30, 29.97 or 30000/1001), got {}", super::shown_arg(s))),
    }
}

/// How the enhancer runs (shared by simulate, inspect and eval): the resolution of its
/// network and how its face guard hides the faces it finds.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct EnhanceArgs {
    /// The enhancer's network at full resolution (1), at half, a quarter or an eighth of it
    /// (2, 4, 8: colours stay per-pixel, the network's correction is upsampled; about 4, 16
    /// and 64 times less work), or auto: 1 below 1280x720, 2 from there, 4 from 2560x1440,
    /// 8 from 5120x2880 (a 50-megapixel photo).
    #[arg(long = "enhance-scale", default_value = "auto", value_parser = parse_scale)]
    pub enhance_scale: campro_eval::enhance::Scale,
    /// How the enhanced view hides every face its guard finds (a face detector run on the
    /// enhanced and the captured image at every scale down to 10-pixel faces: CenterFace,
    /// which `campro models fetch` installs, and YuNet too when present; nothing is
    /// enhanced without one):
    /// pixelate (blocks of a sixth of the face's width) or solid (one colour).
    #[arg(long, value_enum, default_value_t = FacesArg::Pixelate)]
    pub faces: FacesArg,
}

/// `--faces`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum FacesArg {
    Pixelate,
    Solid,
}

impl From<FacesArg> for campro_eval::guard::Hide {
    fn from(f: FacesArg) -> Self {
        match f {
            FacesArg::Pixelate => Self::Pixelate,
            FacesArg::Solid => Self::Solid,
        }
    }
}

fn parse_scale(s: &str) -> Result<campro_eval::enhance::Scale, String> {
    use campro_eval::enhance::Scale;
    match s {
        "auto" => Ok(Scale::Auto),
        "1" | "2" | "4" | "8" => Ok(Scale::Factor(s.parse().expect("a digit"))),
        _ => Err(format!("must be auto, 1, 2, 4 or 8, got {}", super::shown_arg(s))),
    }
}
