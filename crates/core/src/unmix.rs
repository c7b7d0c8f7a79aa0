//! Per-pixel spectral unmixing (the paper's eq. "quadraticProgramming"):
//! `argmin_α ‖x̂ − Fα‖² + η‖D₂Bα‖²  s.t. Bα ≥ 0`, with F the channel response to each basis
//! vector, B the spectral basis (bands × J) and D₂ the second difference across bands.
//!
//! The Hessian H = FᵀF + η BᵀD₂ᵀD₂B is the same for every pixel, so it is factored once per rig:
//! the unconstrained cube is a fixed linear map r = P x̂ (P = B H⁻¹Fᵀ), and only the pixels where
//! that map gives a negative band go through an exact active-set method (Goldfarb–Idnani's dual
//! method, `dual.rs`, which starts from that unconstrained solution). D₂ is taken in band-index
//! units, so η carries the grid spacing (η_nm = η · Δλ⁴).

// `!(x > y)` is deliberate: it is true for NaN too. The small dense kernels index by position.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use crate::cube::all_finite;
use crate::error::Error;
use crate::error::Result;
use crate::Cube;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::Serialize;

mod dual;

use dual::band_blocks;
use dual::lower;
use dual::BandQp;
use dual::WorkingSet;
use dual::BAND_BLOCK;
pub use dual::{MAX_BANDS, MAX_BASIS, MAX_ITERATIONS};

/// Largest number of channels x̂ per pixel.
pub const MAX_CHANNELS: usize = 16;
/// Largest condition number of H accepted by [`Unmixer::new`].
pub const MAX_CONDITION: f64 = 1e12;
/// Rows of the image handled by one rayon task in [`Unmixer::unmix`].
const ROWS_PER_CHUNK: usize = 8;
/// Pixels per register block of the projection r = P x̂.
const LANES: usize = 8;
/// Pixels per block of the unmixing: one 64-byte cache line of every band plane, so that a
/// block's bands are written once, whole lines at a time.
const LINE: usize = 16;

/// The band values of one block of pixels, band by band.
type Block = [[f32; LINE]; MAX_BANDS];

/// The unmixing problem of one rig, factored once and shared by all pixels.
#[derive(Clone, Debug)]
pub struct Unmixer {
    /// Basis vectors J.
    n: usize,
    /// Bands (constraints).
    m: usize,
    /// Channels.
    c: usize,
    /// H, row-major n × n (for objective values).
    h: Vec<f64>,
    /// M = H⁻¹Fᵀ, row-major n × c: α_unc = M x̂.
    mx: Vec<f64>,
    /// diag(gain)·P, P = B M, row-major m × c, in f32 for the batched fast path.
    p32: Vec<f32>,
    /// Per-band output gains (all 1 unless set by [`Unmixer::with_output_gains`]).
    gain: Vec<f64>,
    /// B by columns: `bt[j][k]` = basis vector j at band k (the spectrum Bα as a sum of
    /// scaled columns, which vectorises over the bands).
    bt: Vec<[f64; MAX_BANDS]>,
    /// L⁻ᵀ for H = LLᵀ, column-major and zero-padded: the GPU kernel's starting factor.
    linv_t: [[f64; MAX_BASIS]; MAX_BASIS],
    /// The QP in band space on G = B H⁻¹ Bᵀ that the constrained pixels are solved by.
    qp: BandQp,
    /// H⁻¹ b_kᵀ for each band k, band-major m × n: α = α_u + Σ μ_k H⁻¹ b_kᵀ.
    hinv_bt: Vec<f64>,
    condition: f64,
}

/// The factored problem as plain tables, for another implementation of the same method (the
/// GPU backend's kernel, which runs Goldfarb–Idnani in its textbook form on the factor L⁻ᵀ
/// where [`Unmixer::solve_pixel`] runs it in band space): the same pivots, the same minimiser.
pub struct UnmixTables<'a> {
    /// M = H⁻¹Fᵀ, row-major J × channels: α_unc = M x̂.
    pub unconstrained: &'a [f64],
    /// diag(gain)·B·M, row-major bands × channels, in f32 (the fast path's map x̂ → r).
    pub projection: &'a [f32],
    /// B by columns, each zero-padded to `MAX_BANDS`.
    pub basis_columns: &'a [[f64; MAX_BANDS]],
    /// 1/‖b_k‖_{H⁻¹} for each band (0 for a zero row).
    pub band_inv_norm: &'a [f64],
    /// Per-band output gains.
    pub gains: &'a [f64],
    /// L⁻ᵀ for H = LLᵀ, column-major (`linv_t[col][row]`), zero-padded.
    pub linv_t: &'a [[f64; MAX_BASIS]; MAX_BASIS],
}

/// How one pixel was solved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveInfo {
    /// Active-set iterations (0: the unconstrained solution was feasible).
    pub iterations: usize,
    /// Number of bands held at zero in the final working set.
    pub active: usize,
    bands: [usize; MAX_BASIS],
    multipliers: [f64; MAX_BASIS],
}

impl SolveInfo {
    /// How a pixel was solved: `steps` of the dual method ending in the working set `ws`, or
    /// None where the unconstrained minimiser was feasible (no step, no band held).
    fn new(steps: Option<usize>, ws: &WorkingSet) -> SolveInfo {
        let mut info = SolveInfo {
            iterations: 0,
            active: 0,
            bands: [0; MAX_BASIS],
            multipliers: [0.0; MAX_BASIS],
        };
        if let Some(steps) = steps {
            info.iterations = steps;
            info.active = ws.bands().len();
            info.bands[..info.active].copy_from_slice(ws.bands());
            info.multipliers[..info.active].copy_from_slice(ws.multipliers());
        }
        info
    }

    /// The bands of the final working set (where B α = 0 is enforced).
    pub fn active_bands(&self) -> &[usize] {
        &self.bands[..self.active]
    }

    /// Lagrange multipliers μ ≥ 0 of the working set, in the objective ½αᵀHα − (Fᵀx̂)ᵀα:
    /// Hα − Fᵀx̂ = Σ_k μ_k b_{band_k}ᵀ.
    pub fn multipliers(&self) -> &[f64] {
        &self.multipliers[..self.active]
    }
}

