//! The joint reconstruction on the GPU against the core's `Joint`, kernel by kernel and whole:
//! the start (λ, τ, σ), the dual step alone (q, r, the active flags and the objective at the
//! seed), the primal step after it (α, ᾱ), 30 iterations with per-pixel weights ω (α, the
//! objective after every step, the cube diag(g)·Bα clipped at zero and its violation, the
//! channels Fα), a run without the objective's trace (its two values), a reweighted TV run (α
//! and the objective after every step), a run with its steps rebalanced halfway (α, τ, σ), and
//! the non-finite check. The problem: 24 × 20 pixels (not square, so a
//! swapped axis shows), six sinusoidal patterns, J = 4 cosines over 13 bands (padded to 16:
//! the padding's lanes are exercised), a seed with noise that leaves a third of the pixels
//! infeasible so the constraint's dual is active.
//!
//! Tolerances (relative L2 over all values, f64 sums of the CPU's f32 values):
//! - λ, τ, σ, 1e-6: a sum of |y| and of |α₀| in f32 on the GPU (tree order) against f64 on the
//!   CPU, ~1e-7 relative, then a few f32 products.
//! - one dual or primal step, 2e-6: each value is a short sum (J ≤ 8 products, a J × J
//!   matrix–vector product, 16 lanes) of f32 values in the CPU's order; a GPU may fuse
//!   products into FMAs and M comes from V diag(1/(1 + τe))Vᵀ in f32 rather than an f64
//!   inverse, a few ulps (1e-7) either way.
//! - the objective, 1e-5 of its value: the CPU sums pixel costs in f64, the GPU in f32 (per
//!   pixel, then a tree over 480 pixels): ~log₂(480)·ε plus the cancellation in y − aᵀα.
//! - 30 iterations, α and the cube 1e-4: Chambolle–Pock is non-expansive in the norm of
//!   M = [[I/τ, −Kᵀ], [−K, I/σ]] (He & Yuan 2012), so rounding differences add rather than
//!   grow: ≤ 30 steps × ~1e-6, times √(1/(1 − √(τσ)‖K‖)) ≈ 10 for the L2 norm against M's.
//!
//! A swapped axis, a wrong lane, a dropped constraint or an off-by-one pixel gives 1e-2 or more.
//!
//! By hand: with η = 0 a constant α with Bα > 0 that fits y = aᵀα exactly is a fixed point (its
//! gradient is 0, so q stays 0; r stays 0; the prox of v = α returns α since aᵀα = y), with
//! objective 0. Property: y and α₀ scaled by 2^k scale λ and mean|α₀| alike, so τ and σ are
//! unchanged and every iterate scales by 2^k, bit for bit (products by powers of two are exact).

mod common;

use nalgebra::DMatrix;
use specmux_core::carriers::default_layout;
use specmux_core::joint::{Joint, JointConfig, JointStats, SpectralPrior, WeightRule};
use specmux_core::noise::DataWeights;
use specmux_core::unmix::curvature;
use specmux_core::Cube;
use specmux_gpu::joint::GpuJoint;
use specmux_gpu::{wgpu, GpuContext};

const W: usize = 24;
const H: usize = 20;
const BANDS: usize = 13;
const J: usize = 4;

/// ‖gpu − cpu‖ / ‖cpu‖.
fn rel(gpu: &[f32], cpu: &[f32]) -> f64 {
    let want: Vec<f64> = cpu.iter().map(|&v| v as f64).collect();
    common::rel_l2(gpu, &want)
}

/// Pixel-major (k per pixel) → plane-major.
fn planes(v: &[f32], k: usize) -> Vec<f32> {
    let n = v.len() / k;
    (0..k)
        .flat_map(|i| (0..n).map(move |p| v[p * k + i]))
        .collect()
}

/// The six default carriers' patterns ½(1 + cos) on W × H.
fn patterns() -> Cube {
    let data = default_layout()
        .iter()
        .flat_map(|c| c.ideal_pattern(W, H).into_iter().map(|v| 0.5 * v))
        .collect();
    Cube::from_vec(W, H, 6, data).unwrap()
}

