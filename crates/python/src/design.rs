//! The design tools: `design_filters` and `design_carriers` run `specmux design filters` and
//! `specmux design carriers` with the same options (keyword arguments, parsed by the CLI's own
//! option parser, so defaults and checks are the CLI's) and return what they wrote: the ranked
//! candidates with their scores (`report.json`), the TOML section and the printed text.

use crate::convert::{library, to_py, OutDir};
use crate::error::{err, interruptible};
use clap::{Args, FromArgMatches};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use serde_json::{json, Value};
use specmux_design::carriers::{self, CarrierArgs};
use specmux_design::filters::{self, FilterArgs};
use std::path::PathBuf;

/// Keyword arguments as a command line: `name=value` is `--name value` (`_` as
/// `-`), a list or tuple repeats the option, True is the bare flag, False and None are left out.
fn argv(options: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<String>> {
    let mut out = Vec::new();
    for (k, v) in options.into_iter().flat_map(|d| d.iter()) {
        let flag = format!("--{}", k.str()?.to_string().replace('_', "-"));
        if v.is_none() || v.is_instance_of::<pyo3::types::PyBool>() && !v.is_truthy()? {
            continue;
        }
        if v.is_instance_of::<pyo3::types::PyBool>() {
            out.push(flag);
        } else if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
            for item in v.try_iter()? {
                out.extend([flag.clone(), text(&item?)?]);
            }
        } else {
            out.extend([flag, text(&v)?]);
        }
    }
    Ok(out)
}

/// A value as the command line spells it: a path through `os.fspath`, anything else `str`.
fn text(v: &Bound<'_, PyAny>) -> PyResult<String> {
    let os = v.py().import("os")?;
    match os.call_method1("fspath", (v,)) {
        Ok(p) => Ok(p.str()?.to_string()),
        Err(_) => Ok(v.str()?.to_string()),
    }
}

/// The options of `command` parsed by its clap definition, writing into `out`; a clap error
/// becomes its first line.
fn parse<A: Args + FromArgMatches>(
    command: &'static str,
    mut args: Vec<String>,
    out: &OutDir,
) -> PyResult<A> {
    args.extend(["--out".into(), out.path.display().to_string()]);
    let cmd = A::augment_args(clap::Command::new(command).no_binary_name(true));
    let first_line = |e: clap::Error| {
        let text = e.render().to_string();
        let line = text.lines().next().unwrap_or_default();
        err(format!("{command}: {}", line.trim_start_matches("error: ")))
    };
    let m = cmd.try_get_matches_from(args).map_err(first_line)?;
    A::from_arg_matches(&m).map_err(first_line)
}

/// The JSON report a design wrote, without its provenance keys; and the provenance.
fn report(out: &OutDir) -> PyResult<(Value, Value)> {
    let mut doc: Value = serde_json::from_str(&out.read("report.json")?).map_err(err)?;
    let design = doc
        .as_object_mut()
        .and_then(|o| o.remove("design"))
        .ok_or_else(|| err("report.json: no `design` key"))?;
    Ok((design, doc))
}

/// Choose the wheel's filters from a catalogue: `specmux design filters` with its options as
/// keyword arguments (`catalog`, `choose`, `families`, `no_families`, `keep`, `electrons`,
/// `top`, `simulate`, `scenes`, `scenes_dir`, `size`, `experiment`; paths as on the command
/// line, relative to the working folder). `out`: keep the files there (default: a temporary
/// folder, removed). Generated family curves are written into the spectral library, so with
/// families `spectra=` must name a writable copy of `spectra/`.
///
/// Returns a dict: `ranked` (criterion → the best sets, each `value`, `filters`, `scores`),
/// `simulated` (the sets simulated on the scenes, each with its scores and per-scene
/// `outcomes`), `chosen` (the chosen set's label), `toml` (the `[rig.wheel]` section written),
/// `report` (the rest of report.json: catalogue, combinations, noise model, seconds), the
/// `provenance` every report carries, `text` (what the CLI prints) and `out`.
#[pyfunction]
#[pyo3(signature = (out = None, spectra = None, **options))]
pub fn design_filters<'py>(
    py: Python<'py>,
    out: Option<PathBuf>,
    spectra: Option<PathBuf>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let dir = OutDir::new(out, "design-filters");
    let a: FilterArgs = parse("design filters", argv(options)?, &dir)?;
    let lib = library(spectra);
    let text = interruptible(py, move || filters::run(&a, &lib))?.map_err(err)?;
    let (mut design, provenance) = report(&dir)?;
    let d = PyDict::new(py);
    let rest = design
        .as_object_mut()
        .ok_or_else(|| err("report.json: `design` is not a table"))?;
    let list = rest.remove("ranked").unwrap_or_default();
    d.set_item("ranked", ranked(py, &list)?)?;
    for key in ["simulated", "chosen"] {
        d.set_item(key, to_py(py, &rest.remove(key))?)?;
    }
    d.set_item("toml", dir.read("wheel.toml")?)?;
    finish(py, &d, design, provenance, text, &dir)?;
    Ok(d)
}

