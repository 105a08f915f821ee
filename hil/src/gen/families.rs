//! The building families: flats, offices, warehouses, halls and labs, each a floor plan with
//! its furniture and the person-sized things that are not people.

use crate::gen::furnish::Furnisher;
use crate::gen::layout::{corridor_with_rooms, outer_walls, room_widths, CorridorSpec, Dice, Shell};
use crate::gen::plan::{PlanFurniture, PlanWall, Rect, Region};
use crate::gen::Family;

/// A floor plan and its furniture, before people and routes.
pub struct Building {
    pub outline: Rect,
    pub ceiling_m: f64,
    pub floor_material: &'static str,
    pub walls: Vec<PlanWall>,
    /// Regions the robot and people may be in; the first is where the robot starts.
    pub regions: Vec<Region>,
    pub furniture: Furnisher,
    /// Raised floors people may stand on: footprint and height.
    pub platforms: Vec<(Rect, f64)>,
    /// The robot's start: x, y, heading (deg).
    pub entry: [f64; 3],
}

pub fn build(d: &mut Dice, family: Family) -> Building {
    match family {
        Family::Flat => flat(d),
        Family::Office => office(d),
        Family::Warehouse => warehouse(d),
        Family::Hall => hall(d),
        Family::Lab => lab(d),
    }
}

/// Things shaped like people, and other clutter, in any region.
fn distractors(d: &mut Dice, f: &mut Furnisher, region: &Region, n: usize) {
    const KINDS: [(&str, [f64; 3]); 7] = [
        ("mannequin", [0.5, 0.35, 1.8]),
        ("coat_stand", [0.5, 0.5, 1.8]),
        ("floor_lamp", [0.3, 0.3, 1.7]),
        ("plant", [0.5, 0.5, 1.2]),
        ("bin", [0.35, 0.35, 0.6]),
        ("pole", [0.06, 0.06, 2.2]),
        ("radiator", [1.0, 0.1, 0.6]),
    ];
    for _ in 0..n {
        if let Some((kind, size)) = d.pick(&KINDS) {
            f.against_wall(d, region, kind, size, None);
        }
    }
}

/// Furnishes every region from `first` on with `furnish`, then adds one or two distractors.
fn furnish_rooms(
    d: &mut Dice,
    b: &mut Building,
    first: usize,
    mut furnish: impl FnMut(&mut Dice, &mut Furnisher, &Region),
) {
    for region in b.regions.iter().skip(first) {
        furnish(d, &mut b.furniture, region);
        let n = d.count(1, 2);
        distractors(d, &mut b.furniture, region, n);
    }
}

fn corridor_building(d: &mut Dice, shell: Shell, spec: &CorridorSpec, floor_material: &'static str) -> Building {
    let layout = corridor_with_rooms(d, &shell, spec, "room ");
    let entry_y = spec.width_m / 2.0;
    let mut regions = vec![layout.corridor];
    regions.extend(layout.rooms);
    Building {
        outline: layout.outline,
        ceiling_m: shell.height_m,
        floor_material,
        walls: layout.walls,
        regions,
        furniture: Furnisher::default(),
        platforms: Vec::new(),
        entry: [0.9, entry_y, 0.0],
    }
}

