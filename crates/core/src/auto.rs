//! `[reconstruct.gap] method = "auto"`: the method and iteration count that gives the best final
//! cube within a time budget, read from a measured work–precision table of the device that runs
//! it (the best PSNR among the entries whose time, scaled by pixel count, fits; the fastest entry
//! when none fits).

use crate::demux::WindowShape;
use crate::gap::Method;
use crate::joint::{self, Prior, WeightRule};
use serde::Serialize;

/// One measured setting (crop 0.25, square window): median seconds of the whole reconstruction
/// of a 768² frame on two threads, and the final cube's PSNR on dead-leaves.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Entry {
    pub method: Method,
    pub iterations: usize,
    pub seconds: f64,
    pub psnr_db: f64,
}

/// Measured with `RAYON_NUM_THREADS=2 specmux bench dead-leaves --repeats 5` on 2026-11-28
/// (release build of commit 60fc036, 768², the crop-0.25 square-window rows with the TV prior,
/// the joint rows at its defaults since bd80454 — the trained spectral prior, one reweighting
/// round — on the 2-core build machine, idle before the run; docs/results.md, `method =
/// "auto"`). It replaced the table of 787cb85, whose joint rows were plain TV with the
/// curvature prior (the same time per iteration; 0.05 dB more at 10 it, 1.05–2.28 dB less from
/// 20 it on). Re-measure on the machine the budget is meant for (`[reconstruct] auto_table`):
/// this machine's speed varies by up to 1.6× between days.
pub const TABLE: &[Entry] = &[
    Entry {
        method: Method::Fourier,
        iterations: 0,
        seconds: 0.2272,
        psnr_db: 13.96,
    },
    Entry {
        method: Method::Gap,
        iterations: 1,
        seconds: 0.2303,
        psnr_db: 15.49,
    },
    Entry {
        method: Method::Gap,
        iterations: 2,
        seconds: 0.2214,
        psnr_db: 15.91,
    },
    Entry {
        method: Method::Gap,
        iterations: 5,
        seconds: 0.2467,
        psnr_db: 16.90,
    },
    Entry {
        method: Method::Gap,
        iterations: 10,
        seconds: 0.3505,
        psnr_db: 17.17,
    },
    Entry {
        method: Method::Gap,
        iterations: 20,
        seconds: 0.5315,
        psnr_db: 17.25,
    },
    Entry {
        method: Method::Gap,
        iterations: 50,
        seconds: 1.1370,
        psnr_db: 17.28,
    },
    Entry {
        method: Method::GapTv,
        iterations: 1,
        seconds: 0.3106,
        psnr_db: 14.39,
    },
    Entry {
        method: Method::GapTv,
        iterations: 2,
        seconds: 0.3706,
        psnr_db: 15.31,
    },
    Entry {
        method: Method::GapTv,
        iterations: 5,
        seconds: 0.4884,
        psnr_db: 16.19,
    },
    Entry {
        method: Method::GapTv,
        iterations: 10,
        seconds: 0.7449,
        psnr_db: 17.24,
    },
    Entry {
        method: Method::GapTv,
        iterations: 20,
        seconds: 1.2371,
        psnr_db: 18.83,
    },
    Entry {
        method: Method::GapTv,
        iterations: 50,
        seconds: 2.8658,
        psnr_db: 21.35,
    },
    Entry {
        method: Method::Joint,
        iterations: 10,
        seconds: 0.3985,
        psnr_db: 20.40,
    },
    Entry {
        method: Method::Joint,
        iterations: 15,
        seconds: 0.4924,
        psnr_db: 22.17,
    },
    Entry {
        method: Method::Joint,
        iterations: 20,
        seconds: 0.5739,
        psnr_db: 23.23,
    },
    Entry {
        method: Method::Joint,
        iterations: 30,
        seconds: 0.7366,
        psnr_db: 24.00,
    },
    Entry {
        method: Method::Joint,
        iterations: 40,
        seconds: 0.8509,
        psnr_db: 24.62,
    },
    Entry {
        method: Method::Joint,
        iterations: 80,
        seconds: 1.3297,
        psnr_db: 25.56,
    },
];