/// The report's `ranked`, `[[criterion, [[value, [filters], scores], …]], …]`, as a dict
/// `{criterion: [{"value", "filters", "scores"}, …]}` in the report's order.
fn ranked<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyDict>> {
    let bad =
        || err("report.json: `ranked` is not [[criterion, [[value, filters, scores], …]], …]");
    let out = PyDict::new(py);
    for entry in v.as_array().ok_or_else(bad)? {
        let (Some(name), Some(sets)) = (entry[0].as_str(), entry[1].as_array()) else {
            return Err(bad());
        };
        let sets: Vec<Value> = sets
            .iter()
            .map(|s| json!({"value": s[0], "filters": s[1], "scores": s[2]}))
            .collect();
        out.set_item(name, to_py(py, &sets)?)?;
    }
    Ok(out)
}

/// The keys every design returns: the rest of its report, its provenance, its text, its folder.
fn finish(
    py: Python<'_>,
    d: &Bound<'_, PyDict>,
    design: Value,
    provenance: Value,
    text: String,
    dir: &OutDir,
) -> PyResult<()> {
    d.set_item("report", to_py(py, &design)?)?;
    d.set_item("provenance", to_py(py, &provenance)?)?;
    d.set_item("text", dir.text(text))?;
    d.set_item("out", dir.kept())
}

/// Lay out the carriers: `specmux design carriers` with its options as keyword arguments
/// (`size`, `crop` (a list lets the design choose), `window`, `scenes`,
/// `scenes_dir`, `cube`, `guard`, `harmonic`, `restarts`, `candidates`, `coherent`,
/// `experiment`, `seed`; paths as on the command line). `out`: keep the files there (default: a
/// temporary folder, removed).
///
/// Returns a dict: `candidates` (the paper's layout, the diamond, then the designed ones, each
/// with its `layout` (bins, size, crop), `window`, `predicted` objective and leak, and its
/// simulated `ideal` (and `coherent`) outcomes per scene), `chosen` (index into `candidates`),
/// `toml` (the `[rig.carriers]` section written), `experiment_toml` (a runnable experiment
/// with it, or None when the scenes are files), `report` (design and simulation scenes, notes,
/// seconds), `provenance`, `text` and `out`.
#[pyfunction]
#[pyo3(signature = (out = None, spectra = None, **options))]
pub fn design_carriers<'py>(
    py: Python<'py>,
    out: Option<PathBuf>,
    spectra: Option<PathBuf>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let dir = OutDir::new(out, "design-carriers");
    let a: CarrierArgs = parse("design carriers", argv(options)?, &dir)?;
    let lib = library(spectra);
    let text = interruptible(py, move || carriers::run(&a, &lib))?.map_err(err)?;
    let (mut design, provenance) = report(&dir)?;
    let d = PyDict::new(py);
    let rest = design
        .as_object_mut()
        .ok_or_else(|| err("report.json: `design` is not a table"))?;
    for key in ["candidates", "chosen"] {
        d.set_item(key, to_py(py, &rest.remove(key))?)?;
    }
    d.set_item("toml", dir.read("carriers.toml")?)?;
    let experiment = dir.path.join("experiment.toml");
    d.set_item(
        "experiment_toml",
        experiment
            .is_file()
            .then(|| dir.read("experiment.toml"))
            .transpose()?,
    )?;
    finish(py, &d, design, provenance, text, &dir)?;
    Ok(d)
}