/// J cosines across the bands, and six Gaussian filters seen through them (F = T B).
fn basis_and_system() -> (DMatrix<f64>, DMatrix<f64>) {
    let b = DMatrix::from_fn(BANDS, J, |k, j| {
        let t = k as f64 / (BANDS - 1) as f64;
        (std::f64::consts::PI * j as f64 * t).cos() / (BANDS as f64).sqrt()
    });
    let t = DMatrix::from_fn(6, BANDS, |i, k| {
        (-((k as f64 - 1.0 - 2.0 * i as f64) / 2.0).powi(2)).exp()
    });
    (b.clone(), t * b)
}

/// The tests' settings, the objective traced after every iteration.
/// Plain TV (no reweighting: the core's side of some tests steps with `Joint::step`, which
/// does not refresh the weights; the reweighted run has its own test).
fn config(iterations: usize) -> JointConfig {
    JointConfig {
        iterations,
        tv_weight: 0.05,
        step_ratio: 1.0,
        trace_objective: true,
        reweight_rounds: Some(0),
        ..JointConfig::default()
    }
}

fn solver(iterations: usize) -> Joint {
    solver_with(&config(iterations), 1.0)
}

/// The solver with these settings and smoothness weight η.
fn solver_with(cfg: &JointConfig, eta: f64) -> Joint {
    let (b, f) = basis_and_system();
    Joint::new(&patterns(), &f, &b, &curvature(&b, eta), cfg, "t.toml").unwrap()
}

/// y = aᵀα per pixel for α planes.
fn frame_of(joint: &Joint, alpha: &Cube) -> Cube {
    let (n, a) = (W * H, joint.tables().a);
    let y = (0..n)
        .map(|p| (0..J).map(|j| a[p * J + j] * alpha.data[j * n + p]).sum())
        .collect();
    Cube::from_vec(W, H, 1, y).unwrap()
}

/// A piecewise-constant α (four regions), its frame y = aᵀα per pixel, and a seed: α plus
/// noise large enough that Bα₀ < 0 in some pixels.
fn problem(joint: &Joint) -> (Cube, Cube) {
    let n = W * H;
    let noise = common::noise(n * J, 7);
    let mut alpha = Cube::zeros(W, H, J);
    for p in 0..n {
        let (x, y) = (p % W, p / W);
        let region = (x >= W / 2) as usize + 2 * (y >= H / 3) as usize;
        for j in 0..J {
            alpha.data[j * n + p] = [1.0, 0.3, -0.2, 0.1][j] * (1.0 + 0.5 * region as f32);
        }
    }
    let mut seed = alpha.clone();
    seed.data
        .iter_mut()
        .zip(&noise)
        .for_each(|(v, e)| *v += 0.8 * e);
    (frame_of(joint, &alpha), seed)
}

/// The GPU solver for `joint` on `frame` with the seed uploaded, and its cube buffer.
fn gpu_solver(
    ctx: &GpuContext,
    joint: &Joint,
    frame: &Cube,
    seed: &Cube,
    gains: &[f64],
) -> (GpuJoint, wgpu::Buffer) {
    let y = common::upload(ctx, "frame", &frame.data);
    let cube = ctx.storage("cube", (BANDS * W * H * 4) as u64);
    let g = GpuJoint::new(ctx, joint, &y, &cube, gains).unwrap();
    ctx.queue
        .write_buffer(g.alpha_buffer(), 0, bytemuck::cast_slice(&seed.data));
    (g, cube)
}

/// A whole GPU run of `joint` from `seed` on `frame` (gains 1): its α (plane-major) and stats.
fn gpu_run(ctx: &GpuContext, joint: &Joint, frame: &Cube, seed: &Cube) -> (Vec<f32>, JointStats) {
    let (g, _) = gpu_solver(ctx, joint, frame, seed, &[1.0; BANDS]);
    submit(ctx, |enc| g.encode(enc));
    (g.state(ctx).unwrap().alpha, g.stats(ctx).unwrap())
}

