//! The one table of camera stacks ([`REGISTRY`]): every target campro can deploy to and
//! every stack it refuses, with the reason.

use super::target::Target;
use super::{camera2, cube, rkaiq, rpi};

/// Whether a stack can take CamPro.
#[derive(Clone, Copy)]
pub enum Support {
    /// It can: the target with its default settings.
    Deploy(fn() -> Box<dyn Target>),
    /// It cannot: why (a stack with only a scalar gamma).
    Refused(&'static str),
}

/// One registered camera stack.
#[derive(Clone, Copy)]
pub struct Entry {
    /// Its name on the command line.
    pub name: &'static str,
    /// One line on what it is.
    pub about: &'static str,
    /// What CamPro can do there.
    pub support: Support,
}

/// Every camera stack campro knows, in one table.
pub const REGISTRY: &[Entry] = &[
    Entry {
        name: "camera2",
        about: "Android Camera2: COLOR_CORRECTION_TRANSFORM + TONEMAP_CURVE",
        support: Support::Deploy(|| Box::new(camera2::Camera2::default())),
    },
    Entry {
        name: "rpi-vc4",
        about: "Raspberry Pi 4 and earlier: patched libcamera tuning file (--base)",
        support: Support::Deploy(|| Box::new(rpi::Rpi::Vc4)),
    },
    Entry {
        name: "rpi-pisp",
        about: "Raspberry Pi 5: patched libcamera tuning file (--base)",
        support: Support::Deploy(|| Box::new(rpi::Rpi::Pisp)),
    },
    Entry {
        name: "rkaiq-isp20",
        about: "Rockchip RV1109/RV1126: patched rkaiq IQ file (--base)",
        support: Support::Deploy(|| Box::new(rkaiq::Rkaiq::Isp20)),
    },
    Entry {
        name: "rkaiq-isp3x",
        about: "Rockchip ISP3x (RK3568/RK3588 class): patched rkaiq IQ file (--base)",
        support: Support::Deploy(|| Box::new(rkaiq::Rkaiq::Isp3x)),
    },
    Entry {
        name: "cube",
        about: ".cube 3D LUT on gamma-encoded RGB (--cube-size)",
        support: Support::Deploy(|| Box::new(cube::CubeFile::default())),
    },
    Entry {
        name: "hald",
        about: "Hald CLUT, 16-bit PPM (--hald-level)",
        support: Support::Deploy(|| Box::new(cube::CubeFile::hald(8))),
    },
    Entry {
        name: "rkisp1",
        about: "libcamera rkisp1 (refused: scalar gamma only)",
        support: Support::Refused(
            "libcamera's rkisp1 IPA drives the gamma-out block (GOC) from one scalar gamma (17 fixed knots, 10-bit) and its tuning files carry no curve",
        ),
    },
    Entry {
        name: "simple",
        about: "libcamera simple / software ISP (refused: scalar gamma only)",
        support: Support::Refused(
            "libcamera's simple (software) ISP builds its lookup table from one scalar gamma and a contrast value",
        ),
    },
    Entry {
        name: "uvc",
        about: "plain V4L2 / UVC webcams (refused: scalar gamma only)",
        support: Support::Refused("plain V4L2 / UVC webcams expose only a scalar gamma control (V4L2_CID_GAMMA)"),
    },
];

/// The registered stack called `name`.
pub fn entry(name: &str) -> Option<&'static Entry> {
    REGISTRY.iter().find(|e| e.name == name)
}

/// The target called `name` with its default settings; `None` for unknown or refused
/// stacks.
pub fn by_name(name: &str) -> Option<Box<dyn Target>> {
    match entry(name)?.support {
        Support::Deploy(make) => Some(make()),
        Support::Refused(_) => None,
    }
}

/// Why a stack with only a scalar gamma cannot take CamPro, and what to do instead;
/// `None` for stacks that can (and for unknown names).
pub fn refusal(name: &str) -> Option<String> {
    let Support::Refused(why) = entry(name)?.support else { return None };
    Some(format!(
        "{name}: {why}, so the CamPro tone curve (arbitrary, often non-monotonic) cannot be deployed in the camera. \
         Use the 3D LUT route instead: `campro convert PARAMS --target cube` and apply the .cube right after capture \
         (ffmpeg lut3d, GStreamer, OBS), accepting that the unprotected frame then exists in software for a moment."
    ))
}
