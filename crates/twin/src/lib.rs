//! specmux-twin: the digital twin of the rig. Modules follow the light path: scene → colour
//! wheel and optics (DMD, 4f relay, lens) → exposure timing → sensor; the experiment file
//! composes their configurations, the rig resolves it, the forward pipeline runs the stages,
//! and the captures simulate the calibration frames a real rig would record.

pub mod auto_table;
pub mod budget;
pub mod captures;
pub mod device;
pub mod experiment;
pub mod forward;
pub mod multiplex;
pub mod optics;
pub mod pattern_cache;
pub mod rig;
pub mod run;
pub mod scene;
pub mod sensor;
pub mod timing;

pub use experiment::Experiment;
pub use rig::Rig;
