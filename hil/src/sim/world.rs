//! The scene a scenario describes, as solids: the building's boxes, cylinders and capsules
//! (walls, floors, boxes, clutter, furniture) in a BVH and the people posed at any instant; one
//! ray-casting entry point for the LiDARs and the camera.

use crate::sim::bvh::Bvh;
use crate::sim::human::Body;
use crate::sim::motion::PersonMotion;
use crate::sim::scenario::{DoorState, PoseKind, Scenario};
use crate::sim::shapes::{Hit, Solid, YawBox, V3};

/// Thickness of floor and ceiling slabs.
const SLAB_M: f64 = 0.2;
/// Thickness of a closed door leaf.
const DOOR_LEAF_M: f64 = 0.04;

/// One person of the scenario.
#[derive(Clone, Debug)]
pub struct PersonModel {
    pub label: u16,
    pub name: String,
    pub pose: PoseKind,
    pub height_m: f64,
    /// Width scale of the body (1 = average).
    pub build: f64,
    pub base_z_m: f64,
    pub motion: PersonMotion,
}

impl PersonModel {
    pub fn body_at(&self, t: f64) -> Body {
        let (x, y, yaw, swing) = self.motion.at(t);
        let at = V3::new(x, y, self.base_z_m);
        Body::with_build(self.label, self.pose, self.height_m, self.build, at, yaw, swing)
    }
}

/// The static building and the people.
#[derive(Clone, Debug)]
pub struct World {
    pub building: Bvh,
    pub people: Vec<PersonModel>,
}

