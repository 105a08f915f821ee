//! The parts of each furniture kind, in the item's own frame: x along its length, y across it
//! (a back, a backrest or a seat row's backs on the +y side; a bed's headboard at the +x end),
//! z up from its base. Every part lies within [-l/2, l/2] x [-w/2, w/2] x [0, h], whatever the
//! size: thin parts keep their real thickness (a 5 cm leg stays 5 cm on a longer table) and
//! shrink only when the size leaves no room for it.

use super::FurnitureKind;
use crate::rng::SplitMix64;
use crate::sim::shapes::V3;

/// Whose albedo a part takes: the item's material, or a fixed one (a mattress, a coat, leaves).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mat {
    Main,
    Named(&'static str),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Shape {
    /// An axis-aligned box in the item's frame, by its corners.
    Box { min: V3, max: V3 },
    /// A vertical cylinder about (x, y).
    Cylinder { x: f64, y: f64, r: f64, z0: f64, z1: f64 },
    /// A capsule (a sphere when `a` = `b`).
    Capsule { a: V3, b: V3, r: f64 },
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Part {
    pub shape: Shape,
    pub mat: Mat,
}

/// The item's bounding size and its halves.
#[derive(Clone, Copy, Debug)]
struct Dims {
    l: f64,
    w: f64,
    h: f64,
    hl: f64,
    hw: f64,
}

impl Dims {
    fn new([l, w, h]: [f64; 3]) -> Self {
        Self { l, w, h, hl: l / 2.0, hw: w / 2.0 }
    }
    /// The largest radius a round part centred on the footprint may have.
    fn m(&self) -> f64 {
        self.hl.min(self.hw)
    }
}

/// Collects parts.
#[derive(Default)]
struct Parts(Vec<Part>);

impl Parts {
    /// A box by its footprint centre and size, from `z0` to `z1`.
    fn block(&mut self, (x, y): (f64, f64), (lx, ly): (f64, f64), (z0, z1): (f64, f64), mat: Mat) {
        let (min, max) = (V3::new(x - lx / 2.0, y - ly / 2.0, z0), V3::new(x + lx / 2.0, y + ly / 2.0, z1));
        self.0.push(Part { shape: Shape::Box { min, max }, mat });
    }
    fn cylinder(&mut self, (x, y): (f64, f64), r: f64, (z0, z1): (f64, f64), mat: Mat) {
        self.0.push(Part { shape: Shape::Cylinder { x, y, r, z0, z1 }, mat });
    }
    fn capsule(&mut self, a: [f64; 3], b: [f64; 3], r: f64, mat: Mat) {
        self.0.push(Part { shape: Shape::Capsule { a: V3::from(a), b: V3::from(b), r }, mat });
    }
    /// Four square legs of side `leg`, their outer faces `inset` in from the footprint's edges.
    fn legs(&mut self, d: &Dims, leg: f64, inset: f64, z1: f64, mat: Mat) {
        let (x, y) = (d.hl - inset - leg / 2.0, d.hw - inset - leg / 2.0);
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            self.block((sx * x, sy * y), (leg, leg), (0.0, z1), mat);
        }
    }
}

