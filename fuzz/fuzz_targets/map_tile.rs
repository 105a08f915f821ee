#![no_main]
//! Map tile parser: never panics on any bytes; what it accepts has one normal slot per point,
//! finite coordinates inside its tile, and is taken by a TileMap exactly once per version.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::align::{decode_tile, TileMap, Vec3};

fuzz_target!(|data: &[u8]| {
    if let Ok(tile) = decode_tile(data) {
        assert_eq!(tile.points.len(), tile.normals.len());
        let lo = Vec3::new(f64::from(tile.key.0), f64::from(tile.key.1), f64::from(tile.key.2)) * tile.edge_m;
        for p in &tile.points {
            assert!(p.iter().all(|v| v.is_finite()));
            let d = p - lo;
            assert!(d.iter().all(|v| *v >= -1e-6 && *v <= tile.edge_m + 1e-6), "{p:?} outside tile {:?}", tile.key);
        }
        let mut map = TileMap::default();
        assert!(map.apply(data).is_ok_and(|changed| changed));
        assert!(map.apply(data).is_ok_and(|changed| !changed));
    }
});
