//! The network's inputs as the .npy files scripts/train/onnx_reference.py reads, and its
//! outputs read back (the onnxruntime test and the pillars bench).

use starc_pipeline::detect::pillars::grid::{Pillars, MAX_POINTS, POINT_FEATURES};
use starc_pipeline::detect::pillars::npy::{le_bytes, npy};
use std::path::Path;

/// The f32 values of an .npy file numpy wrote (little-endian float32, C order).
pub fn read_f32_npy(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + len]).unwrap_or("");
    assert!(header.contains("'<f4'"), "{}: {header}", path.display());
    bytes[10 + len..].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

/// features.npy, mask.npy and coords.npy of `pillars` into `dir`.
pub fn write_inputs(dir: &Path, pillars: &Pillars) {
    let p = pillars.len();
    let mask: Vec<f32> = pillars
        .counts
        .iter()
        .flat_map(|&n| (0..MAX_POINTS).map(move |i| if i < usize::from(n) { 1.0 } else { 0.0 }))
        .collect();
    let coords: Vec<i64> = pillars.coords.iter().flat_map(|&(iy, ix)| [i64::from(iy), i64::from(ix)]).collect();
    let write = |name: &str, bytes: Vec<u8>| std::fs::write(dir.join(name), bytes).unwrap_or_else(|e| panic!("{e}"));
    write("features.npy", npy("<f4", &[p, MAX_POINTS, POINT_FEATURES], &le_bytes(&pillars.padded(), f32::to_le_bytes)));
    write("mask.npy", npy("<f4", &[p, MAX_POINTS], &le_bytes(&mask, f32::to_le_bytes)));
    write("coords.npy", npy("<i8", &[p, 2], &le_bytes(&coords, i64::to_le_bytes)));
}
