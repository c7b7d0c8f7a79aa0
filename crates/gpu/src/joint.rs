//! The joint reconstruction's iterations on the GPU (shaders/joint.wgsl), built from the core's
//! `Joint` tables so both run the same Chambolle–Pock steps in the same order of summation:
//! per frame the means that fix λ, τ and σ, M = (I + τη'Q)⁻¹ and the per-pixel proximal tables
//! (all on the GPU, no round trip), then the iterations (dual step with the pixel costs, their
//! sum, primal step), the final objective, the non-finite check, the cube diag(g)·Bα clipped at
//! zero with its violation, and the channels Fα. Per frame only the objective list and a few
//! words come back.

use crate::context::{linear_groups, GpuContext, Launch};
use crate::error::{GpuError, Result};
use crate::gap;
use crate::mix::GpuMix;
use specmux_core::joint::discrepancy::{self, Search};
use specmux_core::joint::{
    normalised_weights, rebalances_before, reweights_before, Joint, JointStats, WeightRule,
};
use specmux_core::noise::DataWeights;
use std::sync::Mutex;

/// Threads per workgroup of shaders/joint.wgsl.
const WORKGROUP: u32 = 256;

/// Words before M in the per-frame scalars (shaders/joint.wgsl's `sc`): the list count,
/// mean|y|, one unused, λ, τ, σ and two unused.
const SCALARS: usize = 8;

/// The `Params` struct of shaders/joint.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    w: u32,
    h: u32,
    npx: u32,
    bands: u32,
    lambda_per_y: f32,
    ratio: f32,
    step: f32,
    /// γ − 1 of the over-relaxation (0: the plain Chambolle–Pock step).
    over: f32,
    /// Reweighted TV: ε per mean ‖∇α‖ (`reweight_eps`).
    eps: f32,
    /// The flush threshold of r per λ at a run's first iteration (`dual_flush`).
    flush: f32,
    _pad: [u32; 2],
}

/// The iterate and dual variables read back, plane-major (value k of pixel p at k·npx + p).
pub struct JointGpuState {
    pub alpha: Vec<f32>,
    pub bar: Vec<f32>,
    pub qx: Vec<f32>,
    pub qy: Vec<f32>,
    /// The constraint dual, `padded_bands` planes.
    pub r: Vec<f32>,
    /// 1 where r ≠ 0 somewhere in the pixel's bands, else 0.
    pub active: Vec<f32>,
    pub lambda: f32,
    pub tau: f32,
    pub sigma: f32,
}

/// The joint solver of one rig on the GPU, bound to the frame and the cube buffers.
pub struct GpuJoint {
    pub iterations: usize,
    /// The objective after every step (`trace_objective`), else at the seed and the end only.
    trace: bool,
    /// Over-relaxation γ (reported in the stats).
    relaxation: f64,
    /// `dual_flush` (reported in the stats).
    dual_flush: f64,
    /// The spectral prior's name (reported in the stats).
    spectral_prior: &'static str,
    /// Times the TV weights are refreshed in a run (`reweight_rounds`; 0: plain TV).
    reweights: usize,
    j: usize,
    nbp: usize,
    npx: usize,
    /// Σ|y| and Σ|α₀| (two sums each), the scalars and M, the tables and the state's start.
    start: Vec<Launch>,
    /// Σ|α| (two sums), the scalars and M again, the tables for the new τ; empty when
    /// `rebalance` is off.
    rebalance: Vec<Launch>,
    /// The host's λ taken (the dual rescaled, ᾱ = α), then as `rebalance` (the CPU's
    /// `set_lambda`).
    relambda: Vec<Launch>,
    /// The discrepancy search's iterations per trial (None: λ fixed by its rule).
    search_iterations: Option<usize>,
    /// The last search's trials and choice, for the stats.
    search: Mutex<Option<Search>>,
    dual: Launch,
    /// Σ of the pixel costs appended to the objective list.
    cost_sum: [Launch; 2],
    primal: Launch,
    /// The flush threshold of r set (`flush_start`) and decayed (`flush_decay`).
    flush: [Launch; 2],
    /// ‖∇α‖ per pixel, its mean appended to the reweighting's list, the new TV weights.
    reweight: Vec<Launch>,
    /// The pixel costs at the current α (the objective after the last step).
    cost: Launch,
    /// ωr² per pixel and its sum appended to the residual list (the residual ratio's sum).
    residual: [Launch; 3],
    /// What the stats need of the data weights last set.
    weights: Mutex<WeightsInfo>,
    non_finite: Launch,
    cube: GpuMix,
    clip: Launch,
    channels: GpuMix,
    b: Buffers,
    /// The objective list, the scalars' header, the extremes, the counter and the residual
    /// list, for the host.
    staging: wgpu::Buffer,
    /// The residual list of a search trial, for the host.
    trial_staging: wgpu::Buffer,
}