/// The GPU's run against the CPU's (`what` names it): α and every objective value within the
/// 30-iteration tolerance (1e-4 relative), the same number of objective values.
fn assert_matches_core(what: &str, gpu: (&[f32], &JointStats), cpu: (&Cube, &JointStats)) {
    let e = rel(gpu.0, &cpu.0.data);
    eprintln!("{what}, α after 30 iterations: relative L2 {e:.2e}");
    assert!(e < 1e-4, "{what} α: {e:.2e}");
    assert_eq!(gpu.1.objective.len(), cpu.1.objective.len());
    for (got, want) in gpu.1.objective.iter().zip(&cpu.1.objective) {
        assert!(
            ((got - want) / want).abs() < 1e-4,
            "{what}: {got} against {want}"
        );
    }
}

fn submit(ctx: &GpuContext, f: impl FnOnce(&mut wgpu::CommandEncoder)) {
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    f(&mut enc);
    ctx.queue.submit([enc.finish()]);
}

#[test]
fn start_dual_and_primal_steps_match_the_core() {
    let Some(ctx) = common::context() else { return };
    let joint = solver(1);
    let (frame, seed) = problem(&joint);
    let mut cpu = joint.start(&frame, &seed, None).unwrap();
    let (g, cube_buf) = gpu_solver(&ctx, &joint, &frame, &seed, &[1.0; BANDS]);
    submit(&ctx, |enc| {
        g.encode_start(enc);
        g.encode_dual(enc);
    });
    let gpu = g.state(&ctx).unwrap();
    for (name, got, want) in [
        ("λ", gpu.lambda, cpu.lambda),
        ("τ", gpu.tau, cpu.tau),
        ("σ", gpu.sigma, cpu.sigma),
    ] {
        let e = ((got - want) / want).abs();
        eprintln!("{name}: GPU {got:e}, CPU {want:e}, relative {e:.1e}");
        assert!(e < 1e-6, "{name}: {got} against {want}");
    }
    let objective = joint.step(&mut cpu);
    let nbp = joint.tables().padded_bands;
    let (qx, qy, r, active) = cpu.duals();
    let flags: Vec<f32> = active.iter().map(|&a| a as f32).collect();
    let constrained = flags.iter().filter(|&&a| a > 0.0).count();
    eprintln!(
        "pixels with an active constraint: {constrained} of {}",
        W * H
    );
    assert!(
        constrained > W * H / 10 && constrained < W * H,
        "{constrained}"
    );
    assert_eq!(gpu.active, flags, "the active flags");
    for (name, got, want, k) in [
        ("qx", &gpu.qx, &qx, J),
        ("qy", &gpu.qy, &qy, J),
        ("r", &gpu.r, &r, nbp),
    ] {
        let e = rel(got, &planes(want, k));
        eprintln!("dual step, {name}: relative L2 {e:.2e}");
        assert!(e < 2e-6, "{name}: {e:.2e}");
    }
    let stats = {
        submit(&ctx, |enc| {
            g.encode_primal(enc);
            g.encode_finish(enc);
        });
        g.stats(&ctx).unwrap()
    };
    let e = (stats.objective[0] - objective).abs() / objective;
    eprintln!(
        "objective at the seed: GPU {:.6e}, CPU {objective:.6e}, relative {e:.1e}",
        stats.objective[0]
    );
    assert!(e < 1e-5, "objective {e:.2e}");
    let gpu = g.state(&ctx).unwrap();
    for (name, got, want) in [
        ("α", &gpu.alpha, &cpu.alpha()),
        ("ᾱ", &gpu.bar, &cpu.extrapolated()),
    ] {
        let e = rel(got, &planes(want, J));
        eprintln!("primal step, {name}: relative L2 {e:.2e}");
        assert!(e < 2e-6, "{name}: {e:.2e}");
    }
    // The cube of the one-step iterate: still infeasible in places, clipped, its violation.
    let alpha = cpu.alpha_cube();
    let (cube, violation) = joint.cube(&alpha, None).unwrap();
    let got: Vec<f32> = ctx.read(&cube_buf, BANDS * W * H).unwrap();
    let e = rel(&got, &cube.data);
    let dv = (stats.violation - violation).abs() / violation;
    eprintln!("one-step cube: relative L2 {e:.2e}; violation {violation:.4e}, relative {dv:.1e}");
    assert!(
        e < 2e-6 && violation > 1e-3 && dv < 2e-6,
        "{e:.2e}, {dv:.2e}"
    );
}

