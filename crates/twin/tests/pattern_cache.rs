//! The pattern cache through the forward pipeline: a second run of the same optical chain reads
//! the patterns bit for bit and runs none of the optical stages; any change of the chain is a
//! miss; a damaged file is refused naming it. Likewise for the calibration captures it keeps.

use specmux_core::calibration::CalibrationFrames;
use specmux_core::spectral::Library;
use specmux_twin::captures::WhiteTarget;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::{Pipeline, Simulated, StageTime};
use specmux_twin::pattern_cache::PatternCache;
use specmux_twin::rig::Rig;
use specmux_twin::run::{kept_calibration_frames, run_in};
use specmux_twin::scene::Materials;
use specmux_twin::sensor::Sensor;
use std::path::PathBuf;

const RIG: &str = "[rig.dmd]\nwidth = 48\nheight = 40\n[rig.fourier_filter]\n[rig.lens]\n";

/// A fresh folder under the system's temporary one, removed when dropped.
struct Folder(PathBuf);

impl Folder {
    fn new(name: &str) -> Folder {
        let dir = std::env::temp_dir().join(format!("specmux-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        Folder(dir)
    }
}

impl Drop for Folder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The 48 × 40 dead-leaves scene through `rig`, its patterns kept in `cache`.
fn pipeline(rig: &str, seed: u64, cache: &Folder) -> Pipeline {
    let toml = format!("[scene]\nsize = [48, 40]\nseed = {seed}\n{rig}");
    let exp = Experiment::from_toml(&toml, "t.toml").unwrap();
    let lib = Library::default_root();
    let materials = Materials::load(&lib).unwrap();
    let rig = Rig::build(&exp, &lib, &materials).unwrap();
    let cache = PatternCache::open(&cache.0).unwrap();
    Pipeline::build(&exp, &rig, &materials)
        .unwrap()
        .with_pattern_cache(Some(cache))
}

fn run(p: &Pipeline) -> (Simulated, Vec<String>) {
    let (sim, times) = p.run().unwrap();
    let names = times.into_iter().map(|t: StageTime| t.stage).collect();
    (sim, names)
}

fn files(dir: &Folder) -> Vec<PathBuf> {
    let mut f: Vec<PathBuf> = std::fs::read_dir(&dir.0)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    f.sort();
    f
}

#[test]
fn a_second_run_of_the_chain_reads_its_patterns_and_runs_no_optical_stage() {
    let dir = Folder::new("pattern-cache-hit");
    let first = pipeline(RIG, 1, &dir);
    assert!(
        first.explain().contains("pattern-cache"),
        "{}",
        first.explain()
    );
    let explain = first.explain();
    assert!(
        explain.contains("yet: the optical stages below run"),
        "{explain}"
    );
    let (a, stages) = run(&first);
    let explain = first.explain();
    assert!(explain.contains("s̃_k read from"), "{explain}");
    assert!(
        stages.contains(&"relay-fourier-filter".to_string()),
        "{stages:?}"
    );
    assert!(stages.contains(&"pattern-cache".to_string()), "{stages:?}");
    assert_eq!(files(&dir).len(), 1);
    // Another scene on the same rig: the chain is the same, so are the patterns.
    let (b, stages) = run(&pipeline(RIG, 2, &dir));
    for optical in [
        "dmd-dither",
        "relay-fourier-filter",
        "lens",
        "pixel-sampling",
    ] {
        assert!(!stages.contains(&optical.to_string()), "{stages:?}");
    }
    assert!(stages.contains(&"pattern-cache".to_string()), "{stages:?}");
    assert_eq!(a.patterns.data, b.patterns.data);
    assert_ne!(a.frame.data, b.frame.data, "the scenes differ");
    // The same scene again gives the first run's frame bit for bit.
    let (c, _) = run(&pipeline(RIG, 1, &dir));
    assert_eq!(a.frame.data, c.frame.data);
}

#[test]
fn a_changed_chain_misses_and_keeps_a_file_of_its_own() {
    let dir = Folder::new("pattern-cache-miss");
    let (a, _) = run(&pipeline(RIG, 1, &dir));
    let wider = RIG.replace(
        "[rig.fourier_filter]\n",
        "[rig.fourier_filter]\npinhole_radius_um = 30\n",
    );
    let (b, stages) = run(&pipeline(&wider, 1, &dir));
    assert!(
        stages.contains(&"relay-fourier-filter".to_string()),
        "{stages:?}"
    );
    assert_ne!(a.patterns.data, b.patterns.data);
    assert_eq!(files(&dir).len(), 2);
}

#[test]
fn a_damaged_file_is_refused_naming_it() {
    let dir = Folder::new("pattern-cache-damaged");
    let p = pipeline(RIG, 1, &dir);
    run(&p);
    let file = cut_short(&dir, 7);
    let e = p.run().err().expect("a damaged file is refused");
    refuses_naming(&e.to_string(), &file);
}

/// The folder's one file, its last `n` bytes cut off.
fn cut_short(dir: &Folder, n: usize) -> PathBuf {
    let file = files(dir).remove(0);
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() - n]).unwrap();
    file
}

