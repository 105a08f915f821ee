#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;
use nalgebra::Isometry3;

/// A 10 x 8 m room, floor at z = -1.2 and ceiling at 1.6 (so fixed heights would be wrong), with
/// a table (a smaller horizontal surface at -0.45) and a wall-mounted shelf board.
fn room() -> Vec<Vec3> {
    let mut pts = Vec::new();
    let step = 0.05;
    for i in 0..=200 {
        for j in 0..=160 {
            let (x, y) = (f64::from(i) * step, f64::from(j) * step);
            pts.push(Vec3::new(x, y, -1.2));
            pts.push(Vec3::new(x, y, 1.6));
        }
    }
    for i in 0..=200 {
        for k in 0..=56 {
            let (a, z) = (f64::from(i) * step, -1.2 + f64::from(k) * step);
            pts.push(Vec3::new(a, 0.0, z));
            pts.push(Vec3::new(a, 8.0, z));
            pts.push(Vec3::new(0.0, a * 0.8, z));
            pts.push(Vec3::new(10.0, a * 0.8, z));
        }
    }
    for i in 0..=30 {
        for j in 0..=16 {
            pts.push(Vec3::new(4.0 + f64::from(i) * step, 3.0 + f64::from(j) * step, -0.45));
        }
    }
    pts
}

#[test]
fn floor_and_ceiling_are_estimated_and_the_bands_removed() {
    let c = MapPrepConfig { band_keep_voxel_m: 0.0, ..MapPrepConfig::default() };
    let m = prepare_map(&room(), &c).unwrap();
    assert!((m.floor_z_m - -1.2).abs() < 0.06, "floor {}", m.floor_z_m);
    assert!((m.ceiling_z_m - 1.6).abs() < 0.06, "ceiling {}", m.ceiling_z_m);
    assert!(m.removed_ground > 1000 && m.removed_ceiling > 1000, "{} {}", m.removed_ground, m.removed_ceiling);
    let (lo, hi) = (m.floor_z_m + c.ground_band_m, m.ceiling_z_m - c.ceiling_band_m);
    assert!(m.points.iter().all(|p| p.z >= lo && p.z <= hi));
    // The table stays (it is above the ground band), and so do the walls between the bands.
    assert!(m.points.iter().any(|p| (p.z - -0.45).abs() < 0.06 && p.x > 4.0 && p.x < 5.5));
    assert!(m.points.iter().any(|p| p.x.abs() < 0.06 && p.z > 0.0));
    assert_eq!(m.points.len(), m.normals.len());
    // The default keeps the bands thinned to 0.5 m: a few floor and ceiling points, not thousands.
    let thin = prepare_map(&room(), &MapPrepConfig::default()).unwrap();
    let banded = thin.points.len() - m.points.len();
    assert!(banded > 100 && banded < (m.removed_ground + m.removed_ceiling) / 10, "{banded}");
    assert!(thin.points.iter().any(|p| (p.z - -1.2).abs() < 0.1));
    // Nothing horizontal: no floor, a typed error.
    let wall: Vec<Vec3> = (0..2000).map(|i| Vec3::new(f64::from(i % 50) * 0.1, 0.0, f64::from(i / 50) * 0.1)).collect();
    assert!(prepare_map(&wall, &c).is_err());
    assert!(prepare_map(&[], &c).is_err());
}

#[test]
fn window_drops_boxes_and_moving_points() {
    // A wall at x = 5 seen through the whole window, a person box at (2, 0), and a "walker"
    // point that moves 1 m/s along y (each place seen in one slice only).
    let mut pts = Vec::new();
    for k in 0..1000u64 {
        let t = k * 1_000_000; // 1 s
        let y = (k % 100) as f64 * 0.05 - 2.5;
        pts.push((t, Vec3::new(5.0, y, 1.0)));
        pts.push((t, Vec3::new(2.0, 0.1 * (k % 3) as f64, 1.0)));
        pts.push((t, Vec3::new(3.0, -2.0 + t as f64 * 1e-9 * 4.0, 0.5)));
    }
    let person = ExclusionBox { centre: Vec3::new(2.0, 0.0, 0.9), size_m: Vec3::new(0.6, 0.6, 1.8), yaw_rad: 0.5 };
    let c = WindowConfig::default();
    let (out, stats) = aggregate_window(&pts, |_| Some(Isometry3::identity()), &Isometry3::identity(), &[person], &c);
    assert_eq!(stats.points_in, 3000);
    assert_eq!(stats.excluded_boxes, 1000);
    // The walker survives only where a voxel straddles a slice boundary (4 boundaries).
    assert!(stats.excluded_moving >= 800, "{stats:?}");
    let off_wall = out.iter().filter(|p| (p.x - 5.0).abs() > 1e-9).count();
    assert!(off_wall <= 10, "{off_wall} points off the wall: {stats:?}");
    assert!(out.len() - off_wall >= 40, "the wall stays: {stats:?}");
    assert_eq!(stats.points_out, out.len());
    // Points the poses cannot place are left out.
    let (none, s) = aggregate_window(&pts, |_| None, &Isometry3::identity(), &[], &c);
    assert!(none.is_empty() && s.points_out == 0);
}

