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
pub mod progress;
pub mod scenes;
pub mod search;
mod small;
