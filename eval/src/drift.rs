//! Whether the robot's LIO says when it drifts: stretches in which its pose error grows by more
//! than `grow_m` within `window_ns`, and whether any scan of the stretch was flagged (its health
//! other than `tracking`). A silent stretch is a failure the operator cannot see.

use serde::Serialize;
use starc_pipeline::lio::Health;
use std::collections::BTreeMap;

/// The odometry issue's drift: a pose whose error exceeds the smallest of the 5 s before it by
/// more than 10 cm (the robot's and the rig's alike).
pub const DRIFT_GROW_M: f64 = 0.10;
pub const DRIFT_WINDOW_NS: u64 = 5_000_000_000;

/// The per-scan error table (robot_error.csv, rig_error.csv): seconds since the first row, the
/// pose error against the truth (m, deg) and the LIO's health (empty where the run did not
/// report it), for finding where an odometry went wrong.
pub fn error_csv(rows: impl IntoIterator<Item = (u64, f64, f64, Option<Health>)>) -> String {
    let mut csv = String::from("time_s,error_m,error_deg,health\n");
    let mut first = None;
    for (t_ns, m, deg, health) in rows {
        let t_s = t_ns.saturating_sub(*first.get_or_insert(t_ns)) as f64 * 1e-9;
        csv += &format!("{t_s:.3},{m:.4},{deg:.3},{}\n", health.map_or("", Health::name));
    }
    csv
}

/// One scored robot pose: its time, its error against the truth, and the LIO's health.
#[derive(Clone, Copy, Debug)]
pub struct ScoredPose {
    pub t_ns: u64,
    pub error_m: f64,
    pub health: Health,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DriftReport {
    /// Stretches whose error grew by more than the limit within the window.
    pub stretches: usize,
    /// Of them, those in which every scan said `tracking`.
    pub silent: usize,
    /// Scans per health.
    pub scans: BTreeMap<&'static str, usize>,
}

/// The drift stretches of `poses` (in time order): a pose whose error exceeds the smallest error
/// of the poses in the `window_ns` before it by more than `grow_m` drifts, over the span from
/// that smallest one to it; drifting poses in a row make one stretch, flagged when any pose of
/// its spans was not `tracking`.
pub fn drift_stretches(poses: &[ScoredPose], window_ns: u64, grow_m: f64) -> DriftReport {
    let mut report = DriftReport::default();
    for h in Health::ALL {
        report.scans.insert(h.name(), poses.iter().filter(|p| p.health == h).count());
    }
    // The open stretch (drifting poses in a row): whether any of its spans was flagged.
    let mut open: Option<bool> = None;
    let mut from = 0usize;
    for (i, p) in poses.iter().enumerate() {
        while poses.get(from).is_some_and(|q| q.t_ns + window_ns < p.t_ns) {
            from += 1;
        }
        let span = poses.get(from..=i).unwrap_or(&[]);
        let lowest = span.iter().enumerate().min_by(|a, b| a.1.error_m.total_cmp(&b.1.error_m));
        match lowest.filter(|(_, low)| p.error_m - low.error_m > grow_m) {
            Some((k, _)) => {
                let flagged = span.iter().skip(k).any(|q| q.health != Health::Tracking);
                open = Some(open.unwrap_or(false) || flagged);
            }
            None => {
                if let Some(flagged) = open.take() {
                    close(&mut report, flagged);
                }
            }
        }
    }
    if let Some(flagged) = open {
        close(&mut report, flagged);
    }
    report
}

fn close(report: &mut DriftReport, flagged: bool) {
    report.stretches += 1;
    if !flagged {
        report.silent += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::{drift_stretches, Health, ScoredPose};

    fn poses(errors: &[(f64, Health)]) -> Vec<ScoredPose> {
        errors
            .iter()
            .enumerate()
            .map(|(i, &(error_m, health))| ScoredPose { t_ns: i as u64 * 1_000_000_000, error_m, health })
            .collect()
    }

    #[test]
    fn a_jump_is_a_stretch_silent_unless_a_scan_of_it_was_flagged() {
        use Health::{Degenerate as D, Tracking as T};
        // Steady, then 15 cm within 2 s while tracking: one silent stretch.
        let silent = poses(&[(0.01, T), (0.02, T), (0.10, T), (0.17, T), (0.17, T)]);
        let r = drift_stretches(&silent, 5_000_000_000, 0.10);
        assert_eq!((r.stretches, r.silent), (1, 1));
        // The same with a degenerate scan on the way: flagged.
        let flagged = poses(&[(0.01, T), (0.02, D), (0.10, T), (0.17, T), (0.17, T)]);
        let r = drift_stretches(&flagged, 5_000_000_000, 0.10);
        assert_eq!((r.stretches, r.silent), (1, 0));
        assert_eq!(r.scans.get("degenerate"), Some(&1));
        // Slow growth, 10 cm over 20 s: never 10 cm within 5 s.
        let slow: Vec<(f64, Health)> = (0..21).map(|i| (f64::from(i) * 0.005, T)).collect();
        assert_eq!(drift_stretches(&poses(&slow), 5_000_000_000, 0.10).stretches, 0);
        // Two jumps far apart: two stretches.
        let mut two: Vec<(f64, Health)> = vec![(0.0, T), (0.2, T)];
        two.extend((0..8).map(|_| (0.2, T)));
        two.extend([(0.4, D), (0.4, T)]);
        let r = drift_stretches(&poses(&two), 5_000_000_000, 0.10);
        assert_eq!((r.stretches, r.silent), (2, 1));
    }
}
