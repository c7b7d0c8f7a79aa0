//! Exact searches over the k-subsets of a catalogue.
//!
//! - The paper's criterion (largest pairwise correlation) by branch and bound: the largest
//!   correlation of a partial set is a lower bound on every completion, so a branch is cut as
//!   soon as it reaches the `top`-th best complete value. Exact: it returns what enumerating
//!   every combination returns (tested against brute force).
//! - The other criteria have no such bound (adding a filter can raise the noise of every
//!   channel), so every combination is scored — in closed form, in parallel — and the best
//!   `top` of each criterion kept.
//!
//! `keep` forces candidates into every set (the paper kept the three dichroic segments and chose
//! the three papers).

use crate::criteria::{Evaluator, Scores, CRITERIA};
use indicatif::ProgressBar;
use rayon::prelude::*;
use specmux_core::error::Result;
use specmux_core::interrupt;

/// A set and its value under one criterion.
#[derive(Clone, Debug, PartialEq)]
pub struct Ranked {
    pub value: f64,
    pub set: Vec<usize>,
}

/// The best `k` (smallest value, then lexicographic set) seen so far.
#[derive(Clone, Debug)]
pub struct TopK {
    k: usize,
    pub items: Vec<Ranked>,
}

impl TopK {
    pub fn new(k: usize) -> TopK {
        TopK {
            k,
            items: Vec::new(),
        }
    }

    /// The value a set must beat to enter (∞ while not full).
    pub fn threshold(&self) -> f64 {
        if self.items.len() < self.k {
            f64::INFINITY
        } else {
            self.items.last().map_or(f64::INFINITY, |r| r.value)
        }
    }

    fn better(a: (f64, &[usize]), b: (f64, &[usize])) -> bool {
        a.0 < b.0 || (a.0 == b.0 && a.1 < b.1)
    }

    /// Offer a set; it is copied only if it enters.
    pub fn offer(&mut self, value: f64, set: &[usize]) {
        if self.items.len() == self.k {
            let last = self.items.last().expect("k > 0");
            if !Self::better((value, set), (last.value, &last.set)) {
                return;
            }
        }
        let pos = self
            .items
            .iter()
            .position(|r| Self::better((value, set), (r.value, &r.set)))
            .unwrap_or(self.items.len());
        self.items.insert(
            pos,
            Ranked {
                value,
                set: set.to_vec(),
            },
        );
        self.items.truncate(self.k);
    }

    /// The union of two lists, best `k` kept.
    pub fn merge(mut self, other: TopK) -> TopK {
        for r in other.items {
            self.offer(r.value, &r.set);
        }
        self
    }
}

/// The free candidates (not kept) and how many of them each set takes.
fn split(n: usize, choose: usize, keep: &[usize]) -> (Vec<usize>, usize) {
    let free: Vec<usize> = (0..n).filter(|c| !keep.contains(c)).collect();
    (free, choose.saturating_sub(keep.len()))
}

/// Best `top` sets by the paper's criterion, by branch and bound.
pub fn minimax_correlation(ev: &Evaluator, choose: usize, keep: &[usize], top: usize) -> TopK {
    let (free, need) = split(ev.len(), choose, keep);
    let mut best = TopK::new(top);
    let mut set = keep.to_vec();
    set.sort_unstable();
    let base = ev.max_corr(&set);
    if need <= free.len() {
        branch(ev, &free, 0, need, &mut set, base, &mut best);
    }
    best
}

fn branch(
    ev: &Evaluator,
    free: &[usize],
    from: usize,
    need: usize,
    set: &mut Vec<usize>,
    partial: f64,
    best: &mut TopK,
) {
    if need == 0 {
        let mut sorted = set.clone();
        sorted.sort_unstable();
        best.offer(partial, &sorted);
        return;
    }
    for p in from..=free.len() - need {
        // Ctrl-C: the caller reports the stop (`interrupt::check`); what is found is dropped.
        if interrupt::requested() {
            return;
        }
        let c = free[p];
        let worst = set.iter().map(|&s| ev.corr(s, c)).fold(partial, f64::max);
        // Equal values still enter on the lexicographic tie-break, so prune only above.
        if worst > best.threshold() {
            continue;
        }
        set.push(c);
        branch(ev, free, p + 1, need - 1, set, worst, best);
        set.pop();
    }
}

/// How many sets of `choose` of `n` candidates, each holding every `keep`, the searches go over.
pub fn combinations(n: usize, choose: usize, keep: &[usize]) -> u64 {
    let (free, need) = split(n, choose, keep);
    binomial(free.len(), need)
}

