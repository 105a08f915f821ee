use super::*;
use crate::sim::scenario::builtin_albedo;

fn albedo(m: &str) -> f32 {
    builtin_albedo(m).unwrap_or(-1.0) as f32
}

/// The solid's extreme points in the item's frame: (min, max) corners of its bounds there.
fn local_bounds(item: &Furniture, s: &Solid) -> (V3, V3) {
    let (sin, cos) = item.yaw_rad().sin_cos();
    let local = |p: V3| {
        let (x, y) = (p.x - item.at[0], p.y - item.at[1]);
        V3::new(cos * x + sin * y, -sin * x + cos * y, p.z - item.base_z_m)
    };
    let round = |c: V3, r: f64| (c - V3::repeat(r), c + V3::repeat(r));
    match s {
        Solid::Box(b) => {
            // A box turned with the item is axis-aligned in its frame: its centre and halves.
            let c = local(b.centre);
            assert!((b.yaw_rad() - item.yaw_rad()).sin().abs() < 1e-9);
            (c - b.half, c + b.half)
        }
        Solid::Cylinder(c) => {
            let (lo, hi) = round(local(V3::new(c.x_m, c.y_m, 0.0)), c.radius_m);
            (V3::new(lo.x, lo.y, c.z0_m - item.base_z_m), V3::new(hi.x, hi.y, c.z1_m - item.base_z_m))
        }
        Solid::Capsule(c) => {
            let (a, b) = (round(local(c.a), c.radius), round(local(c.b), c.radius));
            (a.0.inf(&b.0), a.1.sup(&b.1))
        }
    }
}

fn assert_inside(item: &Furniture) {
    let [l, w, h] = item.size_m();
    let half = V3::new(l / 2.0, w / 2.0, h);
    let solids = item.solids(albedo);
    assert!(!solids.is_empty(), "{}", item.kind);
    for s in &solids {
        let (lo, hi) = local_bounds(item, s);
        let eps = 1e-9;
        let ok = lo.x >= -half.x - eps && lo.y >= -half.y - eps && lo.z >= -eps;
        let ok = ok && hi.x <= half.x + eps && hi.y <= half.y + eps && hi.z <= half.z + eps;
        assert!(ok, "{} {:?}: {lo:?} {hi:?} outside {half:?}", item.kind, item.size_m);
        assert!((lo - hi).iter().all(|v| *v < 0.0), "{} {:?}: empty part {s:?}", item.kind, item.size_m);
        assert!(s.albedo() >= 0.0, "{}: unknown material", item.kind);
    }
}

#[test]
fn every_part_lies_in_the_items_box() {
    let sizes = [[0.3, 0.2, 0.4], [3.0, 2.0, 2.5], [0.05, 0.05, 0.05], [8.0, 0.5, 6.0], [0.9, 1.7, 0.7]];
    for kind in FurnitureKind::ALL {
        for (i, yaw_deg) in [0.0, 90.0, 33.0, -127.0].into_iter().enumerate() {
            let mut item = Furniture { yaw_deg, base_z_m: 0.4 * i as f64, ..Furniture::new(kind, [3.0, -2.0]) };
            assert_inside(&item);
            for size in sizes {
                item.size_m = Some(size);
                assert_inside(&item);
            }
        }
    }
}

#[test]
fn kinds_and_defaults() {
    assert_eq!(FurnitureKind::ALL.len(), 24);
    for (i, kind) in FurnitureKind::ALL.iter().enumerate() {
        assert!(!FurnitureKind::ALL[..i].contains(kind));
        assert!(kind.default_size_m().iter().all(|v| *v > 0.0));
        assert!(builtin_albedo(kind.default_material()).is_some(), "{kind}");
        let parsed: Result<FurnitureKind, _> = serde::Deserialize::deserialize(toml::Value::String(kind.name().into()));
        assert_eq!(parsed.ok(), Some(*kind));
    }
    for kind in FurnitureKind::ALL {
        let item = Furniture::new(kind, [0.0, 0.0]);
        assert!(item.materials().iter().all(|m| builtin_albedo(m).is_some()), "{kind}");
    }
    let bed = Furniture { material: Some("metal".into()), ..Furniture::new(FurnitureKind::Bed, [0.0, 0.0]) };
    assert_eq!(bed.materials(), ["metal", "fabric"]);
    assert_eq!(FurnitureKind::Chair.default_size_m(), [0.45, 0.45, 0.9]);
    assert_eq!(FurnitureKind::Rack.name(), "rack");
}

