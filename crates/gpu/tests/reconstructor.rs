//! The GPU reconstruction (demultiplex, GAP or GAP-TV, crosstalk mix, exact unmixing) against
//! the CPU's `Reconstructor::run` on frames the twin simulates: the cube's PSNR against the
//! true cube must agree within 0.01 dB (issue 17's end-to-end bound) and the cubes closely.
//! Experiments: the prototype's `fourier` chain on dead-leaves (most pixels need the exact QP)
//! and on shaded objects; its default GAP on dead-leaves; GAP-TV on shaded objects; and GAP
//! with the exposure timing and the EMVA sensor (dark/flat correction on the host, crosstalk
//! mix on the GPU after GAP); the joint method (seed α₀ = H⁻¹Fᵀx̂, 40 iterations) on
//! dead-leaves, with the timing's crosstalk in its channel patterns.
//!
//! Against the CPU's run: the channels after de-aliasing within 2e-5 NRMSE (the demultiplexing
//! bound of tests/demux.rs; GAP's iterations keep to it, tests/gap.rs), the cube within 1e-4
//! (the unmixing's f32 solve, tests/unmix.rs). Seen on lavapipe: channels ≤ 4.6e-6 (GAP-TV;
//! ≤ 1.1e-7 otherwise), cube ≤ 9.1e-6 (GAP-TV; ≤ 8.7e-8 otherwise), PSNR equal to 4 decimals.
//! The joint method's channels Fα and objective within 1e-4 (tests/joint.rs's bound for whole
//! runs: the iterations are non-expansive, so rounding adds up over them).

mod common;

use specmux_core::metrics;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::spectral::Library;
use specmux_gpu::GpuReconstructor;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::{Pipeline, Simulated};
use specmux_twin::rig::Rig;
use specmux_twin::run;
use specmux_twin::scene::Materials;

fn check(toml: &str) {
    check_within(toml, 2e-5);
}

/// The twin's frame of the experiment `toml` and the CPU reconstructor of its rig.
fn simulated(toml: &str) -> (Simulated, Reconstructor) {
    let exp = Experiment::from_toml(toml, "test.toml").unwrap();
    let lib = Library::default_root();
    let materials = Materials::load(&lib).unwrap();
    let rig = Rig::build(&exp, &lib, &materials).unwrap();
    let (sim, _) = Pipeline::build(&exp, &rig, &materials)
        .unwrap()
        .run()
        .unwrap();
    let recon = run::reconstructor(&exp, &rig, &sim, None).unwrap();
    (sim, recon)
}

/// `check` with the channels after de-aliasing within `channels` NRMSE of the CPU's.
fn check_within(toml: &str, channels: f64) {
    let Some(ctx) = common::context() else { return };
    let (sim, recon) = simulated(toml);
    let cpu = recon.run(&sim.frame, None).unwrap();
    let gpu_recon = GpuReconstructor::new(&ctx, &recon).unwrap();
    let mut gpu = gpu_recon.output_cube();
    // Twice through the same buffers: the second frame's answer is the one checked.
    gpu_recon.run_into(&ctx, &sim.frame, &mut gpu).unwrap();
    let run = gpu_recon.run_into(&ctx, &sim.frame, &mut gpu).unwrap();
    let truth = &sim.scene.cube;
    let (p_cpu, p_gpu) = (
        metrics::compare(truth, &cpu.cube).unwrap().psnr_db,
        metrics::compare(truth, &gpu).unwrap().psnr_db,
    );
    eprintln!(
        "PSNR CPU {p_cpu:.4} dB, GPU {p_gpu:.4} dB; CPU {:?}; GPU {:?}",
        cpu.unmix, run.unmix
    );
    assert!(
        (p_cpu - p_gpu).abs() < 0.01,
        "PSNR {p_cpu} (CPU) against {p_gpu} (GPU)"
    );
    let m = metrics::compare(&cpu.cube, &gpu).unwrap();
    eprintln!(
        "GPU against CPU cube: {:.1} dB, NRMSE {:.2e}",
        m.psnr_db, m.nrmse
    );
    assert!(
        m.nrmse < 1e-4,
        "GPU cube against CPU cube: NRMSE {:.2e}",
        m.nrmse
    );
    assert_eq!(run.gap.iterations, cpu.gap.iterations);
    assert_eq!(run.gap.residual_rms.len(), cpu.gap.residual_rms.len());
    assert_eq!(run.joint.is_some(), cpu.joint.is_some());
    if let (Some(g), Some(c)) = (&run.joint, &cpu.joint) {
        let (gl, cl) = (g.objective.last().unwrap(), c.objective.last().unwrap());
        eprintln!(
            "joint: objective GPU {gl:.6e}, CPU {cl:.6e}; violation {:.3e} and {:.3e}",
            g.violation, c.violation
        );
        assert_eq!(g.objective.len(), c.objective.len());
        assert!(((gl - cl) / cl).abs() < 1e-4, "objective {gl} against {cl}");
        let (gr, cr) = (g.residual_ratio, c.residual_ratio);
        eprintln!(
            "residual ratio GPU {gr:.6e}, CPU {cr:.6e}; noise weights {}; saturated pixels {} and {}",
            c.noise_weights, g.saturated_pixels, c.saturated_pixels
        );
        assert!(
            ((gr - cr) / cr).abs() < 1e-3,
            "residual ratio {gr} against {cr}"
        );
        assert_eq!(
            (g.noise_weights, g.saturated_pixels),
            (c.noise_weights, c.saturated_pixels)
        );
        assert_eq!(g.discrepancy.is_some(), c.discrepancy.is_some());
        if let (Some(gs), Some(cs)) = (&g.discrepancy, &c.discrepancy) {
            eprintln!("λ searched: GPU {:?}, CPU {:?}", gs.trials, cs.trials);
            assert_eq!(gs.trials.len(), cs.trials.len());
            assert!(((gs.lambda - cs.lambda) / cs.lambda).abs() < 1e-3);
        }
    }
    let gx = gpu_recon.demultiplex(&ctx, &sim.frame).unwrap();
    assert!(metrics::compare(&cpu.xhat, &gx).unwrap().nrmse < 2e-5);
    let (gg, _) = gpu_recon.dealias(&ctx, &sim.frame).unwrap();
    let e = metrics::compare(&cpu.xgap, &gg).unwrap().nrmse;
    eprintln!("channels after de-aliasing: NRMSE {e:.2e}");
    assert!(e < channels, "channels after de-aliasing: {e:.2e}");
}