/// The data weights as the stats report them: the mean ω the tables were divided by, the
/// pixels with ω > 0 and the saturated ones, and whether weights were set at all.
#[derive(Clone, Copy, Debug)]
struct WeightsInfo {
    scale: f64,
    positive: usize,
    saturated: usize,
    set: bool,
}

impl GpuJoint {
    /// Mirror `joint` on the GPU: `frame` holds the linearised frame y (w × h f32); the cube
    /// diag(gains)·Bα goes to the first planes of `cube`. The seed α₀ is written into the
    /// first J planes of `alpha_buffer()` before `encode` (the reconstructor's seed mix, or an
    /// upload). Every buffer is made here, once; ω is 1 until `set_weights`.
    pub fn new(
        ctx: &GpuContext,
        joint: &Joint,
        frame: &wgpu::Buffer,
        cube: &wgpu::Buffer,
        gains: &[f64],
    ) -> Result<GpuJoint> {
        let t = joint.tables();
        let (j, npx) = (t.basis_len, t.width * t.height);
        if gains.len() != t.basis.nrows() {
            return Err(GpuError::Shape(format!(
                "{} output gains for {} bands",
                gains.len(),
                t.basis.nrows()
            )));
        }
        let b = Buffers::new(ctx, joint);
        let gm = gap::module(ctx);
        let params = params(joint);
        let uniform = ctx.uniform("joint params", &params);
        let module = ctx.module("joint", &source(j, t.padded_bands));
        let pixels = linear_groups(npx, WORKGROUP);
        let launch = |entry, bound: &[(u32, &wgpu::Buffer)], groups| {
            let all = joined(&[(0, &uniform)], bound);
            Launch::bound(ctx, &module, entry, &all, groups)
        };
        let common = [
            (1, &b.rig),
            (2, frame),
            (3, &b.scalars),
            (4, &b.tab),
            (5, &b.state),
        ];
        let mean = |input, planes: usize, list| {
            let scale = 1.0 / (npx * planes) as f64;
            gap::abs_sum(ctx, &gm, input, (npx, planes), scale, &b.partials, list)
        };
        let setup = || {
            launch(
                "setup",
                &[(1, &b.rig), (3, &b.scalars), (11, &b.bal), (12, &b.lam)],
                [1, 1, 1],
            )
        };
        let mut start: Vec<Launch> = mean(frame, 1, &b.scalars)
            .into_iter()
            .chain(mean(&b.state, j, &b.bal))
            .collect();
        start.push(setup());
        start.push(launch("tables", &joined(&common, &[(6, &b.r)]), pixels));
        let balance = || {
            let mut l: Vec<Launch> = mean(&b.state, j, &b.bal).into_iter().collect();
            l.push(setup());
            l.push(launch("retable", &common[..4], pixels));
            l
        };
        let rebalance = if t.config.rebalance {
            balance()
        } else {
            Vec::new()
        };
        let bound = [(3, &b.scalars), (5, &b.state), (12, &b.lam)];
        let mut relambda = vec![launch("relambda", &bound, pixels)];
        relambda.extend(balance());
        let mut reweight = vec![launch("grad_norm", &[(5, &b.state), (7, &b.cost)], pixels)];
        let scale = 1.0 / npx as f64;
        reweight.extend(gap::abs_sum(
            ctx,
            &gm,
            &b.cost,
            (npx, 1),
            scale,
            &b.partials,
            &b.rw,
        ));
        let weights = [
            (3, &b.scalars),
            (4, &b.tab),
            (5, &b.state),
            (7, &b.cost),
            (10, &b.rw),
        ];
        reweight.push(launch("reweight", &weights, pixels));
        let ones = vec![1.0; t.system.nrows()];
        let joint = GpuJoint {
            iterations: t.config.iterations,
            trace: t.config.trace_objective,
            relaxation: t.config.relaxation,
            dual_flush: t.config.dual_flush,
            spectral_prior: t.config.spectral_prior_name(),
            reweights: t.config.rounds(),
            j,
            nbp: t.padded_bands,
            npx,
            start,
            rebalance,
            relambda,
            search_iterations: (t.config.weight_rule == WeightRule::Discrepancy)
                .then_some(t.config.search_iterations),
            search: Mutex::new(None),
            dual: launch("dual", &joined(&common, &[(6, &b.r), (7, &b.cost)]), pixels),
            cost_sum: gap::abs_sum(ctx, &gm, &b.cost, (npx, 1), 1.0, &b.partials, &b.objective),
            primal: launch(
                "primal",
                &[
                    (1, &b.rig),
                    (2, frame),
                    (3, &b.scalars),
                    (4, &b.tab),
                    (5, &b.state),
                    (6, &b.r),
                ],
                pixels,
            ),
            reweight,
            flush: [
                launch("flush_start", &[(3, &b.scalars)], [1, 1, 1]),
                // No uniform: the decay is the shader's constant.
                Launch::bound(ctx, &module, "flush_decay", &[(3, &b.scalars)], [1, 1, 1]),
            ],
            cost: launch("objective", &joined(&common, &[(7, &b.cost)]), pixels),
            residual: {
                let [sum, finish] =
                    gap::abs_sum(ctx, &gm, &b.cost, (npx, 1), 1.0, &b.partials, &b.residual);
                let bound = [
                    (1, &b.rig),
                    (2, frame),
                    (4, &b.tab),
                    (5, &b.state),
                    (7, &b.cost),
                ];
                let kernel = launch("residual", &bound, pixels);
                [kernel, sum, finish]
            },
            weights: Mutex::new(WeightsInfo {
                scale: 1.0,
                positive: npx,
                saturated: 0,
                set: false,
            }),
            non_finite: gap::non_finite(ctx, &gm, &b.state, (npx, j), &b.counter),
            cube: GpuMix::into(ctx, &scaled_rows(t.basis, gains), &b.state, npx, cube)?,
            clip: launch("clip", &[(8, cube), (9, &b.extremes)], pixels),
            channels: GpuMix::new(ctx, &scaled_rows(t.system, &ones), &b.state, npx)?,
            staging: ctx.readback(
                "joint staging",
                b.objective.size() + 4 * SCALARS as u64 + 12 + b.residual.size(),
            ),
            trial_staging: ctx.readback("joint trial residual", b.residual.size()),
            b,
        };
        let (ones, mean) = normalised_weights(None, npx)?;
        joint.write_weights(ctx, (&ones, mean), &vec![false; npx], false);
        Ok(joint)
    }