#[test]
fn thirty_weighted_iterations_match_the_core_with_cube_and_channels() {
    let Some(ctx) = common::context() else { return };
    let iterations = 30;
    // The core's side steps with `Joint::step` (the traced objective of each), which does
    // not flush r; the GPU's whole run does unless told not to.
    let exact = JointConfig {
        dual_flush: 0.0,
        ..config(iterations)
    };
    let joint = solver_with(&exact, 1.0);
    let (frame, seed) = problem(&joint);
    let omega: Vec<f32> = common::noise(W * H, 3)
        .iter()
        .map(|v| 1.0 + 0.9 * v)
        .collect();
    let omega = Cube::from_vec(W, H, 1, omega).unwrap();
    let gains: Vec<f64> = (0..BANDS).map(|k| 0.5 + k as f64 / BANDS as f64).collect();
    // Every seventh pixel read as saturated: its data term one-sided.
    let weights = DataWeights {
        omega: omega.clone(),
        saturated: (0..W * H).map(|p| p % 7 == 3).collect(),
    };
    let (alpha, cpu, ratio) = {
        let mut st = joint.start(&frame, &seed, Some(&weights)).unwrap();
        let mut objective: Vec<f64> = (0..iterations).map(|_| joint.step(&mut st)).collect();
        objective.push(joint.objective(&mut st));
        let (sum, positive) = joint.weighted_residual(&st);
        (st.alpha_cube(), objective, sum / positive as f64)
    };
    let (cube, violation) = joint.cube(&alpha, Some(&gains)).unwrap();
    let channels = joint.channels(&alpha).unwrap();
    let (g, cube_buf) = gpu_solver(&ctx, &joint, &frame, &seed, &gains);
    g.set_weights(&ctx, &weights).unwrap();
    // Twice through the same buffers (the seed written again: α is the iterate): the second
    // run's answer is the one checked.
    for _ in 0..2 {
        ctx.queue
            .write_buffer(g.alpha_buffer(), 0, bytemuck::cast_slice(&seed.data));
        submit(&ctx, |enc| g.encode(enc));
    }
    let stats = g.stats(&ctx).unwrap();
    let gpu = g.state(&ctx).unwrap();
    let e = rel(&gpu.alpha, &alpha.data);
    eprintln!("α after {iterations} iterations: relative L2 {e:.2e}");
    assert!(e < 1e-4, "α: {e:.2e}");
    assert_eq!(stats.iterations, iterations);
    assert_eq!(stats.objective.len(), cpu.len());
    let worst = stats
        .objective
        .iter()
        .zip(&cpu)
        .map(|(g, c)| ((g - c) / c).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "objective: {:.5e} → {:.5e}, worst relative difference {worst:.1e}",
        cpu[0], cpu[iterations]
    );
    assert!(worst < 1e-4, "objective {worst:.2e}");
    assert!(
        cpu[iterations] < 0.5 * cpu[0],
        "the run must do something: {cpu:?}"
    );
    let e = (stats.residual_ratio - ratio).abs() / ratio;
    eprintln!(
        "residual ratio GPU {:.6e}, CPU {ratio:.6e}, relative {e:.1e}; saturated {}",
        stats.residual_ratio, stats.saturated_pixels
    );
    assert!(e < 1e-4, "residual ratio {e:.2e}");
    assert!(
        stats.noise_weights
            && stats.saturated_pixels == weights.saturated.iter().filter(|&&s| s).count()
    );
    let got_cube: Vec<f32> = ctx.read(&cube_buf, BANDS * W * H).unwrap();
    let e = rel(&got_cube, &cube.data);
    eprintln!(
        "cube: relative L2 {e:.2e}; violation GPU {:.4e}, CPU {violation:.4e}",
        stats.violation
    );
    assert!(e < 1e-4, "cube: {e:.2e}");
    assert!(got_cube.iter().all(|&v| v >= 0.0));
    // Feasible by now on both (the one-step test checks a positive violation).
    assert!((stats.violation - violation).abs() <= 1e-4 * violation + 1e-7);
    let got: Vec<f32> = ctx.read(g.channels(), 6 * W * H).unwrap();
    let e = rel(&got, &channels.data);
    eprintln!("channels Fα: relative L2 {e:.2e}");
    assert!(e < 1e-4, "channels: {e:.2e}");
}

