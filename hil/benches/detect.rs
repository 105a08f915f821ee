//! The person detector on every shipped scenario, against the simulator's truth.
//!
//! `cargo bench -p starc-hil --bench detect` simulates each scenario (lab and corridor 30 s,
//! auditorium and tactical 60 s so that the robot reaches the people; seed 1; no camera),
//! reads the robot's returns back from the pcap, puts them in the world with the true pose, and
//! feeds 0.3 s windows every 0.1 s to the geometric detector with config/detect.toml. Prints per
//! scenario: windows, TP/FP/misses/ignored, precision, recall, recall per pose, the share of
//! detected points labelled as a person, and the time per window (median, p99).
//! `STARC_DETECT_RUNS=dir` reuses runs in `dir/<scenario>` (from `starc sim <scenario> --out ...`);
//! `STARC_DETECT_SEED` picks another seed; `STARC_DETECT_VERBOSE=1` lists the misses and false positives.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "../../tests/support/detect_sim.rs"]
mod detect_sim;

use starc_pipeline::detect::eval::{Counts, MatchRule};
use starc_pipeline::detect::{DetectConfig, GeometricDetector};
use std::path::PathBuf;

fn main() {
    // `cargo bench` passes --bench; a filter argument picks scenarios.
    let filter: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    // STARC_DETECT_CONFIG: another detector config (kind = "trees" to bench the learned scorer).
    let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/detect.toml").to_string();
    let text = std::fs::read_to_string(std::env::var("STARC_DETECT_CONFIG").unwrap_or(shipped)).unwrap();
    let cfg = DetectConfig::from_toml(&text).unwrap();
    let rule = MatchRule::default();
    let seed: u64 = std::env::var("STARC_DETECT_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(1);
    let verbose = std::env::var("STARC_DETECT_VERBOSE").is_ok_and(|v| v == "1");
    let tmp = std::env::temp_dir().join(format!("starc-detect-bench-{}", std::process::id()));
    println!(
        "window 0.3 s every 0.1 s, seed {seed}; match: >= {} returns to count, centre within {} m or inside the box + {} m",
        rule.min_returns, rule.max_centre_distance_m, rule.box_margin_m
    );
    let mut total = Counts::default();
    // Long enough for the robot to finish its route: in their own 30 s it has barely reached
    // the people in the auditorium and not at all in the tactical house.
    for (name, secs) in [("lab", 30.0), ("auditorium", 60.0), ("tactical", 60.0), ("corridor", 30.0)] {
        if !filter.is_empty() && !filter.iter().any(|f| name.contains(f.as_str())) {
            continue;
        }
        let dir = match std::env::var("STARC_DETECT_RUNS") {
            Ok(d) => PathBuf::from(d).join(name),
            Err(_) => {
                let d = tmp.join(name);
                detect_sim::simulate(name, Some(secs), seed, &d);
                d
            }
        };
        let run = detect_sim::load(&dir);
        if let Ok(path) = std::env::var("STARC_DETECT_FEATURES") {
            features_csv(name, &run, &cfg, &path);
        }
        let mut det = GeometricDetector::new(cfg.clone()).unwrap();
        let ev = detect_sim::evaluate(&run, &mut det, 300_000_000, 100_000_000, &rule);
        let c = ev.counts;
        total.add(&c);
        let (med, p99) = ev.times_ms();
        let mut poses: Vec<String> = ev.per_pose.iter().map(|(k, (f, v))| format!("{k} {f}/{v}")).collect();
        poses.sort();
        println!(
            "{name:<11} {secs:2.0} s, windows {:4}  TP {:4} FP {:3} miss {:4} ignored {:3}  precision {:.3} recall {:.3}  [{}]  person points {:.1} %  time/window median {:.2} ms p99 {:.2} ms ({} points/window)",
            ev.windows,
            c.true_positives,
            c.false_positives,
            c.misses,
            c.ignored,
            c.precision(),
            c.recall(),
            poses.join(", "),
            100.0 * ev.purity(),
            med,
            p99,
            run.points.len() as u64 * 3 / (ev.windows.max(1) as u64 + 2),
        );
        if verbose {
            let mut m: Vec<_> = ev.max_returns.iter().collect();
            m.sort();
            println!("  most returns of each person in one window: {m:?}");
            for (t, label, pose, n) in &ev.misses {
                println!(
                    "  miss t {:.1} s person {label} ({pose}, {n} returns)",
                    (t - 1_767_225_600_000_000_000) as f64 * 1e-9
                );
            }
            for (t, d) in &ev.false_positives {
                println!(
                    "  FP t {:.1} s {:?} at ({:.2}, {:.2}, {:.2}) size {:.2} x {:.2} x {:.2} score {:.2} points {}",
                    (t - 1_767_225_600_000_000_000) as f64 * 1e-9,
                    d.pose,
                    d.centre_m.x,
                    d.centre_m.y,
                    d.centre_m.z,
                    d.size_m.x,
                    d.size_m.y,
                    d.size_m.z,
                    d.score,
                    d.point_indices.len()
                );
            }
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    if let (Ok(name), Ok(t)) = (std::env::var("STARC_DETECT_DUMP"), std::env::var("STARC_DETECT_DUMP_T")) {
        dump(&name, t.parse().unwrap(), &cfg);
    }
    println!(
        "all         TP {} FP {} miss {}  precision {:.3} recall {:.3}",
        total.true_positives,
        total.false_positives,
        total.misses,
        total.precision(),
        total.recall()
    );
}

/// Every cluster of one window, for tuning (`STARC_DETECT_DUMP=<run dir> STARC_DETECT_DUMP_T=<s>`).
fn dump(dir: &str, t_s: f64, cfg: &DetectConfig) {
    use starc_pipeline::detect::Detector;
    let run = detect_sim::load(std::path::Path::new(dir));
    let end = 1_767_225_600_000_000_000 + (t_s * 1e9) as u64;
    let (window, labels) = detect_sim::window_at(&run, end, 300_000_000);
    let mut det = GeometricDetector::new(cfg.clone()).unwrap();
    let mut found = Vec::new();
    det.detect(&window, &mut found);
    println!(
        "floor {:?}; {} points, {} person-labelled",
        det.last_floor(),
        labels.len(),
        labels.iter().filter(|&&l| l != 0).count()
    );
    let xy: Option<Vec<f64>> =
        std::env::var("STARC_DETECT_DUMP_XY").ok().map(|v| v.split(',').map(|x| x.parse().unwrap()).collect());
    det.keep_cluster_points(true);
    found.clear();
    det.detect(&window, &mut found);
    for ((f, s), idx) in det.last_clusters().iter().zip(det.last_cluster_points()) {
        if let Some(xy) = &xy {
            if (f.centre.x - xy[0]).hypot(f.centre.y - xy[1]) < 0.3 {
                for &i in idx {
                    let p = window.points[i as usize];
                    println!("P {:.3} {:.3} {:.3} {}", p.x_m, p.y_m, p.z_m, labels[i as usize]);
                }
            }
        }
        println!(
            "  score {s:.2} at ({:.2}, {:.2}) size {:.2} x {:.2} x {:.2} bottom {:.2} top {:.2} pts {} vox {} face {:.2} lin {:.2} plan {:.2} range {:.1}",
            f.centre.x, f.centre.y, f.size.x, f.size.y, f.size.z, f.bottom_m, f.top_m, f.points, f.voxels, f.face_share, f.linearity, f.planarity, f.range_m
        );
    }
}

/// Appends every scored cluster of every window to a CSV (tuning): scenario, time, share of its
/// points labelled as a person, features, score, top share, then its silhouette (top free,
/// bottom hidden, columns with a return above, below).
fn features_csv(name: &str, run: &detect_sim::SimRun, cfg: &DetectConfig, path: &str) {
    use starc_pipeline::detect::Detector;
    use std::io::Write;
    let mut out = std::fs::OpenOptions::new().create(true).append(true).open(path).unwrap();
    let mut det = GeometricDetector::new(cfg.clone()).unwrap();
    det.keep_cluster_points(true);
    let mut end = run.points[0].t_ns + 300_000_000;
    let mut found = Vec::new();
    while end <= run.points.last().unwrap().t_ns {
        let (window, labels) = detect_sim::window_at(run, end, 300_000_000);
        found.clear();
        det.detect(&window, &mut found);
        for (((f, s), idx), sil) in
            det.last_clusters().iter().zip(det.last_cluster_points()).zip(det.last_silhouettes())
        {
            let person = idx.iter().filter(|&&i| labels[i as usize] != 0).count();
            writeln!(
                out,
                "{name},{:.1},{:.3},{:.2},{:.2},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.4},{:.2},{:.3},{:.3},{:.3},{:.3},{},{}",
                (end - 1_767_225_600_000_000_000) as f64 * 1e-9,
                person as f64 / idx.len().max(1) as f64,
                f.centre.x,
                f.centre.y,
                f.points,
                f.voxels,
                f.size.x,
                f.size.y,
                f.size.z,
                f.bottom_m,
                f.top_m,
                f.face_share,
                f.linearity,
                f.planarity,
                f.thickness_m,
                f.range_m,
                s,
                f.top_share,
                sil.top_free,
                sil.bottom_hidden,
                sil.top_columns,
                sil.bottom_columns
            )
            .unwrap();
        }
        end += 100_000_000;
    }
}