#[test]
fn with_rays_a_walker_goes_and_a_briefly_seen_wall_stays() {
    // 4 s from the origin: a wall at x = 6 in view throughout; a walker standing at x = 3 in
    // the first 0.4 s, then gone (rays to the wall pass where they stood); a side wall at y = 4
    // seen only in one half second (the rig turned its head). Every point is also a ray.
    let mut placed = Vec::new();
    let mut rays = Vec::new();
    let origin = Vec3::new(0.0, 0.0, 0.0);
    let mut shoot = |t_us: u32, end: Vec3| {
        placed.push(PlacedPoint::new(u64::from(t_us), &end));
        rays.push((t_us, Ray { origin, end }));
    };
    for k in 0..4000u32 {
        let t_us = k * 1000;
        let y = f64::from(k % 40) * 0.02 - 0.4;
        let z = f64::from(k % 7) * 0.05 - 0.15;
        if t_us < 400_000 {
            shoot(t_us, Vec3::new(3.0, y * 0.5, z));
        }
        shoot(t_us, Vec3::new(6.0, y, z));
        if (1_700_000..2_200_000).contains(&t_us) {
            shoot(t_us, Vec3::new(2.0 + f64::from(k % 20) * 0.1, 4.0, z));
        }
    }
    let c = WindowConfig { voxel_m: 0.05, ..WindowConfig::default() };
    let (out, stats) = filter_window(&placed, &rays, &Isometry3::identity(), &[], &c);
    assert_eq!(stats.excluded_moving, 400, "the walker's points, and only those: {stats:?}");
    assert!(out.iter().all(|p| p.x > 3.2 || p.y > 3.0), "no walker left");
    assert!(out.iter().any(|p| (p.y - 4.0).abs() < 1e-6), "the side wall seen once stays");
    // Without the rays the slices decide, and they take the side wall too (each of its voxels
    // was seen in one slice of five): what the rays avoid.
    let (_, sliced) = filter_window(&placed, &[], &Isometry3::identity(), &[], &c);
    assert!(sliced.excluded_moving >= 400 + 400, "{sliced:?}");
}

#[test]
fn tiles_round_trip_and_newer_versions_win() {
    let m = prepare_map(&room(), &MapPrepConfig::default()).unwrap();
    let tiles = encode_tiles(&m.points, &m.normals, 4.0, 0.01, 1).unwrap();
    assert!(tiles.len() > 4);
    let mut map = TileMap::default();
    for (_, b) in &tiles {
        assert!(map.apply(b).unwrap());
    }
    let (pts, nrm) = map.points();
    assert_eq!(pts.len(), m.points.len());
    // 1 cm steps: every point within half a step per axis of one original.
    let mut orig: Vec<Vec3> = m.points.clone();
    orig.sort_by(|a, b| a.x.total_cmp(&b.x));
    for p in pts.iter().step_by(97) {
        assert!(m.points.iter().any(|q| (p - q).amax() <= 0.005 + 1e-9), "{p:?}");
    }
    let with_normals = nrm.iter().filter(|n| n.is_some()).count();
    assert_eq!(with_normals, m.normals.iter().filter(|n| n.is_some()).count());
    // Same version again: ignored; a newer one replaces the tile.
    let (key, first) = &tiles[0];
    assert!(!map.apply(first).unwrap());
    let only: Vec<Vec3> =
        vec![Vec3::new(f64::from(key.0) * 4.0 + 0.5, f64::from(key.1) * 4.0 + 0.5, f64::from(key.2) * 4.0 + 0.5)];
    let newer = encode_tiles(&only, &[None], 4.0, 0.01, 2).unwrap();
    assert!(map.apply(&newer[0].1).unwrap());
    assert_eq!(map.tile_count(), tiles.len());
}