impl World {
    pub fn new(s: &Scenario) -> Self {
        let albedo = |m: &str| s.albedo(m).unwrap_or(0.5) as f32;
        let mut boxes = Vec::new();
        for f in &s.floors {
            let f = f.get_ref();
            let (cx, cy) = ((f.min[0] + f.max[0]) / 2.0, (f.min[1] + f.max[1]) / 2.0);
            let (lx, ly) = (f.max[0] - f.min[0], f.max[1] - f.min[1]);
            boxes.push(YawBox::new(
                V3::new(cx, cy, f.z_m - SLAB_M / 2.0),
                V3::new(lx, ly, SLAB_M),
                0.0,
                albedo(&f.material),
            ));
            if let Some(c) = f.ceiling_m {
                boxes.push(YawBox::new(
                    V3::new(cx, cy, f.z_m + c + SLAB_M / 2.0),
                    V3::new(lx, ly, SLAB_M),
                    0.0,
                    albedo(&f.ceiling_material),
                ));
            }
        }
        for w in &s.walls {
            let w = w.get_ref();
            let (dx, dy) = (w.to[0] - w.from[0], w.to[1] - w.from[1]);
            let len = dx.hypot(dy);
            if len <= 0.0 {
                continue;
            }
            let yaw = dy.atan2(dx);
            let (ux, uy) = (dx / len, dy / len);
            let a = albedo(&w.material);
            // A piece of wall from `s0` to `s1` along it and `z0` to `z1` above its base.
            let mut piece = |s0: f64, s1: f64, z0: f64, z1: f64, thick: f64, albedo: f32| {
                if s1 - s0 > 1e-6 && z1 - z0 > 1e-6 {
                    let mid = (s0 + s1) / 2.0;
                    boxes.push(YawBox::new(
                        V3::new(w.from[0] + ux * mid, w.from[1] + uy * mid, w.base_z_m + (z0 + z1) / 2.0),
                        V3::new(s1 - s0, thick, z1 - z0),
                        yaw,
                        albedo,
                    ));
                }
            };
            // Openings sorted along the wall: (start, end, bottom, top, closed door?).
            let mut cuts: Vec<(f64, f64, f64, f64, bool)> = w
                .doors
                .iter()
                .map(|d| {
                    (d.at_m - d.width_m / 2.0, d.at_m + d.width_m / 2.0, 0.0, d.height_m, d.state == DoorState::Closed)
                })
                .chain(w.windows.iter().map(|o| {
                    (o.at_m - o.width_m / 2.0, o.at_m + o.width_m / 2.0, o.sill_m, o.sill_m + o.height_m, false)
                }))
                .collect();
            cuts.sort_by(|p, q| p.0.total_cmp(&q.0));
            let mut s0 = 0.0;
            for &(c0, c1, bottom, top, closed) in &cuts {
                piece(s0, c0, 0.0, w.height_m, w.thickness_m, a);
                piece(c0, c1, 0.0, bottom, w.thickness_m, a);
                piece(c0, c1, top, w.height_m, w.thickness_m, a);
                if closed {
                    piece(c0, c1, bottom, top, DOOR_LEAF_M, albedo("door"));
                }
                s0 = c1;
            }
            piece(s0, len, 0.0, w.height_m, w.thickness_m, a);
        }
        for b in &s.boxes {
            let b = b.get_ref();
            for i in 0..b.count {
                let k = f64::from(i);
                let centre = V3::new(
                    b.at[0] + k * b.step_m[0],
                    b.at[1] + k * b.step_m[1],
                    b.base_z_m + k * b.step_m[2] + b.size_m[2] / 2.0,
                );
                boxes.push(YawBox::new(centre, V3::from(b.size_m), b.yaw_deg.to_radians(), albedo(&b.material)));
            }
        }
        for item in crate::sim::clutter::placed(s) {
            let [x, y] = item.centre;
            let [l, w, h] = item.size_m;
            let material = s.clutter.get(item.table).map_or("cardboard", |c| c.get_ref().material.as_str());
            boxes.push(YawBox::new(V3::new(x, y, h / 2.0), V3::new(l, w, h), item.yaw_rad, albedo(material)));
        }
        let people = s
            .people
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let p = p.get_ref();
                PersonModel {
                    label: (i + 1) as u16,
                    name: p.name.clone(),
                    pose: p.pose,
                    height_m: p.height_m,
                    build: p.build,
                    base_z_m: p.base_z_m,
                    motion: PersonMotion::new(p),
                }
            })
            .collect();
        // Furniture after every box, so a scene without any builds the tree it always did.
        let mut solids: Vec<Solid> = boxes.into_iter().map(Solid::Box).collect();
        for f in &s.furniture {
            solids.extend(f.get_ref().solids(albedo));
        }
        Self { building: Bvh::build(solids), people }
    }

    /// Everyone posed at time `t` (s).
    pub fn bodies_at(&self, t: f64) -> Vec<Body> {
        self.people.iter().map(|p| p.body_at(t)).collect()
    }

    /// The nearest surface along a unit ray, building and `bodies` alike.
    #[inline]
    pub fn cast(&self, o: &V3, d: &V3, t_max: f64, bodies: &[Body]) -> Option<Hit> {
        let inv = d.map(|v| 1.0 / v);
        let mut best = self.building.cast_inv(o, d, &inv, t_max);
        let mut limit = best.map_or(t_max, |h| h.t);
        for b in bodies {
            if let Some(h) = b.cast(o, d, &inv, limit) {
                limit = h.t;
                best = Some(h);
            }
        }
        best
    }

    /// The nearest person along a unit ray, looking through walls.
    pub fn cast_people(o: &V3, d: &V3, t_max: f64, bodies: &[Body]) -> Option<Hit> {
        let inv = d.map(|v| 1.0 / v);
        let mut best: Option<Hit> = None;
        let mut limit = t_max;
        for b in bodies {
            if let Some(h) = b.cast(o, d, &inv, limit) {
                limit = h.t;
                best = Some(h);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doors_open_and_closed() {
        let text = r#"
name = "t"
[[floors]]
min = [-10, -10]
max = [10, 10]
ceiling_m = 3.0
[[walls]]
from = [5, -5]
to = [5, 5]
doors = [{ at_m = 5.0, state = "open" }, { at_m = 8.0, state = "closed" }]
[[people]]
name = "behind"
at = [8, 0]
yaw_deg = 180
[robot]
waypoints = [[0, 0, 0]]
[responder]
waypoints = [[1, 1]]
"#;
        let s = match Scenario::parse(text, "t") {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        };
        let world = World::new(&s);
        let bodies = world.bodies_at(0.0);
        let o = V3::new(0.0, 0.0, 1.2);
        // Through the open door (centred at y = 0) to the person.
        let hit = world.cast(&o, &V3::x(), 100.0, &bodies).map(|h| (h.label, h.t));
        assert!(matches!(hit, Some((1, t)) if (t - 7.88).abs() < 0.05), "{hit:?}");
        // Through the closed door (y = 3): the door leaf, in the wall's middle.
        let d = V3::new(5.0, 3.0, 0.0).normalize();
        let hit = world.cast(&o, &d, 100.0, &bodies).map(|h| (h.label, h.t));
        let expected = (5.0 - 0.02) / d.x;
        assert!(matches!(hit, Some((0, t)) if (t - expected).abs() < 1e-6), "{hit:?}");
        // Beside the doors: the wall's face.
        let d = V3::new(5.0, -3.0, 0.0).normalize();
        let hit = world.cast(&o, &d, 100.0, &bodies).map(|h| h.t);
        assert!(matches!(hit, Some(t) if (t - (5.0 - 0.06) / d.x).abs() < 1e-6), "{hit:?}");
        // Up: the ceiling.
        let hit = world.cast(&o, &V3::z(), 100.0, &bodies).map(|h| h.t);
        assert!(matches!(hit, Some(t) if (t - 1.8).abs() < 1e-9), "{hit:?}");
        // The person seen through the wall beside the open door.
        let d = (V3::new(8.0, 0.1, 1.2) - o).normalize();
        assert!(World::cast_people(&o, &d, 100.0, &bodies).is_some());
    }
    #[test]
    fn table_top_legs_and_a_pillar() {
        let text = r#"
name = "t"
[[floors]]
min = [-10, -10]
max = [10, 10]
[[furniture]]
kind = "table"
at = [3, 0]
[[furniture]]
kind = "pillar"
at = [-4, 2]
size_m = [0.5, 0.5, 3.0]
[robot]
waypoints = [[0, 0, 0]]
[responder]
waypoints = [[1, 1]]
"#;
        let world = match Scenario::parse(text, "t") {
            Ok(s) => World::new(&s),
            Err(e) => panic!("{e}"),
        };
        let down = -V3::z();
        // From above onto the 0.75 m top, wood albedo.
        let hit = world.cast(&V3::new(3.2, 0.1, 2.0), &down, 10.0, &[]).map(|h| (h.t, h.albedo, h.normal));
        assert!(matches!(hit, Some((t, a, n)) if (t - 1.25).abs() < 1e-9 && a == 0.45 && n == V3::z()), "{hit:?}");
        // Below the top, between the legs (1.4 x 0.8 m table): through to the floor at z = 0.
        let hit = world.cast(&V3::new(3.0, 0.0, 0.5), &down, 10.0, &[]).map(|h| h.t);
        assert!(matches!(hit, Some(t) if (t - 0.5).abs() < 1e-9), "{hit:?}");
        // A leg near a corner (legs 5 cm square, 4 cm in from the edges).
        let hit = world.cast(&V3::new(3.0 + 0.7 - 0.065, -1.0, 0.5), &V3::y(), 10.0, &[]).map(|h| h.t);
        assert!(matches!(hit, Some(t) if (t - (1.0 - 0.4 + 0.04)).abs() < 1e-9), "{hit:?}");
        let hit = world.cast(&V3::new(3.0, -1.0, 0.5), &V3::y(), 10.0, &[]);
        assert!(hit.is_none(), "{hit:?}");
        // The pillar's curved side: off its axis by 0.15 m, the 0.25 m radius is 0.2 m nearer.
        let o = V3::new(0.0, 2.15, 1.5);
        let hit = world.cast(&o, &-V3::x(), 10.0, &[]).map(|h| (h.t, h.normal));
        let n = V3::new(0.8, 0.6, 0.0);
        assert!(matches!(hit, Some((t, m)) if (t - 3.8).abs() < 1e-9 && (m - n).norm() < 1e-9), "{hit:?}");
        assert_eq!(world.building.len(), 1 + 5 + 1);
    }
}
