#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;
use nalgebra::Vector3;

/// Points every 5 cm along a segment at height z.
fn line(a: [f64; 2], b: [f64; 2], z: f64) -> Vec<Vector3<f64>> {
    let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / 0.05).ceil() as usize;
    (0..=n)
        .map(|k| {
            let f = k as f64 / n.max(1) as f64;
            Vector3::new(a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f, z)
        })
        .collect()
}

/// Floor points every 5 cm over a rectangle at height z.
fn floor(lo: [f64; 2], hi: [f64; 2], z: f64) -> Vec<Vector3<f64>> {
    let mut out = Vec::new();
    let (nx, ny) = (((hi[0] - lo[0]) / 0.05) as usize, ((hi[1] - lo[1]) / 0.05) as usize);
    for i in 0..=nx {
        for j in 0..=ny {
            out.push(Vector3::new(lo[0] + i as f64 * 0.05, lo[1] + j as f64 * 0.05, z));
        }
    }
    out
}

/// A 6 x 4 m room (x 0-6, y 0-4) with a 1 m doorway in its x = 6 wall (y 1.5-2.5), seen from
/// (1, 2) at 0.5 m: its floor, its walls at 1 m, and the floor 1 m past the doorway.
fn room_scan() -> Vec<Vector3<f64>> {
    let mut pts = floor([0.1, 0.1], [5.9, 3.9], 0.0);
    pts.extend(line([0.0, 0.0], [6.0, 0.0], 1.0));
    pts.extend(line([0.0, 4.0], [6.0, 4.0], 1.0));
    pts.extend(line([0.0, 0.0], [0.0, 4.0], 1.0));
    pts.extend(line([6.0, 0.0], [6.0, 1.5], 1.0));
    pts.extend(line([6.0, 2.5], [6.0, 4.0], 1.0));
    pts.extend(floor([6.05, 1.6], [7.0, 2.4], 0.0));
    pts
}

fn grid() -> OccupancyGrid {
    let cfg = OccupancyConfig { extent_m: 20.0, ..OccupancyConfig::default() };
    OccupancyGrid::new(cfg, [3.0, 2.0]).unwrap()
}

fn at(g: &OccupancyGrid, x: f64, y: f64) -> (usize, usize) {
    g.cell_of(x, y).unwrap()
}

#[test]
fn a_room_is_free_inside_occupied_at_its_walls_and_unknown_behind_them() {
    let mut g = grid();
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &room_scan());
    assert_eq!(g.cell(at(&g, 3.0, 2.0)), Cell::Free);
    assert!(g.traversable(at(&g, 3.0, 2.0)));
    assert_eq!(g.cell(at(&g, 3.02, 0.02)), Cell::Occupied, "the y = 0 wall");
    assert_eq!(g.cell(at(&g, 6.02, 3.0)), Cell::Occupied, "the x = 6 wall");
    assert_eq!(g.cell(at(&g, 3.0, -1.0)), Cell::Unknown, "behind the wall");
    assert_eq!(g.cell(at(&g, 6.5, 2.0)), Cell::Free, "through the doorway");
    assert_eq!(g.cell(at(&g, 8.0, 2.0)), Cell::Unknown, "past what was seen");
    let (free, occupied) = g.known();
    assert!(free > 2000 && occupied > 150, "{free} free, {occupied} occupied");
}