/// Counts over one unmixed cube.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct UnmixStats {
    pub pixels: usize,
    /// Pixels whose unconstrained spectrum went negative somewhere and were solved exactly.
    pub constrained_pixels: usize,
    /// Of those, pixels where the non-negativity bound is active at the solution.
    pub bound_pixels: usize,
    /// Active-set steps of one pixel, at most (each band a warm start drops counts as one).
    pub max_iterations: usize,
    /// Active-set steps over the cube.
    pub total_iterations: usize,
}

/// The second-difference matrix ((bands − 2) × bands), rows [1, −2, 1]; empty below 3 bands.
pub fn second_difference(bands: usize) -> DMatrix<f64> {
    let rows = bands.saturating_sub(2);
    DMatrix::from_fn(rows, bands, |i, j| match j.wrapping_sub(i) {
        0 | 2 => 1.0,
        1 => -2.0,
        _ => 0.0,
    })
}

/// η(D₂B)ᵀ(D₂B): the paper's curvature penalty on the spectrum Bα as a J × J quadratic term.
pub fn curvature(b: &DMatrix<f64>, eta: f64) -> DMatrix<f64> {
    let d2b = second_difference(b.nrows()) * b;
    d2b.transpose() * d2b * eta
}

impl Unmixer {
    /// Factor the problem for channel matrix `f` (channels × J) and basis `b` (bands × J).
    pub fn new(f: &DMatrix<f64>, b: &DMatrix<f64>, eta: f64) -> Result<Unmixer> {
        if !eta.is_finite() || eta < 0.0 {
            return Err(Error::Numerical(format!(
                "unmixing weight η = {eta}: must be finite and ≥ 0"
            )));
        }
        let (c, n, m) = (f.nrows(), f.ncols(), b.nrows());
        if b.ncols() != n {
            return Err(Error::Shape(format!(
                "channel matrix F has {n} basis columns, basis B has {}",
                b.ncols()
            )));
        }
        if !(1..=MAX_BASIS).contains(&n)
            || !(1..=MAX_BANDS).contains(&m)
            || !(1..=MAX_CHANNELS).contains(&c)
        {
            return Err(Error::Shape(format!(
                "unmixing needs 1..={MAX_BASIS} basis vectors, 1..={MAX_BANDS} bands and \
                 1..={MAX_CHANNELS} channels; got {n}, {m} and {c}"
            )));
        }
        if f.iter().chain(b.iter()).any(|v| !v.is_finite()) {
            return Err(Error::Numerical("F or B holds a non-finite value".into()));
        }
        let h = f.transpose() * f + curvature(b, eta);
        let eig = nalgebra::SymmetricEigen::new(h.clone());
        let (lo, hi) = (eig.eigenvalues.min(), eig.eigenvalues.max());
        let condition = if lo > 0.0 { hi / lo } else { f64::INFINITY };
        if !(condition <= MAX_CONDITION) {
            return Err(Error::Numerical(format!(
                "unmixing Hessian FᵀF + η BᵀD₂ᵀD₂B (η = {eta}) is singular or ill-conditioned: \
                 condition number {condition:.3e} > {MAX_CONDITION:e}, eigenvalues {lo:.3e}..{hi:.3e}; \
                 use more independent filters or a larger η"
            )));
        }
        let chol = nalgebra::Cholesky::new(h.clone())
            .ok_or_else(|| Error::Numerical("unmixing Hessian is not positive definite".into()))?;
        let mmat = chol.solve(&f.transpose()); // n × c
        let linv = chol
            .l()
            .solve_lower_triangular(&DMatrix::identity(n, n))
            .ok_or_else(|| Error::Numerical("unmixing Hessian factor is singular".into()))?;
        // Column `col` of L⁻ᵀ is row `col` of L⁻¹.
        let mut linv_t = [[0.0; MAX_BASIS]; MAX_BASIS];
        for (col, column) in linv_t[..n].iter_mut().enumerate() {
            for (row, v) in column[..n].iter_mut().enumerate() {
                *v = linv[(col, row)];
            }
        }
        let p = b * &mmat; // m × c
        let hinv_bt = chol.solve(&b.transpose()); // n × m
        let g_bands = b * &hinv_bt; // m × m
        let row_major = |a: &DMatrix<f64>| -> Vec<f64> {
            (0..a.nrows())
                .flat_map(|i| (0..a.ncols()).map(move |j| a[(i, j)]))
                .collect()
        };
        Ok(Unmixer {
            n,
            m,
            c,
            h: row_major(&h),
            mx: row_major(&mmat),
            p32: row_major(&p).iter().map(|&v| v as f32).collect(),
            gain: vec![1.0; m],
            bt: b.column_iter().map(|col| padded(m, |k| col[k])).collect(),
            linv_t,
            qp: BandQp {
                n,
                m,
                g_bands: g_bands
                    .row_iter()
                    .map(|row| padded(m, |k| row[k]))
                    .collect(),
                b_inv_norm: padded(m, |k| {
                    let norm = (linv.rows(0, n) * b.row(k).transpose()).norm();
                    if norm > 0.0 {
                        1.0 / norm
                    } else {
                        0.0
                    }
                }),
            },
            hinv_bt: row_major(&hinv_bt.transpose()),
            condition,
        })
    }

    pub fn channels(&self) -> usize {
        self.c
    }

    pub fn bands(&self) -> usize {
        self.m
    }

    pub fn basis_len(&self) -> usize {
        self.n
    }

