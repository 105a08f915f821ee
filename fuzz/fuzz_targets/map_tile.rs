#![no_main]
//! Map tile parser: never panics on any bytes; what it accepts has one normal slot per point,
//! finite coordinates inside its tile, coverage voxels inside its tile, and is taken by a
//! TileMap exactly once per version. Each input is also tried resealed with a right CRC, so
//! the fuzzer explores what lies behind the checksum (format 2's coverage section among it).
use libfuzzer_sys::fuzz_target;
use starc_pipeline::align::{decode_tile, TileMap, Vec3};

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

fuzz_target!(|data: &[u8]| {
    check(data);
    if data.len() >= 4 {
        let mut sealed = data.to_vec();
        let n = sealed.len() - 4;
        let sum = CRC32.checksum(&sealed[..n]);
        sealed[n..].copy_from_slice(&sum.to_le_bytes());
        check(&sealed);
    }
});

fn check(data: &[u8]) {
    let Ok(tile) = decode_tile(data) else { return };
    assert_eq!(tile.points.len(), tile.normals.len());
    let lo = Vec3::new(f64::from(tile.key.0), f64::from(tile.key.1), f64::from(tile.key.2)) * tile.edge_m;
    for p in &tile.points {
        assert!(p.iter().all(|v| v.is_finite()));
        let d = p - lo;
        assert!(d.iter().all(|v| *v >= -1e-6 && *v <= tile.edge_m + 1e-6), "{p:?} outside tile {:?}", tile.key);
    }
    if let Some(c) = &tile.coverage {
        let m = (tile.edge_m / c.voxel_m).round() as i32;
        for v in &c.voxels {
            let of = (v.0.div_euclid(m), v.1.div_euclid(m), v.2.div_euclid(m));
            assert_eq!(of, tile.key, "voxel {v:?} outside tile {:?}", tile.key);
        }
    }
    let mut map = TileMap::default();
    assert!(map.apply(data).is_ok_and(|changed| changed));
    assert!(map.apply(data).is_ok_and(|changed| !changed));
    assert_eq!(map.coverage().is_some(), tile.coverage.is_some());
}