fn flat(d: &mut Dice) -> Building {
    let height = d.range(2.4, 2.7);
    let shell = Shell::random(d, height);
    let length = d.range(9.0, 14.0);
    let spec = CorridorSpec {
        length_m: length,
        width_m: d.range(1.2, 1.5),
        north: room_widths(d, length, 3.0, 5.0),
        north_depth_m: d.range(3.2, 4.8),
        south: room_widths(d, length, 2.8, 4.5),
        south_depth_m: d.range(3.0, 4.2),
        door_width_m: (0.8, 0.9),
        closed_door_chance: 0.25,
    };
    let floor = if d.chance(0.5) { "carpet" } else { "wood" };
    let mut b = corridor_building(d, shell, &spec, floor);
    furnish_rooms(d, &mut b, 1, |d, f, region| match d.below(4) {
        0 => {
            f.bed_against_wall(d, region, [2.0, 1.4, 1.0]);
            f.against_wall(d, region, "shelving", [0.9, 0.4, 1.9], None);
            f.against_wall(d, region, "chair", [0.45, 0.45, 0.9], None);
        }
        1 => {
            f.against_wall(d, region, "sofa", [2.0, 0.9, 0.85], None);
            f.free_standing(d, region, "table", [1.0, 0.6, 0.45], 0.5);
            f.against_wall(d, region, "shelving", [1.0, 0.4, 1.9], None);
        }
        2 => {
            f.free_standing(d, region, "kitchen_island", [1.6, 0.9, 0.9], 0.8);
            f.against_wall(d, region, "cabinet", [1.8, 0.6, 0.9], None);
            f.against_wall(d, region, "chair", [0.45, 0.45, 0.9], None);
        }
        _ => {
            f.free_standing(d, region, "table", [1.2, 0.8, 0.75], 0.7);
            for _ in 0..3 {
                f.against_wall(d, region, "chair", [0.45, 0.45, 0.9], None);
            }
        }
    });
    b
}

fn office(d: &mut Dice) -> Building {
    let height = d.range(2.7, 3.2);
    let shell = Shell::random(d, height);
    let length = d.range(14.0, 20.0);
    let open_w = d.range(8.0, 12.0).min(length - 3.0);
    let mut north = vec![open_w];
    north.extend(room_widths(d, length - open_w, 3.0, 5.0));
    let spec = CorridorSpec {
        length_m: length,
        width_m: d.range(1.6, 2.2),
        north,
        north_depth_m: d.range(6.0, 9.0),
        south: room_widths(d, length, 3.5, 5.5),
        south_depth_m: d.range(3.5, 5.0),
        door_width_m: (0.9, 1.2),
        closed_door_chance: 0.2,
    };
    let mut b = corridor_building(d, shell, &spec, "carpet");
    if let Some(open) = b.regions.get(1).cloned() {
        cubicles(d, &mut b.furniture, &open);
        let n = d.count(2, 3);
        distractors(d, &mut b.furniture, &open, n);
    }
    furnish_rooms(d, &mut b, 2, |d, f, region| {
        if d.chance(0.5) {
            f.free_standing(d, region, "table", [2.2, 1.0, 0.75], 0.8);
            for _ in 0..4 {
                f.against_wall(d, region, "chair", [0.5, 0.5, 0.9], None);
            }
        } else {
            f.against_wall(d, region, "desk", [1.4, 0.7, 0.75], None);
            f.against_wall(d, region, "shelving", [1.0, 0.4, 1.9], None);
            f.free_standing(d, region, "round_table", [0.9, 0.9, 0.75], 0.7);
        }
    });
    b
}

/// Rows of desks between 1.2-1.6 m partitions, aisles between the rows.
fn cubicles(d: &mut Dice, f: &mut Furnisher, open: &Region) {
    let partition_h = d.range(1.2, 1.6);
    let r = open.rect.inset(1.2);
    let pitch_x = d.range(2.8, 3.4);
    let pitch_y = d.range(3.4, 4.2);
    let mut y = r.min[1] + 1.0;
    while y + 1.0 < r.max[1] {
        let mut x = r.min[0] + 0.9;
        while x + 0.9 < r.max[0] {
            let wall = PlanFurniture {
                kind: "cubicle_wall",
                at: [x, y],
                yaw_deg: 0.0,
                base_z_m: 0.0,
                size_m: [1.8, 0.06, partition_h],
                material: Some("fabric"),
            };
            if f.at(open, wall, 0.05).is_some() {
                // Its back (+y) on the partition, the chair facing it.
                let desk = PlanFurniture {
                    kind: "desk",
                    at: [x, y + 0.42],
                    yaw_deg: 180.0,
                    base_z_m: 0.0,
                    size_m: [1.4, 0.7, 0.75],
                    material: None,
                };
                f.at(open, desk, 0.02);
                let chair = PlanFurniture {
                    kind: "chair",
                    at: [x, y + 1.15],
                    yaw_deg: 0.0,
                    base_z_m: 0.0,
                    size_m: [0.5, 0.5, 0.95],
                    material: None,
                };
                if d.chance(0.7) {
                    f.at(open, chair, 0.02);
                }
            }
            x += pitch_x;
        }
        y += pitch_y;
    }
}