    /// Per-pixel data weights ω (one plane, finite, ≥ 0) and the saturated pixels (the CPU's
    /// `start(.., Some(weights))`), kept for every later frame.
    pub fn set_weights(&self, ctx: &GpuContext, weights: &DataWeights) -> Result<()> {
        let omega = &weights.omega;
        if omega.planes != 1 || omega.pixels() != self.npx || weights.saturated.len() != self.npx {
            return Err(GpuError::Shape(format!(
                "joint: weights {}×{}×{} and {} saturation flags for {} pixels",
                omega.width,
                omega.height,
                omega.planes,
                weights.saturated.len(),
                self.npx
            )));
        }
        let scaled = normalised_weights(Some(omega), self.npx)?;
        self.write_weights(ctx, (&scaled.0, scaled.1), &weights.saturated, true);
        Ok(())
    }

    /// ω over its mean (`normalised_weights`, as the CPU's `Joint::start` takes it, so λ and
    /// the spectral prior keep their balance against the data whatever the weights' units)
    /// into its table, and the saturation flags into theirs. `set`: the weights are the
    /// caller's (reported as such), not the uniform start.
    fn write_weights(
        &self,
        ctx: &GpuContext,
        (scaled, mean): (&[f32], f64),
        saturated: &[bool],
        set: bool,
    ) {
        let plane = |k: usize| (k * self.npx * 4) as u64;
        let flags: Vec<f32> = saturated.iter().map(|&s| s as u8 as f32).collect();
        let q = &ctx.queue;
        q.write_buffer(&self.b.tab, plane(self.j + 3), bytemuck::cast_slice(scaled));
        q.write_buffer(&self.b.tab, plane(self.j + 5), bytemuck::cast_slice(&flags));
        let mut info = self.weights.lock().unwrap_or_else(|e| e.into_inner());
        *info = WeightsInfo {
            scale: mean,
            positive: scaled.iter().filter(|&&v| v > 0.0).count(),
            saturated: saturated.iter().filter(|&&s| s).count(),
            set,
        };
    }

