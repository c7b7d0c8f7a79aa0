//! `[reconstruct] auto_table`: the rows of a `specmux bench` report (bench.json) measured on the
//! machine that reconstructs, as `method = "auto"`'s table — the crop-0.25 square-window rows
//! with the TV prior and no noise weights, the rows the committed tables hold, with each time
//! scaled to a 768² frame by the pixel count it was measured at.

use serde::Deserialize;
use specmux_core::auto::{at_reference, tabled, Entry};
use specmux_core::demux::WindowShape;
use specmux_core::error::{Error, Result};
use specmux_core::gap::Method;
use specmux_core::joint::Prior;
use std::path::Path;

/// The part of bench.json the table needs.
#[derive(Deserialize)]
struct Report {
    rows: Vec<Row>,
}

#[derive(Deserialize)]
struct Row {
    setting: Setting,
    psnr_db: f64,
    seconds: f64,
    /// Absent in reports written before rows carried their frame size.
    frame: Option<[usize; 2]>,
}

#[derive(Deserialize)]
struct Setting {
    method: Method,
    iterations: usize,
    crop: f64,
    window: WindowShape,
    prior: Prior,
    noise: String,
    /// Absent in reports written before the bench had reweighted TV rows.
    #[serde(default)]
    reweight_rounds: usize,
}

/// The entries of the bench report at `path` (`value` as the experiment `file` wrote it); every
/// error names the file, `reconstruct.auto_table` and the value.
pub fn load(path: &Path, value: &str, file: &str) -> Result<Vec<Entry>> {
    let refuse = |why: String| Error::config(file, "reconstruct.auto_table", value, &why);
    let text = std::fs::read_to_string(path)
        .map_err(|e| refuse(format!("cannot read {}: {e}", path.display())))?;
    let report: Report = serde_json::from_str(&text).map_err(|e| {
        refuse(format!(
            "{} is not a specmux bench report (bench.json): {e}",
            path.display()
        ))
    })?;
    let mut entries = Vec::new();
    // Joint rows the table took before the joint reweighted by default: plain TV, otherwise
    // as tabled (GAP's rule is exactly that).
    let mut plain_joint_rows = false;
    for (i, r) in report.rows.iter().enumerate() {
        let s = &r.setting;
        // The table's rule for method `m` on this row's other settings.
        let takes = |m| {
            let noise = s.noise != "off";
            let (it, rounds) = (s.iterations, s.reweight_rounds);
            tabled(m, it, s.crop, s.window, s.prior, noise, rounds)
        };
        plain_joint_rows |= s.method == Method::Joint && takes(Method::Gap);
        if !takes(s.method) {
            continue;
        }
        let Some([w, h]) = r.frame.filter(|[w, h]| w * h > 0) else {
            return Err(refuse(format!(
                "row {i} of {} has no frame size (a report of an older specmux): run specmux bench again",
                path.display()
            )));
        };
        if !(r.seconds.is_finite() && r.seconds > 0.0 && r.psnr_db.is_finite()) {
            return Err(refuse(format!(
                "row {i} of {} has time {} s and PSNR {} dB; both must be finite, the time > 0",
                path.display(),
                r.seconds,
                r.psnr_db
            )));
        }
        entries.push(Entry {
            method: s.method,
            iterations: s.iterations,
            seconds: at_reference(r.seconds, w * h),
            psnr_db: r.psnr_db,
        });
    }
    if plain_joint_rows && !entries.iter().any(|e| e.method == Method::Joint) {
        return Err(refuse(format!(
            "{}'s joint rows are plain TV, as specmux bench wrote them before the joint's defaults reweighted once (2026-11-28): run specmux bench again",
            path.display()
        )));
    }
    if entries.is_empty() {
        return Err(refuse(format!(
            "{} has no row at crop 0.25, square window, TV prior and no noise weights (the rows auto picks from)",
            path.display()
        )));
    }
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bench report of two usable rows at 384² (the joint's at its default reweighting), one
    /// plug-and-play row and one reweighted TV row (both left out; the rows without
    /// `reweight_rounds` are plain, as in older reports).
    const REPORT: &str = r#"{"schema_version": 1, "rows": [
        {"label": "gap 20 it", "setting": {"method": "gap", "iterations": 20, "crop": 0.25,
         "window": "square", "prior": "tv", "noise": "off"}, "psnr_db": 17.2, "seconds": 0.1,
         "frame": [384, 384]},
        {"label": "joint 40 it", "setting": {"method": "joint", "iterations": 40, "crop": 0.25,
         "window": "square", "prior": "tv", "noise": "off", "reweight_rounds": 1},
         "psnr_db": 22.9, "seconds": 0.5, "frame": [384, 384]},
        {"label": "pnp 80 it", "setting": {"method": "joint", "iterations": 80, "crop": 0.25,
         "window": "square", "prior": "pnp", "noise": "off"}, "psnr_db": 23.7, "seconds": 2.0,
         "frame": [384, 384]},
        {"label": "joint 40 it reweighted", "setting": {"method": "joint", "iterations": 40,
         "crop": 0.25, "window": "square", "prior": "tv", "noise": "off", "reweight_rounds": 3},
         "psnr_db": 24.9, "seconds": 0.5, "frame": [384, 384]}
    ]}"#;

    /// `text` as file `name` in a fresh scratch folder, and its guard (it removes it on drop).
    fn write(name: &str, text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::Builder::new()
            .prefix("specmux-auto-table-")
            .tempdir()
            .unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn usable_rows_become_entries_scaled_to_768() {
        let (_scratch, p) = write("bench.json", REPORT);
        let e = load(&p, "bench.json", "exp.toml").unwrap();
        assert_eq!(e.len(), 2);
        // 384² is a quarter of 768²: four times the time.
        assert_eq!((e[0].method, e[0].iterations), (Method::Gap, 20));
        assert!((e[0].seconds - 0.4).abs() < 1e-12 && (e[1].seconds - 2.0).abs() < 1e-12);
        assert_eq!(e[1].psnr_db, 22.9);
    }

    #[test]
    fn a_bad_report_is_refused_naming_the_file_the_key_and_the_value() {
        let old = REPORT.replace(r#""frame": [384, 384]"#, r#""x": 0"#);
        let none = REPORT.replace(r#""prior": "tv""#, r#""prior": "pnp""#);
        let nan = REPORT.replace(r#""seconds": 0.1"#, r#""seconds": -1"#);
        let plain = REPORT.replace(
            r#""noise": "off", "reweight_rounds": 1}"#,
            r#""noise": "off"}"#,
        );
        assert_ne!(plain, REPORT);
        for (name, text, why) in [
            ("old.json", old.as_str(), "no frame size"),
            ("plain.json", plain.as_str(), "joint rows are plain TV"),
            ("none.json", none.as_str(), "no row at crop 0.25"),
            ("neg.json", nan.as_str(), "time -1 s"),
            ("junk.json", "{", "not a specmux bench report"),
        ] {
            let (_scratch, p) = write(name, text);
            let e = load(&p, name, "exp.toml").unwrap_err().to_string();
            assert!(
                e.contains("exp.toml") && e.contains("reconstruct.auto_table") && e.contains(name),
                "{e}"
            );
            assert!(e.contains(why), "{e}");
        }
        let e = load(Path::new("/nonexistent/b.json"), "b.json", "exp.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot read") && e.contains("b.json"), "{e}");
    }
}
