//! Studies of the reconstruction on one simulated frame: the work–precision table (error of the
//! final cube against the median wall time of demultiplexing + de-aliasing + unmixing, for each
//! method and setting, with its Pareto front) and the paper's crop-size sweep.

use crate::plot;
use crate::plot::Series;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use serde::Serialize;
use specmux_core::auto;
use specmux_core::calibration::Calibration;
use specmux_core::demux::Demux;
use specmux_core::demux::WindowShape;
use specmux_core::demux::SUPER_GAUSSIAN_ORDER;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::gap::GapConfig;
use specmux_core::gap::Method;
use specmux_core::joint::{self, Prior, WeightRule};
use specmux_core::metrics;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_twin::device::{DeviceReconstructor, OpenDevice};
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::Pipeline;
use specmux_twin::pattern_cache::PatternCache;
use specmux_twin::rig::Rig;
use specmux_twin::run;
use specmux_twin::scene::Materials;
use std::path::Path;

/// One simulated frame with its truths and its calibration, simulated once and reconstructed
/// many times.
pub struct Simulated {
    pub exp: Experiment,
    pub rig: Rig,
    /// r: the scene's cube.
    pub truth: Cube,
    /// x: the true channels.
    pub channels: Cube,
    pub frame: Cube,
    /// The calibration the core built from the twin's captures.
    pub calibration: Calibration,
    /// `[compute] device`, as the forward model opened it.
    pub device: OpenDevice,
}

/// Run the experiment's forward model and its calibration captures once.
pub fn simulate(exp: &Experiment, lib: &Library) -> Result<Simulated> {
    let materials = Materials::load(lib)?;
    let rig = Rig::build(exp, lib, &materials)?;
    let cache = PatternCache::from_env()?;
    let pipeline = Pipeline::build(exp, &rig, &materials)?.with_pattern_cache(cache.clone());
    let (sim, _) = pipeline.run()?;
    let calibration = run::calibration(exp, &rig, &sim, cache.as_ref())?;
    Ok(Simulated {
        exp: exp.clone(),
        truth: sim.scene.cube,
        channels: sim.channels,
        frame: sim.frame,
        calibration,
        rig,
        device: pipeline.device().clone(),
    })
}

/// One reconstruction setting of the work–precision study.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Setting {
    pub method: Method,
    /// GAP iterations (0 for `fourier`).
    pub iterations: usize,
    pub crop: f64,
    pub window: WindowShape,
    /// The joint method's prior (TV or plug-and-play); TV for the other methods.
    pub prior: Prior,
    /// The joint method's use of the camera's noise model; off for the other methods.
    pub noise: NoiseAware,
    /// Reweighted TV: times the joint method's TV weights are refreshed (by default as
    /// [`joint::default_rounds`] says: once with TV at a fixed λ; 0 for the other methods).
    /// `auto` never picks rows at other counts (docs/joint.md, "Reweighted TV").
    pub reweight_rounds: usize,
}

/// How the joint method uses the camera's noise model (`[reconstruct.joint]`): the bench's
/// noise-aware rows, on experiments with a `[rig.sensor]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseAware {
    /// Unweighted data term, λ from `tv_weight`.
    #[default]
    Off,
    /// Data term weighted by the noise model (`noise_weights = true`).
    Weighted,
    /// Weighted, and λ by the discrepancy principle (`weight_rule = "discrepancy"`).
    Discrepancy,
}

impl Setting {
    /// `method` at `iterations` with the bench's defaults: crop 0.25, square window, the TV
    /// prior, no noise model, plain TV (the other settings vary one of these by struct update).
    pub fn new(method: Method, iterations: usize) -> Setting {
        Setting {
            method,
            iterations,
            crop: 0.25,
            window: WindowShape::Square,
            prior: Prior::Tv,
            noise: NoiseAware::Off,
            reweight_rounds: 0,
        }
    }

    /// True for a joint row whose TV weights are refreshed other than by default (the bench's
    /// reweighted series).
    pub fn more_reweighting(&self) -> bool {
        let default = default_rounds(self.iterations, self.prior, self.noise);
        self.method == Method::Joint && self.reweight_rounds != default
    }

    /// Short label, e.g. `gap-tv 20 it, crop 0.25 square`.
    pub fn label(&self) -> String {
        let m = match self.method {
            Method::Fourier => "fourier".to_string(),
            Method::Gap => format!("gap {} it", self.iterations),
            Method::GapTv => format!("gap-tv {} it", self.iterations),
            Method::Joint if self.prior == Prior::Pnp => format!("pnp {} it", self.iterations),
            Method::Joint if self.more_reweighting() => {
                let (n, r) = (self.iterations, self.reweight_rounds);
                format!("joint {n} it reweighted ×{r}")
            }
            Method::Joint => match self.noise {
                NoiseAware::Off => format!("joint {} it", self.iterations),
                NoiseAware::Weighted => format!("joint {} it noise-weighted", self.iterations),
                NoiseAware::Discrepancy => format!("joint {} it discrepancy λ", self.iterations),
            },
            Method::Auto => "auto".to_string(),
        };
        let w = match self.window {
            WindowShape::Square => "square",
            WindowShape::Circular => "circular",
            WindowShape::SuperGaussian => "super-gaussian",
        };
        format!("{m}, crop {} {w}", self.crop)
    }
}

/// The default grid: Fourier at three crops × three window shapes, GAP and GAP-TV at
/// 1, 2, 5, 10, 20, 50 iterations (crop 0.25, square), both at 20 iterations with the other
/// two windows, and the joint reconstruction with its TV prior at 10, 15, 20, 30, 40, 80
/// iterations, its plug-and-play prior at 10, 20, 40, 80 and reweighted TV at 20, 40, 80.
pub fn default_grid() -> Vec<Setting> {
    let shapes = [
        WindowShape::Square,
        WindowShape::Circular,
        WindowShape::SuperGaussian,
    ];
    let mut g = Vec::new();
    for crop in [0.15, 0.2, 0.25] {
        for window in shapes {
            g.push(Setting {
                crop,
                window,
                ..Setting::new(Method::Fourier, 0)
            });
        }
    }
    for method in [Method::Gap, Method::GapTv] {
        for iterations in [1, 2, 5, 10, 20, 50] {
            g.push(Setting::new(method, iterations));
        }
        for window in &shapes[1..] {
            g.push(Setting {
                window: *window,
                ..Setting::new(method, 20)
            });
        }
    }
    // TV is what `auto` picks near the default budget: 15 and 30 iterations refine it there.
    for (prior, counts) in [
        (Prior::Tv, &[10, 15, 20, 30, 40, 80][..]),
        (Prior::Pnp, &[10, 20, 40, 80]),
    ] {
        for &iterations in counts {
            g.push(joint_setting(iterations, prior, NoiseAware::Off));
        }
    }
    for iterations in [20, 40, 80] {
        g.push(Setting {
            reweight_rounds: REWEIGHT_ROUNDS,
            ..joint_setting(iterations, Prior::Tv, NoiseAware::Off)
        });
    }
    g
}

