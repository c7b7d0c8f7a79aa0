//! Crosstalk between channels: the exposure weights' inverse that undoes it, and where the
//! demultiplexing error comes from. The demultiplexer is linear and the frame is
//! y = Σ_j x_j + Σ_j x_j·cos(2π ω_j·p + φ_j), so channel i's error x̂_i − crop(x_i) splits exactly
//! into the part leaked from the DC term Σ_j x_j and from each carrier term j (for j = i: its own
//! mirror sideband at −ω_i). Each part is reported as its own PSNR-equivalent against the peak.

use crate::demux::Demux;
use crate::error::{Error, Result};
use crate::Carrier;
use crate::Cube;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::Serialize;

/// The error budget of one channel; levels in dB as 10·log10(peak² / MSE of that part).
#[derive(Clone, Debug, Serialize)]
pub struct ErrorBudget {
    pub channel: usize,
    /// Leak of the DC term Σ_j x_j into this channel's window.
    pub dc_db: f64,
    /// Leak of carrier term j (index = channel j; j = this channel is its own mirror sideband).
    pub carrier_db: Vec<f64>,
    /// The largest single source: "DC", "mirror" or "carrier j".
    pub worst: String,
}

fn level_db(err: &[f32], peak: f64) -> f64 {
    let mse = err.iter().map(|v| (*v as f64).powi(2)).sum::<f64>() / err.len().max(1) as f64;
    if mse > 0.0 {
        10.0 * (peak * peak / mse).log10()
    } else {
        f64::INFINITY
    }
}

/// Error budget of every channel for the ideal patterns of `carriers`; `channels` is the truth x.
pub fn budget(demux: &Demux, channels: &Cube, carriers: &[Carrier]) -> Result<Vec<ErrorBudget>> {
    let (w, h, n) = (channels.width, channels.height, channels.planes);
    let peak = channels.max() as f64;
    let dc_frame = channels.mix(&[vec![1.0; n]])?;
    let dc = demux.run(&dc_frame)?;
    // Carrier term j alone: x_j·(s_j − 1).
    let carrier_out: Vec<Cube> = (0..n)
        .into_par_iter()
        .map(|j| {
            let s = carriers[j].ideal_pattern(w, h);
            let term: Vec<f32> = channels
                .plane(j)
                .iter()
                .zip(&s)
                .map(|(x, s)| x * (s - 1.0))
                .collect();
            demux.run(&Cube::from_vec(w, h, 1, term)?)
        })
        .collect::<Result<_>>()?;
    let bound = demux.crop_bound(channels);
    Ok((0..n)
        .map(|i| {
            let dc_db = level_db(dc.plane(i), peak);
            let carrier_db: Vec<f64> = (0..n)
                .map(|j| {
                    let out = carrier_out[j].plane(i);
                    if j == i {
                        // Own term minus what the window legitimately passes = the mirror's leak.
                        let e: Vec<f32> =
                            out.iter().zip(bound.plane(i)).map(|(a, b)| a - b).collect();
                        level_db(&e, peak)
                    } else {
                        level_db(out, peak)
                    }
                })
                .collect();
            let (jw, lw) = carrier_db
                .iter()
                .enumerate()
                .fold(
                    (0, f64::INFINITY),
                    |a, (j, &v)| if v < a.1 { (j, v) } else { a },
                );
            let worst = if dc_db <= lw {
                "DC".to_string()
            } else if jw == i {
                "mirror".to_string()
            } else {
                format!("carrier {jw}")
            };
            ErrorBudget {
                channel: i,
                dc_db,
                carrier_db,
                worst,
            }
        })
        .collect())
}

/// Condition number above which `crosstalk_inverse` refuses. (Wᵀ)⁻¹ multiplies what the
/// demultiplexing leaves wrong — the other windows' leak, 1–10 % of a channel on edge-rich scenes
/// (docs/results.md) — by up to this factor, so beyond 100 even a 1 % leak outgrows the channel
/// and the corrected channels are worse than the uncorrected ones (half a segment of DMD delay
/// typed to five digits gave a condition of 2.5e5 and x̂ at −88 dB, against 16.4 dB without the
/// correction; docs/timing.md). f32 round-off alone would allow 1e6.
pub const MAX_CROSSTALK_CONDITION: f64 = 100.0;

