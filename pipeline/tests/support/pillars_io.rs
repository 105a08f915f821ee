//! The network's inputs as the .npy files scripts/train/onnx_reference.py reads, and its
//! outputs read back (the onnxruntime test and the pillars bench).

use starc_pipeline::detect::pillars::grid::{Pillars, MAX_POINTS, POINT_FEATURES};
use std::path::Path;

pub fn npy(dtype: &str, shape: &[usize], data: Vec<u8>) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let mut header = format!("{{'descr': '{dtype}', 'fortran_order': False, 'shape': ({},), }}", dims.join(", "));
    header.push_str(&" ".repeat(63 - (10 + header.len()) % 64));
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    out.extend(data);
    out
}

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
    let f32_bytes = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let mask: Vec<f32> = pillars
        .counts
        .iter()
        .flat_map(|&n| (0..MAX_POINTS).map(move |i| if i < usize::from(n) { 1.0 } else { 0.0 }))
        .collect();
    let coords: Vec<u8> =
        pillars.coords.iter().flat_map(|&(iy, ix)| [i64::from(iy), i64::from(ix)]).flat_map(i64::to_le_bytes).collect();
    let write = |name: &str, bytes: Vec<u8>| std::fs::write(dir.join(name), bytes).unwrap_or_else(|e| panic!("{e}"));
    write("features.npy", npy("<f4", &[p, MAX_POINTS, POINT_FEATURES], f32_bytes(&pillars.features)));
    write("mask.npy", npy("<f4", &[p, MAX_POINTS], f32_bytes(&mask)));
    write("coords.npy", npy("<i8", &[p, 2], coords));
}
