//! The learned scorer of the geometric detector's clusters (`[detect] kind = "trees"`):
//! gradient-boosted trees over a cluster's features and shape profile, trained on development
//! buildings by scripts/train/cluster_trees.py, in place of the hand-set posture gates.

pub mod inputs;
pub mod model;
mod shape;

pub use inputs::{inputs, INPUTS};
pub use model::{TreeModel, CLASSES};

use super::{ClusterFeatures, PersonPose, TreesConfig};
use crate::detect::pillars::weights::Weights;
use crate::PipelineError;

const BUILT_IN: &[u8] = include_bytes!("../../../../config/models/cluster_trees.stpw");

/// The trees `cfg.model` names, or the built-in ones.
pub fn load(cfg: &TreesConfig) -> Result<TreeModel, PipelineError> {
    let bytes = match &cfg.model {
        Some(path) => std::fs::read(path).map_err(|e| PipelineError::io(format!("reading {}", path.display()), e))?,
        None => BUILT_IN.to_vec(),
    };
    TreeModel::from_weights(&Weights::parse(&bytes)?)
}

/// Clusters longer or wider than this are not shown to the trees (nor is their face share, the
/// costliest feature, measured): on the validation buildings the trees took none of the 5,484
/// such clusters for a person, and they hold most of a window's points.
const MAX_LENGTH_M: f64 = 3.0;
const MAX_WIDTH_M: f64 = 1.5;

/// Whether the trees judge a cluster of this size at all (the detector calls one that is not no
/// person without scoring it).
pub fn worth_scoring(f: &ClusterFeatures) -> bool {
    f.size.x <= MAX_LENGTH_M && f.size.y <= MAX_WIDTH_M
}

/// The likeliest posture of a cluster and its probability of being a person at all, from its
/// input vector.
pub fn score(model: &TreeModel, x: &[f32; INPUTS]) -> (PersonPose, f64) {
    let p = model.predict(x);
    let postures = [(PersonPose::Upright, p[1]), (PersonPose::Low, p[2]), (PersonPose::Lying, p[3])];
    let best = postures.iter().copied().fold((PersonPose::Upright, f32::MIN), |a, b| if b.1 > a.1 { b } else { a });
    (best.0, f64::from(1.0 - p[0]))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_built_in_trees_load() {
        let m = load(&TreesConfig::default()).unwrap();
        let p = m.predict(&[0.0; INPUTS]);
        assert!((p.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }
}
