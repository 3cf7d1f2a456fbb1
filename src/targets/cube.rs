//! 3D LUTs baked from the whole desktop pipeline on gamma-encoded input, for software
//! that applies them right after capture: `.cube` (ffmpeg `lut3d`, OBS, GStreamer,
//! DaVinci) and Hald CLUT images (ffmpeg `haldclut`), the latter as 16-bit binary PPM.
//!
//! Both store node values red fastest. The deployment error is the interpolation
//! inside a cell (measured under trilinear and tetrahedral interpolation, the two that
//! players use) plus the file's value precision (6 decimals in `.cube`, 1/65535 in the
//! PPM).

use super::target::{Condition, CurveFormat, Feed, Format, MatrixBy, StageOrder, Target, TargetError};
use crate::emulate::Emulator;
use crate::lut3d::{Interp, Lut3d};
use crate::params::Params;
use std::fmt::Write;

/// Which file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Adobe/Resolve `.cube` text.
    Cube,
    /// Hald CLUT image (level L: an L^3 x L^3 image of an L^2-point LUT), 16-bit PPM.
    Hald,
}

/// A LUT file target of one size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CubeFile {
    /// `.cube` text or Hald PPM.
    pub kind: Kind,
    /// Points per axis (for Hald: a square, L^2).
    pub size: usize,
}

impl Default for CubeFile {
    fn default() -> Self {
        Self { kind: Kind::Cube, size: 33 }
    }
}

impl CubeFile {
    /// A Hald CLUT of level `level` (size level^2; 8 gives 64 points per axis).
    pub fn hald(level: usize) -> Self {
        Self { kind: Kind::Hald, size: level * level }
    }
}

fn parse_err(message: impl Into<String>, format: &'static str) -> TargetError {
    TargetError::Parse { file: "LUT".into(), format, message: message.into() }
}

/// Parses `.cube` text (3D only; DOMAIN must be [0, 1]).
pub fn parse_cube(text: &str) -> Result<Lut3d, TargetError> {
    let mut n = None;
    let mut data = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let at = |m: String| parse_err(format!("line {}: {m}", i + 1), ".cube");
        let mut words = line.split_whitespace();
        let first = words.next().unwrap_or_default();
        match first {
            "TITLE" => {}
            "LUT_3D_SIZE" => {
                let v: usize = words
                    .next()
                    .and_then(|w| w.parse().ok())
                    .ok_or_else(|| at("LUT_3D_SIZE needs an integer".into()))?;
                if !(2..=256).contains(&v) {
                    return Err(at(format!("LUT_3D_SIZE must be in 2..=256, got {v}")));
                }
                n = Some(v);
            }
            "LUT_1D_SIZE" => return Err(at("1D LUTs are not supported".into())),
            "DOMAIN_MIN" | "DOMAIN_MAX" => {
                let want = if first == "DOMAIN_MIN" { 0.0 } else { 1.0 };
                let v: Vec<f64> = words.map(|w| w.parse().unwrap_or(f64::NAN)).collect();
                if v.len() != 3 || v.iter().any(|&x| x != want) {
                    return Err(at(format!("{first} must be {want} {want} {want}")));
                }
            }
            _ => {
                let size = n.ok_or_else(|| at("LUT_3D_SIZE must come before the data".into()))?;
                let v: Vec<f32> = std::iter::once(first)
                    .chain(words)
                    .map(|w| w.parse().map_err(|_| at(format!("not a number: {w}"))))
                    .collect::<Result<_, _>>()?;
                if v.len() != 3 {
                    return Err(at(format!("a data line holds 3 numbers, got {}", v.len())));
                }
                if v.iter().any(|x| !x.is_finite()) {
                    return Err(at("values must be finite".into()));
                }
                if data.len() == size * size * size {
                    return Err(at("more data lines than LUT_3D_SIZE^3".into()));
                }
                data.push([v[0], v[1], v[2]]);
            }
        }
    }
    let n = n.ok_or_else(|| parse_err("no LUT_3D_SIZE", ".cube"))?;
    Ok(Lut3d::from_data(n, data)?)
}

