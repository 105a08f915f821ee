//! What the robot has seen of the building besides its surfaces: the space its rays crossed.
//! A rig point that a registration places in that space contradicts the registration (the robot
//! looked through there and saw nothing); one placed where the robot never looked says nothing
//! either way. So acceptance can judge a registration on the part of the rig's view that the
//! robot has covered, and a correct fit of a rig that sees rooms the robot has not mapped still
//! passes.

use super::geometry::Vec3;
use crate::voxel_hash::{key_of, Key, KeyMap};
use serde::Serialize;

/// A ray is walked this many voxels short of its end: the surface it hit, its noise, and the
/// voxels it grazed on the way in are not free.
const END_MARGIN_VOXELS: f64 = 2.0;
/// A ray is walked at most this far: farther returns of an indoor robot are few, and an
/// outdoor one's would grow the coverage without bound.
const MAX_RAY_M: f64 = 40.0;

/// Voxels the robot's rays crossed, with how many rays crossed each (saturating).
#[derive(Clone, Debug)]
pub struct Coverage {
    voxel_m: f64,
    inv_voxel_m: f64,
    crossed: KeyMap<u16>,
}

impl Coverage {
    pub fn new(voxel_m: f64) -> Self {
        let voxel_m = voxel_m.max(0.01);
        Self { voxel_m, inv_voxel_m: 1.0 / voxel_m, crossed: KeyMap::default() }
    }

    pub fn voxel_m(&self) -> f64 {
        self.voxel_m
    }

    /// Voxels crossed at least once.
    pub fn len(&self) -> usize {
        self.crossed.len()
    }

    pub fn is_empty(&self) -> bool {
        self.crossed.is_empty()
    }

    /// Walks the ray from `origin` to `end` (both in the world), counting each voxel it crosses
    /// once; non-finite rays are skipped.
    pub fn add_ray(&mut self, origin: &Vec3, end: &Vec3) {
        self.add_ray_noting(origin, end, 0, &mut Vec::new());
    }

    /// [`Self::add_ray`], noting in `reached` each voxel whose count comes to `min` (0: none):
    /// what changed for a reader that only asks "crossed at least `min` times?".
    pub fn add_ray_noting(&mut self, origin: &Vec3, end: &Vec3, min: u16, reached: &mut Vec<Key>) {
        if !(origin.iter().chain(end.iter()).all(|v| v.is_finite())) {
            return;
        }
        let d = end - origin;
        let free_m = d.norm() - END_MARGIN_VOXELS * self.voxel_m;
        if free_m <= 0.0 {
            return;
        }
        let dir = d.normalize();
        let step_m = 0.5 * self.voxel_m;
        let steps = (free_m.min(MAX_RAY_M) / step_m) as usize;
        let mut last = None;
        for k in 0..=steps {
            let key = key_of(&(origin + dir * (k as f64 * step_m)), self.inv_voxel_m);
            if last != Some(key) {
                let n = self.crossed.entry(key).or_insert(0);
                *n = n.saturating_add(1);
                if min > 0 && *n == min {
                    reached.push(key);
                }
                last = Some(key);
            }
        }
    }

    /// Every voxel crossed, with how many rays crossed it (in no particular order).
    pub fn voxels(&self) -> impl Iterator<Item = (Key, u16)> + '_ {
        self.crossed.iter().map(|(k, n)| (*k, *n))
    }

    /// Rays that crossed voxel `key`.
    pub fn crossings_of(&self, key: &Key) -> u16 {
        self.crossed.get(key).copied().unwrap_or(0)
    }

    /// Sets the count of voxel `key` (a coverage rebuilt from what the robot sent).
    pub fn set_crossings(&mut self, key: Key, crossings: u16) {
        self.crossed.insert(key, crossings);
    }

    /// Rays that crossed the voxel of `p`.
    pub fn crossings(&self, p: &Vec3) -> u16 {
        self.crossed.get(&key_of(p, self.inv_voxel_m)).copied().unwrap_or(0)
    }
}

/// How a registration's source points sit against the robot's map and coverage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Overlap {
    pub points: usize,
    /// Within `inlier_distance_m` of a map point.
    pub explained: usize,
    /// Not explained, in space the robot's rays crossed (at least `min_crossings` times).
    pub contradicted: usize,
}

impl Overlap {
    /// Explained over the points the robot has covered (explained or contradicted); 1 when it
    /// covered none (nothing contradicts; [`Self::explained_share`] then says there is nothing
    /// to judge by).
    pub fn ratio(&self) -> f64 {
        let covered = self.explained + self.contradicted;
        if covered == 0 {
            1.0
        } else {
            self.explained as f64 / covered as f64
        }
    }

    /// Explained points over all points.
    pub fn explained_share(&self) -> f64 {
        self.explained as f64 / self.points.max(1) as f64
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::{Coverage, Overlap};
    use crate::align::geometry::Vec3;

    #[test]
    fn a_ray_frees_the_space_it_crossed_but_not_the_surface_it_hit() {
        let mut c = Coverage::new(0.25);
        c.add_ray(&Vec3::new(0.0, 0.0, 1.0), &Vec3::new(5.0, 0.0, 1.0));
        c.add_ray(&Vec3::new(0.0, 0.0, 1.0), &Vec3::new(5.0, 0.0, 1.0));
        assert_eq!(c.crossings(&Vec3::new(2.0, 0.0, 1.0)), 2);
        assert_eq!(c.crossings(&Vec3::new(4.9, 0.0, 1.0)), 0, "the wall and the margin before it");
        assert_eq!(c.crossings(&Vec3::new(2.0, 1.0, 1.0)), 0, "beside the ray");
        c.add_ray(&Vec3::new(0.0, 0.0, f64::NAN), &Vec3::new(5.0, 0.0, 1.0));
        c.add_ray(&Vec3::zeros(), &Vec3::new(0.1, 0.0, 0.0));
        assert!(c.len() > 10 && c.len() < 30, "{}", c.len());
    }

    #[test]
    fn overlap_ratio_counts_only_what_the_robot_covered() {
        let o = Overlap { points: 100, explained: 30, contradicted: 2 };
        assert!((o.ratio() - 30.0 / 32.0).abs() < 1e-12);
        assert!((o.explained_share() - 0.3).abs() < 1e-12);
        assert_eq!(Overlap::default().ratio(), 1.0);
    }
}
