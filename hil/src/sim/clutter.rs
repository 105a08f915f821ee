//! Scattered clutter: boxes placed from each clutter table's own seed (the world does not change
//! with the run's seed), never where a person stands or walks. The world and the floor plan
//! place them alike.

use crate::rng::{hash2, SplitMix64};
use crate::sim::scenario::{Clutter, Scenario};

/// A person keeps this far from any clutter box on their spot or their walk.
const PERSON_CLEAR_M: f64 = 0.15;

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
        let (s, c) = self.yaw_rad.sin_cos();
        let (dx, dy) = (p[0] - self.centre[0], p[1] - self.centre[1]);
        let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
        let ox = (lx.abs() - self.size_m[0] / 2.0).max(0.0);
        let oy = (ly.abs() - self.size_m[1] / 2.0).max(0.0);
        ox.hypot(oy)
    }
}

/// Every clutter box of the scenario that no person stands on or walks through.
pub fn placed(s: &Scenario) -> Vec<ClutterItem> {
    let routes: Vec<Vec<[f64; 2]>> = s
        .people
        .iter()
        .map(|p| {
            let p = p.get_ref();
            std::iter::once(p.at).chain(p.path.iter().copied()).collect()
        })
        .collect();
    s.clutter
        .iter()
        .enumerate()
        .flat_map(|(i, c)| drawn(c.get_ref(), i))
        .filter(|item| routes.iter().all(|r| !meets(item, r)))
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

/// Whether a person's spot or walk (`route`) comes within `PERSON_CLEAR_M` of the box.
fn meets(item: &ClutterItem, route: &[[f64; 2]]) -> bool {
    let near = |p: [f64; 2]| item.distance_m(p) < PERSON_CLEAR_M;
    if route.len() == 1 {
        return near(route[0]);
    }
    route.windows(2).any(|pair| {
        let (a, b) = (pair[0], pair[1]);
        let steps = ((b[0] - a[0]).hypot(b[1] - a[1]) / 0.02).ceil().max(1.0) as usize;
        (0..=steps).any(|k| {
            let t = k as f64 / steps as f64;
            near([a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t])
        })
    })
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