#[test]
fn an_untraced_run_keeps_the_objective_at_the_seed_and_the_end() {
    let Some(ctx) = common::context() else { return };
    let untraced = JointConfig {
        trace_objective: false,
        ..config(12)
    };
    let joint = solver_with(&untraced, 1.0);
    let (frame, seed) = problem(&joint);
    let (_, cpu) = joint.run(&frame, &seed, None).unwrap();
    let (_, stats) = gpu_run(&ctx, &joint, &frame, &seed);
    assert_eq!((stats.iterations, cpu.iterations), (12, 12));
    assert_eq!((stats.objective.len(), cpu.objective.len()), (2, 2));
    for (got, want) in stats.objective.iter().zip(&cpu.objective) {
        let e = ((got - want) / want).abs();
        eprintln!("objective: GPU {got:.6e}, CPU {want:.6e}, relative {e:.1e}");
        assert!(e < 1e-4, "{got} against {want}");
    }
}

/// Reweighted TV (three stages of 10): the same refreshes at the same iterations as the CPU's
/// run, so α and the objective after every step agree to the 30-iteration tolerance. The mean
/// ‖∇α‖ is an f32 tree sum here and f64 on the CPU (~1e-7 in ε).
#[test]
fn a_reweighted_run_matches_the_core() {
    let Some(ctx) = common::context() else { return };
    let reweighted = JointConfig {
        reweight_rounds: Some(2),
        ..config(30)
    };
    let joint = solver_with(&reweighted, 1.0);
    let (frame, seed) = problem(&joint);
    let (alpha, cpu) = joint.run(&frame, &seed, None).unwrap();
    let (plain, _) = solver(30).run(&frame, &seed, None).unwrap();
    assert!(
        rel(&plain.data, &alpha.data) > 1e-2,
        "the reweighting must change the run"
    );
    let (gpu, stats) = gpu_run(&ctx, &joint, &frame, &seed);
    assert_matches_core("reweighted", (&gpu, &stats), (&alpha, &cpu));
}

/// The steps rebalanced halfway (`rebalance`): the GPU's mean |α| at iteration 15, its τ, σ
/// and tables follow the CPU's, and the run differs from one without the rebalance.
#[test]
fn a_rebalanced_run_matches_the_core() {
    let Some(ctx) = common::context() else { return };
    let rebalanced = JointConfig {
        rebalance: true,
        ..config(30)
    };
    let joint = solver_with(&rebalanced, 1.0);
    let (frame, seed) = problem(&joint);
    let (alpha, cpu) = joint.run(&frame, &seed, None).unwrap();
    let (unbalanced, before) = solver(30).run(&frame, &seed, None).unwrap();
    assert!(
        rel(&unbalanced.data, &alpha.data) > 1e-3
            && (cpu.steps[0] / before.steps[0] - 1.0).abs() > 1e-2,
        "the rebalance must change the steps and the run: τ {:?} against {:?}",
        cpu.steps,
        before.steps
    );
    let (gpu, stats) = gpu_run(&ctx, &joint, &frame, &seed);
    assert_matches_core("rebalanced", (&gpu, &stats), (&alpha, &cpu));
    for (got, want) in stats.steps.iter().zip(&cpu.steps) {
        assert!(
            ((got - want) / want).abs() < 1e-6,
            "step {got} against {want}"
        );
    }
}