    /// The state buffer: its first J planes are α (the seed goes there before `encode`).
    pub fn alpha_buffer(&self) -> &wgpu::Buffer {
        &self.b.state
    }

    /// The channels x = Fα (C planes) after `encode`.
    pub fn channels(&self) -> &wgpu::Buffer {
        self.channels.output()
    }

    /// Record a whole run from the seed: start, `iterations` steps (the steps rebalanced
    /// halfway and the TV weights refreshed between the stages of reweighted TV, as on the
    /// CPU), `encode_finish`.
    pub fn encode(&self, enc: &mut wgpu::CommandEncoder) {
        self.encode_start(enc);
        self.encode_iterations(enc);
        self.encode_finish(enc);
    }

    /// The run's `iterations` steps with their stages (rebalance, reweightings).
    fn encode_iterations(&self, enc: &mut wgpu::CommandEncoder) {
        {
            let mut cp = enc.begin_compute_pass(&Default::default());
            self.flush[0].record(&mut cp);
            for it in 0..self.iterations {
                if rebalances_before(it, self.iterations) {
                    self.rebalance.iter().for_each(|l| l.record(&mut cp));
                }
                if reweights_before(it, self.iterations, self.reweights) {
                    self.reweight.iter().for_each(|l| l.record(&mut cp));
                }
                self.record_dual(&mut cp);
                self.primal.record(&mut cp);
                self.flush[1].record(&mut cp);
            }
        }
    }

    /// Record the start of a run: the lists cleared, λ, τ, σ, M, the tables, ᾱ = α, q = r = 0;
    /// untraced, also the objective at the seed (traced, the first dual step appends it).
    pub fn encode_start(&self, enc: &mut wgpu::CommandEncoder) {
        let mut cp = self.record_start(enc);
        if !self.trace {
            self.record_objective(&mut cp);
        }
    }