/// The bench's reweighted TV rows refresh the weights this often (`reweight_rounds`, the
/// count docs/joint.md measured at 40 iterations).
pub const REWEIGHT_ROUNDS: usize = 3;

/// Joint TV iteration counts a hardware GPU adds to the grid: at well under 1 ms an iteration
/// (docs/gpu.md) its `auto` table reaches past the CPU's 80.
pub const GPU_JOINT_ITERATIONS: [usize; 3] = [160, 320, 640];

/// The grid for `sim` on `device`: the default grid (without GAP's rows where its wavelet
/// cannot split the frame, [`gap_left_out`]); on a hardware GPU the joint method at
/// [`GPU_JOINT_ITERATIONS`] too; and where the rig has a camera (a noise model) the joint
/// method's noise-aware rows — weighted, and with the discrepancy λ — at 20, 40, 80 it.
pub fn grid_for(sim: &Simulated, device: &OpenDevice) -> Vec<Setting> {
    let mut g = default_grid();
    if gap_left_out(sim).is_some() {
        g.retain(|s| s.method != Method::Gap);
    }
    if device.is_hardware_gpu() {
        for iterations in GPU_JOINT_ITERATIONS {
            g.push(joint_setting(iterations, Prior::Tv, NoiseAware::Off));
        }
    }
    if sim.rig.design().noise.is_some() {
        for noise in [NoiseAware::Weighted, NoiseAware::Discrepancy] {
            for iterations in [20, 40, 80] {
                g.push(joint_setting(iterations, Prior::Tv, noise));
            }
        }
    }
    g
}

/// Why the bench leaves GAP's rows out for `sim`: its wavelet cannot split the frame's sides
/// (the other methods take any side). None where it can.
pub fn gap_left_out(sim: &Simulated) -> Option<String> {
    let (w, h) = (sim.frame.width, sim.frame.height);
    let gap = &sim.exp.reconstruct.gap;
    gap.wavelet_for(w, h, &sim.exp.file)
        .err()
        .map(|e| format!("GAP's rows left out (the other methods take any side): {e}"))
}

/// The joint method with `prior` and `noise` (crop 0.25, square window), reweighted as by
/// default.
fn joint_setting(iterations: usize, prior: Prior, noise: NoiseAware) -> Setting {
    Setting {
        prior,
        noise,
        reweight_rounds: default_rounds(iterations, prior, noise),
        ..Setting::new(Method::Joint, iterations)
    }
}

/// The reweighting rounds of a joint run with `reweight_rounds` unset and `noise`'s λ rule
/// ([`joint::default_rounds`]).
fn default_rounds(iterations: usize, prior: Prior, noise: NoiseAware) -> usize {
    let weight_rule = match noise {
        NoiseAware::Discrepancy => WeightRule::Discrepancy,
        _ => WeightRule::Fixed,
    };
    joint::default_rounds(iterations, prior, weight_rule)
}

/// One row of the work–precision table.
#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    pub label: String,
    pub setting: Setting,
    /// Where it ran: "cpu" or "gpu" (`OpenDevice::describe` names the adapter).
    pub device: String,
    /// Final cube r̂ against the true cube.
    pub psnr_db: f64,
    pub ssim: f64,
    pub sam_deg: Option<f64>,
    /// The channel estimate after de-aliasing (x̂ for `fourier`) against the true channels.
    pub x_psnr_db: f64,
    /// Median wall time of demultiplex + de-alias + unmix over the repeats.
    pub seconds: f64,
    /// Every repeat's wall time, in run order.
    pub seconds_all: Vec<f64>,
    /// Median wall time of each stage alone: demultiplex, de-alias, unmix (NaN, null in JSON,
    /// on the GPU, which runs them in one submission).
    pub stage_seconds: [f64; 3],
    /// On the Pareto front of (seconds, psnr_db).
    pub pareto: bool,
    /// The frame [width, height] it was timed on (`[reconstruct] auto_table` scales the time
    /// by the pixel count).
    pub frame: [usize; 2],
    /// Where the calibration came from: "captures" (what a rig records) or "oracle" (the
    /// simulator's exact patterns: no rig's figures; the table marks the row ORACLE).
    pub calibration: String,
}

/// Median of a non-empty slice (mean of the middle two for an even count).
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Indices of the non-dominated points of (cost, value) — less cost and more value are better;
/// a point is dominated when another has cost ≤ and value ≥ with one of them strict. Returned in
/// order of increasing cost (so value increases along them too). Exact duplicates both stay.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    // By cost, then by value descending: a point is on the front iff its value beats every
    // value seen at a lower (or equal, earlier-sorted) cost.
    idx.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[b].1.total_cmp(&points[a].1))
    });
    let mut front: Vec<usize> = Vec::new();
    for i in idx {
        match front.last() {
            Some(&l) if points[l] == points[i] => front.push(i),
            Some(&l) if points[i].1 <= points[l].1 => {}
            _ => front.push(i),
        }
    }
    front
}

/// The reconstructor of `sim`'s rig for one setting.
fn reconstructor(sim: &Simulated, s: &Setting) -> Result<Reconstructor> {
    let mut exp = sim.exp.clone();
    exp.reconstruct.crop = s.crop;
    exp.reconstruct.window = s.window;
    exp.reconstruct.gap.method = s.method;
    match s.method {
        Method::Fourier => {}
        Method::Joint => {
            exp.reconstruct.joint.iterations = s.iterations;
            exp.reconstruct.joint.prior = s.prior;
            exp.reconstruct.joint.reweight_rounds = Some(s.reweight_rounds);
            exp.reconstruct.joint.noise_weights = s.noise != NoiseAware::Off;
            if s.noise == NoiseAware::Discrepancy {
                exp.reconstruct.joint.weight_rule = WeightRule::Discrepancy;
            }
        }
        _ => exp.reconstruct.gap.iterations = s.iterations,
    }
    exp.validate()?;
    Reconstructor::new(
        &exp.reconstruct,
        &sim.rig.design(),
        &sim.calibration,
        &exp.file,
    )
}

