//! Medians of the real-time path on the CPU and on the GPU, 768 × 768, the prototype on
//! dead-leaves and on shaded objects: the GPU FFT alone, demultiplexing, unmixing, and the
//! whole frame with and without reading the 31-band cube back; then the whole chain with 50
//! iterations of GAP and of GAP-TV and with 80 of the joint method (docs/gpu.md). Each figure is the median wall time of
//! REPEATS runs after WARMUP (GAP_REPEATS for the CPU's GAP rows, seconds each), the GPU ones
//! from submission to the finished work (and the host copy where one is named).
//!
//! `cargo bench -p specmux-gpu --bench realtime` (SPECMUX_BENCH_REPEATS overrides REPEATS;
//! SPECMUX_BENCH_SIZE the frames' side, e.g. 64 for a quick run that checks the bench works).

use specmux_core::reconstructor::Reconstructor;
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_gpu::demux::STAGES;
use specmux_gpu::fft::{Direction, GpuFft2};
use specmux_gpu::{wgpu, GpuContext, GpuReconstructor};
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::Pipeline;
use specmux_twin::rig::Rig;
use specmux_twin::run;
use specmux_twin::scene::Materials;
use std::time::Instant;

const WARMUP: usize = 5;
const REPEATS: usize = 50;
/// Repeats of the CPU's GAP rows (several seconds each on the project's machine).
const GAP_REPEATS: usize = 3;
/// The real-time path: no de-aliasing.
const FOURIER: &str = "[reconstruct.gap]\nmethod = \"fourier\"\n";

/// Median seconds of `f` over the repeats.
fn median(repeats: usize, f: impl FnMut()) -> f64 {
    median_after(WARMUP, repeats, f)
}

/// Median seconds of `f` over `repeats` runs after `warmup`.
fn median_after(warmup: usize, repeats: usize, mut f: impl FnMut()) -> f64 {
    for _ in 0..warmup {
        f();
    }
    let mut t: Vec<f64> = (0..repeats)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn row(scene: &str, what: &str, device: &str, s: f64) {
    println!("| {scene} | {what} | {device} | {:.3} |", s * 1e3);
}

/// The GPU 2-D FFT of one 768² complex plane, forward, alone.
fn fft_alone(ctx: &GpuContext, repeats: usize) -> f64 {
    let (w, h) = (768, 768);
    let buf = ctx.storage("fft bench", (w * h * 8) as u64);
    let fft = GpuFft2::new(ctx, &buf, w, h, 1).expect("768 = 4⁴·3");
    median(repeats, || {
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        fft.encode(&mut enc, &buf, Direction::Forward);
        ctx.queue.submit([enc.finish()]);
        ctx.wait().unwrap();
    })
}

/// The GPU path's parts: the frame's upload, demultiplexing with x̂ left on the GPU, and the
/// unmixing of that x̂ (its counters read back, the cube left on the GPU).
fn gpu_stages(ctx: &GpuContext, g: &GpuReconstructor, frame: &Cube, name: &str, repeats: usize) {
    let submit = |f: &dyn Fn(&mut wgpu::CommandEncoder)| {
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        f(&mut enc);
        ctx.queue.submit([enc.finish()]);
    };
    row(
        name,
        "upload frame",
        "GPU",
        median(repeats, || {
            g.demux.upload(ctx, frame).unwrap();
            submit(&|_| ());
            ctx.wait().unwrap();
        }),
    );
    row(
        name,
        "demultiplex, x̂ stays on GPU",
        "GPU",
        median(repeats, || {
            g.demux.upload(ctx, frame).unwrap();
            submit(&|enc| g.demux.encode(enc));
            ctx.wait().unwrap();
        }),
    );
    row(
        name,
        "unmix, x̂ and cube on GPU",
        "GPU",
        median(repeats, || {
            submit(&|enc| g.unmix.encode(enc));
            g.unmix.stats(ctx).unwrap();
        }),
    );
}

/// GPU time of each stage of one frame from timestamps written between them (None where the
/// adapter has no timestamps inside encoders): the five demultiplexing stages and the unmixing.
fn kernel_times(
    ctx: &GpuContext,
    g: &GpuReconstructor,
    frame: &Cube,
    repeats: usize,
) -> Option<Vec<f64>> {
    let need = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
    if !ctx.device.features().contains(need) {
        return None;
    }
    let n = STAGES as u32 + 2;
    let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
        label: None,
        ty: wgpu::QueryType::Timestamp,
        count: n,
    });
    let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: 8 * n as u64,
        usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = ctx.readback("timestamps", 8 * n as u64);
    g.demux.upload(ctx, frame).unwrap();
    let mut per_stage: Vec<Vec<f64>> = vec![Vec::new(); n as usize - 1];
    for _ in 0..WARMUP + repeats {
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        enc.write_timestamp(&set, 0);
        for s in 0..STAGES {
            g.demux.encode_stage(&mut enc, s);
            enc.write_timestamp(&set, s as u32 + 1);
        }
        g.unmix.encode(&mut enc);
        enc.write_timestamp(&set, n - 1);
        enc.resolve_query_set(&set, 0..n, &resolve, 0);
        enc.copy_buffer_to_buffer(&resolve, 0, &staging, 0, 8 * n as u64);
        ctx.queue.submit([enc.finish()]);
        let mut t = vec![0u64; n as usize];
        ctx.read_into(&staging, &mut t).unwrap();
        let period = ctx.queue.get_timestamp_period() as f64 * 1e-9;
        for (acc, w) in per_stage.iter_mut().zip(t.windows(2)) {
            acc.push(w[1].wrapping_sub(w[0]) as f64 * period);
        }
    }
    Some(
        per_stage
            .into_iter()
            .map(|mut v| {
                let mut v = v.split_off(WARMUP);
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            })
            .collect(),
    )
}

