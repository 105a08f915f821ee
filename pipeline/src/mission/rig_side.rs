//! The rig's whole side of a mission between its inputs and its frames, sans-IO: the rig core
//! (LIO, alignment, world pose), the robot's map as it arrives, the robot's detections held and
//! aged, and the AR frame. The rig node drives it from its sockets (running alignment jobs on a
//! worker thread), the offline run and the rerun of recordings drive it in time order (running
//! them inline): one implementation, so the three cannot drift apart.

use super::{render_view, AlignJob, AlignOutcome, AlignVerdict, FrameTime, Overlay, RigCore, RigCoreConfig, View};
use crate::align::TileMap;
use crate::ar::inset::MapInset;
use crate::ar::{ArPerson, CameraModel, RenderConfig};
use crate::lio::{ImuSample, LioScan, ScanOutput};
use crate::PipelineError;
use nalgebra::{Isometry3, Vector3};

/// Detections stay on screen this long after the robot last saw them.
pub const HOLD_NS: u64 = 1_000_000_000;
/// A detection stamped further than this past the rig's newest scan is refused: a forged stamp
/// or a robot clock step would otherwise hold the frame's time there, and every real person
/// after it would be drawn at the wrong time or not at all.
pub const MAX_DETECTION_LEAD_NS: u64 = 5_000_000_000;

/// A detection stamped more than this before the rig's newest scan is refused: a robot clock
/// stepped back (or a replayed message) would otherwise fill the overlay with people it never
/// draws, and the count tells the operator the clocks disagree.
pub const MAX_DETECTION_AGE_NS: u64 = 5_000_000_000;

/// Detections the rig side refused, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RefusedDetections {
    /// Before the rig had a scan: no clock of its own to judge them by.
    pub before_first_scan: u64,
    /// Stamped more than [`MAX_DETECTION_LEAD_NS`] past the rig's newest scan.
    pub from_the_future: u64,
    /// Stamped more than [`MAX_DETECTION_AGE_NS`] before it.
    pub from_the_past: u64,
}

/// The rig side's settings.
#[derive(Clone, Debug)]
pub struct RigSideConfig {
    pub core: RigCoreConfig,
    pub camera: CameraModel,
    /// The camera's pose on the rig, in the LiDAR's frame.
    pub lidar_t_camera: Isometry3<f64>,
    pub render: RenderConfig,
    pub hold_ns: u64,
}

/// Where the robot's map comes from.
enum MapFeed {
    /// Tiles from the link, applied as they come; taken into the core when a job is due.
    Tiles { tiles: TileMap, changed: bool },
    /// The whole map handed over in one piece (an offline run holds the robot's core).
    Points,
}

pub struct RigSide {
    core: RigCore,
    overlay: Overlay,
    map: MapFeed,
    camera: CameraModel,
    lidar_t_camera: Isometry3<f64>,
    render: RenderConfig,
    inset: MapInset,
    newest_detection_ns: u64,
    refused: RefusedDetections,
}

/// What became of a detection handed to [`RigSide::push_detections`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DetectionTake {
    Held,
    RefusedBeforeFirstScan,
    RefusedFromTheFuture,
    RefusedFromThePast,
}

impl RigSide {
    pub fn new(cfg: RigSideConfig) -> Result<Self, PipelineError> {
        cfg.camera.validate()?;
        Ok(Self {
            core: RigCore::new(cfg.core)?,
            overlay: Overlay::new(cfg.hold_ns),
            map: MapFeed::Tiles { tiles: TileMap::default(), changed: false },
            camera: cfg.camera,
            lidar_t_camera: cfg.lidar_t_camera,
            render: cfg.render,
            inset: MapInset::default(),
            newest_detection_ns: 0,
            refused: RefusedDetections::default(),
        })
    }

    pub fn push_imu(&mut self, sample: ImuSample, out: &mut Vec<ScanOutput>) {
        self.core.push_imu(sample, out);
    }

    pub fn push_scan(&mut self, scan: LioScan, out: &mut Vec<ScanOutput>) {
        self.core.push_scan(scan, out);
    }

    /// A map tile from the robot; whether it changed the map. A damaged tile changes nothing.
    pub fn push_tile(&mut self, bytes: &[u8]) -> Result<bool, PipelineError> {
        let MapFeed::Tiles { tiles, changed } = &mut self.map else { return Ok(false) };
        let now = tiles.apply(bytes)?;
        *changed |= now;
        Ok(now)
    }

