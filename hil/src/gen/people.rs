//! People in a generated building: 1-8 of them, in every pose, children to tall adults, on
//! seats, beds and platforms, crouched behind furniture, in doorways, and walking.

use crate::gen::families::Building;
use crate::gen::furnish::distance_to_rect;
use crate::gen::grid::Grid;
use crate::gen::layout::Dice;
use crate::gen::plan::{PlanFurniture, PlanPerson, Region};
use crate::sim::obstacles::{distance_to_polyline, segment_points};
use crate::sim::scenario::PoseKind;

/// Clearance a standing or crouching person needs from walls and furniture.
const STAND_CLEAR_M: f64 = 0.3;
/// People keep this far apart.
const APART_M: f64 = 0.9;
/// A mattress's top as a share of a bed's height (the headboard's top): the simulator's bed.
pub const MATTRESS_SHARE: f64 = 0.55;
/// Height of a seated person's seat above their feet' plane, for the 1.75 m adult the sitting
/// pose is drawn for (hil/src/sim/human.rs); it scales with the person's height.
const SIT_HEIGHT_M: f64 = 0.45;
const REFERENCE_HEIGHT_M: f64 = 1.75;
const KINDS_TO_SIT_ON: [&str; 4] = ["chair", "sofa", "bench", "seat_row"];
const KINDS_TO_HIDE_BEHIND: [&str; 6] = ["kitchen_island", "cabinet", "desk", "table", "pallet_stack", "sofa"];

/// What someone is doing, before a place is found for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    Standing,
    Sitting,
    Crouching,
    Lying,
    Walking,
    InDoorway,
}

fn role(d: &mut Dice) -> Role {
    let r = d.range(0.0, 1.0);
    match r {
        r if r < 0.25 => Role::Standing,
        r if r < 0.45 => Role::Sitting,
        r if r < 0.6 => Role::Crouching,
        r if r < 0.75 => Role::Lying,
        r if r < 0.9 => Role::Walking,
        _ => Role::InDoorway,
    }
}

/// People for `b`; `grid` is the building's (furniture included).
pub fn place(d: &mut Dice, b: &Building, grid: &Grid) -> Vec<PlanPerson> {
    let want = d.count(1, 8);
    let mut people: Vec<PlanPerson> = Vec::new();
    let mut used_seats: Vec<usize> = Vec::new();
    for attempt in 0..want * 6 {
        if people.len() >= want {
            break;
        }
        let region = 1 + d.below(b.regions.len().saturating_sub(1).max(1));
        let Some(r) = b.regions.get(region) else { continue };
        let role = role(d);
        let (placed, seat) = match role {
            Role::Sitting => seated(d, b, region, &used_seats).map_or((None, None), |(p, i)| (Some(p), Some(i))),
            Role::Lying => (lying(d, b, region, grid), None),
            Role::Crouching => (crouched(d, b, region, grid), None),
            Role::InDoorway => (in_doorway(d, r), None),
            Role::Standing | Role::Walking => (standing(d, b, region, grid), None),
        };
        let Some(mut p) = placed else { continue };
        if role == Role::Walking {
            p.path = walk(d, r, grid, p.at).into_iter().collect();
            p.speed_m_s = d.range(0.5, 1.3);
        }
        if people.iter().any(|q| too_close(q, &p)) {
            continue;
        }
        used_seats.extend(seat);
        p.name = format!("p{}_{}", people.len() + 1, attempt);
        p.region = region;
        people.push(p);
    }
    people
}

/// Whether two people (their spots, and a walker's whole walk) come within `APART_M`.
fn too_close(a: &PlanPerson, b: &PlanPerson) -> bool {
    let line = |p: &PlanPerson| -> Vec<[f64; 2]> { std::iter::once(p.at).chain(p.path.iter().copied()).collect() };
    let (la, lb) = (line(a), line(b));
    let near =
        |points: &[[f64; 2]], other: &[[f64; 2]]| points.iter().any(|&p| distance_to_polyline(p, other) < APART_M);
    near(&la, &lb) || near(&lb, &la) || walks_cross(&la, &lb)
}

fn walks_cross(a: &[[f64; 2]], b: &[[f64; 2]]) -> bool {
    a.windows(2).any(|s| segment_points(s[0], s[1], 0.1).any(|p| distance_to_polyline(p, b) < APART_M))
}

