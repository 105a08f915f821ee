//! The rig's own odometry against its true path: each LIO pose of the rig (in its odometry
//! frame, before any alignment) scored against `gt_fpv.tum`, the odometry frame tied to the
//! truth's at the rig's first pose, as the robot's is ([`crate::score::Scorer::robot_pose`]).
//! With the LIO's health per pose, the same drift test as the robot's ([`crate::drift`]): a
//! stretch of error growth the health never flagged is a failure the responder cannot see.

use crate::drift::{drift_stretches, error_csv, ScoredPose, DRIFT_GROW_M, DRIFT_WINDOW_NS};
use crate::quantiles::quantiles;
use crate::report::RobotPoseErrorReport;
use crate::score::rmse;
use nalgebra::Isometry3;
use starc_pipeline::align::pose_error;
use starc_pipeline::lio::Health;

/// One scored rig pose.
#[derive(Clone, Copy, Debug)]
struct Scored {
    t_ns: u64,
    error_m: f64,
    error_deg: f64,
    health: Health,
}

/// The rig's LIO poses as they come, scored against the truth.
#[derive(Clone, Debug, Default)]
pub struct RigLioLog {
    /// The rig's odometry frame in the truth's world, fixed at its first pose.
    odom_t_world: Option<Isometry3<f64>>,
    poses: Vec<Scored>,
}

impl RigLioLog {
    /// One rig LIO pose `odom` (the LiDAR in the rig's odometry frame) at `t_ns`, against the
    /// rig LiDAR's true pose `truth` then.
    pub fn push(&mut self, t_ns: u64, odom: &Isometry3<f64>, truth: &Isometry3<f64>, health: Health) {
        let o_t_w = *self.odom_t_world.get_or_insert_with(|| odom * truth.inverse());
        let (error_m, error_deg) = pose_error(&(o_t_w * truth), odom);
        self.poses.push(Scored { t_ns, error_m, error_deg, health });
    }

    /// What report.json says of it (`rig_lio_error`); `None` before any pose.
    pub fn report(&self) -> Option<RobotPoseErrorReport> {
        if self.poses.is_empty() {
            return None;
        }
        let m: Vec<f64> = self.poses.iter().map(|p| p.error_m).collect();
        let deg: Vec<f64> = self.poses.iter().map(|p| p.error_deg).collect();
        let scored: Vec<ScoredPose> =
            self.poses.iter().map(|p| ScoredPose { t_ns: p.t_ns, error_m: p.error_m, health: p.health }).collect();
        Some(RobotPoseErrorReport {
            translation_m: quantiles(&m),
            rotation_deg: quantiles(&deg),
            rmse_m: rmse(&m),
            drift: Some(drift_stretches(&scored, DRIFT_WINDOW_NS, DRIFT_GROW_M)),
        })
    }

    /// rig_error.csv: per rig scan, as robot_error.csv ([`error_csv`]).
    pub fn csv(&self) -> String {
        error_csv(self.poses.iter().map(|p| (p.t_ns, p.error_m, p.error_deg, Some(p.health))))
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
        let mut log = RigLioLog::default();
        for k in 0..20u64 {
            let truth = at(k as f64 * 0.1);
            log.push(k * 100_000_000, &(frame * truth), &truth, Health::Tracking);
        }
        let r = log.report().unwrap();
        assert!(r.rmse_m < 1e-9, "{}", r.rmse_m);
        assert_eq!(r.drift.as_ref().map(|d| d.stretches), Some(0));
        assert_eq!(log.csv().lines().count(), 21);
    }

    /// 2 s still, then the odometry slides 30 cm over 1 s while the rig stands; `flag` is the
    /// health of one scan of the slide.
    fn sliding(flag: Health) -> RigLioLog {
        let mut log = RigLioLog::default();
        for k in 0..40u64 {
            let slide = if k < 20 { 0.0 } else { ((k - 20) as f64 * 0.03).min(0.3) };
            let health = if k == 25 { flag } else { Health::Tracking };
            log.push(k * 100_000_000, &at(slide), &at(0.0), health);
        }
        log
    }

    #[test]
    fn a_silent_slide_is_found_and_a_flagged_one_is_not_silent() {
        let d = sliding(Health::Tracking).report().unwrap().drift.unwrap();
        assert_eq!((d.stretches, d.silent), (1, 1));
        let d = sliding(Health::ImuOnly).report().unwrap().drift.unwrap();
        assert_eq!((d.stretches, d.silent), (1, 0));
        assert!(RigLioLog::default().report().is_none());
    }
}
