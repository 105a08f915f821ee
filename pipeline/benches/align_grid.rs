//! Success-rate grid of the aligner against small_gicp and Open3D, from the same starts, in one run.
//!
//! `cargo bench -p starc-pipeline --bench align_grid` (release). For each scenario (the real pair
//! in shared/data/registration; simulated scenarios: the robot's map accumulated over its true
//! poses against a window of the responder's rig's raw returns, both through the Avia mock's
//! packets):
//! starts off the truth by yaw every 15 deg around the whole circle x translation 0, 0.75, 1.5,
//! 2.25, 3 m (horizontal, in a direction that turns from trial to trial). Ours runs with the
//! defaults (seed search on); the peers (tests/peers/align_peers.py: point-to-plane ICP at 0.25 m,
//! single-threaded) from the same starts. Printed per method: success (within 5 cm and 0.5 deg;
//! ours must also have accepted), error median / p99 over all trials, time median / p99, and the
//! ratio of the peers' median time to ours. Ours is printed twice: with the reduction of the raw
//! source in every trial (`STARC`), and without it (`STARC red.`), as the peers are timed (they
//! reduce the source once, in their preparation). Then the basin of one attempt without the search.
//!
//! Environment: STARC_ALIGN_CONFIG (TOML overriding the defaults), STARC_ALIGN_NO_PEERS=1,
//! STARC_ALIGN_SIM (`scenario:duration_s:t_end_s:window_s,...`; empty for none),
//! STARC_ALIGN_PREPARE_MAP=1 (simulated maps through `prepare_map`), STARC_ALIGN_KEEP_PEER_DIR=1,
//! STARC_ALIGN_NO_REAL=1, STARC_ALIGN_NO_BASIN=1, STARC_ALIGN_VERBOSE=1 (one line per trial).
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "align_sim/mod.rs"]
mod align_sim;

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use starc_pipeline::align::{
    cloud_points, pose_error, pose_from_rows, pose_rows, AlignConfig, Aligner, Ray, Rejection, Vec3,
};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

const SHIFTS_M: [f64; 5] = [0.0, 0.75, 1.5, 2.25, 3.0];
const TOL_M: f64 = 0.05;
const TOL_DEG: f64 = 0.5;

/// Trial k's start: the truth turned by `yaw_deg` about its own position and shifted by `shift_m`
/// in a direction that changes with k.
fn start(truth: &Isometry3<f64>, k: usize, yaw_deg: f64, shift_m: f64) -> Isometry3<f64> {
    let dir = (k as f64 * 137.5 + 20.0).to_radians();
    Isometry3::from_parts(
        Translation3::new(shift_m * dir.cos(), shift_m * dir.sin(), 0.0) * truth.translation,
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()) * truth.rotation,
    )
}

/// One method's outcome on one trial.
#[derive(Clone, Copy)]
struct Outcome {
    err_m: f64,
    err_deg: f64,
    ms: f64,
    /// CPU time of the aligning thread (robust to other load on this shared machine).
    cpu_ms: f64,
    ok: bool,
}

/// CPU time of the calling thread (ms).
fn thread_cpu_ms() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes into the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 * 1e-6
}