#[test]
fn the_frontier_is_past_the_doorway() {
    let mut g = grid();
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &room_scan());
    let found = frontiers(&g, 3);
    // Past the doorway only (the seen floor's edge there may break into pieces); none along
    // the walls, whose rows of cells have holes where no return fell.
    let centres: Vec<[f64; 2]> = found.iter().map(|f| f.centroid_m).collect();
    assert!(!found.is_empty() && centres.iter().all(|c| c[0] > 6.0 && (1.4..2.6).contains(&c[1])), "{centres:?}");
    let f = &found[0];
    let [x, y] = g.centre_of(f.goal);
    assert!((6.6..7.2).contains(&x) && (1.4..2.6).contains(&y), "goal at ({x:.2}, {y:.2})");
    assert!(g.traversable(f.goal));
    // Its length is about the seen floor's edge past the door (0.8 m wide) and its sides.
    assert!((0.6..3.0).contains(&f.length_m(0.1)), "{} m", f.length_m(0.1));
    // Closed: the floor past the doorway seen to the far wall leaves no frontier there.
    let mut closed = grid();
    let mut scan = room_scan();
    scan.extend(floor([6.05, 1.6], [9.9, 2.4], 0.0));
    scan.extend(line([10.0, 1.5], [10.0, 2.5], 1.0));
    scan.extend(line([6.0, 1.5], [10.0, 1.5], 1.0));
    scan.extend(line([6.0, 2.5], [10.0, 2.5], 1.0));
    closed.add_scan(&Vector3::new(1.0, 2.0, 0.5), &scan);
    closed.add_scan(&Vector3::new(6.5, 2.0, 0.5), &scan);
    assert!(
        frontiers(&closed, 3).is_empty(),
        "{:?}",
        frontiers(&closed, 3).iter().map(|f| f.centroid_m).collect::<Vec<_>>()
    );
}

#[test]
fn what_blocks_is_in_the_body_band_and_what_is_overhead_does_not() {
    let mut g = grid();
    let mut scan = room_scan();
    // A table top at 0.75 m around (3, 1) and a lamp's shade at 2.2 m over (3, 3).
    scan.extend(floor([2.8, 0.8], [3.2, 1.2], 0.75));
    scan.extend(floor([2.8, 2.8], [3.2, 3.2], 2.2));
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &scan);
    assert_eq!(g.cell(at(&g, 3.0, 1.0)), Cell::Occupied);
    assert!(!g.traversable(at(&g, 3.0, 1.0)));
    assert_eq!(g.cell(at(&g, 3.0, 3.0)), Cell::Free);
}

#[test]
fn steps_the_base_cannot_climb_are_not_traversable_and_a_sill_is() {
    // A platform 15 cm up (x 3-6): in the body band, so it blocks, top and all.
    let mut g = grid();
    let mut scan = floor([0.1, 0.1], [2.95, 3.9], 0.0);
    scan.extend(floor([3.0, 0.1], [5.9, 3.9], 0.15));
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &scan);
    assert!(g.traversable(at(&g, 1.5, 2.0)));
    assert_eq!(g.cell(at(&g, 4.5, 2.0)), Cell::Occupied, "the platform");
    // A sill 3 cm up is floor; a floor sunk 15 cm (x 3-6) is floor too, but its edge is a step.
    for (z, edge_ok) in [(0.03, true), (-0.15, false)] {
        let mut g = grid();
        let mut scan = floor([0.1, 0.1], [2.95, 3.9], 0.0);
        scan.extend(floor([3.0, 0.1], [5.9, 3.9], z));
        g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &scan);
        assert!(g.traversable(at(&g, 4.5, 2.0)), "z {z}: the other floor's middle");
        let edge = g.traversable(at(&g, 2.97, 2.0)) && g.traversable(at(&g, 3.03, 2.0));
        assert_eq!(edge, edge_ok, "z {z}: the edge between them");
    }
    // A stairwell: rays cross its cells (to the floor beyond) but no floor return falls in it.
    let mut g = grid();
    let mut scan = floor([0.1, 0.1], [2.95, 3.9], 0.0);
    scan.extend(floor([4.0, 0.1], [5.9, 3.9], 0.0));
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &scan);
    assert_eq!(g.cell(at(&g, 3.5, 2.0)), Cell::Free, "crossed by rays");
    assert!(!g.traversable(at(&g, 3.5, 2.0)), "but no floor seen there");
    assert!(!is_frontier(&g, at(&g, 3.5, 2.0)));
}

