//! The monochrome camera sums the modulated images: y = Σ_k z_k ⊙ s̃_k. Used by the forward
//! model for the scene's frame and by the calibration captures for the white target's.

use crate::device::OpenDevice;
use rayon::prelude::*;
use specmux_core::{Cube, Result};

/// y = Σ_k z_k ⊙ s̃_k, in parallel over pixel chunks.
pub fn multiplex(z: &Cube, s: &Cube) -> Result<Cube> {
    z.check_same_shape(s, "channels against patterns")?;
    let mut y = Cube::zeros(z.width, z.height, 1);
    y.data
        .par_chunks_mut(4096)
        .enumerate()
        .for_each(|(c, out)| {
            let off = c * 4096;
            for k in 0..z.planes {
                let (zs, ss) = (
                    &z.plane(k)[off..off + out.len()],
                    &s.plane(k)[off..off + out.len()],
                );
                for ((o, a), b) in out.iter_mut().zip(zs).zip(ss) {
                    *o += a * b;
                }
            }
        });
    Ok(y)
}

/// The forward model's multiplex on some device: y = Σ_k z_k ⊙ s̃_k. `CpuMultiplex` and,
/// behind the `gpu` feature, `GpuMultiplexer` implement it; `[compute] device` picks one
/// (`device::OpenDevice`, `for_device`), and the same tests check both.
pub trait Multiplexer: Send + Sync {
    /// y of the images z (one per pattern) against the patterns s̃ (the same shape).
    fn multiplex(&self, z: &Cube, s: &Cube) -> Result<Cube>;
    /// "cpu" or "gpu".
    fn device(&self) -> &'static str;
}

/// `multiplex` on the CPU.
pub struct CpuMultiplex;

impl Multiplexer for CpuMultiplex {
    fn multiplex(&self, z: &Cube, s: &Cube) -> Result<Cube> {
        multiplex(z, s)
    }
    fn device(&self) -> &'static str {
        "cpu"
    }
}

/// specmux-gpu's multiplex kernel for one size of images: per call one upload of z and s̃,
/// one kernel, one read-back of y.
#[cfg(feature = "gpu")]
pub struct GpuMultiplexer {
    ctx: specmux_gpu::GpuContext,
    kernel: specmux_gpu::multiplex::GpuMultiplex,
}

#[cfg(feature = "gpu")]
impl GpuMultiplexer {
    /// The kernel for `planes` images of w × h on `ctx`.
    pub fn new(
        ctx: &specmux_gpu::GpuContext,
        shape: (usize, usize, usize),
    ) -> Result<GpuMultiplexer> {
        Ok(GpuMultiplexer {
            ctx: ctx.clone(),
            kernel: specmux_gpu::multiplex::GpuMultiplex::new(ctx, shape)?,
        })
    }
}

#[cfg(feature = "gpu")]
impl Multiplexer for GpuMultiplexer {
    fn multiplex(&self, z: &Cube, s: &Cube) -> Result<Cube> {
        z.check_same_shape(s, "channels against patterns")?;
        Ok(self.kernel.run(&self.ctx, z, s)?)
    }
    fn device(&self) -> &'static str {
        "gpu"
    }
}

