//! Joint spectral–spatial reconstruction: the basis coefficients α (J per pixel) straight from
//! the linearised frame through the whole forward operator. With S'_i = Σ_k w_ik s̃_k the
//! effective pattern of channel i, the frame is y_p = a_pᵀα_p, a_p = Fᵀ S'(p), and
//!
//!   min_α ½Σ_p ω_p (y_p − a_pᵀα_p)² + ½η' Σ_p ‖D₂Bα_p‖² + λ Σ_p ‖∇α(p)‖₂   s.t. Bα ≥ 0
//!
//! (ω: per-pixel data weights, 1 or the inverse noise variance; the TV norm is joint over the J
//! coefficient images and both directions, so the channels share edges). Solved by
//! Chambolle–Pock (2011, Algorithm 1, θ = 1) with K = [∇; βB]: the TV and the constraint are
//! dualised, the quadratic's proximal step is per pixel and closed form (Sherman–Morrison on
//! (I + τη'Q)⁻¹), and τσ‖K‖² < 1 with ‖K‖² ≤ 8 + β²‖B‖² (tested against power iteration).

use crate::error::{check_count, Error, Result};
use crate::noise::DataWeights;
use crate::Cube;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

pub mod discrepancy;
mod lane;
mod method;
mod pnp;
mod rows;

use lane::{fields, LaneKernel, Lanes, Scalar, LANES};
use rows::Rows;

/// τσ‖K‖² of the step sizes: below the bound 1 of Chambolle–Pock's convergence theorem.
const STEP_PRODUCT: f64 = 0.98;

/// The prior of the joint method (`[reconstruct.joint] prior`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Prior {
    /// Vectorial TV on α, solved by Chambolle–Pock.
    #[default]
    Tv,
    /// Plug-and-play ADMM: the guided graph smoother of `denoise.rs` as the prior's proximal step.
    Pnp,
}

/// Reweighting rounds of a TV run with `reweight_rounds` unset: one refresh halfway, which at
/// `auto`'s pick gains 1–2 dB on flat-patch scenes and loses nothing on the smooth ones once
/// paired with the trained spectral prior (docs/joint.md, "The defaults at auto's pick").
pub const DEFAULT_REWEIGHT_ROUNDS: usize = 1;

/// The reweighting rounds of a run with `reweight_rounds` unset: [`DEFAULT_REWEIGHT_ROUNDS`]
/// with the TV prior, a fixed λ and two or more iterations to split, and none otherwise
/// (plug-and-play has no TV weights; the discrepancy rule fits its residual under the weights
/// it searched with).
pub fn default_rounds(iterations: usize, prior: Prior, weight_rule: WeightRule) -> usize {
    let splits = prior == Prior::Tv && weight_rule == WeightRule::Fixed && iterations >= 2;
    if splits {
        DEFAULT_REWEIGHT_ROUNDS
    } else {
        0
    }
}

/// The spectral prior of the joint method (`[reconstruct.joint] spectral_prior`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpectralPrior {
    /// The paper's curvature penalty η‖D₂Bα‖², as the unmixer uses it.
    Curvature,
    /// The Gaussian prior trained with the basis (`Basis::coefficient_prior`): the
    /// coefficients' variances over the training spectra against the misfit they leave.
    /// Better on smooth scenes once converged, slower to converge (docs/joint.md).
    Trained,
}

impl SpectralPrior {
    /// The key's value, as the reports name it.
    pub fn name(self) -> &'static str {
        match self {
            SpectralPrior::Curvature => "curvature",
            SpectralPrior::Trained => "trained",
        }
    }
}

/// How λ is set (`[reconstruct.joint] weight_rule`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WeightRule {
    /// λ from `tv_weight`.
    #[default]
    Fixed,
    /// λ such that Σω(y − aᵀα)² ≈ the number of pixels (needs the camera's noise model).
    Discrepancy,
}

/// Settings of `[reconstruct.joint]`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JointConfig {
    /// Primal–dual iterations.
    pub iterations: usize,
    /// λ as a fraction of mean|y|·mean‖a‖·mean ω (the TV weight free of the frame's, the
    /// patterns' and the weights' scale); the discrepancy search starts from it.
    pub tv_weight: f64,
    /// The spectral prior on each pixel's α: the paper's curvature (η), or trained with the
    /// basis. Unset: the trained one where the design has it, else the curvature (the
    /// reconstructor resolves it; docs/joint.md, "The defaults at auto's pick").
    pub spectral_prior: Option<SpectralPrior>,
    /// τ/σ balance: τ = ratio·s/L, σ = 1/(ratio·s·L), s = mean|α₀|/λ (α's scale over the dual's).
    pub step_ratio: f64,
    /// Take the balance s again from the iterate halfway through the run (τ, σ and the
    /// proximal tables recomputed, the extrapolation kept). Off by default: it gains up to
    /// 0.3 dB on dead-leaves and the full rig but loses 1.3–1.5 dB on the Cornell box
    /// (docs/joint.md, "The mid-run rebalance").
    pub rebalance: bool,
    /// Over-relaxation γ of the Chambolle–Pock step (Condat 2013): z ← z + γ(T z − z),
    /// 0 < γ < 2; 1 is the plain iteration. 1.8 reaches in 10 iterations what the plain one
    /// reaches in about 15–20 (docs/joint.md). TV prior only.
    pub relaxation: f64,
    /// TV (Chambolle–Pock) or plug-and-play (ADMM with a guided smoother).
    pub prior: Prior,
    /// λ fixed by `tv_weight`, or chosen by the discrepancy principle.
    pub weight_rule: WeightRule,
    /// Iterations per trial λ of the discrepancy search (warm started).
    pub search_iterations: usize,
    /// Weigh the data term by the camera's noise model when the design has one (default off:
    /// −0.26 dB on the full rig at the fixed λ, +0.5 dB on an overexposed frame; docs/results.md).
    pub noise_weights: bool,
    /// Plug-and-play: ADMM penalty ρ as a multiple of mean(ω‖a‖²) (larger: less smoothing).
    pub pnp_weight: f64,
    /// Plug-and-play: the smoother's edge scale (h² = edge² · mean squared neighbour difference).
    pub pnp_edge: f64,
    /// Plug-and-play: passes of the smoother per iteration (Wⁿ).
    pub pnp_passes: usize,
    /// Plug-and-play: enforce Bα ≥ 0 (an exact per-pixel projection as a second ADMM copy).
    pub pnp_nonnegative: bool,
    /// Reweighted TV (Candès, Wakin & Boyd 2008): the iterations run in `reweight_rounds` + 1
    /// equal stages, and after each stage but the last the TV weight of pixel p becomes
    /// ε/(e_p + ε), e_p the excess of ‖∇α(p)‖ over its 3 × 3 mean, so jumps are penalised
    /// less; 0 is plain TV. Unset: one round with the TV prior, a fixed λ and two or more
    /// iterations, else none ([`JointConfig::rounds`]; docs/joint.md, "The defaults at auto's
    /// pick").
    pub reweight_rounds: Option<usize>,
    /// ε of the reweighting as a multiple of the mean ‖∇α(p)‖ over the pixels.
    pub reweight_eps: f64,
    /// Set to zero each value of the constraint's dual r whose size falls under
    /// `dual_flush`·λ·0.98ⁿ in iteration n (0: never). Over-relaxed, the dual of a band that
    /// left its constraint decays as (1 − γ)ⁿ instead of reaching zero, so the constraint is
    /// worked on at 80 % of the pixels instead of the few where it holds; the threshold's decay
    /// keeps the perturbation summable, so the run converges to the same minimiser
    /// (docs/joint.md, "The constraint's dual flushed").
    pub dual_flush: f64,
    /// Record the objective before every iteration (`JointStats::objective`); off, only at the
    /// seed and the end: evaluating it costs a quarter of a TV iteration (docs/joint.md).
    pub trace_objective: bool,
}

impl Default for JointConfig {
    fn default() -> Self {
        JointConfig {
            iterations: 100,
            tv_weight: 0.02,
            spectral_prior: None,
            step_ratio: 1.0,
            rebalance: false,
            relaxation: 1.8,
            prior: Prior::Tv,
            weight_rule: WeightRule::Fixed,
            search_iterations: 25,
            noise_weights: false,
            pnp_weight: 0.01,
            pnp_edge: 1.0,
            pnp_passes: 4,
            pnp_nonnegative: true,
            reweight_rounds: None,
            reweight_eps: 0.03,
            dual_flush: 1e-2,
            trace_objective: false,
        }
    }
}

impl JointConfig {
    /// The reweighting rounds a run makes: the key's value, or unset [`default_rounds`].
    pub fn rounds(&self) -> usize {
        let default = || default_rounds(self.iterations, self.prior, self.weight_rule);
        self.reweight_rounds.unwrap_or_else(default)
    }

    /// The spectral prior's name for the stats: the key's value, or "given" when unset (the
    /// matrix passed to [`Joint::new`] is then whatever its caller chose).
    pub fn spectral_prior_name(&self) -> &'static str {
        self.spectral_prior.map_or("given", SpectralPrior::name)
    }

    /// Range checks; errors name `reconstruct.joint.<field>` and the value.
    pub fn validate(&self, file: &str) -> Result<()> {
        let key = |f: &str| format!("reconstruct.joint.{f}");
        // Without an iteration the cube would be the start's unfitted coefficients, worse than
        // the Fourier estimate it is seeded by (`method = "fourier"` is that estimate).
        check_count(
            file,
            &key("iterations"),
            self.iterations,
            1..=100_000,
            "iterations",
        )?;
        for (field, v, unit) in [
            ("search_iterations", self.search_iterations, "iterations"),
            ("pnp_passes", self.pnp_passes, "passes"),
            ("reweight_rounds", self.rounds(), "rounds"),
        ] {
            check_count(file, &key(field), v, 0..=100_000, unit)?;
        }
        for (field, v) in [
            ("tv_weight", self.tv_weight),
            ("dual_flush", self.dual_flush),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::config(
                    file,
                    &key(field),
                    v,
                    "must be finite and ≥ 0",
                ));
            }
        }
        if !(self.relaxation > 0.0 && self.relaxation < 2.0) {
            return Err(Error::config(
                file,
                &key("relaxation"),
                self.relaxation,
                "must lie in (0, 2) (the relaxed iteration converges there)",
            ));
        }
        if !(1e-6..=1e6).contains(&self.step_ratio) {
            return Err(Error::config(
                file,
                &key("step_ratio"),
                format!("{:e}", self.step_ratio),
                "must lie in [1e-6, 1e6] (τ/σ past that range over- or underflows the steps)",
            ));
        }
        for (field, v) in [
            ("pnp_weight", self.pnp_weight),
            ("pnp_edge", self.pnp_edge),
            ("reweight_eps", self.reweight_eps),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::config(
                    file,
                    &key(field),
                    v,
                    "must be finite and > 0",
                ));
            }
        }
        if self.rounds() > 0 && self.rounds() >= self.iterations {
            return Err(Error::config(
                file,
                &key("reweight_rounds"),
                self.rounds(),
                &format!(
                    "needs fewer rounds than iterations ({}): the run is split into rounds + 1 stages of at least one iteration each",
                    self.iterations
                ),
            ));
        }
        if self.prior == Prior::Pnp && self.rounds() > 0 {
            return Err(Error::config(
                file,
                &key("reweight_rounds"),
                self.rounds(),
                "applies to prior = \"tv\" only (plug-and-play has no TV weights)",
            ));
        }
        if self.prior == Prior::Pnp && self.rebalance {
            return Err(Error::config(
                file,
                &key("rebalance"),
                true,
                "applies to prior = \"tv\" only (plug-and-play's ADMM has no Chambolle–Pock steps to rebalance)",
            ));
        }
        if self.weight_rule == WeightRule::Discrepancy {
            if self.prior == Prior::Pnp {
                return Err(Error::config(
                    file,
                    &key("weight_rule"),
                    "\"discrepancy\"",
                    "applies to prior = \"tv\" only (the plug-and-play weight is pnp_weight)",
                ));
            }
            if !(self.tv_weight > 0.0 && self.search_iterations > 0) {
                return Err(Error::config(
                    file,
                    &key("weight_rule"),
                    "\"discrepancy\"",
                    "needs tv_weight > 0 (the search's start) and search_iterations > 0",
                ));
            }
        }
        Ok(())
    }
}

/// What a run did.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct JointStats {
    pub iterations: usize,
    /// The objective (data + smoothness + TV) at the seed, then after each iteration with
    /// `trace_objective`, else after the last only; for the plug-and-play prior data +
    /// smoothness at the seed and at the end.
    pub objective: Vec<f64>,
    /// λ in the units of the objective, whose data term is weighted by ω over its mean (1 for
    /// uniform weights, so then in the frame's units).
    pub lambda: f64,
    /// Primal and dual steps τ, σ (plug-and-play: τ = 1/ρ, σ = 0).
    pub steps: [f64; 2],
    /// Over-relaxation γ of the TV iteration (absent for plug-and-play and in reports made
    /// before it existed, which ran γ = 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relaxation: Option<f64>,
    /// `dual_flush` of the run (absent for plug-and-play and in reports made before it
    /// existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dual_flush: Option<f64>,
    /// Largest −(Bα)_k over the pixels and bands, relative to the largest (Bα)_k: the
    /// constraint's violation left by the last iterate (zero at the limit; clipped in the cube).
    pub violation: f64,
    pub seconds: f64,
    /// "tv" or "pnp".
    #[serde(default)]
    pub prior: String,
    /// The spectral prior on α: "curvature" (the paper's η), "trained", or "given" (a matrix
    /// passed to [`Joint::new`] with the key unset); empty in reports made before it existed,
    /// which ran the curvature.
    #[serde(default)]
    pub spectral_prior: String,
    /// Σ_p ω_p(y_p − a_pᵀα_p)² / #{p: ω_p > 0} at the end: ≈ 1 when the fit matches the noise.
    #[serde(default)]
    pub residual_ratio: f64,
    /// True when ω came from the camera's noise model (else ω = 1 and the ratio is in DN²).
    #[serde(default)]
    pub noise_weights: bool,
    /// Pixels whose raw value reads the camera's saturation: their data term is one-sided.
    #[serde(default)]
    pub saturated_pixels: usize,
    /// Times the TV weights were refreshed from the iterate (`reweight_rounds`; 0: plain TV).
    #[serde(default)]
    pub reweight_rounds: usize,
    /// The discrepancy principle's search, when it chose λ.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub discrepancy: Option<Search>,
    /// Plug-and-play: ‖Δz‖² + ‖Δu‖² per ADMM iteration (non-increasing once the guide is frozen).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fixed_point: Vec<f64>,
}

/// What the discrepancy principle's λ search tried and what it chose (`discrepancy::choose`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Search {
    /// (λ, ρ) of each trial in order, ρ after `search_iterations` warm-started iterations.
    pub trials: Vec<[f64; 2]>,
    /// The chosen λ: the trial whose ρ is closest to 1 (in ln).
    pub lambda: f64,
    /// True when a trial came within the tolerance (±10 %); false when ρ = 1 is out of reach
    /// within λ₀·10^±4 or the trials ran out (then the closest was taken).
    pub reached: bool,
}