#[test]
fn tiles_carry_the_side_each_point_was_seen_from() {
    let pts = vec![Vec3::new(0.5, 0.5, 0.5), Vec3::new(1.0, 2.0, 3.0)];
    let towards = [Some(Vec3::new(-3.0, 0.0, 4.0)), None];
    let b = encode_tile((0, 0, 0), &pts, TileVectors::TowardsSensor(&towards), 4.0, 0.01, 5, None).unwrap();
    let t = decode_tile(&b).unwrap();
    assert_eq!(t.normals, vec![None, None]);
    let d = t.towards_sensor[0].unwrap();
    assert!((d - Vec3::new(-0.6, 0.0, 0.8)).norm() < 0.01, "{d:?}");
    assert_eq!(t.towards_sensor[1], None);
    let mut map = TileMap::default();
    assert!(map.apply(&b).unwrap());
    let (p, towards) = map.points_seen_from();
    assert_eq!((p.len(), towards[1]), (2, Vec3::zeros()));
    // Normals stay normals; a vectors field other than 0 or 1 is refused.
    let n = decode_tile(
        &encode_tile(
            (0, 0, 0),
            &pts,
            TileVectors::Normals(&towards.iter().map(|d| Some(*d)).collect::<Vec<_>>()),
            4.0,
            0.01,
            5,
            None,
        )
        .unwrap(),
    )
    .unwrap();
    assert!(n.normals[0].is_some() && n.towards_sensor.iter().all(Option::is_none));
    let mut odd = b.clone();
    odd[10] = 2;
    let body = odd.len() - 4;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&odd[..body]);
    odd[body..].copy_from_slice(&crc.to_le_bytes());
    assert!(decode_tile(&odd).is_err());
}

#[test]
fn damaged_tiles_are_typed_errors() {
    let pts = vec![Vec3::new(0.5, 0.5, 0.5), Vec3::new(1.0, 2.0, 3.0)];
    let tiles = encode_tiles(&pts, &[None, Some(Vec3::new(0.0, 0.0, 1.0))], 4.0, 0.01, 7).unwrap();
    let good = &tiles[0].1;
    let t = decode_tile(good).unwrap();
    assert_eq!((t.key, t.version, t.points.len()), ((0, 0, 0), 7, 2));
    // Every truncation, every single-bit flip: an error, never a panic.
    for n in 0..good.len() {
        assert!(decode_tile(&good[..n]).is_err(), "truncated to {n}");
    }
    for i in 0..good.len() {
        for bit in 0..8 {
            let mut b = good.clone();
            b[i] ^= 1 << bit;
            assert!(decode_tile(&b).is_err(), "byte {i} bit {bit}");
        }
    }
    let mut long = good.clone();
    long.push(0);
    assert!(matches!(decode_tile(&long), Err(crate::PipelineError::Truncated { .. })));
    assert!(encode_tiles(&pts, &[None, None], 0.0, 0.01, 1).is_err());
    assert!(encode_tiles(&pts, &[None, None], 1000.0, 0.001, 1).is_err());
}