    /// The lists and the host's λ cleared, then the start's launches (in the pass returned).
    fn record_start<'e>(&self, enc: &'e mut wgpu::CommandEncoder) -> wgpu::ComputePass<'e> {
        for b in [
            &self.b.scalars,
            &self.b.objective,
            &self.b.extremes,
            &self.b.counter,
            &self.b.rw,
            &self.b.bal,
            &self.b.lam,
        ] {
            enc.clear_buffer(b, 0, None);
        }
        let mut cp = enc.begin_compute_pass(&Default::default());
        self.start.iter().for_each(|l| l.record(&mut cp));
        cp
    }

    /// The objective at the current α appended to its list.
    fn record_objective(&self, cp: &mut wgpu::ComputePass) {
        self.cost.record(cp);
        self.cost_sum.iter().for_each(|l| l.record(cp));
    }

    /// Whether λ is searched by the discrepancy principle: then a run is
    /// `encode_search_start`, a submission, `search`, and `encode_after_search`.
    pub fn searches(&self) -> bool {
        self.search_iterations.is_some()
    }

    /// Record the start of a searched run (as `encode_start`, the objective left to the run
    /// after the search, as on the CPU).
    pub fn encode_search_start(&self, enc: &mut wgpu::CommandEncoder) {
        self.record_start(enc);
    }

    /// After the submission of `encode_search_start`: λ by the discrepancy principle (the
    /// core's secant search on the residual ratio, each trial `search_iterations` steps warm
    /// from the last, one submission and read-back each), the choice kept for the run.
    pub fn search(&self, ctx: &GpuContext) -> Result<Search> {
        let iterations = self.search_iterations.unwrap_or(0);
        let info = *self.weights.lock().unwrap_or_else(|e| e.into_inner());
        if !info.set || info.positive == 0 {
            return Err(GpuError::Numerical(
                "joint: the discrepancy principle needs the noise weights ω of a camera noise model (GpuJoint::set_weights)".into(),
            ));
        }
        let lambda0 = ctx.read::<f32>(&self.b.scalars, SCALARS)?[3] as f64;
        let search = discrepancy::secant(lambda0, |lambda| {
            let sum = self.trial(ctx, lambda, iterations)?;
            Ok(sum * info.scale / info.positive as f64)
        })?;
        self.set_lambda(ctx, search.lambda);
        *self.search.lock().unwrap_or_else(|e| e.into_inner()) = Some(search.clone());
        Ok(search)
    }

    /// The host's λ for the next submission.
    fn set_lambda(&self, ctx: &GpuContext, lambda: f64) {
        let v = [lambda as f32];
        ctx.queue
            .write_buffer(&self.b.lam, 0, bytemuck::cast_slice(&v));
    }

    /// One trial of the search: λ set, `iterations` steps from the current state, Σωr².
    fn trial(&self, ctx: &GpuContext, lambda: f64, iterations: usize) -> Result<f64> {
        self.set_lambda(ctx, lambda);
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.b.residual, 0, None);
        {
            let mut cp = enc.begin_compute_pass(&Default::default());
            self.relambda.iter().for_each(|l| l.record(&mut cp));
            self.flush[0].record(&mut cp);
            for _ in 0..iterations {
                self.dual.record(&mut cp);
                self.primal.record(&mut cp);
                self.flush[1].record(&mut cp);
            }
            self.residual.iter().for_each(|l| l.record(&mut cp));
        }
        let bytes = self.b.residual.size();
        enc.copy_buffer_to_buffer(&self.b.residual, 0, &self.trial_staging, 0, bytes);
        ctx.queue.submit([enc.finish()]);
        let mut list = [0.0f32; 2];
        ctx.read_into(&self.trial_staging, &mut list)?;
        Ok(list[1] as f64)
    }

    /// Record the run after `search`: the chosen λ taken, the objective there (untraced), the
    /// iterations with their stages and `encode_finish`.
    pub fn encode_after_search(&self, enc: &mut wgpu::CommandEncoder) {
        {
            let mut cp = enc.begin_compute_pass(&Default::default());
            self.relambda.iter().for_each(|l| l.record(&mut cp));
            if !self.trace {
                self.record_objective(&mut cp);
            }
        }
        self.encode_iterations(enc);
        self.encode_finish(enc);
    }

    /// Record the dual step alone, with the objective at the current α appended to the list
    /// when traced.
    pub fn encode_dual(&self, enc: &mut wgpu::CommandEncoder) {
        self.record_dual(&mut enc.begin_compute_pass(&Default::default()));
    }

    /// Record the primal step alone.
    pub fn encode_primal(&self, enc: &mut wgpu::CommandEncoder) {
        self.primal
            .record(&mut enc.begin_compute_pass(&Default::default()));
    }

    fn record_dual(&self, cp: &mut wgpu::ComputePass) {
        self.dual.record(cp);
        if self.trace {
            self.cost_sum.iter().for_each(|l| l.record(cp));
        }
    }

    /// Record the end of a run: the final objective, the non-finite check, the cube (clipped,
    /// with its extremes), the channels, and the copies `stats` reads.
    pub fn encode_finish(&self, enc: &mut wgpu::CommandEncoder) {
        // The residual list holds this run's sum alone (a search's trials used it too).
        enc.clear_buffer(&self.b.residual, 0, None);
        {
            let mut cp = enc.begin_compute_pass(&Default::default());
            self.record_objective(&mut cp);
            self.non_finite.record(&mut cp);
            self.cube.record(&mut cp);
            self.clip.record(&mut cp);
            self.channels.record(&mut cp);
            self.residual.iter().for_each(|l| l.record(&mut cp));
        }
        let o = self.b.objective.size();
        let s = 4 * SCALARS as u64;
        enc.copy_buffer_to_buffer(&self.b.objective, 0, &self.staging, 0, o);
        enc.copy_buffer_to_buffer(&self.b.scalars, 0, &self.staging, o, s);
        enc.copy_buffer_to_buffer(&self.b.extremes, 0, &self.staging, o + s, 8);
        enc.copy_buffer_to_buffer(&self.b.counter, 0, &self.staging, o + s + 8, 4);
        let r = self.b.residual.size();
        enc.copy_buffer_to_buffer(&self.b.residual, 0, &self.staging, o + s + 12, r);
    }

    /// After the submission that held `encode` (or `encode_finish`): the objective at the seed
    /// and after each step (untraced: after the last only), λ, τ, σ, the cube's violation and
    /// the residual ratio Σωr²/#{ω > 0} (ω in the units set), or an error when α holds a NaN or
    /// an infinite value, as on the CPU. `seconds` is 0: the run is part of one submission.
    pub fn stats(&self, ctx: &GpuContext) -> Result<JointStats> {
        let mut w = vec![0u32; (self.staging.size() / 4) as usize];
        ctx.read_into(&self.staging, &mut w)?;
        let f = |i: usize| f32::from_bits(w[i]) as f64;
        // objective list | scalars | extremes (2) | counter | residual list (count, sum).
        let tail = w.len() - SCALARS - 5;
        let (hi, neg) = (f(tail + SCALARS), f(tail + SCALARS + 1));
        let non_finite = w[tail + SCALARS + 2];
        if non_finite > 0 {
            return Err(GpuError::Numerical(format!(
                "joint: {non_finite} non-finite coefficients after {} iterations",
                w[0].saturating_sub(1)
            )));
        }
        let n = (w[0] as usize).min(tail - 1);
        let info = *self.weights.lock().unwrap_or_else(|e| e.into_inner());
        Ok(JointStats {
            iterations: match self.trace {
                true => n.saturating_sub(1),
                false => self.iterations,
            },
            objective: (1..=n).map(f).collect(),
            lambda: f(tail + 3),
            steps: [f(tail + 4), f(tail + 5)],
            violation: if hi > 0.0 { neg / hi } else { 0.0 },
            relaxation: Some(self.relaxation),
            dual_flush: Some(self.dual_flush),
            prior: "tv".into(),
            spectral_prior: self.spectral_prior.into(),
            reweight_rounds: self.reweights,
            residual_ratio: f(tail + SCALARS + 4) * info.scale / info.positive.max(1) as f64,
            noise_weights: info.set,
            saturated_pixels: info.saturated,
            discrepancy: match self.searches() {
                true => self
                    .search
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .clone(),
                false => None,
            },
            ..Default::default()
        })
    }

    /// The iterate, the duals and the scalars read back (one round trip each; for tests).
    pub fn state(&self, ctx: &GpuContext) -> Result<JointGpuState> {
        let (j, n) = (self.j, self.npx);
        let st: Vec<f32> = ctx.read(&self.b.state, 4 * j * n)?;
        let mut r: Vec<f32> = ctx.read(&self.b.r, (self.nbp + 1) * n)?;
        let sc: Vec<f32> = ctx.read(&self.b.scalars, SCALARS)?;
        let active = r.split_off(self.nbp * n);
        let part = |k: usize| st[k * j * n..(k + 1) * j * n].to_vec();
        Ok(JointGpuState {
            alpha: part(0),
            bar: part(1),
            qx: part(2),
            qy: part(3),
            r,
            active,
            lambda: sc[3],
            tau: sc[4],
            sigma: sc[5],
        })
    }
}