impl JointStats {
    /// A warning when the run ended above the seed's objective: with TV the iterate is then
    /// far from a minimiser (on five scene files of `scenes/` 16 iterations lower it 9–500×); with
    /// plug-and-play the fit to the frame got worse than the Fourier seed's.
    pub fn warning(&self) -> Option<String> {
        let (&first, &last) = (self.objective.first()?, self.objective.last()?);
        if last.partial_cmp(&first) != Some(std::cmp::Ordering::Greater) || self.iterations == 0 {
            return None;
        }
        let (what, remedy) = match self.prior.as_str() {
            "pnp" => ("data term", "the denoiser outweighs the frame: lower reconstruct.joint.pnp_weight"),
            _ => ("objective", "the iterate is not near a minimiser: raise reconstruct.joint.iterations or bring step_ratio nearer 1"),
        };
        Some(format!(
            "joint: the {what} rose over the {} iterations ({first:.4e} → {last:.4e}); {remedy}",
            self.iterations
        ))
    }
}

/// The solver for one rig: the per-pixel operator a_p, the basis and the smoothness form.
pub struct Joint {
    w: usize,
    h: usize,
    j: usize,
    /// The layout of the iteration's fields (`rows.rs`).
    rows: Rows,
    cfg: JointConfig,
    /// The experiment file, named by an error that surfaces during a run.
    file: String,
    /// a_p = Fᵀ S'(p), pixel-major (J per pixel).
    a: Vec<f32>,
    /// βB by columns, each padded with zeros to `nbp` (a multiple of 8) bands, so the
    /// per-pixel products run over whole vector lanes.
    bcol: Vec<f32>,
    /// βB by rows (J coefficients, zero-padded), one per band: the band values βBα and Bᵀr.
    bmat: Vec<[f32; MAX_J]>,
    nbp: usize,
    /// The spectral prior P in the joint's units (P·mean‖a‖²/‖F‖²_F), J × J.
    eq: DMatrix<f64>,
    /// ‖K‖ bound: √(8 + β²λmax(BᵀB)).
    norm_k: f64,
    system: DMatrix<f64>,
    basis: DMatrix<f64>,
    /// (min_k, max_k) of each column of βB: the cheap feasibility bound of `surely_feasible`.
    col_range: Vec<(f32, f32)>,
    /// The same bound by column (min_k and max_k, zero-padded).
    col_lo: [f32; MAX_J],
    col_hi: [f32; MAX_J],
    mean_a_norm: f64,
}

/// The iterate, the dual variables and the per-frame tables of one run. The fields the
/// iteration sweeps are in `rows.rs`' layout (`Rows`); the frame's are w × h.
#[derive(Clone)]
pub struct JointState {
    rows: Rows,
    j: usize,
    /// Padded bands of `JointTables`, for [`JointState::duals`].
    nbp: usize,
    /// α (J a pixel).
    alpha: Vec<f32>,
    bar: Vec<f32>,
    /// TV dual: qx and qy, J a pixel each.
    qx: Vec<f32>,
    qy: Vec<f32>,
    /// 1 where the constraint dual r is non-zero somewhere in the pixel's bands.
    active: Vec<u8>,
    /// Constraint dual r ≤ 0 (banded: [`Rows::band`]).
    r: Vec<f32>,
    /// Proximal tables: M = (I + τη'Q)⁻¹, m_p = M a_p (J a pixel), and (t_p = τω_p y_p,
    /// c_p = τω_p / (1 + τω_p a_pᵀm_p), k_p = a_pᵀ m_p, the cap below) (4 a pixel).
    mat: Mat,
    m: Vec<f32>,
    tck: Vec<f32>,
    y: Vec<f32>,
    /// The data weights over their mean (so the spectral prior's balance against the data and
    /// λ's scale do not depend on the weights' units), and that mean.
    omega: Vec<f32>,
    omega_scale: f64,
    /// y_p where the pixel is saturated (a fit a_pᵀα ≥ y_p costs nothing there), else +∞.
    cap: Vec<f32>,
    /// Per-pixel TV weights (1 unless reweighted; one a pixel, in rows): the TV term is
    /// λ Σ_p w_p ‖∇α(p)‖.
    tvw: Vec<f32>,
    pub lambda: f32,
    pub tau: f32,
    pub sigma: f32,
    flush: f32,
    row_sums: Vec<f64>,
}

impl Joint {
    /// The experiment file it was built for (named by errors that surface in a run).
    pub fn file(&self) -> &str {
        &self.file
    }

