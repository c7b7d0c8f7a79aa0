//! specmux-io: the file formats specmux reads and writes — EXR cubes and frames, PNG images,
//! NumPy arrays, JSON reports, camera and calibration frames a user brings — each file written
//! atomically (a temporary beside it, then a rename); and TOML settings files read with errors
//! that name the line, the key and the value.

pub mod atomic;
pub mod exr;
pub mod frame;
pub mod json;
pub mod npy;
pub mod output_set;
pub mod png;
pub mod toml_file;
