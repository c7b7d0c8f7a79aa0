//! A folder of outputs that appears all at once or not at all. The files of a run are written
//! into a staging folder beside the target (`.NAME.staging-PID-N`); `commit` renames it into
//! place, so a failed, killed or concurrent run never leaves a mixed or partial set under the
//! final name. A run that fails drops its staging folder; one that was killed leaves it behind,
//! and the next run into the same place removes it and says so. A set carries a marker file
//! ([`MARKER`]), and a folder is replaced only when it is new, empty or such a set, and holds
//! none of the run's inputs ([`check_target`]): replacing a folder of raw frames or of other
//! files would delete them.

use specmux_core::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The outputs of one run, staged until `commit`.
pub struct OutputSet {
    target: PathBuf,
    staging: PathBuf,
    /// Leftovers of killed runs removed when the set began.
    notes: Vec<String>,
    committed: bool,
}

static SERIAL: AtomicU64 = AtomicU64::new(0);

/// The file that marks a folder as an output set, which the next run into it may replace whole.
pub const MARKER: &str = ".specmux-output";

/// Refuse `target` as an output folder when replacing it would lose files: it holds one of the
/// run's `inputs` ([`inputs_outside`]), or it exists and is a file, or a folder with files and
/// no [`MARKER`] (not a set a run wrote).
pub fn check_target(target: &Path, inputs: &[&Path]) -> Result<()> {
    inputs_outside(target, inputs)?;
    let refuse = |why: String| Err(Error::io(target, std::io::Error::other(why)));
    if target.is_file() {
        return refuse("is a file; --out names the folder the outputs are written to".into());
    }
    let names = entries(target);
    if names.is_empty() || names.iter().any(|n| n == MARKER) {
        return Ok(());
    }
    refuse(format!("the folder holds files that are no output of a specmux run ({}; a run's outputs carry {MARKER}), which writing the outputs (the folder is replaced whole) would delete: pass a new or empty folder", listed(&names)))
}

/// The names in folder `dir` (none where it is not a folder one can read).
pub fn entries(dir: &Path) -> Vec<String> {
    match std::fs::read_dir(dir) {
        Ok(it) => (it.flatten())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect(),
        Err(_) => Vec::new(),
    }
}

/// The first three `names`, and "…" for the rest, for a one-line message.
pub fn listed(names: &[String]) -> String {
    let shown: Vec<&str> = names.iter().take(3).map(String::as_str).collect();
    let more = if names.len() > 3 { ", …" } else { "" };
    format!("{}{more}", shown.join(", "))
}

/// Refuse an output folder `target` that holds one of the run's `inputs` (which need not exist:
/// a built-in scene's name is no path): writing the outputs replaces the folder.
pub fn inputs_outside(target: &Path, inputs: &[&Path]) -> Result<()> {
    // A folder that is not there holds nothing; an input that is not there is no file.
    let Ok(t) = target.canonicalize() else {
        return Ok(());
    };
    for input in inputs {
        let Ok(p) = input.canonicalize() else {
            continue;
        };
        if p.starts_with(&t) {
            let what = match p == t {
                true => "is this run's input".to_string(),
                false => format!("holds {}, an input of this run,", input.display()),
            };
            let why = format!("the output folder {what} which writing the outputs (the folder is replaced whole) would delete: pass another --out");
            return Err(Error::io(target, std::io::Error::other(why)));
        }
    }
    Ok(())
}

impl OutputSet {
    /// Stage a new set for `target` (created on commit), removing stale staging folders; refused
    /// where replacing `target` would lose files ([`check_target`], without inputs: a command
    /// checks its inputs before its work).
    pub fn begin(target: &Path) -> Result<OutputSet> {
        check_target(target, &[])?;
        let (parent, name) = split(target)?;
        std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let notes = remove_stale(&parent, &name)?;
        let serial = SERIAL.fetch_add(1, Ordering::Relaxed);
        let staging = parent.join(format!(".{name}.staging-{}-{serial}", std::process::id()));
        std::fs::create_dir(&staging).map_err(|e| {
            let why = format!(
                "cannot create the staging folder {} beside it: {e}",
                staging.display()
            );
            Error::io(target, std::io::Error::new(e.kind(), why))
        })?;
        let marker = staging.join(MARKER);
        let note =
            "an output set of specmux: the next run with this --out replaces the folder whole\n";
        std::fs::write(&marker, note).map_err(|e| Error::io(&marker, e))?;
        Ok(OutputSet {
            target: target.to_path_buf(),
            staging,
            notes,
            committed: false,
        })
    }

    /// Where a file of the set is written until the commit.
    pub fn path(&self, name: &str) -> PathBuf {
        self.staging.join(name)
    }

    /// The staging folder itself, for writers that take a folder.
    pub fn dir(&self) -> &Path {
        &self.staging
    }

    /// Put the set in place of `target` (replacing a previous set whole) and return what the
    /// set has to say: leftovers removed.
    pub fn commit(mut self) -> Result<Vec<String>> {
        let (parent, name) = split(&self.target)?;
        // Another run may commit between our two renames: then try again (a few times).
        for attempt in 0..8 {
            let old = parent.join(format!(".{name}.old-{}-{attempt}", std::process::id()));
            match std::fs::rename(&self.target, &old) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(Error::io(&self.target, e)),
            }
            let placed = std::fs::rename(&self.staging, &self.target);
            let _ = std::fs::remove_dir_all(&old);
            if placed.is_ok() {
                self.committed = true;
                return Ok(std::mem::take(&mut self.notes));
            }
        }
        Err(Error::io(
            &self.target,
            std::io::Error::other("another run kept replacing this folder; try again"),
        ))
    }
}