/// The parts of a `kind` at `size_m`; `seed` places what varies (items on shelves, rack loads).
pub(super) fn parts(kind: FurnitureKind, size_m: [f64; 3], seed: u64) -> Vec<Part> {
    let d = Dims::new(size_m);
    let mut p = Parts::default();
    let mut rng = SplitMix64::new(seed);
    use FurnitureKind as K;
    match kind {
        K::Chair => chair(&mut p, &d),
        K::Table => table(&mut p, &d, 0.05, 0.03),
        K::RoundTable => round_table(&mut p, &d),
        K::Desk => desk(&mut p, &d),
        K::Sofa => sofa(&mut p, &d),
        K::Bed => bed(&mut p, &d),
        K::Shelving => shelving(&mut p, &d, &mut rng),
        K::Rack => rack(&mut p, &d, &mut rng),
        K::Pillar | K::Pole | K::Bin => p.cylinder((0.0, 0.0), d.m(), (0.0, d.h), Mat::Main),
        K::Plant => plant(&mut p, &d),
        K::CoatStand => coat_stand(&mut p, &d),
        K::FloorLamp => floor_lamp(&mut p, &d),
        K::Radiator => radiator(&mut p, &d),
        K::Bench => table(&mut p, &d, 0.05, 0.04),
        K::Pallet => pallet(&mut p, &d),
        K::PalletStack => pallet_stack(&mut p, &d),
        K::Mannequin => mannequin(&mut p, &d),
        K::CubicleWall => cubicle_wall(&mut p, &d),
        K::KitchenIsland => kitchen_island(&mut p, &d),
        K::SeatRow => seat_row(&mut p, &d),
        K::Cabinet | K::Box => p.block((0.0, 0.0), (d.l, d.w), (0.0, d.h), Mat::Main),
    }
    p.0
}

/// Four legs, a seat at half the height, and a backrest on two back posts above it.
fn chair(p: &mut Parts, d: &Dims) {
    let seat_z = 0.5 * d.h;
    let seat_t = 0.04f64.min(0.1 * d.h);
    let leg = 0.035f64.min(0.15 * d.l).min(0.15 * d.w);
    let back_t = 0.03f64.min(0.15 * d.w);
    p.legs(d, leg, 0.0, seat_z - seat_t, Mat::Main);
    p.block((0.0, 0.0), (d.l, d.w), (seat_z - seat_t, seat_z), Mat::Main);
    for sx in [-1.0, 1.0] {
        p.block((sx * (d.hl - leg / 2.0), d.hw - leg / 2.0), (leg, leg), (seat_z, d.h), Mat::Main);
    }
    let back_z0 = seat_z + 0.45 * (d.h - seat_z);
    p.block((0.0, d.hw - back_t / 2.0), (d.l - 2.0 * leg, back_t), (back_z0, d.h), Mat::Main);
}

/// Four legs of side `leg` and a top `top_t` thick (a table, a bench).
fn table(p: &mut Parts, d: &Dims, leg: f64, top_t: f64) {
    let top_t = top_t.min(0.1 * d.h);
    let leg = leg.min(0.1 * d.l).min(0.15 * d.w);
    let inset = 0.04f64.min(0.05 * d.l).min(0.05 * d.w);
    p.legs(d, leg, inset, d.h - top_t, Mat::Main);
    p.block((0.0, 0.0), (d.l, d.w), (d.h - top_t, d.h), Mat::Main);
}

/// A disc on a central pole standing on a smaller foot disc.
fn round_table(p: &mut Parts, d: &Dims) {
    let r = d.m();
    let top_t = 0.03f64.min(0.1 * d.h);
    let foot_t = 0.03f64.min(0.05 * d.h);
    p.cylinder((0.0, 0.0), 0.6 * r, (0.0, foot_t), Mat::Main);
    p.cylinder((0.0, 0.0), 0.04f64.min(0.1 * r), (foot_t, d.h - top_t), Mat::Main);
    p.cylinder((0.0, 0.0), r, (d.h - top_t, d.h), Mat::Main);
}

/// A top on two side panels, with a modesty panel at the back.
fn desk(p: &mut Parts, d: &Dims) {
    let top_t = 0.03f64.min(0.1 * d.h);
    let panel_t = 0.025f64.min(0.1 * d.l);
    let back_t = 0.02f64.min(0.1 * d.w);
    for sx in [-1.0, 1.0] {
        p.block((sx * (d.hl - panel_t / 2.0), 0.0), (panel_t, d.w), (0.0, d.h - top_t), Mat::Main);
    }
    let back = (d.l - 2.0 * panel_t, back_t);
    p.block((0.0, d.hw - back_t / 2.0), back, (0.3 * d.h, d.h - top_t), Mat::Main);
    p.block((0.0, 0.0), (d.l, d.w), (d.h - top_t, d.h), Mat::Main);
}

