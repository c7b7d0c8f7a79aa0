//! TOML settings files (experiments, the design tools' families): read so that an error names
//! the file, the line, the key path and the value written there.

use specmux_core::error::shown;
use specmux_core::{Error, Result};

/// `T` from TOML `text`; an error names `file` (and the line, when `lines`: text the user
/// wrote), the key path where it arose and the value written there.
pub fn read_toml<T: serde::de::DeserializeOwned>(text: &str, file: &str, lines: bool) -> Result<T> {
    serde_path_to_error::deserialize(toml::Deserializer::new(text))
        .map_err(|err| parse_error(&err, text, file, lines))
}

/// A parse error of a TOML text naming the file (and the line, when `lines`), the key
/// where it arose and the value written there (the key alone where the document cannot be read
/// as TOML or has no value there).
fn parse_error(
    err: &serde_path_to_error::Error<toml::de::Error>,
    text: &str,
    file: &str,
    lines: bool,
) -> Error {
    let inner = err.inner();
    let line = inner
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
    let file = match (lines, line) {
        (true, Some(line)) => format!("{file}:{line}"),
        _ => file.to_string(),
    };
    let reason = shown(inner.message().replace('\n', " "));
    let path = err.path().to_string();
    if path == "." {
        return Error::Toml { file, msg: reason };
    }
    let written = text.parse::<toml::Table>().ok();
    let msg = match written.as_ref().and_then(|t| value_at(t, err.path())) {
        Some(v) => format!("`{path}` = {}: {reason}", shown(v)),
        None => format!("`{path}`: {reason}"),
    };
    Error::Toml { file, msg }
}

/// The value of `table` at a deserializer's `path` (tables by key, arrays by index).
fn value_at<'a>(
    table: &'a toml::Table,
    path: &serde_path_to_error::Path,
) -> Option<&'a toml::Value> {
    use serde_path_to_error::Segment;
    let mut segments = path.iter();
    let mut value = match segments.next()? {
        Segment::Map { key } => table.get(key)?,
        _ => return None,
    };
    for segment in segments {
        value = match segment {
            Segment::Map { key } => value.as_table()?.get(key)?,
            Segment::Seq { index } => value.as_array()?.get(*index)?,
            _ => return None,
        };
    }
    Some(value)
}
