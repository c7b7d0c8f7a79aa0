//! JSON reports: any serialisable value, pretty-printed, written atomically.

use crate::atomic;
use specmux_core::{Error, Result};
use std::path::Path;

/// Write any serialisable value as pretty JSON.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| Error::Image {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })?;
    atomic::write_bytes(path, text.as_bytes())
}
