//! Average precision of the robot's detections per posture, in bird's-eye view at IoU 0.3 and
//! 0.5, computed as OpenPCDet reports it for KITTI (interpolated precision at 40 recall points),
//! so that our figures sit beside published pedestrian ones.
//!
//! Per window and class, detections are taken best score first, each matched to the unmatched
//! true box of its class it overlaps most (at least the threshold). A match to a visible person
//! (at least `min_returns` returns) is a true positive, a match to one barely seen is left out
//! (neither demanded nor wrong, as KITTI's "don't care"), and no match is a false positive.
//! Classes are the postures both detectors tell apart: upright (standing), low (sitting or
//! crouching) and lying.

use crate::truth::TruePose;
use serde::Serialize;
use starc_pipeline::detect::eval::TruthPerson;
use starc_pipeline::detect::pillars::decode::{bev_iou, ModelBox};
use starc_pipeline::detect::{Detection, PersonPose};
use std::collections::BTreeMap;

/// The IoU thresholds reported.
pub const THRESHOLDS: [f64; 2] = [0.3, 0.5];
const RECALL_POINTS: usize = 40;

/// What one detection turned out to be at one threshold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Outcome {
    True,
    False,
    LeftOut,
}

#[derive(Default)]
struct ClassTally {
    /// (score, outcome at each threshold).
    scored: Vec<(f64, [Outcome; 2])>,
    positives: usize,
}

/// The posture classes, by name.
pub fn class_of_pose(p: PersonPose) -> &'static str {
    match p {
        PersonPose::Upright => "upright",
        PersonPose::Low => "low",
        PersonPose::Lying => "lying",
    }
}

pub fn class_of_truth(p: TruePose) -> &'static str {
    match p {
        TruePose::Standing => "upright",
        TruePose::Sitting | TruePose::Crouching => "low",
        TruePose::Lying => "lying",
    }
}

fn bev(centre: [f64; 3], size: [f64; 3], yaw_rad: f64) -> ModelBox {
    ModelBox { centre_m: centre, size_m: size, yaw_rad, score: 0.0, class: 0 }
}

/// Detections and truth over many windows.
#[derive(Default)]
pub struct ApTally {
    classes: BTreeMap<&'static str, ClassTally>,
}

/// AP of one class, in [0, 1], at each threshold.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct ClassAp {
    pub iou_0_3: f64,
    pub iou_0_5: f64,
    pub visible: usize,
    pub detections: usize,
}

impl ApTally {
    /// One window: its detections, and its true people with their postures.
    pub fn window(&mut self, found: &[Detection], truth: &[(TruthPerson, TruePose)], min_returns: usize) {
        for (_, pose) in truth.iter().filter(|(t, _)| t.returns >= min_returns) {
            self.classes.entry(class_of_truth(*pose)).or_default().positives += 1;
        }
        let boxes: Vec<(ModelBox, &'static str, bool)> = truth
            .iter()
            .map(|(t, pose)| {
                let b = bev(t.centre_m.into(), t.size_m.into(), t.yaw_rad);
                (b, class_of_truth(*pose), t.returns >= min_returns)
            })
            .collect();
        let mut order: Vec<&Detection> = found.iter().collect();
        order.sort_by(|a, b| b.score.total_cmp(&a.score));
        let mut taken = [vec![false; boxes.len()], vec![false; boxes.len()]];
        for d in order {
            let class = class_of_pose(d.pose);
            let db = bev(d.centre_m.into(), d.size_m.into(), d.yaw_rad);
            let mut outcome = [Outcome::False; 2];
            for (k, threshold) in THRESHOLDS.iter().enumerate() {
                let best = boxes
                    .iter()
                    .enumerate()
                    .filter(|(i, (_, c, _))| *c == class && !taken[k][*i])
                    .map(|(i, (b, _, visible))| (i, bev_iou(b, &db), *visible))
                    .filter(|(_, iou, _)| iou >= threshold)
                    .max_by(|a, b| a.1.total_cmp(&b.1));
                if let Some((i, _, visible)) = best {
                    taken[k][i] = true;
                    outcome[k] = if visible { Outcome::True } else { Outcome::LeftOut };
                }
            }
            self.classes.entry(class).or_default().scored.push((d.score, outcome));
        }
    }

    /// AP per class.
    pub fn report(&self) -> BTreeMap<&'static str, ClassAp> {
        self.classes
            .iter()
            .map(|(&name, t)| {
                let ap = |k: usize| average_precision(&t.scored, k, t.positives);
                (name, ClassAp { iou_0_3: ap(0), iou_0_5: ap(1), visible: t.positives, detections: t.scored.len() })
            })
            .collect()
    }
}

