//! Pixels across the lanes of a register: the joint iteration's per-pixel kernels run on
//! [`Lanes::WIDTH`] neighbouring pixels at once, one value of each in a lane — eight on AVX
//! registers, one on any CPU ([`Scalar`]) — so a pixel's J coefficients are J registers and
//! its sums over them are plain adds, not sums across a register. The kernels are written once
//! against [`Lanes`], with the same operations in the same order on both (no fused
//! multiply–add), so the same bits.

/// Pixels per AVX register, and the multiple the rows' padded width is rounded to.
pub(super) const LANES: usize = 8;

/// `[e(c) for c in 0..n]` of lane values `L::V`, as a loop: a closure (`array::from_fn`) is
/// compiled without the kernels' AVX target feature, so the lane operations in it would be
/// calls, not instructions.
macro_rules! fields {
    ($L:ty, $n:expr, |$c:ident| $e:expr) => {{
        let mut out = [<$L as Lanes>::splat(0.0); $n];
        for $c in 0..$n {
            out[$c] = $e;
        }
        out
    }};
}
pub(super) use fields;

/// The lane operations of the per-pixel kernels, on `WIDTH` pixels at once.
pub(super) trait Lanes {
    type V: Copy;
    /// Pixels per value (1 or [`LANES`]).
    const WIDTH: usize;
    fn splat(x: f32) -> Self::V;
    /// The first `WIDTH` values of `s`.
    fn load(s: &[f32]) -> Self::V;
    /// `v` into the first `WIDTH` values of `d`.
    fn store(d: &mut [f32], v: Self::V);
    fn add(a: Self::V, b: Self::V) -> Self::V;
    fn sub(a: Self::V, b: Self::V) -> Self::V;
    fn mul(a: Self::V, b: Self::V) -> Self::V;
    fn div(a: Self::V, b: Self::V) -> Self::V;
    fn sqrt(a: Self::V) -> Self::V;
    /// min(a, 0) lane by lane (0 where a is NaN, as f32::min).
    fn min0(a: Self::V) -> Self::V;
    /// x where a ≥ b, else y (y where either is NaN).
    fn select_ge(a: Self::V, b: Self::V, x: Self::V, y: Self::V) -> Self::V;
    /// x where a > b, else y (y where either is NaN).
    fn select_gt(a: Self::V, b: Self::V, x: Self::V, y: Self::V) -> Self::V;
    /// x in the lanes whose bit is set in `bits`, else y.
    fn select_bits(bits: u32, x: Self::V, y: Self::V) -> Self::V;
    /// Bit l set where lane l of a is ≥ 0 (not NaN).
    fn nonneg_bits(a: Self::V) -> u32;
    /// Bit l set where lane l is non-zero (NaN counts).
    fn nonzero_bits(v: Self::V) -> u32;
    /// 0 in the lanes where |v| < d, v elsewhere.
    fn flush(v: Self::V, d: f32) -> Self::V;

    /// All `WIDTH` bits.
    const ALL: u32 = (1 << Self::WIDTH) - 1;

    /// a + s·b.
    #[inline(always)]
    fn add_scaled(a: Self::V, s: Self::V, b: Self::V) -> Self::V {
        Self::add(a, Self::mul(s, b))
    }

    /// Bit l set where flag l of `f` (one byte a pixel) is non-zero.
    #[inline(always)]
    fn load_flags(f: &[u8]) -> u32 {
        f[..Self::WIDTH]
            .iter()
            .enumerate()
            .fold(0, |b, (l, &x)| b | ((x != 0) as u32) << l)
    }

    /// Flag l of `f` ← bit l of `bits`.
    #[inline(always)]
    fn store_flags(f: &mut [u8], bits: u32) {
        for (l, x) in f[..Self::WIDTH].iter_mut().enumerate() {
            *x = (bits >> l & 1) as u8;
        }
    }