/// The multiplexer on `device` for `planes` images of w × h.
pub fn for_device(
    device: &OpenDevice,
    shape: (usize, usize, usize),
) -> Result<Box<dyn Multiplexer>> {
    #[cfg(feature = "gpu")]
    if let Some(ctx) = device.gpu() {
        return Ok(Box::new(GpuMultiplexer::new(ctx, shape)?));
    }
    let _ = (device, shape);
    Ok(Box::new(CpuMultiplex))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};

    /// z = [1 2 | 3 4], s̃ = [5 6 | 7 8] (two planes of 2 × 1): y = [1·5 + 3·7, 2·6 + 4·8];
    /// a third plane of z is a shape error.
    fn hand_case(m: &dyn Multiplexer) {
        let z = Cube::from_vec(2, 1, 2, vec![1.0, 2.0, 3.0, 4.0]).unwrap();
        let s = Cube::from_vec(2, 1, 2, vec![5.0, 6.0, 7.0, 8.0]).unwrap();
        assert_eq!(m.multiplex(&z, &s).unwrap().data, [26.0, 44.0]);
        let e = m
            .multiplex(&Cube::zeros(2, 1, 3), &s)
            .unwrap_err()
            .to_string();
        assert!(e.contains("channels against patterns"), "{e}");
    }

    #[test]
    fn the_cpu_multiplex_sums_the_modulated_images() {
        hand_case(&CpuMultiplex);
        let cpu = OpenDevice::open(specmux_core::reconstructor::ComputeDevice::Cpu).unwrap();
        let m = for_device(&cpu, (2, 1, 2)).unwrap();
        assert_eq!(m.device(), "cpu");
        hand_case(m.as_ref());
    }

    proptest! {
        /// y is linear in z: y(a·z₁ + z₂) = a·y(z₁) + y(z₂) up to f32 rounding of K products.
        #[test]
        fn the_multiplex_is_linear(seed in 0u64..1000, a in -3.0f32..3.0) {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
            let mut cube = |k| Cube::from_vec(5, 3, k, (0..15 * k).map(|_| rng.gen_range(-1.0..1.0)).collect()).unwrap();
            let (s, z1, z2) = (cube(4), cube(4), cube(4));
            let mut z = z1.clone();
            z.data.iter_mut().zip(&z2.data).for_each(|(v, w)| *v = a * *v + w);
            let y = |z: &Cube| CpuMultiplex.multiplex(z, &s).unwrap();
            let (y, y1, y2) = (y(&z), y(&z1), y(&z2));
            for ((v, v1), v2) in y.data.iter().zip(&y1.data).zip(&y2.data) {
                prop_assert!((v - (a * v1 + v2)).abs() <= 1e-5 * (1.0 + a.abs()) * 4.0);
            }
        }
    }

    /// The GPU's multiplex (lavapipe counts; skipped without an adapter) against the CPU's: the
    /// hand case exactly, and random frames within 1e-6 relative L2 (the same K products summed
    /// in the same order; a GPU may fuse them into FMAs, ≤ K ulps).
    #[cfg(feature = "gpu")]
    #[test]
    fn the_gpu_multiplex_matches_the_cpu() {
        let Some(ctx) = crate::forward::gpu_tests::context() else {
            return;
        };
        hand_case(&GpuMultiplexer::new(&ctx, (2, 1, 2)).unwrap());
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        for (w, h, k) in [(64, 48, 6), (31, 17, 3), (300, 2, 8)] {
            let mut cube = || {
                let data = (0..w * h * k).map(|_| rng.gen_range(-1.0..1.0)).collect();
                Cube::from_vec(w, h, k, data).unwrap()
            };
            let (s, z) = (cube(), cube());
            let cpu = CpuMultiplex.multiplex(&z, &s).unwrap();
            let gpu = GpuMultiplexer::new(&ctx, (w, h, k)).unwrap();
            let gpu = gpu.multiplex(&z, &s).unwrap();
            let (num, den) = cpu
                .data
                .iter()
                .zip(&gpu.data)
                .fold((0.0, 0.0), |(n, d), (c, g)| {
                    (n + ((c - g) as f64).powi(2), d + (*c as f64).powi(2))
                });
            let e = (num / den).sqrt();
            eprintln!("multiplex {w}×{h}×{k}: GPU against CPU, relative L2 {e:.2e}");
            assert!(e < 1e-6, "{w}×{h}×{k}: {e:.2e}");
        }
    }

    /// `[compute] device = "gpu"` runs the forward model's multiplex on the GPU (the stage says
    /// so) and gives the CPU's frame within the kernel's bound (48 × 40, exposure timing).
    #[cfg(feature = "gpu")]
    #[test]
    fn the_forward_model_on_the_gpu_gives_the_cpus_frame() {
        use crate::forward::gpu_tests::run;
        let Some((cpu, explain)) = run("[rig.timing]\n", "cpu") else {
            return;
        };
        assert!(explain.contains("on the CPU"), "{explain}");
        let (gpu, explain) = run("[rig.timing]\n", "gpu").unwrap();
        assert!(explain.contains("on the GPU"), "{explain}");
        let e = specmux_core::metrics::compare(&cpu, &gpu).unwrap().nrmse;
        eprintln!("forward model frame, GPU multiplex against CPU: NRMSE {e:.2e}");
        assert!(e < 1e-6, "{e:.2e}");
    }
}