/// Reconstruct `sim`'s frame with every setting `repeats` times (the repeats interleaved over
/// the settings, so that a change of machine load spreads over all of them) and measure it.
pub fn work_precision(sim: &Simulated, grid: &[Setting], repeats: usize) -> Result<Vec<BenchRow>> {
    work_precision_on(&OpenDevice::cpu(), sim, grid, repeats)
}

/// `work_precision` on `device`: each setting that has a GPU kernel runs there.
pub fn work_precision_on(
    device: &OpenDevice,
    sim: &Simulated,
    grid: &[Setting],
    repeats: usize,
) -> Result<Vec<BenchRow>> {
    if repeats == 0 {
        return Err(Error::config(
            "<command line>",
            "--repeats",
            0,
            "must be ≥ 1",
        ));
    }
    let runners = grid
        .iter()
        .map(|s| DeviceReconstructor::new(device, reconstructor(sim, s)?))
        .collect::<Result<Vec<_>>>()?;
    let mut times = vec![Vec::with_capacity(repeats); grid.len()];
    let mut stages = vec![[(); 3].map(|_| Vec::with_capacity(repeats)); grid.len()];
    let mut outputs: Vec<Option<(Cube, Cube)>> = vec![None; grid.len()];
    let bar = crate::progress::bar("work–precision runs");
    bar.set_length((repeats * grid.len()) as u64);
    for _ in 0..repeats {
        for (k, r) in runners.iter().enumerate() {
            crate::progress::step(&bar, "the work–precision runs")?;
            // Timed from the frame in host memory to the cube in host memory.
            let run = r.run(&sim.frame, outputs[k].is_none())?;
            times[k].push(run.seconds);
            for (v, d) in stages[k].iter_mut().zip(run.stage_seconds) {
                v.push(d);
            }
            if let Some(x) = run.dealiased {
                outputs[k] = Some((x, run.cube));
            }
        }
    }
    bar.finish_and_clear();
    let mut rows = Vec::with_capacity(grid.len());
    let devices = runners.iter().map(DeviceReconstructor::device);
    for ((((s, t), st), out), device) in
        grid.iter().zip(times).zip(stages).zip(outputs).zip(devices)
    {
        let (x, cube) = out.expect("repeats ≥ 1 ran every setting");
        let m = metrics::compare(&sim.truth, &cube)?;
        let mx = metrics::compare(&sim.channels, &x)?;
        rows.push(BenchRow {
            label: s.label(),
            setting: *s,
            device: device.to_string(),
            psnr_db: m.psnr_db,
            ssim: m.ssim,
            sam_deg: m.sam_deg,
            x_psnr_db: mx.psnr_db,
            seconds: median(&t),
            seconds_all: t,
            stage_seconds: st.map(|v| median(&v)),
            pareto: false,
            frame: [sim.frame.width, sim.frame.height],
            calibration: sim.calibration.source.clone(),
        });
    }
    let pts: Vec<(f64, f64)> = rows.iter().map(|r| (r.seconds, r.psnr_db)).collect();
    for i in pareto_front(&pts) {
        rows[i].pareto = true;
    }
    Ok(rows)
}

/// The work–precision table as Markdown (also readable as text).
pub fn work_precision_markdown(rows: &[BenchRow]) -> String {
    let mut s = String::from(
        "| setting | device | r̂ PSNR dB | SSIM | SAM ° | x PSNR dB | median s | demux / de-alias / unmix s | Pareto |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for r in rows {
        let stages = match r.stage_seconds.iter().all(|t| t.is_finite()) {
            true => r.stage_seconds.map(|t| format!("{t:.3}")).join(" / "),
            false => "– (one submission)".to_string(),
        };
        let oracle = if r.calibration == specmux_core::calibration::ORACLE {
            " (ORACLE calibration)"
        } else {
            ""
        };
        s += &format!(
            "| {}{oracle} | {} | {:.2} | {:.4} | {} | {:.2} | {:.4} | {stages} | {} |\n",
            r.label,
            r.device,
            r.psnr_db,
            r.ssim,
            metrics::show(r.sam_deg, 2),
            r.x_psnr_db,
            r.seconds,
            if r.pareto { "●" } else { "" }
        );
    }
    s
}

/// What `method = "auto"` would pick from these very measurements at the default budget of a
/// frame of `pixels` (the committed table is a copy of such rows): the plot rings it, the table
/// names it.
pub fn auto_pick(rows: &[BenchRow], pixels: usize) -> Option<auto::Choice> {
    let entries: Vec<auto::Entry> = rows
        .iter()
        .filter(|r| r.seconds > 0.0 && r.seconds.is_finite() && r.psnr_db.is_finite())
        .filter(|r| {
            let s = &r.setting;
            let noise_weighted = s.noise != NoiseAware::Off;
            auto::tabled(
                s.method,
                s.iterations,
                s.crop,
                s.window,
                s.prior,
                noise_weighted,
                s.reweight_rounds,
            )
        })
        .map(|r| auto::Entry {
            method: r.setting.method,
            iterations: r.setting.iterations,
            seconds: auto::at_reference(r.seconds, pixels),
            psnr_db: r.psnr_db,
        })
        .collect();
    let table = auto::Table {
        device: "this run",
        scene: "this run's scene",
        entries: &entries,
    };
    auto::pick_from(table, auto::default_budget(pixels), pixels)
}

