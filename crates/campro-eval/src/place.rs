//! Faces placed where cameras meet them: an LFW face scaled down and pasted into a held-out
//! COCO scene, alone (small: 12–48 px, as CCTV sees a passer-by) or beside other people's
//! faces (group). The privacy evaluation's probes of those scenes are these pictures; the
//! camera (and the enhancer with its face guard) sees the whole picture, and the attacker
//! crops, aligns and upsamples the face after it.
//!
//! Every choice (backdrop, size, place, companions) is drawn from a seed and the probe
//! photo's file name, so a run is repeatable and every condition and preset sees the same
//! pictures.

use crate::data::read_rgb8;
use crate::error::{EvalError, Result};
use crate::face::{central_face, Face, FaceDetector};
use image::imageops::{self, FilterType};
use image::RgbImage;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};

/// A face's surroundings pasted with it: this many face-box widths a side (hair, chin,
/// background of the LFW photo), so that what is pasted looks like a head, not a mask.
pub const CONTEXT: f32 = 1.8;

/// The small scene: a 320 x 240 picture with one face 12 to 48 px wide.
pub const SMALL_CANVAS: (u32, u32) = (320, 240);
/// Face widths of the small scene, px (inclusive).
pub const SMALL_WIDTHS: (u32, u32) = (12, 48);
/// The group scene: a 480 x 320 picture with the probe's face and [`COMPANIONS`] others.
pub const GROUP_CANVAS: (u32, u32) = (480, 320);
/// Face widths of the group scene, px (inclusive); at most `GROUP_CANVAS.0 / (COMPANIONS + 1)
/// / CONTEXT` so that the people stand side by side without overlapping.
pub const GROUP_WIDTHS: (u32, u32) = (16, 64);
/// Other people in a group scene.
pub const COMPANIONS: usize = 3;

/// A face pasted into a picture: where its box and landmarks are there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pasted {
    pub bbox: [f32; 4],
    pub landmarks: [[f32; 2]; 5],
}

/// A probe face placed in a scene.
pub struct Placed {
    pub image: RgbImage,
    /// The probe's face there.
    pub face: Pasted,
}