/// The simulated frame of an experiment and its reconstructor.
fn simulate(name: &str, toml: &str) -> (Cube, Reconstructor) {
    let lib = Library::default_root();
    let materials = Materials::load(&lib).expect("spectra/ is readable");
    let exp = Experiment::from_toml(toml, name).expect("a valid experiment");
    let rig = Rig::build(&exp, &lib, &materials).expect("rig");
    let (sim, _) = Pipeline::build(&exp, &rig, &materials)
        .unwrap()
        .run()
        .unwrap();
    let recon = run::reconstructor(&exp, &rig, &sim, None).unwrap();
    (sim.frame, recon)
}

/// The experiment's lines for `iterations` of `method` (gap, gap-tv or joint).
fn method_toml(method: &str, iterations: usize) -> String {
    let count = format!("iterations = {iterations}\n");
    match method {
        "joint" => format!("[reconstruct.gap]\nmethod = \"joint\"\n[reconstruct.joint]\n{count}"),
        _ => format!("[reconstruct.gap]\nmethod = \"{method}\"\n{count}"),
    }
}

/// The whole chain with `iterations` of `method` (gap, gap-tv or joint), CPU against GPU.
fn bench_gap(
    ctx: &GpuContext,
    name: &str,
    toml: &str,
    (method, iterations): (&str, usize),
    repeats: usize,
) {
    let what = format!("{method} {iterations} it");
    let toml = format!("{toml}{}", method_toml(method, iterations));
    let (frame, recon) = simulate(name, &toml);
    row(
        name,
        &format!("{what}: demultiplex + de-alias + unmix"),
        "CPU",
        median_after(1, GAP_REPEATS, || drop(recon.run(&frame, None).unwrap())),
    );
    let g = GpuReconstructor::new(ctx, &recon).unwrap();
    let mut gcube: Cube = g.output_cube();
    row(
        name,
        &format!("{what}: demultiplex + de-alias + unmix, cube stays on GPU"),
        "GPU",
        median(repeats, || drop(g.run_resident(ctx, &frame).unwrap())),
    );
    row(
        name,
        &format!("{what}: demultiplex + de-alias + unmix, cube read back"),
        "GPU",
        median(repeats, || {
            drop(g.run_into(ctx, &frame, &mut gcube).unwrap())
        }),
    );
    if let Some(t) = gap_kernels(ctx, &g, &frame, repeats) {
        row(
            name,
            &format!("{what}: de-alias kernels"),
            "GPU timestamps",
            t,
        );
    }
}

/// GPU time of the de-aliasing alone, from timestamps around it (None without timestamps).
fn gap_kernels(
    ctx: &GpuContext,
    g: &GpuReconstructor,
    frame: &Cube,
    repeats: usize,
) -> Option<f64> {
    let gap = g.gap.as_ref()?;
    let need = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
    if !ctx.device.features().contains(need) {
        return None;
    }
    let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
        label: None,
        ty: wgpu::QueryType::Timestamp,
        count: 2,
    });
    let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: 16,
        usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = ctx.readback("timestamps", 16);
    let period = ctx.queue.get_timestamp_period() as f64 * 1e-9;
    let t: Vec<f64> = (0..WARMUP + repeats)
        .map(|_| {
            g.demux.upload(ctx, frame).unwrap();
            let mut enc = ctx.device.create_command_encoder(&Default::default());
            g.demux.encode(&mut enc);
            enc.write_timestamp(&set, 0);
            gap.encode(&mut enc);
            enc.write_timestamp(&set, 1);
            enc.resolve_query_set(&set, 0..2, &resolve, 0);
            enc.copy_buffer_to_buffer(&resolve, 0, &staging, 0, 16);
            ctx.queue.submit([enc.finish()]);
            let mut ts = [0u64; 2];
            ctx.read_into(&staging, &mut ts).unwrap();
            ts[1].wrapping_sub(ts[0]) as f64 * period
        })
        .collect();
    let mut t = t[WARMUP..].to_vec();
    t.sort_by(f64::total_cmp);
    Some(t[t.len() / 2])
}

