//! The controller's errors. Each renders as one line that names the key and value at fault, or
//! the device and the command it did not answer, so the CLI can print it as it is.

/// Errors of planning, device control and recording.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An error of the core, the twin or the file formats (already one line).
    #[error(transparent)]
    Core(#[from] specmux_core::Error),
    /// The plan cannot run on these devices; raised before any device command is sent.
    #[error("plan refused: `{key}` = {value}: {reason}")]
    Refused {
        key: String,
        value: String,
        reason: String,
    },
    /// A device refused a command or reported a failure.
    #[error("{device}: {msg}")]
    Device { device: String, msg: String },
    /// A device did not answer in time (a cable pulled, a driver hung).
    #[error("{device}: no answer to {what} within {after_s} s")]
    Timeout {
        device: String,
        what: String,
        after_s: f64,
    },
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// A refusal of the plan naming the key and its value.
    pub fn refused(key: &str, value: impl std::fmt::Display, reason: impl Into<String>) -> Error {
        Error::Refused {
            key: key.into(),
            value: value.to_string(),
            reason: reason.into(),
        }
    }

    /// A device's refusal or failure.
    pub fn device(device: &str, msg: impl Into<String>) -> Error {
        Error::Device {
            device: device.into(),
            msg: msg.into(),
        }
    }

    /// An I/O failure on `path`, as the core reports it.
    pub fn io(path: &std::path::Path, e: std::io::Error) -> Error {
        Error::Core(specmux_core::Error::io(path, e))
    }
}
