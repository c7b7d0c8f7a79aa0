//! The spectral library: resolves names like `wheel/red` to CSV tables, read from a folder
//! (`--spectra`, `$SPECMUX_SPECTRA`) or from the copy of `spectra/` embedded at build time, so
//! that an installed binary works from any folder.

use crate::error::Error;
use crate::error::Result;
use crate::spectral::csv;
use crate::spectral::csv::Table;
use crate::spectral::curve::Curve;
use std::path::{Path, PathBuf};

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/embedded_spectra.rs"));
}

/// Where a library's CSV files live.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Source {
    Folder(PathBuf),
    /// `spectra/` of the source tree this crate was built from, compiled in.
    Embedded,
}

/// A folder of spectral CSV files, or the embedded copy of `spectra/`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Library {
    source: Source,
}

/// The label of the embedded library in paths and reports.
const EMBEDDED_LABEL: &str = "<embedded spectra>";

impl Library {
    /// The library in folder `root`.
    pub fn new(root: impl Into<PathBuf>) -> Library {
        Library {
            source: Source::Folder(root.into()),
        }
    }

    /// The copy of `spectra/` compiled into this binary.
    pub fn embedded() -> Library {
        Library {
            source: Source::Embedded,
        }
    }

    /// `$SPECMUX_SPECTRA` if set, else the embedded library.
    pub fn default_root() -> Library {
        match std::env::var_os("SPECMUX_SPECTRA") {
            Some(p) => Library::new(p),
            None => Library::embedded(),
        }
    }

    /// The folder the library reads, None for the embedded one.
    pub fn root(&self) -> Option<&Path> {
        match &self.source {
            Source::Folder(p) => Some(p),
            Source::Embedded => None,
        }
    }

    /// Where the curves come from, for reports: the folder, or "embedded (specmux X.Y.Z)".
    pub fn provenance(&self) -> String {
        match &self.source {
            Source::Folder(p) => p.display().to_string(),
            Source::Embedded => format!("embedded (specmux {})", env!("CARGO_PKG_VERSION")),
        }
    }

    /// Path of the named table (`wheel/red` → `<root>/wheel/red.csv`); an absolute name is a
    /// file outside the library (`/data/filter` → `/data/filter.csv`).
    pub fn path(&self, name: &str) -> PathBuf {
        let file = format!("{name}.csv");
        match &self.source {
            _ if Path::new(name).is_absolute() => PathBuf::from(file),
            Source::Folder(root) => root.join(file),
            Source::Embedded => Path::new(EMBEDDED_LABEL).join(file),
        }
    }

    /// The text of the named table and the path that names it in errors.
    fn text(&self, name: &str) -> Result<(PathBuf, String)> {
        let path = self.path(name);
        if self.source == Source::Embedded && !Path::new(name).is_absolute() {
            let rel = format!("{name}.csv");
            return match embedded::EMBEDDED.iter().find(|(p, _)| *p == rel) {
                Some((_, text)) => Ok((path, text.to_string())),
                None => Err(Error::io(&path, not_found("no such curve in the library"))),
            };
        }
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        Ok((path, text))
    }

    /// Whether the named table's file holds exactly `text` (false where there is none).
    pub fn holds(&self, name: &str, text: &str) -> bool {
        self.text(name).is_ok_and(|(_, t)| t == text)
    }

    /// Read a named table with all its curves.
    pub fn table(&self, name: &str) -> Result<Table> {
        let (path, text) = self.text(name)?;
        csv::parse(&path, &text)
    }

    /// Read a named single curve (a two-column file); the curve takes the file's name.
    pub fn curve(&self, name: &str) -> Result<Curve> {
        let t = self.table(name)?;
        single_curve(&self.path(name), t, name)
    }

    /// The name of every table of the library (`wheel/red`), searched recursively, sorted.
    pub fn names(&self) -> Result<Vec<String>> {
        let mut names: Vec<String> = match &self.source {
            Source::Folder(root) => {
                let mut files = Vec::new();
                walk(root, &mut files)?;
                files
                    .iter()
                    .filter_map(|f| f.strip_prefix(root).ok())
                    .map(|r| r.with_extension("").to_string_lossy().replace('\\', "/"))
                    .collect()
            }
            Source::Embedded => embedded::EMBEDDED
                .iter()
                .map(|(p, _)| p.trim_end_matches(".csv").to_string())
                .collect(),
        };
        names.sort();
        Ok(names)
    }

    /// All curves of every CSV file directly in folder `dir` (sorted by file name), e.g. the
    /// reflectance library.
    pub fn folder(&self, dir: &str) -> Result<Vec<Curve>> {
        let mut out = Vec::new();
        for name in self.names()? {
            let Some(stem) = name.strip_prefix(&format!("{dir}/")) else {
                continue;
            };
            if stem.contains('/') {
                continue;
            }
            for c in self.table(&name)?.curves {
                let name = format!("{dir}/{stem}/{}", c.name);
                out.push(Curve::new(
                    name,
                    c.wavelengths().to_vec(),
                    c.values().to_vec(),
                )?);
            }
        }
        if out.is_empty() {
            let folder = self.path(dir).with_extension("");
            return Err(Error::io(
                &folder,
                not_found("no CSV curves in this folder"),
            ));
        }
        Ok(out)
    }
}

/// Read a spectral CSV file anywhere (a user's own filter, illuminant or QE) as one curve
/// named `name`.
pub fn curve_file(path: &Path, name: &str) -> Result<Curve> {
    single_curve(path, csv::read(path)?, name)
}

/// The one curve of a two-column table.
fn single_curve(path: &Path, t: Table, name: &str) -> Result<Curve> {
    if t.curves.len() != 1 {
        return Err(Error::Csv {
            path: path.to_path_buf(),
            line: 0,
            msg: format!(
                "expected one curve column, found {} (is this a library table?)",
                t.curves.len()
            ),
        });
    }
    let c = t.curves.into_iter().next().unwrap();
    Curve::new(name, c.wavelengths().to_vec(), c.values().to_vec())
}

fn not_found(msg: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::NotFound, msg.to_string())
}

/// Every `.csv` file under `dir`, recursively.
fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    for e in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let p = e.map_err(|e| Error::io(dir, e))?.path();
        if p.is_dir() {
            walk(&p, out)?;
        } else if p.extension().is_some_and(|x| x == "csv") {
            out.push(p);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The embedded library is the source tree's `spectra/`, file for file and byte for byte.
    #[test]
    fn the_embedded_library_equals_the_spectra_folder() {
        let folder = Library::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../spectra"));
        let (a, b) = (Library::embedded(), folder);
        let names = a.names().unwrap();
        assert_eq!(names, b.names().unwrap());
        assert!(names.contains(&"wheel/red".to_string()), "{names:?}");
        for n in &names {
            assert_eq!(
                a.table(n).unwrap().curves,
                b.table(n).unwrap().curves,
                "{n}"
            );
        }
        assert_eq!(
            a.folder("reflectance").unwrap().len(),
            b.folder("reflectance").unwrap().len()
        );
        let e = a.curve("wheel/nope").unwrap_err().to_string();
        assert!(e.contains("<embedded spectra>/wheel/nope.csv"), "{e}");
        assert!(a.provenance().starts_with("embedded (specmux "));
    }
}
