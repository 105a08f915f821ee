//! Floor-plan pieces the families share: a seeded builder of walls and regions, and a corridor
//! with rooms off one or both sides.

use crate::gen::plan::{PlanDoor, PlanWall, PlanWindow, Rect, Region};
use crate::rng::SplitMix64;

/// Random choices, all from one seed.
pub struct Dice(pub SplitMix64);

impl Dice {
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + self.0.next_f64() * (hi - lo)
    }
    pub fn chance(&mut self, p: f64) -> bool {
        self.0.next_f64() < p
    }
    pub fn below(&mut self, n: usize) -> usize {
        self.0.below(n as u64) as usize
    }
    pub fn pick<T: Copy>(&mut self, items: &[T]) -> Option<T> {
        (!items.is_empty()).then(|| items[self.below(items.len())])
    }
    /// Whole count in `lo..=hi`.
    pub fn count(&mut self, lo: usize, hi: usize) -> usize {
        lo + self.below(hi.saturating_sub(lo) + 1)
    }
}

/// The building's shell settings.
#[derive(Clone, Copy, Debug)]
pub struct Shell {
    pub height_m: f64,
    pub outer_thickness_m: f64,
    pub inner_thickness_m: f64,
    pub outer_material: &'static str,
    pub inner_material: &'static str,
}

impl Shell {
    pub fn random(d: &mut Dice, height_m: f64) -> Self {
        Shell {
            height_m,
            outer_thickness_m: d.range(0.18, 0.32),
            inner_thickness_m: d.range(0.08, 0.16),
            outer_material: d.pick(&["concrete", "brick", "drywall"]).unwrap_or("concrete"),
            inner_material: d.pick(&["drywall", "drywall", "brick", "wood"]).unwrap_or("drywall"),
        }
    }

    pub fn wall(&self, from: [f64; 2], to: [f64; 2], outer: bool) -> PlanWall {
        PlanWall {
            from,
            to,
            thickness_m: if outer { self.outer_thickness_m } else { self.inner_thickness_m },
            height_m: self.height_m,
            material: if outer { self.outer_material } else { self.inner_material },
            doors: Vec::new(),
            windows: Vec::new(),
        }
    }
}

/// The four outer walls of `r`, with windows in some.
pub fn outer_walls(d: &mut Dice, shell: &Shell, r: Rect) -> Vec<PlanWall> {
    let corners = [r.min, [r.max[0], r.min[1]], r.max, [r.min[0], r.max[1]]];
    (0..4)
        .map(|i| {
            let mut w = shell.wall(corners[i], corners[(i + 1) % 4], true);
            let len = (w.to[0] - w.from[0]).hypot(w.to[1] - w.from[1]);
            if len > 3.0 && d.chance(0.5) && shell.height_m > 2.3 {
                let width_m = d.range(0.8, 1.6).min(len - 1.5);
                let height_m = (shell.height_m - 1.3).clamp(0.6, 1.4);
                w.windows.push(PlanWindow { at_m: d.range(1.0, len - 1.0), width_m, sill_m: 0.9, height_m });
                fit_openings(&mut w);
            }
            w
        })
        .collect()
}

/// A corridor along x with rooms off it.
#[derive(Clone, Debug)]
pub struct CorridorSpec {
    pub length_m: f64,
    pub width_m: f64,
    /// Room widths along x on the north side (y > corridor) and the south side; the last room
    /// on each side takes what is left of the length.
    pub north: Vec<f64>,
    pub north_depth_m: f64,
    pub south: Vec<f64>,
    pub south_depth_m: f64,
    pub door_width_m: (f64, f64),
    /// Chance that a room's door is closed (the robot only visits rooms with open doors).
    pub closed_door_chance: f64,
}

/// What a corridor layout made.
pub struct CorridorLayout {
    pub outline: Rect,
    pub walls: Vec<PlanWall>,
    pub corridor: Region,
    pub rooms: Vec<Region>,
}

