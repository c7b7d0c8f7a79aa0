//! Eight f32 lanes holding one pixel's J ≤ 8 basis coefficients (zero-padded) or eight of its
//! bands, so the joint iteration's per-pixel work is whole-register operations. The kernels are
//! written once against [`Lanes`]; [`Portable`] runs them on any CPU and [`Avx`] on AVX
//! registers, with the same operations in the same order (no fused multiply–add), so the
//! same bits.

/// f32 lanes of one AVX register; also the band loops' padding.
pub(super) const LANES: usize = 8;

/// One pixel's coefficients (or a column of a J × J matrix) in the first J lanes, zeros after.
pub(super) type Lane = [f32; LANES];

/// The lane operations of the per-pixel kernels.
pub(super) trait Lanes {
    type V: Copy;
    fn splat(x: f32) -> Self::V;
    /// The first J values of `s`, zero-padded.
    fn load<const J: usize>(s: &[f32]) -> Self::V;
    /// The first J lanes of `v` into `d`.
    fn store<const J: usize>(d: &mut [f32], v: Self::V);
    fn add(a: Self::V, b: Self::V) -> Self::V;
    fn sub(a: Self::V, b: Self::V) -> Self::V;
    fn mul(a: Self::V, b: Self::V) -> Self::V;
    /// min(a, 0) lane by lane.
    fn min0(a: Self::V) -> Self::V;
    /// a where s ≥ 0, else b.
    fn select_nonneg(s: Self::V, a: Self::V, b: Self::V) -> Self::V;
    /// Σ of the lanes in a fixed tree order: (v₀ + v₄ + v₂ + v₆) + (v₁ + v₅ + v₃ + v₇).
    fn sum(v: Self::V) -> f32;
    /// The number of non-zero lanes.
    fn nonzero(v: Self::V) -> u32;
    /// 0 in the lanes where |v| < d, v elsewhere.
    fn flush(v: Self::V, d: f32) -> Self::V;
    fn to_array(v: Self::V) -> Lane;

    /// a + s·b.
    #[inline(always)]
    fn add_scaled(a: Self::V, s: f32, b: Self::V) -> Self::V {
        Self::add(a, Self::mul(Self::splat(s), b))
    }

    /// Σ_c cols[c]·v[c] over the first J columns: a J × J matrix (by columns) times v.
    #[inline(always)]
    fn mat_vec<const J: usize>(cols: &[Lane], v: Self::V) -> Self::V {
        let v = Self::to_array(v);
        let mut out = Self::splat(0.0);
        for (col, &vc) in cols[..J].iter().zip(&v) {
            out = Self::add(out, Self::mul(Self::load::<LANES>(col), Self::splat(vc)));
        }
        out
    }

    /// Σ_k r_k·rows[k]: Bᵀr for B given by its rows (one lane each), skipping the blocks of
    /// `LANES` bands where r is zero (adding r_k·B_k = 0 there would change nothing).
    #[inline(always)]
    fn rows_t_times(rows: &[Lane], r: &[f32]) -> Self::V {
        let mut out = Self::splat(0.0);
        for (block, rb) in rows.chunks_exact(LANES).zip(r.chunks_exact(LANES)) {
            if Self::nonzero(Self::load::<LANES>(rb)) == 0 {
                continue;
            }
            for (row, &rk) in block.iter().zip(rb) {
                out = Self::add(out, Self::mul(Self::load::<LANES>(row), Self::splat(rk)));
            }
        }
        out
    }
}

/// A per-pixel kernel written once over [`Lanes`]: `run` is instantiated for each.
pub(super) trait LaneKernel {
    fn run<L: Lanes>(self);
}

/// Run `k` on AVX registers when the CPU has AVX2, else on plain arrays (the same operations in
/// the same order, so the same bits): the one place the kernels pick their lanes.
pub(super) fn dispatch<K: LaneKernel>(k: K) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, the one feature `on_avx` is compiled for.
        return unsafe { on_avx(k) };
    }
    k.run::<Portable>()
}

/// `k` on [`Avx`], compiled with AVX2 enabled so the lane operations inline as AVX code.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn on_avx<K: LaneKernel>(k: K) {
    k.run::<Avx>()
}

/// [`Lanes`] on plain arrays: any CPU.
pub(super) struct Portable;

