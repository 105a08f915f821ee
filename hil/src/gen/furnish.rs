//! Placing furniture in a region without overlaps, leaving its entrance and a walkway free.
//!
//! Convention (the simulator's furniture kinds): an item's back is its local +y side (a sofa's
//! back, a chair's backrest, a desk's modesty panel), so an item against a wall is turned to put
//! +y on that wall.

use crate::gen::layout::Dice;
use crate::gen::plan::{PlanFurniture, Rect, Region};

/// Nothing is placed this close to a region's entrance (the door swing, the way in).
const ENTRANCE_KEEP_M: f64 = 1.3;
/// Gap between an item and the wall it stands against.
const WALL_GAP_M: f64 = 0.04;
/// Tries per item before giving up on it.
const TRIES: usize = 30;

/// The furniture placed so far.
#[derive(Default)]
pub struct Furnisher {
    pub items: Vec<PlanFurniture>,
}

/// Which side of an item goes to the wall: its back (+y), or a bed's headboard end (+x).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Back {
    PlusY,
    PlusX,
}

/// Which side of a region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    South,
    North,
    West,
    East,
}

impl Side {
    pub const ALL: [Side; 4] = [Side::South, Side::North, Side::West, Side::East];

    /// Yaw that puts an item's back (local +y) on this side's wall.
    pub fn yaw_deg(self) -> f64 {
        match self {
            Side::South => 180.0,
            Side::North => 0.0,
            Side::West => 90.0,
            Side::East => -90.0,
        }
    }
}

impl Furnisher {
    fn fits(&self, r: &Rect, region: &Region, margin_m: f64) -> bool {
        if !(region.rect.contains(r.min) && region.rect.contains(r.max)) {
            return false;
        }
        let grown = r.inset(-margin_m);
        if self.items.iter().any(|f| f.rect().overlaps(&grown)) {
            return false;
        }
        region.entrance.is_none_or(|e| distance_to_rect(e, r) > ENTRANCE_KEEP_M)
    }

    /// An item of about `size_m` (each side varied by up to 15 %) with its back to a wall of
    /// `region` (a random side unless given).
    pub fn against_wall(
        &mut self,
        d: &mut Dice,
        region: &Region,
        kind: &'static str,
        size_m: [f64; 3],
        side: Option<Side>,
    ) -> Option<usize> {
        self.on_wall(d, region, (kind, Back::PlusY), size_m, side)
    }

    /// A bed with its headboard (its +x end) to a wall of `region`.
    pub fn bed_against_wall(&mut self, d: &mut Dice, region: &Region, size_m: [f64; 3]) -> Option<usize> {
        self.on_wall(d, region, ("bed", Back::PlusX), size_m, None)
    }

    fn on_wall(
        &mut self,
        d: &mut Dice,
        region: &Region,
        (kind, back): (&'static str, Back),
        size_m: [f64; 3],
        side: Option<Side>,
    ) -> Option<usize> {
        let size_m = vary(d, size_m);
        // Along the wall, and away from it.
        let (along_m, depth_m) = match back {
            Back::PlusY => (size_m[0], size_m[1]),
            Back::PlusX => (size_m[1], size_m[0]),
        };
        for _ in 0..TRIES {
            let side = side.or_else(|| d.pick(&Side::ALL))?;
            let r = region.rect;
            let half = along_m / 2.0;
            let along = |d: &mut Dice, lo: f64, hi: f64| d.range(lo + half, (hi - half).max(lo + half));
            let off = WALL_GAP_M + depth_m / 2.0;
            let at = match side {
                Side::South => [along(d, r.min[0], r.max[0]), r.min[1] + off],
                Side::North => [along(d, r.min[0], r.max[0]), r.max[1] - off],
                Side::West => [r.min[0] + off, along(d, r.min[1], r.max[1])],
                Side::East => [r.max[0] - off, along(d, r.min[1], r.max[1])],
            };
            let turn = if back == Back::PlusX { 90.0 } else { 0.0 };
            let item =
                PlanFurniture { kind, at, yaw_deg: side.yaw_deg() + turn, base_z_m: 0.0, size_m, material: None };
            if self.fits(&item.rect(), region, 0.08) {
                self.items.push(item);
                return Some(self.items.len() - 1);
            }
        }
        None
    }

    /// An item of about `size_m` away from the walls, with `walkway_m` free around it.
    pub fn free_standing(
        &mut self,
        d: &mut Dice,
        region: &Region,
        kind: &'static str,
        size_m: [f64; 3],
        walkway_m: f64,
    ) -> Option<usize> {
        let size_m = vary(d, size_m);
        for _ in 0..TRIES {
            let quarter = d.below(4) as f64;
            let mut item = PlanFurniture {
                kind,
                at: [0.0, 0.0],
                yaw_deg: quarter * 90.0 - 90.0,
                base_z_m: 0.0,
                size_m,
                material: None,
            };
            let size = item.rect().size();
            let inner = region.rect.inset(walkway_m);
            if inner.size()[0] < size[0] || inner.size()[1] < size[1] {
                continue;
            }
            item.at = [
                d.range(inner.min[0] + size[0] / 2.0, inner.max[0] - size[0] / 2.0),
                d.range(inner.min[1] + size[1] / 2.0, inner.max[1] - size[1] / 2.0),
            ];
            if self.fits(&item.rect(), region, walkway_m) {
                self.items.push(item);
                return Some(self.items.len() - 1);
            }
        }
        None
    }

    /// An item at a given place (a row, a grid), if it fits.
    pub fn at(&mut self, region: &Region, item: PlanFurniture, margin_m: f64) -> Option<usize> {
        if self.fits(&item.rect(), region, margin_m) {
            self.items.push(item);
            return Some(self.items.len() - 1);
        }
        None
    }

    /// Whether a disc of `radius_m` at `p` is clear of every item.
    pub fn clear(&self, p: [f64; 2], radius_m: f64) -> bool {
        self.items.iter().all(|f| distance_to_rect(p, &f.rect()) > radius_m)
    }
}

/// Distance from a point to a rectangle (0 inside).
pub fn distance_to_rect(p: [f64; 2], r: &Rect) -> f64 {
    let dx = (r.min[0] - p[0]).max(p[0] - r.max[0]).max(0.0);
    let dy = (r.min[1] - p[1]).max(p[1] - r.max[1]).max(0.0);
    dx.hypot(dy)
}

/// A size with each dimension scaled by 0.85..1.15.
fn vary(d: &mut Dice, size_m: [f64; 3]) -> [f64; 3] {
    [size_m[0] * d.range(0.85, 1.15), size_m[1] * d.range(0.85, 1.15), size_m[2] * d.range(0.9, 1.1)]
}
