//! The layout search — a heuristic, and labelled so: coordinate descent on the predicted
//! objective from several starts (the paper's layout, the diamond, and seeded random feasible
//! layouts). Each step moves one carrier to the best feasible bin of a lattice (every `step`
//! bins of the upper half plane) with the others held; a sweep over all carriers repeats until
//! none moves, then a last descent on every bin within `step` of each carrier polishes the
//! result. The distinct local optima are returned best first; the caller simulates the best few.

use crate::layout::{Guard, Layout};
use crate::leak::Objective;
use indicatif::ProgressBar;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_pcg::Pcg64;
use rayon::prelude::*;

/// Sweeps allowed per descent (each strictly lowers the cost, so this only caps a pathological case).
const MAX_SWEEPS: usize = 50;

/// The bins of the upper half plane (ky > 0, or ky = 0 and kx > 0) on a lattice of `step`.
pub fn lattice(size: usize, step: usize) -> Vec<(i64, i64)> {
    let h = (size / 2) as i64;
    let s = step.max(1);
    let mut out = Vec::new();
    for ky in (0..=h).step_by(s) {
        for kx in (-h..=h).step_by(s) {
            if ky > 0 || kx > 0 {
                out.push((kx, ky));
            }
        }
    }
    out
}

/// Move carrier `i` to the best feasible site of `sites`; true if the cost fell.
fn best_move(
    l: &mut Layout,
    i: usize,
    sites: &[(i64, i64)],
    obj: &Objective,
    guard: Guard,
) -> bool {
    let old = l.bins[i];
    let mut best = (obj.partial(l, i), old);
    for &s in sites {
        if s == old {
            continue;
        }
        l.bins[i] = s;
        if !l.feasible(guard) {
            continue;
        }
        let c = obj.partial(l, i);
        // A relative margin keeps rounding from cycling between equal sites.
        if c < best.0 * (1.0 - 1e-12) {
            best = (c, s);
        }
    }
    l.bins[i] = best.1;
    best.1 != old
}

/// Coordinate descent from `start` over `sites`, then a unit-step polish.
pub fn descend(
    start: Layout,
    sites: &[(i64, i64)],
    step: usize,
    obj: &Objective,
    guard: Guard,
) -> Layout {
    let mut l = start;
    for _ in 0..MAX_SWEEPS {
        let moved =
            (0..l.bins.len()).fold(false, |m, i| best_move(&mut l, i, sites, obj, guard) | m);
        if !moved {
            break;
        }
    }
    let r = step as i64;
    for _ in 0..MAX_SWEEPS {
        let mut moved = false;
        for i in 0..l.bins.len() {
            let (x, y) = l.bins[i];
            let near: Vec<(i64, i64)> = (-r..=r)
                .flat_map(|dy| (-r..=r).map(move |dx| (x + dx, y + dy)))
                .collect();
            moved |= best_move(&mut l, i, &near, obj, guard);
        }
        if !moved {
            break;
        }
    }
    l
}

/// A random feasible layout: carriers placed one by one on the first free site of a shuffle.
fn random_start(
    template: &Layout,
    sites: &[(i64, i64)],
    guard: Guard,
    seed: u64,
) -> Option<Layout> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut order = sites.to_vec();
    order.shuffle(&mut rng);
    let mut l = Layout {
        bins: Vec::new(),
        ..template.clone()
    };
    for s in order {
        l.bins.push(s);
        if !l.feasible(guard) {
            l.bins.pop();
        }
        if l.bins.len() == template.bins.len() {
            return Some(l);
        }
    }
    None
}

/// Local optima from the given feasible `starts` and `restarts` random ones, distinct, best first,
/// each with its cost. `step` is the lattice pitch of the coarse moves.
pub fn search(
    starts: &[Layout],
    restarts: usize,
    step: usize,
    obj: &Objective,
    guard: Guard,
    seed: u64,
    bar: &ProgressBar,
) -> Vec<(f64, Layout)> {
    let Some(template) = starts.first() else {
        return Vec::new();
    };
    let sites = lattice(template.size, step);
    bar.set_length((starts.len() + restarts) as u64);
    let from_random = (0..restarts as u64)
        .into_par_iter()
        .filter_map(|k| random_start(template, &sites, guard, seed.wrapping_add(k)));
    let mut found: Vec<(f64, Layout)> = starts
        .par_iter()
        .cloned()
        .filter(|s| s.feasible(guard))
        .chain(from_random)
        .map(|s| {
            let l = descend(s, &sites, step, obj, guard);
            bar.inc(1);
            (obj.cost(&l), l)
        })
        .collect();
    found.sort_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.bins.cmp(&b.1.bins)));
    found.dedup_by(|a, b| a.1.bins == b.1.bins);
    found
}
