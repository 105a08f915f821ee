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
pub mod recent_voxels;
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
pub use robot::{RobotCore, RobotCoreConfig, RobotDetection, RobotStep};
pub use robot_map::{MapScan, RobotMap, RobotMapConfig};
pub use sent_people::{people_to_draw, people_to_send};
pub use waiting::Waiting;

use crate::ar::{self, ArFrame, ArPerson, ArStatus, CameraModel, RenderConfig};
use nalgebra::{Isometry3, Vector3};

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

/// The responder's frame at `t_ns` (rig LiDAR clock): the rig's points of the last seconds
/// shaded by depth and, once aligned, the people the robot saw, through the walls.
pub fn render_view(
    camera: &CameraModel,
    lidar_t_camera: &Isometry3<f64>,
    rig: &RigCore,
    overlay: &Overlay,
    t_ns: u64,
    link: &str,
    cfg: &RenderConfig,
) -> View {
    // Past the rig's newest pose (a detection newer than the rig's last scan) the pose holds.
    let pose_ns = rig.last().map_or(t_ns, |(last_ns, _)| t_ns.min(last_ns));
    let rig_pose = rig.world().world_pose(pose_ns).ok().flatten();
    let aligned = rig_pose.is_some();
    let odom_pose = rig.world().odometry().at(pose_ns).ok();
    let world_t_camera = rig_pose.or(odom_pose).unwrap_or_else(Isometry3::identity) * lidar_t_camera;
    // The rig's own points live in its odometry frame: into the world with the correction.
    let correction = rig.world().correction().unwrap_or_else(Isometry3::identity);
    let rig_points: Vec<Vector3<f64>> =
        rig.view_points().map(|p| correction * nalgebra::Point3::from(*p)).map(|p| p.coords).collect();
    let people = if aligned { overlay.at(t_ns) } else { Vec::new() };
    let detection_age_ms = people.iter().map(|p| p.age_ns).min().map(|a| a as f64 * 1e-6);
    let status = ArStatus {
        aligned,
        detection_age_ms,
        link: link.to_string(),
        text: if aligned { String::new() } else { rig.waiting().to_string() },
    };
    let frame = ar::render(camera, &world_t_camera, &rig_points, &people, &status, cfg);
    View { frame, aligned, world_t_camera, people, detection_age_ms }
}