/// `e` is one line that names `file` as a damaged cache file.
fn refuses_naming(e: &str, file: &std::path::Path) {
    assert!(e.contains(&file.display().to_string()), "{e}");
    assert!(e.contains("damaged pattern-cache file"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
}

#[test]
fn a_folder_that_cannot_be_made_is_refused_naming_the_variable_and_the_path() {
    let dir = Folder::new("pattern-cache-file");
    std::fs::create_dir_all(&dir.0).unwrap();
    let blocker = dir.0.join("a-file");
    std::fs::write(&blocker, b"x").unwrap();
    let e = PatternCache::open(blocker.join("sub"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("SPECMUX_PATTERN_CACHE"), "{e}");
    assert!(e.contains("a-file/sub"), "{e}");
    assert!(e.contains("cannot be created"), "{e}");
}

/// /proc/self is a folder no user may add files to (not even root, whom mode bits do not stop).
#[cfg(target_os = "linux")]
#[test]
fn a_folder_that_cannot_be_written_is_refused_before_any_stage_runs() {
    let e = PatternCache::open("/proc/self").unwrap_err().to_string();
    assert!(e.contains("SPECMUX_PATTERN_CACHE"), "{e}");
    assert!(
        e.contains("/proc/self") && e.contains("cannot be written"),
        "{e}"
    );
}

/// The calibration captures of the 48 × 40 rig with a camera (seed `seed`, `frames` exposures
/// averaged), kept in `cache` when given; with the names of the stages that ran.
fn captures(
    seed: u64,
    frames: usize,
    source: &str,
    cache: Option<&PatternCache>,
) -> (CalibrationFrames, Vec<String>) {
    try_captures(seed, frames, source, cache).unwrap()
}

fn try_captures(
    seed: u64,
    frames: usize,
    source: &str,
    cache: Option<&PatternCache>,
) -> specmux_core::Result<(CalibrationFrames, Vec<String>)> {
    let toml = format!(
        "[scene]\nsize = [48, 40]\n{RIG}[rig.sensor]\nseed = {seed}\n[calibration]\nframes = {frames}\nsource = \"{source}\"\n"
    );
    let exp = Experiment::from_toml(&toml, "t.toml").unwrap();
    let lib = Library::default_root();
    let materials = Materials::load(&lib).unwrap();
    let rig = Rig::build(&exp, &lib, &materials).unwrap();
    let (sim, _) = Pipeline::build(&exp, &rig, &materials)
        .unwrap()
        .with_pattern_cache(None)
        .run()
        .unwrap();
    let sensor = Sensor::new(exp.rig.sensor.as_ref().unwrap(), rig.width, rig.height).unwrap();
    let target = WhiteTarget {
        patterns: &sim.patterns,
        exposed_white: &sim.exposed_white,
        full_scale: sim.full_scale,
    };
    let mut times = Vec::new();
    let frames =
        kept_calibration_frames(&exp.calibration, &target, Some(&sensor), cache, &mut times)?;
    Ok((frames, times.into_iter().map(|t| t.stage).collect()))
}

fn open(dir: &Folder) -> PatternCache {
    PatternCache::open(&dir.0).unwrap()
}

/// Every value and label of two sets of calibration frames, bit for bit.
fn same(a: &CalibrationFrames, b: &CalibrationFrames) -> bool {
    let planes = |f: &CalibrationFrames| {
        [&f.dark, &f.flat]
            .map(|c| c.as_ref().map(|c| c.data.clone()))
            .to_vec()
    };
    planes(a) == planes(b)
        && a.patterns.data == b.patterns.data
        && (a.patterns_linear, a.frames_averaged, &a.source)
            == (b.patterns_linear, b.frames_averaged, &b.source)
}

#[test]
fn a_second_run_reads_the_captures_bit_for_bit_and_captures_nothing() {
    let dir = Folder::new("capture-cache-hit");
    let (uncached, stages) = captures(5, 4, "captures", None);
    assert_eq!(stages, ["calibration-captures"]);
    let (first, stages) = captures(5, 4, "captures", Some(&open(&dir)));
    assert_eq!(stages, ["calibration-captures", "calibration-cache"]);
    let kept = files(&dir);
    assert_eq!(kept.len(), 1);
    assert_eq!(kept[0].extension().unwrap(), "captures");
    let (second, stages) = captures(5, 4, "captures", Some(&open(&dir)));
    assert_eq!(stages, ["calibration-cache"]);
    assert!(same(&uncached, &first) && same(&first, &second));
    assert!(uncached.dark.is_some() && uncached.flat.is_some() && !uncached.patterns_linear);
}

#[test]
fn another_camera_seed_or_exposure_count_misses_and_keeps_a_file_of_its_own() {
    let dir = Folder::new("capture-cache-miss");
    let (a, _) = captures(5, 4, "captures", Some(&open(&dir)));
    let (b, stages) = captures(6, 4, "captures", Some(&open(&dir)));
    assert!(
        stages.contains(&"calibration-captures".to_string()),
        "{stages:?}"
    );
    assert_ne!(a.dark.unwrap().data, b.dark.unwrap().data);
    let (c, stages) = captures(5, 2, "captures", Some(&open(&dir)));
    assert!(
        stages.contains(&"calibration-captures".to_string()),
        "{stages:?}"
    );
    assert_eq!(c.frames_averaged, 2);
    assert_eq!(files(&dir).len(), 3);
}

#[test]
fn the_oracle_is_not_kept() {
    let dir = Folder::new("capture-cache-oracle");
    let (f, stages) = captures(5, 4, "oracle", Some(&open(&dir)));
    assert_eq!(stages, ["calibration-captures"]);
    assert!(f.patterns_linear);
    assert!(files(&dir).is_empty());
}

#[test]
fn a_damaged_capture_file_is_refused_naming_it() {
    let dir = Folder::new("capture-cache-damaged");
    captures(5, 4, "captures", Some(&open(&dir)));
    let file = cut_short(&dir, 3);
    let e = try_captures(5, 4, "captures", Some(&open(&dir))).expect_err("a damaged file");
    refuses_naming(&e.to_string(), &file);
}

#[test]
fn runs_sharing_a_memory_cache_image_and_capture_once_with_the_same_results() {
    let lib = Library::default_root();
    let cache = PatternCache::in_memory();
    let run = |seed: u64, cache: Option<&PatternCache>| {
        let toml = format!(
            "[scene]\nsize = [48, 40]\nseed = {seed}\n{RIG}[rig.sensor]\n[calibration]\nframes = 2\n"
        );
        let exp = Experiment::from_toml(&toml, "t.toml").unwrap();
        let (report, data) = run_in(&exp, &lib, cache).unwrap();
        let stages: Vec<String> = report.forward_stages.into_iter().map(|t| t.stage).collect();
        (stages, data.cube.data)
    };
    let (stages, first) = run(1, Some(&cache));
    assert!(
        stages.contains(&"relay-fourier-filter".to_string()),
        "{stages:?}"
    );
    // Another scene on the same rig: no optical stage, and the cube of a run that images and
    // captures afresh (so the kept captures are the right ones too).
    let (stages, second) = run(2, Some(&cache));
    assert!(
        !stages.contains(&"relay-fourier-filter".to_string()),
        "{stages:?}"
    );
    assert!(stages.contains(&"pattern-cache".to_string()), "{stages:?}");
    let (_, uncached) = run(2, None);
    assert_eq!(second, uncached);
    assert_ne!(first, second, "the scenes differ");
}

#[test]
fn a_memory_cache_reads_back_the_last_captures_of_the_rig() {
    let cache = PatternCache::in_memory();
    let (first, stages) = captures(5, 4, "captures", Some(&cache));
    assert_eq!(stages, ["calibration-captures", "calibration-cache"]);
    let (second, stages) = captures(5, 4, "captures", Some(&cache));
    assert_eq!(stages, ["calibration-cache"]);
    assert!(same(&first, &second));
    // Another camera takes the place of the first: one set is held.
    captures(6, 4, "captures", Some(&cache));
    let (_, stages) = captures(5, 4, "captures", Some(&cache));
    assert_eq!(stages, ["calibration-captures", "calibration-cache"]);
}
