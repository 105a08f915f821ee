//! Which side a surface was seen from. A robot that maps a room from outside and a responder
//! inside it see the two faces of one wall, a wall's thickness apart (0.08-0.32 m in the
//! generated buildings, 0.1-0.15 m for plasterboard). That is within ICP's correspondence
//! distance, so the inner face's points pair with the outer face and pull the fit by the
//! thickness (docs/align.md, "a wall seen from its other side"). Each voxel keeps the mean of
//! the unit vectors from its points towards the sensors that saw them; a pair whose surfaces
//! were seen from opposite sides of the target's plane is two faces, not one.

use super::free_space::Ray;
use super::geometry::Vec3;
use crate::voxel_hash::{key_of, Key, KeyMap, VoxelHashMap};

/// Per voxel, the sum of the unit vectors from its points towards their sensors, and how many.
pub struct SeenFrom {
    inv_voxel_m: f64,
    sums: KeyMap<(Vec3, u32)>,
}

impl SeenFrom {
    /// Voxels of `voxel_m` (at least 1 mm), as [`crate::voxel_hash::voxel_downsample`] cuts
    /// them, so that a reduced point finds its own voxel.
    pub fn new(voxel_m: f64) -> Self {
        Self { inv_voxel_m: 1.0 / voxel_m.max(1e-3), sums: KeyMap::default() }
    }

    /// Each ray's end seen from its origin.
    pub fn from_rays(rays: &[Ray], voxel_m: f64) -> Self {
        let mut s = Self::new(voxel_m);
        for r in rays {
            s.add(&r.end, &(r.origin - r.end));
        }
        s
    }

    /// A point seen from the direction `towards_sensor`; a zero or non-finite one is skipped.
    pub fn add(&mut self, point: &Vec3, towards_sensor: &Vec3) {
        let Some(unit) = towards_sensor.try_normalize(1e-9) else { return };
        if !(unit.iter().chain(point.iter()).all(|v| v.is_finite())) {
            return;
        }
        let e = self.sums.entry(key_of(point, self.inv_voxel_m)).or_insert((Vec3::zeros(), 0));
        e.0 += unit;
        e.1 += 1;
    }

    pub fn is_empty(&self) -> bool {
        self.sums.is_empty()
    }

    /// The mean unit vector towards the sensors in the voxel of `p` (zero where nothing was
    /// seen). Seen from both sides alike, it comes out short or zero.
    pub fn at(&self, p: &Vec3) -> Vec3 {
        self.sums.get(&key_of(p, self.inv_voxel_m)).map_or_else(Vec3::zeros, |(sum, n)| sum / f64::from((*n).max(1)))
    }

    /// [`Self::at`] of each point, in order; empty where nothing was seen (sides unknown), and
    /// where `min_side` is 0 (sides not judged).
    pub fn at_each(&self, points: &[Vec3], min_side: f64) -> Vec<Vec3> {
        if min_side <= 0.0 || self.is_empty() {
            return Vec::new();
        }
        points.iter().map(|p| self.at(p)).collect()
    }
}

/// The side a direction points to: the axis of its largest component and that component's
/// sign (0-5), or 6 for none.
pub fn side_class(d: &Vec3) -> u8 {
    let (axis, v) =
        d.iter().enumerate().fold((0, 0.0f64), |best, (i, v)| if v.abs() > best.1.abs() { (i, *v) } else { best });
    if v == 0.0 || !v.is_finite() {
        6
    } else {
        (2 * axis + usize::from(v < 0.0)) as u8
    }
}

/// `d` as a unit vector (zero where it is zero or not finite) and its [`side_class`]: the
/// (voxel, side) buckets of [`reduce_by_side`] and of NDT's sided cells.
pub fn unit_and_side(d: &Vec3) -> (Vec3, u8) {
    let unit = d.try_normalize(1e-9).filter(|u| u.iter().all(|v| v.is_finite())).unwrap_or_else(Vec3::zeros);
    (unit, side_class(&unit))
}

