//! Parameter sweeps: run one experiment over a grid of values of any of its keys
//! (`--vary rig.sensor.electrons_at_full_scale=10;100;1000`) and tabulate the error of every
//! run against the truth with its wall time. A run the program refuses (a singular crosstalk
//! matrix, say) stays in the table with its one-line reason.

use crate::progress;
use serde::Serialize;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::spectral::Library;
use specmux_twin::experiment::Experiment;
use specmux_twin::pattern_cache::PatternCache;
use specmux_twin::run::{self, Row};

/// One swept key and its values (TOML literals).
#[derive(Clone, Debug)]
pub struct Vary {
    pub key: String,
    pub values: Vec<toml::Value>,
}

impl Vary {
    /// Parse `dotted.key=v1;v2;…`, each value a TOML literal (a bare word is taken as a string).
    pub fn parse(arg: &str) -> Result<Vary> {
        let bad = |why: &str| Error::config("<command line>", "--vary", format!("\"{arg}\""), why);
        let (key, vals) = arg
            .split_once('=')
            .ok_or_else(|| bad("expected KEY=V1;V2;…"))?;
        let key = key.trim();
        if key.is_empty() || key.split('.').any(str::is_empty) {
            return Err(bad("the key must be a dotted path such as rig.sensor.bits"));
        }
        let values = vals
            .split(';')
            .map(|v| literal(v.trim()).map_err(|e| bad(&e)))
            .collect::<Result<Vec<_>>>()?;
        Ok(Vary {
            key: key.to_string(),
            values,
        })
    }
}

/// A TOML literal (`1e4`, `"none"`, `[0, 1e-4]`, `true`); a bare word becomes a string.
fn literal(v: &str) -> std::result::Result<toml::Value, String> {
    if v.is_empty() {
        return Err("an empty value".into());
    }
    let parsed = toml::from_str::<toml::Table>(&format!("v = {v}"))
        .ok()
        .and_then(|mut t| t.remove("v"));
    match parsed {
        Some(x) => Ok(x),
        None if v.chars().all(|c| c.is_alphanumeric() || "-_/".contains(c)) => {
            Ok(toml::Value::String(v.to_string()))
        }
        None if v.contains(',') && !v.starts_with('[') => Err(format!(
            "`{v}` is not a TOML value (values are separated by `;`, e.g. KEY=0.2;0.25)"
        )),
        None => Err(format!("`{v}` is not a TOML value")),
    }
}

/// Set `key` (dotted) in a TOML document, creating the tables on the way.
fn set(doc: &mut toml::Table, key: &str, value: toml::Value) {
    let mut parts: Vec<&str> = key.split('.').collect();
    let last = parts.pop().expect("a validated key has a part");
    let mut t = doc;
    for p in parts {
        let e = t
            .entry(p)
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if !e.is_table() {
            *e = toml::Value::Table(toml::Table::new());
        }
        t = e.as_table_mut().expect("made a table above");
    }
    t.insert(last.to_string(), value);
}

/// The experiment with the given (key, value) pairs applied, parsed and validated as a file
/// would be (an unknown key or a value out of range is refused with its name).
pub fn with_values(base: &Experiment, set_to: &[(String, toml::Value)]) -> Result<Experiment> {
    let mut doc = base.to_table()?;
    for (k, v) in set_to {
        set(&mut doc, k, v.clone());
    }
    let label: Vec<String> = set_to.iter().map(|(k, v)| format!("{k}={v}")).collect();
    Experiment::from_table(&doc, &format!("{} with {}", base.file, label.join(", ")))
}

/// Each key swept once, and none inside another swept key (`rig.sensor.bits` with
/// `rig.sensor`): the later one would overwrite the earlier's values, and the table would name
/// runs that did not happen.
fn check_distinct(vary: &[Vary]) -> Result<()> {
    let inside = |a: &str, b: &str| a == b || a.starts_with(&format!("{b}."));
    for (i, v) in vary.iter().enumerate() {
        if let Some(o) = vary[..i]
            .iter()
            .find(|o| inside(&v.key, &o.key) || inside(&o.key, &v.key))
        {
            let why = match v.key == o.key {
                true => format!(
                    "{} is swept twice; give all its values in one --vary",
                    v.key
                ),
                false => format!("{} and {} overlap: sweep one of them", o.key, v.key),
            };
            return Err(Error::config("<command line>", "--vary", &v.key, &why));
        }
    }
    Ok(())
}

