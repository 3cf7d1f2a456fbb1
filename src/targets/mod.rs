//! Deployment targets: how a parameter set becomes the values a camera stack takes.
//!
//! Every target answers the same questions, in [`Format`]: how the CCM is held (range,
//! quantisation step, how it follows the colour temperature), on what grid and with what
//! precision the tone curve is given, and in what order the stages run. A [`Target`]
//! exports a parameter set into the stack's own file and, from that file read back with
//! the same parser, emulates what the ISP then applies ([`Condition`]), so
//! [`crate::compare::deployment_vs_desktop`] can measure the deployment error.
//!
//! Camera2 ([`camera2`]) is a target like the others and also has its own richer API
//! (rationals, read-back, the per-frame camera loop); the file-based stacks are [`rpi`],
//! [`rkaiq`] and [`cube`]. Every stack is registered once in [`REGISTRY`], including those
//! that cannot hold a CamPro curve at all, with the reason ([`Support::Refused`]).

pub mod camera2;
pub mod cube;
pub mod rkaiq;
pub mod rpi;

mod registry;
mod target;

pub use registry::{by_name, entry, refusal, Entry, Support, REGISTRY};
pub use target::{Condition, CurveFormat, Feed, Format, MatrixBy, MatrixFormat, StageOrder, Target, TargetError};
