//! The spectral library: resolves names like `wheel/red` to CSV files under a `spectra/` folder.

use crate::error::Error;
use crate::error::Result;
use crate::spectral::csv;
use crate::spectral::csv::Table;
use crate::spectral::curve::Curve;
use std::path::{Path, PathBuf};

/// A folder of spectral CSV files.
#[derive(Clone, Debug)]
pub struct Library {
    pub root: PathBuf,
}

impl Library {
    /// The library at `root`.
    pub fn new(root: impl Into<PathBuf>) -> Library {
        Library { root: root.into() }
    }

    /// `$SPECMUX_SPECTRA` if set, else the `spectra/` folder at the root of this source tree.
    pub fn default_root() -> Library {
        match std::env::var_os("SPECMUX_SPECTRA") {
            Some(p) => Library::new(p),
            None => Library::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../spectra")),
        }
    }

    /// Path of the named table (`wheel/red` → `<root>/wheel/red.csv`).
    pub fn path(&self, name: &str) -> PathBuf {
        self.root.join(format!("{name}.csv"))
    }

    /// Read a named table with all its curves.
    pub fn table(&self, name: &str) -> Result<Table> {
        csv::read(&self.path(name))
    }

    /// Read a named single curve (a two-column file); the curve takes the file's name.
    pub fn curve(&self, name: &str) -> Result<Curve> {
        let path = self.path(name);
        let t = csv::read(&path)?;
        if t.curves.len() != 1 {
            return Err(Error::Csv {
                path,
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

    /// All curves of every CSV file directly in folder `dir` (sorted by file name), e.g. the
    /// reflectance library.
    pub fn folder(&self, dir: &str) -> Result<Vec<Curve>> {
        let folder = self.root.join(dir);
        let mut files: Vec<PathBuf> = std::fs::read_dir(&folder)
            .map_err(|e| Error::io(&folder, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "csv"))
            .collect();
        files.sort();
        let mut out = Vec::new();
        for f in files {
            let stem = f.file_stem().unwrap().to_string_lossy().to_string();
            for c in csv::read(&f)?.curves {
                let name = format!("{dir}/{stem}/{}", c.name);
                out.push(Curve::new(
                    name,
                    c.wavelengths().to_vec(),
                    c.values().to_vec(),
                )?);
            }
        }
        if out.is_empty() {
            return Err(Error::io(
                &folder,
                std::io::Error::new(std::io::ErrorKind::NotFound, "no CSV curves in this folder"),
            ));
        }
        Ok(out)
    }
}