/// Every combination of the swept values (the last key varies fastest).
pub fn grid(vary: &[Vary]) -> Vec<Vec<(String, toml::Value)>> {
    vary.iter().fold(vec![Vec::new()], |acc, v| {
        acc.iter()
            .flat_map(|point| {
                v.values.iter().map(move |x| {
                    let mut p = point.clone();
                    p.push((v.key.clone(), x.clone()));
                    p
                })
            })
            .collect()
    })
}

/// One run of the sweep: the values, then the error of the channels and of the cube.
#[derive(Clone, Debug, Serialize)]
pub struct SweepRow {
    pub values: Vec<String>,
    /// Mean PSNR of the reconstructed channels x̂ (after de-aliasing) against the true x.
    pub channels_psnr_db: Option<f64>,
    pub cube_psnr_db: Option<f64>,
    pub cube_ssim: Option<f64>,
    pub cube_sam_deg: Option<f64>,
    /// Smallest and largest carrier gain |ĝ|/½ over the channels (1 with ideal sinusoids).
    pub carrier_gain: Option<(f64, f64)>,
    /// Reconstruction of one frame (calibration, demultiplexing, crosstalk, de-aliasing, unmixing).
    pub seconds: Option<f64>,
    /// Why the run was refused, if it was.
    pub refused: Option<String>,
    /// The de-aliasing that ran, as its result row names it ("auto: joint (52 it)", "gap (20
    /// it)", "fourier"): the x̂ figure is its estimate.
    pub method: Option<String>,
    /// Where the calibration came from: "captures", or "oracle" (the simulator's exact
    /// patterns: no rig's figures; the table's note says ORACLE).
    pub calibration: Option<String>,
}

/// Run `base` at every point of the grid. The imaged patterns and calibration captures are kept
/// from point to point (in `$SPECMUX_PATTERN_CACHE`, else in memory), so a point that leaves the
/// rig as it was runs no optical stage and captures nothing again.
pub fn sweep(base: &Experiment, vary: &[Vary], lib: &Library) -> Result<Vec<SweepRow>> {
    check_distinct(vary)?;
    let cache = PatternCache::from_env()?.unwrap_or_else(PatternCache::in_memory);
    let mut rows = Vec::new();
    let points = grid(vary);
    let bar = progress::bar("sweep");
    bar.set_length(points.len() as u64);
    for point in &points {
        let values: Vec<String> = point.iter().map(|(_, v)| v.to_string()).collect();
        bar.set_message(values.join(", "));
        let exp = with_values(base, point)?;
        let row = match run::run_in(&exp, lib, Some(&cache)) {
            Err(e @ Error::Interrupted(_)) => return Err(e),
            Ok((rep, _)) => {
                let (x, cube) = (rep.row(Row::Dealiased), rep.row(Row::Cube));
                SweepRow {
                    values,
                    channels_psnr_db: Some(x.psnr_db),
                    cube_psnr_db: Some(cube.psnr_db),
                    cube_ssim: Some(cube.ssim),
                    cube_sam_deg: cube.sam_deg,
                    carrier_gain: rep
                        .channels
                        .iter()
                        .map(|c| c.carrier_gain)
                        .fold(None, |a, g| {
                            let (lo, hi) = a.unwrap_or((g, g));
                            Some((lo.min(g), hi.max(g)))
                        }),
                    seconds: Some(rep.reconstruction_seconds),
                    refused: None,
                    method: Some(x.stage.clone()),
                    calibration: Some(rep.calibration.source.clone()),
                }
            }
            Err(e) => SweepRow {
                values,
                channels_psnr_db: None,
                cube_psnr_db: None,
                cube_ssim: None,
                cube_sam_deg: None,
                carrier_gain: None,
                seconds: None,
                refused: Some(e.to_string()),
                method: None,
                calibration: None,
            },
        };
        rows.push(row);
        let done = format!("the sweep ({} of {} runs done)", rows.len(), points.len());
        progress::step(&bar, &done)?;
    }
    bar.finish_and_clear();
    Ok(rows)
}