#[test]
fn coverage_tiles_carry_the_crossed_voxels_and_refuse_damage() {
    use crate::align::{encode_tile, Coverage};
    let mut cov = Coverage::new(0.25);
    // Rays along +x at y 0.6 from x -1 (tile -1) into tile 0; and one ray only once, at y 2.1.
    for _ in 0..2 {
        cov.add_ray(&Vec3::new(-1.0, 0.6, 1.1), &Vec3::new(3.0, 0.6, 1.1));
    }
    cov.add_ray(&Vec3::new(0.1, 2.1, 1.1), &Vec3::new(3.0, 2.1, 1.1));
    let pts = vec![Vec3::new(3.0, 0.6, 1.1)];
    let good = encode_tile((0, 0, 0), &pts, TileVectors::Normals(&[None]), 4.0, 0.01, 3, Some((&cov, 2))).unwrap();
    assert_eq!(good.len(), 32 + 10 + 8 + 512 + 4, "16^3 voxels: 512 bytes");
    let t = decode_tile(&good).unwrap();
    let c = t.coverage.clone().unwrap();
    assert_eq!((c.min_crossings, c.voxel_m), (2, 0.25));
    // The tile holds x 0..4: the twice-crossed voxels from 0 to 2.5 m (the ray's last 0.5 m is
    // not free), none of the once-crossed ones.
    assert_eq!(c.voxels.len(), 11, "{:?}", c.voxels);
    assert!(c.voxels.iter().all(|v| v.1 == 2 && v.2 == 4 && (0..=10).contains(&v.0)), "{:?}", c.voxels);
    let mut map = TileMap::default();
    map.apply(&good).unwrap();
    let rebuilt = map.coverage().unwrap();
    assert_eq!(rebuilt.crossings(&Vec3::new(1.0, 0.6, 1.1)), 2);
    assert_eq!(rebuilt.crossings(&Vec3::new(1.0, 2.1, 1.1)), 0);
    assert_eq!(rebuilt.crossings(&Vec3::new(-0.5, 0.6, 1.1)), 0, "another tile's");
    // A negative tile keys its voxels below zero.
    let neg =
        decode_tile(&encode_tile((-1, 0, 0), &[], TileVectors::Normals(&[]), 4.0, 0.01, 3, Some((&cov, 2))).unwrap())
            .unwrap();
    assert_eq!(neg.coverage.unwrap().voxels.len(), 4, "x -1 to 0");
    // Truncations and bit flips are errors; so are pad bits or sizes that do not tile, even
    // under a right CRC.
    for n in 0..good.len() {
        assert!(decode_tile(&good[..n]).is_err(), "truncated to {n}");
    }
    for i in (0..good.len()).step_by(7) {
        let mut b = good.clone();
        b[i] ^= 0x10;
        assert!(decode_tile(&b).is_err(), "byte {i}");
    }
    let mut voxel = good.clone();
    voxel[42..44].copy_from_slice(&300u16.to_le_bytes());
    assert!(decode_tile(&resealed(voxel)).is_err(), "4 m is no whole number of 0.3 m voxels");
    let mut odd =
        encode_tile((0, 0, 0), &[], TileVectors::Normals(&[]), 0.75, 0.01, 1, Some((&Coverage::new(0.25), 1))).unwrap();
    assert!(decode_tile(&odd).is_ok());
    let pad = odd.len() - 5;
    odd[pad] |= 0x80;
    assert!(decode_tile(&resealed(odd)).is_err(), "27 voxels: the pad bits must be 0");
    assert!(
        encode_tile((0, 0, 0), &[], TileVectors::Normals(&[]), 4.0, 0.01, 1, Some((&Coverage::new(0.3), 2))).is_err()
    );
}

#[test]
fn a_coverage_tile_whose_voxel_keys_would_overflow_is_refused() {
    use crate::align::{encode_tile, Coverage};
    let cov = Coverage::new(0.25);
    // Tile keys this far out have no i32 voxel keys at 16 voxels per edge.
    assert!(encode_tile((i32::MAX / 4, 0, 0), &[], TileVectors::Normals(&[]), 4.0, 0.01, 1, Some((&cov, 2))).is_err());
    let good = encode_tile((0, 0, 0), &[], TileVectors::Normals(&[]), 4.0, 0.01, 1, Some((&cov, 2))).unwrap();
    let mut far = good.clone();
    far[12..16].copy_from_slice(&(i32::MAX / 4).to_le_bytes());
    assert!(decode_tile(&resealed(far)).is_err());
    // At the edge of the range it still decodes.
    let edge = encode_tile(
        (i32::MAX / 16 - 1, -(i32::MAX / 16), 0),
        &[],
        TileVectors::Normals(&[]),
        4.0,
        0.01,
        1,
        Some((&cov, 2)),
    )
    .unwrap();
    assert!(decode_tile(&edge).is_ok());
}

/// `b` with its last four bytes replaced by the right CRC of the rest: a forged tile that only
/// the parser's other checks can refuse.
fn resealed(mut b: Vec<u8>) -> Vec<u8> {
    let n = b.len() - 4;
    let sum = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&b[..n]);
    b[n..].copy_from_slice(&sum.to_le_bytes());
    b
}