fn lab(d: &mut Dice) -> Building {
    let height = d.range(2.6, 3.2);
    let shell = Shell::random(d, height);
    let length = d.range(12.0, 20.0);
    let spec = CorridorSpec {
        length_m: length,
        width_m: d.range(1.8, 2.6),
        north: room_widths(d, length, 4.0, 8.0),
        north_depth_m: d.range(4.5, 7.0),
        south: if d.chance(0.6) { room_widths(d, length, 3.5, 6.0) } else { Vec::new() },
        south_depth_m: d.range(3.5, 5.5),
        door_width_m: (0.9, 1.1),
        closed_door_chance: 0.3,
    };
    let mut b = corridor_building(d, shell, &spec, "floor_tile");
    furnish_rooms(d, &mut b, 1, |d, f, region| {
        f.free_standing(d, region, "table", [1.6, 0.8, 0.9], 0.8);
        f.against_wall(d, region, "table", [1.8, 0.7, 0.9], None);
        f.against_wall(d, region, "shelving", [1.0, 0.45, 1.9], None);
        f.against_wall(d, region, "cabinet", [1.2, 0.5, 1.1], None);
        for _ in 0..2 {
            f.against_wall(d, region, "chair", [0.45, 0.45, 0.9], None);
        }
    });
    b
}

fn hall(d: &mut Dice) -> Building {
    let height = d.range(4.0, 7.0);
    let shell = Shell::random(d, height);
    let length = d.range(14.0, 22.0);
    let lobby_w = d.range(2.0, 3.0);
    let depth = d.range(12.0, 18.0);
    let spec = CorridorSpec {
        length_m: length,
        width_m: lobby_w,
        north: vec![length],
        north_depth_m: depth,
        south: Vec::new(),
        south_depth_m: 0.0,
        door_width_m: (1.2, 1.6),
        closed_door_chance: 0.0,
    };
    let mut b = corridor_building(d, shell, &spec, "carpet");
    let Some(hall) = b.regions.get(1).cloned() else { return b };
    let stage_depth = d.range(3.0, 4.5);
    let stage_h = d.range(0.6, 1.0);
    let stage = Rect::new([hall.rect.min[0], hall.rect.max[1] - stage_depth], hall.rect.max);
    b.furniture.items.push(PlanFurniture {
        kind: "box",
        at: stage.centre(),
        yaw_deg: 0.0,
        base_z_m: 0.0,
        size_m: [stage.size()[0], stage.size()[1], stage_h],
        material: Some("wood"),
    });
    b.platforms.push((stage, stage_h));
    seat_rows(d, &mut b.furniture, &hall, stage.min[1] - 2.0);
    let n = d.count(2, 3);
    distractors(d, &mut b.furniture, &hall, n);
    b
}

/// Rows of seats from the back of the hall to `front_y`, a side aisle and a centre aisle free.
fn seat_rows(d: &mut Dice, f: &mut Furnisher, hall: &Region, front_y: f64) {
    let pitch = d.range(0.9, 1.1);
    let aisle = 1.4;
    let (x0, x1) = (hall.rect.min[0] + aisle, hall.rect.max[0] - aisle);
    let mid = (x0 + x1) / 2.0;
    let mut y = hall.rect.min[1] + 3.0;
    while y + 0.6 < front_y {
        for (a, b) in [(x0, mid - aisle / 2.0), (mid + aisle / 2.0, x1)] {
            if b - a > 1.5 {
                // Facing the stage (+y): the seats' fronts are their local -y.
                let row = PlanFurniture {
                    kind: "seat_row",
                    at: [(a + b) / 2.0, y],
                    yaw_deg: 180.0,
                    base_z_m: 0.0,
                    size_m: [b - a, 0.6, 0.9],
                    material: Some("fabric"),
                };
                f.at(hall, row, 0.05);
            }
        }
        y += pitch;
    }
}