    /// Σ of J ≤ 8 per-pixel terms in a fixed tree order, the terms past J taken as 0:
    /// (t₀ + t₄ + t₂ + t₆) + (t₁ + t₅ + t₃ + t₇), on every `WIDTH` (so the same bits).
    #[inline(always)]
    fn tree_sum<const J: usize>(t: [Self::V; J]) -> Self::V {
        let mut t8 = [Self::splat(0.0); LANES];
        t8[..J].copy_from_slice(&t);
        let half = fields!(Self, 4, |l| Self::add(t8[l], t8[l + 4]));
        Self::add(Self::add(half[0], half[2]), Self::add(half[1], half[3]))
    }

    /// The values of J fields at `x` (field c at `c·stride + x`).
    #[inline(always)]
    fn load_fields<const J: usize>(s: &[f32], stride: usize, x: usize) -> [Self::V; J] {
        fields!(Self, J, |c| Self::load(&s[c * stride + x..]))
    }

    /// `v` into J fields at `x` (field c at `c·stride + x`).
    #[inline(always)]
    fn store_fields<const J: usize>(d: &mut [f32], stride: usize, x: usize, v: [Self::V; J]) {
        for (c, vc) in v.into_iter().enumerate() {
            Self::store(&mut d[c * stride + x..], vc);
        }
    }
}

/// A per-pixel kernel written once over [`Lanes`]: `run` is instantiated for each.
pub(super) trait LaneKernel {
    fn run<L: Lanes>(self);
}

/// Run `k` on AVX registers when the CPU has AVX2, else one pixel at a time (the same
/// operations in the same order, so the same bits): the one place the kernels pick their lanes.
pub(super) fn dispatch<K: LaneKernel>(k: K) {
    #[cfg(test)]
    if tests::scalar_only() {
        return k.run::<Scalar>();
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, the one feature `on_avx` is compiled for.
        return unsafe { on_avx(k) };
    }
    k.run::<Scalar>()
}

/// `k` on [`Avx`], compiled with AVX2 enabled so the lane operations inline as AVX code.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn on_avx<K: LaneKernel>(k: K) {
    k.run::<Avx>()
}

/// [`Lanes`] one pixel wide, on plain f32: any CPU.
pub(super) struct Scalar;

impl Lanes for Scalar {
    type V = f32;
    const WIDTH: usize = 1;
    #[inline(always)]
    fn splat(x: f32) -> f32 {
        x
    }
    #[inline(always)]
    fn load(s: &[f32]) -> f32 {
        s[0]
    }
    #[inline(always)]
    fn store(d: &mut [f32], v: f32) {
        d[0] = v;
    }
    #[inline(always)]
    fn add(a: f32, b: f32) -> f32 {
        a + b
    }
    #[inline(always)]
    fn sub(a: f32, b: f32) -> f32 {
        a - b
    }
    #[inline(always)]
    fn mul(a: f32, b: f32) -> f32 {
        a * b
    }
    #[inline(always)]
    fn div(a: f32, b: f32) -> f32 {
        a / b
    }
    #[inline(always)]
    fn sqrt(a: f32) -> f32 {
        a.sqrt()
    }
    #[inline(always)]
    fn min0(a: f32) -> f32 {
        a.min(0.0)
    }
    #[inline(always)]
    fn select_ge(a: f32, b: f32, x: f32, y: f32) -> f32 {
        if a >= b {
            x
        } else {
            y
        }
    }
    #[inline(always)]
    fn select_gt(a: f32, b: f32, x: f32, y: f32) -> f32 {
        if a > b {
            x
        } else {
            y
        }
    }
    #[inline(always)]
    fn select_bits(bits: u32, x: f32, y: f32) -> f32 {
        if bits & 1 != 0 {
            x
        } else {
            y
        }
    }
    #[inline(always)]
    fn nonneg_bits(a: f32) -> u32 {
        (a >= 0.0) as u32
    }
    #[inline(always)]
    fn nonzero_bits(v: f32) -> u32 {
        (v != 0.0) as u32
    }
    #[inline(always)]
    fn flush(v: f32, d: f32) -> f32 {
        if v.abs() < d {
            0.0
        } else {
            v
        }
    }
}

/// [`Lanes`] on AVX registers, eight pixels; only for code compiled with AVX2 enabled and run
/// on a CPU that has it (`on_avx`, picked at run time by `dispatch`).
#[cfg(target_arch = "x86_64")]
pub(super) struct Avx;

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