/// Points reduced to the mean of each voxel's points seen from one side (`towards_sensor[i]`
/// from `points[i]`, zero where unknown), with the mean direction of each. The two faces of a
/// wall thinner than a voxel stay two points, each on its own face: reduced together, their mean
/// lies inside the wall, a face's half thickness from either. Sorted by voxel, then side.
pub fn reduce_by_side(points: &[Vec3], towards_sensor: &[Vec3], voxel_m: f64) -> (Vec<Vec3>, Vec<Vec3>) {
    let inv = 1.0 / voxel_m.max(1e-3);
    let mut cells: VoxelHashMap<(Key, u8), (Vec3, Vec3, u32)> = VoxelHashMap::default();
    for (p, d) in points.iter().zip(towards_sensor) {
        if !p.iter().all(|v| v.is_finite()) {
            continue;
        }
        let (unit, side) = unit_and_side(d);
        let e = cells.entry((key_of(p, inv), side)).or_insert((Vec3::zeros(), Vec3::zeros(), 0));
        e.0 += p;
        e.1 += unit;
        e.2 += 1;
    }
    let mut out: Vec<((Key, u8), Vec3, Vec3)> =
        cells.into_iter().map(|(k, (sum, dir, n))| (k, sum / f64::from(n), dir / f64::from(n))).collect();
    out.sort_unstable_by_key(|c| c.0);
    out.into_iter().map(|(_, p, d)| (p, d)).unzip()
}

/// Whether two surfaces paired across the target's plane (normal `n`, either sign) were seen
/// from its opposite sides: their mean directions towards their sensors, `a` and `b`, lie on
/// opposite sides of the plane, each at least `min_side` along its normal (a mean cosine; 0:
/// never). A side seen from both ways, or at a graze, says nothing.
pub fn seen_from_opposite_sides(n: &Vec3, a: &Vec3, b: &Vec3, min_side: f64) -> bool {
    let (sa, sb) = (n.dot(a), n.dot(b));
    min_side > 0.0 && sa * sb < 0.0 && sa.abs() >= min_side && sb.abs() >= min_side
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::{reduce_by_side, seen_from_opposite_sides, SeenFrom};
    use crate::align::free_space::Ray;
    use crate::align::geometry::Vec3;

    #[test]
    fn a_wall_seen_from_both_sides_says_nothing_and_from_one_side_says_which() {
        let wall = Vec3::new(0.0, 0.1, 1.0);
        let from = |x: f64| Ray { origin: Vec3::new(x, 0.0, 1.0), end: wall };
        let one = SeenFrom::from_rays(&[from(-3.0), from(-5.0)], 0.25);
        assert!(one.at(&wall).x < -0.99);
        let both = SeenFrom::from_rays(&[from(-3.0), from(3.0)], 0.25);
        assert!(both.at(&wall).x.abs() < 1e-9, "across the wall, the two sides cancel");
        assert_eq!(one.at(&Vec3::new(5.0, 0.0, 0.0)), Vec3::zeros());
        assert!(SeenFrom::from_rays(&[Ray { origin: wall, end: wall }], 0.25).is_empty());
    }

    #[test]
    fn a_thin_wall_seen_from_both_sides_keeps_both_faces() {
        // Faces at x = 0.02 (seen from -x) and x = 0.16 (seen from +x), one 0.25 m voxel.
        let pts = [Vec3::new(0.02, 0.1, 0.1), Vec3::new(0.02, 0.2, 0.1), Vec3::new(0.16, 0.1, 0.1)];
        let dirs = [Vec3::new(-2.0, 0.0, 0.0), Vec3::new(-1.0, 0.1, 0.0), Vec3::new(3.0, 0.0, 0.0)];
        let (p, d) = reduce_by_side(&pts, &dirs, 0.25);
        assert_eq!(p.len(), 2);
        let outer = p.iter().position(|q| q.x < 0.1).unwrap();
        assert!((p[outer].x - 0.02).abs() < 1e-12 && (p[1 - outer].x - 0.16).abs() < 1e-12);
        assert!(d[outer].x < -0.9 && d[1 - outer].x > 0.99);
        // Unknown sides reduce together, as a plain voxel mean.
        let (p, d) = reduce_by_side(&pts, &[Vec3::zeros(); 3], 0.25);
        assert_eq!((p.len(), d[0]), (1, Vec3::zeros()));
    }

    #[test]
    fn only_clearly_opposite_sides_are_opposite() {
        let n = Vec3::new(-1.0, 0.0, 0.0);
        let (left, right) = (Vec3::new(-1.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0));
        assert!(seen_from_opposite_sides(&n, &left, &right, 0.3));
        assert!(!seen_from_opposite_sides(&n, &left, &left, 0.3));
        assert!(!seen_from_opposite_sides(&n, &left, &(right * 0.2), 0.3));
        assert!(!seen_from_opposite_sides(&n, &left, &Vec3::zeros(), 0.3));
        assert!(!seen_from_opposite_sides(&n, &left, &right, 0.0));
    }
}
