//! The full rig's relay pair sums (scenes/full-rig.toml, 768², its six patterns), relay by
//! relay: the CPU's sums as the relay stage runs them (the pair loop below
//! `SLICED_FROM_BINS` passed bins, by slices above) and, built with `--features gpu` on a
//! machine with an adapter, the GPU's pair-sum kernel on every relay with its largest
//! difference from the CPU's sums (docs/gpu.md). Medians of REPEATS runs after one warm-up, s.
//!
//! `cargo bench --bench relay [--features gpu]` (SPECMUX_BENCH_REPEATS overrides REPEATS).

use specmux_core::reconstructor::ComputeDevice;
use specmux_core::spectral::Library;
use specmux_twin::device::OpenDevice;
use specmux_twin::experiment::Experiment;
use specmux_twin::optics::relay::{
    pair_summer_for, relative_difference, CpuPairSums, PairSummer, PairSums, PassedBin,
    SLICED_FROM_BINS,
};
use specmux_twin::rig::Rig;
use specmux_twin::scene::Materials;
use std::sync::{Arc, Mutex};
use std::time::Instant;

const REPEATS: usize = 5;

/// Keeps the bins of every relay it is asked to sum, and sums them on the CPU.
#[derive(Default)]
struct Recorder(Mutex<Vec<Vec<PassedBin>>>);

impl PairSummer for Recorder {
    fn pair_loop(&self, bins: &[PassedBin]) -> specmux_core::error::Result<PairSums> {
        CpuPairSums.pair_loop(bins)
    }
    fn pair_sums(&self, bins: &[PassedBin]) -> specmux_core::error::Result<PairSums> {
        self.0.lock().unwrap().push(bins.to_vec());
        CpuPairSums.pair_sums(bins)
    }
    fn device(&self) -> &'static str {
        "cpu"
    }
}

/// The passed bins of the full rig's six relays, fewest first.
fn full_rig_relays() -> Vec<Vec<PassedBin>> {
    let lib = Library::default_root();
    let materials = Materials::load(&lib).expect("spectra/ is readable");
    let exp = Experiment::load(std::path::Path::new("scenes/full-rig.toml")).expect("full rig");
    let rig = Rig::build(&exp, &lib, &materials).expect("full rig");
    let recorder = Arc::new(Recorder::default());
    let chain = rig.chain(&exp).expect("full-rig optics");
    let filter = chain
        .config()
        .fourier_filter
        .clone()
        .expect("a Fourier filter");
    let chain = chain.with_pair_summer(recorder.clone());
    let displays = chain.dither().expect("dithered patterns");
    chain.relay_filtered(&filter, &displays).expect("relays");
    let mut relays = std::mem::take(&mut *recorder.0.lock().unwrap());
    relays.sort_by_key(|b| b.len());
    relays
}

/// Median seconds of `f` over `repeats` runs after one warm-up, and its last result.
fn median<T>(repeats: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut last = f();
    let mut t: Vec<f64> = (0..repeats)
        .map(|_| {
            let s = Instant::now();
            last = f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], last)
}

fn main() {
    let repeats = std::env::var("SPECMUX_BENCH_REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(REPEATS);
    let gpu = OpenDevice::open(ComputeDevice::Gpu)
        .map_err(|e| println!("no GPU kernel: {e}"))
        .ok()
        .map(|d| pair_summer_for(&d));
    println!(
        "CPU threads: {}; median of {repeats} runs, s\n",
        rayon::current_num_threads()
    );
    println!("| passed bins | cells (CPU, GPU) | CPU (as the stage runs) | GPU kernel | kernel against the CPU (S0, S1) |");
    println!("| --- | --- | --- | --- | --- |");
    let (mut cpu_total, mut gpu_total, mut stage_on_gpu) = (0.0, 0.0, 0.0);
    for bins in full_rig_relays() {
        let (cpu_s, cpu) = median(repeats, || CpuPairSums.pair_sums(&bins).unwrap());
        let path = match bins.len() < SLICED_FROM_BINS {
            true => "pair loop",
            false => "slices",
        };
        cpu_total += cpu_s;
        let kernel = gpu.as_ref().map(|g| match g.pair_loop(&bins) {
            // A box of more cells than one buffer holds (lavapipe's 128 MiB: the two largest);
            // the stage sums such a relay by slices (it is past SLICED_FROM_BINS).
            Err(e) => {
                stage_on_gpu += cpu_s;
                ("—".into(), format!("refused: {e} | —"))
            }
            Ok(_) => {
                let (s, sums) = median(repeats, || g.pair_loop(&bins).unwrap());
                let e = relative_difference(&sums, &cpu);
                gpu_total += s;
                stage_on_gpu += if path == "pair loop" { s } else { cpu_s };
                let timed = format!("{s:.3} | {:.1e}, {:.1e}", e[0], e[1]);
                (sums.cells().to_string(), timed)
            }
        });
        let (cells, kernel) = kernel.unwrap_or(("—".into(), "— | —".into()));
        println!(
            "| {} | {}, {cells} | {cpu_s:.3} ({path}) | {kernel} |",
            bins.len(),
            cpu.cells(),
        );
    }
    let gpu_sum = gpu
        .as_ref()
        .map_or("—".into(), |_| format!("{gpu_total:.3}"));
    println!("| relays' sum | | {cpu_total:.3} | {gpu_sum} | |");
    if gpu.is_some() {
        println!("\n`device = \"gpu\"` (the kernel below {SLICED_FROM_BINS} bins, slices above): {stage_on_gpu:.3} s of sums");
    }
}