/// The per-pixel demixing matrix M with x = M·z, where the demultiplexed carrier k carries
/// z_k = Σ_i w_ik x_i, i.e. M = (Wᵀ)⁻¹, M[i][k] multiplies z_k. Refuses a non-square, non-finite,
/// singular or ill-conditioned W (condition number > `MAX_CROSSTALK_CONDITION`), naming the number.
pub fn crosstalk_inverse(w: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
    let n = w.len();
    if n == 0 || w.iter().any(|r| r.len() != n) {
        return Err(Error::Shape(format!(
            "crosstalk matrix must be square and non-empty, got {n} rows of lengths {:?}",
            w.iter().map(Vec::len).collect::<Vec<_>>()
        )));
    }
    if w.iter().flatten().any(|v| !v.is_finite()) {
        return Err(Error::Numerical(
            "crosstalk matrix has a non-finite entry".into(),
        ));
    }
    let wt = DMatrix::from_fn(n, n, |k, i| w[i][k]);
    let sv = wt.clone().svd(false, false).singular_values;
    let (smax, smin) = (sv.max(), sv.min());
    let cond = if smin > 0.0 {
        smax / smin
    } else {
        f64::INFINITY
    };
    if cond > MAX_CROSSTALK_CONDITION {
        return Err(Error::Numerical(format!(
            "crosstalk matrix W is singular or ill-conditioned (condition number {cond:.3e} > {MAX_CROSSTALK_CONDITION}): \
             a pattern is shown through no filter, or two patterns see nearly the same mix of filters, and its inverse would \
             multiply the demultiplexing error that much; fix the timing (delays, exposure), or set reconstruct.crosstalk = \"none\""
        )));
    }
    let inv = wt.try_inverse().ok_or_else(|| {
        Error::Numerical(format!(
            "crosstalk matrix W is singular (condition number {cond:.3e})"
        ))
    })?;
    Ok((0..n)
        .map(|i| (0..n).map(|k| inv[(i, k)]).collect())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::carriers::default_layout;

    #[test]
    fn parts_add_up_to_the_demultiplexing_error() {
        // Σ of the leaked parts must equal x̂ − crop(x) exactly (linearity), checked by rebuilding
        // the error from the parts on a random-ish scene.
        let (w, h) = (32, 32);
        let c = default_layout();
        let x = Cube::from_vec(
            w,
            h,
            6,
            (0..w * h * 6)
                .map(|i| ((i * 7919) % 89) as f32 / 89.0)
                .collect(),
        )
        .unwrap();
        let d = Demux::new(w, h, &c, 0.25);
        let mut y = vec![0.0f32; w * h];
        for (j, cj) in c.iter().enumerate() {
            for ((yy, xv), s) in y.iter_mut().zip(x.plane(j)).zip(cj.ideal_pattern(w, h)) {
                *yy += xv * s;
            }
        }
        let xhat = d.run(&Cube::from_vec(w, h, 1, y).unwrap()).unwrap();
        let dc = d.run(&x.mix(&[vec![1.0; 6]]).unwrap()).unwrap();
        let mut sum = dc.clone();
        for (j, cj) in c.iter().enumerate() {
            let term: Vec<f32> = x
                .plane(j)
                .iter()
                .zip(cj.ideal_pattern(w, h))
                .map(|(a, s)| a * (s - 1.0))
                .collect();
            let o = d.run(&Cube::from_vec(w, h, 1, term).unwrap()).unwrap();
            sum.data.iter_mut().zip(&o.data).for_each(|(a, b)| *a += b);
        }
        for (a, b) in sum.data.iter().zip(&xhat.data) {
            assert!((a - b).abs() < 1e-4);
        }
        let b = budget(&d, &x, &c).unwrap();
        assert_eq!(b.len(), 6);
        assert!(b.iter().all(|e| e.dc_db.is_finite()));
    }
}
