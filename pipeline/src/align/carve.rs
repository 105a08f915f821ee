//! Moving points of a window, found by the rays that passed where they had been.
//!
//! A walker's points stand in voxels that other rays of the window, fired after they left (or
//! before they came), crossed on their way to something farther. A static surface is never
//! crossed while it is in sight: whenever a ray grazes one of its voxels, others end in it. So a
//! voxel is moving when something was seen in it only briefly and rays crossed it in time slices
//! in which nothing was seen in it. (Counting crossings against hits over the whole window took
//! a quarter of every window for moving: rays grazing the far floor cross its voxels more often
//! than they end there. Without the brevity test, half of a house's ceiling went: its sparse far
//! voxels are not hit in every half second that rays graze them.)

use super::free_space::Ray;
use super::geometry::Vec3;
use crate::voxel_hash::{key_of, Key, KeyMap};

/// A ray longer than this many voxels is walked only this far (a bound on the work per ray).
const MAX_STEPS: usize = 4096;

/// The voxels (of `voxel_m`) seen in at most `max_seen` slices that rays crossed at least
/// `min_rays` times in slices in which nothing was seen in them; `occupied` has, per voxel, a
/// bit per slice that saw a point in it. Each ray comes with its slice (0..64). The first `near_m` of a ray (the rig, its operator) and its last one
/// and a half voxels (the surface it hit, with its noise) do not count as crossed.
pub fn seen_through(
    rays: &[(u32, Ray)],
    occupied: &KeyMap<u64>,
    voxel_m: f64,
    near_m: f64,
    min_rays: u32,
    max_seen: u32,
) -> KeyMap<u32> {
    let voxel_m = voxel_m.max(1e-3);
    let inv = 1.0 / voxel_m;
    let mut crossed: KeyMap<u32> = KeyMap::default();
    for (slice, r) in rays {
        if !(r.origin.iter().chain(r.end.iter()).all(|v| v.is_finite())) {
            continue;
        }
        let d = r.end - r.origin;
        let len = d.norm();
        let stop = len - 1.5 * voxel_m;
        if stop <= near_m {
            continue;
        }
        let dir = d / len;
        let bit = 1u64 << (*slice).min(63);
        walk(&(r.origin + dir * near_m), &dir, (stop - near_m) * inv, inv, |k| {
            if occupied.get(&k).is_some_and(|m| m & bit == 0 && m.count_ones() <= max_seen) {
                *crossed.entry(k).or_insert(0) += 1;
            }
        });
    }
    crossed.retain(|_, n| *n >= min_rays.max(1));
    crossed
}

