//! Deployment targets: how a parameter set becomes the values a camera stack takes.

pub mod camera2;
