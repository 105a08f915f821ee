//! A device's odometry against its true path: each LIO pose (in the LIO's own frame) scored
//! against the device's truth, that frame tied to the truth's at the first pose (the absolute
//! pose error of evo's APE with that anchor instead of a fitted alignment). The robot's
//! (`robot_pose_error`, robot_error.csv) and the rig's own, before any alignment
//! (`rig_lio_error`, rig_error.csv), alike. With the LIO's health per pose, the drift test of
//! [`crate::drift`]: a stretch of error growth the health never flagged is a failure nobody sees.

use crate::drift::{drift_stretches, error_csv, ScoredPose, DRIFT_GROW_M, DRIFT_WINDOW_NS};
use crate::quantiles::quantiles;
use crate::report::RobotPoseErrorReport;
use crate::score::rmse;
use nalgebra::Isometry3;
use starc_pipeline::align::pose_error;
use starc_pipeline::lio::Health;

/// One scored pose.
#[derive(Clone, Copy, Debug)]
struct Scored {
    t_ns: u64,
    error_m: f64,
    error_deg: f64,
    /// `None` where the run does not report it (live runs).
    health: Option<Health>,
}

/// A device's LIO poses as they come, scored against the truth.
#[derive(Clone, Debug, Default)]
pub struct OdometryLog {
    /// The LIO's frame in the truth's world, fixed at the first pose.
    frame_t_world: Option<Isometry3<f64>>,
    poses: Vec<Scored>,
}

impl OdometryLog {
    /// One LIO pose `pose` (the LiDAR in the LIO's frame) at `t_ns`, against the LiDAR's true
    /// pose `truth` then; the first one ties the two frames.
    pub fn push(&mut self, t_ns: u64, pose: &Isometry3<f64>, truth: &Isometry3<f64>, health: Option<Health>) {
        let f_t_w = *self.frame_t_world.get_or_insert_with(|| pose * truth.inverse());
        let (error_m, error_deg) = pose_error(&(f_t_w * truth), pose);
        self.poses.push(Scored { t_ns, error_m, error_deg, health });
    }

    /// The LIO's frame from the truth's world, once a pose came.
    pub fn frame_t_world(&self) -> Option<Isometry3<f64>> {
        self.frame_t_world
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// What report.json says of it; `drift` only where the run reported the LIO's health.
    pub fn report(&self) -> RobotPoseErrorReport {
        let m: Vec<f64> = self.poses.iter().map(|p| p.error_m).collect();
        let deg: Vec<f64> = self.poses.iter().map(|p| p.error_deg).collect();
        RobotPoseErrorReport {
            translation_m: quantiles(&m),
            rotation_deg: quantiles(&deg),
            rmse_m: rmse(&m),
            drift: self.drift(),
        }
    }

    fn drift(&self) -> Option<crate::drift::DriftReport> {
        let scored: Vec<ScoredPose> = self
            .poses
            .iter()
            .filter_map(|p| Some(ScoredPose { t_ns: p.t_ns, error_m: p.error_m, health: p.health? }))
            .collect();
        (!scored.is_empty()).then(|| drift_stretches(&scored, DRIFT_WINDOW_NS, DRIFT_GROW_M))
    }

    /// The per-scan error table ([`error_csv`]).
    pub fn csv(&self) -> String {
        error_csv(self.poses.iter().map(|p| (p.t_ns, p.error_m, p.error_deg, p.health)))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn at(x: f64) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::new(x, 0.0, 1.6), UnitQuaternion::identity())
    }

    #[test]
    fn an_odometry_frame_of_its_own_is_tied_at_the_first_pose() {
        // The rig's odometry starts at its own origin, turned: a perfect odometry scores 0.
        let frame =
            Isometry3::from_parts(Translation3::new(-3.0, 2.0, 0.0), UnitQuaternion::from_euler_angles(0.0, 0.0, 1.0));
        let mut log = OdometryLog::default();
        for k in 0..20u64 {
            let truth = at(k as f64 * 0.1);
            log.push(k * 100_000_000, &(frame * truth), &truth, Some(Health::Tracking));
        }
        let r = log.report();
        assert!(r.rmse_m < 1e-9, "{}", r.rmse_m);
        assert_eq!(r.drift.as_ref().map(|d| d.stretches), Some(0));
        assert_eq!(log.csv().lines().count(), 21);
    }

    /// 2 s still, then the odometry slides 30 cm over 1 s while the rig stands; `flag` is the
    /// health of one scan of the slide.
    fn sliding(flag: Health) -> OdometryLog {
        let mut log = OdometryLog::default();
        for k in 0..40u64 {
            let slide = if k < 20 { 0.0 } else { ((k - 20) as f64 * 0.03).min(0.3) };
            let health = if k == 25 { flag } else { Health::Tracking };
            log.push(k * 100_000_000, &at(slide), &at(0.0), Some(health));
        }
        log
    }

    #[test]
    fn a_silent_slide_is_found_and_a_flagged_one_is_not_silent() {
        let d = sliding(Health::Tracking).report().drift.unwrap();
        assert_eq!((d.stretches, d.silent), (1, 1));
        let d = sliding(Health::ImuOnly).report().drift.unwrap();
        assert_eq!((d.stretches, d.silent), (1, 0));
        assert!(OdometryLog::default().is_empty());
        // A run that does not report the health (live) has no drift test.
        let mut live = OdometryLog::default();
        live.push(0, &at(0.0), &at(0.0), None);
        assert!(live.report().drift.is_none());
    }
}