fn warehouse(d: &mut Dice) -> Building {
    let height = d.range(5.0, 8.0);
    let shell = Shell::random(d, height);
    let (w, h) = (d.range(18.0, 28.0), d.range(14.0, 22.0));
    let outline = Rect::new([0.0, 0.0], [w, h]);
    let walls = outer_walls(d, &shell, outline);
    let inner = outline.inset(shell.outer_thickness_m / 2.0);
    let main_aisle = Rect::new(inner.min, [inner.max[0], inner.min[1] + d.range(3.5, 4.5)]);
    let mut regions = vec![Region { name: "main aisle".into(), rect: main_aisle, entrance: None, walled: false }];
    let mut f = Furnisher::default();
    let (rack_depth, aisle_w) = (d.range(1.0, 1.2), d.range(2.6, 3.4));
    let rack_h = (height - 1.0).min(d.range(3.5, 5.5));
    let y0 = main_aisle.max[1] + 0.2;
    let y1 = inner.max[1] - 1.8;
    let mut x = inner.min[0] + aisle_w;
    let mut aisle_index = 0;
    while x + 2.0 * rack_depth + aisle_w < inner.max[0] {
        // A back-to-back double row of racks along y.
        let row_x = x + rack_depth;
        rack_row(&mut f, row_x, y0, y1, rack_depth, rack_h);
        let aisle_lo = x + 2.0 * rack_depth + 0.1;
        let aisle = Rect::new([aisle_lo, y0], [aisle_lo + aisle_w - 0.2, y1]);
        aisle_index += 1;
        regions.push(Region {
            name: format!("aisle {aisle_index}"),
            rect: aisle,
            entrance: Some([aisle.centre()[0], y0]),
            walled: false,
        });
        x += 2.0 * rack_depth + aisle_w;
    }
    for _ in 0..d.count(2, 5) {
        f.free_standing(d, &regions[0], "pallet_stack", [1.2, 0.8, 1.2], 0.9);
    }
    let n = d.count(1, 3);
    distractors(d, &mut f, &regions[0], n);
    let mut platforms = Vec::new();
    if let Some(last) = regions.last().cloned() {
        let p = Rect::new([last.rect.min[0] + 0.3, last.rect.max[1] - 2.5], [last.rect.max[0] - 0.3, last.rect.max[1]]);
        let ph = d.range(0.8, 1.2);
        let item = PlanFurniture {
            kind: "box",
            at: p.centre(),
            yaw_deg: 0.0,
            base_z_m: 0.0,
            size_m: [p.size()[0], p.size()[1], ph],
            material: Some("metal"),
        };
        if f.at(&last, item, 0.0).is_some() {
            platforms.push((p, ph));
        }
    }
    for region in regions.iter().skip(1) {
        if d.chance(0.6) {
            f.free_standing(d, region, "pallet", [1.2, 0.8, 0.15], 0.3);
        }
    }
    Building {
        outline,
        ceiling_m: height,
        floor_material: "concrete",
        walls,
        regions,
        furniture: f,
        platforms,
        entry: [inner.min[0] + 1.0, main_aisle.centre()[1], 0.0],
    }
}

/// Rack units end to end along y at `row_x` (two back to back), from `y0` to `y1`.
fn rack_row(f: &mut Furnisher, row_x: f64, y0: f64, y1: f64, depth: f64, height: f64) {
    let unit = 2.7;
    let mut y = y0 + unit / 2.0;
    while y + unit / 2.0 <= y1 {
        for dx in [-depth / 2.0, depth / 2.0] {
            f.items.push(PlanFurniture {
                kind: "rack",
                at: [row_x + dx, y],
                yaw_deg: 90.0,
                base_z_m: 0.0,
                size_m: [unit, depth, height],
                material: Some("metal"),
            });
        }
        y += unit;
    }
}
