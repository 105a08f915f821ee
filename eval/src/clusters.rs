//! Training data for the learned cluster scorer (`[detect] kind = "trees"`, docs/detect.md):
//! every cluster the geometric detector would judge in a detection window (surveyed: nothing
//! detected, every cluster too big for one person split as well), with the scorer's input vector
//! and what the simulator's truth says it is. Made from the mission's own windows (the robot's
//! LIO, its world frame, its floor and ceiling), so the scorer learns what it will be shown.

use starc_pipeline::detect::eval::TruthPerson;
use starc_pipeline::detect::trees::INPUTS;
use starc_pipeline::detect::{DetectConfig, DetectWindow, Detector, DetectorKind, GeometricDetector};
use std::collections::HashMap;

/// Columns after the inputs: posture of the person with the most points in the cluster
/// (0 none, 1 standing, 2 sitting or crouching, 3 lying), the share of the cluster's points on
/// them, the share of their window points in the cluster, their returns, the distance from the
/// cluster's centre to theirs over the floor (m; 1e6 without a person), the window index, the
/// cluster centre (x, y in the world) and the hand-set gates' score.
pub const EXTRA_COLUMNS: usize = 9;
pub const COLUMNS: usize = INPUTS + EXTRA_COLUMNS;
const NO_PERSON_M: f32 = 1e6;

/// One window's people as the table needs them: the label, box, returns and posture column.
pub struct LabelledPerson<'a> {
    pub truth: &'a TruthPerson,
    /// 1 standing, 2 sitting or crouching, 3 lying.
    pub posture: u8,
}

/// The survey detector, with the hand-set gates (so that their score can be compared).
pub fn surveyor() -> Result<GeometricDetector, starc_pipeline::PipelineError> {
    let mut d = GeometricDetector::new(DetectConfig { kind: DetectorKind::Geometric, ..DetectConfig::default() })?;
    d.survey(true);
    Ok(d)
}

/// Appends a row per cluster of `window` to `rows`; `labels` holds each window point's person
/// label (0: none).
pub fn survey_window(
    det: &mut GeometricDetector,
    window: &DetectWindow<'_>,
    labels: &[u16],
    people: &[LabelledPerson<'_>],
    window_index: usize,
    rows: &mut Vec<f32>,
) {
    let mut found = Vec::new();
    det.detect(window, &mut found);
    let clusters = det.last_clusters().iter().zip(det.last_cluster_points()).zip(det.last_inputs());
    for (((f, score), idx), x) in clusters {
        rows.extend(x);
        rows.extend(truth_columns(idx, labels, people, [f.centre.x, f.centre.y]));
        rows.extend([window_index as f32, f.centre.x as f32, f.centre.y as f32, *score as f32]);
    }
}

/// Posture, share on the person, share of the person, returns and distance (see the module).
fn truth_columns(idx: &[u32], labels: &[u16], people: &[LabelledPerson<'_>], centre: [f64; 2]) -> [f32; 5] {
    let mut counts: HashMap<u16, usize> = HashMap::new();
    for l in idx.iter().filter_map(|&i| labels.get(i as usize)).filter(|&&l| l != 0) {
        *counts.entry(*l).or_default() += 1;
    }
    // Ties go to the lower label, so that the table does not depend on the map's order.
    let best = counts.iter().max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)));
    let Some((&label, &on)) = best else { return [0.0, 0.0, 0.0, 0.0, NO_PERSON_M] };
    let Some(person) = people.iter().find(|p| p.truth.label == label) else {
        return [0.0, 0.0, 0.0, 0.0, NO_PERSON_M];
    };
    let total = labels.iter().filter(|&&l| l == label).count().max(1);
    let c = person.truth.centre_m;
    let apart = (c.x - centre[0]).hypot(c.y - centre[1]);
    [
        f32::from(person.posture),
        on as f32 / idx.len().max(1) as f32,
        on as f32 / total as f32,
        person.truth.returns as f32,
        apart as f32,
    ]
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use nalgebra::Vector3;
    use starc_pipeline::detect::WindowPoint;
    use starc_time::{Clock, Stamp};

    /// A floor, and a 1.7 m column of points (a person, label 7) 4 m ahead.
    fn window_points() -> (Vec<WindowPoint>, Vec<u16>) {
        let (mut pts, mut labels) = (Vec::new(), Vec::new());
        for i in 0..60 {
            for j in 0..60 {
                pts.push(WindowPoint { x_m: 1.0 + i as f32 * 0.1, y_m: -3.0 + j as f32 * 0.1, z_m: 0.0, t_ns: 1 });
                labels.push(0);
            }
        }
        for k in 0..400 {
            let a = k as f32 * 0.7;
            let z = 0.1 + (k % 80) as f32 * 0.02;
            pts.push(WindowPoint { x_m: 4.0 + 0.15 * a.cos(), y_m: 0.2 * a.sin(), z_m: z, t_ns: 1 });
            labels.push(7);
        }
        (pts, labels)
    }

    #[test]
    fn a_person_column_is_one_row_labelled_standing() {
        let (pts, labels) = window_points();
        let truth = TruthPerson {
            label: 7,
            centre_m: Vector3::new(4.0, 0.0, 0.85),
            size_m: Vector3::new(0.4, 0.3, 1.7),
            yaw_rad: 0.0,
            returns: 400,
        };
        let people = [LabelledPerson { truth: &truth, posture: 1 }];
        let sensor = nalgebra::Isometry3::translation(0.0, 0.0, 0.45);
        let window = DetectWindow { stamp: Stamp::new(1, Clock::Ptp), sensor_pose: sensor, points: &pts };
        let mut rows = Vec::new();
        survey_window(&mut surveyor().unwrap(), &window, &labels, &people, 3, &mut rows);
        assert_eq!(rows.len() % COLUMNS, 0);
        let person: Vec<&[f32]> = rows.chunks_exact(COLUMNS).filter(|r| r[INPUTS] == 1.0).collect();
        assert_eq!(person.len(), 1, "one cluster on the person");
        let r = person[0];
        assert!(r[INPUTS + 1] > 0.99 && r[INPUTS + 2] > 0.9, "share on {} of {}", r[INPUTS + 1], r[INPUTS + 2]);
        assert_eq!(r[INPUTS + 3], 400.0);
        assert!(r[INPUTS + 4] < 0.1, "apart {}", r[INPUTS + 4]);
        assert_eq!(r[INPUTS + 5], 3.0);
    }
}
