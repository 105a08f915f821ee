//! Drift correction on a simulated walk: the responder's world pose from the rig's own LIO after
//! one registration, against the same with periodic re-registration and bounded correction.
//!
//! `cargo bench -p starc-pipeline --bench align_drift` (release). Runs the simulator (default
//! `office`, 60 s, seed 1), the LIO on the rig's Avia (points and internal IMU, decoded from the
//! capture), registers windows of the rig's scans (placed by the LIO's poses) against the
//! robot's map (robot scans placed by the robot's true poses, reduced to 5 cm), renders at 30 Hz
//! and compares both world poses with the rig's true pose. Writes `align_drift.csv` and
//! `align_drift.svg` into STARC_ALIGN_OUT (default: target/align_drift/) and prints a summary.
//!
//! Environment: STARC_DRIFT_SIM=`scenario:duration_s` (default `office:60`, the benches' own
//! scenario), STARC_DRIFT_PERIOD_S (re-registration period, default 2), STARC_DRIFT_WINDOW_S
//! (window of a re-registration, default 8), STARC_DRIFT_FIRST_WINDOW_S (of the first, default 10),
//! STARC_DRIFT_MIN_DEGENERACY (acceptance of re-registrations, default the aligner's 0.01),
//! STARC_DRIFT_GUESS_M / _DEG (how far the first registration's guess is off the truth, default
//! 0.3 m and 5 deg), STARC_DRIFT_FIRST_SEARCH=1 (the first registration with the seed search),
//! STARC_DRIFT_HALF_GAIN (`WorldPoseConfig::half_gain_info`; 0 follows every registration fully),
//! STARC_DRIFT_GATE_M / STARC_DRIFT_GATE_M_PER_S (`WorldPoseConfig::gate_m`, `gate_m_per_s`; 0: off).
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "align_sim/mod.rs"]
mod align_sim;

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};
use starc_hil::tum::pose_at;
use starc_pipeline::align::{aggregate_window, pose_error, AggregateStats, AlignConfig, Aligner, Vec3, WindowConfig};
use starc_pipeline::lio::{Lio, LioConfig, LioScan, ScanOutput};
use starc_pipeline::pose::{Constraint, PoseBuffer, WorldPose, WorldPoseConfig};
use std::fmt::Write as _;
use std::path::PathBuf;

fn env_f64(name: &str, default: f64) -> f64 {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// The rig's scans over `[end - window, end]`, placed by the LIO's poses relative to its pose at
/// `end` (so the window is in the rig's LiDAR frame at `end`), moving points left out
/// (`aggregate_window`); points the buffer cannot place are left out too.
fn window(scans: &[LioScan], odom: &PoseBuffer, end_ns: u64, window_ns: u64, stats: &mut AggregateStats) -> Vec<Vec3> {
    let Ok(at_end) = odom.at(end_ns) else { return Vec::new() };
    let from = end_ns.saturating_sub(window_ns);
    let mut timed = Vec::new();
    for s in scans.iter().filter(|s| s.end_ns >= from && s.start_ns <= end_ns) {
        for p in s.points.iter().filter(|p| p.t_ns >= from && p.t_ns <= end_ns) {
            timed.push((p.t_ns, Vec3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m))));
        }
    }
    let (out, st) = aggregate_window(
        &timed,
        |t| odom.at(t).ok(),
        &at_end.inverse(),
        &[],
        &WindowConfig { voxel_m: 0.05, ..WindowConfig::default() },
    );
    stats.points_in += st.points_in;
    stats.excluded_moving += st.excluded_moving;
    stats.points_out += st.points_out;
    out
}

/// One rendered frame's errors.
struct Row {
    t_s: f64,
    lio_only_m: f64,
    lio_only_deg: f64,
    corrected_m: f64,
    corrected_deg: f64,
    event: String,
}