/// λ by the discrepancy principle: y = aᵀα plus uniform noise of variance σ², ω = 1/σ². The
/// GPU's search (its trials a submission each, the residual ratio read back) takes the CPU's
/// trials — the same count, each λ and ratio within 1e-3 — reaches ρ ≈ 1, and its run from the
/// choice ends within 1e-3 of the CPU's α (8 × 20 search steps and 30 more: rounding adds up
/// over 190 non-expansive steps, tests/joint.rs's 30-step bound × 6).
#[test]
fn the_discrepancy_search_matches_the_core() {
    let Some(ctx) = common::context() else { return };
    let searched = JointConfig {
        weight_rule: WeightRule::Discrepancy,
        search_iterations: 20,
        tv_weight: 1.0,
        ..config(30)
    };
    let joint = solver_with(&searched, 1.0);
    let (mut frame, seed) = problem(&joint);
    let mean = frame.data.iter().map(|v| v.abs()).sum::<f32>() / frame.data.len() as f32;
    let half_width = 0.05 * mean;
    let noise = common::noise(W * H, 11);
    frame
        .data
        .iter_mut()
        .zip(&noise)
        .for_each(|(v, n)| *v += half_width * n);
    // Uniform on ±h: variance h²/3.
    let omega = vec![3.0 / (half_width * half_width); W * H];
    let weights = DataWeights::new(Cube::from_vec(W, H, 1, omega).unwrap());
    let (alpha, cpu) = joint.run(&frame, &seed, Some(&weights)).unwrap();
    let want = cpu.discrepancy.clone().unwrap();
    let (g, _) = gpu_solver(&ctx, &joint, &frame, &seed, &[1.0; BANDS]);
    g.set_weights(&ctx, &weights).unwrap();
    assert!(g.searches());
    submit(&ctx, |enc| g.encode_search_start(enc));
    let got = g.search(&ctx).unwrap();
    submit(&ctx, |enc| g.encode_after_search(enc));
    let stats = g.stats(&ctx).unwrap();
    eprintln!("CPU search {want:?}\nGPU search {got:?}");
    assert!(want.trials.len() >= 2, "the search must move λ: {want:?}");
    assert_eq!(got.trials.len(), want.trials.len());
    for (a, b) in got.trials.iter().zip(&want.trials) {
        for k in 0..2 {
            assert!(((a[k] - b[k]) / b[k]).abs() < 1e-3, "{a:?} against {b:?}");
        }
    }
    assert!(want.reached && got.reached, "{want:?}");
    assert!(((got.lambda - want.lambda) / want.lambda).abs() < 1e-3);
    assert!(((stats.lambda - cpu.lambda) / cpu.lambda).abs() < 1e-3);
    assert!(stats.discrepancy.is_some_and(|s| s.trials == got.trials));
    let e = rel(&g.state(&ctx).unwrap().alpha, &alpha.data);
    let dr = (stats.residual_ratio - cpu.residual_ratio).abs() / cpu.residual_ratio;
    eprintln!(
        "α after the search and 30 iterations: relative L2 {e:.2e}; residual ratio GPU {:.4}, CPU {:.4}",
        stats.residual_ratio, cpu.residual_ratio
    );
    assert!(e < 1e-3 && dr < 1e-3, "α {e:.2e}, ratio {dr:.2e}");
    assert_eq!(stats.objective.len(), cpu.objective.len());
    // Without weights the search has nothing to match.
    let (g, _) = gpu_solver(&ctx, &joint, &frame, &seed, &[1.0; BANDS]);
    submit(&ctx, |enc| g.encode_search_start(enc));
    let e = g.search(&ctx).unwrap_err().to_string();
    assert!(e.contains("noise weights"), "{e}");
}

/// A diagonal spectral prior of unequal weights (the form of the trained prior) in place of
/// the curvature: the GPU's eigenpair tables follow the core's prior, not the curvature's.
#[test]
fn a_diagonal_spectral_prior_matches_the_core() {
    let Some(ctx) = common::context() else { return };
    let (b, f) = basis_and_system();
    let p = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![0.01, 0.5, 2.0, 8.0]));
    let trained = JointConfig {
        spectral_prior: Some(SpectralPrior::Trained),
        ..config(30)
    };
    let joint = Joint::new(&patterns(), &f, &b, &p, &trained, "t.toml").unwrap();
    let (frame, seed) = problem(&joint);
    let (alpha, cpu) = joint.run(&frame, &seed, None).unwrap();
    let (curved, _) = solver(30).run(&frame, &seed, None).unwrap();
    assert!(
        rel(&curved.data, &alpha.data) > 1e-3,
        "the prior must change the run"
    );
    let (gpu, stats) = gpu_run(&ctx, &joint, &frame, &seed);
    assert_matches_core("diagonal prior", (&gpu, &stats), (&alpha, &cpu));
    assert_eq!(
        (stats.spectral_prior.as_str(), cpu.spectral_prior.as_str()),
        ("trained", "trained")
    );
}