/// A base on short legs, a back along +y and an arm at each end.
fn sofa(p: &mut Parts, d: &Dims) {
    let leg_h = 0.1 * d.h;
    let base_top = 0.5 * d.h;
    let leg = 0.05f64.min(0.1 * d.l).min(0.1 * d.w);
    let back_t = 0.2f64.min(0.25 * d.w);
    let arm_w = 0.2f64.min(0.15 * d.l);
    p.legs(d, leg, 0.0, leg_h, Mat::Main);
    p.block((0.0, 0.0), (d.l, d.w), (leg_h, base_top), Mat::Main);
    p.block((0.0, d.hw - back_t / 2.0), (d.l, back_t), (base_top, d.h), Mat::Main);
    for sx in [-1.0, 1.0] {
        let at = (sx * (d.hl - arm_w / 2.0), -back_t / 2.0);
        p.block(at, (arm_w, d.w - back_t), (base_top, 0.73 * d.h), Mat::Main);
    }
}

/// A frame on short legs, a mattress (its top at 0.55 of the height) and a headboard at +x.
fn bed(p: &mut Parts, d: &Dims) {
    let head_t = 0.05f64.min(0.05 * d.l);
    let leg = 0.06f64.min(0.1 * d.l).min(0.1 * d.w);
    let (leg_h, frame_top, mattress_top) = (0.15 * d.h, 0.35 * d.h, 0.55 * d.h);
    let gap = 0.02f64.min(0.02 * d.l).min(0.02 * d.w);
    let x1 = d.hl - head_t;
    for (x, y) in [(-d.hl, -d.hw), (-d.hl, d.hw - leg), (x1 - leg, -d.hw), (x1 - leg, d.hw - leg)] {
        p.block((x + leg / 2.0, y + leg / 2.0), (leg, leg), (0.0, leg_h), Mat::Main);
    }
    p.block(((x1 - d.hl) / 2.0, 0.0), (x1 + d.hl, d.w), (leg_h, frame_top), Mat::Main);
    let mattress = (x1 + d.hl - 2.0 * gap, d.w - 2.0 * gap);
    p.block(((x1 - d.hl) / 2.0, 0.0), mattress, (frame_top, mattress_top), Mat::Named("fabric"));
    p.block((d.hl - head_t / 2.0, 0.0), (head_t, d.w), (0.0, d.h), Mat::Main);
}

/// Two side panels, four or five shelves, and a few boxes standing on the shelves.
fn shelving(p: &mut Parts, d: &Dims, rng: &mut SplitMix64) {
    let panel_t = 0.02f64.min(0.05 * d.l);
    let n = if d.h >= 1.5 { 5 } else { 4 };
    let shelf_t = 0.02f64.min(d.h / (4.0 * n as f64));
    let pitch = (d.h - shelf_t) / (n - 1) as f64;
    let inner = d.l - 2.0 * panel_t;
    for sx in [-1.0, 1.0] {
        p.block((sx * (d.hl - panel_t / 2.0), 0.0), (panel_t, d.w), (0.0, d.h), Mat::Main);
    }
    for k in 0..n {
        let z = k as f64 * pitch;
        p.block((0.0, 0.0), (inner, d.w), (z, z + shelf_t), Mat::Main);
        if k + 1 < n {
            shelf_items(p, rng, (-inner / 2.0, inner / 2.0), d.w, (z + shelf_t, (k + 1) as f64 * pitch));
        }
    }
}