/// Final-cube PSNR against median run time, log time axis (ln t drawn linearly, ticked at 1, 2
/// and 5 × 10ⁿ s, so that every decade gets labels), one colour per method, the Pareto
/// front as a line through its points, each labelled with its setting, and `pick`, the setting
/// that `method = "auto"` picks from these rows for a frame of `pixels` at the default budget
/// ([`auto_pick`]), ringed.
pub fn work_precision_plot(
    path: &Path,
    title: &str,
    rows: &[BenchRow],
    pixels: usize,
    pick: Option<&auto::Choice>,
) -> Result<()> {
    let ok: Vec<&BenchRow> = rows
        .iter()
        .filter(|r| r.seconds > 0.0 && r.seconds.is_finite() && r.psnr_db.is_finite())
        .collect();
    if ok.is_empty() {
        return Err(Error::Image {
            path: path.to_path_buf(),
            msg: "nothing finite to plot".into(),
        });
    }
    let (mut t0, mut t1, mut p0, mut p1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for r in &ok {
        (t0, t1) = (t0.min(r.seconds), t1.max(r.seconds));
        (p0, p1) = (p0.min(r.psnr_db), p1.max(r.psnr_db));
    }
    let pad = 0.05 * (p1 - p0).max(0.1);
    // The time axis, with room for the labels right of the slowest point.
    let (x0, x1) = (t0 / 1.3, t1 * 2.5);
    plot::render_png(path, (1000, 640), |root| {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(LnTimeAxis::new(x0, x1), (p0 - pad)..(p1 + pad))
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_label_formatter(&|v| seconds_label(v.exp()))
            .x_desc("median wall time of demultiplex + de-alias/joint + unmix, s (log)")
            .y_desc("final cube PSNR, dB")
            .draw()
            .map_err(|x| e(&x))?;
        let (tv, pnp, off) = (Prior::Tv, Prior::Pnp, NoiseAware::Off);
        // The reweighted series' legend names its count.
        const _: () = assert!(REWEIGHT_ROUNDS == 3);
        // (colour, method, prior, noise, reweighted, legend)
        for (c, method, prior, noise, reweighted, name) in [
            (
                0,
                Method::Fourier,
                tv,
                off,
                false,
                "fourier (crops, windows)",
            ),
            (1, Method::Gap, tv, off, false, "gap"),
            (2, Method::GapTv, tv, off, false, "gap-tv"),
            (
                3,
                Method::Joint,
                tv,
                off,
                false,
                "joint (PDHG, vectorial TV; by default reweighted once)",
            ),
            (
                4,
                Method::Joint,
                pnp,
                off,
                false,
                "joint plug-and-play (ADMM, guided smoother)",
            ),
            (
                5,
                Method::Joint,
                tv,
                NoiseAware::Weighted,
                false,
                "joint, noise-weighted",
            ),
            (
                6,
                Method::Joint,
                tv,
                NoiseAware::Discrepancy,
                false,
                "joint, noise-weighted, discrepancy λ",
            ),
            (
                7,
                Method::Joint,
                tv,
                off,
                true,
                "joint, reweighted TV ×3 (auto skips it)",
            ),
        ] {
            let color = Palette99::pick(c).to_rgba();
            let of_method: Vec<&&BenchRow> = ok
                .iter()
                .filter(|r| {
                    let s = &r.setting;
                    let series = (method, prior, noise, reweighted);
                    (s.method, s.prior, s.noise, s.more_reweighting()) == series
                })
                .collect();
            if of_method.is_empty() {
                continue;
            }
            let pts: Vec<(f64, f64)> = of_method
                .iter()
                .map(|r| (r.seconds.ln(), r.psnr_db))
                .collect();
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 5, color.filled())))
                .map_err(|x| e(&x))?
                .label(on_devices(name, &of_method, &ok))
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
        }
        let mut front: Vec<&&BenchRow> = ok.iter().filter(|r| r.pareto).collect();
        front.sort_by(|a, b| a.seconds.total_cmp(&b.seconds));
        chart
            .draw_series(LineSeries::new(
                front.iter().map(|r| (r.seconds.ln(), r.psnr_db)),
                BLACK.stroke_width(2),
            ))
            .map_err(|x| e(&x))?
            .label("Pareto front (labelled)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        let labels: Vec<String> = front
            .iter()
            .map(|r| r.label.replace(", crop 0.25 square", ""))
            .collect();
        let points: Vec<(f64, f64)> = front.iter().map(|r| (r.seconds.ln(), r.psnr_db)).collect();
        let spans = ((x1 / x0).ln(), p1 - p0 + 2.0 * pad);
        let others: Vec<(f64, f64)> = (ok.iter().filter(|r| !r.pareto))
            .map(|r| (r.seconds.ln(), r.psnr_db))
            .collect();
        let spots = label_spots(&points, &labels, &others, spans, pad);
        // A label moved off its first spot is tied to its point by a thin line.
        let leaders = points.iter().zip(&spots).filter_map(|(&p, spot)| {
            let end = spot.leader?;
            Some(PathElement::new(vec![p, end], BLACK.mix(0.6)))
        });
        chart.draw_series(leaders).map_err(|x| e(&x))?;
        chart
            .draw_series(
                labels
                    .iter()
                    .zip(spots)
                    .map(|(l, spot)| Text::new(l.clone(), spot.at, ("sans-serif", 13))),
            )
            .map_err(|x| e(&x))?;
        // At the pick's predicted time and PSNR: a measured point, or one interpolated between
        // two measured counts of its method.
        let picked = pick
            .iter()
            .map(|a| (a.predicted_seconds.ln(), a.table_psnr_db));
        chart
            .draw_series(picked.map(|at| Circle::new(at, 11, RED.stroke_width(3))))
            .map_err(|x| e(&x))?
            .label(format!(
                "method = \"auto\": best within {:.2} s (1 s per 768²)",
                auto::default_budget(pixels)
            ))
            .legend(|(x, y)| Circle::new((x + 10, y), 7, RED.stroke_width(3)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| e(&x))
    })
}

/// The plot's time axis: ln t drawn linearly, ticked at [`time_ticks`] (plotters' own log
/// axis labels only the decades when they are few).
struct LnTimeAxis {
    ln: RangedCoordf64,
    ticks: Vec<f64>,
}

impl LnTimeAxis {
    /// The axis from `lo` to `hi` seconds.
    fn new(lo: f64, hi: f64) -> LnTimeAxis {
        LnTimeAxis {
            ln: (lo.ln()..hi.ln()).into(),
            ticks: time_ticks(lo, hi),
        }
    }
}

impl Ranged for LnTimeAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;
    fn map(&self, v: &f64, limit: (i32, i32)) -> i32 {
        self.ln.map(v, limit)
    }
    fn key_points<H: KeyPointHint>(&self, _: H) -> Vec<f64> {
        self.ticks.clone()
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.ln.range()
    }
}