    /// `patterns`: the C effective channel patterns S'_i (planes); `system` F (C × J);
    /// `basis` B (bands × J); `prior` the spectral prior's J × J quadratic term in the
    /// unmixer's units (`unmix::curvature(B, η)` or `Basis::coefficient_prior`).
    pub fn new(
        patterns: &Cube,
        system: &DMatrix<f64>,
        basis: &DMatrix<f64>,
        prior: &DMatrix<f64>,
        cfg: &JointConfig,
        file: &str,
    ) -> Result<Joint> {
        cfg.validate(file)?;
        let (w, h, n) = (patterns.width, patterns.height, patterns.pixels());
        let (c, j, bands) = (system.nrows(), system.ncols(), basis.nrows());
        if patterns.planes != c || basis.ncols() != j || n == 0 || j == 0 {
            return Err(Error::Shape(format!(
                "joint: {} pattern planes of {w}×{h}, F {c}×{j}, B {bands}×{}",
                patterns.planes,
                basis.ncols()
            )));
        }
        if j > MAX_J || bands > MAX_BANDS {
            return Err(Error::Shape(format!(
                "joint: J = {j} basis vectors and {bands} bands, at most {MAX_J} and {MAX_BANDS}"
            )));
        }
        if !patterns.all_finite() || system.iter().chain(basis.iter()).any(|v| !v.is_finite()) {
            return Err(Error::Numerical(
                "joint: the patterns, F or B hold a non-finite value".into(),
            ));
        }
        if prior.shape() != (j, j) || prior.iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!(
                "joint: the spectral prior is {}×{} or not finite; it must be a finite {j}×{j} matrix",
                prior.nrows(),
                prior.ncols()
            )));
        }
        let a = patterns.mix(
            &(0..j)
                .map(|jj| (0..c).map(|i| system[(i, jj)]).collect())
                .collect::<Vec<Vec<f64>>>(),
        )?;
        let a = to_pixel_major(&a);
        let mean_a2 = a.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / n as f64;
        if !(mean_a2 > 0.0 && mean_a2.is_finite()) {
            return Err(Error::Numerical(format!(
                "joint: the patterns through F carry no energy (mean ‖a‖² = {mean_a2:.3e}); the frame says nothing of α"
            )));
        }
        let mean_a_norm = a
            .chunks_exact(j)
            .map(|ap| ap.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt())
            .sum::<f64>()
            / n as f64;
        let btb = basis.transpose() * basis;
        let lmax = nalgebra::SymmetricEigen::new(btb).eigenvalues.max();
        if lmax <= 0.0 {
            return Err(Error::Numerical("joint: the basis B is zero".into()));
        }
        // β scales the constraint's block of K to the gradient's norm (‖∇‖² ≤ 8).
        let beta = (8.0 / lmax).sqrt();
        // The unmixer weighs ‖x − Fα‖² (data Hessian FᵀF) against the prior's αᵀPα; here the
        // data Hessian is a aᵀ, so P is scaled by mean‖a‖² / ‖F‖²_F to keep the same balance.
        let prior_scale = mean_a2 / system.norm_squared();
        let nbp = bands.div_ceil(LANES) * LANES;
        let col_range: Vec<(f32, f32)> = (0..j)
            .map(|jj| {
                let col = basis.column(jj) * beta;
                (col.min() as f32, col.max() as f32)
            })
            .collect();
        let bound =
            |f: fn(&(f32, f32)) -> f32| std::array::from_fn(|l| col_range.get(l).map_or(0.0, f));
        Ok(Joint {
            file: file.to_string(),
            w,
            h,
            j,
            rows: Rows::new(w, h),
            cfg: cfg.clone(),
            a,
            bcol: (0..j)
                .flat_map(|jj| {
                    (0..nbp).map(move |k| {
                        if k < bands {
                            (beta * basis[(k, jj)]) as f32
                        } else {
                            0.0
                        }
                    })
                })
                .collect(),
            bmat: (0..bands)
                .map(|k| {
                    std::array::from_fn(|jj| match jj < j {
                        true => (beta * basis[(k, jj)]) as f32,
                        false => 0.0,
                    })
                })
                .collect(),
            nbp,
            eq: prior * prior_scale,
            norm_k: 4.0,
            col_lo: bound(|r| r.0),
            col_hi: bound(|r| r.1),
            col_range,
            system: system.clone(),
            basis: basis.clone(),
            mean_a_norm,
        })
    }

    /// The state for `frame` (one plane) seeded by `seed` (J planes of α₀), with per-pixel
    /// data weights ω and saturated pixels (None: ω = 1, none saturated).
    pub fn start(
        &self,
        frame: &Cube,
        seed: &Cube,
        weights: Option<&DataWeights>,
    ) -> Result<JointState> {
        let omega = weights.map(|d| &d.omega);
        let (w, h, j, n) = (self.w, self.h, self.j, self.w * self.h);
        if (frame.width, frame.height, frame.planes) != (w, h, 1)
            || (seed.width, seed.height, seed.planes) != (w, h, j)
            || omega.is_some_and(|o| (o.width, o.height, o.planes) != (w, h, 1))
        {
            return Err(Error::Shape(format!(
                "joint: frame {}×{}×{}, seed {}×{}×{} for {w}×{h} and J = {j}",
                frame.width, frame.height, frame.planes, seed.width, seed.height, seed.planes
            )));
        }
        if !frame.all_finite() || !seed.all_finite() || omega.is_some_and(|o| !o.all_finite()) {
            return Err(Error::Numerical(
                "joint: the frame, the seed or the weights contain NaN or infinite values".into(),
            ));
        }
        let (omega, omega_scale) = normalised_weights(omega, n)?;
        let mean_y = frame.data.iter().map(|v| v.abs() as f64).sum::<f64>() / n as f64;
        let lambda = self.cfg.tv_weight * mean_y * self.mean_a_norm;
        let cap = match weights {
            Some(d) if d.saturated.len() != n => {
                return Err(Error::Shape(format!(
                    "joint: {} saturation flags for {n} pixels",
                    d.saturated.len()
                )))
            }
            Some(d) => (d.saturated.iter().zip(&frame.data))
                .map(|(&s, &y)| if s { y } else { f32::INFINITY })
                .collect(),
            None => vec![f32::INFINITY; n],
        };
        let rows = self.rows;
        let alpha = rows.planes_to_rows(&seed.data, j);
        let mut st = JointState {
            rows,
            j,
            nbp: self.nbp,
            bar: alpha.clone(),
            alpha,
            qx: vec![0.0; rows.len(j)],
            qy: vec![0.0; rows.len(j)],
            active: vec![0; rows.len(1)],
            r: crate::pages::zeroed(rows.len(self.bmat.len())),
            mat: [[0.0; MAX_J]; MAX_J],
            m: Vec::new(),
            tck: Vec::new(),
            y: frame.data.clone(),
            omega,
            omega_scale,
            cap,
            tvw: vec![1.0; rows.len(1)],
            lambda: lambda as f32,
            tau: 0.0,
            sigma: 0.0,
            row_sums: vec![0.0; h],
            flush: 0.0,
        };
        self.set_lambda(&mut st, lambda)?;
        Ok(st)
    }

    /// Set λ: the TV dual rescaled into the new ball, the steps balanced for it
    /// ([`Joint::balance_steps`]), the extrapolation restarted (ᾱ = α).
    pub fn set_lambda(&self, st: &mut JointState, lambda: f64) -> Result<()> {
        let f = if st.lambda > 0.0 {
            (lambda / st.lambda as f64) as f32
        } else {
            0.0
        };
        st.qx
            .iter_mut()
            .chain(st.qy.iter_mut())
            .for_each(|v| *v *= f);
        self.balance_steps(st, lambda)?;
        st.bar.copy_from_slice(&st.alpha);
        Ok(())
    }

    /// λ, the steps for the balance s = mean|α|/λ of the current α (τ = ratio·s/L,
    /// σ = 1/(ratio·s·L)) and the proximal tables for the new τ; the duals and ᾱ are kept.
    fn balance_steps(&self, st: &mut JointState, lambda: f64) -> Result<()> {
        // The padding's zeros add nothing to the sum.
        let mean_alpha = st.alpha.iter().map(|v| v.abs() as f64).sum::<f64>()
            / (self.w * self.h * self.j) as f64;
        let scale = if lambda > 0.0 && mean_alpha > 0.0 {
            mean_alpha / lambda
        } else {
            1.0
        };
        let tau = self.cfg.step_ratio * scale * STEP_PRODUCT.sqrt() / self.norm_k;
        let sigma = STEP_PRODUCT.sqrt() / (self.cfg.step_ratio * scale * self.norm_k);
        let (mat, m, tck) = self.prox_tables(tau, st)?;
        st.m = self.rows.pixel_major_to_rows(&m, self.j);
        st.tck = self.rows.pixel_major_to_rows(tck.as_flattened(), 4);
        (st.mat, st.lambda, st.tau, st.sigma) = (mat, lambda as f32, tau as f32, sigma as f32);
        Ok(())
    }

    /// The proximal tables of τ for `st`'s frame, weights and caps: M = (I + τη'Q)⁻¹,
    /// m_p = M a_p and (τω_p y_p, τω_p/(1 + τω_p k_p), k_p = a_pᵀm_p, cap_p) per pixel, both
    /// pixel-major.
    fn prox_tables(&self, tau: f64, st: &JointState) -> Result<(Mat, Vec<f32>, Vec<[f32; 4]>)> {
        let (y, omega) = (&st.y, &st.omega);
        let (j, n) = (self.j, self.w * self.h);
        let inv = (DMatrix::identity(j, j) + tau * &self.eq)
            .try_inverse()
            .ok_or_else(|| Error::Numerical("joint: I + τη'Q is singular".into()))?;
        let mat: Mat = std::array::from_fn(|r| {
            std::array::from_fn(|c| match r < j && c < j {
                true => inv[(r, c)] as f32,
                false => 0.0,
            })
        });
        let mut m = vec![0.0f32; n * j];
        let mut tck = vec![[0.0f32; 4]; n];
        m.par_chunks_mut(j)
            .zip(tck.par_iter_mut())
            .zip(self.a.par_chunks(j))
            .zip(y.par_iter().zip(omega.par_iter()).zip(&st.cap))
            .for_each(|(((mp, t), ap), ((&y, &om), &cap))| {
                let k = with_basis_len!(j, J => {
                    let a: [f32; J] = std::array::from_fn(|c| ap[c]);
                    let ma = mat_vec::<J, Scalar>(&mat, a);
                    mp.copy_from_slice(&ma);
                    Scalar::tree_sum::<J>(std::array::from_fn(|c| a[c] * ma[c]))
                });
                let tw = tau as f32 * om;
                *t = [tw * y, tw / (1.0 + tw * k), k, cap];
            });
        Ok((mat, m, tck))
    }

    /// Σ_p ω_p r_p² (r_p the data residual, one-sided where saturated) and the number of
    /// pixels with ω_p > 0.
    pub fn weighted_residual(&self, st: &JointState) -> (f64, usize) {
        let (w, j, wp) = (self.w, self.j, self.rows.wp);
        let sum = st
            .alpha
            .par_chunks(self.rows.row_len(j))
            .zip(self.a.par_chunks(w * j))
            .zip(
                st.y.par_chunks(w)
                    .zip(st.omega.par_chunks(w))
                    .zip(st.cap.par_chunks(w)),
            )
            .map(|((al, ar), ((y, om), cap))| {
                let pixels = ar.chunks_exact(j).zip(y.iter().zip(om).zip(cap));
                let mut sum = 0.0;
                for (x, (ap, ((&y, &om), &cap))) in pixels.enumerate() {
                    let fit: f64 = pixel_values(al, wp, j, x)
                        .zip(ap)
                        .map(|(u, v)| u as f64 * *v as f64)
                        .sum();
                    sum += om as f64 * data_residual(y, fit, cap).powi(2);
                }
                sum
            })
            .sum::<f64>();
        (
            sum * st.omega_scale,
            st.omega.iter().filter(|&&v| v > 0.0).count(),
        )
    }

    /// One Chambolle–Pock iteration: the dual steps on ∇ᾱ and βBᾱ, then the primal
    /// proximal step and the extrapolation ᾱ = 2α⁺ − x (both steps relaxed by γ: x = α at
    /// γ = 1). Returns the objective at the α the iteration started from (computed in the
    /// dual pass, which reads α's rows anyway).
    pub fn step(&self, st: &mut JointState) -> f64 {
        self.sweep(st, true, STRIP_ROWS)
    }

    /// One iteration without the objective (the same iterate as [`Joint::step`]).
    fn step_untraced(&self, st: &mut JointState) {
        self.sweep(st, false, STRIP_ROWS);
    }

    /// One iteration in one pass over strips of `rows` rows (in parallel): row by row, the
    /// dual update (q ← P_{‖·‖≤λ}(q + σ∇ᾱ), r ← min(r + σβBᾱ, 0), both relaxed) and then the
    /// row's primal update, while its q and r (and q of the row above) are still in cache. A
    /// strip's first row needs q of the strip above, so its primal update waits until all
    /// strips are done; until then its ᾱ and α are the old ones, which the strip above reads.
    /// The same bits for any `rows` (1: every dual update, then every primal one). With `cost`,
    /// returns the objective at α before the step.
    fn sweep(&self, st: &mut JointState, cost: bool, rows: usize) -> f64 {
        let (wp, nb) = (self.rows.wp, self.bmat.len());
        let rl = self.rows.row_len(self.j);
        let tables = SweepTables {
            data: DataTerm {
                y: &st.y,
                om: &st.omega,
                cap: &st.cap,
                tvw: &st.tvw,
            },
            mat: &st.mat,
            m: &st.m,
            tck: &st.tck,
            sigma: st.sigma,
            lambda: st.lambda,
            flush: st.flush,
            tau: st.tau,
        };
        let halo = (
            first_rows(&st.bar, rl, rows),
            match cost {
                true => first_rows(&st.alpha, rl, rows),
                false => Vec::new(),
            },
        );
        let fields = StripFields {
            alpha: &mut st.alpha,
            bar: &mut st.bar,
            qx: &mut st.qx,
            qy: &mut st.qy,
            r: &mut st.r,
            active: &mut st.active,
            sums: &mut st.row_sums,
        };
        let strips = Strip::split(fields, (wp, self.j, nb), rows, &halo);
        strips.into_par_iter().for_each_init(
            || (vec![0.0f32; rl], vec![0.0f32; rl]),
            |scratch, strip| self.strip_pass(strip, &tables, cost, scratch),
        );
        let (qx, qy, active, r) = (&st.qx, &st.qy, &st.active, &st.r);
        st.alpha
            .par_chunks_mut(rows * rl)
            .zip(st.bar.par_chunks_mut(rows * rl))
            .enumerate()
            .for_each_init(
                || vec![0.0f32; rl],
                |div, (s, (alpha, bar))| {
                    let yy = s * rows;
                    let duals = RowDuals {
                        qx: &qx[yy * rl..],
                        qy: &qy[yy * rl..],
                        up: row_above(qy, rl, yy),
                        active: &active[yy * wp..],
                        r: &r[yy * wp * nb..],
                    };
                    let rows = (&mut alpha[..rl], &mut bar[..rl]);
                    self.primal_at(yy, rows, duals, &tables, div);
                },
            );
        st.row_sums.iter().sum()
    }

    /// Phase one of [`Joint::sweep`] on one strip: each row's dual update (and its share of
    /// the objective) and the primal update of every row but the first.
    fn strip_pass(
        &self,
        s: Strip<'_>,
        t: &SweepTables<'_>,
        cost: bool,
        (ga, gb): &mut (Vec<f32>, Vec<f32>),
    ) {
        let (wp, nb, rl) = (self.rows.wp, self.bmat.len(), self.rows.row_len(self.j));
        let (sigma, lambda, flush) = (t.sigma, t.lambda, t.flush);
        let Strip {
            y0,
            f,
            next_bar,
            next_alpha,
        } = s;
        for k in 0..f.sums.len() {
            let yy = y0 + k;
            if cost {
                let next = f.alpha.get((k + 1) * rl..(k + 2) * rl).or(next_alpha);
                f.sums[k] = self.row_cost(
                    (&f.alpha[k * rl..(k + 1) * rl], next),
                    &t.data,
                    lambda,
                    yy,
                    (ga, gb),
                );
            }
            let next = f.bar.get((k + 1) * rl..(k + 2) * rl).or(next_bar);
            let bar = &f.bar[k * rl..(k + 1) * rl];
            row_gradients((bar, next), self.rows, ga, gb);
            let row = DualRow {
                qx: &mut f.qx[k * rl..(k + 1) * rl],
                qy: &mut f.qy[k * rl..(k + 1) * rl],
                r: &mut f.r[k * wp * nb..(k + 1) * wp * nb],
                active: &mut f.active[k * wp..(k + 1) * wp],
                weight: &t.data.tvw[yy * wp..(yy + 1) * wp],
            };
            let step = DualStep {
                gx: ga,
                gy: gb,
                sigma,
                lambda,
                flush,
            };
            with_basis_len!(self.j, J => lane::dispatch(DualKernel::<J> { joint: self, row, bar, step }));
            if k > 0 {
                let duals = RowDuals {
                    qx: &f.qx[k * rl..],
                    qy: &f.qy[k * rl..],
                    up: Some(&f.qy[(k - 1) * rl..k * rl]),
                    active: &f.active[k * wp..],
                    r: &f.r[k * wp * nb..],
                };
                let rows = (
                    &mut f.alpha[k * rl..(k + 1) * rl],
                    &mut f.bar[k * rl..(k + 1) * rl],
                );
                self.primal_at(yy, rows, duals, t, ga);
            }
        }
    }

    /// The primal update of row `yy` (α and ᾱ there, written) from its duals; `div` is
    /// scratch for the row's div q.
    fn primal_at(
        &self,
        yy: usize,
        (alpha, bar): (&mut [f32], &mut [f32]),
        d: RowDuals<'_>,
        t: &SweepTables<'_>,
        div: &mut [f32],
    ) {
        let (j, wp, nb) = (self.j, self.rows.wp, self.bmat.len());
        row_divergence(d.qx, d.qy, d.up, self.rows, div);
        let row = PrimalRow {
            alpha,
            bar,
            div,
            active: &d.active[..wp],
            r: &d.r[..wp * nb],
            m: &t.m[yy * wp * j..(yy + 1) * wp * j],
            tck: &t.tck[yy * wp * 4..(yy + 1) * wp * 4],
        };
        with_basis_len!(j, J => lane::dispatch(PrimalKernel::<J> { joint: self, row, mat: t.mat, tau: t.tau }));
    }

    /// Bit l set where pixel l of `alpha` has min_k Σ_j βB_kj α_j ≥ 0 by the per-column
    /// extremes of βB alone.
    #[inline(always)]
    fn surely_feasible<const J: usize, L: Lanes>(&self, alpha: [L::V; J]) -> u32 {
        let zero = L::splat(0.0);
        L::nonneg_bits(L::tree_sum::<J>(fields!(L, J, |c| {
            let low = L::mul(alpha[c], L::splat(self.col_lo[c]));
            let high = L::mul(alpha[c], L::splat(self.col_hi[c]));
            L::select_ge(alpha[c], zero, low, high)
        })))
    }

    /// Row `yy`'s share of the objective Σ ½ω(y − aᵀα)² + ½αᵀη'Qα + λ‖∇α‖, in f64 in pixel
    /// order, from α's row and the row below; (gx, gy) is scratch for the row's ∇α.
    fn row_cost(
        &self,
        (alpha, next): (&[f32], Option<&[f32]>),
        data: &DataTerm<'_>,
        lambda: f32,
        yy: usize,
        (gx, gy): (&mut [f32], &mut [f32]),
    ) -> f64 {
        let (w, j) = (self.w, self.j);
        row_gradients((alpha, next), self.rows, gx, gy);
        let px = yy * w..(yy + 1) * w;
        let row = CostRow {
            alpha,
            a: &self.a[px.start * j..px.end * j],
            y: &data.y[px.clone()],
            om: &data.om[px.clone()],
            cap: &data.cap[px],
            tvw: &data.tvw[yy * self.rows.wp..],
            gx,
            gy,
        };
        with_basis_len!(j, J => self.row_cost_j::<J>(row, lambda))
    }

    /// [`Joint::row_cost`] with J fixed per compiled copy.
    #[inline(always)]
    fn row_cost_j<const J: usize>(&self, row: CostRow<'_>, lambda: f32) -> f64 {
        let wp = self.rows.wp;
        let eq: [[f64; J]; J] = std::array::from_fn(|r| std::array::from_fn(|c| self.eq[(r, c)]));
        let at = |v: &[f32], x: usize| -> [f32; J] { std::array::from_fn(|c| v[c * wp + x]) };
        let data = row.y.iter().zip(row.om).zip(row.cap.iter().zip(row.tvw));
        let mut sum = 0.0;
        for ((x, a), ((&y, &om), (&cap, &tw))) in row.a.chunks_exact(J).enumerate().zip(data) {
            let alpha = at(row.alpha, x);
            let fit: f64 = a.iter().zip(alpha).map(|(u, v)| *u as f64 * v as f64).sum();
            let mut quad = 0.0;
            for (r, er) in eq.iter().enumerate() {
                for (c, e) in er.iter().enumerate() {
                    quad += alpha[r] as f64 * e * alpha[c] as f64;
                }
            }
            let (gx, gy) = (at(row.gx, x), at(row.gy, x));
            let g2: f64 = gx.iter().chain(&gy).map(|&g| (g as f64).powi(2)).sum();
            let r = data_residual(y, fit, cap);
            sum += 0.5 * om as f64 * r * r + 0.5 * quad + (lambda * tw) as f64 * g2.sqrt();
        }
        sum
    }

    /// The dual update of one row given ∇ᾱ there (gx, gy): q ← P_{‖·‖≤λ}(q + σ∇ᾱ) per pixel
    /// and r by [`Joint::constraint_dual`], each result t stored relaxed as t + (γ − 1)(t − old).
    /// J is the basis length, fixed per compiled copy, and `L` the lanes: `L::WIDTH` pixels
    /// at a time.
    #[inline(always)]
    fn dual_row<const J: usize, L: Lanes>(&self, row: DualRow<'_>, bar: &[f32], step: DualStep) {
        let wp = self.rows.wp;
        let over = L::splat(self.cfg.relaxation as f32 - 1.0);
        let (sigma, lambda) = (L::splat(step.sigma), L::splat(step.lambda));
        for x in (0..wp).step_by(L::WIDTH) {
            let (ox, oy) = (
                L::load_fields::<J>(row.qx, wp, x),
                L::load_fields::<J>(row.qy, wp, x),
            );
            let (gx, gy) = (
                L::load_fields::<J>(step.gx, wp, x),
                L::load_fields::<J>(step.gy, wp, x),
            );
            let tx = fields!(L, J, |c| L::add_scaled(ox[c], sigma, gx[c]));
            let ty = fields!(L, J, |c| L::add_scaled(oy[c], sigma, gy[c]));
            let n2 = L::tree_sum::<J>(fields!(L, J, |c| {
                L::add(L::mul(tx[c], tx[c]), L::mul(ty[c], ty[c]))
            }));
            let f = ball_factor::<L>(n2, L::mul(lambda, L::load(&row.weight[x..])));
            let qx = fields!(L, J, |c| relaxed::<L>(ox[c], L::mul(tx[c], f), over));
            let qy = fields!(L, J, |c| relaxed::<L>(oy[c], L::mul(ty[c], f), over));
            L::store_fields(row.qx, wp, x, qx);
            L::store_fields(row.qy, wp, x, qy);
            let bl = L::load_fields::<J>(bar, wp, x);
            let live = L::load_flags(&row.active[x..]);
            let idle = !live & self.surely_feasible::<J, L>(bl) & L::ALL;
            if idle == L::ALL || (live == 0 && self.all_bands_nonneg::<J, L>(bl)) {
                // r = 0 and βBᾱ ≥ 0 at every pixel: r stays 0 (not touched).
                continue;
            }
            let dual = ConstraintStep {
                idle,
                sigma,
                over,
                flush: step.flush,
            };
            let live = self.constraint_dual::<J, L>(bl, (row.r, x), dual);
            L::store_flags(&mut row.active[x..], live);
        }
    }

    /// Band k's value βB_kᾱ of `bl`, its products summed in column order.
    #[inline(always)]
    fn band_value<const J: usize, L: Lanes>(b: &[f32; MAX_J], bl: &[L::V; J]) -> L::V {
        let mut v = L::splat(0.0);
        for (&bc, &a) in b[..J].iter().zip(bl) {
            v = L::add(v, L::mul(L::splat(bc), a));
        }
        v
    }

    /// True when every band value βB_kᾱ of every pixel of `bl` is ≥ 0 (or NaN, as `min0`).
    #[inline(always)]
    fn all_bands_nonneg<const J: usize, L: Lanes>(&self, bl: [L::V; J]) -> bool {
        let mut low = L::splat(0.0);
        for b in &self.bmat {
            low = L::add(low, L::min0(Self::band_value::<J, L>(b, &bl)));
        }
        L::nonzero_bits(low) == 0
    }

    /// r ← min(r + σβBᾱ, 0) at pixels x.. of a row's r ([`Rows::band`]), relaxed, with the
    /// values under the flush threshold set to 0; the `idle` pixels (r = 0 and βBᾱ ≥ 0 by
    /// `surely_feasible`) keep r = 0. Returns the bits of the pixels whose r is non-zero.
    #[inline(always)]
    fn constraint_dual<const J: usize, L: Lanes>(
        &self,
        bl: [L::V; J],
        (r, x): (&mut [f32], usize),
        step: ConstraintStep<L>,
    ) -> u32 {
        let (zero, nb) = (L::splat(0.0), self.bmat.len());
        // Relaxed (γ > 1), r may leave r ≤ 0, so the flag marks r ≠ 0.
        let mut live = 0;
        for (k, b) in self.bmat.iter().enumerate() {
            let u = L::select_bits(step.idle, zero, Self::band_value::<J, L>(b, &bl));
            let at = &mut r[Rows::band(nb, k, x)..];
            let old = L::load(at);
            let next = relaxed::<L>(old, L::min0(L::add_scaled(old, step.sigma, u)), step.over);
            let next = L::flush(next, step.flush);
            L::store(at, next);
            live |= L::nonzero_bits(next);
        }
        live
    }

    /// The primal update of one row given div q there: α⁺ = prox_{τf}(x + τ(div q − βBᵀr)),
    /// ᾱ = 2α⁺ − x (x = α + (γ − 1)(ᾱ − α), the relaxed point), with J and the lanes as in
    /// [`Joint::dual_row`].
    #[inline(always)]
    fn primal_row<const J: usize, L: Lanes>(&self, row: PrimalRow<'_>, mat: &Mat, tau: f32) {
        let wp = self.rows.wp;
        let (over, tau) = (L::splat(self.cfg.relaxation as f32 - 1.0), L::splat(tau));
        for x in (0..wp).step_by(L::WIDTH) {
            // The relaxed primal point x = α⁻ + γ(α − α⁻), with α⁻ = 2α − ᾱ the point the
            // last prox step started from.
            let a = L::load_fields::<J>(row.alpha, wp, x);
            let b = L::load_fields::<J>(row.bar, wp, x);
            let div = L::load_fields::<J>(row.div, wp, x);
            let xr = fields!(L, J, |c| L::add_scaled(a[c], over, L::sub(b[c], a[c])));
            let mut v = fields!(L, J, |c| L::add_scaled(xr[c], tau, div[c]));
            if L::load_flags(&row.active[x..]) != 0 {
                let btr = self.basis_t_times::<J, L>(row.r, x);
                v = fields!(L, J, |c| L::sub(v[c], L::mul(tau, btr[c])));
            }
            let mp = L::load_fields::<J>(row.m, wp, x);
            let mv = prox::<J, L>(mat, mp, L::load_fields::<4>(row.tck, wp, x), v);
            let bar = fields!(L, J, |c| L::sub(L::add(mv[c], mv[c]), xr[c]));
            L::store_fields(row.bar, wp, x, bar);
            L::store_fields(row.alpha, wp, x, mv);
        }
    }

    /// βBᵀr at pixels x.. of a row's r ([`Rows::band`]), summed in band order.
    #[inline(always)]
    fn basis_t_times<const J: usize, L: Lanes>(&self, r: &[f32], x: usize) -> [L::V; J] {
        let nb = self.bmat.len();
        let mut out = [L::splat(0.0); J];
        for (k, b) in self.bmat.iter().enumerate() {
            let rk = L::load(&r[Rows::band(nb, k, x)..]);
            for (o, &bc) in out.iter_mut().zip(&b[..J]) {
                *o = L::add(*o, L::mul(L::splat(bc), rk));
            }
        }
        out
    }

    /// ½Σω(y − aᵀα)² + ½Σ αᵀη'Qα + λΣ‖∇α‖ at the current α (row sums in f64, fixed order).
    pub fn objective(&self, st: &mut JointState) -> f64 {
        let rl = self.rows.row_len(self.j);
        let (alpha, lambda) = (&st.alpha, st.lambda);
        let data = DataTerm {
            y: &st.y,
            om: &st.omega,
            cap: &st.cap,
            tvw: &st.tvw,
        };
        st.row_sums.par_iter_mut().enumerate().for_each_init(
            || (vec![0.0f32; rl], vec![0.0f32; rl]),
            |(gx, gy), (yy, sum)| {
                *sum = self.row_cost(row_pair(alpha, rl, yy), &data, lambda, yy, (gx, gy))
            },
        );
        st.row_sums.iter().sum()
    }

    /// `iterations` Chambolle–Pock steps, the steps rebalanced halfway and the TV weights
    /// refreshed between stages as `stages` says: the objective before each (traced; else at
    /// the start only) and after the last.
    fn iterate(&self, st: &mut JointState, iterations: usize, stages: Stages) -> Result<Vec<f64>> {
        let mut objective = Vec::with_capacity(iterations + 1);
        // f32 as on the GPU (`flush_start`), which then decays it the same way.
        st.flush = self.cfg.dual_flush as f32 * st.lambda;
        if !self.cfg.trace_objective {
            objective.push(self.objective(st));
        }
        for it in 0..iterations {
            crate::interrupt::check("the joint reconstruction")?;
            if stages.rebalance && rebalances_before(it, iterations) {
                self.balance_steps(st, st.lambda as f64)?;
            }
            if reweights_before(it, iterations, stages.reweights) {
                self.reweight(st);
            }
            if self.cfg.trace_objective {
                objective.push(self.step(st));
            } else {
                self.step_untraced(st);
            }
            st.flush *= FLUSH_DECAY;
        }
        objective.push(self.objective(st));
        Ok(objective)
    }

    /// The TV weights from the current α: w_p = ε/(e_p + ε), e_p the excess of ‖∇α(p)‖ over
    /// its 3 × 3 mean (a jump is a thin ridge of the gradient, shading a broad plateau: only
    /// jumps lose weight), ε = `reweight_eps` × the mean ‖∇α(p)‖; the dual q projected into
    /// the new balls, the extrapolation restarted.
    fn reweight(&self, st: &mut JointState) {
        let (w, h, j, wp) = (self.w, self.h, self.j, self.rows.wp);
        let (alpha, rl) = (&st.alpha, self.rows.row_len(j));
        let mut g = vec![0.0f32; w * h];
        g.par_chunks_mut(w).enumerate().for_each_init(
            || (vec![0.0f32; rl], vec![0.0f32; rl]),
            |(gx, gy), (yy, row)| {
                row_gradients(row_pair(alpha, rl, yy), self.rows, gx, gy);
                for (x, g) in row.iter_mut().enumerate() {
                    let grad = pixel_values(gx, wp, j, x).chain(pixel_values(gy, wp, j, x));
                    *g = grad.map(|v| v * v).sum::<f32>().sqrt();
                }
            },
        );
        let mean = g.iter().map(|&v| v as f64).sum::<f64>() / g.len() as f64;
        let eps = (self.cfg.reweight_eps * mean) as f32;
        let excess = ridge_excess(&g, w, h);
        let lambda = st.lambda;
        st.tvw
            .par_chunks_mut(wp)
            .zip(st.qx.par_chunks_mut(rl).zip(st.qy.par_chunks_mut(rl)))
            .zip(excess.par_chunks(w))
            .for_each(|((tw, (qx, qy)), e)| {
                for (x, (t, &e)) in tw.iter_mut().zip(e).enumerate() {
                    *t = if eps > 0.0 { eps / (e + eps) } else { 1.0 };
                    let q = pixel_values(qx, wp, j, x).chain(pixel_values(qy, wp, j, x));
                    let n2: f32 = q.map(|v| v * v).sum();
                    let f = ball_factor::<Scalar>(n2, lambda * *t);
                    for c in 0..j {
                        qx[c * wp + x] *= f;
                        qy[c * wp + x] *= f;
                    }
                }
            });
        st.bar.copy_from_slice(&st.alpha);
    }

    /// The stats of a run ending in `st` (α finite, else an error).
    fn finish(
        &self,
        st: &JointState,
        objective: Vec<f64>,
        t0: Instant,
        noise_weights: bool,
    ) -> Result<JointStats> {
        if !st.alpha.iter().all(|v| v.is_finite()) {
            let c = &self.cfg;
            return Err(Error::Numerical(format!(
                "joint: non-finite coefficients after {} iterations (step_ratio {:e}, relaxation {}, tv_weight {:e})",
                c.iterations, c.step_ratio, c.relaxation, c.tv_weight
            ))
            .within(&self.file, "reconstruct.gap.method", "\"joint\""));
        }
        let (sum, n) = self.weighted_residual(st);
        Ok(JointStats {
            iterations: self.cfg.iterations,
            objective,
            lambda: st.lambda as f64,
            steps: [st.tau as f64, st.sigma as f64],
            relaxation: (self.cfg.prior == Prior::Tv).then_some(self.cfg.relaxation),
            dual_flush: (self.cfg.prior == Prior::Tv).then_some(self.cfg.dual_flush),
            violation: 0.0,
            seconds: t0.elapsed().as_secs_f64(),
            prior: format!("{:?}", self.cfg.prior).to_lowercase(),
            spectral_prior: self.cfg.spectral_prior_name().into(),
            residual_ratio: sum / n.max(1) as f64,
            noise_weights,
            saturated_pixels: st.cap.iter().filter(|c| c.is_finite()).count(),
            reweight_rounds: self.cfg.rounds(),
            discrepancy: None,
            fixed_point: Vec::new(),
        })
    }

    /// The squared M-norm ‖z⁺ − z‖²_M of one step (M = [[I/τ, −Kᵀ], [−K, I/σ]]) of the state
    /// z = (x, q, r), x = 2α − ᾱ the point the next prox step starts from: PDHG is a
    /// proximal-point method in this metric and its relaxation a Krasnosel'skii–Mann iteration
    /// of it, so the value never increases along the iterations (He & Yuan 2012).
    pub fn step_residual(&self, before: &JointState, after: &JointState) -> f64 {
        let d =
            |u: &[f32], v: &[f32]| -> Vec<f32> { u.iter().zip(v).map(|(a, b)| a - b).collect() };
        let dot = |u: &[f32], v: &[f32]| -> f64 {
            u.iter().zip(v).map(|(a, b)| *a as f64 * *b as f64).sum()
        };
        let da = d(&after.start_point(), &before.start_point());
        let (dqx, dqy, dr) = (
            d(&after.qx, &before.qx),
            d(&after.qy, &before.qy),
            d(&after.r, &before.r),
        );
        let (gx, gy, bda) = self.apply_k(&da);
        dot(&da, &da) / after.tau as f64
            + (dot(&dqx, &dqx) + dot(&dqy, &dqy) + dot(&dr, &dr)) / after.sigma as f64
            - 2.0 * (dot(&gx, &dqx) + dot(&gy, &dqy) + dot(&bda, &dr))
    }

    /// Kα = (∇α, βBα) of α in rows (`rows.rs`), in rows (βBα banded as r is).
    fn apply_k(&self, alpha: &[f32]) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let (j, nb, wp) = (self.j, self.bmat.len(), self.rows.wp);
        let rl = self.rows.row_len(j);
        let (mut gx, mut gy) = (vec![0.0f32; alpha.len()], vec![0.0f32; alpha.len()]);
        for (yy, (rx, ry)) in gx.chunks_mut(rl).zip(gy.chunks_mut(rl)).enumerate() {
            row_gradients(row_pair(alpha, rl, yy), self.rows, rx, ry);
        }
        let mut bv = vec![0.0f32; self.rows.len(nb)];
        for (a, u) in alpha.chunks(rl).zip(bv.chunks_mut(wp * nb)) {
            for (k, b) in self.bmat.iter().enumerate() {
                for x in 0..self.w {
                    u[Rows::band(nb, k, x)] = (0..j).map(|c| b[c] * a[c * wp + x]).sum();
                }
            }
        }
        (gx, gy, bv)
    }

    /// ‖K‖² by power iteration on KᵀK (for checking the bound the steps use).
    pub fn power_iteration(&self, iterations: usize) -> f64 {
        let (w, j, nb, wp) = (self.w, self.j, self.bmat.len(), self.rows.wp);
        let rl = self.rows.row_len(j);
        let start: Vec<f32> = (0..self.w * self.h * j)
            .map(|i| ((i * 7919) % 101) as f32 / 101.0 - 0.5)
            .collect();
        let mut v = self.rows.pixel_major_to_rows(&start, j);
        let mut est = 0.0;
        let mut div = vec![0.0f32; rl];
        for _ in 0..iterations {
            let norm = v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
            v.iter_mut().for_each(|x| *x /= norm as f32);
            let (gx, gy, bv) = self.apply_k(&v);
            let mut out = vec![0.0f32; v.len()];
            for (yy, orow) in out.chunks_mut(rl).enumerate() {
                let at = yy * rl..;
                let up = row_above(&gy, rl, yy);
                row_divergence(&gx[at.clone()], &gy[at], up, self.rows, &mut div);
                let bvr = &bv[yy * wp * nb..];
                for (c, x) in (0..j).flat_map(|c| (0..w).map(move |x| (c, x))) {
                    let btr: f32 = (self.bmat.iter().enumerate())
                        .map(|(k, b)| b[c] * bvr[Rows::band(nb, k, x)])
                        .sum();
                    orow[c * wp + x] = btr - div[c * wp + x];
                }
            }
            est = out.iter().zip(&v).map(|(a, b)| (a * b) as f64).sum::<f64>();
            v = out;
        }
        est
    }

    /// The channels x = Fα (C planes) of coefficient planes α.
    pub fn channels(&self, alpha: &Cube) -> Result<Cube> {
        alpha.mix(&rows(&self.system))
    }

    /// The cube diag(gains)·Bα with its negative values (the constraint's violation left by the
    /// last iterate) set to zero, and that violation relative to the largest value.
    pub fn cube(&self, alpha: &Cube, gains: Option<&[f64]>) -> Result<(Cube, f64)> {
        let mut b = rows(&self.basis);
        if let Some(g) = gains {
            b.iter_mut()
                .zip(g)
                .for_each(|(row, g)| row.iter_mut().for_each(|v| *v *= g));
        }
        let mut cube = alpha.mix(&b)?;
        // The range and the clip in one pass over the cube.
        let (lo, hi) = cube
            .data
            .par_chunks_mut(1 << 16)
            .map(|c| {
                c.iter_mut().fold((0.0f32, 0.0f32), |(lo, hi), v| {
                    let range = (lo.min(*v), hi.max(*v));
                    *v = v.max(0.0);
                    range
                })
            })
            .reduce(|| (0.0, 0.0), |(a, b), (c, d)| (a.min(c), b.max(d)));
        let violation = if hi > 0.0 && lo < 0.0 {
            (-lo / hi) as f64
        } else {
            0.0
        };
        Ok((cube, violation))
    }

    /// The bound ‖K‖ the step sizes use.
    pub fn operator_norm(&self) -> f64 {
        self.norm_k
    }

    /// The per-rig tables a backend mirrors to run these iterations (see [`JointTables`]).
    pub fn tables(&self) -> JointTables<'_> {
        JointTables {
            width: self.w,
            height: self.h,
            basis_len: self.j,
            padded_bands: self.nbp,
            config: &self.cfg,
            a: &self.a,
            basis_columns: &self.bcol,
            column_range: &self.col_range,
            spectral_prior: &self.eq,
            operator_norm: self.norm_k,
            mean_a_norm: self.mean_a_norm,
            step_product: STEP_PRODUCT,
            system: &self.system,
            basis: &self.basis,
        }
    }
}