#[test]
fn bad_weights_are_refused_and_a_non_finite_seed_is_an_error() {
    let Some(ctx) = common::context() else { return };
    let joint = solver(3);
    let (frame, mut seed) = problem(&joint);
    let (g, _) = gpu_solver(&ctx, &joint, &frame, &seed, &[1.0; BANDS]);
    let mut omega = Cube::zeros(W, H, 1);
    omega.data[5] = -1.0;
    let e = g
        .set_weights(&ctx, &DataWeights::new(omega))
        .unwrap_err()
        .to_string();
    assert!(e.contains("weight"), "{e}");
    assert!(g
        .set_weights(&ctx, &DataWeights::new(Cube::zeros(W, 2, 1)))
        .is_err());
    seed.data[17] = f32::NAN;
    ctx.queue
        .write_buffer(g.alpha_buffer(), 0, bytemuck::cast_slice(&seed.data));
    submit(&ctx, |enc| g.encode(enc));
    let e = g.stats(&ctx).unwrap_err().to_string();
    assert!(e.contains("non-finite"), "{e}");
}

#[test]
fn an_exact_constant_fit_is_a_fixed_point_with_zero_objective() {
    let Some(ctx) = common::context() else { return };
    let joint = solver_with(&config(20), 0.0);
    let mut alpha = Cube::zeros(W, H, J);
    for (plane, v) in alpha.planes_mut().zip([2.0f32, 0.2, -0.1, 0.05]) {
        plane.fill(v);
    }
    let frame = frame_of(&joint, &alpha);
    let (g, _) = gpu_solver(&ctx, &joint, &frame, &alpha, &[1.0; BANDS]);
    submit(&ctx, |enc| g.encode(enc));
    let stats = g.stats(&ctx).unwrap();
    let gpu = g.state(&ctx).unwrap();
    let e = rel(&gpu.alpha, &alpha.data);
    let energy: f64 = frame.data.iter().map(|&v| 0.5 * (v as f64).powi(2)).sum();
    let worst = stats.objective.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    eprintln!("fixed point: α moved by {e:.2e} (relative L2), objective ≤ {worst:.2e} of ½Σy² = {energy:.3e}");
    assert!(e < 1e-5, "α moved by {e:.2e}");
    assert!(worst < 1e-6 * energy, "objective {worst:e}");
    // The constraint never acts; q holds only the rounding of α's flat field (ulps).
    assert!(gpu.active.iter().all(|&a| a == 0.0));
    let q = gpu
        .qx
        .iter()
        .chain(&gpu.qy)
        .fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(q < 1e-5 * gpu.lambda, "max |q| = {q:e}, λ = {}", gpu.lambda);
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config {
        cases: 8,
        failure_persistence: None,
        ..Default::default()
    })]
    /// Scaling y and α₀ by 2^k scales every iterate by 2^k exactly and leaves τ, σ unchanged.
    #[test]
    fn scaling_the_frame_and_seed_by_a_power_of_two_scales_alpha_exactly(k in -6i32..6, seed in 0u64..1000) {
        let Some(ctx) = common::context() else { return Ok(()) };
        let joint = solver(5);
        let (frame, mut alpha0) = problem(&joint);
        alpha0.data.iter_mut().zip(common::noise(W * H * J, seed)).for_each(|(v, e)| *v += 0.1 * e);
        let c = 2f32.powi(k);
        let scaled = |x: &Cube| {
            let mut y = x.clone();
            y.data.iter_mut().for_each(|v| *v *= c);
            y
        };
        let run = |y: &Cube, a0: &Cube| {
            let (g, _) = gpu_solver(&ctx, &joint, y, a0, &[1.0; BANDS]);
            submit(&ctx, |enc| g.encode(enc));
            g.stats(&ctx).unwrap();
            g.state(&ctx).unwrap()
        };
        let (one, two) = (run(&frame, &alpha0), run(&scaled(&frame), &scaled(&alpha0)));
        proptest::prop_assert_eq!((one.tau, one.sigma), (two.tau, two.sigma));
        let want: Vec<f32> = one.alpha.iter().map(|v| v * c).collect();
        proptest::prop_assert_eq!(two.alpha, want);
    }
}