fn person(d: &mut Dice, pose: PoseKind, at: [f64; 2], yaw_deg: f64, base_z_m: f64) -> PlanPerson {
    let child = d.chance(0.12);
    PlanPerson {
        name: String::new(),
        pose,
        at,
        base_z_m,
        yaw_deg,
        height_m: if child { d.range(1.1, 1.45) } else { d.range(1.5, 1.95) },
        build: d.range(0.8, 1.3),
        path: Vec::new(),
        speed_m_s: 1.0,
        region: 0,
    }
}

/// A free point in `region` (or on one of its platforms) with room to stand.
fn free_spot(d: &mut Dice, b: &Building, region: usize, grid: &Grid, clear_m: f64) -> Option<([f64; 2], f64)> {
    let r = b.regions.get(region)?;
    for _ in 0..40 {
        let p = [d.range(r.rect.min[0], r.rect.max[0]), d.range(r.rect.min[1], r.rect.max[1])];
        if let Some((_, h)) = b.platforms.iter().find(|(pr, _)| pr.inset(0.3).contains(p)) {
            return Some((p, *h));
        }
        if grid.clearance_m(p) >= clear_m && b.platforms.iter().all(|(pr, _)| distance_to_rect(p, pr) > clear_m) {
            return Some((p, 0.0));
        }
    }
    None
}

fn standing(d: &mut Dice, b: &Building, region: usize, grid: &Grid) -> Option<PlanPerson> {
    let (at, z) = free_spot(d, b, region, grid, STAND_CLEAR_M + 0.1)?;
    let yaw = d.range(-180.0, 180.0);
    Some(person(d, PoseKind::Standing, at, yaw, z))
}

