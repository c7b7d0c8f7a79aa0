//! Runs an experiment end to end — forward model, reconstruction, error against the truth — and
//! gathers every figure with its wall time into one report.

use crate::error::Result;
use crate::forward::{Pipeline, StageTime};
use crate::metrics::{self, Metrics};
use crate::recon::crosstalk::{self, ErrorBudget};
use crate::recon::qp::UnmixStats;
use crate::recon::Reconstructor;
use crate::rig::Rig;
use crate::scene::{Cube, Experiment, Materials};
use crate::spectral::basis::BasisFit;
use crate::spectral::Library;
use serde::Serialize;
use std::time::Instant;

/// One row of the result table: an estimate against its truth, and what it cost.
#[derive(Clone, Debug, Serialize)]
pub struct ResultRow {
    pub stage: String,
    pub against: String,
    pub psnr_db: f64,
    pub ssim: f64,
    pub nrmse: f64,
    pub sam_deg: f64,
    pub seconds: f64,
}

/// Demultiplexing of one channel against the best its crop window could do alone.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelRow {
    pub channel: usize,
    pub filter: String,
    pub carrier: [f64; 2],
    pub psnr_db: f64,
    pub ssim: f64,
    pub bound_psnr_db: f64,
    pub bound_ssim: f64,
    /// |ĝ|/½: the carrier amplitude the demultiplexer divides by, against the ideal pattern's
    /// (1 for ideal sinusoids; measured on the imaged patterns otherwise).
    pub carrier_gain: f64,
}

/// How well the spectral basis represents the training and the held-out reflectances.
#[derive(Clone, Debug, Serialize)]
pub struct BasisReport {
    pub vectors: usize,
    pub train: BasisFit,
    pub held_out: BasisFit,
}

/// Everything an experiment run measured.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    pub experiment: String,
    pub scene: String,
    pub size: [usize; 2],
    pub bands: usize,
    pub forward_stages: Vec<StageTime>,
    pub results: Vec<ResultRow>,
    pub channels: Vec<ChannelRow>,
    pub basis: BasisReport,
    pub unmix: UnmixStats,
    /// Where each channel's demultiplexing error comes from (ideal patterns only).
    pub error_budget: Option<Vec<ErrorBudget>>,
    /// What the rig operator should know (timing: exposure not whole turns, rates, spokes).
    pub warnings: Vec<String>,
    /// Building the reconstructor: windows, unmixer, GAP, calibration frames.
    pub setup_seconds: f64,
    /// Per frame: calibration, demultiplexing, crosstalk, de-aliasing and unmixing.
    pub reconstruction_seconds: f64,
    pub total_seconds: f64,
}

/// The arrays of a run, for writing files.
pub struct RunData {
    pub truth: Cube,
    pub channels: Cube,
    pub frame: Cube,
    pub xhat: Cube,
    pub cube: Cube,
}

fn row(stage: &str, against: &str, m: &Metrics, seconds: f64) -> ResultRow {
    ResultRow {
        stage: stage.into(),
        against: against.into(),
        psnr_db: m.psnr_db,
        ssim: m.ssim,
        nrmse: m.nrmse,
        sam_deg: m.sam_deg,
        seconds,
    }
}

