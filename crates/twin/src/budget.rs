//! Resource budgets, checked before any work: the memory an experiment's run holds at once and
//! its work, against what this machine has. A run that would not fit is refused with the
//! estimate and the key to change, instead of aborting after an allocation of terabytes.

use crate::experiment::Experiment;
use specmux_core::{Error, Result};

/// Largest band count a cube may have: far beyond any spectrometer (1 nm over 300–2500 nm).
pub const MAX_BANDS: usize = 4096;

/// The bytes a run of `exp` holds at once, by the arrays it keeps, and the work of its GAP.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    pub bytes: f64,
    /// GAP iterations × pixels × channels: the de-aliasing's work in pixel-channel updates.
    pub gap_updates: f64,
}

impl Estimate {
    /// The scene cube, its truth copy and the reconstructed cube (bands planes each); channels,
    /// exposed channels, patterns, calibration captures, the estimates and GAP's buffers (about
    /// twelve channel-sized cubes at once); f32 throughout.
    pub fn of(exp: &Experiment) -> Result<Estimate> {
        let [w, h] = exp.scene.size;
        let bands = exp.scene.grid(&exp.file)?.count as f64;
        let channels = exp.rig.wheel.filters.len() as f64;
        let pixels = (w * h) as f64;
        let gap = &exp.reconstruct.gap;
        Ok(Estimate {
            bytes: 4.0 * pixels * (3.0 * bands + 12.0 * channels) + 8.0 * bands * bands,
            gap_updates: gap.iterations as f64 * pixels * channels,
        })
    }
}

/// Refuse an experiment whose run would not fit in `available` bytes, naming the largest factor.
pub fn check(exp: &Experiment, available: f64) -> Result<Estimate> {
    let f = exp.file.as_str();
    let bands = exp.scene.grid(f)?.count;
    if bands > MAX_BANDS {
        let [lo, hi, step] = exp.scene.wavelengths_nm;
        return Err(Error::config(
            f,
            "scene.wavelengths_nm",
            format!("[{lo}, {hi}, {step}]"),
            &format!("gives {bands} bands, more than {MAX_BANDS}; use a coarser step"),
        ));
    }
    let e = Estimate::of(exp)?;
    if e.bytes > available {
        let [w, h] = exp.scene.size;
        return Err(Error::config(
            f,
            "scene.size",
            format!("[{w}, {h}]"),
            &format!(
                "a run holds about {:.1} GB at once ({bands} bands, {} channels) and this machine has {:.1} GB available; use a smaller size",
                e.bytes / 1e9,
                exp.rig.wheel.filters.len(),
                available / 1e9
            ),
        ));
    }
    Ok(e)
}

/// The memory this machine has available now (Linux `MemAvailable`), else a generous 16 GB.
pub fn available_memory() -> f64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| {
            let line = t.lines().find(|l| l.starts_with("MemAvailable:"))?;
            let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
            Some(kb * 1024.0)
        })
        .unwrap_or(16e9)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_prototype_fits_and_its_estimate_is_the_sum_of_its_arrays() {
        let exp = Experiment::prototype();
        let e = check(&exp, 24e9).unwrap();
        let px = 768.0 * 768.0;
        assert_eq!(
            e.bytes,
            4.0 * px * (3.0 * 31.0 + 12.0 * 6.0) + 8.0 * 31.0 * 31.0
        );
        assert_eq!(e.gap_updates, 20.0 * px * 6.0);
    }

    #[test]
    fn too_large_or_too_fine_is_refused_by_key() {
        let big = Experiment::from_toml("[scene]\nsize = [8192, 8192]\n", "big.toml").unwrap();
        let msg = check(&big, 24e9).unwrap_err().to_string();
        assert!(
            msg.contains("big.toml") && msg.contains("scene.size") && msg.contains("GB"),
            "{msg}"
        );
        let fine =
            Experiment::from_toml("[scene]\nwavelengths_nm = [400, 700, 0.01]\n", "fine.toml")
                .unwrap();
        let msg = check(&fine, 24e9).unwrap_err().to_string();
        assert!(
            msg.contains("scene.wavelengths_nm") && msg.contains("30001 bands"),
            "{msg}"
        );
    }
}