/// Pastes `face` of `photo` (with [`CONTEXT`] of its surroundings, clipped to the photo) into
/// `canvas`, scaled so that its box is `width` px wide, with the pasted square's top-left
/// corner at (`x`, `y`) (clipped to the canvas). Returns where the face is; bilinear
/// (triangle) resampling.
pub fn paste(canvas: &mut RgbImage, photo: &RgbImage, face: &Face, width: f32, x: i64, y: i64) -> Pasted {
    let b = face.bbox;
    let (bw, cx, cy) = ((b[2] - b[0]).max(1.0), (b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let (pw, ph) = (photo.width() as f32, photo.height() as f32);
    let half = (CONTEXT / 2.0 * bw).min(cx).min(cy).min(pw - cx).min(ph - cy).max(1.0);
    let (x0, y0) = ((cx - half).max(0.0) as u32, (cy - half).max(0.0) as u32);
    let side = ((2.0 * half) as u32).clamp(1, (photo.width() - x0).min(photo.height() - y0));
    let crop = imageops::crop_imm(photo, x0, y0, side, side).to_image();
    let k = width / bw;
    let out = ((side as f32 * k).round() as u32).max(1);
    let small = imageops::resize(&crop, out, out, FilterType::Triangle);
    imageops::replace(canvas, &small, x, y);
    let at = |p: [f32; 2]| [(p[0] - x0 as f32) * k + x as f32, (p[1] - y0 as f32) * k + y as f32];
    let [a, c] = [at([b[0], b[1]]), at([b[2], b[3]])];
    Pasted { bbox: [a[0], a[1], c[0], c[1]], landmarks: face.landmarks.map(at) }
}

/// The side of the square [`paste`] writes for a face box `bw` px wide scaled to `width`
/// (at most; less where the photo clips the surroundings).
pub fn pasted_side(width: u32) -> u32 {
    (CONTEXT * width as f32).ceil() as u32
}

/// FNV-1a of `s`: a seed from a file name that does not change between runs or platforms.
fn fnv1a(s: &str) -> u64 {
    s.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// `img` scaled to cover `(w, h)` and cut from its centre.
fn cover(img: &RgbImage, (w, h): (u32, u32)) -> RgbImage {
    let k = (w as f32 / img.width() as f32).max(h as f32 / img.height() as f32);
    let (sw, sh) = (((img.width() as f32 * k).ceil() as u32).max(w), ((img.height() as f32 * k).ceil() as u32).max(h));
    let big = imageops::resize(img, sw, sh, FilterType::Triangle);
    imageops::crop_imm(&big, (sw - w) / 2, (sh - h) / 2, w, h).to_image()
}

/// What the small and group scenes are made of: held-out COCO pictures as backdrops, and
/// people who are never probed (LFW identities with one photo) as companions.
pub struct Stage {
    backdrops: Vec<PathBuf>,
    companions: Vec<PathBuf>,
    seed: u64,
}

impl Stage {
    /// The backdrops are the COCO person set's images held out of detector fine-tuning
    /// ([`crate::data::detector_held_out`]) under `coco`; the companions are `lfw`'s people
    /// with exactly one photo (never probed, never distractors: those need two).
    pub fn new(coco: &Path, lfw: &crate::data::Lfw, seed: u64) -> Result<Self> {
        let backdrops: Vec<PathBuf> = crate::data::coco_person(coco)?
            .into_iter()
            .filter(|im| crate::data::detector_held_out(im.id))
            .map(|im| im.path)
            .collect();
        let companions: Vec<PathBuf> = lfw.people.values().filter(|v| v.len() == 1).map(|v| v[0].clone()).collect();
        if backdrops.is_empty() {
            return Err(EvalError::Invalid(format!(
                "{}: no held-out COCO image to paste faces into",
                campro::file::shown(coco)
            )));
        }
        if companions.len() < COMPANIONS {
            return Err(EvalError::Invalid("LFW: too few people with one photo to stand beside the probes".into()));
        }
        Ok(Self { backdrops, companions, seed })
    }

    /// The seeded draws of scene `scene` for the probe photo `path`.
    fn rng(&self, scene: &str, path: &Path) -> ChaCha8Rng {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        ChaCha8Rng::seed_from_u64(fnv1a(&format!("{scene}/{name}")) ^ self.seed)
    }

    fn backdrop(&self, rng: &mut ChaCha8Rng, size: (u32, u32)) -> Result<RgbImage> {
        let path = &self.backdrops[rng.random_range(0..self.backdrops.len())];
        Ok(cover(&read_rgb8(path)?, size))
    }

    /// The small scene of probe photo `path` (its `face`): one face 12–48 px wide
    /// ([`SMALL_WIDTHS`]) somewhere in a 320 x 240 backdrop ([`SMALL_CANVAS`]).
    pub fn small(&self, path: &Path, photo: &RgbImage, face: &Face) -> Result<Placed> {
        let mut rng = self.rng("small", path);
        let mut image = self.backdrop(&mut rng, SMALL_CANVAS)?;
        let width = rng.random_range(SMALL_WIDTHS.0..=SMALL_WIDTHS.1);
        let side = pasted_side(width);
        let x = rng.random_range(0..=SMALL_CANVAS.0 - side) as i64;
        let y = rng.random_range(0..=SMALL_CANVAS.1 - side) as i64;
        let face = paste(&mut image, photo, face, width as f32, x, y);
        Ok(Placed { image, face })
    }

    /// The group scene of probe photo `path`: the probe's face and [`COMPANIONS`] other
    /// people's, 16–64 px wide ([`GROUP_WIDTHS`]), side by side in cells of a 480 x 320
    /// backdrop ([`GROUP_CANVAS`]), the probe in a drawn cell. A companion whose photo has no
    /// face the `detector` finds leaves its cell empty.
    pub fn group(&self, path: &Path, photo: &RgbImage, face: &Face, detector: &FaceDetector) -> Result<Placed> {
        let mut rng = self.rng("group", path);
        let mut image = self.backdrop(&mut rng, GROUP_CANVAS)?;
        let cells = COMPANIONS as u32 + 1;
        let cell = GROUP_CANVAS.0 / cells;
        let probe_cell = rng.random_range(0..cells);
        let mut probe = None;
        for c in 0..cells {
            let width = rng.random_range(GROUP_WIDTHS.0..=GROUP_WIDTHS.1);
            let side = pasted_side(width);
            let x = (c * cell + rng.random_range(0..=cell - side.min(cell))) as i64;
            let y = rng.random_range(0..=GROUP_CANVAS.1 - side) as i64;
            if c == probe_cell {
                probe = Some(paste(&mut image, photo, face, width as f32, x, y));
                continue;
            }
            let other = &self.companions[rng.random_range(0..self.companions.len())];
            let img = read_rgb8(other)?;
            if let Some(f) = central_face(&detector.detect(&img)?, img.width(), img.height()) {
                paste(&mut image, &img, &f, width as f32, x, y);
            }
        }
        Ok(Placed { image, face: probe.expect("the probe's cell is one of the cells") })
    }
}

/// How far a face turns from the camera, from its five landmarks (right eye, left eye,
/// nose, right and left mouth corner): `(yaw, pitch_ratio)` where yaw is the nose's offset
/// from the eyes' midpoint along the eye line in eye distances (0 frontal, about ±0.5 in
/// profile) and pitch_ratio is how far down from the eyes to the mouth the nose sits
/// (about 0.5 frontal; smaller looking up, larger looking down). None for a degenerate
/// face (eyes at one point).
pub fn pose(landmarks: &[[f32; 2]; 5]) -> Option<(f32, f32)> {
    let [e0, e1, n, m0, m1] = landmarks.map(|p| [p[0] as f64, p[1] as f64]);
    let u = [e1[0] - e0[0], e1[1] - e0[1]];
    let d = u[0].hypot(u[1]);
    if d.is_nan() || d <= 1e-6 {
        return None;
    }
    let (u, v) = ([u[0] / d, u[1] / d], [-u[1] / d, u[0] / d]);
    let mid = [(e0[0] + e1[0]) / 2.0, (e0[1] + e1[1]) / 2.0];
    let mouth = [(m0[0] + m1[0]) / 2.0, (m0[1] + m1[1]) / 2.0];
    let dot = |a: [f64; 2], b: [f64; 2]| (a[0] - mid[0]) * b[0] + (a[1] - mid[1]) * b[1];
    let down = dot(mouth, v);
    if down.is_nan() || down.abs() <= 1e-6 {
        return None;
    }
    Some(((dot(n, u) / d) as f32, (dot(n, v) / down) as f32))
}

/// How far from frontal a face is ([`pose`]): the larger of |yaw| and twice the pitch
/// ratio's distance from `frontal_pitch` (a pitch ratio moves about half as far as yaw
/// for the same turn). Larger is more turned.
pub fn turn(landmarks: &[[f32; 2]; 5], frontal_pitch: f32) -> f32 {
    match pose(landmarks) {
        Some((yaw, pitch)) => yaw.abs().max(2.0 * (pitch - frontal_pitch).abs()),
        None => f32::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    #[test]
    fn pose_by_hand() {
        // Eyes at (40, 50) and (60, 50), mouth corners at (42, 70) and (58, 70).
        let face = |nose: [f32; 2]| [[40.0, 50.0], [60.0, 50.0], nose, [42.0, 70.0], [58.0, 70.0]];
        // Nose midway: frontal, halfway down to the mouth.
        assert_eq!(pose(&face([50.0, 60.0])), Some((0.0, 0.5)));
        // Nose 5 px towards the second eye: a quarter of the eye distance; 4 px lower: 0.7.
        assert_eq!(pose(&face([55.0, 64.0])), Some((0.25, 0.7)));
        assert!((turn(&face([55.0, 64.0]), 0.5) - 0.4).abs() < 1e-6);
        assert_eq!(turn(&face([45.0, 60.0]), 0.5), 0.25);
        // Rotating the whole face changes nothing (the eye line is the axis).
        let r = |p: [f32; 2]| [p[0] * 0.6 - p[1] * 0.8, p[0] * 0.8 + p[1] * 0.6];
        let (yaw, pitch) = pose(&face([55.0, 64.0]).map(r)).unwrap();
        assert!((yaw - 0.25).abs() < 1e-5 && (pitch - 0.7).abs() < 1e-5, "{yaw} {pitch}");
        // Degenerate: both eyes at one point.
        assert_eq!(pose(&[[1.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 3.0], [2.0, 3.0]]), None);
    }

    #[test]
    fn paste_maps_the_face_box_to_the_width_asked() {
        // A 100 x 100 photo, face box (30, 30)-(70, 70): 40 px; pasted at 20 px wide at (5, 7).
        let photo = RgbImage::from_fn(100, 100, |x, y| Rgb([x as u8, y as u8, 0]));
        let lm = [[40.0, 45.0], [60.0, 45.0], [50.0, 55.0], [42.0, 62.0], [58.0, 62.0]];
        let face = Face { bbox: [30.0, 30.0, 70.0, 70.0], score: 1.0, landmarks: lm };
        let mut canvas = RgbImage::new(64, 64);
        let p = paste(&mut canvas, &photo, &face, 20.0, 5, 7);
        // Context 1.8 x 40 = 72 px square from (14, 14); scale 0.5: box (8, 8)-(28, 28) + (5, 7).
        assert_eq!(p.bbox, [13.0, 15.0, 33.0, 35.0]);
        assert_eq!(p.landmarks[2], [5.0 + 18.0, 7.0 + 20.5]);
        assert_eq!(pasted_side(20), 36);
        // The square is written (36 x 36 from (5, 7)), the rest untouched.
        assert_eq!(canvas.get_pixel(4, 7), &Rgb([0, 0, 0]));
        assert_ne!(canvas.get_pixel(5 + 18, 7 + 18), &Rgb([0, 0, 0]));
        // The pixel at the pasted nose is the photo's nose, up to the 2:1 averaging.
        let nose = canvas.get_pixel(23, 27);
        assert!((nose[0] as i32 - 50).abs() <= 1 && (nose[1] as i32 - 55).abs() <= 1, "{nose:?}");
    }

    #[test]
    fn seeds_come_from_the_name_not_the_folder() {
        assert_eq!(fnv1a(""), 0xcbf2_9ce4_8422_2325);
        // FNV-1a 64 of "a" (the published test vector).
        assert_eq!(fnv1a("a"), 0xaf63_dc4c_8601_ec8c);
    }
}