const FOURIER: &str = "[reconstruct.gap]\nmethod = \"fourier\"\n";

#[test]
fn fourier_prototype_dead_leaves() {
    check(&format!("[scene]\nsize = [192, 192]\n{FOURIER}"));
}

#[test]
fn fourier_prototype_shaded_objects() {
    check(&format!(
        "[scene]\nsource = \"shaded-objects\"\nseed = 11\nsize = [160, 128]\n{FOURIER}"
    ));
}

#[test]
fn gap_prototype_dead_leaves() {
    check("[scene]\nsize = [192, 192]\n");
}

#[test]
fn gap_tv_shaded_objects() {
    check(
        "[scene]\nsource = \"shaded-objects\"\nseed = 11\nsize = [160, 128]\n[reconstruct.gap]\nmethod = \"gap-tv\"\n"
    );
}

#[test]
fn gap_with_timing_and_sensor() {
    check("[scene]\nsize = [128, 128]\n[rig.timing]\n[rig.sensor]\n");
}

#[test]
fn joint_dead_leaves_with_timing() {
    check_within(
        "[scene]\nsize = [64, 64]\n[rig.timing]\n[reconstruct.gap]\nmethod = \"joint\"\n[reconstruct.joint]\niterations = 40\n",
        1e-4,
    );
}

/// Noise weights with saturated pixels (an overexposed camera: their data term one-sided),
/// as on the CPU; the CPU's run must see some saturated pixels and not all.
#[test]
fn joint_with_noise_weights_and_saturated_pixels() {
    let toml = "[scene]\nsize = [64, 64]\n[rig.timing]\n[rig.sensor]\nelectrons_at_full_scale = 60000\n[reconstruct.gap]\nmethod = \"joint\"\n[reconstruct.joint]\niterations = 40\nnoise_weights = true\n";
    let (sim, recon) = simulated(toml);
    let stats = recon.run(&sim.frame, None).unwrap().joint.unwrap();
    let n = 64 * 64;
    assert!(stats.noise_weights, "{stats:?}");
    assert!(
        stats.saturated_pixels > n / 100 && stats.saturated_pixels < n / 2,
        "{} of {n} saturated",
        stats.saturated_pixels
    );
    check_within(toml, 1e-4);
}

/// λ by the discrepancy principle on the camera's noise weights: the search's trials on the
/// GPU, a submission and a read-back each, as on the CPU.
#[test]
fn joint_with_the_discrepancy_rule() {
    check_within(
        "[scene]\nsize = [64, 64]\n[rig.sensor]\n[reconstruct.gap]\nmethod = \"joint\"\n[reconstruct.joint]\niterations = 20\nsearch_iterations = 10\nnoise_weights = true\nweight_rule = \"discrepancy\"\n",
        1e-4,
    );
}

/// A frame of almost no light (10⁻⁶ e⁻ at full scale: dark noise alone) with noise weights and
/// the discrepancy rule: finite on both devices, and the same.
#[test]
fn joint_on_a_dark_frame_with_the_discrepancy_rule() {
    check_within(
        "[scene]\nsize = [48, 48]\n[rig.sensor]\nelectrons_at_full_scale = 1e-6\n[reconstruct.gap]\nmethod = \"joint\"\n[reconstruct.joint]\niterations = 10\nsearch_iterations = 5\nnoise_weights = true\nweight_rule = \"discrepancy\"\n",
        1e-4,
    );
}

/// The plug-and-play prior, which runs on the CPU only, is refused by name, not run
/// differently.
#[test]
fn the_plug_and_play_prior_is_refused_naming_the_key() {
    let Some(ctx) = common::context() else { return };
    let toml = "[scene]\nsize = [32, 32]\n[rig.sensor]\n[reconstruct.gap]\nmethod = \"joint\"\n[reconstruct.joint]\niterations = 2\nprior = \"pnp\"\n";
    let (_, recon) = simulated(toml);
    let e = GpuReconstructor::new(&ctx, &recon)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("reconstruct.joint.prior") && e.contains("CPU only"),
        "{e}"
    );
}