/// Boxes side by side along a shelf from `x0` to `x1`, between heights `z0` and `z1`.
fn shelf_items(p: &mut Parts, rng: &mut SplitMix64, (x0, x1): (f64, f64), depth_m: f64, (z0, z1): (f64, f64)) {
    let mut x = x0 + rng.next_f64() * 0.15;
    for _ in 0..8 {
        let len = 0.08 + rng.next_f64() * 0.22;
        if x + len > x1 {
            break;
        }
        if rng.next_f64() < 0.6 {
            let depth = depth_m * (0.5 + 0.45 * rng.next_f64());
            let h = (z1 - z0) * (0.4 + 0.5 * rng.next_f64());
            p.block((x + len / 2.0, 0.0), (len, depth), (z0, z0 + h), Mat::Named("cardboard"));
        }
        x += len + 0.02 + rng.next_f64() * 0.1;
    }
}

/// Pallet racking: four uprights, a pair of beams at each level, and loads on some pallets.
fn rack(p: &mut Parts, d: &Dims, rng: &mut SplitMix64) {
    let post = 0.08f64.min(0.05 * d.l).min(0.1 * d.w);
    let n = if d.h >= 3.0 { 4 } else { 3 };
    let gap = d.h / n as f64;
    let beam_h = 0.1f64.min(0.1 * gap);
    let inner = d.l - 2.0 * post;
    p.legs(d, post, 0.0, d.h, Mat::Main);
    for k in 1..=n {
        let z = k as f64 * gap;
        for sy in [-1.0, 1.0] {
            p.block((0.0, sy * (d.hw - post / 2.0)), (inner, post), (z - beam_h, z), Mat::Main);
        }
    }
    let slots = ((inner / 1.25).floor() as usize).clamp(1, 3);
    let slot_l = inner / slots as f64;
    for k in 0..n {
        let z0 = k as f64 * gap;
        let room = gap - beam_h - 0.1f64.min(0.1 * gap);
        for s in 0..slots {
            if room > 0.1 && rng.next_f64() < 0.65 {
                let x = -inner / 2.0 + slot_l * (s as f64 + 0.5);
                rack_load(p, rng, (x, slot_l), d.w, (z0, z0 + room));
            }
        }
    }
}

/// A pallet and its load in a rack slot centred at `x`, `slot_l` long, between `z0` and `z1`.
fn rack_load(p: &mut Parts, rng: &mut SplitMix64, (x, slot_l): (f64, f64), w: f64, (z0, z1): (f64, f64)) {
    let ph = 0.15f64.min(0.3 * (z1 - z0));
    p.block((x, 0.0), (0.9 * slot_l, 0.95 * w), (z0, z0 + ph), Mat::Named("wood"));
    let top = z0 + ph + (z1 - z0 - ph) * (0.6 + 0.4 * rng.next_f64());
    p.block((x, 0.0), (0.84 * slot_l, 0.9 * w), (z0 + ph, top), Mat::Named("cardboard"));
}

/// A pot, a trunk and a crown of leafy spheres.
fn plant(p: &mut Parts, d: &Dims) {
    let m = d.m();
    // The crown's scale: as wide as the pot allows, yet short enough to stay under the top.
    let s = m.min(d.h / 2.4);
    let pot_top = 0.3 * d.h;
    p.cylinder((0.0, 0.0), 0.7 * m, (0.0, pot_top), Mat::Main);
    p.capsule([0.0, 0.0, pot_top], [0.0, 0.0, 0.75 * d.h], 0.02f64.min(0.1 * m).min(0.2 * d.h), Mat::Named("wood"));
    let top = [0.0, 0.0, d.h - 0.8 * s];
    p.capsule(top, top, 0.8 * s, Mat::Named("foliage"));
    for [x, y, z] in [[0.45, 0.0, 0.62], [-0.45, 0.0, 0.62], [0.0, 0.45, 0.72], [0.0, -0.45, 0.72]] {
        let c = [x * m, y * m, z * d.h];
        p.capsule(c, c, 0.5 * s, Mat::Named("foliage"));
    }
}