#[test]
fn bad_points_and_places_outside_the_grid_do_nothing_bad() {
    let mut g = grid();
    let junk = [
        Vector3::new(f64::NAN, 0.0, 0.0),
        Vector3::new(1e12, 1e12, 0.0),
        Vector3::new(-1e9, 3.0, 1.0),
        Vector3::new(f64::INFINITY, 2.0, 0.5),
    ];
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &junk);
    g.add_scan(&Vector3::new(1e9, 0.0, 0.5), &room_scan());
    g.add_scan(&Vector3::new(f64::NAN, 0.0, 0.5), &room_scan());
    assert!(g.known().1 == 0);
    assert!(OccupancyGrid::new(OccupancyConfig { cell_m: 0.0, ..OccupancyConfig::default() }, [0.0, 0.0]).is_none());
    assert!(OccupancyGrid::new(OccupancyConfig { extent_m: 1e9, ..OccupancyConfig::default() }, [0.0, 0.0]).is_none());
    assert_eq!(g.cell((usize::MAX, 0)), Cell::Unknown);
    // Rays that would run for kilometres stop at the grid's edge.
    let cfg = OccupancyConfig { extent_m: 20.0, max_range_m: 1e12, ..OccupancyConfig::default() };
    let mut far = OccupancyGrid::new(cfg, [3.0, 2.0]).unwrap();
    far.add_scan(&Vector3::new(1.0, 2.0, 0.5), &[Vector3::new(1e9, 2.0, 0.0)]);
    assert_eq!(far.cell(at(&far, 12.5, 2.0)), Cell::Unknown, "one pass is not enough to decide");
}

/// The room with its doorway `door_m` wide (centred on y = 2), seen from (1, 2).
fn room_with_door(door_m: f64) -> OccupancyGrid {
    let (lo, hi) = (2.0 - door_m / 2.0, 2.0 + door_m / 2.0);
    let mut pts = floor([0.1, 0.1], [5.9, 3.9], 0.0);
    pts.extend(line([0.0, 0.0], [6.0, 0.0], 1.0));
    pts.extend(line([0.0, 4.0], [6.0, 4.0], 1.0));
    pts.extend(line([0.0, 0.0], [0.0, 4.0], 1.0));
    pts.extend(line([6.0, 0.0], [6.0, lo], 1.0));
    pts.extend(line([6.0, hi], [6.0, 4.0], 1.0));
    pts.extend(floor([6.05, lo + 0.1], [7.0, hi - 0.1], 0.0));
    let mut g = grid();
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &pts);
    g
}

#[test]
fn the_goal_is_past_the_doorway_and_the_way_keeps_clear_of_the_walls() {
    let g = room_with_door(1.0);
    let robot = at(&g, 1.0, 2.0);
    let cfg = PlanConfig::default();
    let ok = usable(&g, robot, cfg.robot_radius_m);
    let costs = Costs::from(&g, &ok, robot);
    let found = frontiers(&g, 3);
    let choice = choose_goal(&g, &found, &costs, &[], &cfg).expect("a goal");
    let [x, _] = g.centre_of(choice.goal);
    assert!(x > 6.0, "goal at x {x:.2}");
    assert!((5.0..7.5).contains(&choice.travel_m), "{} m", choice.travel_m);
    let path = costs.path_to(choice.goal);
    assert_eq!(path.first(), Some(&robot));
    assert_eq!(path.last(), Some(&choice.goal));
    // Every step is to a neighbour, on usable floor, and at least the radius from every wall cell.
    for w in path.windows(2) {
        assert!(w[0].0.abs_diff(w[1].0) <= 1 && w[0].1.abs_diff(w[1].1) <= 1);
    }
    let side = g.side();
    let walls: Vec<[f64; 2]> = (0..side * side)
        .map(|k| (k % side, k / side))
        .filter(|&c| g.cell(c) == Cell::Occupied)
        .map(|c| g.centre_of(c))
        .collect();
    for &c in &path[3..] {
        let [x, y] = g.centre_of(c);
        let nearest = walls.iter().map(|w| (w[0] - x).hypot(w[1] - y)).fold(f64::INFINITY, f64::min);
        assert!(nearest > cfg.robot_radius_m - 1e-9, "({x:.2}, {y:.2}) is {nearest:.2} m from a wall");
    }
    // Blacklisted (the robot could not get there): no other frontier, so no goal.
    let [gx, gy] = g.centre_of(choice.goal);
    assert!(choose_goal(&g, &found, &costs, &[[gx, gy]], &PlanConfig { blacklist_radius_m: 2.0, ..cfg }).is_none());
}