/// The data weights (1 without any) over their mean, and the mean; negative, NaN or infinite
/// weights and weights that are all zero are refused. The CPU's `start` and the GPU's
/// `set_weights` both take ω through it.
pub fn normalised_weights(omega: Option<&Cube>, n: usize) -> Result<(Vec<f32>, f64)> {
    let Some(o) = omega else {
        return Ok((vec![1.0; n], 1.0));
    };
    if o.data.iter().any(|&v| !(v.is_finite() && v >= 0.0)) {
        return Err(Error::Numerical(
            "joint: a data weight is negative, NaN or infinite".into(),
        ));
    }
    let mean = o.data.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
    if mean <= 0.0 {
        return Err(Error::Numerical(
            "joint: every data weight is zero; there is no measurement to fit".into(),
        ));
    }
    Ok((
        o.data.iter().map(|&v| (v as f64 / mean) as f32).collect(),
        mean,
    ))
}

/// Read-only view of a `Joint`'s tables, for a backend (specmux-gpu) that runs the same
/// iterations: every value `start` and `step` read besides the frame, the seed and ω.
pub struct JointTables<'a> {
    pub width: usize,
    pub height: usize,
    /// J.
    pub basis_len: usize,
    /// Bands padded to whole lanes (the length of each column of `basis_columns`).
    pub padded_bands: usize,
    pub config: &'a JointConfig,
    /// a_p = Fᵀ S'(p), pixel-major (J per pixel).
    pub a: &'a [f32],
    /// βB by columns, each padded with zeros to `padded_bands`.
    pub basis_columns: &'a [f32],
    /// (min_k, max_k) of each column of βB (`surely_feasible`'s bound).
    pub column_range: &'a [(f32, f32)],
    /// The spectral prior's quadratic term in the joint's units (J × J).
    pub spectral_prior: &'a DMatrix<f64>,
    /// The bound on ‖K‖ the steps use.
    pub operator_norm: f64,
    /// mean‖a_p‖ (λ's scale).
    pub mean_a_norm: f64,
    /// τσ‖K‖².
    pub step_product: f64,
    pub system: &'a DMatrix<f64>,
    pub basis: &'a DMatrix<f64>,
}

