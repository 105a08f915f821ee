//! Both sides of a mission in one process, in time order, sans-IO: the robot's core and the
//! rig's side, with what the link would carry between them handed over directly (detections
//! through the same conversion as the link; the robot's map whole, when a registration is due).
//! `starc mission`, `starc eval` and the rerun of recordings drive it; alignment jobs run
//! inline, so a run is the same every time.

use super::sent_people::{people_to_draw, people_to_send};
use super::{AlignVerdict, MissionInput, RigSide, RobotCore, RobotDetection, RobotStep, Side};
use crate::lio::ScanOutput;
use nalgebra::Isometry3;

/// What one input made happen, in order.
pub enum MissionEvent {
    /// A robot LIO pose; `lio_ms` is its compute time.
    RobotPose { end_ns: u64, pose: Isometry3<f64>, lio_ms: f64, health: crate::lio::Health },
    /// A robot detection window (already on its way to the rig).
    Detection(Box<RobotDetection>),
    /// The rig's first LIO pose.
    RigStarted { first_ns: u64 },
    /// A rig LIO pose with its health, and its world pose if the rig is placed.
    RigPose { end_ns: u64, odom: Isometry3<f64>, world: Option<Isometry3<f64>>, health: crate::lio::Health },
    /// A registration ran (`world_t_lidar` is identity and `total_ms` NaN when it failed to run).
    Alignment { end_ns: u64, world_t_lidar: Isometry3<f64>, total_ms: f64, verdict: AlignVerdict },
}

pub struct OfflineMission {
    robot: RobotCore,
    rig: RigSide,
    robot_steps: Vec<RobotStep>,
    rig_outs: Vec<ScanOutput>,
    robot_last_ns: Option<u64>,
    use_coverage: bool,
}

impl OfflineMission {
    pub fn new(robot: RobotCore, rig: RigSide) -> Self {
        Self { robot, rig, robot_steps: Vec::new(), rig_outs: Vec::new(), robot_last_ns: None, use_coverage: true }
    }

    /// Whether the rig's acceptance judges the overlap with the robot's coverage (on by
    /// default) or the inlier ratio over its whole window (to measure what coverage brings).
    pub fn with_coverage(mut self, on: bool) -> Self {
        self.use_coverage = on;
        self
    }

    /// Feeds one input; what it gave goes to `events`. Alignment waits for [`Self::align`], so
    /// the caller can act on [`MissionEvent::RigStarted`] first.
    pub fn push(&mut self, input: MissionInput, events: &mut Vec<MissionEvent>) {
        match input {
            MissionInput::Imu(Side::Robot, s) => self.robot.push_imu(s, &mut self.robot_steps),
            MissionInput::Imu(Side::Rig, s) => self.rig.push_imu(s, &mut self.rig_outs),
            MissionInput::Scan(Side::Robot, s) => self.robot.push_scan(s, &mut self.robot_steps),
            MissionInput::Scan(Side::Rig, s) => self.rig.push_scan(s, &mut self.rig_outs),
            MissionInput::Wheel(Side::Robot, w) => self.robot.push_wheel(w),
            // A handheld or helmet rig has no wheels.
            MissionInput::Wheel(Side::Rig, _) => {}
        }
        for step in self.robot_steps.drain(..) {
            let o = &step.output;
            self.robot_last_ns = Some(o.end_ns);
            self.rig.push_robot_pose(&o.lidar_pose);
            events.push(MissionEvent::RobotPose {
                end_ns: o.end_ns,
                pose: o.lidar_pose,
                lio_ms: o.elapsed_us as f64 * 1e-3,
                health: o.health,
            });
            if let Some(det) = step.detection {
                self.rig.push_detections(det.stamp_ns, people_to_draw(&people_to_send(&det)));
                events.push(MissionEvent::Detection(Box::new(det)));
            }
        }
        for o in self.rig_outs.drain(..) {
            if self.rig.core().first_ns() == Some(o.end_ns) {
                events.push(MissionEvent::RigStarted { first_ns: o.end_ns });
            }
            let world = self.rig.core().world().world_pose(o.end_ns).ok().flatten();
            events.push(MissionEvent::RigPose { end_ns: o.end_ns, odom: o.lidar_pose, world, health: o.health });
        }
    }

    /// Runs the registration that is due, if any, against the robot's map as it stands.
    pub fn align(&mut self) -> Option<MissionEvent> {
        if self.rig.wants_map() && self.robot.map_len() != self.rig.core().map_len() {
            let (points, towards_sensor) = self.robot.map_points_seen_from();
            self.rig.set_map_points_seen_from(points, towards_sensor);
            if self.use_coverage {
                self.rig.set_coverage(self.robot.map_coverage());
            }
        }
        let job = self.rig.next_job()?;
        let end_ns = job.end_ns;
        let outcome = job.run();
        let (world_t_lidar, total_ms) =
            outcome.as_ref().map_or((Isometry3::identity(), f64::NAN), |o| (o.world_t_lidar, o.report.total_ms));
        let verdict = self.rig.apply(outcome);
        Some(MissionEvent::Alignment { end_ns, world_t_lidar, total_ms, verdict })
    }

    /// Both devices have passed this time: a frame up to it sees all they will say about it.
    pub fn horizon_ns(&self) -> Option<u64> {
        let rig = self.rig.core().last().map(|(t, _)| t)?;
        Some(self.robot_last_ns?.min(rig))
    }

    pub fn robot(&self) -> &RobotCore {
        &self.robot
    }

    /// The robot's core, for a scorer's look at its map (flushing the map changes nothing the
    /// mission computes: scans are added in the same order whenever it happens).
    pub fn robot_mut(&mut self) -> &mut RobotCore {
        &mut self.robot
    }

    pub fn rig(&self) -> &RigSide {
        &self.rig
    }

    pub fn rig_mut(&mut self) -> &mut RigSide {
        &mut self.rig
    }
}