/// Interpolated precision at recall 1/40, 2/40, ..., 1, averaged (0 without positives).
fn average_precision(scored: &[(f64, [Outcome; 2])], k: usize, positives: usize) -> f64 {
    if positives == 0 {
        return 0.0;
    }
    let mut sorted: Vec<(f64, Outcome)> =
        scored.iter().map(|(s, o)| (*s, o[k])).filter(|(_, o)| *o != Outcome::LeftOut).collect();
    sorted.sort_by(|a, b| b.0.total_cmp(&a.0));
    let (mut tp, mut fp) = (0usize, 0usize);
    let mut curve: Vec<(f64, f64)> = Vec::with_capacity(sorted.len());
    for (_, o) in &sorted {
        if *o == Outcome::True {
            tp += 1;
        } else {
            fp += 1;
        }
        curve.push((tp as f64 / positives as f64, tp as f64 / (tp + fp) as f64));
    }
    (1..=RECALL_POINTS)
        .map(|i| {
            let r = i as f64 / RECALL_POINTS as f64;
            curve.iter().filter(|(recall, _)| *recall >= r - 1e-12).map(|(_, p)| *p).fold(0.0, f64::max)
        })
        .sum::<f64>()
        / RECALL_POINTS as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use starc_time::{Clock, Stamp};

    fn person(label: u16, x: f64, returns: usize) -> TruthPerson {
        TruthPerson {
            label,
            centre_m: Vector3::new(x, 0.0, 0.9),
            size_m: Vector3::new(0.5, 0.5, 1.8),
            yaw_rad: 0.0,
            returns,
        }
    }

    fn found(x: f64, score: f64, pose: PersonPose) -> Detection {
        Detection {
            stamp: Stamp::new(0, Clock::Ptp),
            centre_m: Vector3::new(x, 0.0, 0.9),
            size_m: Vector3::new(0.5, 0.5, 1.8),
            yaw_rad: 0.0,
            score,
            pose,
            point_indices: Vec::new(),
        }
    }

    #[test]
    fn a_perfect_detector_scores_one_and_a_false_positive_ranked_first_costs() {
        let truth = [(person(1, 2.0, 100), TruePose::Standing), (person(2, 5.0, 100), TruePose::Standing)];
        let mut t = ApTally::default();
        t.window(&[found(2.0, 0.9, PersonPose::Upright), found(5.05, 0.8, PersonPose::Upright)], &truth, 30);
        assert_eq!(t.report()["upright"].iou_0_5, 1.0);
        let mut t = ApTally::default();
        t.window(
            &[
                found(9.0, 0.95, PersonPose::Upright),
                found(2.0, 0.9, PersonPose::Upright),
                found(5.0, 0.8, PersonPose::Upright),
            ],
            &truth,
            30,
        );
        // Precision 1/2 up to recall 1/2, 2/3 after: interpolated, 2/3 everywhere.
        assert!((t.report()["upright"].iou_0_3 - 2.0 / 3.0).abs() < 1e-9);
    }

    #[test]
    fn a_barely_seen_person_is_neither_demanded_nor_a_false_positive() {
        let truth = [(person(1, 2.0, 5), TruePose::Lying), (person(2, 5.0, 100), TruePose::Lying)];
        let mut t = ApTally::default();
        t.window(&[found(2.0, 0.9, PersonPose::Lying), found(5.0, 0.5, PersonPose::Lying)], &truth, 30);
        let r = t.report()["lying"];
        assert_eq!((r.iou_0_5, r.visible), (1.0, 1));
        // A box shifted by more than half its side misses at 0.5 but not at 0.3.
        let mut t = ApTally::default();
        t.window(&[found(5.2, 0.9, PersonPose::Lying)], &truth, 30);
        let r = t.report()["lying"];
        assert_eq!((r.iou_0_3, r.iou_0_5), (1.0, 0.0));
    }
}