/// The GPU's rows: `specmux bench dead-leaves --device gpu --repeats 3` on an NVIDIA H200
/// (2026-11-28, Vulkan; docs/gpu.md): median seconds of the whole reconstruction of a 768² frame
/// with the cube read back to the host, the same PSNRs as the CPU's, the joint method at its
/// defaults (the trained spectral prior, one reweighting). On a hardware GPU the bench adds the
/// joint method at 160, 320 and 640 iterations: the cube still gains 0.2 dB from 160 to 640. The
/// plug-and-play row is left out: it has no GPU kernel and runs on the CPU.
pub const GPU_TABLE: &[Entry] = &[
    Entry {
        method: Method::Fourier,
        iterations: 0,
        seconds: 0.0176,
        psnr_db: 13.96,
    },
    Entry {
        method: Method::Gap,
        iterations: 50,
        seconds: 0.0316,
        psnr_db: 17.28,
    },
    Entry {
        method: Method::GapTv,
        iterations: 50,
        seconds: 0.0428,
        psnr_db: 21.35,
    },
    Entry {
        method: Method::Joint,
        iterations: 10,
        seconds: 0.0234,
        psnr_db: 20.40,
    },
    Entry {
        method: Method::Joint,
        iterations: 15,
        seconds: 0.0275,
        psnr_db: 22.17,
    },
    Entry {
        method: Method::Joint,
        iterations: 20,
        seconds: 0.0313,
        psnr_db: 23.23,
    },
    Entry {
        method: Method::Joint,
        iterations: 30,
        seconds: 0.0373,
        psnr_db: 24.00,
    },
    Entry {
        method: Method::Joint,
        iterations: 40,
        seconds: 0.0446,
        psnr_db: 24.62,
    },
    Entry {
        method: Method::Joint,
        iterations: 80,
        seconds: 0.0649,
        psnr_db: 25.56,
    },
    Entry {
        method: Method::Joint,
        iterations: 160,
        seconds: 0.1051,
        psnr_db: 26.09,
    },
    Entry {
        method: Method::Joint,
        iterations: 320,
        seconds: 0.1789,
        psnr_db: 26.27,
    },
    Entry {
        method: Method::Joint,
        iterations: 640,
        seconds: 0.3191,
        psnr_db: 26.30,
    },
];

/// A measured table, the device it was measured on and the scene its PSNRs are of.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Table<'a> {
    pub device: &'a str,
    pub scene: &'a str,
    pub entries: &'a [Entry],
}

/// The CPU's table ([`TABLE`]): what `auto` reads unless the reconstruction runs on a GPU.
pub const CPU: Table<'static> = Table {
    device: "two CPU threads",
    scene: "dead-leaves 768²",
    entries: TABLE,
};

/// The GPU's table ([`GPU_TABLE`]): what `auto` reads when a hardware GPU runs the
/// reconstruction (a software adapter emulates one on the CPU, slower than the CPU path).
pub const GPU: Table<'static> = Table {
    device: "an NVIDIA H200 GPU",
    scene: "dead-leaves 768²",
    entries: GPU_TABLE,
};

/// Budget for a 768² frame when `reconstruct.budget_s` is not given (scaled by pixel count).
pub const DEFAULT_BUDGET_S: f64 = 1.0;
/// The frame size the table was measured at.
pub const REFERENCE_PIXELS: usize = 768 * 768;

/// What `auto` picked and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Choice {
    pub method: Method,
    pub iterations: usize,
    /// The table's time scaled to this frame, and the table's PSNR.
    pub predicted_seconds: f64,
    pub table_psnr_db: f64,
    pub budget_s: f64,
    pub reason: String,
    /// The two measured iteration counts a count between them was interpolated from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interpolated_from: Option<[usize; 2]>,
    /// The device the table was measured on.
    pub measured_on: String,
}