/// Number of k-subsets of n, `u64::MAX` where it does not fit (a catalogue no search can cover).
pub fn binomial(n: usize, k: usize) -> u64 {
    if k > n {
        return 0;
    }
    // acc·(n − i) is divisible by i + 1 at every step (acc = C(n, i)); u128 holds the product
    // until acc itself passes u64.
    (0..k.min(n - k))
        .try_fold(1u64, |acc, i| {
            let next = acc as u128 * (n - i) as u128 / (i + 1) as u128;
            u64::try_from(next).ok()
        })
        .unwrap_or(u64::MAX)
}

/// Score every combination; the best `top` of each criterion (in [`CRITERIA`] order). Ctrl-C
/// stops it within a few thousand sets per thread, as an error.
pub fn exhaustive(
    ev: &Evaluator,
    choose: usize,
    keep: &[usize],
    top: usize,
    bar: &ProgressBar,
) -> Result<Vec<TopK>> {
    let (free, need) = split(ev.len(), choose, keep);
    let empty = || vec![TopK::new(top); CRITERIA.len()];
    if need == 0 || need > free.len() {
        let mut t = empty();
        if need == 0 {
            let mut set = keep.to_vec();
            set.sort_unstable();
            record(&mut t, &ev.score(&set), &set);
        }
        return Ok(t);
    }
    bar.set_length(binomial(free.len(), need));
    let ranked = (0..=free.len() - need)
        .into_par_iter()
        .map(|first| {
            let mut t = empty();
            let mut set = keep.to_vec();
            set.push(free[first]);
            let mut count = 0u64;
            each(&free[first + 1..], need - 1, &mut set, &mut |s| {
                let mut sorted = s.to_vec();
                sorted.sort_unstable();
                record(&mut t, &ev.score(&sorted), &sorted);
                count += 1;
                count % 4096 != 0 || !interrupt::requested()
            });
            bar.inc(count);
            t
        })
        .reduce(empty, |a, b| {
            a.into_iter().zip(b).map(|(x, y)| x.merge(y)).collect()
        });
    interrupt::check("the filter search")?;
    Ok(ranked)
}

fn record(t: &mut [TopK], s: &Scores, set: &[usize]) {
    for (k, top) in t.iter_mut().enumerate() {
        let v = s.get(k);
        if v.is_finite() {
            top.offer(v, set);
        }
    }
}

/// Call `f` on `set` extended by every `need`-subset of `pool` (in lexicographic order), until
/// `f` returns false; false when it did.
pub fn each(
    pool: &[usize],
    need: usize,
    set: &mut Vec<usize>,
    f: &mut impl FnMut(&[usize]) -> bool,
) -> bool {
    if need == 0 {
        return f(set);
    }
    for p in 0..pool.len().saturating_sub(need - 1) {
        set.push(pool[p]);
        let go_on = each(&pool[p + 1..], need - 1, set, f);
        set.pop();
        if !go_on {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::criteria::tests::evaluator;

    /// Every combination, sorted by (value, set): the obvious answer.
    fn brute(
        ev: &Evaluator,
        choose: usize,
        keep: &[usize],
        value: impl Fn(&[usize]) -> f64,
    ) -> Vec<Ranked> {
        let (free, need) = split(ev.len(), choose, keep);
        let mut all = Vec::new();
        each(&free, need, &mut keep.to_vec(), &mut |s| {
            let mut set = s.to_vec();
            set.sort_unstable();
            all.push(Ranked {
                value: value(&set),
                set,
            });
            true
        });
        all.retain(|r| r.value.is_finite());
        all.sort_by(|a, b| a.value.total_cmp(&b.value).then_with(|| a.set.cmp(&b.set)));
        all
    }

    #[test]
    fn branch_and_bound_agrees_with_brute_force() {
        let (ev, _) = evaluator(8);
        for (choose, keep) in [(4, vec![]), (6, vec![]), (5, vec![0, 1, 2])] {
            let want = brute(&ev, choose, &keep, |s| ev.max_corr(s));
            let got = minimax_correlation(&ev, choose, &keep, 7);
            assert_eq!(
                got.items,
                want[..7].to_vec(),
                "choose {choose} keep {keep:?}"
            );
        }
    }

    #[test]
    fn exhaustive_top_lists_agree_with_brute_force_for_every_criterion() {
        let (ev, _) = evaluator(6);
        let got = exhaustive(&ev, 6, &[3], 5, &ProgressBar::hidden()).unwrap();
        for (k, top) in got.iter().enumerate() {
            let want = brute(&ev, 6, &[3], |s| ev.score(s).get(k));
            assert_eq!(top.items, want[..5].to_vec(), "{}", CRITERIA[k]);
        }
        assert_eq!(binomial(40, 6), 3_838_380);
        assert_eq!((binomial(10_000, 16), binomial(3, 5)), (u64::MAX, 0));
    }
}