#[test]
fn footprint_material_and_check() {
    let mut item = Furniture { yaw_deg: 90.0, ..Furniture::new(FurnitureKind::Table, [1.0, 2.0]) };
    let (c, half, yaw) = item.footprint();
    assert_eq!((c, half), ([1.0, 2.0], [0.7, 0.4]));
    assert!((yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert_eq!((item.material(), item.label()), ("wood", "table".to_string()));
    assert!(item.check().is_ok());
    item.size_m = Some([1.0, 0.0, 1.0]);
    assert!(item.check().is_err_and(|e| e.contains("width")));
    item.size_m = Some([1.0, 1.0, 1e3]);
    assert!(item.check().is_err_and(|e| e.contains("height")));
    item.size_m = None;
    item.at[0] = f64::NAN;
    assert!(item.check().is_err());
}

/// The main material follows the item; accents (a mattress) keep theirs.
#[test]
fn material_applies_to_the_main_parts() {
    let bed = Furniture { material: Some("metal".into()), ..Furniture::new(FurnitureKind::Bed, [0.0, 0.0]) };
    let albedos: Vec<f32> = bed.solids(albedo).iter().map(Solid::albedo).collect();
    assert!(albedos.contains(&0.6) && albedos.contains(&0.2) && !albedos.contains(&0.45), "{albedos:?}");
}

/// The same item in the same place gives the same parts; moved, its shelves fill differently.
#[test]
fn contents_follow_the_position() {
    let a = Furniture::new(FurnitureKind::Shelving, [1.0, 1.0]);
    assert_eq!(a.solids(albedo), a.solids(albedo));
    let count = |x: f64| Furniture::new(FurnitureKind::Rack, [x, 0.0]).solids(albedo).len();
    let counts: Vec<usize> = (0..8).map(|i| count(f64::from(i) * 3.0)).collect();
    assert!(counts.iter().any(|c| *c != counts[0]), "{counts:?}");
    let shelf = Furniture::new(FurnitureKind::Shelving, [0.0, 0.0]).solids(albedo);
    assert!(shelf.len() > 7 + 3, "shelving has items on its shelves: {}", shelf.len());
}

/// Kinds are made of the primitives they should be.
#[test]
fn kinds_use_round_parts() {
    let count =
        |kind, f: fn(&Solid) -> bool| Furniture::new(kind, [0.0, 0.0]).solids(albedo).iter().filter(|s| f(s)).count();
    let cyl = |s: &Solid| matches!(s, Solid::Cylinder(_));
    let cap = |s: &Solid| matches!(s, Solid::Capsule(_));
    assert_eq!(count(FurnitureKind::Pillar, cyl), 1);
    assert_eq!(count(FurnitureKind::RoundTable, cyl), 3);
    assert!(count(FurnitureKind::Plant, cap) >= 5);
    assert!(count(FurnitureKind::Mannequin, cap) >= 3 && count(FurnitureKind::CoatStand, cap) >= 4);
    assert_eq!(count(FurnitureKind::Chair, |s| matches!(s, Solid::Box(_))), 8);
    // Eight seats on a 4 m row, each a seat, a back and a post.
    assert_eq!(Furniture::new(FurnitureKind::SeatRow, [0.0, 0.0]).solids(albedo).len(), 3 + 8 * 3);
}