impl Lanes for Portable {
    type V = Lane;
    #[inline(always)]
    fn splat(x: f32) -> Lane {
        [x; LANES]
    }
    #[inline(always)]
    fn load<const J: usize>(s: &[f32]) -> Lane {
        let mut v = [0.0; LANES];
        v[..J].copy_from_slice(&s[..J]);
        v
    }
    #[inline(always)]
    fn store<const J: usize>(d: &mut [f32], v: Lane) {
        d[..J].copy_from_slice(&v[..J]);
    }
    #[inline(always)]
    fn add(a: Lane, b: Lane) -> Lane {
        std::array::from_fn(|l| a[l] + b[l])
    }
    #[inline(always)]
    fn sub(a: Lane, b: Lane) -> Lane {
        std::array::from_fn(|l| a[l] - b[l])
    }
    #[inline(always)]
    fn mul(a: Lane, b: Lane) -> Lane {
        std::array::from_fn(|l| a[l] * b[l])
    }
    #[inline(always)]
    fn min0(a: Lane) -> Lane {
        a.map(|v| v.min(0.0))
    }
    #[inline(always)]
    fn select_nonneg(s: Lane, a: Lane, b: Lane) -> Lane {
        std::array::from_fn(|l| if s[l] >= 0.0 { a[l] } else { b[l] })
    }
    #[inline(always)]
    fn sum(v: Lane) -> f32 {
        let half: [f32; 4] = std::array::from_fn(|l| v[l] + v[l + 4]);
        (half[0] + half[2]) + (half[1] + half[3])
    }
    #[inline(always)]
    fn nonzero(v: Lane) -> u32 {
        v.iter().map(|&x| (x != 0.0) as u32).sum()
    }
    #[inline(always)]
    fn flush(v: Lane, d: f32) -> Lane {
        v.map(|x| if x.abs() < d { 0.0 } else { x })
    }
    #[inline(always)]
    fn to_array(v: Lane) -> Lane {
        v
    }
}

/// [`Lanes`] on AVX registers; only for code compiled with AVX2 enabled and run on a CPU that
/// has it (`on_avx`, picked at run time by `dispatch`).
#[cfg(target_arch = "x86_64")]
pub(super) struct Avx;

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

// Partial loads and stores touch exactly the J values (no masked moves): a masked store
// followed by a load of the next pixel's overlapping 32 bytes cannot be forwarded and
// stalls the loop (it did: a quarter of the primal step's samples on one load).

/// s[0..n] (n ≤ 4, n ≤ s.len(), checked by the caller) in the low lanes, zeros above.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn load_part(s: *const f32, n: usize) -> __m128 {
    match n {
        0 => _mm_setzero_ps(),
        1 => _mm_load_ss(s),
        2 => _mm_castpd_ps(_mm_load_sd(s.cast())),
        3 => _mm_movelh_ps(_mm_castpd_ps(_mm_load_sd(s.cast())), _mm_load_ss(s.add(2))),
        _ => _mm_loadu_ps(s),
    }
}

/// The low n lanes of v (n ≤ 4, n ≤ d.len(), checked by the caller) into d[0..n].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn store_part(d: *mut f32, n: usize, v: __m128) {
    match n {
        0 => {}
        1 => _mm_store_ss(d, v),
        2 => _mm_store_sd(d.cast(), _mm_castps_pd(v)),
        3 => {
            _mm_store_sd(d.cast(), _mm_castps_pd(v));
            _mm_store_ss(d.add(2), _mm_movehl_ps(v, v));
        }
        _ => _mm_storeu_ps(d, v),
    }
}