    /// The factored problem's tables (see [`UnmixTables`]).
    pub fn tables(&self) -> UnmixTables<'_> {
        UnmixTables {
            unconstrained: &self.mx,
            projection: &self.p32,
            basis_columns: &self.bt,
            band_inv_norm: &self.qp.b_inv_norm[..self.m],
            gains: &self.gain,
            linv_t: &self.linv_t,
        }
    }

    /// Condition number of H.
    pub fn condition(&self) -> f64 {
        self.condition
    }

    /// Write diag(gains)·Bα instead of Bα (the light of a radiance scene, `Rig::light_gains`),
    /// in the same pass. The gains must be finite and > 0, so the constraint Bα ≥ 0 is unchanged.
    pub fn with_output_gains(mut self, gains: &[f64]) -> Result<Unmixer> {
        if gains.len() != self.m {
            return Err(Error::Shape(format!(
                "{} output gains for {} bands",
                gains.len(),
                self.m
            )));
        }
        if let Some((k, g)) = gains
            .iter()
            .enumerate()
            .find(|(_, g)| !(g.is_finite() && **g > 0.0))
        {
            return Err(Error::Numerical(format!(
                "output gain of band {k} is {g}; it must be finite and > 0"
            )));
        }
        for ((row, &g), &g0) in self.p32.chunks_exact_mut(self.c).zip(gains).zip(&self.gain) {
            row.iter_mut()
                .for_each(|v| *v = (*v as f64 / g0 * g) as f32);
        }
        self.gain = gains.to_vec();
        Ok(self)
    }

    /// The objective ½αᵀHα − (Fᵀx̂)ᵀα, written with M: Fᵀx̂ = H M x̂. It equals half of
    /// ‖x̂ − Fα‖² + η‖D₂Bα‖² − ‖x̂‖².
    pub fn objective(&self, xhat: &[f64], alpha: &[f64]) -> f64 {
        let n = self.n;
        let au = self.unconstrained_alpha(xhat);
        let mut obj = 0.0;
        for i in 0..n {
            let hrow = &self.h[i * n..(i + 1) * n];
            let ha: f64 = hrow.iter().zip(alpha).map(|(h, a)| h * a).sum();
            let hu: f64 = hrow.iter().zip(&au[..n]).map(|(h, a)| h * a).sum();
            obj += alpha[i] * (0.5 * ha - hu);
        }
        obj
    }

    fn unconstrained_alpha(&self, xhat: &[f64]) -> [f64; MAX_BASIS] {
        let mut a = [0.0; MAX_BASIS];
        for (i, ai) in a[..self.n].iter_mut().enumerate() {
            *ai = self.mx[i * self.c..(i + 1) * self.c]
                .iter()
                .zip(xhat)
                .map(|(m, x)| m * x)
                .sum();
        }
        a
    }

    /// r = Bα on the bands, eight bands at a time with their sums in registers (each sum from 0
    /// in basis order, as one pass per basis vector would add them); the bands past the last
    /// block of eight are left as they are.
    fn spectrum(&self, alpha: &[f64], r: &mut [f64; MAX_BANDS]) {
        for (at, out) in band_blocks(self.m, r) {
            let mut acc = [0.0; BAND_BLOCK];
            for (col, &a) in self.bt.iter().zip(alpha) {
                for (s, &b) in acc.iter_mut().zip(&col[at.clone()]) {
                    *s += b * a;
                }
            }
            out.copy_from_slice(&acc);
        }
    }

    /// The exact solution α for one pixel's channel values `xhat` (length = channels), written to
    /// `out_alpha` (length = J).
    pub fn solve_pixel(&self, xhat: &[f64], out_alpha: &mut [f64]) -> Result<SolveInfo> {
        if xhat.len() != self.c || out_alpha.len() != self.n {
            return Err(Error::Shape(format!(
                "solve_pixel: {} channel values and {} coefficients for a {}-channel, J = {} unmixer",
                xhat.len(),
                out_alpha.len(),
                self.c,
                self.n
            )));
        }
        if let Some(k) = xhat.iter().position(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!(
                "channel {k} value is {}",
                xhat[k]
            )));
        }
        let mut r = [0.0; MAX_BANDS];
        let mut ws = WorkingSet::empty();
        let (steps, au) = self.solve(xhat, &mut r, &mut ws)?;
        let info = SolveInfo::new(steps, &ws);
        let alpha = self.alpha_from(&au, &info);
        if let Some(v) = alpha[..self.n].iter().find(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!(
                "unmixing active set ended with a coefficient of {v}"
            )));
        }
        out_alpha.copy_from_slice(&alpha[..self.n]);
        Ok(info)
    }

    /// [`Unmixer::solve_pixel`]'s work on checked input: writes the band values r = Bα (to the
    /// solver's round-off; the bands it holds at zero exactly 0) and returns the unconstrained
    /// minimiser α_u with the steps of the dual method, which starts from the working set `start`
    /// and leaves its final set there — or None where α_u is feasible (`start` left as it was).
    fn solve(
        &self,
        xhat: &[f64],
        r: &mut [f64; MAX_BANDS],
        start: &mut WorkingSet,
    ) -> Result<(Option<usize>, [f64; MAX_BASIS])> {
        let au = self.unconstrained_alpha(xhat);
        self.spectrum(&au[..self.n], r);
        if r[..self.m].iter().all(|&v| v >= 0.0) {
            return Ok((None, au));
        }
        Ok((Some(self.qp.solve(r, start)?), au))
    }

    /// α = α_u + Σ μ_k H⁻¹b_kᵀ over the final working set (0 when all J coefficients are
    /// pinned).
    fn alpha_from(&self, au: &[f64; MAX_BASIS], info: &SolveInfo) -> [f64; MAX_BASIS] {
        let n = self.n;
        if info.active == n {
            return [0.0; MAX_BASIS];
        }
        let mut alpha = *au;
        for (&band, &mu) in info.active_bands().iter().zip(info.multipliers()) {
            let col = &self.hinv_bt[band * n..(band + 1) * n];
            for (a, c) in alpha[..n].iter_mut().zip(col) {
                *a += mu * c;
            }
        }
        alpha
    }

    /// Unmix a cube of channel planes x̂ into a cube of band planes r = Bα, α from the QP.
    /// Bands of solved pixels are B α as the solver's steps carried it (the bands it holds at
    /// zero exactly 0, any other round-off below zero — ≤ 1e-9 of the pixel's scale, checked —
    /// set to zero), so every output value is ≥ 0.
    pub fn unmix(&self, xhat: &Cube) -> Result<(Cube, UnmixStats)> {
        let mut out = Cube::zeros_on_huge_pages(xhat.width, xhat.height, self.m);
        let stats = self.unmix_into(xhat, &mut out)?;
        Ok((out, stats))
    }

    /// [`Unmixer::unmix`] into a cube of the right size that the caller keeps from frame to
    /// frame: a real-time loop then pays for its 31 output planes' memory once.
    pub fn unmix_into(&self, xhat: &Cube, out: &mut Cube) -> Result<UnmixStats> {
        if (out.width, out.height, out.planes) != (xhat.width, xhat.height, self.m) {
            return Err(Error::Shape(format!(
                "unmixing output {}×{}×{} for channels {}×{} and {} bands",
                out.width, out.height, out.planes, xhat.width, xhat.height, self.m
            )));
        }
        self.unmix_into_slice(xhat, &mut out.data)
    }

    /// [`Unmixer::unmix_into`] into the memory of a (bands, height, width) array in row-major
    /// order, such as a numpy array a caller keeps (every value overwritten).
    pub fn unmix_into_slice(&self, xhat: &Cube, out: &mut [f32]) -> Result<UnmixStats> {
        if xhat.planes != self.c {
            return Err(Error::Shape(format!(
                "unmixing expects {} channel planes, the cube has {}",
                self.c, xhat.planes
            )));
        }
        if out.len() != self.m * xhat.pixels() {
            return Err(Error::Shape(format!(
                "unmixing output of {} values for channels {}×{} and {} bands",
                out.len(),
                xhat.width,
                xhat.height,
                self.m
            )));
        }
        let (wid, npx) = (xhat.width, xhat.pixels());
        if npx == 0 {
            return Ok(UnmixStats::default());
        }
        let chunk_px = ROWS_PER_CHUNK * wid;
        let nchunks = npx.div_ceil(chunk_px);
        let mut views: Vec<Vec<&mut [f32]>> =
            (0..nchunks).map(|_| Vec::with_capacity(self.m)).collect();
        for plane in out.chunks_exact_mut(npx) {
            for (k, part) in plane.chunks_mut(chunk_px).enumerate() {
                views[k].push(part);
            }
        }
        views
            .into_par_iter()
            .enumerate()
            .map(|(k, mut bands)| {
                let start = k * chunk_px;
                let len = bands[0].len();
                let xs: [&[f32]; MAX_CHANNELS] = std::array::from_fn(|j| {
                    if j < self.c {
                        &xhat.plane(j)[start..start + len]
                    } else {
                        &[]
                    }
                });
                self.unmix_chunk(&xs[..self.c], &mut bands)
                    .map_err(|(i, msg)| {
                        let p = start + i;
                        Error::Numerical(format!(
                            "unmixing pixel ({}, {}): {msg}",
                            p % wid,
                            p / wid
                        ))
                    })
            })
            .try_reduce(UnmixStats::default, |a, b| {
                Ok(UnmixStats {
                    pixels: a.pixels + b.pixels,
                    constrained_pixels: a.constrained_pixels + b.constrained_pixels,
                    bound_pixels: a.bound_pixels + b.bound_pixels,
                    max_iterations: a.max_iterations.max(b.max_iterations),
                    total_iterations: a.total_iterations + b.total_iterations,
                })
            })
    }

    /// One chunk, block by block: r = P x̂ for every pixel, the exact solver on the pixels
    /// with a negative band, then the block's bands written. The blocks are the bands' cache
    /// lines (the first one up to the first line boundary), so whole lines can be streamed to
    /// memory without first being read. An error carries the pixel's offset in the chunk.
    fn unmix_chunk(
        &self,
        xs: &[&[f32]],
        bands: &mut [&mut [f32]],
    ) -> std::result::Result<UnmixStats, (usize, String)> {
        for (j, x) in xs.iter().enumerate() {
            if !all_finite(x) {
                let i = x.iter().position(|v| !v.is_finite()).unwrap_or(0);
                return Err((i, format!("channel {j} is {}", x[i])));
            }
        }
        let mut stats = UnmixStats {
            pixels: xs[0].len(),
            ..UnmixStats::default()
        };
        let done = self.unmix_lines(xs, bands, &mut stats);
        store_fence();
        done.map(|()| stats)
    }

    /// [`Unmixer::unmix_chunk`]'s blocks, each written as soon as it is solved.
    fn unmix_lines(
        &self,
        xs: &[&[f32]],
        bands: &mut [&mut [f32]],
        stats: &mut UnmixStats,
    ) -> std::result::Result<(), (usize, String)> {
        let len = xs[0].len();
        let mut block: Block = [[0.0; LINE]; MAX_BANDS];
        // The last solved pixel's final working set, the next one's start (in the chunk only, so
        // the result does not depend on how the threads split the cube).
        let mut warm = WorkingSet::empty();
        // The first band's lines begin where (offset + pixel) is a multiple of LINE.
        let offset = bands[0].as_ptr() as usize / 4 % LINE;
        let mut start = 0;
        while start < len {
            let end = (((offset + start) / LINE + 1) * LINE - offset).min(len);
            self.unmix_block(xs, start, end - start, &mut block, &mut warm, stats)?;
            for (out, b) in bands.iter_mut().zip(&block) {
                store_line(&mut out[start..end], &b[..end - start]);
            }
            start = end;
        }
        Ok(())
    }

    /// The bands of the `lanes` ≤ 16 pixels from `start` into `block`: projected eight pixels
    /// at a time, then each pixel with a negative band solved exactly, starting from the working
    /// set `warm` that the last one left.
    #[inline(always)]
    fn unmix_block(
        &self,
        xs: &[&[f32]],
        start: usize,
        lanes: usize,
        block: &mut Block,
        warm: &mut WorkingSet,
        stats: &mut UnmixStats,
    ) -> std::result::Result<(), (usize, String)> {
        let mut low = [f32::INFINITY; LINE];
        // A whole line spelled out, so that both halves are projected with a constant width.
        if lanes == LINE {
            self.project(xs, start, LANES, block, 0, &mut low);
            self.project(xs, start + LANES, LANES, block, LANES, &mut low);
        } else {
            for from in (0..lanes).step_by(LANES) {
                let n = (lanes - from).min(LANES);
                self.project(xs, start + from, n, block, from, &mut low);
            }
        }
        for (l, _) in low[..lanes]
            .iter()
            .enumerate()
            .filter(|(_, &v)| !(v >= 0.0))
        {
            self.solve_lane(xs, start + l, block, l, warm, stats)
                .map_err(|e| (start + l, e.to_string()))?;
        }
        Ok(())
    }

    /// The exact solution of pixel `i` from the working set `warm`, written into lane `l` of
    /// `block` (bands r ≥ 0 times their gains), and counted in `stats`.
    fn solve_lane(
        &self,
        xs: &[&[f32]],
        i: usize,
        block: &mut Block,
        l: usize,
        warm: &mut WorkingSet,
        stats: &mut UnmixStats,
    ) -> Result<()> {
        let mut xp = [0.0f64; MAX_CHANNELS];
        for (xv, x) in xp.iter_mut().zip(xs) {
            *xv = x[i] as f64;
        }
        let mut r = [0.0f64; MAX_BANDS];
        let (steps, _) = self.solve(&xp[..self.c], &mut r, warm)?;
        for ((b, &v), g) in block.iter_mut().zip(&r[..self.m]).zip(&self.gain) {
            b[l] = (v.max(0.0) * g) as f32;
        }
        // Not the bands or multipliers (`SolveInfo`): the cube needs their count only.
        stats.constrained_pixels += 1;
        stats.bound_pixels += steps.is_some_and(|_| !warm.bands().is_empty()) as usize;
        let steps = steps.unwrap_or(0);
        stats.max_iterations = stats.max_iterations.max(steps);
        stats.total_iterations += steps;
        Ok(())
    }

    /// r = P x̂ for the `lanes` ≤ 8 pixels from `start`, into lanes `to..` of `block`, and each
    /// pixel's smallest band into `low`. The pixels' channel values and sums stay in registers
    /// while all the bands are formed; inlined, so that for a whole block the copies have a
    /// length known when compiling (moves, not calls to `memcpy`). The sums are added in
    /// channel order, as the scalar formula.
    #[inline(always)]
    fn project(
        &self,
        xs: &[&[f32]],
        start: usize,
        lanes: usize,
        block: &mut Block,
        to: usize,
        low: &mut [f32; LINE],
    ) {
        let c = self.c;
        let mut x = [[0.0f32; LANES]; MAX_CHANNELS];
        for (xj, plane) in x.iter_mut().zip(xs) {
            xj[..lanes].copy_from_slice(&plane[start..start + lanes]);
        }
        let low = &mut low[to..to + lanes];
        for (p, out) in self.p32.chunks_exact(c).zip(block.iter_mut()) {
            let mut acc = [0.0f32; LANES];
            for (a, &v) in acc.iter_mut().zip(&x[0]) {
                *a = p[0] * v;
            }
            for (&pj, xj) in p[1..].iter().zip(&x[1..c]) {
                for (a, &v) in acc.iter_mut().zip(xj) {
                    *a += pj * v;
                }
            }
            for (l, &a) in low.iter_mut().zip(&acc) {
                *l = lower(*l, a);
            }
            out[to..to + lanes].copy_from_slice(&acc[..lanes]);
        }
    }
}