/// True for the bench rows the tables hold: crop 0.25, square window, the TV prior, no noise
/// weights, and the joint method at its default reweighting for `iterations`
/// ([`joint::default_rounds`]) (`specmux bench` and `[reconstruct] auto_table` select them
/// alike).
pub fn tabled(
    method: Method,
    iterations: usize,
    crop: f64,
    window: WindowShape,
    prior: Prior,
    noise_weighted: bool,
    reweight_rounds: usize,
) -> bool {
    let default_rounds = match method {
        Method::Joint => joint::default_rounds(iterations, prior, WeightRule::Fixed),
        _ => 0,
    };
    let default_tv = prior == Prior::Tv && reweight_rounds == default_rounds;
    crop == 0.25 && window == WindowShape::Square && default_tv && !noise_weighted
}

/// A time measured on a frame of `pixels`, scaled to the tables' 768² frame.
pub fn at_reference(seconds: f64, pixels: usize) -> f64 {
    seconds * REFERENCE_PIXELS as f64 / pixels as f64
}

/// The default budget for a frame of `pixels`: 1 s per 768² frame.
pub fn default_budget(pixels: usize) -> f64 {
    DEFAULT_BUDGET_S * pixels as f64 / REFERENCE_PIXELS as f64
}

/// The best setting of `table` whose time scaled to `pixels` fits `budget_s` — an entry, or an
/// iteration count between two measured ones ([`between`]) — or else the fastest entry. Of
/// settings with the same PSNR (the table's 0.01 dB) the faster is best.
pub fn pick_from(table: Table<'_>, budget_s: f64, pixels: usize) -> Option<Choice> {
    let Table {
        device,
        scene,
        entries,
    } = table;
    let table = entries;
    let scale = pixels as f64 / REFERENCE_PIXELS as f64;
    let measured = table.iter().map(|e| (*e, None));
    let fits = measured
        .chain(
            between(table, budget_s / scale)
                .into_iter()
                .map(|(e, from)| (e, Some(from))),
        )
        .filter(|(e, _)| e.seconds * scale <= budget_s)
        .max_by(|a, b| {
            let faster = b.0.seconds.total_cmp(&a.0.seconds);
            a.0.psnr_db.total_cmp(&b.0.psnr_db).then(faster)
        });
    let ((e, from), why) = match fits {
        Some(c) => (c, "the best final-cube PSNR within the budget"),
        None => (
            (
                *table
                    .iter()
                    .min_by(|a, b| a.seconds.total_cmp(&b.seconds))?,
                None,
            ),
            "nothing measured fits the budget: the fastest setting",
        ),
    };
    let source = match from {
        Some([lo, hi]) => format!("interpolated between the measured {lo} and {hi} it"),
        None => "measured".to_string(),
    };
    Some(Choice {
        method: e.method,
        iterations: e.iterations,
        predicted_seconds: e.seconds * scale,
        table_psnr_db: e.psnr_db,
        budget_s,
        reason: format!(
            "{why} ({} {} it, {source} on {device}: {:.3} s predicted, {:.2} dB on {scene}; budget {:.3} s)",
            e.method,
            e.iterations,
            e.seconds * scale,
            e.psnr_db,
            budget_s
        ),
        interpolated_from: from,
        measured_on: device.to_string(),
    })
}

