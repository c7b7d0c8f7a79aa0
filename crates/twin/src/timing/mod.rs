//! Timing: the coupling of the spinning colour wheel, the DMD's pattern sequence and the camera's
//! exposure. It yields the weights w_ik (light through filter i while pattern k is shown, during
//! one exposure) of the forward model y = Σ_i Σ_k w_ik x_i ⊙ s̃_k, the demixing matrix that
//! reconstruction applies, and a timeline plot for the rig operator. See docs/timing.md.

mod config;
mod schedule;
mod weights;

pub use config::{CameraTiming, DmdTiming, TimingConfig, WheelTiming};
pub use schedule::{disk_fraction_past, Schedule, WheelState};
pub use weights::{weights, TimingWeights};

#[cfg(test)]
mod tests;