fn main() {
    let spec = std::env::var("STARC_DRIFT_SIM").unwrap_or_else(|_| "office:60".into());
    let (scenario, duration) = spec.split_once(':').unwrap();
    let duration_s: f64 = duration.parse().unwrap();
    let period_ns = (env_f64("STARC_DRIFT_PERIOD_S", 2.0) * 1e9) as u64;
    let window_ns = (env_f64("STARC_DRIFT_WINDOW_S", 8.0) * 1e9) as u64;
    // The first registration has no prior: a longer window (the responder looks around).
    let first_window_ns = (env_f64("STARC_DRIFT_FIRST_WINDOW_S", 10.0) * 1e9) as u64;
    let out_dir = std::env::var_os("STARC_ALIGN_OUT")
        .map_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/align_drift"), PathBuf::from);
    std::fs::create_dir_all(&out_dir).unwrap();

    let sim = align_sim::simulate(scenario, duration_s, "drift");
    let target = starc_pipeline::voxel_hash::voxel_downsample(
        &align_sim::accumulate(&sim.robot.scans, 0, u64::MAX, |t| pose_at(&sim.robot_truth, t).unwrap()),
        0.05,
    );
    let aligner = Aligner::new(&target, AlignConfig::default()).unwrap();
    // Re-registration starts from the current world pose: one attempt, no seed search, and no
    // NDT levels coarser than the room (8 and 4 m cells blur an office into false minima).
    let tracking = AlignConfig {
        reseed_yaw_step_deg: 0.0,
        ndt_resolutions_m: vec![2.0, 1.0],
        seed_levels: 1,
        min_degeneracy_index: env_f64("STARC_DRIFT_MIN_DEGENERACY", AlignConfig::default().min_degeneracy_index),
        ..AlignConfig::default()
    };
    let tracker = Aligner::new(&target, tracking).unwrap();
    let first_search = std::env::var_os("STARC_DRIFT_FIRST_SEARCH").is_some();
    let (guess_m, guess_deg) = (env_f64("STARC_DRIFT_GUESS_M", 0.3), env_f64("STARC_DRIFT_GUESS_DEG", 5.0));
    println!(
        "{scenario} {duration_s} s: robot map {} points; rig {} scans, {} IMU samples",
        target.len(),
        sim.fpv.scans.len(),
        sim.fpv.imu.len()
    );

    // The rig's LIO (the Avia's internal IMU: axes aligned with the LiDAR, offset as the datasheet).
    let cfg = LioConfig {
        pos_imu_lidar: Vector3::new(0.04165, 0.02326, -0.0284),
        rot_imu_lidar: Rotation3::identity(),
        ..LioConfig::default()
    };
    let mut lio = Lio::new(cfg);
    let mut lio_out: Vec<ScanOutput> = Vec::new();
    let mut next_scan = sim.fpv.scans.iter().cloned().peekable();
    for s in &sim.fpv.imu {
        while let Some(scan) = next_scan.next_if(|sc| sc.start_ns <= s.t_ns) {
            lio.push_scan(scan, &mut lio_out);
        }
        lio.push_imu(*s, &mut lio_out);
    }
    println!("LIO: {} scan outputs", lio_out.len());

    // STARC_DRIFT_HALF_GAIN: the per-direction fusion's half-gain information (0: follow every
    // registration, as before the fusion).
    let config = WorldPoseConfig {
        half_gain_info: env_f64("STARC_DRIFT_HALF_GAIN", WorldPoseConfig::default().half_gain_info),
        gate_m: env_f64("STARC_DRIFT_GATE_M", 0.0),
        gate_m_per_s: env_f64("STARC_DRIFT_GATE_M_PER_S", 0.0),
        ..WorldPoseConfig::default()
    };
    let mut corrected = WorldPose::new(config.clone());
    let mut lio_only = WorldPose::new(config.clone());
    let mut odom = PoseBuffer::new(1_000_000);
    let frame_ns = 33_333_333u64;
    let mut rows: Vec<Row> = Vec::new();
    let mut next_frame = 0u64;
    let mut next_registration = 0u64;
    let (mut accepted, mut rejected) = (0u32, 0u32);
    let mut align_ms = Vec::new();
    let mut window_stats = AggregateStats::default();
    // The largest correction step applied in one frame (at the rig).
    let (mut max_step_m, mut max_step_deg) = (0.0f64, 0.0f64);
    for o in &lio_out {
        for w in [&mut corrected, &mut lio_only, &mut WorldPose::new(config.clone())] {
            let _ = w.push_odometry(o.end_ns, o.lidar_pose);
        }
        odom.push(o.end_ns, o.lidar_pose).unwrap();
        let now = o.end_ns;
        let Some((first, _)) = odom.span_ns() else { continue };
        let mut event = String::new();
        let aligned = corrected.correction().is_some();
        let w_ns = if aligned { window_ns } else { first_window_ns };
        if now >= first + w_ns && now >= next_registration {
            let src = window(&sim.fpv.scans, &odom, now, w_ns, &mut window_stats);
            let truth = pose_at(&sim.fpv_truth, now).unwrap();
            let report = match corrected.world_pose(now).ok().flatten() {
                // First registration: a hand-off guess, the truth off by STARC_DRIFT_GUESS_M and
                // _DEG (the seed search only with STARC_DRIFT_FIRST_SEARCH).
                None => {
                    let guess = Isometry3::from_parts(
                        Translation3::new(guess_m * 0.8, -guess_m * 0.6, 0.0),
                        UnitQuaternion::from_euler_angles(0.0, 0.0, guess_deg.to_radians()),
                    ) * truth;
                    if first_search {
                        aligner.align(&src, &guess)
                    } else {
                        tracker.align(&src, &guess)
                    }
                }
                Some(guess) => tracker.align(&src, &guess),
            };
            align_ms.push(report.total_ms);
            let (e_m, e_deg) = pose_error(&report.pose, &truth);
            if report.accepted {
                accepted += 1;
                if lio_only.correction().is_none() {
                    lio_only.push_registration(now, report.pose).unwrap();
                }
                // Per-direction fusion: only what the window pins down moves the correction.
                let constraint = report.best().and_then(|a| {
                    Constraint::from_rows(
                        &a.metrics.information,
                        a.metrics.information_centre_m,
                        a.metrics.information_radius_m,
                    )
                });
                let outcome = match constraint {
                    Some(c) => corrected.push_registration_constrained(now, report.pose, &c).unwrap(),
                    None => corrected.push_registration(now, report.pose).unwrap(),
                };
                event = format!("accepted, {outcome:?} ({:.1} cm {:.2} deg off the truth)", e_m * 100.0, e_deg);
            } else {
                rejected += 1;
                event = format!("rejected: {}", report.failure.map_or_else(String::new, |f| f.to_string()));
                println!("  t {:.1} s: {event}", (now - sim.robot_truth[0].0) as f64 * 1e-9);
            }
            next_registration = now + period_ns;
        }
        while next_frame <= now {
            if next_frame >= first {
                let step = corrected.step_frame();
                max_step_m = max_step_m.max(step.step_m);
                max_step_deg = max_step_deg.max(step.step_deg);
                let t = now.min(next_frame.max(first));
                let truth = pose_at(&sim.fpv_truth, t).unwrap();
                if let (Ok(Some(a)), Ok(Some(b))) = (lio_only.world_pose(t), corrected.world_pose(t)) {
                    let (lm, ld) = pose_error(&a, &truth);
                    let (cm, cd) = pose_error(&b, &truth);
                    rows.push(Row {
                        t_s: (t - sim.robot_truth[0].0) as f64 * 1e-9,
                        lio_only_m: lm,
                        lio_only_deg: ld,
                        corrected_m: cm,
                        corrected_deg: cd,
                        event: std::mem::take(&mut event),
                    });
                }
            }
            next_frame += frame_ns;
        }
    }
    let mut csv = String::from("t_s,lio_only_err_m,lio_only_err_deg,corrected_err_m,corrected_err_deg,event\n");
    for r in &rows {
        writeln!(
            csv,
            "{:.3},{:.4},{:.3},{:.4},{:.3},{}",
            r.t_s,
            r.lio_only_m,
            r.lio_only_deg,
            r.corrected_m,
            r.corrected_deg,
            r.event.replace(',', ";")
        )
        .unwrap();
    }
    std::fs::write(out_dir.join("align_drift.csv"), csv).unwrap();
    std::fs::write(out_dir.join("align_drift.svg"), svg(&rows, scenario)).unwrap();
    let stat = |f: &dyn Fn(&Row) -> f64| {
        let mut v: Vec<f64> = rows.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
        (rms, v.last().copied().unwrap_or(f64::NAN), rows.last().map_or(f64::NAN, f))
    };
    let (l_rms, l_max, l_end) = stat(&|r| r.lio_only_m);
    let (c_rms, c_max, c_end) = stat(&|r| r.corrected_m);
    let (ld_rms, _, ld_end) = stat(&|r| r.lio_only_deg);
    let (cd_rms, _, cd_end) = stat(&|r| r.corrected_deg);
    // The largest frame-to-frame change of the corrected pose beyond the rig's own motion.
    println!(
        "{} frames at 30 Hz over {:.1} s; registrations: {accepted} accepted ({} refused by the world pose as too far, {} of them by the gate, {} snapped), {rejected} rejected by the aligner; align median {:.1} ms",
        rows.len(),
        rows.last().map_or(0.0, |r| r.t_s) - rows.first().map_or(0.0, |r| r.t_s),
        corrected.refused,
        corrected.gated,
        corrected.snaps,
        {
            align_ms.sort_by(f64::total_cmp);
            align_ms.get(align_ms.len() / 2).copied().unwrap_or(f64::NAN)
        }
    );
    println!("| world pose | RMS err cm | max err cm | final err cm | RMS err deg | final err deg |");
    println!("|---|---|---|---|---|---|");
    println!(
        "| LIO only (one registration) | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} |",
        l_rms * 100.0,
        l_max * 100.0,
        l_end * 100.0,
        ld_rms,
        ld_end
    );
    println!(
        "| re-registered every {:.0} s | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} |",
        period_ns as f64 * 1e-9,
        c_rms * 100.0,
        c_max * 100.0,
        c_end * 100.0,
        cd_rms,
        cd_end
    );
    println!(
        "largest correction step in one frame: {:.2} mm, {:.3} deg (bounds {} mm, {} deg); windows: {} points in, {} moving left out, {} after 5 cm voxels",
        max_step_m * 1e3,
        max_step_deg,
        config.max_step_m * 1e3,
        config.max_step_deg,
        window_stats.points_in,
        window_stats.excluded_moving,
        window_stats.points_out
    );
    println!("wrote {}", out_dir.join("align_drift.{csv,svg}").display());
}

