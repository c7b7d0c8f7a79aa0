//! Exact Poisson sampling for shot noise, fast enough to draw a new mean at every pixel:
//! Knuth's product-of-uniforms method below λ = 10 and Hörmann's transformed rejection with
//! squeeze (PTRS, Insurance: Mathematics and Economics 12, 1993) above. PTRS needs no set-up
//! table, so a per-pixel mean costs one square root and a few divisions; about 9 draws in 10
//! are accepted by the squeeze without any logarithm.

use rand::Rng;

/// Below this mean Knuth's method (expected λ + 1 uniforms) is used, above it PTRS.
const PTRS_MIN_MEAN: f64 = 10.0;

/// Size of the ln k! table (counts up to 4× the default full well).
const LN_FACTORIAL_TABLE: usize = 1 << 16;

/// ln k! by summation for k < 65536 (built once, 512 KiB), Stirling's series with terms to k⁻⁵
/// above (absolute error < 1e-13 there).
fn ln_factorial(k: f64) -> f64 {
    use std::sync::OnceLock;
    static TABLE: OnceLock<Vec<f64>> = OnceLock::new();
    if k < LN_FACTORIAL_TABLE as f64 {
        let table = TABLE.get_or_init(|| {
            let mut t = vec![0.0; LN_FACTORIAL_TABLE];
            for i in 2..LN_FACTORIAL_TABLE {
                t[i] = t[i - 1] + (i as f64).ln();
            }
            t
        });
        return table[k as usize];
    }
    let r = 1.0 / k;
    let r2 = r * r;
    (k + 0.5) * k.ln() - k
        + 0.5 * (2.0 * std::f64::consts::PI).ln()
        + r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 / 1260.0))
}

/// floor(x) without a libm call on the baseline x86-64 target: truncation is floor for
/// 0 ≤ x < 2^52; other values (rare: they are rejected) take the library floor.
#[inline]
pub(crate) fn fast_floor(x: f64) -> f64 {
    if (0.0..4.5e15).contains(&x) {
        x as i64 as f64
    } else {
        x.floor()
    }
}

/// Poisson(λ) for one mean, its constants computed once: a pixel's mean is the same in every
/// exposure a capture averages, so they are drawn from one `Poisson` (the draws are those of
/// computing the constants anew each time, bit for bit).
#[derive(Clone, Copy, Debug)]
pub struct Poisson {
    lambda: f64,
    method: Method,
}

#[derive(Clone, Copy, Debug)]
enum Method {
    Zero,
    /// Knuth's method: e^{−λ}.
    Knuth {
        limit: f64,
    },
    /// PTRS: b, a, v_r, and what only the draws outside the squeeze need (1/α and ln λ,
    /// computed at the first such draw: a single exposure seldom needs them).
    Ptrs {
        b: f64,
        a: f64,
        v_r: f64,
        tail: Option<(f64, f64)>,
    },
}

impl Poisson {
    /// The sampler for mean `lambda`, which must be finite and ≥ 0 (the caller checks).
    #[inline(always)]
    pub fn new(lambda: f64) -> Poisson {
        let method = if lambda <= 0.0 {
            Method::Zero
        } else if lambda < PTRS_MIN_MEAN {
            Method::Knuth {
                limit: (-lambda).exp(),
            }
        } else {
            let b = 0.931 + 2.53 * lambda.sqrt();
            Method::Ptrs {
                b,
                a: -0.059 + 0.02483 * b,
                v_r: 0.9277 - 3.6224 / (b - 2.0),
                tail: None,
            }
        };
        Poisson { lambda, method }
    }

    /// One draw as f64.
    #[inline(always)]
    pub fn sample<R: Rng + ?Sized>(&mut self, rng: &mut R) -> f64 {
        let lambda = self.lambda;
        let (b, a, v_r, tail) = match &mut self.method {
            Method::Zero => return 0.0,
            Method::Knuth { limit } => return knuth(rng, *limit),
            Method::Ptrs { b, a, v_r, tail } => (*b, *a, *v_r, tail),
        };
        loop {
            let u = rng.gen::<f64>() - 0.5;
            let v: f64 = rng.gen();
            let us = 0.5 - u.abs();
            let k = fast_floor((2.0 * a / us + b) * u + lambda + 0.43);
            if us >= 0.07 && v <= v_r {
                return k;
            }
            if k < 0.0 || (us < 0.013 && v > us) {
                continue;
            }
            // Only the draws outside the squeeze (about 1 in 10) need α and the logarithms.
            let (inv_alpha, ln_lambda) =
                *tail.get_or_insert_with(|| (1.1239 + 1.1328 / (b - 3.4), lambda.ln()));
            let lhs = (v * inv_alpha / (a / (us * us) + b)).ln();
            if lhs <= -lambda + k * ln_lambda - ln_factorial(k) {
                return k;
            }
        }
    }
}