/// A pole on a base disc with four hooks, and two coats hanging from the hooks on +x and -x:
/// from a distance, much like a person.
fn coat_stand(p: &mut Parts, d: &Dims) {
    let m = d.m();
    let s = m.min(d.h / 3.6);
    p.cylinder((0.0, 0.0), 0.6 * m, (0.0, 0.02 * d.h), Mat::Main);
    p.cylinder((0.0, 0.0), 0.02f64.min(0.1 * m), (0.0, d.h), Mat::Main);
    let hook_r = 0.012f64.min(0.05 * m).min(0.03 * d.h);
    for (x, y) in [(0.35, 0.0), (-0.35, 0.0), (0.0, 0.35), (0.0, -0.35)] {
        p.capsule([0.0, 0.0, 0.93 * d.h], [x * m, y * m, 0.97 * d.h], hook_r, Mat::Main);
    }
    for sx in [-1.0, 1.0] {
        let x = sx * 0.5 * m;
        p.capsule([x, 0.0, 0.8 * d.h], [x, 0.0, 0.55 * d.h], 0.45 * s, Mat::Named("clothing"));
        p.block((x, 0.0), (0.7 * s, 0.8 * s), (0.3 * d.h, 0.55 * d.h), Mat::Named("clothing"));
    }
}

/// A base disc, a pole and a shade on top.
fn floor_lamp(p: &mut Parts, d: &Dims) {
    let m = d.m();
    let shade_z = 0.82 * d.h;
    p.cylinder((0.0, 0.0), 0.8 * m, (0.0, 0.03f64.min(0.05 * d.h)), Mat::Main);
    p.cylinder((0.0, 0.0), 0.012f64.min(0.1 * m), (0.0, shade_z), Mat::Main);
    p.cylinder((0.0, 0.0), m, (shade_z, d.h), Mat::Named("fabric"));
}

/// A flat panel on two short feet (placed against a wall).
fn radiator(p: &mut Parts, d: &Dims) {
    let leg_h = 0.12 * d.h;
    let foot = 0.03f64.min(0.05 * d.l);
    let foot_x = d.hl - 0.1f64.min(0.15 * d.l);
    for sx in [-1.0, 1.0] {
        p.block((sx * foot_x, 0.0), (foot, d.w), (0.0, leg_h), Mat::Main);
    }
    p.block((0.0, 0.0), (d.l, d.w), (leg_h, d.h), Mat::Main);
}

/// A EUR-style pallet: three bottom boards, nine blocks, five top boards along the length.
fn pallet(p: &mut Parts, d: &Dims) {
    let t = 0.022f64.min(d.h / 5.0);
    let board = 0.1f64.min(d.w / 5.0);
    let block = 0.145f64.min(d.l / 6.0);
    let ys = [-d.hw + board / 2.0, 0.0, d.hw - board / 2.0];
    for y in ys {
        p.block((0.0, y), (d.l, board), (0.0, t), Mat::Main);
        for x in [-d.hl + block / 2.0, 0.0, d.hl - block / 2.0] {
            p.block((x, y), (block, board), (t, d.h - t), Mat::Main);
        }
    }
    for i in 0..5 {
        let y = -d.hw + board / 2.0 + i as f64 * (d.w - board) / 4.0;
        p.block((0.0, y), (d.l, board), (d.h - t, d.h), Mat::Main);
    }
}

/// A pallet with a wrapped load on it.
fn pallet_stack(p: &mut Parts, d: &Dims) {
    let ph = 0.15f64.min(0.3 * d.h);
    pallet(p, &Dims { h: ph, ..*d });
    let inset = 0.04f64.min(0.05 * d.l).min(0.05 * d.w);
    p.block((0.0, 0.0), (d.l - inset, d.w - inset), (ph, d.h), Mat::Named("cardboard"));
}

