//! Scattered clutter: boxes placed from each clutter table's own seed (the world does not change
//! with the run's seed), never where a person stands or walks. The world and the floor plan
//! place them alike.

use crate::rng::{hash2, SplitMix64};
use crate::sim::obstacles::{rect_distance_m, segment_points};
use crate::sim::scenario::{Clutter, PoseKind, Scenario};

/// A person keeps this far from any clutter box on their spot or their walk: a shoulder's
/// half width, and a lying person's half length (a lying person's spot is their pelvis).
const PERSON_CLEAR_M: f64 = 0.35;
const LYING_CLEAR_M: f64 = 1.0;

/// One clutter box: footprint centre, size (length, width, height) and yaw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClutterItem {
    pub centre: [f64; 2],
    pub size_m: [f64; 3],
    pub yaw_rad: f64,
    /// Which clutter table of the scenario it came from.
    pub table: usize,
}

impl ClutterItem {
    /// Distance from a point to the box's footprint (0 inside).
    pub fn distance_m(&self, p: [f64; 2]) -> f64 {
        rect_distance_m(self.centre, [self.size_m[0] / 2.0, self.size_m[1] / 2.0], self.yaw_rad, p)
    }
}

/// Every clutter box of the scenario that no person stands on or walks through.
pub fn placed(s: &Scenario) -> Vec<ClutterItem> {
    let routes: Vec<(Vec<[f64; 2]>, f64)> = s
        .people
        .iter()
        .map(|p| {
            let p = p.get_ref();
            let clear_m = if p.pose == PoseKind::Lying { LYING_CLEAR_M } else { PERSON_CLEAR_M };
            (std::iter::once(p.at).chain(p.path.iter().copied()).collect(), clear_m)
        })
        .collect();
    s.clutter
        .iter()
        .enumerate()
        .flat_map(|(i, c)| drawn(c.get_ref(), i))
        .filter(|item| routes.iter().all(|(r, clear_m)| !meets(item, r, *clear_m)))
        .collect()
}

/// The boxes of the `table`-th clutter table, as its seed draws them.
fn drawn(c: &Clutter, table: usize) -> Vec<ClutterItem> {
    let mut rng = SplitMix64::new(hash2(c.seed, table as u64));
    (0..c.count)
        .map(|_| {
            let mut size = || c.size_min_m + rng.next_f64() * (c.size_max_m - c.size_min_m);
            let size_m = [size(), size(), size()];
            let x = c.min[0] + rng.next_f64() * (c.max[0] - c.min[0]);
            let y = c.min[1] + rng.next_f64() * (c.max[1] - c.min[1]);
            let yaw_rad = rng.next_f64() * std::f64::consts::PI;
            ClutterItem { centre: [x, y], size_m, yaw_rad, table }
        })
        .collect()
}

/// Whether a person's spot or walk (`route`) comes within `clear_m` of the box.
fn meets(item: &ClutterItem, route: &[[f64; 2]], clear_m: f64) -> bool {
    let near = |p: [f64; 2]| item.distance_m(p) < clear_m;
    match route {
        [only] => near(*only),
        _ => route.windows(2).any(|pair| segment_points(pair[0], pair[1], 0.02).any(near)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clutter_keeps_off_people_and_their_walks() {
        let base = "name = \"t\"\n[[clutter]]\nmin = [0, 0]\nmax = [4, 4]\ncount = 60\nseed = 3\n[robot]\nwaypoints = [[9, 9, 0]]\n[responder]\nwaypoints = [[9, 8]]\n";
        let parse = |t: &str| match Scenario::parse(t, "t") {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        };
        let alone = placed(&parse(base));
        assert_eq!(alone.len(), 60);
        let walker = format!("{base}[[people]]\nname = \"w\"\nat = [0, 2]\npath = [[4, 2]]\n");
        let kept = placed(&parse(&walker));
        assert!(kept.len() < 60 && !kept.is_empty(), "{}", kept.len());
        assert!(kept.iter().all(|c| (0..=40).all(|k| c.distance_m([f64::from(k) * 0.1, 2.0]) >= PERSON_CLEAR_M)));
        // The boxes that stay are the same boxes, where they were.
        assert!(kept.iter().all(|c| alone.contains(c)));
    }
}
