//! Helpers shared by the integration tests: scratch folders and copies of the spectral library.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use tempfile::TempDir;

/// A fresh scratch folder `specmux-{tag}-*`, removed when the returned guard drops.
pub fn tmpdir(tag: &str) -> TempDir {
    tempfile::Builder::new()
        .prefix(&format!("specmux-{tag}-"))
        .tempdir()
        .unwrap()
}

/// A copy of the real spectra/ folder inside `dir` that a test may corrupt.
pub fn spectra_copy(dir: &Path) -> PathBuf {
    let dst = dir.join("spectra");
    copy_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("spectra"), &dst);
    dst
}

fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let p = e.unwrap().path();
        let to = dst.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &to)
        } else {
            std::fs::copy(&p, &to).unwrap();
        }
    }
}
