//! The see-through mission's two sides, sans-IO, shared by the offline run (`starc mission`),
//! the live nodes (`starc robot`, `starc fpv`) and the simulated mission (`starc sim`):
//!
//! - [`RobotCore`]: the robot's LIO, person detection and the map it shares;
//! - [`RigCore`]: the rig's LIO, its alignment to the robot's map and its world pose;
//! - [`Overlay`]: the robot's detections as the rig holds and ages them;
//! - [`render_view`]: the responder's frame at a time, from the three;
//! - [`RigSide`]: everything the rig does between its inputs and its frames (core, map, overlay,
//!   render), which the rig node, the offline run and the rerun all drive;
//! - [`OfflineMission`]: both sides in one process, in time order.

mod input;
mod offline;
mod overlay;
mod person_motion;
mod place;
mod recent_voxels;
mod rig;
mod rig_history;
mod rig_side;
mod robot;
mod robot_map;
mod sent_people;
mod waiting;

pub use input::{MissionInput, Side};
pub use offline::{MissionEvent, OfflineMission};
pub use overlay::Overlay;
pub use place::ScanPlacer;
pub use rig::{AlignInputs, AlignJob, AlignOutcome, AlignVerdict, RigCore, RigCoreConfig, CONFIRM_FIRST_S};
pub use rig_side::{
    DetectionTake, RefusedDetections, RigSide, RigSideConfig, HOLD_NS, MAX_DETECTION_AGE_NS, MAX_DETECTION_LEAD_NS,
};
pub use robot::{RobotCore, RobotCoreConfig, RobotDetection, RobotStep, FLOOR_GRID_RAY_STRIDE};
pub use robot_map::{MapScan, RobotMap, RobotMapConfig};
pub use sent_people::{people_to_draw, people_to_send};
pub use waiting::Waiting;

use crate::ar::{self, ArFrame, ArPerson, ArStatus, CameraModel, RenderConfig};
use nalgebra::Isometry3;

/// One rendered view and what went into it.
pub struct View {
    pub frame: ArFrame,
    pub aligned: bool,
    /// The camera in the robot's world (in the rig's odometry frame until aligned).
    pub world_t_camera: Isometry3<f64>,
    pub people: Vec<ArPerson>,
    /// Age of the newest detection shown.
    pub detection_age_ms: Option<f64>,
}

/// When a frame is drawn, on the rig LiDAR's clock: the scene's time (the rig's pose and the
/// people held then) and now by the wall clock, from which the people's ages are shown, so an
/// age keeps growing on screen while nothing new arrives. Offline runs have no wall clock of
/// their own and pass the scene's time for both ([`FrameTime::at`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameTime {
    pub scene_ns: u64,
    pub now_ns: u64,
}

impl FrameTime {
    /// A frame whose ages are measured at the scene's own time.
    pub fn at(scene_ns: u64) -> Self {
        Self { scene_ns, now_ns: scene_ns }
    }
}

/// The people the overlay holds at the scene's time, aged to now.
fn people_at(overlay: &Overlay, time: FrameTime) -> Vec<ArPerson> {
    let since_scene_ns = time.now_ns.saturating_sub(time.scene_ns);
    let mut people = overlay.at(time.scene_ns);
    for p in &mut people {
        p.age_ns = p.age_ns.saturating_add(since_scene_ns);
    }
    people
}

/// The responder's frame at `time` (rig LiDAR clock): the rig's points of the last seconds
/// shaded by depth and, once aligned, the people the robot saw, through the walls.
pub fn render_view(
    camera: &CameraModel,
    lidar_t_camera: &Isometry3<f64>,
    rig: &RigCore,
    overlay: &Overlay,
    time: FrameTime,
    link: &str,
    cfg: &RenderConfig,
) -> View {
    let t_ns = time.scene_ns;
    // Past the rig's newest pose (a detection newer than the rig's last scan) the pose holds.
    let pose_ns = rig.last().map_or(t_ns, |(last_ns, _)| t_ns.min(last_ns));
    let rig_pose = rig.world().world_pose(pose_ns).ok().flatten();
    let aligned = rig_pose.is_some();
    let odom_pose = rig.world().odometry().at(pose_ns).ok();
    let world_t_camera = rig_pose.or(odom_pose).unwrap_or_else(Isometry3::identity) * lidar_t_camera;
    // The rig's own points live in its odometry frame: into the world with the correction.
    let correction = rig.world().correction().unwrap_or_else(Isometry3::identity);
    let people = if aligned { people_at(overlay, time) } else { Vec::new() };
    let detection_age_ms = people.iter().map(|p| p.age_ns).min().map(|a| a as f64 * 1e-6);
    let status = ArStatus {
        aligned,
        detection_age_ms,
        link: link.to_string(),
        text: if aligned { String::new() } else { rig.waiting().to_string() },
    };
    let frame = ar::render_in(camera, &world_t_camera, rig.view_points(), &correction, &people, &status, cfg);
    View { frame, aligned, world_t_camera, people, detection_age_ms }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ar::OrientedBox;
    use nalgebra::Vector3;

    #[test]
    fn ages_run_on_the_wall_clock_while_the_scene_stands_still() {
        let bbox =
            OrientedBox { centre_m: Vector3::new(3.0, 0.0, 0.9), size_m: Vector3::new(0.5, 0.4, 1.8), yaw_rad: 0.0 };
        let person = ArPerson { points_world: vec![bbox.centre_m], bbox: Some(bbox), age_ns: 0, pose: None };
        let mut overlay = Overlay::new(HOLD_NS);
        overlay.push(1_000_000_000, vec![person.clone()]);
        overlay.push(1_100_000_000, vec![person]);
        let ages = |time| people_at(&overlay, time).iter().map(|p| p.age_ns).collect::<Vec<_>>();
        // Offline: the age is the scene's.
        assert_eq!(ages(FrameTime::at(1_150_000_000)), vec![50_000_000]);
        // Live, nothing new for 0.7 s: the same scene, 0.7 s older on screen.
        assert_eq!(ages(FrameTime { scene_ns: 1_150_000_000, now_ns: 1_850_000_000 }), vec![750_000_000]);
        // A wall clock behind the scene (a clock offset's jitter) never makes anyone younger.
        assert_eq!(ages(FrameTime { scene_ns: 1_150_000_000, now_ns: 1_000_000_000 }), vec![50_000_000]);
    }
}
