//! Reading the simulator's TUM ground truth back, for the code below `starc-eval` in the
//! dependency graph, which cannot use `starc_eval::truth::{read_tum, at}`: the benches and
//! examples of starc-hil and starc-pipeline (starc-eval depends on both), and `detect_sim.rs`,
//! which starc-hil's detect bench shares. The root crate's tests use starc_eval.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::path::Path;

/// (PTP ns, pose) per line of a TUM file (`time tx ty tz qx qy qz qw`, time in seconds with
/// nanosecond digits, as the simulator writes it).
pub fn read_tum(path: &Path) -> Vec<(u64, Isometry3<f64>)> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let (s, ns) = f[0].split_once('.').unwrap_or_else(|| panic!("bad time in {l:?}"));
            let whole = |x: &str| x.parse::<u64>().unwrap_or_else(|e| panic!("{x:?}: {e}"));
            let t = whole(s) * 1_000_000_000 + whole(ns);
            let v: Vec<f64> = f[1..].iter().map(|x| x.parse().unwrap_or_else(|e| panic!("{x:?}: {e}"))).collect();
            let q = UnitQuaternion::from_quaternion(Quaternion::new(v[6], v[3], v[4], v[5]));
            (t, Isometry3::from_parts(Translation3::new(v[0], v[1], v[2]), q))
        })
        .collect()
}

/// The truth at `t`, interpolated between its samples (200 Hz).
pub fn truth_at(tum: &[(u64, Isometry3<f64>)], t: u64) -> Isometry3<f64> {
    let i = tum.partition_point(|(s, _)| *s <= t).clamp(1, tum.len() - 1);
    let ((ta, a), (tb, b)) = (tum[i - 1], tum[i]);
    let f = ((t as f64 - ta as f64) / (tb as f64 - ta as f64)).clamp(0.0, 1.0);
    a.lerp_slerp(&b, f)
}