impl Drop for OutputSet {
    /// A set that was not committed (the run failed) leaves nothing behind.
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

/// The folder that holds `target` and the target's own name.
fn split(target: &Path) -> Result<(PathBuf, String)> {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| {
            Error::io(
                target,
                std::io::Error::other("an output folder needs a name (not `/`, `.` or `..`)"),
            )
        })?;
    let parent = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((parent, name))
}

/// Remove `.NAME.staging-PID-*` and `.NAME.old-PID-*` folders whose process is gone; one note each.
fn remove_stale(parent: &Path, name: &str) -> Result<Vec<String>> {
    let entries = std::fs::read_dir(parent).map_err(|e| Error::io(parent, e))?;
    let mut notes = Vec::new();
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = [".staging-", ".old-"]
            .iter()
            .find_map(|kind| file.strip_prefix(&format!(".{name}{kind}")))
            .and_then(|rest| rest.split('-').next()?.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !process_alive(pid) {
            std::fs::remove_dir_all(entry.path()).map_err(|e| Error::io(entry.path(), e))?;
            notes.push(format!(
                "removed {} left by an interrupted run (process {pid})",
                entry.path().display()
            ));
        }
    }
    Ok(notes)
}

/// Whether a process with this id is running (Linux: /proc/PID; elsewhere assumed alive, so
/// nothing is removed that might still be written).
fn process_alive(pid: u32) -> bool {
    if cfg!(target_os = "linux") {
        Path::new(&format!("/proc/{pid}")).exists()
    } else {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh scratch folder `specmux-outset-{name}-*`, removed when the returned guard drops.
    fn temp(name: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("specmux-outset-{name}-"))
            .tempdir()
            .unwrap()
    }

    #[test]
    fn nothing_appears_before_the_commit_and_everything_after() {
        let scratch = temp("commit");
        let d = scratch.path();
        let target = d.join("out");
        let set = OutputSet::begin(&target).unwrap();
        std::fs::write(set.path("a.txt"), "1").unwrap();
        assert!(!target.exists());
        set.commit().unwrap();
        assert_eq!(std::fs::read_to_string(target.join("a.txt")).unwrap(), "1");
        // A second set replaces the first whole: no file of the first survives.
        let set = OutputSet::begin(&target).unwrap();
        std::fs::write(set.path("b.txt"), "2").unwrap();
        set.commit().unwrap();
        assert!(!target.join("a.txt").exists() && target.join("b.txt").exists());
        assert_eq!(std::fs::read_dir(d).unwrap().count(), 1, "no staging left");
    }

    #[test]
    fn a_failed_run_leaves_nothing_and_a_dead_runs_leftovers_are_removed() {
        let scratch = temp("drop");
        let d = scratch.path();
        let target = d.join("out");
        {
            let set = OutputSet::begin(&target).unwrap();
            std::fs::write(set.path("half.exr"), "x").unwrap();
        }
        assert_eq!(std::fs::read_dir(d).unwrap().count(), 0);
        // A staging folder of a process that no longer exists (pid 0 is never a user process).
        std::fs::create_dir(d.join(".out.staging-0-0")).unwrap();
        let set = OutputSet::begin(&target).unwrap();
        assert!(
            set.notes.iter().any(|n| n.contains("interrupted")),
            "{:?}",
            set.notes
        );
        assert!(!d.join(".out.staging-0-0").exists());
    }

    #[test]
    fn a_folder_of_other_files_or_of_the_runs_inputs_is_not_replaced() {
        let scratch = temp("guard");
        let d = scratch.path();
        // Files no run wrote: refused, named, and left as they were.
        let other = d.join("lab");
        std::fs::create_dir(&other).unwrap();
        std::fs::write(other.join("important.txt"), "keep").unwrap();
        let e = OutputSet::begin(&other).err().unwrap().to_string();
        assert!(
            e.contains("important.txt") && e.contains("no output of a specmux run"),
            "{e}"
        );
        assert!(other.join("important.txt").exists());
        // A set a run wrote carries the marker and is replaced; an empty folder is taken.
        let target = d.join("out");
        OutputSet::begin(&target).unwrap().commit().unwrap();
        assert!(target.join(MARKER).exists());
        OutputSet::begin(&target).unwrap().commit().unwrap();
        std::fs::create_dir(d.join("empty")).unwrap();
        OutputSet::begin(&d.join("empty"))
            .unwrap()
            .commit()
            .unwrap();
        // An input inside the folder (even a set's): refused; a name that is no path is not one.
        let frame = target.join("frame.exr");
        std::fs::write(&frame, "x").unwrap();
        let e = check_target(&target, &[Path::new("dead-leaves"), &frame])
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("frame.exr") && e.contains("an input of this run"),
            "{e}"
        );
        assert!(check_target(&target, &[Path::new("dead-leaves")]).is_ok());
        assert!(check_target(&frame, &[])
            .err()
            .unwrap()
            .to_string()
            .contains("is a file"));
    }

    /// A place where no folder can be made (/proc takes none): the error names the output
    /// folder the user asked for first, then the staging folder that failed.
    #[cfg(target_os = "linux")]
    #[test]
    fn an_output_where_no_folder_can_be_made_is_named() {
        let err = OutputSet::begin(Path::new("/proc/specmux-out"))
            .err()
            .expect("/proc takes no new folder")
            .to_string();
        assert!(
            err.starts_with(
                "/proc/specmux-out: cannot create the staging folder /proc/.specmux-out.staging-"
            ),
            "{err}"
        );
    }
}