// SAFETY (every method): `Avx` is only used inside functions compiled with AVX2 enabled,
// which run only after `is_x86_feature_detected!("avx2")`; loads and stores touch the
// first 8 values of a slice whose length is checked first.
#[cfg(target_arch = "x86_64")]
impl Lanes for Avx {
    type V = __m256;
    const WIDTH: usize = LANES;
    #[inline(always)]
    fn splat(x: f32) -> __m256 {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    fn load(s: &[f32]) -> __m256 {
        let s = &s[..LANES];
        unsafe { _mm256_loadu_ps(s.as_ptr()) }
    }
    #[inline(always)]
    fn store(d: &mut [f32], v: __m256) {
        let d = &mut d[..LANES];
        unsafe { _mm256_storeu_ps(d.as_mut_ptr(), v) }
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
    fn div(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_div_ps(a, b) }
    }
    #[inline(always)]
    fn sqrt(a: __m256) -> __m256 {
        unsafe { _mm256_sqrt_ps(a) }
    }
    #[inline(always)]
    fn min0(a: __m256) -> __m256 {
        // minps returns its second operand (0) when a is NaN, as f32::min(NaN, 0) does.
        unsafe { _mm256_min_ps(a, _mm256_setzero_ps()) }
    }
    #[inline(always)]
    fn select_ge(a: __m256, b: __m256, x: __m256, y: __m256) -> __m256 {
        unsafe { _mm256_blendv_ps(y, x, _mm256_cmp_ps(a, b, _CMP_GE_OQ)) }
    }
    #[inline(always)]
    fn select_gt(a: __m256, b: __m256, x: __m256, y: __m256) -> __m256 {
        unsafe { _mm256_blendv_ps(y, x, _mm256_cmp_ps(a, b, _CMP_GT_OQ)) }
    }
    #[inline(always)]
    fn select_bits(bits: u32, x: __m256, y: __m256) -> __m256 {
        unsafe {
            let lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bit);
            let mask = _mm256_cmpeq_epi32(set, lane_bit);
            _mm256_blendv_ps(y, x, _mm256_castsi256_ps(mask))
        }
    }
    #[inline(always)]
    fn nonneg_bits(a: __m256) -> u32 {
        unsafe { _mm256_movemask_ps(_mm256_cmp_ps(a, _mm256_setzero_ps(), _CMP_GE_OQ)) as u32 }
    }
    #[inline(always)]
    fn nonzero_bits(v: __m256) -> u32 {
        unsafe { _mm256_movemask_ps(_mm256_cmp_ps(v, _mm256_setzero_ps(), _CMP_NEQ_UQ)) as u32 }
    }
    #[inline(always)]
    fn flush(v: __m256, d: f32) -> __m256 {
        unsafe {
            let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), v);
            _mm256_andnot_ps(_mm256_cmp_ps(abs, _mm256_set1_ps(d), _CMP_LT_OQ), v)
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use std::cell::Cell;

    thread_local! {
        static SCALAR_ONLY: Cell<bool> = const { Cell::new(false) };
    }

    /// True while `on_scalar_lanes` runs its closure on this thread.
    pub fn scalar_only() -> bool {
        SCALAR_ONLY.with(Cell::get)
    }

    /// `f()` with `dispatch` picking `Scalar` on this thread (kernels run under rayon take
    /// other threads: call with a one-thread pool).
    pub fn on_scalar_lanes<T>(f: impl FnOnce() -> T) -> T {
        SCALAR_ONLY.with(|s| s.set(true));
        let out = f();
        SCALAR_ONLY.with(|s| s.set(false));
        out
    }

