//! Registration of one point cloud (the source, e.g. a responder's scan) against another (the
//! target, e.g. the robot's map): multi-resolution NDT for the coarse pose, then trimmed
//! point-to-plane ICP with a Huber loss, acceptance on RMS residual, inlier ratio, update norm and
//! degeneracy index, and a yaw-grid reseed when the first attempt is rejected.
//!
//! ```no_run
//! # use starc_pipeline::align::{Aligner, AlignConfig, cloud_points};
//! # fn f(src: &starc_pipeline::cloud::PointCloud, tgt: &starc_pipeline::cloud::PointCloud) -> Result<(), starc_pipeline::PipelineError> {
//! let aligner = Aligner::new(&cloud_points(tgt), AlignConfig::default())?;
//! let report = aligner.align(&cloud_points(src), &nalgebra::Isometry3::identity());
//! println!("accepted {} transform {:?}", report.accepted, report.transform);
//! # Ok(()) }
//! ```

mod carve;
mod config;
pub mod correlative;
pub mod coverage;
mod free_space;
mod geometry;
pub mod global;
mod icp;
mod map;
mod ndt;
mod register;
mod rejection;
mod seen_from;
mod tiles;

pub use carve::seen_through;
pub use config::AlignConfig;
pub use correlative::KnownFit;
pub use coverage::{Coverage, Overlap};
pub use free_space::{FreeSpace, Ray};
pub use geometry::{
    cloud_points, estimate_normals, pose_error, pose_from_rows, pose_rows, pose_xyz_yaw, Vec3, VoxelIndex,
};
pub use map::{
    aggregate_window, filter_window, floor_and_ceiling, prepare_map, AggregateStats, ExclusionBox, MapPrepConfig,
    Placed, PlacedPoint, PreparedMap, WindowConfig,
};
pub use register::{
    yaw_offsets_deg, AlignMetrics, AlignReport, Aligner, Attempt, PinnedCheck, Probe, Rival, Seed, SeedOrigin,
    WeakDirection,
};
pub use rejection::{slide_words, AlignFailure, Reasons, Rejection};
pub use seen_from::SeenFrom;
pub use tiles::{decode_tile, encode_tile, encode_tiles, Tile, TileCoverage, TileMap, TileVectors, MAX_TILE_POINTS};

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_coverage;
#[cfg(test)]
mod tests_map;
#[cfg(test)]
mod tests_seen_from;