/// Visits the voxels a segment passes through (Amanatides and Woo): from `start` along the unit
/// `dir` for `cells` voxel lengths, in voxels of `1 / inv`.
fn walk(start: &Vec3, dir: &Vec3, cells: f64, inv: f64, mut visit: impl FnMut(Key)) {
    let p = start * inv;
    let mut key = key_of(start, inv);
    let mut cell = [key.0, key.1, key.2];
    let mut step = [0i32; 3];
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for a in 0..3 {
        if dir[a] > 0.0 {
            step[a] = 1;
            t_max[a] = (f64::from(cell[a]) + 1.0 - p[a]) / dir[a];
            t_delta[a] = 1.0 / dir[a];
        } else if dir[a] < 0.0 {
            step[a] = -1;
            t_max[a] = (p[a] - f64::from(cell[a])) / -dir[a];
            t_delta[a] = -1.0 / dir[a];
        }
    }
    for _ in 0..MAX_STEPS {
        visit(key);
        let a = if t_max[0] <= t_max[1] && t_max[0] <= t_max[2] {
            0
        } else if t_max[1] <= t_max[2] {
            1
        } else {
            2
        };
        if t_max[a] >= cells {
            break;
        }
        cell[a] = cell[a].saturating_add(step[a]);
        t_max[a] += t_delta[a];
        key = (cell[0], cell[1], cell[2]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ray(o: [f64; 3], e: [f64; 3]) -> Ray {
        Ray { origin: Vec3::from(o), end: Vec3::from(e) }
    }

    #[test]
    fn a_walk_visits_the_voxels_between_its_ends_in_order() {
        let mut seen = Vec::new();
        walk(&Vec3::new(0.05, 0.05, 0.05), &Vec3::x(), 3.5, 10.0, |k| seen.push(k));
        assert_eq!(seen, vec![(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0)]);
        // Diagonal in the plane: every voxel it enters, each once.
        let mut diag = Vec::new();
        let dir = Vec3::new(1.0, 1.0, 0.0).normalize();
        walk(&Vec3::new(0.05, 0.02, 0.05), &dir, 2.0, 10.0, |k| diag.push(k));
        assert_eq!(diag.first(), Some(&(0, 0, 0)));
        for w in diag.windows(2) {
            let (a, b) = (w[0], w[1]);
            assert_eq!((b.0 - a.0) + (b.1 - a.1), 1, "one step at a time: {diag:?}");
        }
        assert!(diag.len() >= 3 && diag.len() <= 4, "{diag:?}");
    }

    #[test]
    fn where_a_walker_stood_is_seen_through_and_a_wall_is_not() {
        let inv = 1.0 / 0.3;
        let walker = Vec3::new(5.0, 0.0, 1.0);
        let wall = Vec3::new(10.0, 0.0, 1.0);
        let far_floor = Vec3::new(8.0, 0.0, -0.5);
        // Slice 0: the walker stands at x = 5 and the wall is seen around them. Slices 1-2: the
        // walker has gone; rays pass where they stood on to the wall; rays graze the floor.
        let mut occupied: KeyMap<u64> = KeyMap::default();
        for (p, mask) in [(walker, 0b001), (wall, 0b111), (far_floor, 0b110)] {
            occupied.insert(key_of(&p, inv), mask);
        }
        let mut rays = Vec::new();
        for i in 0..10 {
            let y = -0.1 + 0.02 * f64::from(i);
            rays.push((0, ray([0.0, 0.0, 1.0], [5.0, y, 1.0])));
            rays.push((1, ray([0.0, 0.0, 1.0], [10.0, y, 1.0])));
            rays.push((2, ray([0.0, 0.0, 1.0], [10.0, y, 1.0])));
            // Grazing the floor's voxel at x = 8 on their way to x = 9, in slices that saw it.
            rays.push((1 + i % 2, ray([0.0, 0.0, 1.0], [9.0, y, -0.55])));
        }
        let through = seen_through(&rays, &occupied, 0.3, 0.5, 2, 2);
        assert!(through.contains_key(&key_of(&walker, inv)), "the walker's voxel");
        assert!(!through.contains_key(&key_of(&wall, inv)), "the wall");
        assert!(!through.contains_key(&key_of(&far_floor, inv)), "the floor, grazed while in view");
        // Had the floor been out of sight in slice 1, the grazing rays would have seen through it.
        occupied.insert(key_of(&far_floor, inv), 0b100);
        let grazed = seen_through(&rays, &occupied, 0.3, 0.5, 2, 2);
        assert!(grazed.contains_key(&key_of(&far_floor, inv)));
        // Seen in more slices than a walker stays, it stays however it is crossed.
        let walker_key = key_of(&walker, inv);
        occupied.insert(walker_key, 0b1000_1001);
        let long = seen_through(&rays, &occupied, 0.3, 0.5, 2, 2);
        assert!(!long.contains_key(&walker_key));
    }

    #[test]
    fn bad_rays_count_for_nothing() {
        let rays = vec![
            ray([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]),
            ray([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
            ray([0.0, 0.0, 0.0], [1e12, 0.0, 0.0]),
        ];
        let mut occupied: KeyMap<u64> = KeyMap::default();
        occupied.insert((1, 0, 0), 0b10);
        let rays: Vec<(u32, Ray)> = rays.into_iter().map(|r| (0, r)).collect();
        let through = seen_through(&rays, &occupied, 0.3, 0.5, 1, 2);
        assert!(through.len() <= 1);
    }
}