fn bench_scene(ctx: &GpuContext, name: &str, toml: &str, repeats: usize) {
    let (frame, recon) = simulate(name, &format!("{toml}{FOURIER}"));
    let xhat = recon.demultiplex(&frame).unwrap();
    let mut cube = recon.unmix(&xhat).unwrap().0;
    let stats = recon.unmixer.unmix_into(&xhat, &mut cube).unwrap();
    let mut x = xhat.clone();
    eprintln!(
        "{name}: {} of {} pixels constrained",
        stats.constrained_pixels, stats.pixels
    );
    row(
        name,
        "demultiplex",
        "CPU",
        median(repeats, || drop(recon.demultiplex(&frame).unwrap())),
    );
    row(
        name,
        "unmix",
        "CPU",
        median(repeats, || {
            recon.unmixer.unmix_into(&xhat, &mut cube).unwrap();
        }),
    );
    row(
        name,
        "demultiplex + unmix, cubes reused",
        "CPU",
        median(repeats, || {
            recon.demultiplex_into(&frame, &mut x).unwrap();
            recon.unmixer.unmix_into(&x, &mut cube).unwrap();
        }),
    );
    let g = GpuReconstructor::new(ctx, &recon).unwrap();
    let mut gcube: Cube = g.output_cube();
    gpu_stages(ctx, &g, &frame, name, repeats);
    if let Some(t) = kernel_times(ctx, &g, &frame, repeats) {
        let names = [
            "to complex",
            "forward FFT",
            "crop",
            "inverse FFT (6 planes)",
            "demodulate + mix",
            "unmix (both kernels)",
        ];
        for (what, s) in names.iter().zip(&t) {
            row(name, &format!("kernel: {what}"), "GPU timestamps", *s);
        }
        row(
            name,
            "kernels: demultiplex + unmix",
            "GPU timestamps",
            t.iter().sum(),
        );
    }
    row(
        name,
        "demultiplex, x̂ read back",
        "GPU",
        median(repeats, || drop(g.demultiplex(ctx, &frame).unwrap())),
    );
    row(
        name,
        "demultiplex + unmix, cube stays on GPU",
        "GPU",
        median(repeats, || {
            g.run_resident(ctx, &frame).unwrap();
        }),
    );
    row(
        name,
        "demultiplex + unmix, cube read back",
        "GPU",
        median(repeats, || {
            g.run_into(ctx, &frame, &mut gcube).unwrap();
        }),
    );
}

fn main() {
    let ctx = match GpuContext::new() {
        Ok(c) => c,
        Err(e) => {
            println!("no GPU: {e}; nothing to time");
            return;
        }
    };
    let repeats = std::env::var("SPECMUX_BENCH_REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(REPEATS);
    let size: usize = std::env::var("SPECMUX_BENCH_SIZE")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(768);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "adapter: {}; CPU threads: {threads}; frames of {size} × {size}; median of {repeats} runs, ms\n",
        ctx.adapter_name()
    );
    if ctx.is_software() {
        println!("(a software adapter: its GPU rows say nothing of a GPU's speed)\n");
    }
    println!("| scene | stage | device | median ms |\n| --- | --- | --- | --- |");
    row(
        "—",
        "FFT 768² complex, forward",
        "GPU",
        fft_alone(&ctx, repeats),
    );
    let dead = format!("[scene]\nsize = [{size}, {size}]\n");
    let shaded = format!("{dead}source = \"shaded-objects\"\nseed = 11\n");
    bench_scene(&ctx, "dead-leaves", &dead, repeats);
    bench_scene(&ctx, "shaded-objects", &shaded, repeats);
    for method in [("gap", 50), ("gap-tv", 50), ("joint", 80)] {
        bench_gap(&ctx, "dead-leaves", &dead, method, repeats);
        bench_gap(&ctx, "shaded-objects", &shaded, method, repeats);
    }
}