impl JointState {
    /// α, pixel-major (J per pixel).
    pub fn alpha(&self) -> Vec<f32> {
        self.rows.rows_to_pixel_major(&self.alpha, self.j)
    }

    /// α as J planes.
    pub fn alpha_cube(&self) -> Cube {
        let (w, h) = (self.rows.w, self.rows.h);
        Cube::from_vec(w, h, self.j, self.rows.rows_to_planes(&self.alpha, self.j))
            .expect("J planes of w × h")
    }

    /// Set α from pixel-major values (J per pixel).
    fn set_alpha(&mut self, pixel_major: &[f32]) {
        self.alpha = self.rows.pixel_major_to_rows(pixel_major, self.j);
    }

    /// The dual variables and the active flags, pixel-major: (qx, qy, r, active), r padded to
    /// `JointTables::padded_bands` per pixel (for checking another backend's steps).
    pub fn duals(&self) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<u8>) {
        let (rows, j, nbp) = (self.rows, self.j, self.nbp);
        let bands = self.r.len() / rows.len(1).max(1);
        let r = rows.bands_to_pixel_major(&self.r, bands);
        let padded = r.chunks(bands.max(1)).flat_map(|p| {
            p.iter()
                .copied()
                .chain(std::iter::repeat(0.0).take(nbp - bands))
        });
        let active = (self.active.chunks(rows.wp))
            .flat_map(|row| &row[..rows.w])
            .copied()
            .collect();
        (
            rows.rows_to_pixel_major(&self.qx, j),
            rows.rows_to_pixel_major(&self.qy, j),
            padded.collect(),
            active,
        )
    }

    /// ᾱ = 2α⁺ − x of the last step (x the relaxed point), pixel-major.
    pub fn extrapolated(&self) -> Vec<f32> {
        self.rows.rows_to_pixel_major(&self.bar, self.j)
    }

    /// x = 2α − ᾱ: the point the last prox step started from (the primal part of the
    /// Chambolle–Pock state z = (x, q, r)).
    fn start_point(&self) -> Vec<f32> {
        self.alpha
            .iter()
            .zip(&self.bar)
            .map(|(a, b)| 2.0 * a - b)
            .collect()
    }
}

/// The decay per iteration of the flush threshold of r (`JointConfig::dual_flush`): a
/// geometric series, so the values flushed over a run have a finite sum (an inexact
/// Krasnosel'skii–Mann iteration with summable errors converges as the exact one; Combettes
/// 2004), and slower than the (1 − γ)ⁿ decay of an idle band's dual at γ = 1.8, so those reach it.
const FLUSH_DECAY: f32 = 0.98;

/// Largest J the per-pixel kernels handle on the stack.
pub const MAX_J: usize = crate::unmix::MAX_BASIS;
/// Largest number of bands (padded).
const MAX_BANDS: usize = crate::unmix::MAX_BANDS;

/// A J × J matrix (row r, column c), zero-padded to `MAX_J`.
type Mat = [[f32; MAX_J]; MAX_J];

/// `$body` with the constant `$J` equal to the basis length `$j` (1..=MAX_J, checked by
/// [`Joint::new`]): the per-pixel kernels are compiled once per J.
macro_rules! with_basis_len {
    ($j:expr, $J:ident => $body:expr) => {
        match $j {
            1 => {
                const $J: usize = 1;
                $body
            }
            2 => {
                const $J: usize = 2;
                $body
            }
            3 => {
                const $J: usize = 3;
                $body
            }
            4 => {
                const $J: usize = 4;
                $body
            }
            5 => {
                const $J: usize = 5;
                $body
            }
            6 => {
                const $J: usize = 6;
                $body
            }
            7 => {
                const $J: usize = 7;
                $body
            }
            _ => {
                const $J: usize = MAX_J;
                $body
            }
        }
    };
}
use with_basis_len;

/// One row's dual variables: q (both directions, J per pixel), r (banded) and the flags of
/// pixels whose r is non-zero; the TV weights.
struct DualRow<'a> {
    qx: &'a mut [f32],
    qy: &'a mut [f32],
    r: &'a mut [f32],
    active: &'a mut [u8],
    weight: &'a [f32],
}

/// What one constraint update ([`Joint::constraint_dual`]) of `L::WIDTH` pixels reads besides
/// ᾱ and r: the idle pixels' bits, σ, γ − 1 and the flush threshold.
struct ConstraintStep<L: Lanes> {
    idle: u32,
    sigma: L::V,
    over: L::V,
    flush: f32,
}

/// What one row's dual update reads besides its duals: ∇ᾱ there, σ, λ and the flush
/// threshold of r.
#[derive(Clone, Copy)]
struct DualStep<'a> {
    gx: &'a [f32],
    gy: &'a [f32],
    sigma: f32,
    lambda: f32,
    flush: f32,
}

/// One row's data for its share of the objective: α, a, y, ω and the row's ∇α.
struct CostRow<'a> {
    alpha: &'a [f32],
    a: &'a [f32],
    y: &'a [f32],
    om: &'a [f32],
    cap: &'a [f32],
    tvw: &'a [f32],
    gx: &'a [f32],
    gy: &'a [f32],
}

/// The data term's per-pixel frame, weights and saturation caps, read together, and the
/// TV weights.
struct DataTerm<'a> {
    y: &'a [f32],
    om: &'a [f32],
    cap: &'a [f32],
    tvw: &'a [f32],
}

/// y − fit, or 0 where the pixel is saturated (cap = y) and the fit reaches its reading: the
/// one-sided residual of a censored observation.
#[inline]
fn data_residual(y: f32, fit: f64, cap: f32) -> f64 {
    match fit >= cap as f64 {
        true => 0.0,
        false => y as f64 - fit,
    }
}

/// One row's dual update ([`Joint::dual_row`]) as a kernel over lanes, for `lane::dispatch`.
struct DualKernel<'a, const J: usize> {
    joint: &'a Joint,
    row: DualRow<'a>,
    bar: &'a [f32],
    step: DualStep<'a>,
}

impl<const J: usize> LaneKernel for DualKernel<'_, J> {
    #[inline(always)]
    fn run<L: Lanes>(self) {
        self.joint.dual_row::<J, L>(self.row, self.bar, self.step)
    }
}

/// One row's primal update ([`Joint::primal_row`]) as a kernel over lanes.
struct PrimalKernel<'a, const J: usize> {
    joint: &'a Joint,
    row: PrimalRow<'a>,
    mat: &'a Mat,
    tau: f32,
}

impl<const J: usize> LaneKernel for PrimalKernel<'_, J> {
    #[inline(always)]
    fn run<L: Lanes>(self) {
        self.joint.primal_row::<J, L>(self.row, self.mat, self.tau)
    }
}

/// One row of the primal update: α and ᾱ (written), div q, and the row's share of the dual
/// flags, r and the proximal tables.
struct PrimalRow<'a> {
    alpha: &'a mut [f32],
    bar: &'a mut [f32],
    div: &'a [f32],
    active: &'a [u8],
    r: &'a [f32],
    m: &'a [f32],
    /// (t, c, k, cap) of the proximal step, 4 values a pixel.
    tck: &'a [f32],
}

/// Rows per strip of [`Joint::sweep`]: a strip's rows of q and r (about 100 kB a row at 768
/// pixels) are still in cache when the row's primal update reads them.
const STRIP_ROWS: usize = 16;

/// The read-only tables of one [`Joint::sweep`]: the data term, the proximal tables, the
/// steps σ and τ, λ and the flush threshold of r.
struct SweepTables<'a> {
    data: DataTerm<'a>,
    mat: &'a Mat,
    m: &'a [f32],
    tck: &'a [f32],
    sigma: f32,
    lambda: f32,
    flush: f32,
    tau: f32,
}

/// What a row's primal update reads of the duals: qx, qy, the flags and r, each from the
/// row's start on, and qy of the row above (`None` for the first row).
struct RowDuals<'a> {
    qx: &'a [f32],
    qy: &'a [f32],
    up: Option<&'a [f32]>,
    active: &'a [u8],
    r: &'a [f32],
}

/// One strip of rows of the iterate and the duals (`f`), starting at row `y0`, with the first
/// rows of ᾱ and α below it (as they were before the sweep; `None` for the last strip).
struct Strip<'a> {
    y0: usize,
    f: StripFields<'a>,
    next_bar: Option<&'a [f32]>,
    next_alpha: Option<&'a [f32]>,
}

/// The state's fields a sweep cuts into strips (the whole state, or one strip of it).
struct StripFields<'a> {
    alpha: &'a mut [f32],
    bar: &'a mut [f32],
    qx: &'a mut [f32],
    qy: &'a mut [f32],
    r: &'a mut [f32],
    active: &'a mut [u8],
    sums: &'a mut [f64],
}

impl<'a> Strip<'a> {
    /// The strips of `rows` rows of a `w`-pixel-wide state, J and `nb` values a pixel; `halo` holds the first rows of ᾱ and α of each
    /// strip (α's empty when the sweep needs no cost).
    fn split(
        f: StripFields<'a>,
        (w, j, nb): (usize, usize, usize),
        rows: usize,
        halo: &'a (Vec<f32>, Vec<f32>),
    ) -> Vec<Strip<'a>> {
        let wj = w * j;
        let next = |v: &'a [f32], s: usize| v.get((s + 1) * wj..(s + 2) * wj);
        let cut = |v: &'a mut [f32], per: usize| v.chunks_mut(rows * per);
        cut(f.alpha, wj)
            .zip(cut(f.bar, wj))
            .zip(cut(f.qx, wj).zip(cut(f.qy, wj)))
            .zip(cut(f.r, w * nb).zip(f.active.chunks_mut(rows * w)))
            .zip(f.sums.chunks_mut(rows))
            .enumerate()
            .map(
                |(s, ((((alpha, bar), (qx, qy)), (r, active)), sums))| Strip {
                    y0: s * rows,
                    f: StripFields {
                        alpha,
                        bar,
                        qx,
                        qy,
                        r,
                        active,
                        sums,
                    },
                    next_bar: next(&halo.0, s),
                    next_alpha: next(&halo.1, s),
                },
            )
            .collect()
    }
}

/// The first row of each strip of `rows` rows of a pixel-major field, `wj` values a row.
fn first_rows(u: &[f32], wj: usize, rows: usize) -> Vec<f32> {
    u.chunks(rows * wj)
        .flat_map(|s| &s[..wj])
        .copied()
        .collect()
}

/// The factor that brings a vector of squared norm `n2` into the ball of radius `r`: 1 inside
/// it, r/√n2 outside (0 for r = 0). The TV dual's projection, in the step and the reweighting.
#[inline(always)]
fn ball_factor<L: Lanes>(n2: L::V, r: L::V) -> L::V {
    let zero = L::splat(0.0);
    let outside = L::select_gt(r, zero, L::div(r, L::sqrt(n2)), zero);
    L::select_gt(n2, L::mul(r, r), outside, L::splat(1.0))
}

/// The relaxed dual t + (γ − 1)(t − q) of the step's result t, from the old q (exactly t at
/// γ = 1).
#[inline(always)]
fn relaxed<L: Lanes>(q: L::V, t: L::V, over: L::V) -> L::V {
    L::add_scaled(t, over, L::sub(t, q))
}

/// M v for a J × J matrix M, each row's products summed in column order.
#[inline(always)]
fn mat_vec<const J: usize, L: Lanes>(mat: &Mat, v: [L::V; J]) -> [L::V; J] {
    let mut out = [L::splat(0.0); J];
    for (o, row) in out.iter_mut().zip(mat) {
        for (&m, &vc) in row[..J].iter().zip(&v) {
            *o = L::add(*o, L::mul(L::splat(m), vc));
        }
    }
    out
}

/// prox_{τf}(v) per pixel, f = ½ω(y − aᵀα)² + ½αᵀη'Qα: (I + τH)⁻¹(v + τωya) by
/// Sherman–Morrison on M = (I + τη'Q)⁻¹ with its tables m = Ma and (t, c, k, cap)
/// (`prox_tables`); for a saturated pixel (cap = y) the data term is ½ω·max(0, y − aᵀα)².
/// J fixed per compiled copy.
#[inline(always)]
fn prox<const J: usize, L: Lanes>(
    mat: &Mat,
    mp: [L::V; J],
    [t, c, k, cap]: [L::V; 4],
    v: [L::V; J],
) -> [L::V; J] {
    let out = mat_vec::<J, L>(mat, v);
    // aᵀMv = m_pᵀv: the fit without the data term. A saturated pixel whose fit reaches its
    // reading keeps it (its one-sided term is zero there); else the full quadratic's step.
    let mtv = L::tree_sum::<J>(fields!(L, J, |i| L::mul(mp[i], v[i])));
    let step = L::sub(t, L::mul(c, L::add(mtv, L::mul(t, k))));
    let coef = L::select_ge(mtv, cap, L::splat(0.0), step);
    fields!(L, J, |i| L::add_scaled(out[i], coef, mp[i]))
}