fn items_in<'a>(
    b: &'a Building,
    region: usize,
    kinds: &'a [&str],
) -> impl Iterator<Item = (usize, &'a PlanFurniture)> + 'a {
    let rect = b.regions.get(region).map(|r| r.rect);
    b.furniture
        .items
        .iter()
        .enumerate()
        .filter(move |(_, f)| kinds.contains(&f.kind) && rect.is_some_and(|r| r.contains(f.at)))
}

/// On a seat, facing out of it (a seat's front is its local -y), at one of its seats, thighs
/// on its top: a chair's, a sofa's and a seat row's seat is at half their height, a bench's at
/// its top.
fn seated(d: &mut Dice, b: &Building, region: usize, used: &[usize]) -> Option<(PlanPerson, usize)> {
    let seats: Vec<usize> =
        items_in(b, region, &KINDS_TO_SIT_ON).map(|(i, _)| i).filter(|i| !used.contains(i)).collect();
    let i = d.pick(&seats)?;
    let seat = b.furniture.items.get(i)?;
    let (s, c) = seat.yaw_deg.to_radians().sin_cos();
    let offset = if seat.kind == "seat_row" {
        // The simulator's seat row holds a seat per 0.5 m; sit on one, not between two.
        let n = (seat.size_m[0] / 0.5).floor().max(1.0);
        let pitch = seat.size_m[0] / n;
        -seat.size_m[0] / 2.0 + pitch * (d.below(n as usize) as f64 + 0.5)
    } else {
        let along = (seat.size_m[0] / 2.0 - 0.35).max(0.0);
        d.range(-along, along)
    };
    let at = [seat.at[0] + c * offset, seat.at[1] + s * offset];
    let seat_top = seat.base_z_m + if seat.kind == "bench" { seat.size_m[2] } else { 0.5 * seat.size_m[2] };
    let mut p = person(d, PoseKind::Sitting, at, seat.yaw_deg - 90.0, 0.0);
    p.base_z_m = seat_top - SIT_HEIGHT_M * p.height_m / REFERENCE_HEIGHT_M;
    Some((p, i))
}

/// On a bed (along its length, local x, head at the headboard's +x end), or on the floor.
fn lying(d: &mut Dice, b: &Building, region: usize, grid: &Grid) -> Option<PlanPerson> {
    let beds: Vec<usize> = items_in(b, region, &["bed"]).map(|(i, _)| i).collect();
    if let Some(i) = d.pick(&beds) {
        let bed = b.furniture.items.get(i)?;
        let (s, c) = bed.yaw_deg.to_radians().sin_cos();
        // The head (0.7 m from the pelvis for a 1.75 m adult) a hand's width from the
        // headboard at the bed's +x end.
        let mut p = person(d, PoseKind::Lying, bed.at, bed.yaw_deg, bed.base_z_m + bed.size_m[2] * MATTRESS_SHARE);
        let from_centre = bed.size_m[0] / 2.0 - 0.2 - 0.7 * p.height_m / REFERENCE_HEIGHT_M;
        p.at = [bed.at[0] + c * from_centre, bed.at[1] + s * from_centre];
        return Some(p);
    }
    for _ in 0..20 {
        let (at, z) = free_spot(d, b, region, grid, STAND_CLEAR_M)?;
        let yaw = d.range(-180.0, 180.0);
        let (s, c) = yaw.to_radians().sin_cos();
        let head = [at[0] + c * 0.8, at[1] + s * 0.8];
        let feet = [at[0] - c * 0.9, at[1] - s * 0.9];
        let on_platform = |q: [f64; 2]| b.platforms.iter().any(|(r, _)| r.inset(0.1).contains(q));
        let fits = if z > 0.0 {
            on_platform(head) && on_platform(feet)
        } else {
            grid.clearance_m(head) > 0.25 && grid.clearance_m(feet) > 0.25
        };
        if fits {
            return Some(person(d, PoseKind::Lying, at, yaw, z));
        }
    }
    None
}

/// Crouched behind a piece of furniture, on its side away from the region's entrance.
fn crouched(d: &mut Dice, b: &Building, region: usize, grid: &Grid) -> Option<PlanPerson> {
    let covers: Vec<usize> = items_in(b, region, &KINDS_TO_HIDE_BEHIND).map(|(i, _)| i).collect();
    let entrance = b.regions.get(region)?.entrance;
    if let (Some(i), Some(e)) = (d.pick(&covers), entrance) {
        let cover = b.furniture.items.get(i)?.rect();
        let c = cover.centre();
        let (dx, dy) = (c[0] - e[0], c[1] - e[1]);
        let n = dx.hypot(dy).max(1e-6);
        let reach = cover.size()[0].max(cover.size()[1]) / 2.0 + 0.45;
        let at = [c[0] + dx / n * reach, c[1] + dy / n * reach];
        let inside = b.regions.get(region).is_some_and(|r| r.rect.inset(0.25).contains(at));
        if inside && grid.clearance_m(at) >= 0.2 {
            let yaw = dy.atan2(dx).to_degrees() + 180.0;
            return Some(person(d, PoseKind::Crouching, at, yaw, 0.0));
        }
    }
    let (at, z) = free_spot(d, b, region, grid, STAND_CLEAR_M)?;
    let yaw = d.range(-180.0, 180.0);
    Some(person(d, PoseKind::Crouching, at, yaw, z))
}

/// Standing just inside a room's door, facing out.
fn in_doorway(d: &mut Dice, r: &Region) -> Option<PlanPerson> {
    let e = r.entrance.filter(|_| r.walled)?;
    let c = r.rect.centre();
    let (dx, dy) = (c[0] - e[0], c[1] - e[1]);
    // Into the room along the door's normal (the wall runs along x or y).
    let inward = if dx.abs() > dy.abs() { [dx.signum(), 0.0] } else { [0.0, dy.signum()] };
    let at = [e[0] + inward[0] * 0.35, e[1] + inward[1] * 0.35];
    let yaw = (-inward[1]).atan2(-inward[0]).to_degrees();
    Some(person(d, PoseKind::Standing, at, yaw, 0.0))
}

/// A straight walk of 2-5 m from `from` inside the region, clear of furniture.
fn walk(d: &mut Dice, r: &Region, grid: &Grid, from: [f64; 2]) -> Option<[f64; 2]> {
    for _ in 0..30 {
        let to = [d.range(r.rect.min[0], r.rect.max[0]), d.range(r.rect.min[1], r.rect.max[1])];
        let len = (to[0] - from[0]).hypot(to[1] - from[1]);
        if (2.0..=5.0).contains(&len) && clear_line(grid, from, to, STAND_CLEAR_M + 0.05) {
            return Some(to);
        }
    }
    None
}

fn clear_line(grid: &Grid, a: [f64; 2], b: [f64; 2], clear_m: f64) -> bool {
    segment_points(a, b, 0.05).all(|p| grid.clearance_m(p) >= clear_m)
}
