//! The rig's whole side of a mission between its inputs and its frames, sans-IO: the rig core
//! (LIO, alignment, world pose), the robot's map as it arrives, the robot's detections held and
//! aged, and the AR frame. The rig node drives it from its sockets (running alignment jobs on a
//! worker thread), the offline run and the rerun of recordings drive it in time order (running
//! them inline): one implementation, so the three cannot drift apart.

use super::{render_view, AlignJob, AlignOutcome, AlignVerdict, Overlay, RigCore, RigCoreConfig, View};
use crate::align::TileMap;
use crate::ar::{ArPerson, CameraModel, RenderConfig};
use crate::lio::{ImuSample, LioScan, ScanOutput};
use crate::PipelineError;
use nalgebra::{Isometry3, Vector3};

/// Detections stay on screen this long after the robot last saw them.
pub const HOLD_NS: u64 = 1_000_000_000;

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
    newest_detection_ns: u64,
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
            newest_detection_ns: 0,
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
        self.map = MapFeed::Points;
        self.core.set_map(points);
    }

    /// Map tiles held (0 when the map came whole).
    pub fn tile_count(&self) -> usize {
        match &self.map {
            MapFeed::Tiles { tiles, .. } => tiles.tile_count(),
            MapFeed::Points => 0,
        }
    }

    /// The robot's detection at `stamp_ns`, already on the rig's LiDAR clock.
    pub fn push_detections(&mut self, stamp_ns: u64, people: Vec<ArPerson>) {
        self.newest_detection_ns = self.newest_detection_ns.max(stamp_ns);
        self.overlay.push(stamp_ns, people);
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
                self.core.set_map(tiles.points().0);
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

    /// The responder's frame at `t_ns` (rig LiDAR clock). `next_frame` moves the world pose's
    /// bounded correction one frame on (each displayed frame does, once).
    pub fn render(&mut self, t_ns: u64, link: &str, next_frame: bool) -> View {
        if next_frame {
            self.core.world_mut().step_frame();
        }
        render_view(&self.camera, &self.lidar_t_camera, &self.core, &self.overlay, t_ns, link, &self.render)
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