/// What happens between the iterations of a run (`Joint::iterate`); the default: nothing.
#[derive(Clone, Copy, Debug, Default)]
struct Stages {
    /// TV reweightings, splitting the run into `reweights` + 1 equal stages.
    reweights: usize,
    /// Rebalance the steps halfway ([`rebalances_before`]).
    rebalance: bool,
}

/// Whether the steps are rebalanced before iteration `it` of `iterations` (halfway; the
/// CPU's and the GPU's alike).
pub fn rebalances_before(it: usize, iterations: usize) -> bool {
    it > 0 && it == iterations / 2
}

/// Whether the TV weights are refreshed before iteration `it` of `iterations` split into
/// `reweights` + 1 equal stages (the CPU's and the GPU's stage boundaries alike).
pub fn reweights_before(it: usize, iterations: usize, reweights: usize) -> bool {
    let stage = |i: usize| i * (reweights + 1) / iterations;
    it > 0 && stage(it) > stage(it - 1)
}

/// max(g_p − mean of g over the 3 × 3 neighbourhood of p, 0) for a w × h image g (the
/// neighbourhood clipped at the borders): what stands out of its surroundings.
fn ridge_excess(g: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(yy, row)| {
        let rows = yy.saturating_sub(1)..(yy + 2).min(h);
        for (xx, e) in row.iter_mut().enumerate() {
            let cols = xx.saturating_sub(1)..(xx + 2).min(w);
            let sum: f32 = (rows.clone())
                .map(|y| g[y * w + cols.start..y * w + cols.end].iter().sum::<f32>())
                .sum();
            let mean = sum / (rows.len() * cols.len()) as f32;
            *e = (g[yy * w + xx] - mean).max(0.0);
        }
    });
    out
}

/// The values of pixel x in a row's k fields (`rows.rs`), in field order.
fn pixel_values(v: &[f32], wp: usize, k: usize, x: usize) -> impl Iterator<Item = f32> + '_ {
    (0..k).map(move |c| v[c * wp + x])
}

/// A row of a field (`wj` values a row) and the row below it, if there is one.
fn row_pair(u: &[f32], wj: usize, yy: usize) -> (&[f32], Option<&[f32]>) {
    (
        &u[yy * wj..(yy + 1) * wj],
        u.get((yy + 1) * wj..(yy + 2) * wj),
    )
}

/// The row above row `yy` of a pixel-major field, if there is one.
fn row_above(u: &[f32], wj: usize, yy: usize) -> Option<&[f32]> {
    (yy > 0).then(|| &u[(yy - 1) * wj..yy * wj])
}

/// Forward differences of a row of a field in rows (`rows.rs`) given the row below (`None`
/// for the last row), zero across the last column and row (Neumann boundaries, as in `tv.rs`)
/// and in the padding.
fn row_gradients(
    (row, next): (&[f32], Option<&[f32]>),
    rows: Rows,
    gx: &mut [f32],
    gy: &mut [f32],
) {
    let inner = rows.w.saturating_sub(1);
    for (g, run) in gx.chunks_exact_mut(rows.wp).zip(row.chunks_exact(rows.wp)) {
        for ((g, b), a) in g.iter_mut().zip(&run[1..rows.w]).zip(run) {
            *g = b - a;
        }
        g[inner..].fill(0.0);
    }
    match next {
        Some(next) => {
            for ((g, a), b) in gy.iter_mut().zip(row).zip(next) {
                *g = b - a;
            }
        }
        None => gy.fill(0.0),
    }
}

/// div q = −∇ᵀq on a row for `row_gradients`' differences, from the row's qx and qy (the first
/// `div.len()` values of each) and qy of the row above (`None` for the first row); qx must be
/// zero in the last column and qy in the last row (as every gradient there is), and both in
/// the padding, where div q is 0.
fn row_divergence(qx: &[f32], qy: &[f32], up: Option<&[f32]>, rows: Rows, div: &mut [f32]) {
    let (rl, w) = (div.len(), rows.w);
    let (qxr, qyr) = (&qx[..rl], &qy[..rl]);
    for (d, q) in div.chunks_exact_mut(rows.wp).zip(qxr.chunks_exact(rows.wp)) {
        // The first pixel has no left neighbour and the first row none above: 0 there.
        d[0] = q[0];
        for ((d, q), left) in d[1..w].iter_mut().zip(&q[1..w]).zip(q) {
            *d = q - left;
        }
        d[w..].fill(0.0);
    }
    match up {
        None => div.iter_mut().zip(qyr).for_each(|(d, q)| *d += q),
        Some(up) => {
            for ((d, q), u) in div.iter_mut().zip(qyr).zip(up) {
                *d = *d + q - u;
            }
        }
    }
}

