//! What the camera is pointed at, for the privacy evaluation: LFW's photos as they are
//! (colour); as a black-and-white, infrared or night camera sees them (grey); each probe's
//! face small in a held-out scene, as CCTV sees a passer-by (small), or beside other
//! people's faces (group) ([`crate::place`]); or LFW's most turned faces (pose).
//!
//! Grey changes the photos before anything else, so the adversary's gallery, the probes
//! and the verification pairs all see it. Small and group change only what the camera sees
//! of a probe (the gallery stays the raw photos: the adversary enrolled people from their
//! ordinary pictures); pose changes which photos are probed. The protections
//! ([`crate::Condition`]) then run on what the camera sees.

use image::{Rgb, RgbImage};
use serde::Serialize;

/// A scene of the privacy evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scene {
    /// The photos as they are.
    #[default]
    Colour,
    /// Each pixel replaced by its BT.601 luma ([`campro::chroma::luma`]) in all three
    /// channels.
    Grey,
    /// Each probe's face 12–48 px wide in a held-out scene ([`crate::place::Stage::small`]).
    Small,
    /// Each probe's face beside three other people's ([`crate::place::Stage::group`]).
    Group,
    /// Each identity's most frontal photo enrolled, its most turned ones probed
    /// ([`crate::place::turn`]).
    Pose,
}

impl Scene {
    /// Every scene, in report order.
    pub const ALL: [Scene; 5] = [Scene::Colour, Scene::Grey, Scene::Small, Scene::Group, Scene::Pose];

    /// The name in flags, folders and reports.
    pub fn name(self) -> &'static str {
        match self {
            Scene::Colour => "colour",
            Scene::Grey => "grey",
            Scene::Small => "small",
            Scene::Group => "group",
            Scene::Pose => "pose",
        }
    }

    /// Whether the probe's face is placed in another picture ([`crate::place`]).
    pub fn placed(self) -> bool {
        matches!(self, Scene::Small | Scene::Group)
    }

    /// Every photo (gallery, probe, pair) as this scene shows it: grey makes it grey; the
    /// others leave it (they place or choose probes instead).
    pub fn apply(self, img: RgbImage) -> RgbImage {
        match self {
            Scene::Colour | Scene::Small | Scene::Group | Scene::Pose => img,
            Scene::Grey => {
                let mut img = img;
                for p in img.pixels_mut() {
                    *p = Rgb([campro::chroma::luma(p.0); 3]);
                }
                img
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_is_the_integer_luma_in_every_channel() {
        let img = RgbImage::from_vec(3, 1, vec![255, 0, 0, 0, 255, 0, 10, 20, 30]).unwrap();
        let g = Scene::Grey.apply(img.clone());
        // 77·255 >> 8 = 76; 150·255 >> 8 = 149; (770 + 3000 + 870) >> 8 = 18.
        assert_eq!(g.into_raw(), vec![76, 76, 76, 149, 149, 149, 18, 18, 18]);
        assert_eq!(Scene::Colour.apply(img.clone()), img);
        // What the chroma measure calls grey.
        let photo = RgbImage::from_fn(40, 30, |x, y| Rgb([(x * 6) as u8, (y * 8) as u8, ((x + y) * 3) as u8]));
        assert!(!campro::chroma::measure(photo.as_raw()).is_grey());
        assert!(campro::chroma::measure(Scene::Grey.apply(photo).as_raw()).is_grey());
    }
}
