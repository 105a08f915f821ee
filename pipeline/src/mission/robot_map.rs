//! The robot's map for the rig's alignment, sans-IO: placed scans in, one point per voxel kept,
//! the tiles changed since the last call encoded out (see [`crate::align::tiles`]). Separate
//! from [`super::RobotCore`] so that a node can grow it off the live path.

use crate::align::{encode_tile, Coverage, TileVectors};
use crate::detect::WindowPoint;
use crate::voxel_hash::key_of;
use crate::voxel_hash::{VoxelHashMap, VoxelHashSet};
use crate::PipelineError;
use nalgebra::Vector3;
use std::sync::Arc;

type VoxelKey = crate::voxel_hash::Key;

/// One placed scan for the map: its points in the world and where the sensor was.
#[derive(Clone, Debug)]
pub struct MapScan {
    pub origin_m: Vector3<f64>,
    pub points: Arc<Vec<WindowPoint>>,
}

/// Voxel and tile sizes of a [`RobotMap`].
#[derive(Clone, Copy, Debug)]
pub struct RobotMapConfig {
    /// One point per voxel of this size.
    pub voxel_m: f64,
    /// The coverage (space the rays crossed) in voxels of this size, from every
    /// `coverage_ray_stride`-th point's ray (0: no coverage).
    pub coverage_voxel_m: f64,
    pub coverage_ray_stride: usize,
    /// Tiles carry the coverage's voxels crossed at least this many times (format 2; 0: tiles
    /// carry surfaces only). The tile edge must then be a whole number of coverage voxels.
    pub tile_coverage_min_crossings: u16,
    /// Edge and quantization of the tiles.
    pub tile_edge_m: f64,
    pub tile_step_m: f64,
}

/// A tile's points (one per voxel) and, for each, the unit vector from it towards the sensor
/// that first saw it (zero where not known): which side of a wall the robot saw, so that the
/// rig does not pair the wall's other face with it (see [`crate::align::SeenFrom`]).
#[derive(Default)]
struct TilePoints {
    points: Vec<Vector3<f64>>,
    towards_sensor: Vec<Vector3<f64>>,
}

pub struct RobotMap {
    cfg: RobotMapConfig,
    /// Occupied voxels, and each tile's points (one per voxel).
    voxels: VoxelHashSet<VoxelKey>,
    tiles: VoxelHashMap<VoxelKey, TilePoints>,
    dirty_tiles: VoxelHashSet<VoxelKey>,
    tile_version: u32,
    coverage: Arc<Coverage>,
}

impl RobotMap {
    pub fn new(cfg: RobotMapConfig) -> Result<Self, PipelineError> {
        if !(cfg.voxel_m > 0.0 && cfg.tile_edge_m > cfg.voxel_m) {
            return Err(PipelineError::BadFile {
                format: "robot config",
                reason: "map_voxel_m and tile_edge_m must be positive, tiles larger than voxels".into(),
            });
        }
        let per_edge = cfg.tile_edge_m / cfg.coverage_voxel_m;
        let whole = (per_edge - per_edge.round()).abs() < 1e-6 && (1.0..=64.0).contains(&per_edge.round());
        if cfg.tile_coverage_min_crossings > 0 && !(cfg.coverage_ray_stride > 0 && whole) {
            return Err(PipelineError::BadFile {
                format: "robot config",
                reason: "coverage in tiles needs rays and a tile edge of 1 to 64 whole coverage voxels".into(),
            });
        }
        Ok(Self {
            cfg,
            voxels: VoxelHashSet::default(),
            tiles: VoxelHashMap::default(),
            dirty_tiles: VoxelHashSet::default(),
            tile_version: 0,
            coverage: Arc::new(Coverage::new(cfg.coverage_voxel_m)),
        })
    }

    /// Adds a placed scan: the first point of each new voxel is kept, and a sample of its rays
    /// grows the coverage.
    pub fn add_scan(&mut self, scan: &MapScan) {
        self.add_seen_from(&scan.points, Some(&scan.origin_m));
        if self.cfg.coverage_ray_stride == 0 {
            return;
        }
        let min = self.cfg.tile_coverage_min_crossings;
        let coverage = Arc::make_mut(&mut self.coverage);
        let mut reached = Vec::new();
        for p in scan.points.iter().step_by(self.cfg.coverage_ray_stride) {
            coverage.add_ray_noting(&scan.origin_m, &p.xyz(), min, &mut reached);
        }
        // A voxel that came to the crossings the tiles carry changes its tile.
        let per_tile = (self.cfg.tile_edge_m / self.cfg.coverage_voxel_m).round().max(1.0) as i32;
        for v in reached {
            self.dirty_tiles.insert((v.0.div_euclid(per_tile), v.1.div_euclid(per_tile), v.2.div_euclid(per_tile)));
        }
    }

