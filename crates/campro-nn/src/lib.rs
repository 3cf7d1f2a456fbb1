//! campro-nn: the neural-network layer of campro's training on candle, everything that is
//! not a training loop. One module per op family, each op a fast CPU custom op with its own
//! backward and a generic fallback from candle's ops (the path on any other device, and the
//! second implementation the tests check the fast one against):
//!
//! - [`conv`]: dense 2-D convolution (im2col + `gemm`);
//! - [`depthwise`]: depthwise convolution;
//! - [`batch_norm`]: training-mode batch norm with PReLU fused;
//! - [`activation`]: PReLU, SiLU, ReLU;
//! - [`channel`]: per-channel bias and affine (evaluation-mode batch norm);
//! - [`kernels`]: the vector kernels they share (one version per CPU feature level);
//!
//! and the networks built on them: [`onnx_net`] (an ONNX graph as trainable candle ops,
//! written back to ONNX), [`mobilefacenet`] (the face attacker, from its PyTorch checkpoint
//! through [`torch_legacy`]) and [`yolox`] (the person detector). A [`Context`] says where a
//! run computes.

pub mod activation;
pub mod batch_norm;
pub mod channel;
pub mod context;
pub mod conv;
pub mod depthwise;
pub mod error;
pub mod kernels;
pub mod mobilefacenet;
pub mod onnx_net;
mod storage;
pub mod torch_legacy;
pub mod yolox;

pub use candle_core::{Device, Tensor};
pub use context::Context;
pub use error::NnError;