/// The `m` band values `value(k)`, zero-padded to `MAX_BANDS` (the solver's per-band arrays).
fn padded(m: usize, value: impl Fn(usize) -> f64) -> [f64; MAX_BANDS] {
    std::array::from_fn(|k| if k < m { value(k) } else { 0.0 })
}

/// `dst` ← `src`; a whole 64-byte line by non-temporal stores (it goes to memory without being
/// read into the cache first: the 73 MB of bands of a frame are not read again soon).
#[inline(always)]
fn store_line(dst: &mut [f32], src: &[f32]) {
    #[cfg(target_arch = "x86_64")]
    if dst.len() == LINE && dst.as_ptr() as usize % 64 == 0 {
        use std::arch::x86_64::{_mm_loadu_ps, _mm_stream_ps};
        for k in (0..LINE).step_by(4) {
            // SAFETY: dst holds 16 values from a 64-byte boundary, so each 16-byte store is
            // aligned and in bounds; src holds 16 values.
            unsafe { _mm_stream_ps(dst.as_mut_ptr().add(k), _mm_loadu_ps(src.as_ptr().add(k))) };
        }
        return;
    }
    dst.copy_from_slice(src);
}

/// Orders the non-temporal stores of [`store_line`] before any later store (such as the one
/// telling another thread that the chunk is done, or failed).
fn store_fence() {
    // SAFETY: SSE is part of x86-64; the fence has no other effect.
    #[cfg(target_arch = "x86_64")]
    unsafe {
        std::arch::x86_64::_mm_sfence()
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use clarabel::algebra::CscMatrix;
    use clarabel::solver::{
        DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
    };
    use nalgebra::DVector;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, StandardNormal};
    use rand_pcg::Pcg64;

    const BANDS: usize = 31;
    const J: usize = 6;

    /// Random smooth positive spectra (sums of Gaussians on a floor), bands × count.
    fn smooth_spectra(rng: &mut Pcg64, count: usize) -> DMatrix<f64> {
        let mut s = DMatrix::zeros(BANDS, count);
        for c in 0..count {
            let floor: f64 = rng.gen_range(0.02..0.2);
            let bumps: Vec<(f64, f64, f64)> = (0..3)
                .map(|_| {
                    (
                        rng.gen_range(0.0..0.6),
                        rng.gen_range(0.0..31.0),
                        rng.gen_range(3.0..10.0),
                    )
                })
                .collect();
            for b in 0..BANDS {
                s[(b, c)] = floor
                    + bumps
                        .iter()
                        .map(|(a, mu, w)| a * (-((b as f64 - mu) / w).powi(2)).exp())
                        .sum::<f64>();
            }
        }
        s
    }

    /// Uncentred PCA basis (BANDS × J) of random smooth spectra.
    fn basis(rng: &mut Pcg64) -> DMatrix<f64> {
        let s = smooth_spectra(rng, 200);
        let eig = nalgebra::SymmetricEigen::new(&s * s.transpose());
        let mut order: Vec<usize> = (0..BANDS).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        DMatrix::from_fn(BANDS, J, |b, j| eig.eigenvectors[(b, order[j])])
    }

    /// Channel matrix F = T B for six smooth broad filters T (channels × bands).
    fn filters(rng: &mut Pcg64, b: &DMatrix<f64>) -> DMatrix<f64> {
        let t = smooth_spectra(rng, 6).transpose();
        &t * b
    }

    /// The problem in the reference form: H and g = Fᵀx̂, built from F, B, η directly.
    fn hessian(f: &DMatrix<f64>, b: &DMatrix<f64>, eta: f64) -> DMatrix<f64> {
        f.transpose() * f + curvature(b, eta)
    }

    fn objective(h: &DMatrix<f64>, g: &DVector<f64>, a: &DVector<f64>) -> f64 {
        0.5 * a.dot(&(h * a)) - g.dot(a)
    }

    fn dense_csc(a: &DMatrix<f64>, upper_only: bool) -> CscMatrix<f64> {
        let (mut colptr, mut rowval, mut nzval) = (vec![0], vec![], vec![]);
        for j in 0..a.ncols() {
            for i in 0..a.nrows() {
                if (!upper_only || i <= j) && a[(i, j)] != 0.0 {
                    rowval.push(i);
                    nzval.push(a[(i, j)]);
                }
            }
            colptr.push(rowval.len());
        }
        CscMatrix::new(a.nrows(), a.ncols(), colptr, rowval, nzval)
    }

    /// Clarabel on min ½αᵀHα − gᵀα s.t. −Bα + s = 0, s ≥ 0.
    fn clarabel(h: &DMatrix<f64>, g: &DVector<f64>, b: &DMatrix<f64>) -> DVector<f64> {
        let p = dense_csc(h, true);
        let a = dense_csc(&(-b), false);
        let q: Vec<f64> = g.iter().map(|v| -v).collect();
        let rhs = vec![0.0; b.nrows()];
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .tol_gap_abs(1e-11)
            .tol_gap_rel(1e-11)
            .tol_feas(1e-11)
            .max_iter(400)
            .build()
            .unwrap();
        let mut solver =
            DefaultSolver::new(&p, &q, &a, &rhs, &[NonnegativeConeT(b.nrows())], settings);
        solver.solve();
        assert!(
            matches!(
                solver.solution.status,
                SolverStatus::Solved | SolverStatus::AlmostSolved
            ),
            "clarabel: {:?}",
            solver.solution.status
        );
        DVector::from_vec(solver.solution.x.clone())
    }

    /// KKT conditions of our solution, from the reported working set and multipliers.
    fn assert_kkt(
        h: &DMatrix<f64>,
        g: &DVector<f64>,
        b: &DMatrix<f64>,
        a: &DVector<f64>,
        info: &SolveInfo,
    ) {
        let r = b * a;
        let scale = (b * h.clone().cholesky().unwrap().solve(g))
            .amax()
            .max(1e-300);
        assert!(r.min() >= -1e-9 * scale, "primal infeasible: {}", r.min());
        let mut grad = h * a - g;
        let mmax = info
            .multipliers()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for (&k, &mu) in info.active_bands().iter().zip(info.multipliers()) {
            assert!(mu >= -1e-12 * mmax, "negative multiplier {mu} on band {k}");
            assert!(
                (mu * r[k]).abs() <= 1e-9 * mmax * scale,
                "complementarity {mu} · {}",
                r[k]
            );
            grad -= b.row(k).transpose() * mu;
        }
        let gscale = g.amax().max((h * a).amax());
        assert!(
            grad.amax() <= 1e-9 * gscale,
            "stationarity residual {:e}",
            grad.amax()
        );
    }

    /// Solve with the unmixer and Clarabel and check objective, solution and KKT.
    fn check_against_clarabel(
        f: &DMatrix<f64>,
        b: &DMatrix<f64>,
        eta: f64,
        x: &[f64],
        alpha_tol: f64,
    ) -> SolveInfo {
        let u = Unmixer::new(f, b, eta).unwrap();
        let mut a = vec![0.0; b.ncols()];
        let info = u.solve_pixel(x, &mut a).unwrap();
        let a = DVector::from_vec(a);
        let h = hessian(f, b, eta);
        let g = f.transpose() * DVector::from_column_slice(x);
        let ac = clarabel(&h, &g, b);
        let (fo, fc) = (objective(&h, &g, &a), objective(&h, &g, &ac));
        // Scale of the objective: its value at the unconstrained minimum, ½ gᵀH⁻¹g.
        let fscale = 0.5 * g.dot(&h.clone().cholesky().unwrap().solve(&g));
        assert!(
            (fo - fc).abs() <= 1e-7 * fscale.max(fo.abs()),
            "objective {fo} vs clarabel {fc}"
        );
        // Relative to the larger solution; at the vertex α = 0 (J bands pinned) a relative test is
        // undefined and the unconstrained solution sets the scale.
        let da = (&a - &ac).norm();
        let ascale = if info.active == a.len() {
            h.clone().cholesky().unwrap().solve(&g).norm()
        } else {
            a.norm().max(ac.norm())
        };
        assert!(
            da <= alpha_tol * ascale,
            "α {a} vs clarabel {ac}: {:e} relative",
            da / ascale
        );
        assert_kkt(&h, &g, b, &a, &info);
        assert!((u.objective(x, a.as_slice()) - fo).abs() <= 1e-9 * fscale.max(fo.abs()));
        info
    }

    /// Solve `x` from the working set `warm` (the previous pixel's final set, as a cube's pixels
    /// are solved) and from the empty one: the minimiser is unique, so the band values must
    /// agree to the solver's own feasibility tolerance (10⁻⁹ of the pixel's largest
    /// unconstrained band), with the warm start's multipliers ≥ 0 and its working set's bands
    /// exactly 0. Returns the steps of the two (empty start, warm start).
    fn check_warm_start(u: &Unmixer, x: &[f64], warm: &mut WorkingSet) -> [usize; 2] {
        let (mut cold, mut warmed) = ([0.0; MAX_BANDS], [0.0; MAX_BANDS]);
        let mut empty = WorkingSet::empty();
        let (steps, _) = u.solve(x, &mut cold, &mut empty).unwrap();
        let cold_info = SolveInfo::new(steps, &empty);
        let (steps, _) = u.solve(x, &mut warmed, warm).unwrap();
        let info = SolveInfo::new(steps, warm);
        // The solver's own scale: the largest unconstrained band value (`BandQp::solve`).
        let mut unconstrained = [0.0; MAX_BANDS];
        u.spectrum(&u.unconstrained_alpha(x)[..u.n], &mut unconstrained);
        let scale = unconstrained.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for k in 0..BANDS {
            assert!(
                (warmed[k] - cold[k]).abs() <= 1e-9 * scale,
                "band {k}: {} warm, {} cold (scale {scale:e})",
                warmed[k],
                cold[k]
            );
        }
        assert!(info.multipliers().iter().all(|&mu| mu >= 0.0), "{info:?}");
        assert!(info.active_bands().iter().all(|&k| warmed[k] == 0.0));
        [cold_info.iterations, info.iterations]
    }

    fn normal(rng: &mut Pcg64) -> f64 {
        StandardNormal.sample(rng)
    }

    #[test]
    fn unconstrained_solution_is_the_normal_equations() {
        let mut rng = Pcg64::seed_from_u64(1);
        let b = basis(&mut rng);
        let f = filters(&mut rng, &b);
        let eta = 0.5;
        let u = Unmixer::new(&f, &b, eta).unwrap();
        // A positive spectrum in the basis span with a strong floor: unconstrained optimum feasible.
        let alpha_true = b.transpose() * DVector::from_element(BANDS, 1.0);
        let x = &f * &alpha_true;
        let mut a = vec![0.0; J];
        let info = u.solve_pixel(x.as_slice(), &mut a).unwrap();
        assert_eq!(info.iterations, 0);
        let h = hessian(&f, &b, eta);
        let want = h.lu().solve(&(f.transpose() * &x)).unwrap();
        let err = (DVector::from_vec(a) - &want).amax();
        assert!(err <= 1e-10 * want.amax(), "{err:e}");
    }

    #[test]
    fn hand_solved_two_variable_qp() {
        // F = [[2,0],[1,1]], B = I, η = 0, x̂ = (−2, 1): H = [[5,1],[1,1]], g = (−3, 1),
        // unconstrained α = (−1, 2); with α₁ = 0 the minimum of ½α₂² − α₂ is α₂ = 1, and
        // Hα − g = (4, 0) = 4·e₁ gives the multiplier 4 ≥ 0.
        let f = DMatrix::from_row_slice(2, 2, &[2.0, 0.0, 1.0, 1.0]);
        let b = DMatrix::identity(2, 2);
        let u = Unmixer::new(&f, &b, 0.0).unwrap();
        let mut a = [0.0; 2];
        let info = u.solve_pixel(&[-2.0, 1.0], &mut a).unwrap();
        assert!(
            (a[0] - 0.0).abs() < 1e-15 && (a[1] - 1.0).abs() < 1e-14,
            "{a:?}"
        );
        assert_eq!(info.active_bands(), &[0]);
        assert!(
            (info.multipliers()[0] - 4.0).abs() < 1e-13,
            "{:?}",
            info.multipliers()
        );
        assert!((u.objective(&[-2.0, 1.0], &a) - -0.5).abs() < 1e-14);
    }

    #[test]
    fn matches_clarabel_on_random_problems() {
        let mut rng = Pcg64::seed_from_u64(2);
        let mut bound = 0;
        for trial in 0..240 {
            if trial % 20 == 0 {
                rng = Pcg64::seed_from_u64(1000 + trial);
            }
            let b = basis(&mut rng);
            let f = filters(&mut rng, &b);
            let eta = [0.0, 0.01, 0.3, 5.0][trial as usize % 4];
            // A spectrum in the span plus noise large enough to push bands negative.
            let s = smooth_spectra(&mut rng, 1);
            let x: Vec<f64> = (&f * (b.transpose() * s.column(0)))
                .iter()
                .map(|v| v + 0.3 * normal(&mut rng) * v.abs().max(0.1))
                .collect();
            let info = check_against_clarabel(&f, &b, eta, &x, 1e-5);
            bound += (info.active > 0) as usize;
        }
        assert!(
            bound >= 40,
            "only {bound} problems had a binding constraint"
        );
    }

    #[test]
    fn matches_clarabel_on_ill_conditioned_problems() {
        let mut rng = Pcg64::seed_from_u64(3);
        let b = basis(&mut rng);
        let f0 = filters(&mut rng, &b);
        // Nearly collinear F columns, small η.
        let mut f1 = f0.clone();
        let c0 = f1.column(0).clone_owned();
        for i in 0..6 {
            f1[(i, 1)] = c0[i] * 0.9 + 1e-3 * normal(&mut rng);
        }
        let u1 = Unmixer::new(&f1, &b, 1e-4).unwrap();
        assert!(
            u1.condition() > 1e6,
            "not ill-conditioned: {:e}",
            u1.condition()
        );
        let (mut cases, mut shorter) = (0, 0);
        for (f, eta) in [(&f1, 1e-4), (&f0, 0.0), (&f0, 1e4)] {
            // Each pixel also solved from the previous one's final working set.
            let u = Unmixer::new(f, &b, eta).unwrap();
            let mut warm = WorkingSet::empty();
            for _ in 0..60 {
                // Large negative parts: many bands bind, often the vertex α = 0.
                let x: Vec<f64> = (0..6).map(|_| normal(&mut rng) - 0.7).collect();
                check_against_clarabel(f, &b, eta, &x, 1e-5);
                let [cold, warmed] = check_warm_start(&u, &x, &mut warm);
                shorter += (warmed < cold) as usize;
                cases += 1;
            }
        }
        assert_eq!(cases, 180);
        assert!(shorter >= 30, "{shorter} warm starts saved a step");
    }

    #[test]
    fn all_negative_channels_give_zero_spectrum() {
        // With positive filters and a positive spectrum all channels are ≥ 0; all-negative x̂ has
        // its minimum at α = 0, the most degenerate vertex (every band active).
        let mut rng = Pcg64::seed_from_u64(4);
        let b = basis(&mut rng);
        let f = filters(&mut rng, &b);
        let u = Unmixer::new(&f, &b, 0.3).unwrap();
        let mut a = [1.0; J];
        let info = u
            .solve_pixel(&[-1.0, -2.0, -0.5, -1.5, -3.0, -1.0], &mut a)
            .unwrap();
        assert!(a.iter().all(|v| v.abs() < 1e-12), "{a:?}");
        assert_eq!(info.active, J);
    }

    proptest! {
        #[test]
        fn scaling_the_channels_scales_the_solution(seed in 0u64..1000, c in 1e-3f64..1e3) {
            let mut rng = Pcg64::seed_from_u64(seed);
            let b = basis(&mut rng);
            let f = filters(&mut rng, &b);
            let u = Unmixer::new(&f, &b, 0.1).unwrap();
            let x: Vec<f64> = (0..6).map(|_| normal(&mut rng)).collect();
            let xc: Vec<f64> = x.iter().map(|v| v * c).collect();
            let (mut a, mut ac) = ([0.0; J], [0.0; J]);
            u.solve_pixel(&x, &mut a).unwrap();
            u.solve_pixel(&xc, &mut ac).unwrap();
            let norm = a.iter().map(|v| v * v).sum::<f64>().sqrt();
            for (p, q) in a.iter().zip(&ac) {
                prop_assert!((p * c - q).abs() <= 1e-9 * c * norm.max(1e-300), "{} vs {}", p * c, q);
            }
        }
    }

    #[test]
    fn cube_unmixing_matches_the_pixel_solver() {
        let mut rng = Pcg64::seed_from_u64(5);
        let b = basis(&mut rng);
        let f = filters(&mut rng, &b);
        let u = Unmixer::new(&f, &b, 0.2).unwrap();
        // Planes off the cache lines (37 × 19) and on them (64 × 24: whole lines streamed).
        for (w, h) in [(37, 19), (64, 24)] {
            check_cube_unmixing(&u, &b, &f, &mut rng, w, h);
        }
    }

    fn check_cube_unmixing(
        u: &Unmixer,
        b: &DMatrix<f64>,
        f: &DMatrix<f64>,
        rng: &mut Pcg64,
        w: usize,
        h: usize,
    ) {
        let s = smooth_spectra(rng, w * h);
        let x = f * (b.transpose() * s);
        let mut cube = Cube::zeros(w, h, 6);
        for p in 0..w * h {
            for j in 0..6 {
                cube.plane_mut(j)[p] = (x[(j, p)] * (1.0 + 0.4 * normal(rng))) as f32;
            }
        }
        let (out, stats) = u.unmix(&cube).unwrap();
        assert_eq!((out.width, out.height, out.planes), (w, h, BANDS));
        assert_eq!(stats.pixels, w * h);
        assert!(
            stats.bound_pixels > 10 && stats.bound_pixels <= stats.constrained_pixels,
            "{stats:?}"
        );
        assert!(out.data.iter().all(|&v| v >= 0.0));
        // Into a caller's memory (a numpy array's): the same bits; a wrong length refused.
        let mut kept = vec![f32::NAN; out.data.len()];
        u.unmix_into_slice(&cube, &mut kept).unwrap();
        assert!(kept
            .iter()
            .zip(&out.data)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert!(u.unmix_into_slice(&cube, &mut kept[1..]).is_err());
        let mut a = [0.0; J];
        for p in 0..w * h {
            let xp: Vec<f64> = (0..6).map(|j| cube.plane(j)[p] as f64).collect();
            let info = u.solve_pixel(&xp, &mut a).unwrap();
            // The bands the solution holds at zero are zero, not round-off.
            for &k in info.active_bands() {
                assert_eq!(out.plane(k)[p], 0.0, "pixel {p} band {k}");
            }
            let r = b * DVector::from_column_slice(&a);
            let scale = r.amax();
            for k in 0..BANDS {
                let got = out.plane(k)[p] as f64;
                assert!(
                    (got - r[k].max(0.0)).abs() <= 1e-5 * scale,
                    "pixel {p} band {k}: {got} vs {}",
                    r[k]
                );
            }
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let mut rng = Pcg64::seed_from_u64(6);
        let b = basis(&mut rng);
        let f = filters(&mut rng, &b);
        for eta in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(
                matches!(Unmixer::new(&f, &b, eta), Err(Error::Numerical(_))),
                "η = {eta}"
            );
        }
        // Two identical filter responses and no smoothing: H is singular.
        let mut fs = f.clone();
        let row = fs.row(0).clone_owned();
        fs.set_row(1, &row);
        let fs = fs.rows(0, 5).clone_owned(); // 5 channels for 6 unknowns
        match Unmixer::new(&fs, &b, 0.0) {
            Err(Error::Numerical(msg)) => assert!(msg.contains("condition number"), "{msg}"),
            other => panic!("expected a numerical error, got {other:?}"),
        }
        let u = Unmixer::new(&f, &b, 0.1).unwrap();
        let mut a = [0.0; J];
        assert!(matches!(
            u.solve_pixel(&[1.0, f64::NAN, 0.0, 0.0, 0.0, 0.0], &mut a),
            Err(Error::Numerical(_))
        ));
        assert!(matches!(
            u.solve_pixel(&[1.0; 5], &mut a),
            Err(Error::Shape(_))
        ));
        let mut cube = Cube::zeros(9, 9, 6);
        cube.plane_mut(3)[40] = f32::NAN;
        match u.unmix(&cube) {
            Err(Error::Numerical(msg)) => assert!(msg.contains("(4, 4)"), "{msg}"),
            other => panic!("expected a numerical error, got {other:?}"),
        }
        assert!(matches!(
            u.unmix(&Cube::zeros(4, 4, 5)),
            Err(Error::Shape(_))
        ));
    }
}