    /// The robot's whole map (one point per voxel, in its world), replacing any before; from
    /// then on tiles are ignored.
    pub fn set_map_points(&mut self, points: Vec<Vector3<f64>>) {
        self.set_map_points_seen_from(points, Vec::new());
    }

    /// [`Self::set_map_points`] with the direction from each point towards the robot's sensor
    /// that saw it (see [`RigCore::set_map_seen_from`]).
    pub fn set_map_points_seen_from(&mut self, points: Vec<Vector3<f64>>, towards_sensor: Vec<Vector3<f64>>) {
        self.map = MapFeed::Points;
        self.core.set_map_seen_from(points, towards_sensor);
    }

    /// The space the robot's rays crossed (see [`RigCore::set_coverage`]).
    pub fn set_coverage(&mut self, coverage: std::sync::Arc<crate::align::Coverage>) {
        self.core.set_coverage(coverage);
    }

    /// Map tiles held (0 when the map came whole).
    pub fn tile_count(&self) -> usize {
        match &self.map {
            MapFeed::Tiles { tiles, .. } => tiles.tile_count(),
            MapFeed::Points => 0,
        }
    }

    /// The robot's detection at `stamp_ns`, already on the rig's LiDAR clock; held unless its
    /// time makes no sense against the rig's own scans (then counted, see [`Self::refused`]).
    pub fn push_detections(&mut self, stamp_ns: u64, people: Vec<ArPerson>) -> DetectionTake {
        let Some((rig_ns, _)) = self.core.last() else {
            self.refused.before_first_scan += 1;
            return DetectionTake::RefusedBeforeFirstScan;
        };
        if stamp_ns > rig_ns.saturating_add(MAX_DETECTION_LEAD_NS) {
            self.refused.from_the_future += 1;
            return DetectionTake::RefusedFromTheFuture;
        }
        if stamp_ns.saturating_add(MAX_DETECTION_AGE_NS) < rig_ns {
            self.refused.from_the_past += 1;
            return DetectionTake::RefusedFromThePast;
        }
        self.newest_detection_ns = self.newest_detection_ns.max(stamp_ns);
        self.overlay.push(stamp_ns, people);
        DetectionTake::Held
    }

    /// The robot's newest pose (its LiDAR in its world), for the view's inset.
    pub fn push_robot_pose(&mut self, world_t_lidar: &Isometry3<f64>) {
        self.inset.set_robot_pose(world_t_lidar);
    }

    /// Detections refused so far.
    pub fn refused(&self) -> RefusedDetections {
        self.refused
    }

    /// The newest detection's time on the rig's LiDAR clock (0 before any).
    pub fn newest_detection_ns(&self) -> u64 {
        self.newest_detection_ns
    }

    /// Whether a registration is due and the map should be handed over first (offline: then
    /// call [`Self::set_map_points`] if the robot's map grew).
    pub fn wants_map(&self) -> bool {
        self.core.wants_map()
    }

    /// The next registration when one is due, against the newest map; the people the robot
    /// sees at the rig's newest scan are left out of its window.
    pub fn next_job(&mut self) -> Option<AlignJob> {
        if let MapFeed::Tiles { tiles, changed } = &mut self.map {
            if *changed && self.core.wants_map() {
                let (points, towards_sensor) = tiles.points_seen_from();
                self.core.set_map_seen_from(points, towards_sensor);
                if let Some(coverage) = tiles.coverage() {
                    self.core.set_coverage(std::sync::Arc::new(coverage));
                }
                *changed = false;
            }
        }
        let now_ns = self.core.last().map_or(0, |(t, _)| t);
        let overlay = &self.overlay;
        self.core.next_job(|| overlay.boxes_at(now_ns))
    }

    pub fn apply(&mut self, outcome: Result<AlignOutcome, PipelineError>) -> AlignVerdict {
        self.core.apply(outcome)
    }

    /// The responder's frame at `time` (rig LiDAR clock). `next_frame` moves the world pose's
    /// bounded correction one frame on (each displayed frame of new data does, once).
    pub fn render(&mut self, time: FrameTime, link: &str, next_frame: bool) -> View {
        if next_frame {
            self.core.world_mut().step_frame();
        }
        let mut view =
            render_view(&self.camera, &self.lidar_t_camera, &self.core, &self.overlay, time, link, &self.render);
        if view.aligned {
            let world_t_rig = view.world_t_camera * self.lidar_t_camera.inverse();
            self.inset.draw(&mut view.frame, self.core.map(), &world_t_rig, &view.people, &self.render);
        }
        view
    }

