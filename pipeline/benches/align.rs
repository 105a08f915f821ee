//! Registration accuracy and time on the real scan pair (shared/data/registration).
//!
//! Run with `cargo bench -p starc-pipeline --bench align`. Prints:
//! - the target preparation time (NDT grids, normals);
//! - from identity and from yaw starts (about the true position): error (cm, deg), NDT and ICP
//!   time, attempts, accepted or not, with reseeding on (the defaults);
//! - the basin: single attempts (no reseeding) from yaw errors 0-180 deg in 5 deg steps, with and
//!   without a 1 m shift, and the largest yaw error below which every start converged;
//! - a grid, yaw every 30 deg x shift 0/1/2 m (along a direction that turns with the yaw), with
//!   reseeding on: success rate (accepted and within 5 cm / 0.5 deg) and median time.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use starc_pipeline::align::{cloud_points, pose_error, pose_from_rows, AlignConfig, AlignReport, Aligner};
use std::path::PathBuf;

fn start(truth: &Isometry3<f64>, yaw_deg: f64, shift_m: f64) -> Isometry3<f64> {
    let dir = f64::to_radians(yaw_deg * 0.37 + 20.0);
    let shift = Translation3::new(shift_m * dir.cos(), shift_m * dir.sin(), 0.0);
    Isometry3::from_parts(
        shift * truth.translation,
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()) * truth.rotation,
    )
}

fn good(r: &AlignReport, truth: &Isometry3<f64>) -> bool {
    let (t, a) = pose_error(&r.pose, truth);
    r.accepted && t < 0.05 && a < 0.5
}

fn line(label: &str, r: &AlignReport, truth: &Isometry3<f64>) {
    let (t, a) = pose_error(&r.pose, truth);
    let ndt: f64 = r.attempts.iter().map(|x| x.ndt_ms).sum();
    let icp: f64 = r.attempts.iter().map(|x| x.icp_ms).sum();
    println!(
        "{label:<28} err {:7.2} cm {:7.3} deg  total {:7.1} ms (ndt {:6.1}, icp {:6.1})  attempts {:2}  accepted {}",
        t * 100.0,
        a,
        r.total_ms,
        ndt,
        icp,
        r.attempts.len(),
        r.accepted
    );
}

fn main() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/registration");
    let source = cloud_points(&starc_pipeline::cloud::read(&dir.join("source.ply")).expect("shared/data/registration"));
    let target = cloud_points(&starc_pipeline::cloud::read(&dir.join("target.ply")).unwrap());
    let v: Vec<f64> = std::fs::read_to_string(dir.join("T_target_source.txt"))
        .unwrap()
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    let mut rows = [[0.0; 4]; 4];
    for (i, x) in v.iter().enumerate() {
        rows[i / 4][i % 4] = *x;
    }
    let truth = pose_from_rows(&rows).unwrap();
    println!("source {} points, target {} points", source.len(), target.len());

    // STARC_ALIGN_CONFIG: TOML text overriding the defaults, to compare settings.
    let config = AlignConfig::from_toml(&std::env::var("STARC_ALIGN_CONFIG").unwrap_or_default()).unwrap();
    let aligner = Aligner::new(&target, config.clone()).unwrap();
    let single = Aligner::new(&target, AlignConfig { reseed_yaw_step_deg: 0.0, ..config }).unwrap();
    println!("target preparation {:.1} ms", aligner.prepare_ms);

    let basin_only = std::env::var_os("STARC_ALIGN_BASIN_ONLY").is_some();
    if !basin_only {
        println!("\n-- from identity and yaw starts (reseeding every {} deg)", aligner.config().reseed_yaw_step_deg);
        line("identity", &aligner.align(&source, &Isometry3::identity()), &truth);
        for yaw in [15.0, 30.0, 45.0, 90.0, 135.0, 180.0] {
            line(&format!("yaw {yaw} deg"), &aligner.align(&source, &start(&truth, yaw, 0.0)), &truth);
        }
    }
    println!("\n-- basin: single attempt, no reseeding");
    for shift in [0.0, 1.0] {
        let mut basin = None;
        let mut row = String::new();
        for k in 0..=36 {
            let yaw = f64::from(k) * 5.0;
            let ok = [yaw, -yaw].iter().all(|y| good(&single.align(&source, &start(&truth, *y, shift)), &truth));
            row.push(if ok { '+' } else { '.' });
            if !ok && basin.is_none() {
                basin = Some(yaw - 5.0);
            }
        }
        println!("shift {shift} m: yaw 0..180 by 5 (+ converged at +yaw and -yaw): {row}");
        println!("shift {shift} m: basin = every start within +-{} deg converged", basin.unwrap_or(180.0));
    }

    if basin_only {
        return;
    }
    println!("\n-- grid: yaw every 30 deg x shift 0/1/2 m, reseeding on");
    for shift in [0.0, 1.0, 2.0] {
        let mut times = Vec::new();
        let mut ok = 0;
        let mut n = 0;
        for k in 0..12 {
            let r = aligner.align(&source, &start(&truth, f64::from(k) * 30.0 - 180.0, shift));
            n += 1;
            ok += usize::from(good(&r, &truth));
            times.push(r.total_ms);
        }
        times.sort_by(f64::total_cmp);
        println!("shift {shift} m: success {ok}/{n}, median {:.1} ms, max {:.1} ms", times[n / 2], times[n - 1]);
    }
}
