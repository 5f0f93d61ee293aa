//! The render error.

use crate::l3::table::TableError;

/// Errors of a render: input the renderer cannot take, a table or kernel set it cannot
/// render with, a buffer of the wrong size, and a render its caller abandoned.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A table whose kernels cannot be rendered with.
    #[error("table is not usable: {0}")]
    Table(String),
    /// The table cannot be prepared to render: its classification geometry, its transfer
    /// kernels, or a light its chroma classes cannot balance by.
    #[error(transparent)]
    Prepare(#[from] TableError),
    #[error("the render was canceled")]
    RenderCanceled,
    /// A kernel set whose length is not the table's (the caller's fault, never the input's).
    #[error("a kernel set of {got} weights does not match the table's {expected}")]
    KernelMismatch { got: usize, expected: usize },
    /// An output buffer of the wrong size (the caller's fault, never the input's).
    #[error("the output buffer holds {got} bytes; the {width}×{height} region needs {need}")]
    OutputBuffer {
        got: usize,
        need: usize,
        width: usize,
        height: usize,
    },
}
