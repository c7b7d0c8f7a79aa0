//! Scenes: the hyperspectral cube, EXR input/output, procedural scenes, the experiment file.

pub mod cube;
pub mod exr_io;

pub use cube::Cube;