/// Simulate the experiment's frame, reconstruct it and compare every stage with the truth.
pub fn run(exp: &Experiment, lib: &Library) -> Result<(RunReport, RunData)> {
    let t_all = Instant::now();
    let materials = Materials::load(lib)?;
    let rig = Rig::build(exp, lib, &materials)?;
    let pipeline = Pipeline::build(exp, &rig, &materials)?;
    let (state, forward_stages) = pipeline.run()?;
    let scene = state.scene.expect("the scene stage always runs");
    let channels = state.channels.expect("the wheel stage always runs");
    let frame = state.frame.expect("the multiplex stage always runs");

    let t = Instant::now();
    let recon = Reconstructor::new(exp, &rig, state.patterns.as_ref())?;
    let t_setup = t.elapsed().as_secs_f64();
    let z_truth = state.exposed.as_ref().unwrap_or(&channels);
    let out = recon.run(&frame, Some(z_truth))?;
    let [t_demux, t_gap, t_unmix] = out.seconds;
    let (xhat, xgap, cube, gap_stats, unmix) = (out.xhat, out.xgap, out.cube, out.gap, out.unmix);

    let t = Instant::now();
    let bound = recon.demux.crop_bound(&channels);
    let t_bound = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (ideal_cube, _) = recon.unmix(&channels)?;
    let t_ideal = t.elapsed().as_secs_f64();

    let m_x = metrics::compare(&channels, &xhat)?;
    let m_gap = metrics::compare(&channels, &xgap)?;
    let m_bound = metrics::compare(&channels, &bound)?;
    let m_cube = metrics::compare(&scene.cube, &cube)?;
    let m_ideal = metrics::compare(&scene.cube, &ideal_cube)?;
    let results = vec![
        row("demultiplex", "x (true channels)", &m_x, t_demux),
        row(
            &format!(
                "gap ({:?}, {} it)",
                exp.reconstruct.gap.method, gap_stats.iterations
            ),
            "x (true channels)",
            &m_gap,
            t_gap,
        ),
        row(
            "crop bound",
            "x (window on each channel alone)",
            &m_bound,
            t_bound,
        ),
        row("unmix", "r (true cube)", &m_cube, t_unmix),
        row("unmix of true x", "r (spectral limit)", &m_ideal, t_ideal),
    ];
    let channels_rows = (0..channels.planes)
        .map(|i| ChannelRow {
            channel: i,
            filter: rig.wheel.filters[i].name.clone(),
            carrier: [rig.carriers[i].fx, rig.carriers[i].fy],
            psnr_db: m_x.psnr_per_plane[i],
            ssim: m_x.ssim_per_plane[i],
            bound_psnr_db: m_bound.psnr_per_plane[i],
            bound_ssim: m_bound.ssim_per_plane[i],
            carrier_gain: recon.demux.gains[i].norm() / 0.5,
        })
        .collect();
    // The budget splits the leaks of the ideal sinusoids; with simulated optics or timing it
    // would describe another frame than the one reconstructed.
    let error_budget = if exp.rig.has_optics() || exp.rig.timing.is_some() {
        None
    } else {
        Some(crosstalk::budget(&recon.demux, &channels, &rig.carriers)?)
    };
    let warnings = match &exp.rig.timing {
        Some(t) => crate::timing::weights(t)?.warnings,
        None => Vec::new(),
    };
    let basis = BasisReport {
        vectors: rig.basis.len(),
        train: rig.basis.fit(&materials.train)?,
        held_out: rig.basis.fit(&materials.held_out)?,
    };
    let report = RunReport {
        experiment: exp.file.clone(),
        scene: scene.name.clone(),
        size: [frame.width, frame.height],
        bands: scene.grid.count,
        forward_stages,
        results,
        channels: channels_rows,
        basis,
        unmix,
        error_budget,
        warnings,
        setup_seconds: t_setup,
        reconstruction_seconds: t_demux + t_gap + t_unmix,
        total_seconds: t_all.elapsed().as_secs_f64(),
    };
    let data = RunData {
        truth: scene.cube,
        channels,
        frame,
        xhat,
        cube,
    };
    Ok((report, data))
}

impl RunReport {
    /// The result table as fixed-width text.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<18} {:<34} {:>9} {:>7} {:>8} {:>8} {:>10}\n",
            "stage", "against", "PSNR dB", "SSIM", "NRMSE", "SAM °", "seconds"
        );
        for r in &self.results {
            s += &format!(
                "{:<18} {:<34} {:>9.2} {:>7.4} {:>8.4} {:>8.2} {:>10.4}\n",
                r.stage, r.against, r.psnr_db, r.ssim, r.nrmse, r.sam_deg, r.seconds
            );
        }
        s += &format!(
            "\n{:<8} {:<16} {:>12} {:>10} {:>8} {:>10} {:>8} {:>7}\n",
            "channel", "filter", "carrier", "PSNR dB", "SSIM", "bound dB", "bound", "gain"
        );
        for c in &self.channels {
            s += &format!(
                "{:<8} {:<16} {:>12} {:>10.2} {:>8.4} {:>10.2} {:>8.4} {:>7.3}\n",
                c.channel,
                c.filter,
                format!("({},{})", c.carrier[0], c.carrier[1]),
                c.psnr_db,
                c.ssim,
                c.bound_psnr_db,
                c.bound_ssim,
                c.carrier_gain
            );
        }
        if let Some(b) = &self.error_budget {
            s += "\nerror budget of demultiplexing, dB (higher = smaller leak): DC term, then each carrier term (own = mirror)\n";
            for e in b {
                let parts: Vec<String> = e.carrier_db.iter().map(|v| format!("{v:6.1}")).collect();
                s += &format!(
                    "ch{} DC {:6.1} | {} | worst: {}\n",
                    e.channel,
                    e.dc_db,
                    parts.join(" "),
                    e.worst
                );
            }
        }
        for w in &self.warnings {
            s += &format!("\nwarning: {w}");
        }
        s += "\nforward stages: ";
        s += &self
            .forward_stages
            .iter()
            .map(|t| format!("{} {:.3}s", t.stage, t.seconds))
            .collect::<Vec<_>>()
            .join(", ");
        s += &format!(
            "\nbasis J={}: held-out RMSE {:.4} (train {:.4}), energy {:.5}\nunmix: {} of {} pixels hit the non-negativity bound\nreconstructor set-up {:.4}s, reconstruction {:.4}s, total {:.2}s\n",
            self.basis.vectors,
            self.basis.held_out.rmse,
            self.basis.train.rmse,
            self.basis.held_out.energy_captured,
            self.unmix.constrained_pixels,
            self.unmix.pixels,
            self.setup_seconds,
            self.reconstruction_seconds,
            self.total_seconds
        );
        s
    }
}
