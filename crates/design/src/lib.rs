//! specmux-design: the design tools of the rig — which filters go on the colour wheel, and where
//! the carriers go in the Fourier plane — scored by closed-form predictions and confirmed by
//! simulating the twin. They use the twin's library directly (rig, forward model, reconstructor).
//!
//! - `catalog` → `criteria` → `search` → `filters`: the filter set (`specmux design filters`);
//! - `layout` → `leak` → `optimise` → `carriers`: the carrier layout (`specmux design carriers`);
//! - `scenes`: the scenes a design is scored on and one simulated run; `plot`: the figures.

pub mod carriers;
pub mod catalog;
pub mod criteria;
pub mod layout;
pub mod leak;
pub mod optimise;
pub mod filters;
pub mod plot;
pub mod progress;
pub mod scenes;
pub mod search;
mod small;
