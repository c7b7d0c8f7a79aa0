//! specmux-io: the file formats specmux reads and writes — EXR cubes and frames, PNG images,
//! JSON reports — each file written atomically (a temporary beside it, then a rename).

pub mod atomic;
pub mod exr;
pub mod json;
pub mod output_set;
pub mod png;