/// Parses a binary PPM (P6, maxval 255 or 65535) holding a Hald CLUT.
pub fn parse_hald(bytes: &[u8]) -> Result<Lut3d, TargetError> {
    let err = |m: &str| parse_err(m, "Hald PPM");
    // Header: "P6" w h maxval, whitespace separated, then one whitespace byte.
    let mut fields = Vec::new();
    let mut pos = 0;
    while fields.len() < 4 {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if pos < bytes.len() && bytes[pos] == b'#' {
            while pos < bytes.len() && bytes[pos] != b'\n' {
                pos += 1;
            }
            continue;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err(err("truncated header"));
        }
        fields.push(std::str::from_utf8(&bytes[start..pos]).map_err(|_| err("header is not ASCII"))?.to_string());
    }
    pos += 1;
    if fields[0] != "P6" {
        return Err(err("not a binary PPM (P6)"));
    }
    let num = |s: &str| s.parse::<usize>().map_err(|_| err("bad header number"));
    let (w, h, max) = (num(&fields[1])?, num(&fields[2])?, num(&fields[3])?);
    let level =
        (1..=16).find(|l| l * l * l == w).ok_or_else(|| err("width is not a cube L^3 (Hald level L in 1..=16)"))?;
    if h != w || !(max == 255 || max == 65535) {
        return Err(err("a Hald image is square, with maxval 255 or 65535"));
    }
    let bps = if max == 255 { 1 } else { 2 };
    let body = &bytes[pos.min(bytes.len())..];
    if body.len() != w * h * 3 * bps {
        return Err(err("pixel data length does not match the header"));
    }
    let sample = |i: usize| {
        if bps == 1 {
            body[i] as f32 / 255.0
        } else {
            u16::from_be_bytes([body[2 * i], body[2 * i + 1]]) as f32 / 65535.0
        }
    };
    let data = (0..w * h).map(|p| [sample(3 * p), sample(3 * p + 1), sample(3 * p + 2)]).collect();
    Ok(Lut3d::from_data(level * level, data)?)
}

/// A LUT applied to gamma-encoded RGB in [0, 1].
struct Applied {
    lut: Lut3d,
    interp: Interp,
}

impl Emulator for Applied {
    fn sensor_to_output(&self, rgb: [f64; 3]) -> [f64; 3] {
        self.lut.eval(rgb.map(|v| v as f32), self.interp).map(f64::from)
    }
}

impl Target for CubeFile {
    fn name(&self) -> &'static str {
        match self.kind {
            Kind::Cube => "cube",
            Kind::Hald => "hald",
        }
    }

    fn format(&self) -> Format {
        let y_step = match self.kind {
            Kind::Cube => 1e-6,
            Kind::Hald => 1.0 / 65535.0,
        };
        Format {
            matrix: None,
            curve: CurveFormat {
                grid: (0..self.size).map(|i| i as f64 / (self.size - 1) as f64).collect(),
                y_step,
                monotonic: false,
            },
            matrix_by: MatrixBy::Baked,
            order: StageOrder::EncodedLut,
        }
    }

    fn export(&self, params: &Params, _base: Option<&str>) -> Result<Vec<u8>, TargetError> {
        let lut = Lut3d::bake(params, self.size);
        match self.kind {
            Kind::Cube => {
                let mut s = String::with_capacity(30 * lut.data().len() + 200);
                let title = if params.name.is_empty() { "campro" } else { &params.name };
                let _ = writeln!(s, "TITLE \"{}\"", title.replace('"', "'"));
                let _ = writeln!(s, "# CamPro desktop pipeline baked on gamma-encoded RGB (red fastest)");
                let _ = writeln!(s, "LUT_3D_SIZE {}\nDOMAIN_MIN 0 0 0\nDOMAIN_MAX 1 1 1", self.size);
                for v in lut.data() {
                    let _ = writeln!(s, "{:.6} {:.6} {:.6}", v[0], v[1], v[2]);
                }
                Ok(s.into_bytes())
            }
            Kind::Hald => {
                let level = (1..=16).find(|l| l * l == self.size).ok_or_else(|| TargetError::Unsupported {
                    target: "hald",
                    why: format!("size {} is not a square L^2", self.size),
                })?;
                let side = level * level * level;
                let mut out = format!("P6\n{side} {side}\n65535\n").into_bytes();
                out.reserve(side * side * 6);
                for v in lut.data() {
                    for c in v {
                        out.extend(((c.clamp(0.0, 1.0) as f64 * 65535.0).round() as u16).to_be_bytes());
                    }
                }
                Ok(out)
            }
        }
    }

    fn emulate(&self, _params: &Params, exported: &[u8], _base: Option<&str>) -> Result<Vec<Condition>, TargetError> {
        let lut = match self.kind {
            Kind::Cube => parse_cube(std::str::from_utf8(exported).map_err(|e| parse_err(e.to_string(), ".cube"))?)?,
            Kind::Hald => parse_hald(exported)?,
        };
        let n = lut.size();
        Ok([Interp::Trilinear, Interp::Tetrahedral]
            .into_iter()
            .map(|interp| Condition {
                bound: None,
                label: format!("{n}^3 {interp:?}").to_lowercase(),
                feed: Feed::Encoded,
                emulator: Box::new(Applied { lut: lut.clone(), interp }),
            })
            .collect())
    }
}
