//! The Rust trees against scikit-learn: config/models/cluster_trees_reference.npy holds 64
//! validation clusters' input vectors and the probabilities scikit-learn's classifier gave them
//! (written by scripts/train/cluster_trees.py with the shipped trees); the built-in trees must
//! give the same.
#![allow(clippy::expect_used)]

use starc_pipeline::detect::trees::{load, CLASSES, INPUTS};
use starc_pipeline::detect::TreesConfig;
use std::path::PathBuf;

#[path = "support/pillars_io.rs"]
#[allow(dead_code)] // its writer is the onnxruntime test's
mod pillars_io;
use pillars_io::read_f32_npy;

#[test]
fn the_built_in_trees_give_scikit_learns_probabilities() {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/models/cluster_trees_reference.npy"));
    let rows = read_f32_npy(&path);
    let width = INPUTS + CLASSES;
    assert!(rows.len() >= 16 * width && rows.len().is_multiple_of(width), "{} values", rows.len());
    let model = load(&TreesConfig::default()).expect("the built-in trees");
    let mut worst = 0.0f32;
    let mut people = 0;
    for row in rows.chunks_exact(width) {
        let x: [f32; INPUTS] = row[..INPUTS].try_into().expect("a row");
        let ours = model.predict(&x);
        people += usize::from(row[INPUTS] < 0.5);
        for (a, b) in ours.iter().zip(&row[INPUTS..]) {
            worst = worst.max((a - b).abs());
        }
    }
    println!("{} rows ({people} more likely a person than not): max |dp| {worst:.2e}", rows.len() / width);
    assert!(worst < 1e-4, "max |dp| {worst}");
}