/// A dressed torso and a head on a stand: a person-sized figure without legs, shoulders along x.
fn mannequin(p: &mut Parts, d: &Dims) {
    let s = d.hl.min(d.hw / 0.7).min(d.h / 3.6);
    let hip_z = 0.55 * d.h;
    p.cylinder((0.0, 0.0), 0.6 * d.m(), (0.0, 0.02 * d.h), Mat::Main);
    p.cylinder((0.0, 0.0), 0.015f64.min(0.05 * s), (0.0, hip_z), Mat::Main);
    let torso_r = 0.52 * s;
    for sx in [-1.0, 1.0] {
        let x = sx * 0.36 * s;
        p.capsule([x, 0.0, hip_z + torso_r], [x, 0.0, 0.79 * d.h], torso_r, Mat::Named("clothing"));
    }
    p.capsule([0.0, 0.0, 0.84 * d.h], [0.0, 0.0, 0.88 * d.h], 0.22 * s, Mat::Main);
    let head = [0.0, 0.0, d.h - 0.42 * s];
    p.capsule(head, head, 0.42 * s, Mat::Main);
}

/// An office partition: a panel with a metal rail along its top.
fn cubicle_wall(p: &mut Parts, d: &Dims) {
    let rail = 0.03f64.min(0.05 * d.h);
    p.block((0.0, 0.0), (d.l, d.w), (0.0, d.h - rail), Mat::Main);
    p.block((0.0, 0.0), (d.l, d.w), (d.h - rail, d.h), Mat::Named("metal"));
}

/// Cabinets on a recessed plinth under a worktop that overhangs on +y (a breakfast bar).
fn kitchen_island(p: &mut Parts, d: &Dims) {
    let top_t = 0.04f64.min(0.1 * d.h);
    let overhang = 0.25f64.min(0.3 * d.w);
    let kick = 0.05f64.min(0.05 * d.l).min(0.05 * d.w);
    let body_w = d.w - overhang;
    let body_y = -d.hw + body_w / 2.0;
    p.block((0.0, body_y), (d.l - 2.0 * kick, body_w - 2.0 * kick), (0.0, 0.1 * d.h), Mat::Main);
    p.block((0.0, body_y), (d.l - kick, body_w), (0.1 * d.h, d.h - top_t), Mat::Main);
    p.block((0.0, 0.0), (d.l, d.w), (d.h - top_t, d.h), Mat::Main);
}

/// Auditorium seats side by side on a shared beam carried by a leg at each end.
fn seat_row(p: &mut Parts, d: &Dims) {
    let n = ((d.l / 0.5).floor() as usize).clamp(1, 200);
    let pitch = d.l / n as f64;
    let (beam_z0, beam_z1, seat_z) = (0.2 * d.h, 0.27 * d.h, 0.5 * d.h);
    let beam_w = 0.08f64.min(0.2 * d.w);
    let leg = 0.06f64.min(0.1 * pitch);
    let seat_t = 0.05f64.min(0.1 * d.h);
    let back_t = 0.06f64.min(0.15 * d.w);
    let gap = 0.04f64.min(0.1 * pitch);
    for sx in [-1.0, 1.0] {
        p.block((sx * (d.hl - leg / 2.0), 0.0), (leg, 0.5 * d.w), (0.0, beam_z0), Mat::Named("metal"));
    }
    p.block((0.0, 0.0), (d.l, beam_w), (beam_z0, beam_z1), Mat::Named("metal"));
    for i in 0..n {
        let x = -d.hl + pitch * (i as f64 + 0.5);
        let post = beam_w.min(0.5 * pitch);
        p.block((x, 0.0), (post, beam_w), (beam_z1, seat_z - seat_t), Mat::Named("metal"));
        p.block((x, -back_t / 2.0), (pitch - gap, d.w - back_t), (seat_z - seat_t, seat_z), Mat::Main);
        p.block((x, d.hw - back_t / 2.0), (pitch - gap, back_t), (seat_z - seat_t, d.h), Mat::Main);
    }
}
