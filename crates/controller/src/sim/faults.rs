//! Faults the simulated devices inject, each keyed to the n-th exposure of the scene (0-based),
//! so that a test or `specmux rehearse --fault KIND@N` hits the acquisition where it wants.

use crate::error::{Error, Result};
use serde::Serialize;

/// What goes wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultKind {
    /// The wheel's index sensor misses one pulse in the middle of the exposure: the DMD does not
    /// start its sequence for that turn.
    MissedIndex,
    /// The frame is lost in transport (its frame id is skipped).
    DroppedFrame,
    /// The DMD fails to start its sequence on one trigger in the middle of the exposure.
    DmdUnderrun,
    /// From that exposure on, the wheel's speed drifts by `DRIFT_PER_S` of its target per second.
    WheelDrift,
    /// From that exposure on, the camera answers nothing and delivers no frame.
    CameraStops,
    /// From that exposure on, the wheel's controller answers nothing (it keeps spinning).
    WheelStops,
}

/// Relative speed drift per second of a `WheelDrift` fault (1 %/s).
pub const DRIFT_PER_S: f64 = 0.01;

/// One fault at one exposure of the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Fault {
    pub kind: FaultKind,
    pub exposure: u64,
}

impl Fault {
    /// Parse `KIND@N`, e.g. `missed-index@3`; `key` names the argument in an error (`--fault`
    /// on the command line, `faults` in Python).
    pub fn parse(text: &str, key: &str) -> Result<Fault> {
        let bad = |why: &str| Error::refused(key, text, why);
        let (kind, n) = text
            .split_once('@')
            .ok_or_else(|| bad("expected KIND@EXPOSURE, e.g. missed-index@3"))?;
        let kind = match kind {
            "missed-index" => FaultKind::MissedIndex,
            "dropped-frame" => FaultKind::DroppedFrame,
            "dmd-underrun" => FaultKind::DmdUnderrun,
            "wheel-drift" => FaultKind::WheelDrift,
            "camera-stops" => FaultKind::CameraStops,
            "wheel-stops" => FaultKind::WheelStops,
            _ => return Err(bad("kinds: missed-index, dropped-frame, dmd-underrun, wheel-drift, camera-stops, wheel-stops")),
        };
        let exposure = n
            .parse()
            .map_err(|_| bad("the exposure must be a whole number ≥ 0"))?;
        Ok(Fault { kind, exposure })
    }
}

/// The faults of one simulated rig.
#[derive(Clone, Debug, Default)]
pub struct Faults(pub Vec<Fault>);

impl Faults {
    /// True when `kind` is planned at scene exposure `n`.
    pub fn at(&self, kind: FaultKind, n: u64) -> bool {
        self.0.iter().any(|f| f.kind == kind && f.exposure == n)
    }

    /// The first scene exposure from which a lasting fault (`kind`) holds.
    pub fn from(&self, kind: FaultKind) -> Option<u64> {
        self.0
            .iter()
            .filter(|f| f.kind == kind)
            .map(|f| f.exposure)
            .min()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_refuses_with_the_key() {
        assert_eq!(
            Fault::parse("dmd-underrun@7", "--fault").unwrap(),
            Fault {
                kind: FaultKind::DmdUnderrun,
                exposure: 7
            }
        );
        for bad in ["dmd-underrun", "melt@3", "missed-index@-1"] {
            let msg = Fault::parse(bad, "faults").unwrap_err().to_string();
            assert!(msg.contains("`faults`") && msg.contains(bad), "{msg}");
        }
    }
}
