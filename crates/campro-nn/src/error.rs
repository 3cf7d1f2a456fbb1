//! The crate's one error enum, [`NnError`]: each module's error kind converts into it.

/// Any error of the networks: a checkpoint or graph that does not read, or a tensor op.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NnError {
    /// A legacy PyTorch checkpoint.
    #[error(transparent)]
    Torch(#[from] crate::torch_legacy::TorchError),
    /// An ONNX graph.
    #[error(transparent)]
    Graph(#[from] crate::onnx_net::GraphError),
    /// A tensor operation.
    #[error("tensor: {0}")]
    Tensor(#[from] candle_core::Error),
}