#[test]
fn a_frontier_past_a_door_narrower_than_the_robot_is_not_chosen() {
    let g = room_with_door(0.5);
    let robot = at(&g, 1.0, 2.0);
    let cfg = PlanConfig::default();
    let found = frontiers(&g, 1);
    assert!(!found.is_empty(), "the floor past the door is a frontier");
    let costs = Costs::from(&g, &usable(&g, robot, cfg.robot_radius_m), robot);
    assert_eq!(choose_goal(&g, &found, &costs, &[], &cfg), None);
    // A robot half as wide fits through.
    let narrow = PlanConfig { robot_radius_m: 0.15, ..cfg };
    let costs = Costs::from(&g, &usable(&g, robot, narrow.robot_radius_m), robot);
    assert!(choose_goal(&g, &found, &costs, &[], &narrow).is_some());
}

#[test]
fn the_controller_drives_the_planned_way_through_the_doorway_without_touching_a_wall() {
    let g = room_with_door(1.0);
    let robot = at(&g, 1.0, 2.0);
    let cfg = PlanConfig::default();
    let costs = Costs::from(&g, &usable(&g, robot, cfg.robot_radius_m), robot);
    let choice = choose_goal(&g, &frontiers(&g, 3), &costs, &[], &cfg).expect("a goal");
    let path: Vec<[f64; 2]> = costs.path_to(choice.goal).into_iter().map(|c| g.centre_of(c)).collect();
    // The controller's obstacles: the walls as the live scan sees them, and the grid's occupied
    // cells within 1.5 m (the door's posts, beside the base as it passes, out of the view).
    let walls: Vec<[f64; 2]> = room_scan().iter().filter(|p| p.z > 0.5).map(|p| [p.x, p.y]).collect();
    let obstacles = |p: &Pose2| {
        let mut seen = super::tests_control::seen(p, &walls);
        seen.extend(super::tests_control::in_body(p, g.occupied_near(p.x_m, p.y_m, 1.5).into_iter()));
        seen
    };
    let start = Pose2 { x_m: 1.0, y_m: 2.0, yaw_rad: 0.0 };
    let steps = super::tests_control::run_with(start, &path, 1200, obstacles);
    let (end, last) = steps.last().expect("steps");
    assert_eq!(last.state, ControlState::Arrived, "{end:?}");
    let radius = ControlConfig::default().robot_radius_m;
    for (p, s) in &steps {
        let nearest = walls.iter().map(|w| (w[0] - p.x_m).hypot(w[1] - p.y_m)).fold(f64::INFINITY, f64::min);
        assert!(nearest > radius, "{nearest} m from a wall at {p:?}");
        assert!(!matches!(s.state, ControlState::Blocked { .. }), "{s:?} at {p:?}");
    }
}

#[test]
fn the_floor_the_base_stood_on_is_traversable() {
    let mut g = grid();
    let here = at(&g, 1.0, 2.0);
    assert_eq!(g.cell(here), Cell::Unknown);
    g.mark_driven(1.0, 2.0, 0.3);
    assert!(g.traversable(here) && g.traversable(at(&g, 1.25, 2.0)));
    assert_eq!(g.cell(at(&g, 1.45, 2.0)), Cell::Unknown, "outside the radius");
    // Nothing bad from places off the grid, NaN or a radius wider than the grid.
    g.mark_driven(f64::NAN, 2.0, 0.3);
    g.mark_driven(1e9, 2.0, 0.3);
    g.mark_driven(1.0, 2.0, 1e12);
    assert!(g.traversable(at(&g, 9.0, 9.0)));
}

#[test]
fn a_thin_band_without_floor_returns_at_the_edge_of_the_seen_floor_is_looked_past() {
    // Floor seen up to x = 2.9; rays run on to x = 3.05 over the floor (returns 1.5 m up, over
    // the body), so the cells between are free with no floor return; past them, unknown.
    let mut g = grid();
    let mut scan = floor([0.1, 0.5], [2.9, 3.5], 0.0);
    scan.extend(line([3.05, 0.5], [3.05, 3.5], 1.5));
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), &scan);
    assert_eq!(g.cell(at(&g, 2.95, 2.0)), Cell::Free);
    assert!(!g.traversable(at(&g, 2.95, 2.0)), "no floor return in the band");
    let found = frontiers(&g, 3);
    assert!(
        found.iter().any(|f| (2.7..3.0).contains(&f.centroid_m[0])),
        "{:?}",
        found.iter().map(|f| f.centroid_m).collect::<Vec<_>>()
    );
}

