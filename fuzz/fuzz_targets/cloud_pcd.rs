#![no_main]
//! PCD reader: never panics on any bytes, and whatever it reads survives a write and a second
//! read unchanged, in both encodings.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::cloud::{pcd, to_bytes, CloudFormat, CloudPoint, PointCloud};

fn same(a: &PointCloud, b: &PointCloud) -> bool {
    let bits = |p: &CloudPoint| {
        let f = |v: f32| if v.is_nan() { u32::MAX } else { v.to_bits() };
        (f(p.x_m), f(p.y_m), f(p.z_m), f(p.intensity), p.offset_ns, p.line, p.tag)
    };
    a.start == b.start
        && a.points.len() == b.points.len()
        && a.points.iter().zip(&b.points).all(|(p, q)| bits(p) == bits(q))
}

fuzz_target!(|data: &[u8]| {
    if let Ok(cloud) = pcd::read_bytes(data) {
        for format in [CloudFormat::PcdBinary, CloudFormat::PcdAscii] {
            let again = pcd::read_bytes(&to_bytes(&cloud, format));
            assert!(again.as_ref().is_ok_and(|c| same(c, &cloud)), "{format}: {again:?}");
        }
    }
});