    /// The space the robot's rays crossed (shared: cloning it is cheap until the map grows).
    pub fn coverage(&self) -> Arc<Coverage> {
        Arc::clone(&self.coverage)
    }

    /// Adds a placed scan's points (world frame): the first point of each new voxel is kept.
    pub fn add(&mut self, points: &[WindowPoint]) {
        self.add_seen_from(points, None);
    }

    /// [`Self::add`], each new point also keeping the direction towards `sensor` when given.
    fn add_seen_from(&mut self, points: &[WindowPoint], sensor: Option<&Vector3<f64>>) {
        let per_tile = self.voxels_per_tile();
        let inv_voxel_m = 1.0 / self.cfg.voxel_m;
        for p in points {
            let xyz = p.xyz();
            let key = key_of(&xyz, inv_voxel_m);
            if self.voxels.insert(key) {
                let tile = (key.0.div_euclid(per_tile), key.1.div_euclid(per_tile), key.2.div_euclid(per_tile));
                let towards = sensor.and_then(|o| (o - xyz).try_normalize(1e-9)).unwrap_or_else(Vector3::zeros);
                let t = self.tiles.entry(tile).or_default();
                t.points.push(xyz);
                t.towards_sensor.push(towards);
                self.dirty_tiles.insert(tile);
            }
        }
    }

    fn voxels_per_tile(&self) -> i32 {
        (self.cfg.tile_edge_m / self.cfg.voxel_m).round().max(1.0) as i32
    }

    /// The whole map (one point per voxel), in the robot's world.
    pub fn points(&self) -> Vec<Vector3<f64>> {
        self.tiles.values().flat_map(|t| &t.points).copied().collect()
    }