/// The buffers of one rig's run: shaders/joint.wgsl's bindings and the sums' partials.
struct Buffers {
    rig: wgpu::Buffer,
    /// m | t | c | k | ω | the TV weight | the saturation flag.
    tab: wgpu::Buffer,
    /// α | ᾱ | qx | qy.
    state: wgpu::Buffer,
    /// r (padded bands) | active.
    r: wgpu::Buffer,
    cost: wgpu::Buffer,
    scalars: wgpu::Buffer,
    objective: wgpu::Buffer,
    extremes: wgpu::Buffer,
    counter: wgpu::Buffer,
    partials: wgpu::Buffer,
    /// The reweighting's means of ‖∇α‖: a count, then one value per refresh.
    rw: wgpu::Buffer,
    /// The means of |α| the steps are balanced by: a count, the seed's, the rebalance's.
    bal: wgpu::Buffer,
    /// Σωr² at the end of a run: a count, then the sum.
    residual: wgpu::Buffer,
    /// λ set by the host (0: the rule's).
    lam: wgpu::Buffer,
}

impl Buffers {
    /// Every buffer of `joint`'s run, zeroed but for the rig's tables.
    fn new(ctx: &GpuContext, joint: &Joint) -> Buffers {
        let t = joint.tables();
        let (j, npx) = (t.basis_len as u64, t.width * t.height);
        let plane = (npx * 4) as u64;
        let groups = gap::count(linear_groups(npx * t.basis_len, WORKGROUP));
        Buffers {
            rig: ctx.storage_init("joint rig tables", &rig_tables(joint)),
            tab: ctx.storage("joint prox tables", (j + 6) * plane),
            state: ctx.storage("joint state", 4 * j * plane),
            r: ctx.storage("joint constraint dual", (t.padded_bands as u64 + 1) * plane),
            cost: ctx.storage("joint pixel costs", plane),
            scalars: ctx.storage("joint scalars", 4 * (SCALARS as u64 + j * j)),
            objective: ctx.storage("joint objective", 4 * (t.config.iterations as u64 + 2)),
            extremes: ctx.storage("joint cube extremes", 8),
            counter: ctx.storage("joint non-finite", 4),
            partials: ctx.storage("joint partials", 4 * groups as u64),
            rw: ctx.storage("joint reweight means", 4 * (t.config.rounds() as u64 + 2)),
            bal: ctx.storage(
                "joint alpha means",
                4 * (3 + discrepancy::MAX_TRIALS as u64 + 1),
            ),
            residual: ctx.storage("joint residual", 4 * 2),
            lam: ctx.storage("joint host lambda", 4),
        }
    }
}