/// Builds the corridor and its rooms; the corridor runs from x = 0 to `length_m` at y 0..width.
pub fn corridor_with_rooms(d: &mut Dice, shell: &Shell, spec: &CorridorSpec, prefix: &str) -> CorridorLayout {
    let (cw, l) = (spec.width_m, spec.length_m);
    let south_depth = if spec.south.is_empty() { 0.0 } else { spec.south_depth_m };
    let north_depth = if spec.north.is_empty() { 0.0 } else { spec.north_depth_m };
    let outline = Rect::new([0.0, -south_depth], [l, cw + north_depth]);
    let mut walls = outer_walls(d, shell, outline);
    let half_in = shell.inner_thickness_m / 2.0;
    let half_out = shell.outer_thickness_m / 2.0;
    let mut rooms = Vec::new();
    for (side, widths, depth) in [(1.0, &spec.north, north_depth), (-1.0, &spec.south, south_depth)] {
        if widths.is_empty() {
            continue;
        }
        let wall_y = if side > 0.0 { cw } else { 0.0 };
        let far_y = wall_y + side * depth;
        let mut corridor_wall = shell.wall([0.0, wall_y], [l, wall_y], false);
        let mut x0 = 0.0;
        for (i, &w) in widths.iter().enumerate() {
            let x1 = if i + 1 == widths.len() { l } else { (x0 + w).min(l) };
            if x1 - x0 < 1.5 {
                break;
            }
            if x1 < l {
                walls.push(shell.wall([x1, wall_y], [x1, far_y], false));
            }
            let lo_x = x0 + if x0 > 0.0 { half_in } else { half_out };
            let hi_x = x1 - if x1 < l { half_in } else { half_out };
            let (y_a, y_b) = (wall_y + side * half_in, far_y - side * half_out);
            let rect = Rect::new([lo_x, y_a.min(y_b)], [hi_x, y_a.max(y_b)]);
            let door_w = d.range(spec.door_width_m.0, spec.door_width_m.1);
            let at = d.range(lo_x + door_w / 2.0 + 0.3, (hi_x - door_w / 2.0 - 0.3).max(lo_x + door_w / 2.0 + 0.3));
            let open = !d.chance(spec.closed_door_chance);
            corridor_wall.doors.push(PlanDoor { at_m: at, width_m: door_w, open });
            if d.chance(0.25) && rect.size()[0] > 3.5 {
                // A window on the far side of the room's door.
                let at_m = if at - lo_x > hi_x - at { lo_x + 1.2 } else { hi_x - 1.2 };
                let width_m = d.range(0.8, 1.5);
                corridor_wall.windows.push(PlanWindow { at_m, width_m, sill_m: 1.0, height_m: 0.8 });
            }
            rooms.push(Region {
                name: format!("{prefix}{}{}", if side > 0.0 { "n" } else { "s" }, i + 1),
                rect,
                entrance: Some([at, wall_y]),
                walled: true,
            });
            x0 = x1;
        }
        fit_openings(&mut corridor_wall);
        walls.push(corridor_wall);
    }
    let corridor_rect = Rect::new(
        [half_out, if spec.south.is_empty() { half_out } else { half_in }],
        [l - half_out, cw - if spec.north.is_empty() { half_out } else { half_in }],
    );
    let corridor = Region { name: "corridor".into(), rect: corridor_rect, entrance: None, walled: true };
    CorridorLayout { outline, walls, corridor, rooms }
}

/// Drops windows that overlap a door or each other, or do not fit the wall.
pub fn fit_openings(w: &mut PlanWall) {
    let len = (w.to[0] - w.from[0]).hypot(w.to[1] - w.from[1]);
    let doors: Vec<(f64, f64)> = w.doors.iter().map(|d| (d.at_m - d.width_m / 2.0, d.at_m + d.width_m / 2.0)).collect();
    let mut taken = doors.clone();
    w.windows.retain(|o| {
        let (a, b) = (o.at_m - o.width_m / 2.0, o.at_m + o.width_m / 2.0);
        let fits = a > 0.2 && b < len - 0.2 && o.sill_m + o.height_m < w.height_m - 0.05;
        let clear = taken.iter().all(|&(c, e)| b + 0.2 < c || a > e + 0.2);
        if fits && clear {
            taken.push((a, b));
        }
        fits && clear
    });
}

/// Widths that fill `total` with rooms of `lo..hi` metres.
pub fn room_widths(d: &mut Dice, total: f64, lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut left = total;
    while left > hi {
        let w = d.range(lo, hi);
        out.push(w);
        left -= w;
    }
    if left >= lo * 0.7 || out.is_empty() {
        out.push(left);
    } else if let Some(last) = out.last_mut() {
        *last += left;
    }
    out
}