    /// [`Self::points`] and, in the same order, the unit vector from each towards the sensor
    /// that first saw it (zero where not known).
    pub fn points_seen_from(&self) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let (mut points, mut towards) = (Vec::with_capacity(self.len()), Vec::with_capacity(self.len()));
        for t in self.tiles.values() {
            points.extend_from_slice(&t.points);
            towards.extend_from_slice(&t.towards_sensor);
        }
        (points, towards)
    }

    /// Occupied voxels.
    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.voxels.is_empty()
    }

    /// The tiles changed since the last call, encoded; every call that sends anything bumps the
    /// version, so a rig keeps the newest of each tile.
    pub fn take_changed_tiles(&mut self) -> Result<Vec<Vec<u8>>, PipelineError> {
        if self.dirty_tiles.is_empty() {
            return Ok(Vec::new());
        }
        let per_tile = self.voxels_per_tile();
        let mut dirty: Vec<VoxelKey> = std::mem::take(&mut self.dirty_tiles).into_iter().collect();
        dirty.sort_unstable();
        self.tile_version = self.tile_version.wrapping_add(1);
        let edge_m = f64::from(per_tile) * self.cfg.voxel_m;
        let min = self.cfg.tile_coverage_min_crossings;
        let coverage = (min > 0).then_some((self.coverage.as_ref(), min));
        let none = TilePoints::default();
        dirty
            .into_iter()
            .map(|key| {
                let tile = self.tiles.get(&key).unwrap_or(&none);
                let towards: Vec<Option<Vector3<f64>>> =
                    tile.towards_sensor.iter().map(|d| (d.norm() > 0.0).then_some(*d)).collect();
                let (step_m, version) = (self.cfg.tile_step_m, self.tile_version);
                encode_tile(key, &tile.points, TileVectors::TowardsSensor(&towards), edge_m, step_m, version, coverage)
            })
            .collect()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::align::TileMap;

    fn points(xs: impl Iterator<Item = f64>) -> Vec<WindowPoint> {
        xs.map(|x| WindowPoint { x_m: x as f32, y_m: 0.5, z_m: 1.0, t_ns: 0 }).collect()
    }

    #[test]
    fn keeps_a_point_per_voxel_and_sends_each_change_once() {
        let cfg = RobotMapConfig {
            voxel_m: 0.1,
            tile_edge_m: 4.0,
            tile_step_m: 0.01,
            coverage_voxel_m: 0.25,
            coverage_ray_stride: 0,
            tile_coverage_min_crossings: 0,
        };
        let mut map = RobotMap::new(cfg).unwrap();
        // 0.01 m apart over 2 m: 20 voxels of 0.1 m, one tile of 4 m.
        map.add(&points((0..200).map(|i| f64::from(i) * 0.01 + 0.005)));
        assert_eq!(map.len(), 20);
        let first = map.take_changed_tiles().unwrap();
        assert_eq!(first.len(), 1);
        assert!(map.take_changed_tiles().unwrap().is_empty(), "nothing changed since");
        // The same voxels again change nothing; a point 10 m away makes one new tile.
        map.add(&points((0..200).map(|i| f64::from(i) * 0.01 + 0.005)));
        assert!(map.take_changed_tiles().unwrap().is_empty());
        map.add(&points([10.05].into_iter()));
        let second = map.take_changed_tiles().unwrap();
        assert_eq!(second.len(), 1);
        // A rig applying every tile holds the whole map.
        let mut rig = TileMap::default();
        for t in first.iter().chain(&second) {
            rig.apply(t).unwrap();
        }
        assert_eq!(rig.points().0.len(), map.points().len());
        assert_eq!(map.points().len(), 21);
    }

    #[test]
    fn refuses_tiles_smaller_than_voxels() {
        assert!(RobotMap::new(RobotMapConfig {
            voxel_m: 0.5,
            tile_edge_m: 0.2,
            tile_step_m: 0.01,
            coverage_voxel_m: 0.25,
            coverage_ray_stride: 0,
            tile_coverage_min_crossings: 0,
        })
        .is_err());
        // Coverage in tiles needs tiles of whole coverage voxels.
        assert!(RobotMap::new(RobotMapConfig {
            voxel_m: 0.1,
            tile_edge_m: 4.0,
            tile_step_m: 0.01,
            coverage_voxel_m: 0.3,
            coverage_ray_stride: 16,
            tile_coverage_min_crossings: 2,
        })
        .is_err());
    }

    #[test]
    fn tiles_carry_the_space_the_rays_crossed_to_the_rig() {
        let cfg = RobotMapConfig {
            voxel_m: 0.1,
            tile_edge_m: 4.0,
            tile_step_m: 0.01,
            coverage_voxel_m: 0.25,
            coverage_ray_stride: 1,
            tile_coverage_min_crossings: 2,
        };
        let mut map = RobotMap::new(cfg).unwrap();
        // A wall 6 m ahead along +x, seen from the origin: the rays cross two tiles of 4 m
        // before it (the second tile holds the wall).
        let wall: Vec<WindowPoint> =
            (0..20).map(|i| WindowPoint { x_m: 6.0, y_m: 0.5 + i as f32 * 0.01, z_m: 1.0, t_ns: 0 }).collect();
        let scan = MapScan { origin_m: Vector3::new(0.1, 0.5, 1.0), points: Arc::new(wall) };
        map.add_scan(&scan);
        let tiles = map.take_changed_tiles().unwrap();
        assert_eq!(tiles.len(), 2, "the wall's tile and the empty one before it");
        let mut rig = TileMap::default();
        for t in &tiles {
            rig.apply(t).unwrap();
        }
        let seen = rig.coverage().unwrap();
        let robot = map.coverage();
        // Every voxel the robot's rays crossed twice or more, and only those, reach the rig.
        for x in 0..30 {
            let p = Vector3::new(f64::from(x) * 0.25 + 0.1, 0.5, 1.0);
            assert_eq!(seen.crossings(&p) >= 2, robot.crossings(&p) >= 2, "{p:?}");
        }
        assert!(seen.crossings(&Vector3::new(3.0, 0.5, 1.0)) >= 2);
        assert_eq!(seen.crossings(&Vector3::new(5.9, 0.5, 1.0)), 0, "not the wall");
        // The same scan again reaches no new voxel: nothing to send.
        map.add_scan(&scan);
        assert!(map.take_changed_tiles().unwrap().is_empty());
    }
}
