//! specmux-report: what a person reads — tables, plots and studies (work–precision, crop and
//! key sweeps, pattern report, photon transfer, timeline) — and one function per CLI command
//! that runs the library and returns the text to print.

pub mod bench;
pub mod commands;
pub mod panel;
pub mod patterns;
pub mod plot;
pub mod progress;
pub mod ptc;
pub mod sweep;
pub mod timeline;
