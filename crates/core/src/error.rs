//! The library's error type: every variant names the file, field or value at fault so the CLI can
//! report it in one line.

use std::path::PathBuf;

/// Errors raised by specmux. Display renders one line that says what is wrong and where.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}:{line}: {msg}")]
    Csv {
        path: PathBuf,
        line: usize,
        msg: String,
    },
    #[error("{path}: {msg}")]
    Exr { path: PathBuf, msg: String },
    #[error("{path}: {msg}")]
    Image { path: PathBuf, msg: String },
    #[error("{file}: {msg}")]
    Toml { file: String, msg: String },
    /// A configuration value outside its valid range; names the key and the value.
    #[error("{file}: `{key}` = {value}: {reason}")]
    Config {
        file: String,
        key: String,
        value: String,
        reason: String,
    },
    /// A spectral curve that cannot be used (NaN, decreasing wavelengths, …).
    #[error("{name}: {msg}")]
    Curve { name: String, msg: String },
    /// Shapes that do not agree (plane sizes, band counts).
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// A numerical problem the input makes unsolvable (a singular system, an empty window).
    #[error("numerical: {0}")]
    Numerical(String),
    /// A problem found late, deep in numerical code, with the input that led there.
    #[error("{file}: `{key}` = {value}: {source}")]
    Within {
        file: String,
        key: String,
        value: String,
        source: Box<Error>,
    },
    /// The run was stopped (Ctrl-C) at a safe point; names the step it stopped in.
    #[error("interrupted (Ctrl-C) during {0}")]
    Interrupted(String),
}

/// The file a configuration error names where the experiment's file is not known (the twin's
/// optical chain); [`Error::in_file`] puts the real file in at the boundary that knows it.
pub const UNNAMED_FILE: &str = "optics";

/// Result alias for the crate.
pub type Result<T> = std::result::Result<T, Error>;

/// `v` within `range`, or the configuration error naming `file`'s `key` and `v`:
/// "must be START to END {unit}" (`unit` may carry a note: "pixels (as scene.size)").
pub fn check_count(
    file: &str,
    key: &str,
    v: usize,
    range: std::ops::RangeInclusive<usize>,
    unit: &str,
) -> Result<()> {
    if range.contains(&v) {
        return Ok(());
    }
    let why = format!("must be {} to {} {unit}", range.start(), range.end());
    Err(Error::config(file, key, v, &why))
}

/// A value or message as an error shows it: as written, but every decimal number longer than 24
/// characters (Display writes 1e308 with 308 digits) in exponent form, the same shortest digits
/// that read back to the same f64, so the error stays one short line. Digits within a word or a
/// path (`run_2026…`, `/tmp/123…`) are left as they are.
pub fn shown(text: impl std::fmt::Display) -> String {
    let text = text.to_string();
    let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || "_/\\".contains(c));
    let mut out = String::with_capacity(text.len());
    let mut at = 0;
    while let Some(found) = text[at..].find(|c: char| c.is_ascii_digit()) {
        let start = at + found;
        let len = text[start..]
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(text.len() - start);
        let before = text[..start].strip_suffix('-').unwrap_or(&text[..start]);
        let standalone =
            !word(before.chars().next_back()) && !word(text[start + len..].chars().next());
        let number = &text[start..start + len];
        out.push_str(&text[at..start]);
        match number.parse::<f64>() {
            Ok(v) if standalone && number.len() > 24 => out.push_str(&format!("{v:e}")),
            _ => out.push_str(number),
        }
        at = start + len;
    }
    out.push_str(&text[at..]);
    out
}

impl Error {
    /// Shorthand for a configuration error.
    pub fn config(file: &str, key: &str, value: impl std::fmt::Display, reason: &str) -> Self {
        Error::Config {
            file: file.to_string(),
            key: key.to_string(),
            value: shown(value),
            reason: shown(reason),
        }
    }

    /// Name the input behind a numerical or shape error found late (`file`, `key`, `value`);
    /// errors that already name their source (a file, a key, a curve) are returned unchanged.
    pub fn within(self, file: &str, key: &str, value: impl std::fmt::Display) -> Self {
        match self {
            Error::Numerical(_) | Error::Shape(_) => Error::Within {
                file: file.to_string(),
                key: key.to_string(),
                value: shown(value),
                source: Box::new(self),
            },
            named => named,
        }
    }

    /// A configuration error raised under [`UNNAMED_FILE`], named by the experiment's `file`;
    /// every other error unchanged.
    pub fn in_file(self, file: &str) -> Self {
        match self {
            Error::Config {
                file: f,
                key,
                value,
                reason,
            } if f == UNNAMED_FILE => Error::Config {
                file: file.to_string(),
                key,
                value,
                reason,
            },
            other => other,
        }
    }

    /// Wrap an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_decimals_are_shown_in_exponent_form_and_the_rest_as_written() {
        let long = format!("floating point `{}`, expected u32", 1e308);
        assert_eq!(shown(&long), "floating point `1e308`, expected u32");
        assert_eq!(shown(-1e-300), "-1e-300");
        assert_eq!(shown(f64::MAX), format!("{:e}", f64::MAX));
        assert_eq!(shown(f64::MAX).parse::<f64>().unwrap(), f64::MAX);
        for kept in [
            "/tmp/run_20261129181500123456789/frame.exr",
            "a-1000000000000000000000000000",
            "0.25",
            "100000",
            "u64::MAX 18446744073709551615",
            "1.2.3",
            "[[1.0, 0.0]]",
            "NaN",
        ] {
            assert_eq!(shown(kept), kept);
        }
    }
}