/// Knuth's method: the number of uniforms whose running product stays above `limit` = e^{−λ}.
fn knuth<R: Rng + ?Sized>(rng: &mut R, limit: f64) -> f64 {
    let mut k = 0.0;
    let mut prod: f64 = rng.gen();
    while prod > limit {
        k += 1.0;
        prod *= rng.gen::<f64>();
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_pcg::Pcg64Mcg;

    #[test]
    fn ln_factorial_matches_summation() {
        let mut sum = 0.0f64;
        for k in 1..200u32 {
            sum += (k as f64).ln();
            let got = ln_factorial(k as f64);
            assert!(
                (got - sum).abs() < 1e-11 * sum.max(1.0),
                "k={k}: {got} vs {sum}"
            );
        }
    }

    /// Pearson χ² of `n` draws against the Poisson(λ) pmf, bins with expected count ≥ 5, the
    /// two tails pooled. Returns (χ², degrees of freedom).
    fn chi_square(lambda: f64, n: usize, seed: u128) -> (f64, usize) {
        let mut rng = Pcg64Mcg::new(seed);
        let kmax = (lambda + 12.0 * lambda.sqrt() + 20.0) as usize;
        let mut counts = vec![0f64; kmax + 1];
        let mut poisson = Poisson::new(lambda);
        for _ in 0..n {
            let k = poisson.sample(&mut rng) as usize;
            counts[k.min(kmax)] += 1.0;
        }
        let pmf: Vec<f64> = (0..=kmax)
            .map(|k| (-lambda + k as f64 * lambda.ln() - ln_factorial(k as f64)).exp())
            .collect();
        // Pool into bins of expected count ≥ 5, walking up from 0; the last bin takes the tail.
        let (mut chi2, mut bins) = (0.0, 0usize);
        let (mut obs, mut exp) = (0.0, 0.0);
        let mut cum = 0.0;
        for k in 0..=kmax {
            obs += counts[k];
            exp += pmf[k] * n as f64;
            cum += pmf[k];
            let rest = (1.0 - cum) * n as f64;
            if exp >= 5.0 && rest >= 5.0 {
                chi2 += (obs - exp).powi(2) / exp;
                bins += 1;
                obs = 0.0;
                exp = 0.0;
            }
        }
        let tail_obs: f64 = obs;
        let tail_exp = exp + (1.0 - cum).max(0.0) * n as f64;
        chi2 += (tail_obs - tail_exp).powi(2) / tail_exp;
        bins += 1;
        (chi2, bins - 1)
    }

    /// Both branches follow the Poisson pmf: χ² below its 1e-6 upper quantile, from the
    /// Wilson–Hilferty approximation ν·(1 − 2/(9ν) + z·√(2/(9ν)))³ with z = 4.753 (the normal
    /// 1e-6 upper quantile). The draws are seeded, so the test is deterministic.
    #[test]
    fn draws_follow_the_poisson_pmf() {
        for (i, &lambda) in [0.3, 3.7, 9.99, 10.0, 40.0, 1234.5].iter().enumerate() {
            let (chi2, dof) = chi_square(lambda, 200_000, 0x5eed + i as u128);
            let nu = dof as f64;
            let h = 2.0 / (9.0 * nu);
            let limit = nu * (1.0 - h + 4.753 * h.sqrt()).powi(3);
            assert!(
                chi2 < limit,
                "λ={lambda}: χ²={chi2:.1} with {dof} dof (limit {limit:.1})"
            );
        }
    }

    #[test]
    fn fast_floor_is_floor() {
        for x in [
            0.0,
            0.3,
            1.0,
            2.999,
            12345.5,
            -0.2,
            -3.0,
            -7.5,
            1e17,
            f64::NEG_INFINITY,
        ] {
            assert_eq!(fast_floor(x), x.floor(), "{x}");
        }
    }

    #[test]
    fn zero_mean_gives_zero() {
        let mut rng = Pcg64Mcg::new(1);
        assert_eq!(Poisson::new(0.0).sample(&mut rng), 0.0);
    }
}
