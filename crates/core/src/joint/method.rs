//! `Joint::run`: the configured method from a seed — TV with λ fixed or chosen by the
//! discrepancy principle (`discrepancy`), or plug-and-play (`pnp`). Here, not in `joint.rs`, so
//! that the file of the iteration imports neither of the two, which import it.

use super::{discrepancy, pnp, Joint, JointStats, Prior, Stages, WeightRule};
use crate::error::{Error, Result};
use crate::noise::DataWeights;
use crate::Cube;
use std::time::Instant;

impl Joint {
    /// Run the configured method from `seed` with data weights ω and saturated pixels (None:
    /// ω = 1, none): TV with λ fixed or by the discrepancy principle, or plug-and-play.
    pub fn run(
        &self,
        frame: &Cube,
        seed: &Cube,
        weights: Option<&DataWeights>,
    ) -> Result<(Cube, JointStats)> {
        if self.cfg.prior == Prior::Pnp {
            return pnp::run(self, frame, seed, weights);
        }
        let t0 = Instant::now();
        let mut st = self.start(frame, seed, weights)?;
        let search = match self.cfg.weight_rule {
            WeightRule::Fixed => None,
            WeightRule::Discrepancy if weights.is_none() => {
                return Err(Error::Numerical(
                    "joint: the discrepancy principle needs the noise weights ω of a camera noise model".into(),
                ))
            }
            WeightRule::Discrepancy => Some(discrepancy::choose(self, &mut st)?),
        };
        let stages = Stages {
            reweights: self.cfg.rounds(),
            rebalance: self.cfg.rebalance,
        };
        let objective = self.iterate(&mut st, self.cfg.iterations, stages)?;
        let mut stats = self.finish(&st, objective, t0, weights.is_some())?;
        stats.discrepancy = search;
        Ok((st.alpha_cube(), stats))
    }
}