    /// The kernels' operations on `L`, over eight pixels, on fixed inputs with a NaN and
    /// signed zeros among them, as bit patterns.
    fn ops<L: Lanes>() -> Vec<u32> {
        let a = [1.5, -2.0, 3.25, 0.0, -0.5, 7.0, f32::NAN, -0.0];
        let b = [0.1, 0.2, -0.3, 0.4, -5.0, 6.0, 0.7, -0.8];
        let flags = [1u8, 0, 0, 3, 0, 0, 0, 1];
        let mut out = vec![0.0f32; LANES * 9];
        let mut bits = Vec::new();
        let mut stored = [9u8; LANES];
        for x in (0..LANES).step_by(L::WIDTH) {
            let (va, vb) = (L::load(&a[x..]), L::load(&b[x..]));
            let fields: [L::V; 7] = [
                L::add_scaled(va, L::splat(0.3), vb),
                L::div(vb, L::sqrt(L::mul(vb, vb))),
                L::min0(va),
                L::select_ge(va, vb, va, L::splat(-1.0)),
                L::select_gt(vb, L::splat(0.2), vb, va),
                L::flush(vb, 0.35),
                L::select_bits(0b1010_0110 >> x, va, vb),
            ];
            L::store_fields(&mut out, LANES, x, fields);
            let sums = [L::sub(va, vb), vb, va, L::splat(2.0), vb, vb, vb];
            L::store(&mut out[7 * LANES + x..], L::tree_sum(sums));
            L::store(&mut out[8 * LANES + x..], L::tree_sum([vb, va]));
            bits.extend([
                L::nonneg_bits(va) << x,
                L::nonzero_bits(va) << x,
                L::load_flags(&flags[x..]) << x,
            ]);
            L::store_flags(&mut stored[x..], L::load_flags(&flags[x..]));
        }
        let words = |k: usize| bits.iter().skip(k).step_by(3).fold(0, |s, b| s | b);
        let mut all: Vec<u32> = out.iter().map(|v| v.to_bits()).collect();
        all.extend([words(0), words(1), words(2)]);
        all.extend(stored.map(u32::from));
        all
    }

    #[test]
    fn scalar_lanes_by_hand() {
        let out = ops::<Scalar>();
        let f = |field: usize, l: usize| f32::from_bits(out[field * LANES + l]);
        assert_eq!(f(0, 0), 1.5 + 0.3 * 0.1);
        assert_eq!((f(1, 2), f(1, 4)), (-1.0, -1.0));
        assert_eq!((f(2, 0), f(2, 1), f(2, 6)), (0.0, -2.0, 0.0));
        assert_eq!((f(3, 0), f(3, 1), f(3, 6)), (1.5, -1.0, -1.0));
        assert_eq!((f(4, 0), f(4, 1), f(4, 3)), (1.5, -2.0, 0.4));
        assert_eq!((f(5, 0), f(5, 3), f(5, 4)), (0.0, 0.4, -5.0));
        let picked: Vec<f32> = (0..4).map(|l| f(6, l)).collect();
        assert_eq!(picked, [0.1, -2.0, 3.25, 0.4]);
        // (t₀ + t₄ + t₂ + t₆) + (t₁ + t₅ + t₃ + t₇) with t₇ = 0.
        let (a, b) = (1.5f32, 0.1f32);
        assert_eq!(f(7, 0), (((a - b) + b) + (a + b)) + ((b + b) + (2.0 + 0.0)));
        assert_eq!(
            f(8, 0),
            ((b + 0.0) + (0.0 + 0.0)) + ((a + 0.0) + (0.0 + 0.0))
        );
        let n = LANES * 9;
        // Non-negative: 1.5, 3.25, 0, 7, −0 (−0 ≥ 0); non-zero: all but the zeros (NaN counts).
        assert_eq!(out[n..n + 3], [0b1010_1101, 0b0111_0111, 0b1000_1001]);
        assert_eq!(out[n + 3..], [1, 0, 0, 1, 0, 0, 0, 1]);
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx_lanes_are_the_scalar_lanes_to_the_bit() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        struct Ops<'a>(&'a mut Vec<u32>);
        impl LaneKernel for Ops<'_> {
            fn run<L: Lanes>(self) {
                *self.0 = ops::<L>();
            }
        }
        let mut avx = Vec::new();
        // SAFETY: the CPU has AVX2.
        unsafe { on_avx(Ops(&mut avx)) };
        assert_eq!(avx, ops::<Scalar>());
    }
}