    pub fn core(&self) -> &RigCore {
        &self.core
    }

    pub fn core_mut(&mut self) -> &mut RigCore {
        &mut self.core
    }

    pub fn overlay(&self) -> &Overlay {
        &self.overlay
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ar::OrientedBox;
    use crate::lio::{Clock, TimedPoint};
    use nalgebra::Vector3;

    const MS: u64 = 1_000_000;

    fn side() -> RigSide {
        RigSide::new(RigSideConfig {
            core: RigCoreConfig::default(),
            camera: CameraModel::default(),
            lidar_t_camera: Isometry3::identity(),
            render: RenderConfig::default(),
            hold_ns: HOLD_NS,
        })
        .unwrap_or_else(|e| panic!("{e}"))
    }

    /// A rig standing still until `until_ns` (IMU at 200 Hz), then one scan of a 10 m x 8 m room
    /// ending there: the LIO's first pose.
    fn first_pose(side: &mut RigSide, until_ns: u64) {
        let mut outs = Vec::new();
        let mut t = 0;
        while t <= until_ns + 20 * MS {
            let sample = ImuSample {
                t_ns: t,
                clock: Clock::Ptp,
                gyro_rad_s: Vector3::zeros(),
                acc_m_s2: Vector3::new(0.0, 0.0, 9.81),
            };
            side.push_imu(sample, &mut outs);
            t += 5 * MS;
        }
        let start_ns = until_ns - 100 * MS;
        let mut points = Vec::new();
        for i in 0..2000u32 {
            let a = f64::from(i) * 0.0314;
            let (x, y) = (5.0 * a.cos(), 4.0 * a.sin());
            let z = -1.0 + f64::from(i % 30) * 0.1;
            let t_ns = start_ns + u64::from(i) * 50_000;
            points.push(TimedPoint { x_m: x as f32, y_m: y as f32, z_m: z as f32, t_ns });
        }
        side.push_scan(LioScan { start_ns, end_ns: until_ns, clock: Clock::Ptp, points }, &mut outs);
        assert!(side.core().last().is_some(), "the LIO gave no pose");
    }

    fn person() -> Vec<ArPerson> {
        let bbox =
            OrientedBox { centre_m: Vector3::new(3.0, 0.0, 0.9), size_m: Vector3::new(0.5, 0.4, 1.8), yaw_rad: 0.0 };
        vec![ArPerson { points_world: vec![bbox.centre_m], bbox: Some(bbox), age_ns: 0, pose: None }]
    }

    #[test]
    fn detections_are_judged_by_the_rigs_own_clock() {
        let mut side = side();
        assert_eq!(side.push_detections(1_000 * MS, person()), DetectionTake::RefusedBeforeFirstScan);
        // Long enough that a clock stepped back by more than MAX_DETECTION_AGE_NS is still >= 0.
        first_pose(&mut side, 6_500 * MS);
        let (now_ns, _) = side.core().last().unwrap_or_default();
        // A forged stamp (or a robot clock step) an hour ahead is refused and does not move the
        // frame's time; the real detection after it is held and drawn at its own time.
        let forged = now_ns + 3_600_000 * MS;
        assert_eq!(side.push_detections(forged, person()), DetectionTake::RefusedFromTheFuture);
        assert_eq!(side.newest_detection_ns(), 0);
        // Two sightings 100 ms apart: the overlay draws a person once a second sighting confirms them.
        assert_eq!(side.push_detections(now_ns - 100 * MS, person()), DetectionTake::Held);
        assert_eq!(side.push_detections(now_ns, person()), DetectionTake::Held);
        assert_eq!(side.newest_detection_ns(), now_ns);
        assert_eq!(side.overlay().at(now_ns).len(), 1);
        // Within the allowed lead (clock jitter between the two LiDARs) is held.
        assert_eq!(side.push_detections(now_ns + MAX_DETECTION_LEAD_NS, person()), DetectionTake::Held);
        // A robot clock stepped back 6 s: refused and counted, nothing of it held.
        let stepped_back = now_ns - 6_000 * MS;
        assert_eq!(side.push_detections(stepped_back, person()), DetectionTake::RefusedFromThePast);
        assert_eq!(side.newest_detection_ns(), now_ns + MAX_DETECTION_LEAD_NS);
        let refused = RefusedDetections { before_first_scan: 1, from_the_future: 1, from_the_past: 1 };
        assert_eq!(side.refused(), refused);
    }
}