/// ln of the times 1, 2 and 5 × 10ⁿ s within [lo, hi]: the log time axis's ticks.
fn time_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    (first..=last)
        .flat_map(|n| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(n)))
        .filter(|t| (lo..=hi).contains(t))
        .map(f64::ln)
        .collect()
}

/// A tick's time in seconds with as many decimals as its leading digit needs (0.002, 0.5, 20).
fn seconds_label(t: f64) -> String {
    let decimals = (-t.log10().floor()).max(0.0) as usize;
    format!("{t:.decimals$}")
}

/// Where a Pareto label goes: its top-left corner, and where a line from its point meets it
/// when it is not at its first spot.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LabelSpot {
    at: (f64, f64),
    leader: Option<(f64, f64)>,
}

/// Where each Pareto label goes ([`LabelSpot`]). The first spot is right of and just below
/// the point; where that would cover a label already placed, another labelled point or one of
/// the `others` (the points off the front), above the point, then left of it (the front rises
/// to the right, so up and left of a point is free of others), then below the label before it,
/// then further below, left and above; where every spot covers something, the one that covers
/// least. Sizes are estimated from the 13-px font and 5-px dots on the plot's ~880 × 560 px
/// area spanning `spans` (ln seconds, dB).
fn label_spots(
    points: &[(f64, f64)],
    labels: &[String],
    others: &[(f64, f64)],
    spans: (f64, f64),
    pad: f64,
) -> Vec<LabelSpot> {
    let h = 16.0 / 560.0 * spans.1;
    let dot = (6.0 / 880.0 * spans.0, 6.0 / 560.0 * spans.1);
    let mut placed: Vec<(f64, f64, f64)> = Vec::new();
    let mut spots = Vec::new();
    for (i, (&(px, py), label)) in points.iter().zip(labels).enumerate() {
        let w = label.chars().count() as f64 * 7.0 / 880.0 * spans.0;
        // What a label at (x, ty) would cover: labels placed, and points but its own.
        let covers = |&(x, ty): &(f64, f64)| {
            let on_labels = (placed.iter())
                .filter(|&&(lx, ly, lw)| x < lx + lw && lx < x + w && (ty - ly).abs() < h)
                .count();
            let obstacles = (points.iter().enumerate())
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| q)
                .chain(others);
            let on_points = obstacles
                .filter(|&&(qx, qy)| {
                    let inside_x = qx + dot.0 > x && qx - dot.0 < x + w;
                    inside_x && qy + dot.1 > ty - h && qy - dot.1 < ty
                })
                .count();
            on_labels + on_points
        };
        let right = px + 0.04;
        let below_last = placed.last().map_or(py, |&(_, ly, _)| ly - 1.05 * h);
        let first = (right, py - 0.15 * pad);
        let left = px - 0.04 - w;
        let candidates = [
            first,
            (right, py + 1.1 * h),
            (left, py + 0.5 * h),
            (right, below_last),
            (right, py - 1.2 * h),
            (left, py - 0.6 * h),
            (right, py + 2.2 * h),
        ];
        // The first free spot; where none is, the one that covers least.
        let (x, ty) = (candidates.into_iter().enumerate())
            .min_by_key(|&(k, c)| (covers(&c), k))
            .map_or(first, |(_, c)| c);
        let meets = if x < px { x + w } else { x };
        let leader = ((x, ty) != first).then_some((meets, ty - 0.5 * h));
        placed.push((x, ty, w));
        spots.push(LabelSpot {
            at: (x, ty),
            leader,
        });
    }
    spots
}

/// A legend entry with the devices its rows ran on, in a bench where some row ran elsewhere
/// than on the CPU (so a GPU bench marks the methods that stayed on the CPU).
fn on_devices(name: &str, rows: &[&&BenchRow], all: &[&BenchRow]) -> String {
    if all.iter().all(|r| r.device == "cpu") {
        return name.to_string();
    }
    let mut devices: Vec<&str> = rows.iter().map(|r| r.device.as_str()).collect();
    devices.sort();
    devices.dedup();
    format!("{name} — {}", devices.join(", ").to_uppercase())
}

/// The paper's crop fractions: 0.05 to 0.4 of the width in steps of 0.025.
pub fn paper_crops() -> Vec<f64> {
    (0..=14).map(|i| 0.05 + 0.025 * i as f64).collect()
}

/// Mean over the channels of one estimate against the true channels.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ChannelError {
    pub psnr_db: f64,
    pub rmse: f64,
    pub ssim: f64,
}

fn channel_error(truth: &Cube, est: &Cube) -> Result<ChannelError> {
    let m = metrics::compare(truth, est)?;
    Ok(ChannelError {
        psnr_db: m.psnr_db,
        rmse: m.rmse,
        ssim: m.ssim,
    })
}

/// One crop of the sweep on one scene.
#[derive(Clone, Debug, Serialize)]
pub struct CropRow {
    pub scene: String,
    pub crop: f64,
    /// Window size in bins (x, y).
    pub bins: [usize; 2],
    /// x̂ of the Fourier crop.
    pub fourier: ChannelError,
    /// GAP seeded by that x̂ (None when not asked for).
    pub gap: Option<ChannelError>,
    /// Each channel low-passed by the same window alone (no multiplexing).
    pub bound: ChannelError,
}