/// For each pair of entries of one method measured at neighbouring counts i0 < i1 whose times
/// bracket `budget` (seconds at 768²): the largest count in between that fits, its time and PSNR
/// interpolated linearly in the count (an iterative method's time is close to affine in it
/// between neighbouring rows; the joint method's cost per iteration falls, by about 1.6× from
/// its first twenty iterations to its last forty, as its constraint's live pixels do). Never
/// beyond the measured range.
fn between(table: &[Entry], budget: f64) -> Vec<(Entry, [usize; 2])> {
    let mut out = Vec::new();
    for a in table {
        let next = table
            .iter()
            .filter(|b| b.method == a.method && b.iterations > a.iterations)
            .min_by_key(|b| b.iterations);
        let Some(b) = next else { continue };
        if !(a.seconds <= budget && budget < b.seconds) {
            continue;
        }
        let span = (b.iterations - a.iterations) as f64;
        let steps = ((budget - a.seconds) / (b.seconds - a.seconds) * span).floor() as usize;
        if steps == 0 {
            continue;
        }
        let f = steps as f64 / span;
        let e = Entry {
            method: a.method,
            iterations: a.iterations + steps,
            seconds: a.seconds + f * (b.seconds - a.seconds),
            psnr_db: a.psnr_db + f * (b.psnr_db - a.psnr_db),
        };
        out.push((e, [a.iterations, b.iterations]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_table(entries: &[Entry]) -> Table<'_> {
        Table {
            device: "a test machine",
            scene: "a test scene",
            entries,
        }
    }

    #[test]
    fn picks_the_best_that_fits_and_scales_with_the_pixels() {
        let t = [
            Entry {
                method: Method::Fourier,
                iterations: 0,
                seconds: 0.3,
                psnr_db: 14.0,
            },
            Entry {
                method: Method::Gap,
                iterations: 10,
                seconds: 0.45,
                psnr_db: 17.2,
            },
            Entry {
                method: Method::Joint,
                iterations: 20,
                seconds: 1.8,
                psnr_db: 21.6,
            },
        ];
        assert_eq!(
            pick_from(test_table(&t), 1.0, REFERENCE_PIXELS)
                .unwrap()
                .method,
            Method::Gap
        );
        assert_eq!(
            pick_from(test_table(&t), 2.0, REFERENCE_PIXELS)
                .unwrap()
                .method,
            Method::Joint
        );
        // A quarter of the pixels: the joint method's 1.8 s becomes 0.45 s and fits 1 s; the
        // default budget shrinks with the pixels too, so it picks what it picks at 768².
        let c = pick_from(test_table(&t), 1.0, REFERENCE_PIXELS / 4).unwrap();
        assert_eq!(c.method, Method::Joint);
        let quarter = REFERENCE_PIXELS / 4;
        assert_eq!(
            pick_from(test_table(&t), default_budget(quarter), quarter)
                .unwrap()
                .method,
            Method::Gap
        );
        assert!(c.reason.contains("within the budget"), "{}", c.reason);
        // Nothing fits: the fastest, said so.
        let c = pick_from(test_table(&t), 0.01, REFERENCE_PIXELS).unwrap();
        assert_eq!(c.method, Method::Fourier);
        assert!(c.reason.contains("nothing measured fits"));
        assert_eq!(pick_from(test_table(&[]), 1.0, 1), None);
    }

    /// Equal PSNRs (a converged method at several counts): the fastest wins, wherever it sits.
    #[test]
    fn of_equal_psnrs_the_fastest_is_picked() {
        let entry = |iterations, seconds| Entry {
            method: Method::Joint,
            iterations,
            seconds,
            psnr_db: 23.33,
        };
        for t in [
            [entry(160, 0.36), entry(320, 0.22), entry(640, 0.37)],
            [entry(640, 0.37), entry(320, 0.22), entry(160, 0.36)],
        ] {
            let c = pick_from(test_table(&t), 1.0, REFERENCE_PIXELS).unwrap();
            assert_eq!((c.iterations, c.predicted_seconds), (320, 0.22), "{t:?}");
        }
    }

    /// A count between two measured ones: time and PSNR interpolated, never extrapolated.
    #[test]
    fn a_count_between_two_measured_ones_is_interpolated() {
        let entry = |method, iterations, seconds, psnr_db| Entry {
            method,
            iterations,
            seconds,
            psnr_db,
        };
        let t = [
            entry(Method::Gap, 10, 0.3, 17.0),
            entry(Method::Joint, 10, 0.76, 20.45),
            entry(Method::Joint, 20, 1.12, 22.18),
        ];
        let c = pick_from(test_table(&t), 1.0, REFERENCE_PIXELS).unwrap();
        // 10 + ⌊(1 − 0.76)/0.36 · 10⌋ = 16; 0.76 + 0.6 · 0.36 s; 20.45 + 0.6 · 1.73 dB.
        assert_eq!((c.method, c.iterations), (Method::Joint, 16));
        assert!((c.predicted_seconds - 0.976).abs() < 1e-12, "{c:?}");
        assert!((c.table_psnr_db - 21.488).abs() < 1e-12, "{c:?}");
        assert_eq!(c.interpolated_from, Some([10, 20]));
        assert!(c
            .reason
            .contains("interpolated between the measured 10 and 20 it"));
        // The same at a quarter of the pixels with a quarter of the budget.
        let q = pick_from(test_table(&t), 0.25, REFERENCE_PIXELS / 4).unwrap();
        assert_eq!((q.iterations, q.interpolated_from), (16, Some([10, 20])));
        // Not one more step fits: the measured 10; beyond the last row: the last row.
        let c = pick_from(test_table(&t), 0.77, REFERENCE_PIXELS).unwrap();
        assert_eq!((c.iterations, c.interpolated_from), (10, None));
        let c = pick_from(test_table(&t), 5.0, REFERENCE_PIXELS).unwrap();
        assert_eq!((c.iterations, c.interpolated_from), (20, None));
        let c = pick_from(test_table(&t), 0.5, REFERENCE_PIXELS).unwrap();
        assert_eq!((c.method, c.iterations), (Method::Gap, 10));
    }

    /// The committed table gives the picks docs/results.md quotes.
    #[test]
    fn the_committed_table_picks_what_the_docs_say() {
        for (budget, iterations, from) in [
            // 40 + ⌊(1 − 0.8509)/(1.3297 − 0.8509) · 40⌋ = 52.
            (default_budget(REFERENCE_PIXELS), 52, Some([40, 80])),
            // 20 + ⌊(0.7 − 0.5739)/(0.7366 − 0.5739) · 10⌋ = 27.
            (0.7, 27, Some([20, 30])),
            (1.4, 80, None),
        ] {
            let c = pick_from(CPU, budget, REFERENCE_PIXELS).unwrap();
            assert_eq!(
                (c.method, c.iterations, c.interpolated_from),
                (Method::Joint, iterations, from),
                "{}",
                c.reason
            );
        }
    }

    /// On the GPU's table the default budget holds every measured setting: the best one, the
    /// joint method's 640 iterations, measured (never extrapolated beyond it); a budget of 30 ms
    /// falls between the 15 and 20 iteration rows.
    #[test]
    fn the_gpu_table_picks_the_best_measured_joint_count() {
        let c = pick_from(GPU, default_budget(REFERENCE_PIXELS), REFERENCE_PIXELS).unwrap();
        assert_eq!(
            (c.method, c.iterations, c.interpolated_from),
            (Method::Joint, 640, None)
        );
        assert!(c.reason.contains("an NVIDIA H200 GPU"), "{}", c.reason);
        assert_eq!(c.measured_on, GPU.device);
        // 15 + ⌊(0.030 − 0.0275)/(0.0313 − 0.0275) · 5⌋ = 18 iterations.
        let c = pick_from(GPU, 0.030, REFERENCE_PIXELS).unwrap();
        assert_eq!(
            (c.method, c.iterations, c.interpolated_from),
            (Method::Joint, 18, Some([15, 20]))
        );
        assert_eq!(
            pick_from(CPU, 1.0, REFERENCE_PIXELS).unwrap().measured_on,
            CPU.device
        );
    }
}
