//! How fast each person the robot finds is walking, from the centres of their recent detections:
//! a walker's lower legs, smeared over a stride by the scan, are left out of what is drawn.

use nalgebra::{Vector2, Vector3};
use std::collections::VecDeque;

/// A detection this close (m, floor plane) to a person's previous one is theirs, plus what a
/// brisk walk covers in the time between them.
const SAME_PERSON_M: f64 = 0.3;
const WALK_MPS: f64 = 1.5;

/// A person at least this fast is walking (a standing person's detected centre wanders by a few
/// centimetres from window to window, well under this).
pub const WALKING_MPS: f64 = 0.3;

/// The centres of every detection of the last `span_ns`, window by window.
#[derive(Debug, Default)]
pub struct PersonMotion {
    span_ns: u64,
    min_baseline_ns: u64,
    windows: VecDeque<(u64, Vec<Vector3<f64>>)>,
}

impl PersonMotion {
    /// Velocities are fitted over the last `span_ns`, and only over at least `min_baseline_ns`.
    pub fn new(span_ns: u64, min_baseline_ns: u64) -> Self {
        Self { span_ns, min_baseline_ns, windows: VecDeque::new() }
    }

    /// The floor-plane velocity (m/s) of the person detected at `centre` at `stamp_ns`, fitted
    /// by least squares to their earlier detections of the last `span_ns` (followed back window
    /// by window); zero when they were not seen over the baseline.
    pub fn velocity(&self, stamp_ns: u64, centre: &Vector3<f64>) -> Vector2<f64> {
        let mut track = vec![(0.0, centre.xy())];
        let mut last = (stamp_ns, centre.xy());
        for (t_ns, centres) in self.windows.iter().rev() {
            if *t_ns >= stamp_ns {
                continue;
            }
            if t_ns.saturating_add(self.span_ns) < stamp_ns {
                break;
            }
            if let Some(c) = next_sighting(last, *t_ns, centres.iter().copied()) {
                last = (*t_ns, c);
                track.push((-((stamp_ns - t_ns) as f64) * 1e-9, c));
            }
        }
        let baseline_s = -track.last().map_or(0.0, |(t, _)| *t);
        if track.len() < 3 || baseline_s < self.min_baseline_ns as f64 * 1e-9 {
            return Vector2::zeros();
        }
        let n = track.len() as f64;
        let mean_t = track.iter().map(|(t, _)| t).sum::<f64>() / n;
        let mean_c = track.iter().map(|(_, c)| c).sum::<Vector2<f64>>() / n;
        let var_t: f64 = track.iter().map(|(t, _)| (t - mean_t).powi(2)).sum();
        let cov: Vector2<f64> = track.iter().map(|(t, c)| (c - mean_c) * (t - mean_t)).sum();
        if var_t > 0.0 {
            cov / var_t
        } else {
            Vector2::zeros()
        }
    }

    /// Records a window's detections (after [`Self::velocity`] was asked for them).
    pub fn push(&mut self, stamp_ns: u64, centres: Vec<Vector3<f64>>) {
        self.windows.push_back((stamp_ns, centres));
        while self.windows.front().is_some_and(|(t, _)| t.saturating_add(self.span_ns) < stamp_ns) {
            self.windows.pop_front();
        }
    }
}

/// Of the centres of a detection window at `t_ns`, the one of the person last seen at `last`
/// (stamp, centre), if any: the nearest within a step plus a brisk walk over the time between.
pub(super) fn next_sighting(
    last: (u64, Vector2<f64>),
    t_ns: u64,
    centres: impl Iterator<Item = Vector3<f64>>,
) -> Option<Vector2<f64>> {
    let reach = SAME_PERSON_M + WALK_MPS * last.0.abs_diff(t_ns) as f64 * 1e-9;
    centres
        .map(|c| c.xy())
        .min_by(|a, b| (a - last.1).norm().total_cmp(&(b - last.1).norm()))
        .filter(|c| (c - last.1).norm() <= reach)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_walker_has_their_velocity_and_a_standing_person_none() {
        let mut m = PersonMotion::new(500 * MS, 200 * MS);
        let walker = |t_ms: u64| Vector3::new(1.0 + 0.8 * t_ms as f64 * 1e-3, 2.0, 1.0);
        let still = Vector3::new(5.0, -1.0, 1.0);
        for t in (0..=1000).step_by(100) {
            let jitter = if (t / 100) % 2 == 0 { 0.02 } else { -0.02 };
            let w = walker(t) + Vector3::new(0.0, jitter, 0.0);
            if t >= 600 {
                let v = m.velocity(t * MS, &w);
                assert!((v - Vector2::new(0.8, 0.0)).norm() < 0.1, "{v}");
                assert!(m.velocity(t * MS, &still).norm() < 1e-9);
            }
            m.push(t * MS, vec![w, still]);
        }
        // Someone seen only now, or for less than the baseline, is not known to move.
        assert_eq!(m.velocity(1100 * MS, &Vector3::new(-5.0, 0.0, 1.0)), Vector2::zeros());
        let mut short = PersonMotion::new(500 * MS, 200 * MS);
        short.push(0, vec![walker(0)]);
        assert_eq!(short.velocity(100 * MS, &walker(100)), Vector2::zeros());
    }

    #[test]
    fn a_window_from_before_the_span_or_after_the_stamp_is_not_used() {
        let mut m = PersonMotion::new(500 * MS, 200 * MS);
        m.push(0, vec![Vector3::new(0.0, 0.0, 0.0)]);
        m.push(700 * MS, vec![Vector3::new(0.5, 0.0, 0.0)]);
        m.push(800 * MS, vec![Vector3::new(0.6, 0.0, 0.0)]);
        // 0 ms is older than the span: the fit is the last three sightings' 1 m/s alone.
        let v = m.velocity(900 * MS, &Vector3::new(0.7, 0.0, 0.0));
        assert!((v - Vector2::new(1.0, 0.0)).norm() < 1e-9, "{v}");
        // A replayed older window sees nothing newer than itself.
        assert_eq!(m.velocity(750 * MS, &Vector3::new(0.55, 0.0, 0.0)), Vector2::zeros());
    }
}
