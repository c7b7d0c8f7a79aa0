//! The channel weights w_ik: the energy of light through filter i while pattern k is shown,
//! during one exposure, normalised by T/N; and their inverse for reconstruction.

use crate::timing::config::TimingConfig;
use crate::timing::schedule::GaussLegendre;
use crate::timing::schedule::Schedule;
use serde::Serialize;
use specmux_core::error::Result;

/// Gauss–Legendre order for the spoke-crossing integrals (the integrand is analytic in the
/// substituted variable; 32 points reach rounding error, checked against 64 in the tests).
pub(crate) const GL_ORDER: usize = 32;

/// Share of a pattern's light that must come through its own segment before a misalignment
/// warning (spoke mixing of a small spot stays well above it; a 10° index error does not).
const OWN_SEGMENT_SHARE: f64 = 0.9;

/// The result of the timing model for one exposure.
#[derive(Clone, Debug, Serialize)]
pub struct TimingWeights {
    /// w[i][k] = (N/T)·∫_exposure a_i(t)·p_k(t) dt: segments × patterns. The identity for an
    /// aligned whole-turn exposure of equal segments; w_ii = N·Δ_i/360 for unequal ones.
    pub w: Vec<Vec<f64>>,
    /// Fraction of the time the spot straddles a spoke: N·asin(r/R)/π ≈ N·d/(2πR).
    pub spoke_fraction: f64,
    /// Exposure length in wheel turns, T·f.
    pub turns_per_exposure: f64,
    /// What a rig operator should know before recording (empty when everything is aligned).
    pub warnings: Vec<String>,
}

/// Weights of the validated configuration (errors name the offending `rig.timing.…` key).
pub fn weights(cfg: &TimingConfig) -> Result<TimingWeights> {
    cfg.validate("[rig.timing]")?;
    let s = Schedule::new(cfg);
    let gl = GaussLegendre::new(GL_ORDER);
    let (t0, t) = (cfg.camera.start_s, cfg.camera.exposure_s);
    let e = exposure_energy(&s, t0, t, &gl);
    let scale = s.n as f64 / t;
    let w: Vec<Vec<f64>> = e
        .iter()
        .map(|row| row.iter().map(|v| v * scale).collect())
        .collect();
    let spoke_fraction = s.n as f64 * 2.0 * s.half_crossing_s / s.period;
    let turns = t * cfg.wheel.rate_hz;
    let warnings = warnings(cfg, &s, &w, spoke_fraction, turns);
    Ok(TimingWeights {
        w,
        spoke_fraction,
        turns_per_exposure: turns,
        warnings,
    })
}

/// ∫ over [t0, t0+T) in seconds, using periodicity: m whole turns from t0, then the remainder.
pub(crate) fn exposure_energy(s: &Schedule, t0: f64, t: f64, gl: &GaussLegendre) -> Vec<Vec<f64>> {
    let m = (t / s.period).floor();
    let mut e = s.energy(t0 + m * s.period, t0 + t, gl);
    if m > 0.0 {
        let turn = s.energy(t0, t0 + s.period, gl);
        for (row, trow) in e.iter_mut().zip(&turn) {
            for (v, tv) in row.iter_mut().zip(trow) {
                *v += m * tv;
            }
        }
    }
    e
}

fn warnings(
    cfg: &TimingConfig,
    s: &Schedule,
    w: &[Vec<f64>],
    spoke: f64,
    turns: f64,
) -> Vec<String> {
    let mut out = Vec::new();
    if (turns - turns.round()).abs() > 1e-9 * turns.max(1.0) {
        out.push(format!(
            "exposure is {turns:.4} wheel turns, not a whole number: the channels get unequal light \
             (set rig.timing.camera.exposure_s to a multiple of {} s)",
            s.period
        ));
    }
    if spoke > 0.0 {
        out.push(format!(
            "the spot straddles a spoke {:.2} % of the time: light of neighbouring segments mixes \
             (off-diagonal weights up to {:.4})",
            100.0 * spoke,
            w.iter()
                .enumerate()
                .flat_map(|(i, r)| r
                    .iter()
                    .enumerate()
                    .filter(move |(k, _)| *k != i)
                    .map(|(_, v)| *v))
                .fold(0.0, f64::max)
        ));
    }
    let picture = 1.0 / cfg.dmd.max_rate_hz;
    for (k, &(_, dur)) in s.slots.iter().enumerate() {
        let pictures = dur / picture;
        if pictures < 2.0 {
            out.push(format!(
                "pattern {k} is shown {:.2} µs = {pictures:.2} DMD picture times: within a factor 2 of \
                 the DMD's rate limit ({} Hz)",
                dur * 1e6,
                cfg.dmd.max_rate_hz
            ));
        }
    }
    for k in 0..s.n {
        let col: f64 = w.iter().map(|r| r[k]).sum();
        if col == 0.0 {
            out.push(format!(
                "pattern {k} is never shown during the exposure: its channel is lost"
            ));
            continue;
        }
        let other = (0..s.n)
            .filter(|&j| j != k)
            .max_by(|&a, &b| w[a][k].total_cmp(&w[b][k]))
            .unwrap_or(k);
        if w[k][k] < OWN_SEGMENT_SHARE * col {
            out.push(format!(
                "only {:.1} % of pattern {k}'s light comes through segment {k} (the largest other \
                 share through segment {other}, w = {:.3}): check rig.timing.dmd.delays_s and rig.timing.wheel.index_offset_deg",
                100.0 * w[k][k] / col,
                w[other][k]
            ));
        }
    }
    let frame_turns = cfg.wheel.rate_hz / cfg.camera.frame_rate_hz;
    if (frame_turns - frame_turns.round()).abs() > 1e-9 * frame_turns {
        let waited = frame_turns.ceil();
        out.push(format!(
            "the frame period is {frame_turns:.3} wheel turns: exposures triggered from the index \
             pulse start every {waited} turns, i.e. {:.3} fps rather than {}",
            cfg.wheel.rate_hz / waited,
            cfg.camera.frame_rate_hz
        ));
    }
    out
}