/// shaders/joint.wgsl's `Params` for `joint`.
fn params(joint: &Joint) -> Params {
    let t = joint.tables();
    Params {
        w: t.width as u32,
        h: t.height as u32,
        npx: (t.width * t.height) as u32,
        bands: t.basis.nrows() as u32,
        lambda_per_y: (t.config.tv_weight * t.mean_a_norm) as f32,
        ratio: t.config.step_ratio as f32,
        step: (t.step_product.sqrt() / t.operator_norm) as f32,
        over: (t.config.relaxation - 1.0) as f32,
        eps: t.config.reweight_eps as f32,
        flush: t.config.dual_flush as f32,
        _pad: [0; 2],
    }
}

/// The rows of `m` each times its gain (the mixing matrices of `GpuMix`).
fn scaled_rows(m: &nalgebra::DMatrix<f64>, gains: &[f64]) -> Vec<Vec<f64>> {
    m.row_iter()
        .zip(gains)
        .map(|(row, &g)| row.iter().map(|v| v * g).collect())
        .collect()
}

/// The bindings `a` then `b`.
fn joined<'a>(
    a: &[(u32, &'a wgpu::Buffer)],
    b: &[(u32, &'a wgpu::Buffer)],
) -> Vec<(u32, &'a wgpu::Buffer)> {
    a.iter().chain(b).copied().collect()
}

/// shaders/joint.wgsl with the rig's J and padded band count written over its placeholders.
fn source(j: usize, nbp: usize) -> String {
    let mut src = include_str!("shaders/joint.wgsl").to_string();
    for (line, value) in [("const J: u32 = 8u;", j), ("const NBP: u32 = 64u;", nbp)] {
        assert!(src.contains(line), "shaders/joint.wgsl declares {line}");
        let name = &line[..line.find(':').unwrap_or(0)];
        src = src.replace(line, &format!("{name}: u32 = {value}u;"));
    }
    src
}

/// shaders/joint.wgsl's `rig`: a (plane-major) | βB by columns | column minima | maxima |
/// P' (the spectral prior) row-major | its eigenvectors (column i the i-th) | eigenvalues, in
/// f32. M = (I + τP')⁻¹ is V diag(1/(1 + τe)) Vᵀ from these, since τ is known only on the GPU.
fn rig_tables(joint: &Joint) -> Vec<f32> {
    let t = joint.tables();
    let (j, n) = (t.basis_len, t.width * t.height);
    let mut out: Vec<f32> = (0..j)
        .flat_map(|k| (0..n).map(move |p| t.a[p * j + k]))
        .collect();
    out.extend_from_slice(t.basis_columns);
    out.extend(t.column_range.iter().map(|r| r.0));
    out.extend(t.column_range.iter().map(|r| r.1));
    out.extend(t.spectral_prior.transpose().iter().map(|&v| v as f32));
    let eig = t.spectral_prior.clone().symmetric_eigen();
    out.extend(eig.eigenvectors.transpose().iter().map(|&v| v as f32));
    out.extend(eig.eigenvalues.iter().map(|&v| v as f32));
    out
}