/// Demultiplex `sim`'s frame at every crop in `crops` with the rig's carriers held fixed. The
/// demultiplexer is built directly (`Demux::new`), bypassing the layout check, so crops above
/// the largest non-overlapping one (0.25 for the default layout) are measured too, with windows
/// that overlap their neighbours. With `gap`, each x̂ also seeds GAP with that configuration.
pub fn sweep_crop(
    sim: &Simulated,
    scene: &str,
    crops: &[f64],
    gap: Option<&GapConfig>,
) -> Result<Vec<CropRow>> {
    let (w, h) = (sim.frame.width, sim.frame.height);
    let mut cfg = sim.exp.reconstruct.clone();
    cfg.gap = gap.cloned().unwrap_or_else(|| GapConfig {
        method: Method::Fourier,
        ..cfg.gap.clone()
    });
    let recon = Reconstructor::new(&cfg, &sim.rig.design(), &sim.calibration, &sim.exp.file)?;
    let frame = sim.calibration.linearise(&sim.frame)?;
    let window = sim.exp.reconstruct.window;
    crops
        .iter()
        .map(|&crop| {
            if !(crop > 0.0 && crop <= 0.5) {
                return Err(Error::config(
                    "<command line>",
                    "crop",
                    crop,
                    "must be in (0, 0.5]",
                ));
            }
            let mut d = Demux::new(w, h, &sim.rig.carriers, crop)
                .with_window(window, SUPER_GAUSSIAN_ORDER)?;
            if d.dc.wx < 1 || d.dc.wy < 1 {
                return Err(Error::config(
                    "<command line>",
                    "crop",
                    crop,
                    &format!("gives an empty window on a {w}×{h} frame"),
                ));
            }
            d = d.with_calibration(&recon.demux_carriers())?;
            let z = d.run(&frame)?;
            let xhat = recon.to_channels(&z)?;
            let g = match &recon.gap {
                Some(s) => Some(channel_error(
                    &sim.channels,
                    &recon.to_channels(&s.run(&frame, &z, None)?.0)?,
                )?),
                None => None,
            };
            Ok(CropRow {
                scene: scene.to_string(),
                crop,
                bins: [d.dc.wx, d.dc.wy],
                fourier: channel_error(&sim.channels, &xhat)?,
                gap: g,
                bound: channel_error(&sim.channels, &d.crop_bound(&sim.channels))?,
            })
        })
        .collect()
}

/// The crop sweep as a Markdown table.
pub fn sweep_markdown(rows: &[CropRow]) -> String {
    let mut s = String::from(
        "| scene | crop | bins | Fourier PSNR dB | RMSE | SSIM | GAP PSNR dB | GAP SSIM | bound PSNR dB |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for r in rows {
        let (gp, gs) = r.gap.map_or(("–".into(), "–".into()), |g| {
            (format!("{:.2}", g.psnr_db), format!("{:.4}", g.ssim))
        });
        s += &format!(
            "| {} | {:.3} | {}×{} | {:.2} | {:.4} | {:.4} | {} | {} | {:.2} |\n",
            r.scene,
            r.crop,
            r.bins[0],
            r.bins[1],
            r.fourier.psnr_db,
            r.fourier.rmse,
            r.fourier.ssim,
            gp,
            gs,
            r.bound.psnr_db
        );
    }
    s
}

/// The crop of highest Fourier PSNR per scene, in first-seen scene order.
pub fn sweep_peaks(rows: &[CropRow]) -> Vec<(String, f64, f64)> {
    let mut peaks: Vec<(String, f64, f64)> = Vec::new();
    for r in rows {
        match peaks.iter_mut().find(|p| p.0 == r.scene) {
            Some(p) if r.fourier.psnr_db > p.2 => (p.1, p.2) = (r.crop, r.fourier.psnr_db),
            Some(_) => {}
            None => peaks.push((r.scene.clone(), r.crop, r.fourier.psnr_db)),
        }
    }
    peaks
}

