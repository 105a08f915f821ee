//! plots/: the rig's pose error and the inlier ratio over time, the latency histogram.

use crate::error::{write, EvalError, Result};
use crate::svg_plot::{histogram, lines, Series};
use std::path::Path;

/// Writes `pose_error.svg`, `inlier_ratio.svg` and `latency.svg` into `out/plots`.
pub fn write_plots(out: &Path, err_cm: &[(f64, f64)], inlier_pct: &[(f64, f64)], total_ms: &[f64]) -> Result<()> {
    let dir = out.join("plots");
    std::fs::create_dir_all(&dir).map_err(|source| EvalError::Write { path: dir.clone(), source })?;
    let err = lines(
        "rig world pose error against the truth",
        "time (s)",
        "position error (cm)",
        &[Series { name: "rig", colour: "#c33", points: err_cm }],
    );
    let inl = lines(
        "projected person points inside the see-through mask",
        "time (s)",
        "inlier ratio (%)",
        &[Series { name: "per frame", colour: "#36c", points: inlier_pct }],
    );
    let lat = histogram("compute latency per robot scan (LIO + detection + AR frame)", "ms", total_ms, 30);
    for (name, svg) in [("pose_error.svg", err), ("inlier_ratio.svg", inl), ("latency.svg", lat)] {
        write(&dir.join(name), svg)?;
    }
    Ok(())
}
