//! The `specmux` command line: parses, calls the library, prints. Errors are one line.

mod cli;

use clap::Parser;
use cli::{device_of, Cli, Command};
use specmux_controller::commands as controller;
use specmux_core::spectral::Library;
use specmux_core::Result;
use specmux_report::commands;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Print a command's text to stdout; a closed pipe (`specmux demo | head`) ends quietly.
fn emit(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if writeln!(out, "{}", text.trim_end_matches('\n')).is_err() {
        std::process::exit(0);
    }
}

/// Ctrl-C (or SIGTERM) asks the running command to stop at its next safe point; a second one
/// ends the process at once (the output sets' staging folders keep the final names clean).
fn install_interrupt_handler() {
    // The messages may meet a closed stderr (`… 2>&1 | head`): eprintln! would panic and take
    // the handler's thread, and every later Ctrl-C, with it.
    let say = |text: &str| {
        let _ = writeln!(std::io::stderr(), "{text}");
    };
    let handler = move || {
        if specmux_core::interrupt::requested() {
            say("specmux: interrupted again; stopping now");
            std::process::exit(130);
        }
        specmux_core::interrupt::request();
        say("specmux: stopping at the next safe point (Ctrl-C again to stop now)");
    };
    if let Err(e) = ctrlc::set_handler(handler) {
        eprintln!("specmux: warning: no Ctrl-C handler ({e}); Ctrl-C stops at once");
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(dir) = &cli.pattern_cache {
        // Before any thread starts; the commands read it (`PatternCache::from_env`).
        std::env::set_var(specmux_twin::pattern_cache::ENV, dir);
    }
    install_interrupt_handler();
    let done = library(cli.spectra.clone()).and_then(|lib| dispatch(cli.command, &lib));
    match done {
        Ok(text) => {
            emit(&text);
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("specmux: {e}");
            if specmux_core::interrupt::requested() {
                ExitCode::from(130)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// The spectral library `--spectra`, else `$SPECMUX_SPECTRA`, names (a folder that is there),
/// else the embedded one.
fn library(spectra: Option<PathBuf>) -> std::result::Result<Library, String> {
    let from = if spectra.is_some() {
        "--spectra"
    } else {
        "$SPECMUX_SPECTRA"
    };
    let lib = spectra
        .map(Library::new)
        .unwrap_or_else(Library::default_root);
    match lib.root().filter(|dir| !dir.is_dir()) {
        Some(dir) => Err(format!(
            "{from} = {}: no such folder (it names a spectral library: a copy of spectra/)",
            dir.display()
        )),
        None => Ok(lib),
    }
}

/// Refuse, before any work, an `--out` whose replacement would lose files: one holding the
/// command's inputs, or (for the commands that replace their folder whole) files no run wrote.
fn check_out(cmd: &Command) -> Result<()> {
    use specmux_io::output_set::check_target;
    let p = |s: &String| PathBuf::from(s);
    let (out, inputs): (&Path, Vec<PathBuf>) = match cmd {
        Command::Demo { scene, out, .. } => (out, vec![p(scene)]),
        Command::Simulate {
            experiment, out, ..
        }
        | Command::Bench {
            experiment, out, ..
        }
        | Command::Sweep {
            experiment, out, ..
        }
        | Command::Patterns {
            experiment, out, ..
        }
        | Command::Timing { experiment, out } => (out, vec![p(experiment)]),
        Command::SweepCrop {
            experiments, out, ..
        } => (out, experiments.iter().map(p).collect()),
        Command::Ptc {
            experiment, out, ..
        } => (out, experiment.iter().map(p).collect()),
        Command::Reconstruct {
            frame,
            experiment,
            calibration,
            truth,
            out,
            ..
        } => {
            let mut inputs = vec![frame.clone()];
            inputs.extend(
                experiment
                    .iter()
                    .map(p)
                    .chain(calibration.clone())
                    .chain(truth.clone()),
            );
            (out, inputs)
        }
        // A recording's folder is checked by the controller (its experiment outside, the folder
        // new or empty, or a simulated recording); design writes its files one by one.
        Command::Rehearse(_) | Command::Acquire { .. } | Command::Design { .. } => return Ok(()),
    };
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    check_target(out, &inputs)
}

fn dispatch(cmd: Command, lib: &Library) -> std::result::Result<String, String> {
    check_out(&cmd).map_err(|e| e.to_string())?;
    let done: Result<String> = match cmd {
        Command::Demo {
            scene,
            size,
            out,
            npy,
        } => commands::demo(&scene, size, &out, npy, lib),
        Command::Simulate {
            experiment,
            explain,
            out,
            npy,
        } => commands::simulate(&experiment, explain, &out, npy, lib),
        Command::Bench {
            experiment,
            out,
            repeats,
            size,
            device,
        } => commands::bench(&experiment, &out, repeats, size, device.map(device_of), lib),
        Command::SweepCrop {
            experiments,
            out,
            size,
            no_gap,
        } => commands::sweep_crop(&experiments, &out, size, no_gap, lib),
        Command::Sweep {
            experiment,
            vary,
            out,
            size,
        } => commands::sweep(&experiment, &vary, &out, size, lib),
        Command::Patterns {
            experiment,
            out,
            size,
            study,
        } => commands::patterns(&experiment, &out, size, study.as_deref(), lib),
        Command::Timing { experiment, out } => commands::timing(&experiment, &out, lib),
        Command::Ptc {
            experiment,
            size,
            emva,
            out,
        } => commands::ptc(experiment.as_deref(), size, emva, &out, lib),
        Command::Design { what } => what.run(lib),
        Command::Reconstruct {
            frame,
            experiment,
            calibration,
            truth,
            out,
            npy,
        } => {
            // A folder is a recording (`specmux acquire`/`rehearse`): its own experiment,
            // calibration and truths are used.
            if frame.is_dir() {
                if experiment.is_some() || calibration.is_some() || truth.is_some() || npy {
                    return Err(format!("{}: a recording brings its own experiment, calibration and truths; --experiment, --calibration, --truth and --npy are for one frame", frame.display()));
                }
                return specmux_controller::reconstruct::reconstruct_recording(&frame, &out, lib);
            }
            commands::reconstruct(
                &frame,
                experiment.as_deref(),
                calibration.as_deref(),
                truth.as_deref(),
                &out,
                npy,
                lib,
            )
        }
        Command::Rehearse(a) => return controller::rehearse(&a.into(), lib),
        Command::Acquire { run, backend, real } => {
            return controller::acquire(&backend, &run.into(), &real, lib)
        }
    };
    done.map_err(|e| e.to_string())
}