/// PSNR against crop, one colour per scene: Fourier solid, GAP dashed.
pub fn sweep_plot(path: &Path, rows: &[CropRow]) -> Result<()> {
    let mut series = Vec::new();
    for (c, (scene, _, _)) in sweep_peaks(rows).into_iter().enumerate() {
        let of = |f: &dyn Fn(&CropRow) -> Option<f64>| -> Vec<(f64, f64)> {
            rows.iter()
                .filter(|r| r.scene == scene)
                .filter_map(|r| f(r).map(|v| (r.crop, v)))
                .collect()
        };
        series.push(Series {
            label: format!("{scene} Fourier"),
            color: c,
            dashed: false,
            points: of(&|r| Some(r.fourier.psnr_db)),
        });
        let g = of(&|r| r.gap.map(|g| g.psnr_db));
        if !g.is_empty() {
            series.push(Series {
                label: format!("{scene} GAP"),
                color: c,
                dashed: true,
                points: g,
            });
        }
    }
    plot::line_plot(
        path,
        "Demultiplexed channels against crop size (default carriers held fixed)",
        "crop (fraction of the width)",
        "mean channel PSNR, dB",
        &series,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The time axis of a bench from 0.03 s to 40 s is ticked at 0.05, 0.1, 0.2, 0.5, 1, 2, 5,
    /// 10, 20 s (in ln) and labelled without trailing digits.
    #[test]
    fn time_ticks_are_one_two_five_per_decade() {
        let ticks: Vec<f64> = time_ticks(0.03, 40.0).into_iter().map(f64::exp).collect();
        let want = [0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0];
        assert_eq!(ticks.len(), want.len(), "{ticks:?}");
        for (t, w) in ticks.iter().zip(want) {
            assert!((t / w - 1.0).abs() < 1e-12, "{ticks:?}");
        }
        let labels: Vec<String> = ticks.iter().map(|&t| seconds_label(t)).collect();
        assert_eq!(
            labels,
            ["0.05", "0.1", "0.2", "0.5", "1", "2", "5", "10", "20"]
        );
        assert_eq!(seconds_label(0.002), "0.002");
    }

    #[test]
    fn pareto_front_of_a_hand_made_set() {
        // (time, psnr): 0 and 2 and 4 are non-dominated; 1 is beaten by 0 (slower, worse),
        // 3 by 2 (same time, worse), 5 by 4 (slower, same value); 6 is not finite.
        let pts = [
            (1.0, 20.0),
            (2.0, 19.0),
            (3.0, 25.0),
            (3.0, 24.0),
            (10.0, 30.0),
            (11.0, 30.0),
            (f64::NAN, 40.0),
        ];
        assert_eq!(pareto_front(&pts), vec![0, 2, 4]);
        // No point of the front is dominated, and every other point is.
        let front = pareto_front(&pts);
        let dominated = |i: usize| {
            pts.iter().enumerate().any(|(j, q)| {
                j != i && q.0 <= pts[i].0 && q.1 >= pts[i].1 && (q.0 < pts[i].0 || q.1 > pts[i].1)
            })
        };
        for i in 0..6 {
            assert_eq!(front.contains(&i), !dominated(i), "point {i}");
        }
        assert_eq!(pareto_front(&[]), Vec::<usize>::new());
        // Identical points are both kept; a single point is its own front.
        assert_eq!(pareto_front(&[(1.0, 1.0), (1.0, 1.0)]), vec![0, 1]);
        assert_eq!(pareto_front(&[(5.0, -3.0)]), vec![0]);
    }

    proptest::proptest! {
        #[test]
        fn pareto_front_is_exactly_the_non_dominated_set(
            pts in proptest::collection::vec((0u8..8, 0u8..8), 0..30)
        ) {
            let p: Vec<(f64, f64)> = pts.iter().map(|&(a, b)| (a as f64, b as f64)).collect();
            let front = pareto_front(&p);
            for i in 0..p.len() {
                let dom = p.iter().any(|q| q.0 <= p[i].0 && q.1 >= p[i].1 && q != &p[i]);
                proptest::prop_assert_eq!(front.contains(&i), !dom);
            }
            // Along the front cost rises and value rises.
            for w in front.windows(2) {
                proptest::prop_assert!(p[w[0]].0 <= p[w[1]].0 && p[w[0]].1 <= p[w[1]].1);
            }
        }
    }

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&[7.0]), 7.0);
    }

    fn tiny() -> Simulated {
        let mut exp = Experiment::prototype();
        exp.scene.size = [32, 32];
        exp.validate().unwrap();
        simulate(&exp, &Library::default_root()).unwrap()
    }

    #[test]
    fn crop_sweep_is_finite_and_the_bound_improves_with_the_crop() {
        let sim = tiny();
        let cfg = GapConfig {
            method: Method::Gap,
            iterations: 3,
            levels: 2,
            ..Default::default()
        };
        let rows = sweep_crop(&sim, "tiny", &paper_crops(), Some(&cfg)).unwrap();
        assert_eq!(rows.len(), 15);
        for r in &rows {
            let g = r.gap.unwrap();
            for v in [
                r.fourier.psnr_db,
                r.fourier.rmse,
                r.fourier.ssim,
                g.psnr_db,
                g.ssim,
                r.bound.psnr_db,
            ] {
                assert!(v.is_finite(), "crop {}: {r:?}", r.crop);
            }
        }
        // Without multiplexing a larger window only keeps more of each channel.
        for w in rows.windows(2) {
            assert!(w[1].bound.rmse <= w[0].bound.rmse + 1e-9, "{w:?}");
        }
        // Past 0.25 the windows overlap their neighbours: the Fourier estimate must fall
        // below its own crop bound by more than it does at 0.25.
        let at = |c: f64| rows.iter().find(|r| (r.crop - c).abs() < 1e-9).unwrap();
        let gap_to_bound = |r: &CropRow| r.bound.psnr_db - r.fourier.psnr_db;
        assert!(gap_to_bound(at(0.4)) > gap_to_bound(at(0.25)));
        assert_eq!(sweep_peaks(&rows).len(), 1);
        assert!(sweep_crop(&sim, "tiny", &[0.0], None).is_err());
    }

    #[test]
    fn a_pareto_label_that_would_cover_another_moves_and_a_free_one_stays() {
        let labels = vec!["gap 20 it".to_string(); 3];
        let spans = (4.0, 10.0);
        let h = 16.0 / 560.0 * spans.1;
        // Two points on top of each other, then one far away.
        let pts = [(0.0, 17.0), (0.01, 17.02), (3.0, 22.0)];
        let spots = label_spots(&pts, &labels, &[], spans, 0.5);
        let unmoved = |at| LabelSpot { at, leader: None };
        assert_eq!(spots[0], unmoved((0.04, 17.0 - 0.075)));
        let (x1, y1) = spots[1].at;
        assert!((y1 - spots[0].at.1).abs() >= h, "{spots:?}");
        let tied = Some((x1, y1 - 0.5 * h));
        assert_eq!(spots[1].leader, tied, "a moved label is tied to its point");
        assert_eq!(spots[2], unmoved((3.04, 22.0 - 0.075)));
    }

    /// A point off the front where a label would go moves the label as a labelled point does.
    #[test]
    fn a_label_moves_off_a_point_that_is_not_on_the_front() {
        let labels = vec!["gap 20 it".to_string()];
        let spans = (4.0, 10.0);
        let pts = [(0.0, 17.0)];
        let first = label_spots(&pts, &labels, &[], spans, 0.5)[0];
        assert_eq!(first.leader, None);
        let (x, y) = first.at;
        // A point in the middle of that first spot.
        let spot = label_spots(&pts, &labels, &[(x + 0.1, y - 0.1)], spans, 0.5)[0];
        assert_ne!(spot.at, first.at, "{spot:?}");
        assert!(spot.leader.is_some(), "{spot:?}");
    }

    /// A label whose first spot is taken by its neighbour's label and whose spot above holds the
    /// next point goes left of its point, tied to it at the label's right end.
    #[test]
    fn a_label_boxed_in_on_the_right_goes_left_of_its_point() {
        let labels = vec!["gap 20 it".to_string(); 3];
        let spans = (4.0, 10.0);
        let (h, w) = (16.0 / 560.0 * spans.1, 9.0 * 7.0 / 880.0 * spans.0);
        let pts = [(0.0, 17.0), (0.01, 17.05), (0.1, 17.4)];
        let spot = label_spots(&pts, &labels, &[], spans, 0.5)[1];
        let (x, y) = spot.at;
        assert!((x - (0.01 - 0.04 - w)).abs() < 1e-12 && (y - (17.05 + 0.5 * h)).abs() < 1e-12);
        let (lx, ly) = spot.leader.unwrap();
        assert!(
            (lx - (0.01 - 0.04)).abs() < 1e-12 && (ly - 17.05).abs() < 1e-12,
            "{spot:?}"
        );
    }

    #[test]
    fn a_frame_the_wavelet_cannot_split_leaves_only_gaps_rows_out() {
        let sim = tiny();
        assert_eq!(gap_left_out(&sim), None);
        let mut exp = sim.exp.clone();
        exp.scene.size = [40, 40];
        let odd = simulate(&exp, &Library::default_root()).unwrap();
        let why = gap_left_out(&odd).unwrap();
        assert!(
            why.contains("reconstruct.gap.levels") && why.contains("40×40"),
            "{why}"
        );
        let grid = grid_for(&odd, &OpenDevice::cpu());
        let kept = |m: Method| grid.iter().filter(|s| s.method == m).count();
        let all = |m: Method| default_grid().iter().filter(|s| s.method == m).count();
        assert_eq!(kept(Method::Gap), 0);
        for m in [Method::Fourier, Method::GapTv, Method::Joint] {
            assert_eq!(kept(m), all(m), "{m:?}");
        }
        let gap_tv = grid.iter().find(|s| s.method == Method::GapTv).unwrap();
        let rows = work_precision(&odd, &[*gap_tv], 1).unwrap();
        assert!(rows[0].psnr_db.is_finite(), "{rows:?}");
    }

    #[test]
    fn a_rig_with_a_camera_adds_the_noise_aware_joint_rows() {
        let sim = tiny();
        assert_eq!(grid_for(&sim, &OpenDevice::cpu()), default_grid());
        let mut exp = sim.exp.clone();
        exp.rig.sensor = Some(Default::default());
        let noisy = simulate(&exp, &Library::default_root()).unwrap();
        let grid = grid_for(&noisy, &OpenDevice::cpu());
        let extra = &grid[default_grid().len()..];
        assert_eq!(extra.len(), 6);
        assert_eq!(
            extra[0].label(),
            "joint 20 it noise-weighted, crop 0.25 square"
        );
        assert_eq!(
            extra[5].label(),
            "joint 80 it discrepancy λ, crop 0.25 square"
        );
        // Each runs: the weighted data term and the discrepancy search, through the Reconstructor.
        let rows = work_precision(&noisy, &[extra[0], extra[3]], 1).unwrap();
        assert!(rows.iter().all(|r| r.psnr_db.is_finite()), "{rows:?}");
    }

    #[test]
    fn work_precision_rows_are_finite_and_the_front_is_marked() {
        let sim = tiny();
        let joint = joint_setting(30, Prior::Tv, NoiseAware::Off);
        let grid = [
            Setting {
                window: WindowShape::Circular,
                ..Setting::new(Method::Fourier, 0)
            },
            Setting::new(Method::Gap, 2),
            joint,
            joint_setting(30, Prior::Pnp, NoiseAware::Off),
            Setting {
                reweight_rounds: REWEIGHT_ROUNDS,
                ..joint
            },
        ];
        let rows = work_precision(&sim, &grid, 2).unwrap();
        assert_eq!(rows.len(), 5);
        // The joint method beats the Fourier estimate it starts from, through the Reconstructor.
        assert!(rows[2].psnr_db > rows[0].psnr_db + 1.0, "{rows:?}");
        for r in &rows {
            assert!(
                r.psnr_db.is_finite()
                    && r.ssim.is_finite()
                    && r.sam_deg.is_some_and(f64::is_finite)
            );
            assert_eq!(r.seconds_all.len(), 2);
        }
        assert!(rows.iter().any(|r| r.pareto));
        assert!(work_precision(&sim, &grid, 0).is_err());
        let e = work_precision(
            &sim,
            &[Setting {
                crop: 0.3,
                ..grid[0]
            }],
            1,
        )
        .unwrap_err();
        assert!(e.to_string().contains("overlap"), "{e}");
        assert!(rows.iter().all(|r| r.device == "cpu"));
        // The plug-and-play prior is a row of its own, labelled so, and beats the Fourier estimate.
        assert!(rows[3].psnr_db > rows[0].psnr_db + 1.0, "{rows:?}");
        let table = work_precision_markdown(&rows);
        assert!(table.contains("| gap 2 it, crop 0.25 square | cpu |"));
        assert!(
            table.contains("| pnp 30 it, crop 0.25 square | cpu |"),
            "{table}"
        );
        // Reweighted TV runs as its own row (a different cube than plain TV's), which `auto`
        // does not take into its table.
        assert!(table.contains("| joint 30 it reweighted ×3, crop 0.25 square | cpu |"));
        assert_ne!(rows[4].psnr_db, rows[2].psnr_db, "{rows:?}");
        let s = &grid[4];
        assert!(!auto::tabled(
            s.method,
            s.iterations,
            s.crop,
            s.window,
            s.prior,
            false,
            s.reweight_rounds
        ));
    }

    /// On a GPU (lavapipe counts), every setting, the joint method included, runs there and
    /// gives the CPU's error (issue 17: within 0.01 dB).
    #[cfg(feature = "gpu")]
    #[test]
    fn on_a_gpu_the_rows_say_where_they_ran_and_match_the_cpu() {
        use specmux_core::reconstructor::ComputeDevice;
        let device = match OpenDevice::open(ComputeDevice::Gpu) {
            Ok(d) => d,
            Err(e) => return eprintln!("{e}: GPU test skipped"),
        };
        // `auto` reads the GPU's table on a hardware adapter only (lavapipe is slower than the
        // CPU path), the CPU's on the CPU.
        let software = device.gpu().is_some_and(|c| c.is_software());
        let want = match software {
            true => specmux_core::auto::CPU,
            false => specmux_core::auto::GPU,
        };
        assert_eq!(device.auto_table(), want);
        assert_eq!(OpenDevice::cpu().auto_table(), specmux_core::auto::CPU);
        let sim = tiny();
        let grid = [
            Setting::new(Method::Fourier, 0),
            Setting::new(Method::Gap, 3),
            Setting::new(Method::GapTv, 3),
            Setting::new(Method::Joint, 5),
        ];
        let gpu = work_precision_on(&device, &sim, &grid, 1).unwrap();
        let cpu = work_precision(&sim, &grid, 1).unwrap();
        let devices: Vec<&str> = gpu.iter().map(|r| r.device.as_str()).collect();
        assert_eq!(devices, ["gpu", "gpu", "gpu", "gpu"]);
        for (g, c) in gpu.iter().zip(&cpu) {
            assert!(
                (g.psnr_db - c.psnr_db).abs() < 0.01,
                "{}: {} against {}",
                g.label,
                g.psnr_db,
                c.psnr_db
            );
            assert!((g.x_psnr_db - c.x_psnr_db).abs() < 0.01, "{}", g.label);
        }
        assert!(gpu.iter().all(|r| r.stage_seconds[0].is_nan()));
        assert!(cpu.iter().all(|r| r.stage_seconds[0].is_finite()));
        assert!(work_precision_markdown(&gpu).contains("| gpu |"));
        assert!(device.describe().starts_with("GPU "));
    }
}