/// A matrix as rows of f64 (the mixing matrices of `Cube::mix`).
fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// Planes → pixel-major (the planes of one pixel contiguous).
fn to_pixel_major(c: &Cube) -> Vec<f32> {
    let (n, j) = (c.pixels(), c.planes);
    let mut out = vec![0.0f32; n * j];
    out.par_chunks_mut(j).enumerate().for_each(|(p, o)| {
        for (k, v) in o.iter_mut().enumerate() {
            *v = c.data[k * n + p];
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::carriers::default_layout;
    use crate::unmix::curvature;

    const BANDS: usize = 16;

    /// Six sinusoidal patterns of the default layout on a w × h frame.
    fn patterns(w: usize, h: usize) -> Cube {
        let carriers = default_layout();
        let mut c = Cube::zeros(w, h, carriers.len());
        for (k, cr) in carriers.iter().enumerate() {
            let plane = c.plane_mut(k);
            for y in 0..h {
                for x in 0..w {
                    let ph = 2.0 * std::f64::consts::PI * (cr.fx * x as f64 + cr.fy * y as f64);
                    plane[y * w + x] = (0.5 * (1.0 + ph.cos())) as f32;
                }
            }
        }
        c
    }

    /// A smooth basis (bands × 4): constant, and three cosines across the bands.
    fn basis() -> DMatrix<f64> {
        DMatrix::from_fn(BANDS, 4, |k, j| {
            let t = k as f64 / (BANDS - 1) as f64;
            (std::f64::consts::PI * j as f64 * t).cos() / (BANDS as f64).sqrt()
        })
    }

    /// Six Gaussian filters across the bands seen through the basis: F = T B.
    fn system(b: &DMatrix<f64>) -> DMatrix<f64> {
        let t = DMatrix::from_fn(6, BANDS, |i, k| {
            let c = 1.0 + i as f64 * 2.6;
            (-((k as f64 - c) / 2.5).powi(2)).exp()
        });
        t * b
    }

    /// α: the first coefficient 1 (or 2 in the right half), the others a small pattern of
    /// three rectangles, so Bα > 0 everywhere.
    fn truth(w: usize, h: usize) -> Cube {
        let mut a = Cube::zeros(w, h, 4);
        for y in 0..h {
            for x in 0..w {
                let p = y * w + x;
                let right = x >= w / 2;
                let block = (w / 4..w / 2).contains(&y);
                a.data[p] = if right { 2.0 } else { 1.0 };
                a.data[w * h + p] = if block { 0.3 } else { -0.1 };
                a.data[2 * w * h + p] = if right && block { 0.2 } else { 0.0 };
                a.data[3 * w * h + p] = 0.05;
            }
        }
        a
    }

    /// [`truth`] at w² with a strong second coefficient in its block rows, so that Bα < 0 at
    /// the red end there and the constraint's dual is live.
    fn truth_with_live_constraint(w: usize) -> Cube {
        let mut t = truth(w, w);
        t.plane_mut(1)[w / 4 * w..w / 2 * w].fill(1.6);
        t
    }

    /// y = Σ_j a_j ⊙ α_j with a = Fᵀ s.
    fn frame_of(j: &Joint, alpha: &Cube) -> Cube {
        let (w, h) = (alpha.width, alpha.height);
        let am = to_pixel_major(alpha);
        let y = (0..w * h)
            .map(|p| (0..j.j).map(|k| j.a[p * j.j + k] * am[p * j.j + k]).sum())
            .collect();
        Cube::from_vec(w, h, 1, y).unwrap()
    }

    fn solver(w: usize, eta: f64, cfg: JointConfig) -> Joint {
        let b = basis();
        Joint::new(
            &patterns(w, w),
            &system(&b),
            &b,
            &curvature(&b, eta),
            &cfg,
            "t.toml",
        )
        .unwrap()
    }

    /// The spectral prior enters scaled by mean‖a‖²/‖F‖²_F (the unmixer's balance of data and
    /// prior, per unit of data); a prior of the wrong size or with a NaN is refused.
    #[test]
    fn the_spectral_prior_enters_at_the_unmixers_balance() {
        let (b, cfg) = (basis(), JointConfig::default());
        let f = system(&b);
        let p = DMatrix::from_fn(4, 4, |r, c| if r == c { 1.0 + r as f64 } else { 0.1 });
        let j = Joint::new(&patterns(16, 16), &f, &b, &p, &cfg, "t.toml").unwrap();
        let mean_a2 = j.a.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / 256.0;
        let want = &p * (mean_a2 / f.norm_squared());
        assert!((j.tables().spectral_prior - &want).amax() < 1e-12 * want.amax());
        for bad in [
            DMatrix::identity(3, 3),
            DMatrix::from_element(4, 4, f64::NAN),
        ] {
            let e = Joint::new(&patterns(16, 16), &f, &b, &bad, &cfg, "t.toml");
            assert!(matches!(e, Err(Error::Numerical(m)) if m.contains("spectral prior")));
        }
    }

    /// The seed: every pixel the image-wide mean of the truth (what a blurry estimate gives).
    fn flat_seed(t: &Cube) -> Cube {
        let n = t.pixels();
        let mut s = t.clone();
        for plane in s.planes_mut() {
            let m = plane.iter().sum::<f32>() / n as f32;
            plane.iter_mut().for_each(|v| *v = m);
        }
        s
    }

    #[test]
    fn an_untraced_run_keeps_the_traced_iterate_and_its_ends() {
        let t = truth(24, 24);
        let run = |trace_objective| {
            let j = solver(
                24,
                30.0,
                JointConfig {
                    iterations: 15,
                    trace_objective,
                    ..JointConfig::default()
                },
            );
            j.run(&frame_of(&j, &t), &flat_seed(&t), None).unwrap()
        };
        let ((traced, ts), (untraced, us)) = (run(true), run(false));
        assert_eq!(
            traced.data, untraced.data,
            "the iterate does not depend on the trace"
        );
        assert_eq!(ts.objective.len(), 16);
        assert_eq!(us.objective, [ts.objective[0], ts.objective[15]]);
        assert_eq!((ts.iterations, us.iterations), (15, 15));
    }

    #[test]
    fn the_step_bound_holds_against_power_iteration() {
        let j = solver(16, 1.0, JointConfig::default());
        let est = j.power_iteration(200);
        assert!(est <= j.operator_norm().powi(2) * (1.0 + 1e-5), "{est}");
        // The bound is not loose by more than the gradient's boundary effect.
        assert!(est > 0.8 * j.operator_norm().powi(2), "{est}");
    }

    /// Six traced sweeps of `rows`-row strips on a 37 × 37 frame (37 pixels padded to 40)
    /// with the constraint's dual live and flushed: the objectives, every field's bits and the
    /// flags.
    fn six_sweeps(rows: usize) -> (Vec<f64>, Vec<u32>, Vec<u8>) {
        let j = solver(37, 1.0, JointConfig::default());
        let t = truth_with_live_constraint(37);
        let mut st = j.start(&frame_of(&j, &t), &flat_seed(&t), None).unwrap();
        st.flush = 0.01 * st.lambda;
        let costs: Vec<f64> = (0..6).map(|_| j.sweep(&mut st, true, rows)).collect();
        let fields = [&st.alpha, &st.bar, &st.qx, &st.qy, &st.r];
        let bits: Vec<u32> = fields
            .iter()
            .flat_map(|v| v.iter().map(|x| x.to_bits()))
            .collect();
        (costs, bits, st.active.clone())
    }

    /// The fused sweep gives the same bits for strips of 1 row (every dual update, then every
    /// primal one: the two passes), 3 and 16 rows, one strip and more rows than the frame has.
    #[test]
    fn the_sweep_gives_the_same_bits_for_any_strip_height() {
        let two_passes = six_sweeps(1);
        assert!(
            two_passes.2.contains(&1),
            "the constraint's dual never became live"
        );
        for rows in [3, 16, 37, 64] {
            assert!(six_sweeps(rows) == two_passes, "strips of {rows} rows");
        }
    }

    /// The kernels on eight pixels a register (AVX2, where the CPU has it) give the bits of the
    /// one-pixel scalar kernels, the padding and the row ends included.
    #[test]
    fn the_lanes_give_the_scalar_kernels_bits() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let scalar = pool.install(|| lane::tests::on_scalar_lanes(|| six_sweeps(16)));
        assert!(
            scalar.2.contains(&1),
            "the constraint's dual never became live"
        );
        assert!(six_sweeps(16) == scalar);
    }

    #[test]
    fn the_fixed_point_residual_never_increases_over_500_iterations() {
        for (relaxation, reweighted) in [(1.0, false), (1.8, false), (1.8, true)] {
            fixed_point_residual_never_increases(relaxation, reweighted);
        }
    }

    /// 500 steps at over-relaxation γ: ‖Δz‖²_M non-increasing at every step, and down by 10³.
    /// `reweighted`: the TV weights are first refreshed from the iterate after 100 steps; with
    /// them fixed the problem is again convex and the same bound holds.
    fn fixed_point_residual_never_increases(relaxation: f64, reweighted: bool) {
        let cfg = JointConfig {
            iterations: 500,
            tv_weight: 0.01,
            relaxation,
            ..Default::default()
        };
        let j = solver(32, 1.0, cfg);
        let t = truth(32, 32);
        let y = frame_of(&j, &t);
        let mut st = j.start(&y, &flat_seed(&t), None).unwrap();
        if reweighted {
            (0..100).for_each(|_| j.step_untraced(&mut st));
            j.reweight(&mut st);
            assert!(st.tvw.iter().any(|&w| w < 0.5), "no edge was reweighted");
        }
        // The start (ᾱ = α, q = 0) is no Chambolle–Pock state: the first step's dual half
        // completes it, and the steps from there on map z = (2α − ᾱ, q, r) as the theory says.
        j.step(&mut st);
        let mut last = f64::INFINITY;
        let mut first = 0.0;
        for it in 0..500 {
            let before = st.clone();
            j.step(&mut st);
            let r = j.step_residual(&before, &st);
            if it == 0 {
                first = r;
            }
            // f32 iterates: allow rounding at 1e-4 of the first step's residual.
            assert!(
                r <= last + 1e-4 * first,
                "γ {relaxation}, iteration {it}: {r} after {last}"
            );
            last = r;
        }
        assert!(last < 1e-3 * first, "γ {relaxation}: {last} vs {first}");
        let obj = j.objective(&mut st);
        assert!(obj.is_finite() && obj > 0.0);
    }

    /// The rebalance before the second of two iterations takes τ and σ from that iterate's
    /// mean |α| (τ = ratio·s·√(τσ‖K‖²)/‖K‖, s = mean|α|/λ) and keeps ᾱ and the duals; without
    /// it the run keeps the seed's steps.
    #[test]
    fn the_rebalance_takes_the_steps_from_the_iterate_halfway() {
        let j = solver(32, 1.0, JointConfig::default());
        let t = truth(32, 32);
        let y = frame_of(&j, &t);
        let seed = flat_seed(&t);
        let mut st = j.start(&y, &seed, None).unwrap();
        let start_tau = st.tau;
        j.step_untraced(&mut st);
        let mean = st.alpha.iter().map(|v| v.abs() as f64).sum::<f64>() / st.alpha.len() as f64;
        let scale = mean / st.lambda as f64;
        let (tau, sigma) = (
            scale * STEP_PRODUCT.sqrt() / j.norm_k,
            STEP_PRODUCT.sqrt() / (scale * j.norm_k),
        );
        let (bar, qx) = (st.bar.clone(), st.qx.clone());
        let lambda = st.lambda as f64;
        j.balance_steps(&mut st, lambda).unwrap();
        assert!(
            (st.tau as f64 / tau - 1.0).abs() < 1e-6,
            "τ {} against {tau}",
            st.tau
        );
        assert!((st.sigma as f64 / sigma - 1.0).abs() < 1e-6);
        assert!(
            (st.tau / start_tau - 1.0).abs() > 1e-2,
            "one step must move mean|α|"
        );
        assert_eq!((st.bar.clone(), st.qx.clone()), (bar, qx));
        let mut run = j.start(&y, &seed, None).unwrap();
        let rebalanced = Stages {
            rebalance: true,
            ..Stages::default()
        };
        j.iterate(&mut run, 2, rebalanced).unwrap();
        assert_eq!(run.tau, st.tau);
        let mut fixed = j.start(&y, &seed, None).unwrap();
        j.iterate(&mut fixed, 2, Stages::default()).unwrap();
        assert_eq!(fixed.tau, start_tau);
    }

    /// Reweighting by hand: on 8 × 8, α₀ = 1 left of x = 4 and 3 from there (other coefficients
    /// 0): ‖∇α‖ is 2 at x = 3 and 0 elsewhere, mean 2·8/64 = 0.25 = ε (`reweight_eps` 1); the
    /// 3 × 3 mean on that column is 2/3 (borders too), so the excess is 4/3 and
    /// w = 0.25/(4/3 + 0.25) = 3/19 at x = 3, 1 elsewhere (no excess beside the ridge); a large
    /// dual is projected into the new balls λw_p and the extrapolation restarts (ᾱ = α).
    #[test]
    fn reweighting_follows_the_gradient_by_hand() {
        let cfg = JointConfig {
            reweight_eps: 1.0,
            ..Default::default()
        };
        let j = solver(8, 0.0, cfg);
        let mut seed = Cube::zeros(8, 8, 4);
        for (p, v) in seed.plane_mut(0).iter_mut().enumerate() {
            *v = if p % 8 < 4 { 1.0 } else { 3.0 };
        }
        let mut st = j.start(&frame_of(&j, &seed), &seed, None).unwrap();
        st.qx.fill(1e3);
        st.qy.fill(-1e3);
        st.bar.fill(7.0);
        j.reweight(&mut st);
        // 8 pixels a row: the rows' TV weights have no padding.
        let (qx, qy, _, _) = st.duals();
        for (p, &w) in st.tvw.iter().enumerate() {
            let expected = if p % 8 == 3 { 3.0 / 19.0 } else { 1.0 };
            assert!((w - expected).abs() < 1e-6, "pixel {p}: {w}");
            let q2: f32 = (qx[p * 4..p * 4 + 4].iter())
                .chain(&qy[p * 4..p * 4 + 4])
                .map(|v| v * v)
                .sum();
            assert!(q2.sqrt() <= st.lambda * w * (1.0 + 1e-5), "pixel {p}");
        }
        assert_eq!(st.bar, st.alpha);
    }

    /// A plateau of the gradient (shading) stands out nowhere; a one-pixel ridge by 2/3 of its
    /// height (the 3 × 3 mean holds three of its nine values), at the borders too.
    #[test]
    fn only_ridges_of_the_gradient_stand_out() {
        assert!(ridge_excess(&[0.1; 25], 5, 5)
            .iter()
            .all(|&e| e.abs() < 1e-7));
        let line: Vec<f32> = (0..25)
            .map(|p| if p / 5 == 2 { 3.0 } else { 0.0 })
            .collect();
        for (p, e) in ridge_excess(&line, 5, 5).into_iter().enumerate() {
            let expected = if p / 5 == 2 { 2.0 } else { 0.0 };
            assert!((e - expected).abs() < 1e-6, "pixel {p}: {e}");
        }
    }

    /// Plain TV shrinks the jumps of a piecewise-constant field, which one measurement per
    /// pixel cannot fully restore; reweighted TV penalises the found edges less and comes
    /// closer (η = 0, 32², 1200 iterations from the flat seed).
    #[test]
    fn reweighting_recovers_a_piecewise_constant_field_closer() {
        let t = truth(32, 32);
        let error = |rounds: usize| {
            let cfg = JointConfig {
                iterations: 1200,
                tv_weight: 1e-2,
                reweight_rounds: Some(rounds),
                ..Default::default()
            };
            let j = solver(32, 0.0, cfg);
            let (est, _) = j.run(&frame_of(&j, &t), &flat_seed(&t), None).unwrap();
            relative_error(&est, &t)
        };
        let (plain, reweighted) = (error(0), error(3));
        eprintln!("relative error: plain TV {plain:.3e}, reweighted {reweighted:.3e}");
        assert!(reweighted < 0.2 * plain, "{reweighted:.3e} vs {plain:.3e}");
    }

    /// The relaxed step is z + γ(Tz − z) with T the plain step, in the state z = (2α − ᾱ, q, r).
    #[test]
    fn a_relaxed_step_is_the_plain_step_extended_by_gamma() {
        let cfg = |relaxation| JointConfig {
            tv_weight: 0.01,
            relaxation,
            ..Default::default()
        };
        let (plain, relaxed) = (solver(32, 1.0, cfg(1.0)), solver(32, 1.0, cfg(1.8)));
        let t = truth(32, 32);
        let mut st = plain
            .start(&frame_of(&plain, &t), &flat_seed(&t), None)
            .unwrap();
        for _ in 0..5 {
            plain.step(&mut st);
        }
        let (mut to_t, mut to_r) = (st.clone(), st.clone());
        plain.step(&mut to_t);
        relaxed.step(&mut to_r);
        let state = |s: &JointState| -> Vec<f64> {
            let duals = s.qx.iter().chain(&s.qy).chain(&s.r);
            s.start_point()
                .iter()
                .chain(duals)
                .map(|&v| f64::from(v))
                .collect()
        };
        let (z, zt, zr) = (state(&st), state(&to_t), state(&to_r));
        let scale = zt
            .iter()
            .zip(&z)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(scale > 0.0);
        for (k, ((a, b), c)) in z.iter().zip(&zt).zip(&zr).enumerate() {
            let want = a + 1.8 * (b - a);
            assert!(
                (c - want).abs() <= 1e-4 * scale,
                "entry {k}: {c} against {want}"
            );
        }
    }

    #[test]
    fn flushing_the_dual_keeps_the_iterate_and_idles_the_constraint() {
        // The constraint holds at the minimiser of this scene; γ = 1.8, 300 iterations, exact
        // and flushed (the default).
        let t = truth_with_live_constraint(32);
        let run = |dual_flush: f64| {
            let cfg = JointConfig {
                iterations: 300,
                tv_weight: 0.01,
                dual_flush,
                ..Default::default()
            };
            let j = solver(32, 1.0, cfg);
            let mut st = j.start(&frame_of(&j, &t), &flat_seed(&t), None).unwrap();
            j.iterate(&mut st, 300, Stages::default()).unwrap();
            let live = st.active.iter().filter(|&&a| a != 0).count();
            let tiny =
                st.r.iter()
                    .filter(|&&v| v != 0.0 && v.abs() < 1e-3 * st.lambda)
                    .count();
            (st.alpha, live, tiny)
        };
        let (exact, live_exact, tiny_exact) = run(0.0);
        let (flushed, live_flushed, tiny_flushed) = run(JointConfig::default().dual_flush);
        let norm = |v: &[f32]| v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
        let diff: Vec<f32> = exact.iter().zip(&flushed).map(|(a, b)| a - b).collect();
        let rel = norm(&diff) / norm(&exact);
        eprintln!(
            "α flushed vs exact {rel:.2e}; pixels with r ≠ 0: {live_exact} → {live_flushed}; \
             values 0 < |r| < 1e-3 λ: {tiny_exact} → {tiny_flushed}"
        );
        // Exact, an idle band's r only decays (0.8ⁿ at γ = 1.8) and is never zero: the
        // flushed run has none of those left, fewer live pixels and the same iterate.
        assert!(tiny_exact > 0 && tiny_flushed == 0);
        assert!(live_flushed < live_exact);
        assert!(rel < 1e-4, "α moved by {rel:.2e}");
    }

    /// With η = 0 a constant α field fitting y = Aα exactly has objective 0, the least any
    /// field can have, and no other field reaches it (zero TV means constant, and the patterns
    /// vary enough across the frame that one constant fits): the exact minimiser.
    #[test]
    fn a_cube_in_the_range_is_recovered() {
        // The relaxed iteration is slower in this test's tail (1.8e-4 after 2000 iterations,
        // 1.6e-5 after 4000; docs/joint.md), so it runs longer.
        for (relaxation, iterations) in [(1.0, 2000), (1.8, 4000)] {
            range_recovery(relaxation, iterations);
        }
    }

    /// The constant α field (0.9, 0.2, −0.1, 0.05) the range tests recover.
    fn range_cube() -> Cube {
        let mut t = Cube::zeros(32, 32, 4);
        for (plane, v) in t.planes_mut().zip([0.9f32, 0.2, -0.1, 0.05]) {
            plane.fill(v);
        }
        t
    }

    /// ‖est − t‖ / ‖t‖ in f64.
    fn relative_error(est: &Cube, t: &Cube) -> f64 {
        let d: f64 = est
            .data
            .iter()
            .zip(&t.data)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum();
        let n: f64 = t.data.iter().map(|&v| (v as f64).powi(2)).sum();
        (d / n).sqrt()
    }

    /// The range cube's frame clipped at 0.8 of its peak, as a camera saturates: flagged as
    /// saturated, the clipped pixels only bound the fit from below, the cube still has
    /// objective 0 and is recovered to 1e-4 (4000 iterations: with fewer pixels fitted exactly
    /// the tail is slower, 1.5e-4 after 2000); taken as readings, it is not (error > 1 %).
    #[test]
    fn a_clipped_frame_flagged_as_saturated_still_recovers_the_range_cube() {
        let cfg = JointConfig {
            iterations: 4000,
            tv_weight: 1e-3,
            relaxation: 1.0,
            ..Default::default()
        };
        let j = solver(32, 0.0, cfg);
        let t = range_cube();
        let mut y = frame_of(&j, &t);
        let top = 0.8 * y.max();
        let saturated: Vec<bool> = y.data.iter().map(|&v| v >= top).collect();
        let share = saturated.iter().filter(|&&s| s).count() as f64 / saturated.len() as f64;
        assert!(share > 0.05, "only {share:.3} of the pixels clipped");
        y.data.iter_mut().for_each(|v| *v = v.min(top));
        let seed = flat_seed(&truth(32, 32));
        let error = |est: &Cube| relative_error(est, &t);
        let omega = Cube::from_vec(32, 32, 1, vec![1.0; 32 * 32]).unwrap();
        let flagged = DataWeights {
            omega: omega.clone(),
            saturated,
        };
        let (est, stats) = j.run(&y, &seed, Some(&flagged)).unwrap();
        let (plain, _) = j.run(&y, &seed, Some(&DataWeights::new(omega))).unwrap();
        eprintln!(
            "{share:.3} clipped: error flagged {:.3e}, as readings {:.3e}",
            error(&est),
            error(&plain)
        );
        assert!(error(&est) < 1e-4, "flagged: {:.3e}", error(&est));
        assert!(error(&plain) > 1e-2, "as readings: {:.3e}", error(&plain));
        assert_eq!(stats.saturated_pixels, (share * 1024.0).round() as usize);
    }

    /// The weights' units do not matter: ω and 10⁻³·ω (a camera's 1/DN² against unit
    /// weights) give the same α and λ, and Σωr² scales with them. Before the weights
    /// were taken over their mean, λ followed mean ω but the spectral prior did not, so DN-unit
    /// noise weights smoothed the spectra 10³ times harder than unit ones.
    #[test]
    fn the_weights_scale_leaves_the_solution_unchanged() {
        let cfg = JointConfig {
            iterations: 60,
            ..Default::default()
        };
        let j = solver(32, 1.0, cfg);
        let t = truth(32, 32);
        let y = frame_of(&j, &t);
        let seed = flat_seed(&t);
        let field: Vec<f32> = (0..32 * 32).map(|p| 0.5 + (p % 7) as f32 / 6.0).collect();
        let weights = |c: f32| {
            let scaled = field.iter().map(|&v| c * v).collect();
            DataWeights::new(Cube::from_vec(32, 32, 1, scaled).unwrap())
        };
        let (a1, s1) = j.run(&y, &seed, Some(&weights(1.0))).unwrap();
        let (a2, s2) = j.run(&y, &seed, Some(&weights(1e-3))).unwrap();
        assert!(
            relative_error(&a2, &a1) < 1e-5,
            "{:e}",
            relative_error(&a2, &a1)
        );
        assert!(
            (s2.lambda / s1.lambda - 1.0).abs() < 1e-6,
            "{} {}",
            s1.lambda,
            s2.lambda
        );
        let ratio = s2.residual_ratio / s1.residual_ratio;
        assert!((ratio / 1e-3 - 1.0).abs() < 1e-3, "{ratio:e}");
    }

    /// The constant field of [`a_cube_in_the_range_is_recovered`] from a wrong seed, to 1e-4.
    fn range_recovery(relaxation: f64, iterations: usize) {
        let cfg = JointConfig {
            iterations,
            tv_weight: 1e-3,
            relaxation,
            ..Default::default()
        };
        let j = solver(32, 0.0, cfg);
        let t = range_cube();
        let y = frame_of(&j, &t);
        let seed = flat_seed(&truth(32, 32));
        let (est, stats) = j.run(&y, &seed, None).unwrap();
        let rel = relative_error(&est, &t);
        eprintln!(
            "γ {relaxation}: relative error {rel:.3e}, objective at the seed and the end {:?}",
            stats.objective
        );
        assert!(rel < 1e-4, "γ {relaxation}: relative error {rel:.3e}");
        assert!(stats.objective.iter().all(|v| v.is_finite()));
    }

    /// The frame of `t` with its first 22 of 32 rows (70 %) clipped to 0.6 of its peak.
    fn clipped_frame(j: &Joint, t: &Cube) -> Cube {
        let mut y = frame_of(j, t);
        let top = y.max() * 0.6;
        y.data.iter_mut().take(32 * 22).for_each(|v| *v = top);
        y
    }

    /// F with its first two filters alike to 10⁻⁹.
    fn near_singular(b: &DMatrix<f64>) -> DMatrix<f64> {
        let mut f = system(b);
        let row = f.row(0).clone_owned();
        f.set_row(1, &(row * (1.0 + 1e-9)));
        f
    }

    /// The runs of [`stiff_cases_stay_finite_or_are_refused`] with `cfg`: zero frame → zero,
    /// clipped or flagged → finite, F near-singular → finite.
    fn stiff_runs_stay_finite(cfg: &JointConfig) {
        let j = solver(32, 1.0, cfg.clone());
        // Zero frame, zero seed: zero out, objective zero throughout.
        let zero = Cube::zeros(32, 32, 1);
        let (est, st) = j.run(&zero, &Cube::zeros(32, 32, 4), None).unwrap();
        assert!(est.data.iter().all(|&v| v == 0.0) && st.objective.iter().all(|&v| v == 0.0));
        // 70 % of the frame clipped to one value: finite, and the objective falls below the seed's.
        let t = truth(32, 32);
        let y = clipped_frame(&j, &t);
        let (est, st) = j.run(&y, &flat_seed(&t), None).unwrap();
        assert!(est.all_finite() && st.objective.iter().all(|v| v.is_finite()));
        assert!(
            st.objective.last().unwrap() < &st.objective[0],
            "{:?}",
            st.objective
        );
        // The same clipped rows flagged as saturated (one-sided data term): finite, counted.
        let flagged = DataWeights {
            omega: Cube::from_vec(32, 32, 1, vec![1.0; 32 * 32]).unwrap(),
            saturated: (0..32 * 32).map(|p| p < 32 * 22).collect(),
        };
        let (est, st) = j.run(&y, &flat_seed(&t), Some(&flagged)).unwrap();
        assert!(est.all_finite() && st.objective.iter().all(|v| v.is_finite()));
        assert_eq!(st.saturated_pixels, 32 * 22);
        // Two filters alike to 1e-9 (F near-singular): the prior keeps the problem posed.
        let b = basis();
        let f = near_singular(&b);
        let near = Joint::new(
            &patterns(32, 32),
            &f,
            &b,
            &curvature(&b, 1.0),
            cfg,
            "t.toml",
        )
        .unwrap();
        let (est, st) = near
            .run(&frame_of(&near, &t), &flat_seed(&t), None)
            .unwrap();
        assert!(est.all_finite() && st.objective.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn stiff_cases_stay_finite_or_are_refused() {
        for reweight_rounds in [0, 3] {
            stiff_runs_stay_finite(&JointConfig {
                iterations: 200,
                reweight_rounds: Some(reweight_rounds),
                ..Default::default()
            });
        }
        let cfg = JointConfig {
            iterations: 200,
            ..Default::default()
        };
        let b = basis();
        let f = near_singular(&b);
        // F = 0: the frame says nothing of α; refused with the reason.
        let e = Joint::new(
            &patterns(32, 32),
            &(f * 0.0),
            &b,
            &curvature(&b, 1.0),
            &cfg,
            "t.toml",
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("no energy"), "{e}");
        // Bad settings name their key.
        for (bad, key) in [
            (
                JointConfig {
                    tv_weight: -1.0,
                    ..cfg.clone()
                },
                "reconstruct.joint.tv_weight",
            ),
            (
                // No iteration would leave the start's unfitted coefficients.
                JointConfig {
                    iterations: 0,
                    ..cfg.clone()
                },
                "`reconstruct.joint.iterations` = 0: must be 1 to 100000 iterations",
            ),
            (
                JointConfig {
                    relaxation: 2.0,
                    ..cfg.clone()
                },
                "`reconstruct.joint.relaxation` = 2:",
            ),
            (
                JointConfig {
                    relaxation: f64::NAN,
                    ..cfg.clone()
                },
                "`reconstruct.joint.relaxation` = NaN:",
            ),
            (
                JointConfig {
                    reweight_eps: -1.0,
                    ..cfg.clone()
                },
                "`reconstruct.joint.reweight_eps` = -1:",
            ),
            (
                // 10 rounds in 5 iterations refreshed 4 times and reported 10.
                JointConfig {
                    reweight_rounds: Some(10),
                    iterations: 5,
                    ..cfg.clone()
                },
                "`reconstruct.joint.reweight_rounds` = 10: needs fewer rounds than iterations (5)",
            ),
            (
                JointConfig {
                    dual_flush: -1e-3,
                    ..cfg.clone()
                },
                "`reconstruct.joint.dual_flush` = -0.001: must be finite and ≥ 0",
            ),
            (
                JointConfig {
                    dual_flush: f64::INFINITY,
                    ..cfg.clone()
                },
                "`reconstruct.joint.dual_flush` = inf:",
            ),
            (
                JointConfig {
                    step_ratio: 1e-300,
                    ..cfg.clone()
                },
                "`reconstruct.joint.step_ratio` = 1e-300:",
            ),
            (
                JointConfig {
                    step_ratio: f64::NAN,
                    ..cfg.clone()
                },
                "`reconstruct.joint.step_ratio` = NaN:",
            ),
            (
                JointConfig {
                    prior: Prior::Pnp,
                    reweight_rounds: Some(2),
                    ..cfg.clone()
                },
                "`reconstruct.joint.reweight_rounds` = 2:",
            ),
            (
                JointConfig {
                    prior: Prior::Pnp,
                    rebalance: true,
                    ..cfg
                },
                "`reconstruct.joint.rebalance` = true:",
            ),
        ] {
            let e = refusal(&bad);
            assert!(e.contains(key), "{e}");
        }
    }

    /// Unset, the reweighting is one round exactly where a round can run and keeps its
    /// promise (TV, a fixed λ, two or more iterations); a value set is taken as it is, and those
    /// defaults are accepted where a set round is refused (plug-and-play, one iteration).
    #[test]
    fn the_default_reweighting_is_one_round_where_one_applies() {
        let at = |iterations, prior, weight_rule| JointConfig {
            iterations,
            prior,
            weight_rule,
            ..Default::default()
        };
        let (tv, pnp, fixed, disc) = (
            Prior::Tv,
            Prior::Pnp,
            WeightRule::Fixed,
            WeightRule::Discrepancy,
        );
        assert_eq!(at(56, tv, fixed).rounds(), DEFAULT_REWEIGHT_ROUNDS);
        assert_eq!(DEFAULT_REWEIGHT_ROUNDS, 1);
        for (cfg, why) in [
            (at(1, tv, fixed), "one iteration has nothing to split"),
            (at(56, pnp, fixed), "plug-and-play has no TV weights"),
            (
                at(56, tv, disc),
                "the discrepancy λ is searched without them",
            ),
        ] {
            assert_eq!(cfg.rounds(), 0, "{why}");
            cfg.validate("t.toml").unwrap();
        }
        let set = JointConfig {
            reweight_rounds: Some(3),
            ..at(56, tv, disc)
        };
        assert_eq!(set.rounds(), 3);
        let plain = JointConfig {
            reweight_rounds: Some(0),
            ..at(56, tv, fixed)
        };
        assert_eq!(plain.rounds(), 0);
    }

    /// A run that ends above its seed's objective is named, with the remedy of its prior; one
    /// that descends, or runs no iteration, is not.
    #[test]
    fn a_rising_objective_is_a_warning() {
        let stats = |prior: &str, objective: Vec<f64>| JointStats {
            iterations: 100,
            objective,
            prior: prior.into(),
            ..JointStats::default()
        };
        assert!(stats("tv", vec![2.0, 1.0]).warning().is_none());
        assert!(stats("tv", vec![2.0, f64::NAN]).warning().is_none());
        let tv = stats("tv", vec![2.0, 3.0]).warning().unwrap();
        assert!(
            tv.contains("objective rose") && tv.contains("step_ratio"),
            "{tv}"
        );
        let pnp = stats("pnp", vec![2.0, 3.0]).warning().unwrap();
        assert!(
            pnp.contains("data term rose") && pnp.contains("pnp_weight"),
            "{pnp}"
        );
        let none = JointStats {
            iterations: 0,
            ..stats("tv", vec![2.0, 3.0])
        };
        assert!(none.warning().is_none());
    }

    /// The error of a 32² solver with settings `bad`.
    fn refusal(bad: &JointConfig) -> String {
        let b = basis();
        let e = Joint::new(
            &patterns(32, 32),
            &system(&b),
            &b,
            &curvature(&b, 1.0),
            bad,
            "t.toml",
        );
        e.err().expect("refused").to_string()
    }

    /// y = Aα + N(0, σ²) with ω = 1/σ²: the discrepancy rule ends with Σω r²/N within its
    /// tolerance of 1, and without weights it is refused.
    #[test]
    fn the_discrepancy_rule_matches_the_noise() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let cfg = JointConfig {
            iterations: 300,
            weight_rule: WeightRule::Discrepancy,
            search_iterations: 60,
            ..Default::default()
        };
        let j = solver(32, 1.0, cfg);
        let t = truth(32, 32);
        let mut y = frame_of(&j, &t);
        let sigma = 0.02 * y.data.iter().map(|v| v.abs()).sum::<f32>() / y.data.len() as f32;
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let noise = Normal::new(0.0, sigma).unwrap();
        y.data.iter_mut().for_each(|v| *v += noise.sample(&mut rng));
        let omega = Cube::from_vec(32, 32, 1, vec![1.0 / (sigma * sigma); 32 * 32]).unwrap();
        let weights = DataWeights::new(omega);
        let (est, stats) = j.run(&y, &flat_seed(&t), Some(&weights)).unwrap();
        let search = stats.discrepancy.clone().unwrap();
        eprintln!("{search:?}, final ratio {}", stats.residual_ratio);
        assert!(search.reached && est.all_finite(), "{search:?}");
        assert!(
            (0.8..1.25).contains(&stats.residual_ratio),
            "{}",
            stats.residual_ratio
        );
        let e = j.run(&y, &flat_seed(&t), None).unwrap_err();
        assert!(e.to_string().contains("noise weights"), "{e}");
    }

    fn pnp(iterations: usize) -> JointConfig {
        JointConfig {
            iterations,
            prior: Prior::Pnp,
            ..Default::default()
        }
    }

    /// With η = 0 the constant α fitting y exactly minimises data + prior (the smoother keeps
    /// constants, so its prior is zero there, and only constants have zero prior): PnP-ADMM
    /// recovers it from a wrong seed (6.6·10⁻⁵ relative after 2000 iterations with ρ = 0.01, W⁸
    /// and Bα ≥ 0; without the constraint 8.8·10⁻⁶ after 600; the low spatial frequencies of α
    /// that one pixel's equation does not pin diffuse slowly through W).
    #[test]
    fn pnp_recovers_a_cube_in_the_range() {
        let cfg = JointConfig {
            pnp_weight: 0.01,
            pnp_passes: 8,
            ..pnp(2000)
        };
        let j = solver(32, 0.0, cfg);
        let t = range_cube();
        let (est, stats) = j
            .run(&frame_of(&j, &t), &flat_seed(&truth(32, 32)), None)
            .unwrap();
        let rel = relative_error(&est, &t);
        eprintln!(
            "relative error {rel:.3e}, fixed point {:.3e} → {:.3e}",
            stats.fixed_point[0],
            stats.fixed_point.last().unwrap()
        );
        assert!(rel < 1e-4, "relative error {rel:.3e}");
    }

    /// Once the guide is frozen (second half) PnP is ADMM on a convex problem: ‖Δz‖² + ‖Δu‖²
    /// never increases (He & Yuan 2015; f32 allowance 10⁻⁴ of its value at the freeze) and falls.
    #[test]
    fn pnp_fixed_point_residual_never_increases_after_the_freeze() {
        let j = solver(32, 1.0, pnp(400));
        let t = truth(32, 32);
        let (_, stats) = j.run(&frame_of(&j, &t), &flat_seed(&t), None).unwrap();
        let fp = &stats.fixed_point[200..];
        for (i, w) in fp.windows(2).enumerate() {
            assert!(
                w[1] <= w[0] + 1e-4 * fp[0],
                "iteration {}: {} after {}",
                200 + i + 1,
                w[1],
                w[0]
            );
        }
        eprintln!(
            "fixed point {:.3e} at the freeze, {:.3e} at the end",
            fp[0],
            fp.last().unwrap()
        );
        assert!(
            *fp.last().unwrap() < 1e-2 * fp[0],
            "{} vs {}",
            fp.last().unwrap(),
            fp[0]
        );
    }

    #[test]
    fn pnp_stiff_cases_stay_finite_or_are_refused() {
        let j = solver(32, 1.0, pnp(100));
        let zero = Cube::zeros(32, 32, 1);
        let (est, st) = j.run(&zero, &Cube::zeros(32, 32, 4), None).unwrap();
        assert!(est.data.iter().all(|&v| v == 0.0) && st.fixed_point.iter().all(|&v| v == 0.0));
        let t = truth(32, 32);
        let y = clipped_frame(&j, &t);
        let (est, st) = j.run(&y, &flat_seed(&t), None).unwrap();
        assert!(est.all_finite() && st.objective.iter().all(|v| v.is_finite()));
        let b = basis();
        let f = near_singular(&b);
        let near = Joint::new(
            &patterns(32, 32),
            &f,
            &b,
            &curvature(&b, 1.0),
            &pnp(100),
            "t.toml",
        )
        .unwrap();
        let (est, _) = near
            .run(&frame_of(&near, &t), &flat_seed(&t), None)
            .unwrap();
        assert!(est.all_finite());
        // All weights zero: nothing to fit, refused.
        let e = j
            .run(
                &y,
                &flat_seed(&t),
                Some(&DataWeights::new(Cube::zeros(32, 32, 1))),
            )
            .unwrap_err();
        assert!(e.to_string().contains("weight"), "{e}");
        let refused = |bad: JointConfig, key: &str| {
            let e = refusal(&bad);
            assert!(e.contains(key), "{e}");
        };
        let zero_weight = JointConfig {
            pnp_weight: 0.0,
            ..pnp(10)
        };
        refused(zero_weight, "reconstruct.joint.pnp_weight");
        let discrepancy = JointConfig {
            weight_rule: WeightRule::Discrepancy,
            ..pnp(10)
        };
        refused(discrepancy, "reconstruct.joint.weight_rule");
    }
}