fn pct(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

fn sorted(v: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = v.collect();
    v.sort_by(f64::total_cmp);
    v
}

struct Summary {
    time_median_ms: f64,
    cpu_median_ms: f64,
}

fn summarize(name: &str, outcomes: &[Outcome]) -> Summary {
    let n = outcomes.len();
    let ok = outcomes.iter().filter(|o| o.ok).count();
    let em = sorted(outcomes.iter().map(|o| o.err_m * 100.0));
    let ed = sorted(outcomes.iter().map(|o| o.err_deg));
    let t = sorted(outcomes.iter().map(|o| o.ms));
    let c = sorted(outcomes.iter().map(|o| o.cpu_ms));
    println!(
        "| {name:<10} | {ok:>3}/{n:<3} {:>6.1} % | {:>7.2} / {:>8.2} | {:>6.3} / {:>7.3} | {:>7.1} / {:>7.1} | {:>7.1} / {:>7.1} |",
        100.0 * ok as f64 / n.max(1) as f64,
        pct(&em, 0.5),
        pct(&em, 0.99),
        pct(&ed, 0.5),
        pct(&ed, 0.99),
        pct(&t, 0.5),
        pct(&t, 0.99),
        pct(&c, 0.5),
        pct(&c, 0.99),
    );
    Summary { time_median_ms: pct(&t, 0.5), cpu_median_ms: pct(&c, 0.5) }
}

fn write_f64(path: &Path, pts: &[Vec3]) {
    let mut bytes = Vec::with_capacity(pts.len() * 24);
    for p in pts {
        for v in [p.x, p.y, p.z] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// Runs the peers on the same clouds and starts; per peer, its outcome per trial.
fn run_peers(
    source: &[Vec3],
    target: &[Vec3],
    starts: &[Isometry3<f64>],
    truth: &Isometry3<f64>,
) -> Vec<(String, f64, Vec<Outcome>)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let python = root.join(".venv/bin/python");
    let dir = std::env::temp_dir().join(format!("starc_align_peers_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    write_f64(&dir.join("source.f64"), source);
    write_f64(&dir.join("target.f64"), target);
    let mut seeds = std::fs::File::create(dir.join("seeds.txt")).unwrap();
    for s in starts {
        let rows = pose_rows(s);
        let line: Vec<String> = rows.iter().flatten().map(|v| format!("{v:.17e}")).collect();
        writeln!(seeds, "{}", line.join(" ")).unwrap();
    }
    drop(seeds);
    let out = Command::new(&python)
        .arg(root.join("tests/peers/align_peers.py"))
        .arg(&dir)
        .env("OMP_NUM_THREADS", "1")
        .output()
        .unwrap_or_else(|e| panic!("{}: {e}", python.display()));
    if std::env::var_os("STARC_ALIGN_KEEP_PEER_DIR").is_some() {
        println!("peer inputs kept in {}", dir.display());
    } else {
        let _ = std::fs::remove_dir_all(&dir);
    }
    assert!(out.status.success(), "align_peers.py: {}", String::from_utf8_lossy(&out.stderr));
    let mut peers: Vec<(String, f64, Vec<Outcome>)> = Vec::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let peer = v["peer"].as_str().unwrap().to_string();
        if let Some(ms) = v["prepare_ms"].as_f64() {
            peers.push((peer, ms, Vec::new()));
            continue;
        }
        let t: Vec<f64> = v["T"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        let mut rows = [[0.0; 4]; 4];
        for (i, x) in t.iter().enumerate() {
            rows[i / 4][i % 4] = *x;
        }
        let (err_m, err_deg) = pose_from_rows(&rows).map_or((f64::INFINITY, 180.0), |p| pose_error(&p, truth));
        let ms = v["ms"].as_f64().unwrap();
        let cpu_ms = v["cpu_ms"].as_f64().unwrap();
        let entry = peers.iter_mut().find(|p| p.0 == peer).unwrap();
        entry.2.push(Outcome { err_m, err_deg, ms, cpu_ms, ok: err_m < TOL_M && err_deg < TOL_DEG });
    }
    peers
}

fn scenario(name: &str, source: &[Vec3], rays: &[Ray], target: &[Vec3], truth: &Isometry3<f64>, config: &AlignConfig) {
    let verbose = std::env::var_os("STARC_ALIGN_VERBOSE").is_some();
    println!("\n## {name}: source {} points, target {} points", source.len(), target.len());
    let aligner = Aligner::new(target, config.clone()).unwrap();
    println!("target preparation {:.1} ms", aligner.prepare_ms);
    // How well the pair fits at its truth: one attempt from the truth itself.
    let single = Aligner::new(target, AlignConfig { reseed_yaw_step_deg: 0.0, ..config.clone() }).unwrap();
    let r = single.align_with_rays(source, rays, truth);
    if let Some(a) = r.best() {
        let (e_m, e_deg) = pose_error(&r.pose, truth);
        println!(
            "from the truth: accepted {}, moved {:.2} cm {:.3} deg; rms {:.3} m, inlier ratio {:.3}, degeneracy {:.4}, rays blocked {}",
            r.accepted,
            e_m * 100.0,
            e_deg,
            a.metrics.rms_residual_m,
            a.metrics.inlier_ratio,
            a.metrics.degeneracy_index,
            a.free_space.as_ref().map_or("not checked".to_string(), |f| format!("{}/{}", f.blocked, f.rays))
        );
    }
    println!("rays for the free-space check: {}", rays.len());
    // Free-space blocked ratios of every attempt the check ran on, split by whether it was right.
    let (mut blocked_right, mut blocked_wrong) = (Vec::new(), Vec::new());
    let mut rejected_free_space = 0usize;
    // Where the time goes, per trial: source reduction, seed ranking, full attempts, checks; and
    // the correlative stage across them.
    let mut split_ms: [Vec<f64>; 5] = Default::default();
    let mut free_space_ms = Vec::new();
    let mut starts = Vec::new();
    let mut ours = Vec::new();
    let mut ours_reduced = Vec::new();
    let mut attempts_hist = [0usize; 8];
    let mut probe_spread: Vec<(f64, f64, f64)> = Vec::new();
    let mut hops = 0usize;
    let (mut wrong_accepted, mut ambiguous) = (0usize, 0usize);
    let mut probe_iters: Vec<f64> = Vec::new();
    for (si, &shift) in SHIFTS_M.iter().enumerate() {
        for y in 0..24 {
            let k = si * 24 + y;
            let yaw = y as f64 * 15.0 - 180.0;
            let s = start(truth, k, yaw, shift);
            let c0 = thread_cpu_ms();
            let r = aligner.align_with_rays(source, rays, &s);
            let cpu_ms = thread_cpu_ms() - c0;
            for a in &r.attempts {
                let Some(f) = &a.free_space else { continue };
                free_space_ms.push(f.ms);
                let (am, ad) = pose_error(&a.pose, truth);
                if am < TOL_M && ad < TOL_DEG {
                    blocked_right.push(f.blocked_ratio);
                } else {
                    blocked_wrong.push(f.blocked_ratio);
                }
            }
            split_ms[0].push(r.source_reduce_ms);
            split_ms[1].push(r.seed_ms);
            split_ms[2].push(r.attempts.iter().map(|a| a.ndt_ms + a.icp_ms).sum());
            split_ms[3].push(r.attempts.iter().map(|a| a.verify_ms).sum());
            split_ms[4].push(r.correlative_ms);
            if r.attempts
                .iter()
                .any(|a| a.rejected_because.iter().any(|w| matches!(w, Rejection::SeesThroughMap { .. })))
            {
                rejected_free_space += 1;
            }
            let (err_m, err_deg) = pose_error(&r.pose, truth);
            let ok = r.accepted && err_m < TOL_M && err_deg < TOL_DEG;
            let close = err_m < TOL_M && err_deg < TOL_DEG;
            if r.accepted && !close {
                wrong_accepted += 1;
            }
            if r.attempts.iter().any(|a| a.ambiguous) {
                ambiguous += 1;
            }
            if verbose || !ok {
                println!(
                    "  trial yaw {yaw:+5.0} shift {shift:.2}: {} err {:.2} cm {:.3} deg {:.1} ms (seeds {:.1} ms) attempts {} best seed {:+.0} deg, degeneracy {:.4}{}",
                    if ok { "ok  " } else { "FAIL" },
                    err_m * 100.0,
                    err_deg,
                    r.total_ms,
                    r.seed_ms,
                    r.attempts.len(),
                    r.best().map_or(0.0, |a| a.seed_yaw_offset_deg),
                    r.best().map_or(0.0, |a| a.metrics.degeneracy_index),
                    r.failure.as_ref().map_or(String::new(), |f| format!(" ({f})")),
                );
            }
            if !ok {
                // Every full attempt of a miss: where it ended and what the acceptance saw.
                for a in &r.attempts {
                    let (am, ad) = pose_error(&a.pose, truth);
                    println!(
                        "    attempt seed {:+.0} deg ({:+.1}, {:+.1}) m: {:.2} cm {:.3} deg off; icp {} it, rms {:.4}, inliers {:.3}, update {:.1e}, degeneracy {:.4}, blocked {}, accepted {}",
                        a.seed_yaw_offset_deg,
                        a.seed_shift_m[0],
                        a.seed_shift_m[1],
                        am * 100.0,
                        ad,
                        a.icp_iterations,
                        a.metrics.rms_residual_m,
                        a.metrics.inlier_ratio,
                        a.metrics.update_norm,
                        a.metrics.degeneracy_index,
                        a.free_space.as_ref().map_or("-".to_string(), |f| format!("{:.3}", f.blocked_ratio)),
                        a.accepted
                    );
                    for p in &a.alternatives {
                        println!(
                            "      alternative seed {:+.0} deg: {:.2} m {:.2} deg away, rms {:.4}, inliers {:.3}",
                            p.yaw_deg, p.moved_m, p.moved_deg, p.rms_residual_m, p.inlier_ratio
                        );
                    }
                    for p in &a.probes {
                        println!(
                            "      probe ({:+.2}, {:+.2}) m {:+.1} deg: moved {:.2} cm {:.3} deg, rms {:.4}, inliers {:.3}",
                            p.shift_m[0],
                            p.shift_m[1],
                            p.yaw_deg,
                            p.moved_m * 100.0,
                            p.moved_deg,
                            p.rms_residual_m,
                            p.inlier_ratio
                        );
                    }
                }
            }
            // How far the probes of accepted, correct results land from them (the check's margin).
            if ok {
                if let Some(a) = r.best() {
                    for p in &a.probes {
                        probe_spread.push((p.moved_m * 100.0, p.moved_deg, a.verify_ms));
                        probe_iters.push(f64::from(p.iterations));
                    }
                    if a.verify_hops > 0 {
                        hops += 1;
                    }
                }
            }
            attempts_hist[r.attempts.len().min(7)] += 1;
            starts.push(s);
            ours.push(Outcome { err_m, err_deg, ms: r.total_ms, cpu_ms, ok });
            // The peers reduce the source once, outside their timed trials: ours timed alike.
            let reduce_ms = r.source_reduce_ms;
            ours_reduced.push(Outcome { err_m, err_deg, ms: r.total_ms - reduce_ms, cpu_ms: cpu_ms - reduce_ms, ok });
        }
    }
    if !probe_iters.is_empty() {
        let it = sorted(probe_iters.iter().copied());
        println!("probe ICP iterations median {} p99 {} max {:?}", pct(&it, 0.5), pct(&it, 0.99), it.last());
    }
    if !probe_spread.is_empty() {
        let cm = sorted(probe_spread.iter().map(|p| p.0));
        let deg = sorted(probe_spread.iter().map(|p| p.1));
        let ms = sorted(probe_spread.iter().map(|p| p.2));
        println!(
            "successes moved by the check: {hops}; probes of the successes ({}): moved cm median {:.2} p99 {:.2} max {:.2}; deg median {:.3} p99 {:.3} max {:.3}; check ms median {:.1}",
            cm.len(),
            pct(&cm, 0.5),
            pct(&cm, 0.99),
            cm.last().copied().unwrap_or(f64::NAN),
            pct(&deg, 0.5),
            pct(&deg, 0.99),
            deg.last().copied().unwrap_or(f64::NAN),
            pct(&ms, 0.5)
        );
    }
    for (what, v) in [("right", &blocked_right), ("wrong", &blocked_wrong)] {
        let v = sorted(v.iter().copied());
        if let (Some(lo), Some(hi)) = (v.first(), v.last()) {
            println!(
                "free-space check on {} {what} results: blocked ratio min {lo:.3} median {:.3} p99 {:.3} max {hi:.3}",
                v.len(),
                pct(&v, 0.5),
                pct(&v, 0.99)
            );
        }
    }
    println!("trials with an attempt rejected by the free-space check: {rejected_free_space}");
    if !free_space_ms.is_empty() {
        let v = sorted(free_space_ms.iter().copied());
        println!(
            "free-space check ms per attempt: median {:.2} p99 {:.2} max {:.2}",
            pct(&v, 0.5),
            pct(&v, 0.99),
            v.last().copied().unwrap_or(f64::NAN)
        );
    }
    let med = |v: &[f64]| pct(&sorted(v.iter().copied()), 0.5);
    println!(
        "time per trial, median ms: source reduction {:.1}, seed ranking {:.1}, NDT+ICP attempts {:.1}, checks {:.1}; correlative stage {:.1} (its search is part of the seed ranking)",
        med(&split_ms[0]),
        med(&split_ms[1]),
        med(&split_ms[2]),
        med(&split_ms[3]),
        med(&split_ms[4])
    );
    let peers = if std::env::var_os("STARC_ALIGN_NO_PEERS").is_some() {
        Vec::new()
    } else {
        run_peers(source, target, &starts, truth)
    };
    println!(
        "\n{} trials: yaw every 15 deg x shift {SHIFTS_M:?} m; success = within {} cm and {TOL_DEG} deg (ours: and accepted)",
        starts.len(),
        TOL_M * 100.0
    );
    println!("| method     | success          | err cm med / p99  | err deg med / p99 | wall ms med / p99 | cpu ms med / p99  |");
    println!("|------------|------------------|-------------------|-------------------|-------------------|-------------------|");
    summarize("STARC", &ours);
    // Without the source's reduction: how the peers are timed (theirs is in their preparation).
    let mine = summarize("STARC red.", &ours_reduced);
    let mut ratios = Vec::new();
    for (peer, prep, outcomes) in &peers {
        let s = summarize(peer, outcomes);
        ratios.push(format!(
            "{peer} {:.2}x wall, {:.2}x cpu (its preparation {prep:.1} ms once)",
            s.time_median_ms / mine.time_median_ms,
            s.cpu_median_ms / mine.cpu_median_ms
        ));
    }
    // The local subset, where plain ICP is expected to converge: |yaw| <= 15 deg, shift <= 0.75 m.
    let local: Vec<usize> = (0..starts.len()).filter(|k| (k % 24).abs_diff(12) <= 1 && k / 24 <= 1).collect();
    println!("local starts only ({} trials: |yaw| <= 15 deg, shift <= 0.75 m):", local.len());
    let pick = |o: &[Outcome]| local.iter().filter_map(|&k| o.get(k).copied()).collect::<Vec<_>>();
    summarize("STARC", &pick(&ours));
    for (peer, _, outcomes) in &peers {
        summarize(peer, &pick(outcomes));
    }
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "accepted but wrong (beyond {} cm or {TOL_DEG} deg): {wrong_accepted}; trials with an attempt rejected as ambiguous: {ambiguous}",
        TOL_M * 100.0
    );
    println!("load average at the end: {}", load.split_whitespace().take(3).collect::<Vec<_>>().join(" "));
    println!(
        "full attempts per trial (1..): {:?}; peers' median time / ours without the source's reduction (STARC red.): {}",
        &attempts_hist[1..],
        if ratios.is_empty() { "peers not run".to_string() } else { ratios.join(", ") }
    );
}

/// Single attempts (search off) from yaw errors 0..180 deg by 10 (both signs) at each shift:
/// the largest yaw below which every start converged.
fn basin(name: &str, source: &[Vec3], target: &[Vec3], truth: &Isometry3<f64>, config: &AlignConfig) {
    let single = Aligner::new(target, AlignConfig { reseed_yaw_step_deg: 0.0, ..config.clone() }).unwrap();
    println!("\n{name}: basin of one attempt (no search); '+' = converged from +yaw and -yaw (4 shift directions)");
    for shift in SHIFTS_M {
        let mut row = String::new();
        let mut basin = None;
        for k in 0..=18 {
            let yaw = f64::from(k) * 10.0;
            let ok = (0..4).all(|d| {
                [yaw, -yaw].iter().all(|y| {
                    let r = single.align(source, &start(truth, d * 6 + 1, *y, shift));
                    let (t, a) = pose_error(&r.pose, truth);
                    r.accepted && t < TOL_M && a < TOL_DEG
                })
            });
            row.push(if ok { '+' } else { '.' });
            if !ok && basin.is_none() {
                basin = Some(yaw - 10.0);
            }
        }
        println!(
            "  shift {shift:.2} m, yaw 0..180 by 10: {row}  every start within +-{} deg converged",
            basin.unwrap_or(180.0)
        );
    }
}

fn real_pair() -> (Vec<Vec3>, Vec<Vec3>, Isometry3<f64>) {
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
    (source, target, pose_from_rows(&rows).unwrap())
}

fn main() {
    let config = AlignConfig::from_toml(&std::env::var("STARC_ALIGN_CONFIG").unwrap_or_default()).unwrap();
    let (source, target, truth) = real_pair();
    let real = std::env::var_os("STARC_ALIGN_NO_REAL").is_none();
    if real {
        // One scan from one place: every ray starts at the sensor's origin.
        let rays: Vec<Ray> = source.iter().step_by(50).map(|p| Ray { origin: Vec3::zeros(), end: *p }).collect();
        scenario("real pair (shared/data/registration)", &source, &rays, &target, &truth, &config);
    }
    // STARC_ALIGN_SIM: scenario:duration_s:t_end_s:window_s,... (empty: none).
    let spec = std::env::var("STARC_ALIGN_SIM").unwrap_or_else(|_| "office:30:26:12".into());
    let mut sims = Vec::new();
    for item in spec.split(',').filter(|s| !s.is_empty()) {
        let f: Vec<&str> = item.split(':').collect();
        let num = |i: usize| f[i].parse::<f64>().unwrap();
        let mut p = align_sim::sim_pair(f[0], num(1), num(2), num(3));
        // STARC_ALIGN_PREPARE_MAP=1: the map with its floor band and ceiling removed (prepare_map).
        if std::env::var_os("STARC_ALIGN_PREPARE_MAP").is_some() {
            // STARC_ALIGN_BAND_KEEP_M overrides band_keep_voxel_m (0: the bands removed entirely).
            let mut c = starc_pipeline::align::MapPrepConfig::default();
            if let Some(k) = std::env::var("STARC_ALIGN_BAND_KEEP_M").ok().and_then(|v| v.parse().ok()) {
                c.band_keep_voxel_m = k;
            }
            let m = starc_pipeline::align::prepare_map(&p.target, &c).unwrap();
            println!(
                "prepared map: floor {:.2} m, ceiling {:.2} m, {} points kept, {} ground and {} ceiling points removed",
                m.floor_z_m,
                m.ceiling_z_m,
                m.points.len(),
                m.removed_ground,
                m.removed_ceiling
            );
            p.target = m.points;
        }
        println!("\nsimulated pair: {}", p.describe);
        scenario(&format!("simulated {}", f[0]), &p.source, &p.rays, &p.target, &p.truth, &config);
        sims.push((f[0].to_string(), p));
    }
    if std::env::var_os("STARC_ALIGN_NO_BASIN").is_none() {
        if real {
            basin("real pair", &source, &target, &truth, &config);
        }
        for (name, p) in &sims {
            basin(&format!("simulated {name}"), &p.source, &p.target, &p.truth, &config);
        }
    }
}