#[test]
fn a_ray_clears_nothing_nearer_than_the_lidars_minimum_range() {
    let cfg = OccupancyConfig { extent_m: 20.0, min_range_m: 1.0, ..OccupancyConfig::default() };
    let mut g = OccupancyGrid::new(cfg, [0.0, 0.0]).unwrap();
    // A chair leg at (3, 2) seen from (1, 2), then, from (2.5, 2), 0.5 m from it and so
    // unseen, rays past it to the wall at x = 6 cross its cell.
    let leg = [Vector3::new(3.0, 2.0, 0.4)];
    g.add_scan(&Vector3::new(1.0, 2.0, 0.5), leg.iter());
    let wall = line([6.0, 1.8], [6.0, 2.2], 0.8);
    for _ in 0..20 {
        g.add_scan(&Vector3::new(2.5, 2.0, 0.5), wall.iter());
    }
    assert_eq!(g.cell(at(&g, 3.0, 2.0)), Cell::Occupied, "the leg is kept");
    assert_eq!(g.cell(at(&g, 4.0, 2.0)), Cell::Free, "past the minimum range the rays clear");
    // Without the minimum range the same rays wipe the leg out.
    let mut ideal = OccupancyGrid::new(OccupancyConfig { min_range_m: 0.0, ..cfg }, [0.0, 0.0]).unwrap();
    ideal.add_scan(&Vector3::new(1.0, 2.0, 0.5), leg.iter());
    for _ in 0..20 {
        ideal.add_scan(&Vector3::new(2.5, 2.0, 0.5), wall.iter());
    }
    assert_eq!(ideal.cell(at(&ideal, 3.0, 2.0)), Cell::Free);
}

#[test]
fn the_starts_blind_ring_is_floor_where_floor_was_seen_past_it() {
    let cfg = OccupancyConfig { extent_m: 20.0, min_range_m: 1.0, ..OccupancyConfig::default() };
    let mut g = OccupancyGrid::new(cfg, [0.0, 0.0]).unwrap();
    // Seen from (0, 0) with nothing nearer than 1 m: floor from 1.0 to 2.5 m all round, but
    // to the east a bed's side (0.4 m up) from 1.0 m on, which may reach into the ring.
    let mut pts = Vec::new();
    for k in 0..360 {
        let a = f64::from(k).to_radians();
        let east = a.cos() > 0.9;
        let mut d = 1.0;
        while d <= 2.5 {
            pts.push(Vector3::new(d * a.cos(), d * a.sin(), if east { 0.4 } else { 0.0 }));
            d += 0.05;
        }
    }
    g.add_scan(&Vector3::new(0.0, 0.0, 0.5), &pts);
    let (north, east) = (at(&g, 0.0, 0.7), at(&g, 0.7, 0.0));
    assert_eq!((g.cell(north), g.cell(east)), (Cell::Unknown, Cell::Unknown), "nothing seen inside 1 m");
    g.assume_blind_floor(0.0, 0.0, 0.95);
    assert!(g.traversable(north) && g.floor(north) == Some(0.0));
    assert!(!g.traversable(east) && g.cell(east) == Cell::Unknown, "not towards the bed");
}

#[test]
fn a_frontier_is_looked_at_from_beyond_the_minimum_range_by_the_cheapest_way() {
    let g = room_with_door(1.2);
    let robot = at(&g, 1.0, 2.0);
    let costs = Costs::from(&g, &usable(&g, robot, 0.35), robot);
    let target = at(&g, 6.5, 2.0);
    let v = viewpoint(&g, &costs, target, 1.1, 2.1).unwrap();
    let ([vx, vy], [tx, ty]) = (g.centre_of(v), g.centre_of(target));
    let d = (vx - tx).hypot(vy - ty);
    assert!((1.1..=2.1).contains(&d), "{d}");
    // On the way there, not round the far side: the room is west of the doorway.
    assert!(vx < 6.0 && (4.0..=5.5).contains(&vx), "{vx} {vy}");
    // Nothing can be reached that far from a target out in the unknown.
    assert!(viewpoint(&g, &costs, at(&g, 12.0, 2.0), 1.1, 2.1).is_none());
}
