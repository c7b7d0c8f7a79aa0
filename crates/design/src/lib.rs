//! specmux-design: the design tools of the rig — which filters go on the colour wheel, and where
//! the carriers go in the Fourier plane — scored by closed-form predictions and confirmed by
//! simulating the twin. They use the twin's library directly (rig, forward model, reconstructor).
//!
//! - `catalog` → `criteria` → `search` → `filters`: the filter set (`specmux design filters`);
//! - `layout` → `leak` → `optimise` → `carriers`: the carrier layout (`specmux design carriers`);
//! - `scenes`: the scenes a design is scored on and one simulated run; `plot`: the figures.

// `!(x > y)` is deliberate (true for NaN too, as in the core); the small dense kernels index
// by position.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod carriers;
pub mod catalog;
pub mod criteria;
pub mod filters;
pub mod layout;
pub mod leak;
pub mod optimise;
pub mod plot;
pub mod scenes;
pub mod search;
mod small;

/// `specmux design …`: the two design problems of the rig.
#[derive(clap::Subcommand)]
pub enum DesignCommand {
    /// Choose the wheel's filters from a catalogue: the paper's criterion and better predictors,
    /// searched exactly, the best sets simulated on the scenes; writes `[rig.wheel]`.
    Filters(filters::FilterArgs),
    /// Lay out the carriers on exact FFT bins, scored by scene spectra leaking into the windows
    /// and by simulation against the paper's layout and the diamond rule; writes `[rig.carriers]`.
    Carriers(carriers::CarrierArgs),
}

impl DesignCommand {
    /// Run the chosen design and return its report.
    pub fn run(&self, lib: &specmux_core::spectral::Library) -> specmux_core::Result<String> {
        match self {
            DesignCommand::Filters(a) => filters::run(a, lib),
            DesignCommand::Carriers(a) => carriers::run(a, lib),
        }
    }
}
