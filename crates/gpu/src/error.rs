//! The errors of the GPU backend.

/// What went wrong on the GPU path; each message is one line.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter of a native backend was found (no GPU driver, no lavapipe).
    #[error("no GPU adapter found: {0}")]
    NoAdapter(String),
    /// The adapter refused a device, or the device failed while working.
    #[error("GPU device error: {0}")]
    Device(String),
    /// A size or layout the GPU kernels do not handle.
    #[error("not supported on the GPU: {0}")]
    Unsupported(String),
    /// A shape mismatch between inputs.
    #[error("shape: {0}")]
    Shape(String),
    /// A numerical failure reported by a kernel (non-finite input, a QP that did not converge).
    #[error("numerical: {0}")]
    Numerical(String),
    /// An error of the reconstruction core (building the CPU-side description).
    #[error(transparent)]
    Core(#[from] specmux_core::Error),
}

pub type Result<T> = std::result::Result<T, GpuError>;

impl From<GpuError> for specmux_core::Error {
    /// A GPU failure in a core call: the core's own error, a shape, or one numerical line.
    fn from(e: GpuError) -> Self {
        match e {
            GpuError::Core(c) => c,
            GpuError::Shape(s) => specmux_core::Error::Shape(s),
            other => specmux_core::Error::Numerical(other.to_string()),
        }
    }
}
