//! The points of one de-skewed scan that enter the update: the blind zone left out, one centroid
//! per voxel, at most a fixed number.
//!
//! A scan whose view is mostly inside the blind zone (a helmet by a wall, a doorway) keeps only
//! a few dozen voxels of the usual size, and the few planes it still sees (a door jamb, the
//! corridor beyond) are averaged away. Such a scan is reduced again on voxels half the size,
//! down to a floor, until it keeps enough points (docs/lio.md, "Fine voxels where the view is
//! small"). A scan with a wide view keeps the usual coarse voxels and their robustness.

use crate::voxel_hash::voxel_downsample;
use nalgebra::Vector3;

/// How a scan is reduced before the update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanReduction {
    /// Points closer than this to the LiDAR are dropped.
    pub blind_m: f64,
    /// The voxel a scan is first reduced on (one centroid per voxel).
    pub voxel_m: f64,
    /// A scan left with fewer points than this is reduced again on voxels half the size; 0: never.
    pub min_points: usize,
    /// Voxels are never made smaller than this.
    pub min_voxel_m: f64,
    /// At most this many of the centroids enter the update (evenly spread); 0: all.
    pub max_points: usize,
}

impl ScanReduction {
    /// The update's points of `deskewed` (in the LiDAR frame) and the voxel they were reduced on.
    pub fn reduce(&self, deskewed: &[Vector3<f64>]) -> (Vec<Vector3<f64>>, f64) {
        let blind_sq = self.blind_m * self.blind_m;
        // A non-finite point fails the comparison (NaN) or is kept out explicitly (infinity).
        let seen = || deskewed.iter().filter(move |p| p.norm_squared() >= blind_sq && p.iter().all(|v| v.is_finite()));
        let mut voxel_m = self.voxel_m;
        let mut used = voxel_downsample(seen(), voxel_m);
        while used.len() < self.min_points && voxel_m * 0.5 >= self.min_voxel_m {
            voxel_m *= 0.5;
            used = voxel_downsample(seen(), voxel_m);
        }
        thin_out(&mut used, self.max_points);
        (used, voxel_m)
    }
}

/// Keeps at most `max` points, evenly strided through the (voxel-ordered) list; 0 keeps all.
fn thin_out(points: &mut Vec<Vector3<f64>>, max: usize) {
    if max == 0 || points.len() <= max {
        return;
    }
    let n = points.len();
    let kept: Vec<_> = (0..max).filter_map(|i| points.get(i * n / max).copied()).collect();
    *points = kept;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reduction(min_points: usize) -> ScanReduction {
        ScanReduction { blind_m: 0.5, voxel_m: 0.5, min_points, min_voxel_m: 0.1, max_points: 0 }
    }

    /// A 1 m x 1 m patch of wall 2 m away, sampled every 2 cm.
    fn small_view() -> Vec<Vector3<f64>> {
        (0..50)
            .flat_map(|i| (0..50).map(move |j| Vector3::new(2.0, f64::from(i) * 0.02, f64::from(j) * 0.02)))
            .collect()
    }

    #[test]
    fn a_small_view_is_reduced_on_finer_voxels_down_to_the_floor() {
        let (coarse, v) = reduction(0).reduce(&small_view());
        assert_eq!((coarse.len(), v), (4, 0.5));
        let (fine, v) = reduction(50).reduce(&small_view());
        assert_eq!((fine.len(), v), (64, 0.125), "halved twice: 16 then 64 voxels");
        let (floor, v) = reduction(10_000).reduce(&small_view());
        assert!(v >= 0.1 && floor.len() == 64, "not below the floor: {v} m, {} points", floor.len());
    }

    #[test]
    fn a_wide_view_keeps_the_coarse_voxels() {
        let wide: Vec<Vector3<f64>> = (0..200)
            .flat_map(|i| (0..20).map(move |j| Vector3::new(5.0, f64::from(i) * 0.05, f64::from(j) * 0.1)))
            .collect();
        let (used, v) = reduction(50).reduce(&wide);
        assert_eq!(v, 0.5);
        assert!(used.len() >= 50, "{}", used.len());
    }

    #[test]
    fn the_blind_zone_and_non_finite_points_are_left_out() {
        let pts = [
            Vector3::new(0.3, 0.0, 0.0),
            Vector3::new(f64::NAN, 0.0, 0.0),
            Vector3::new(f64::INFINITY, 0.0, 0.0),
            Vector3::new(3.0, 0.0, 0.0),
        ];
        let (used, _) = reduction(100).reduce(&pts);
        assert_eq!(used, vec![Vector3::new(3.0, 0.0, 0.0)]);
    }

    #[test]
    fn thinning_keeps_an_even_spread() {
        let mut pts: Vec<Vector3<f64>> = (0..10).map(|i| Vector3::new(f64::from(i), 0.0, 0.0)).collect();
        thin_out(&mut pts, 4);
        let xs: Vec<f64> = pts.iter().map(|p| p.x).collect();
        assert_eq!(xs, [0.0, 2.0, 5.0, 7.0]);
        thin_out(&mut pts, 0);
        assert_eq!(pts.len(), 4);
    }
}