/// A plain SVG line plot of both translation errors over time, with the registrations marked.
fn svg(rows: &[Row], scenario: &str) -> String {
    let (w, h, left, right, top, bottom) = (900.0, 420.0, 70.0, 20.0, 40.0, 50.0);
    let t0 = rows.first().map_or(0.0, |r| r.t_s);
    let t1 = rows.last().map_or(1.0, |r| r.t_s).max(t0 + 1e-3);
    let ymax_cm = rows.iter().map(|r| r.lio_only_m.max(r.corrected_m) * 100.0).fold(1.0f64, f64::max);
    let ymax_cm = nice_ceiling(ymax_cm);
    let x = |t: f64| left + (t - t0) / (t1 - t0) * (w - left - right);
    let y = |cm: f64| top + (1.0 - cm.min(ymax_cm) / ymax_cm) * (h - top - bottom);
    let mut s = String::new();
    writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">"#
    )
    .unwrap();
    writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#).unwrap();
    writeln!(
        s,
        r#"<text x="{left}" y="22" font-size="14">Responder world-pose error, simulated {scenario} (translation, cm)</text>"#
    )
    .unwrap();
    // Axes, grid and ticks.
    for k in 0..=5 {
        let v = ymax_cm * f64::from(k) / 5.0;
        let yy = y(v);
        writeln!(s, r##"<line x1="{left}" y1="{yy:.1}" x2="{:.1}" y2="{yy:.1}" stroke="#ddd"/>"##, w - right).unwrap();
        writeln!(s, r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{v:.1}</text>"#, left - 6.0, yy + 4.0).unwrap();
    }
    let tick = nice_ceiling((t1 - t0) / 8.0);
    let mut t = (t0 / tick).ceil() * tick;
    while t <= t1 {
        let xx = x(t);
        writeln!(s, r##"<line x1="{xx:.1}" y1="{top}" x2="{xx:.1}" y2="{:.1}" stroke="#eee"/>"##, h - bottom).unwrap();
        writeln!(s, r#"<text x="{xx:.1}" y="{:.1}" text-anchor="middle">{t:.0}</text>"#, h - bottom + 16.0).unwrap();
        t += tick;
    }
    writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">time (s)</text>"#,
        (left + w - right) / 2.0,
        h - 10.0
    )
    .unwrap();
    writeln!(
        s,
        r##"<line x1="{left}" y1="{top}" x2="{left}" y2="{:.1}" stroke="black"/><line x1="{left}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="black"/>"##,
        h - bottom,
        h - bottom,
        w - right,
        h - bottom
    )
    .unwrap();
    // Registrations.
    for r in rows.iter().filter(|r| !r.event.is_empty()) {
        let colour = if r.event.starts_with("accepted") { "#2a2" } else { "#d22" };
        writeln!(
            s,
            r#"<line x1="{0:.1}" y1="{top}" x2="{0:.1}" y2="{1:.1}" stroke="{colour}" stroke-dasharray="3,3"><title>{2}</title></line>"#,
            x(r.t_s),
            h - bottom,
            r.event.replace('<', "&lt;").replace('&', "&amp;")
        )
        .unwrap();
    }
    for (name, colour, f) in [
        ("LIO only (one registration)", "#d62", &(|r: &Row| r.lio_only_m) as &dyn Fn(&Row) -> f64),
        ("re-registered, bounded correction", "#26c", &|r: &Row| r.corrected_m),
    ] {
        let pts: Vec<String> = rows.iter().map(|r| format!("{:.1},{:.1}", x(r.t_s), y(f(r) * 100.0))).collect();
        writeln!(s, r#"<polyline fill="none" stroke="{colour}" stroke-width="1.5" points="{}"><title>{name}</title></polyline>"#, pts.join(" "))
            .unwrap();
    }
    let lx = w - right - 260.0;
    for (i, (name, colour)) in [
        ("LIO only (one registration)", "#d62"),
        ("re-registered, bounded correction", "#26c"),
        ("registration accepted / rejected", "#2a2"),
    ]
    .iter()
    .enumerate()
    {
        let ly = top + 14.0 + 16.0 * i as f64;
        writeln!(s, r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="2"/>"#, lx + 20.0)
            .unwrap();
        writeln!(s, r#"<text x="{}" y="{}">{name}</text>"#, lx + 26.0, ly + 4.0).unwrap();
    }
    s.push_str("</svg>\n");
    s
}

/// 1, 2 or 5 times a power of ten, at least `v`.
fn nice_ceiling(v: f64) -> f64 {
    let p = 10f64.powf(v.max(1e-9).log10().floor());
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|c| *c >= v).unwrap_or(10.0 * p)
}