/// The sweep as a Markdown table.
pub fn markdown(vary: &[Vary], rows: &[SweepRow]) -> String {
    let f = |v: Option<f64>, p: usize| v.map_or("—".to_string(), |x| format!("{x:.p$}"));
    let keys: Vec<&str> = vary.iter().map(|v| v.key.as_str()).collect();
    let mut s = format!(
        "| {} | method | carrier gain | x̂ PSNR dB | cube PSNR dB | cube SSIM | cube SAM ° | recon s | note |\n|{}---|---|---|---|---|---|---|---|\n",
        keys.join(" | "),
        "---|".repeat(keys.len())
    );
    for r in rows {
        let gain = r
            .carrier_gain
            .map_or("—".to_string(), |(lo, hi)| format!("{lo:.3}–{hi:.3}"));
        let oracle = r.calibration.as_deref() == Some(specmux_core::calibration::ORACLE);
        let note = match (&r.refused, oracle) {
            (Some(why), _) => why.as_str(),
            (None, true) => {
                "ORACLE calibration: the simulator's exact patterns, not a rig's figures"
            }
            (None, false) => "",
        };
        s += &format!(
            "| {} | {} | {gain} | {} | {} | {} | {} | {} | {note} |\n",
            r.values.join(" | "),
            r.method.as_deref().unwrap_or("—"),
            f(r.channels_psnr_db, 2),
            f(r.cube_psnr_db, 2),
            f(r.cube_ssim, 4),
            f(r.cube_sam_deg, 2),
            f(r.seconds, 3),
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_literals_and_words() {
        let v = Vary::parse("rig.sensor.electrons_at_full_scale=10;1e5").unwrap();
        assert_eq!(
            v.values,
            vec![toml::Value::Integer(10), toml::Value::Float(1e5)]
        );
        let v = Vary::parse("reconstruct.crosstalk=timing;none").unwrap();
        assert_eq!(v.values[1], toml::Value::String("none".into()));
        let v = Vary::parse("rig.timing.dmd.delays_s=[0, 1e-4]").unwrap();
        assert!(v.values[0].is_array());
        assert!(Vary::parse("nokey").is_err());
        assert!(Vary::parse("a..b=1").is_err());
        assert!(Vary::parse("a=1;{").is_err());
        // A comma list is not one value: the separator is named.
        let e = Vary::parse("reconstruct.crop=0.2,0.25").err().unwrap();
        assert!(e.to_string().contains("separated by `;`"), "{e}");
    }

    #[test]
    fn grid_is_the_cartesian_product() {
        let a = Vary::parse("a=1;2").unwrap();
        let b = Vary::parse("b=x;y;z").unwrap();
        let g = grid(&[a, b]);
        assert_eq!(g.len(), 6);
        assert_eq!(g[1][0].1, toml::Value::Integer(1));
        assert_eq!(g[1][1].1, toml::Value::String("y".into()));
    }

    #[test]
    fn a_key_swept_twice_or_inside_another_is_refused() {
        let v = |a: &str| Vary::parse(a).unwrap();
        assert!(check_distinct(&[v("a.b=1"), v("a.c=2"), v("a.bc=3")]).is_ok());
        let e = check_distinct(&[v("a.b=1;2"), v("c=1"), v("a.b=3")]).unwrap_err();
        assert!(e.to_string().contains("a.b is swept twice"), "{e}");
        let e = check_distinct(&[v("rig.sensor.bits=10"), v("rig.sensor={}")]).unwrap_err();
        assert!(
            e.to_string()
                .contains("rig.sensor.bits and rig.sensor overlap"),
            "{e}"
        );
    }

    #[test]
    fn values_are_applied_and_checked_like_a_file() {
        let base = Experiment::prototype();
        let e = with_values(
            &base,
            &[
                ("reconstruct.eta".into(), toml::Value::Float(50.0)),
                ("rig.sensor.bits".into(), toml::Value::Integer(10)),
            ],
        )
        .unwrap();
        assert_eq!(e.reconstruct.eta, 50.0);
        assert_eq!(e.rig.sensor.unwrap().bits, 10);
        let err = with_values(
            &base,
            &[("reconstruct.etaa".into(), toml::Value::Float(1.0))],
        )
        .unwrap_err();
        assert!(err.to_string().contains("etaa"), "{err}");
        let err = with_values(
            &base,
            &[("reconstruct.eta".into(), toml::Value::Float(-1.0))],
        )
        .unwrap_err();
        assert!(err.to_string().contains("reconstruct.eta"), "{err}");
        // A value of the wrong type: the sweep's label, without a line of the generated text.
        let err = with_values(&base, &[("scene.size".into(), toml::Value::Integer(16))])
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with(&format!(
                "{} with scene.size=16: `scene.size` = 16: invalid type",
                base.file
            )),
            "{err}"
        );
    }
}
