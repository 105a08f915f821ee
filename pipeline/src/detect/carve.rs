//! The box each confirmation was made in, and finding a followed person again inside a cluster they merged with (the trees' following).
//!
//! One window's clusters are not the next one's: someone lying on a bed or sitting in a chair is
//! their own cluster in one window and part of the bed's or the chair's in the next, and no
//! score of the merged cluster finds them there. Where someone the trees confirmed lately is in
//! no detection, the points inside the box they were last confirmed in (moved on at their
//! track's velocity, grown by a margin) are clustered again on their own, and the largest piece
//! is shown to the trees.

use super::features::ClusterFeatures;
use nalgebra::{Vector2, Vector3};

/// The box a person was confirmed in, over the floor, and when.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shape {
    /// Centre over the floor (x, y in the world) and the window's stamp.
    pub at: Vector2<f64>,
    pub t_ns: u64,
    half_length_m: f64,
    half_width_m: f64,
    yaw_rad: f64,
    /// Lowest and highest point above the floor.
    bottom_m: f64,
    top_m: f64,
}

impl Shape {
    /// The box of a cluster confirmed in the window stamped `t_ns`.
    pub fn of(f: &ClusterFeatures, t_ns: u64) -> Self {
        Self {
            at: Vector2::new(f.centre.x, f.centre.y),
            t_ns,
            half_length_m: f.size.x / 2.0,
            half_width_m: f.size.y / 2.0,
            yaw_rad: f.yaw_rad,
            bottom_m: f.bottom_m,
            top_m: f.top_m,
        }
    }

    /// Whether `p` (x, y in the world, height above the floor) lies in this box moved to
    /// `centre` and grown by `margin_m` on every side.
    pub fn holds(&self, centre: Vector2<f64>, p: &Vector3<f64>, margin_m: f64) -> bool {
        let (s, c) = self.yaw_rad.sin_cos();
        let (dx, dy) = (p.x - centre.x, p.y - centre.y);
        let along = c * dx + s * dy;
        let across = -s * dx + c * dy;
        along.abs() <= self.half_length_m + margin_m
            && across.abs() <= self.half_width_m + margin_m
            && p.z >= self.bottom_m - margin_m
            && p.z <= self.top_m + margin_m
    }

    /// Whether a box of `length_m` by `width_m` over the floor is more than `by_m` longer or
    /// wider than this one: someone merged with what lies beside them (a bed, a bench), not
    /// them alone.
    pub fn outgrown_by(&self, length_m: f64, width_m: f64, by_m: f64) -> bool {
        length_m > 2.0 * self.half_length_m + by_m || width_m > 2.0 * self.half_width_m + by_m
    }

    /// Whether `xy` lies over this box's footprint moved to `centre` and grown by `margin_m`
    /// (a detection there is a piece of this person).
    pub fn covers(&self, centre: Vector2<f64>, xy: Vector2<f64>, margin_m: f64) -> bool {
        self.holds(centre, &Vector3::new(xy.x, xy.y, self.bottom_m), margin_m)
    }
}

/// The points of `kept` (window index; x, y, height above the floor) inside `shape` moved to
/// `centre` and grown by `margin_m`.
pub fn carve(
    kept: &[(u32, Vector3<f64>)],
    shape: &Shape,
    centre: Vector2<f64>,
    margin_m: f64,
) -> Vec<(u32, Vector3<f64>)> {
    kept.iter().filter(|(_, p)| shape.holds(centre, p, margin_m)).copied().collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn lying_on_a_bed() -> ClusterFeatures {
        ClusterFeatures {
            points: 300,
            voxels: 40,
            centre: Vector3::new(2.0, 1.0, 0.65),
            size: Vector3::new(1.2, 0.4, 0.15),
            yaw_rad: std::f64::consts::FRAC_PI_2,
            bottom_m: 0.57,
            top_m: 0.74,
            face_share: 0.3,
            top_share: 0.2,
            linearity: 0.5,
            planarity: 0.3,
            thickness_m: 0.05,
            range_m: 3.0,
        }
    }

    #[test]
    fn the_box_is_turned_and_grown() {
        let shape = Shape::of(&lying_on_a_bed(), 7);
        let at = shape.at;
        // Along its length (y, turned 90 deg), 0.59 m out is in; across it 0.25 m out is not.
        assert!(shape.holds(at, &Vector3::new(2.0, 1.59, 0.7), 0.0));
        assert!(!shape.holds(at, &Vector3::new(2.25, 1.0, 0.7), 0.0));
        assert!(shape.holds(at, &Vector3::new(2.25, 1.0, 0.7), 0.1));
        // The bed's top under them is below their lowest point less the margin.
        assert!(!shape.holds(at, &Vector3::new(2.0, 1.0, 0.45), 0.1));
        assert!(shape.holds(at, &Vector3::new(2.0, 1.0, 0.50), 0.1));
    }

    #[test]
    fn a_box_a_bed_long_has_outgrown_the_person() {
        let shape = Shape::of(&lying_on_a_bed(), 7);
        assert!(!shape.outgrown_by(1.5, 0.6, 0.5), "a little longer and wider: still them");
        assert!(shape.outgrown_by(2.0, 0.6, 0.5), "0.8 m longer");
        assert!(shape.outgrown_by(1.2, 1.0, 0.5), "0.6 m wider");
    }

    #[test]
    fn carving_keeps_what_lies_in_the_moved_box() {
        let shape = Shape::of(&lying_on_a_bed(), 7);
        let kept = vec![
            (0, Vector3::new(2.0, 1.0, 0.7)),  // where they were
            (1, Vector3::new(3.0, 1.0, 0.7)),  // where their track says they are now
            (2, Vector3::new(3.0, 1.0, 1.5)),  // above them there
            (3, Vector3::new(3.1, 0.45, 0.7)), // along their length there
        ];
        let now = Vector2::new(3.0, 1.0);
        let carved: Vec<u32> = carve(&kept, &shape, now, 0.1).iter().map(|c| c.0).collect();
        assert_eq!(carved, vec![1, 3]);
    }
}
