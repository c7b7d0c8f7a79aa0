//! Allocation-free kernels for the small dense matrices of the filter criteria (J ≤ 8 basis
//! vectors, k ≤ 16 channels), so that millions of sets can be scored; checked against nalgebra.

/// The most channels a filter set of the search has (the core unmixer's limit).
pub const MAX_K: usize = specmux_core::unmix::MAX_CHANNELS;
use specmux_core::unmix::MAX_BASIS;

/// Smallest and largest eigenvalue of the leading n × n block of a symmetric matrix (cyclic
/// Jacobi rotations until the off-diagonal mass is negligible).
pub fn eigen_range(mut a: [[f64; MAX_BASIS]; MAX_BASIS], n: usize) -> (f64, f64) {
    let scale: f64 = (0..n)
        .map(|i| a[i][i].abs())
        .sum::<f64>()
        .max(f64::MIN_POSITIVE);
    for _ in 0..60 {
        let off: f64 = (0..n)
            .flat_map(|p| (p + 1..n).map(move |q| (p, q)))
            .map(|(p, q)| a[p][q] * a[p][q])
            .sum();
        if off.sqrt() <= 1e-15 * scale {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for r in 0..n {
                    let (arp, arq) = (a[r][p], a[r][q]);
                    a[r][p] = c * arp - s * arq;
                    a[r][q] = s * arp + c * arq;
                }
                for r in 0..n {
                    let (apr, aqr) = (a[p][r], a[q][r]);
                    a[p][r] = c * apr - s * aqr;
                    a[q][r] = s * apr + c * aqr;
                }
            }
        }
    }
    (0..n).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), i| {
        (lo.min(a[i][i]), hi.max(a[i][i]))
    })
}

/// M = H⁻¹Fᵀ for a symmetric positive definite n × n H and a k × n F (rows of `f`), by
/// Cholesky; None when H is not positive definite.
pub fn solve_spd(
    h: [[f64; MAX_BASIS]; MAX_BASIS],
    n: usize,
    f: &[[f64; MAX_BASIS]; MAX_K],
    k: usize,
) -> Option<[[f64; MAX_K]; MAX_BASIS]> {
    let mut l = [[0.0; MAX_BASIS]; MAX_BASIS];
    for i in 0..n {
        for jj in 0..=i {
            let s = h[i][jj] - (0..jj).map(|p| l[i][p] * l[jj][p]).sum::<f64>();
            if i == jj {
                if !(s > 0.0) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][jj] = s / l[jj][jj];
            }
        }
    }
    let mut m = [[0.0; MAX_K]; MAX_BASIS];
    for col in 0..k {
        // L y = f_col, then Lᵀ x = y.
        let mut y = [0.0; MAX_BASIS];
        for i in 0..n {
            y[i] = (f[col][i] - (0..i).map(|p| l[i][p] * y[p]).sum::<f64>()) / l[i][i];
        }
        for i in (0..n).rev() {
            let x = (y[i] - (i + 1..n).map(|p| l[p][i] * m[p][col]).sum::<f64>()) / l[i][i];
            m[i][col] = x;
        }
    }
    Some(m)
}