// SAFETY (every method): `Avx` is only used inside functions compiled with AVX2 enabled,
// which run only after `is_x86_feature_detected!("avx2")`; loads and stores touch the
// first J (≤ the slice's length, checked) values only.
#[cfg(target_arch = "x86_64")]
impl Lanes for Avx {
    type V = __m256;
    #[inline(always)]
    fn splat(x: f32) -> __m256 {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    fn load<const J: usize>(s: &[f32]) -> __m256 {
        let s = &s[..J];
        unsafe {
            let lo = load_part(s.as_ptr(), J.min(4));
            let hi = load_part(s.as_ptr().add(J.min(4)), J.saturating_sub(4));
            _mm256_set_m128(hi, lo)
        }
    }
    #[inline(always)]
    fn store<const J: usize>(d: &mut [f32], v: __m256) {
        let d = &mut d[..J];
        unsafe {
            store_part(d.as_mut_ptr(), J.min(4), _mm256_castps256_ps128(v));
            let hi = _mm256_extractf128_ps(v, 1);
            store_part(d.as_mut_ptr().add(J.min(4)), J.saturating_sub(4), hi);
        }
    }
    #[inline(always)]
    fn add(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_add_ps(a, b) }
    }
    #[inline(always)]
    fn sub(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    fn mul(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    fn min0(a: __m256) -> __m256 {
        // minps returns its second operand (0) when a is NaN, as f32::min(NaN, 0) does.
        unsafe { _mm256_min_ps(a, _mm256_setzero_ps()) }
    }
    #[inline(always)]
    fn select_nonneg(s: __m256, a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_blendv_ps(b, a, _mm256_cmp_ps(s, _mm256_setzero_ps(), _CMP_GE_OQ)) }
    }
    #[inline(always)]
    fn sum(v: __m256) -> f32 {
        unsafe {
            let half = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
            let pairs = _mm_add_ps(half, _mm_movehl_ps(half, half));
            _mm_cvtss_f32(_mm_add_ss(pairs, _mm_movehdup_ps(pairs)))
        }
    }
    #[inline(always)]
    fn nonzero(v: __m256) -> u32 {
        unsafe {
            let ne = _mm256_cmp_ps(v, _mm256_setzero_ps(), _CMP_NEQ_UQ);
            (_mm256_movemask_ps(ne) as u32).count_ones()
        }
    }
    #[inline(always)]
    fn flush(v: __m256, d: f32) -> __m256 {
        unsafe {
            let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
            _mm256_andnot_ps(_mm256_cmp_ps(abs, _mm256_set1_ps(d), _CMP_LT_OQ), v)
        }
    }
    #[inline(always)]
    fn to_array(v: __m256) -> Lane {
        let mut out = [0.0; LANES];
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), v) };
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernels' operations on `L`, on fixed inputs (NaN-free), as plain arrays.
    fn ops<L: Lanes>() -> Vec<Lane> {
        let a = L::load::<6>(&[1.5, -2.0, 3.25, 0.0, -0.5, 7.0, 99.0]);
        let b = L::load::<LANES>(&[0.1, 0.2, -0.3, 0.4, -5.0, 6.0, 0.7, -0.8]);
        let rows: Vec<Lane> = (0..16)
            .map(|k| [k as f32, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5])
            .collect();
        let mut r = vec![0.0f32; 16];
        (r[9], r[15]) = (-2.0, 0.5);
        let cols = [
            [1.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [2.0, 4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ];
        let mut stored = [7.0f32; LANES];
        L::store::<3>(&mut stored, b);
        vec![
            L::to_array(L::add_scaled(a, 0.3, b)),
            L::to_array(L::sub(a, b)),
            L::to_array(L::min0(b)),
            L::to_array(L::select_nonneg(b, a, L::splat(-1.0))),
            [
                L::sum(b),
                L::sum(a),
                L::nonzero(a) as f32,
                L::nonzero(b) as f32,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
            L::to_array(L::mat_vec::<2>(&cols, L::load::<2>(&[1.0, -1.0]))),
            L::to_array(L::rows_t_times(&rows, &r)),
            stored,
            L::to_array(L::flush(b, 0.35)),
        ]
    }

    #[test]
    fn portable_lanes_by_hand() {
        let out = ops::<Portable>();
        assert_eq!(out[1][..7], [1.4, -2.2, 3.55, -0.4, 4.5, 1.0, -0.7]);
        assert_eq!(out[2], [0.0, 0.0, -0.3, 0.0, -5.0, 0.0, 0.0, -0.8]);
        assert_eq!(out[3], [1.5, -2.0, -1.0, 0.0, -1.0, 7.0, 0.0, -1.0]);
        assert_eq!(out[4][1..4], [9.25, 5.0, 8.0]);
        // [[1, 2], [3, 4]] by columns, times (1, −1).
        assert_eq!(out[5][..3], [-1.0, -1.0, 0.0]);
        // Bᵀr with B_k = (k, 1, 0 …, ½): r non-zero in the second block only.
        assert_eq!(out[6][..3], [9.0 * -2.0 + 15.0 * 0.5, -1.5, 0.0]);
        assert_eq!(out[6][7], -0.75);
        assert_eq!(out[7], [0.1, 0.2, -0.3, 7.0, 7.0, 7.0, 7.0, 7.0]);
        assert_eq!(out[8], [0.0, 0.0, 0.0, 0.4, -5.0, 6.0, 0.7, -0.8]);
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx_lanes_are_the_portable_lanes_to_the_bit() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        struct Ops<'a>(&'a mut Vec<Lane>);
        impl LaneKernel for Ops<'_> {
            fn run<L: Lanes>(self) {
                *self.0 = ops::<L>();
            }
        }
        let mut avx = Vec::new();
        // SAFETY: the CPU has AVX2.
        unsafe { on_avx(Ops(&mut avx)) };
        let bits =
            |v: &Vec<Lane>| -> Vec<u32> { v.iter().flatten().map(|x| x.to_bits()).collect() };
        assert_eq!(bits(&avx), bits(&ops::<Portable>()));
    }
}
