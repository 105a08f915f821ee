//! Diagnosis of the rig's alignment attempts on a `starc sim --sensors-only` run, against the
//! truth: `cargo run --release -p starc-pipeline --example rig_diag -- DIR [hint_m hint_deg]`.
//! Runs the offline mission's robot and rig cores in time order (as `starc mission` does) and
//! prints, per attempt, every full attempt's result against the truth, the start gate, and a
//! single attempt from the true pose. Environment: `NO_HINT=1` (no start hint, as scored runs),
//! `NEVER_APPLY=1` (every search a first alignment), `ALIGN_TOML=file` (the settings of the search
//! and of the attempt from the truth),
//! `DUMP_DIR=dir` (each search's window, map and truth for scripts/align_window_peers.py),
//! `STOP_AFTER_S=s` (end at the first search past s seconds of the rig). Many buildings at once:
//! scripts/rig_diag_sweep.py.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use starc_bridge::wheels::{read_wheel_log, with_wheels, MotorFeedback, WheelFeedback};
use starc_hil::sim::run::{FPV_AVIA_IP, ROBOT_AVIA_IP};
use starc_hil::sim::scenario::{MotorProtocol, Scenario};
use starc_hil::tum::{pose_at, read_tum};
use starc_pipeline::align::SeedOrigin;
use starc_pipeline::align::{pose_error, AlignConfig, Attempt, Reasons};
use starc_pipeline::mission::{MissionInput, RigCore, RigCoreConfig, RobotCore, RobotCoreConfig, Side};
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let dir = PathBuf::from(args.get(1).expect("DIR"));
    let hint_m: f64 = args.get(2).map_or(1.0, |a| a.parse().unwrap());
    let hint_deg: f64 = args.get(3).map_or(20.0, |a| a.parse().unwrap());
    let gate_m: f64 = std::env::var("GATE_M").map_or(2.0, |v| v.parse().unwrap());
    let gt_robot = read_tum(&dir.join("gt_robot.tum")).unwrap();
    let gt_fpv = read_tum(&dir.join("gt_fpv.tum")).unwrap();
    let no_hint = std::env::var("NO_HINT").is_ok();
    let pcap = dir.join("avia.pcap");
    let mut inputs = starc_bridge::from_capture(&pcap, ROBOT_AVIA_IP, FPV_AVIA_IP).unwrap();
    // The base's wheels, as `starc mission` fuses them (the scenario's layout and motors).
    if let Ok((scenario, _)) = Scenario::load(&dir.join("scenario.toml").to_string_lossy()) {
        let robot = scenario.robot.get_ref();
        let motors = match robot.motors {
            MotorProtocol::C620 => MotorFeedback::C620,
            MotorProtocol::Cia402 => MotorFeedback::Cia402,
        };
        let base = WheelFeedback::plain(starc_hil::sim::wheels::default_geometry(robot.wheels), motors);
        if let Ok(w) = read_wheel_log(&dir.join("robot_can.log"), &base, 0) {
            inputs = with_wheels(inputs, w);
        }
    }

    let mut rc = RobotCore::new(RobotCoreConfig::default()).unwrap();
    let max_window_s: f64 = std::env::var("MAX_WINDOW_S").map_or(10.0, |v| v.parse().unwrap());
    // ALIGN_TOML=file: the first alignment's settings from that file (an `[align]`-style table).
    let align = std::env::var("ALIGN_TOML").map_or_else(
        |_| RigCoreConfig::default().align,
        |p| toml::from_str::<AlignConfig>(&std::fs::read_to_string(p).unwrap()).unwrap(),
    );
    let truth_align = align.clone();
    let mut core = RigCore::new(RigCoreConfig {
        align,
        start_gate_m: gate_m,
        max_first_window_ns: (max_window_s * 1e9) as u64,
        first_history_ns: std::env::var("HISTORY_S")
            .map_or(RigCoreConfig::default().first_history_ns, |v| (v.parse::<f64>().unwrap() * 1e9) as u64),
        ..RigCoreConfig::default()
    })
    .unwrap();
    let (mut rsteps, mut routs) = (Vec::new(), Vec::new());
    let mut lio_t_world: Option<Isometry3<f64>> = None;
    let mut odom: Vec<(u64, Isometry3<f64>)> = Vec::new();
    let mut hint_set = false;
    // The robot's LIO against the truth now (m, deg), and its largest angle so far.
    let (mut robot_err, mut robot_max_deg) = ((0.0, 0.0), 0.0f64);
    for input in inputs {
        match input.unwrap() {
            MissionInput::Imu(Side::Robot, s) => rc.push_imu(s, &mut rsteps),
            MissionInput::Scan(Side::Robot, s) => rc.push_scan(s, &mut rsteps),
            MissionInput::Wheel(_, s) => rc.push_wheel(s),
            MissionInput::Imu(Side::Rig, s) => core.push_imu(s, &mut routs),
            MissionInput::Scan(Side::Rig, s) => core.push_scan(s, &mut routs),
        }
        for st in rsteps.drain(..) {
            if lio_t_world.is_none() {
                lio_t_world = Some(st.output.lidar_pose * pose_at(&gt_robot, st.output.end_ns).unwrap().inverse());
            }
            if let (Some(l_t_w), Some(t)) = (lio_t_world, pose_at(&gt_robot, st.output.end_ns)) {
                robot_err = pose_error(&(l_t_w * t), &st.output.lidar_pose);
                robot_max_deg = robot_max_deg.max(robot_err.1);
            }
        }
        for o in routs.drain(..) {
            odom.push((o.end_ns, o.lidar_pose));
            let (Some(first), Some(l_t_w)) = (core.first_ns(), lio_t_world) else { continue };
            if !hint_set && !no_hint {
                let off = Isometry3::from_parts(
                    Translation3::new(0.8 * hint_m, -0.6 * hint_m, 0.0),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, hint_deg.to_radians()),
                );
                core.set_start_hint(l_t_w * pose_at(&gt_fpv, first).unwrap() * off);
                hint_set = true;
            }
            if core.wants_map() && rc.map_len() != core.map_len() {
                let (points, towards_sensor) = rc.map_points_seen_from();
                core.set_map_seen_from(points, towards_sensor);
                if std::env::var("NO_COVERAGE").is_err() {
                    core.set_coverage(rc.map_coverage());
                }
            }
            let Some(job) = core.next_job(Vec::new) else { continue };
            let end = job.end_ns;
            let truth = l_t_w * pose_at(&gt_fpv, end).unwrap();
            let t_s = (end - first) as f64 * 1e-9;
            // STOP_AFTER_S=s: end the run at the first search past s seconds of the rig.
            if std::env::var("STOP_AFTER_S").is_ok_and(|v| t_s > v.parse::<f64>().unwrap()) {
                return;
            }
            let truth_job = job.clone();
            // DUMP_DIR=dir: each search's inputs for the peers (scripts/align_window_peers.py):
            // the window in its frame, the robot's map, the true pose of the frame.
            let dump = std::env::var("DUMP_DIR").ok().map(|d| {
                let name = dir.file_name().map_or("run".into(), |n| n.to_string_lossy().into_owned());
                let out = PathBuf::from(d).join(format!("{name}_t{t_s:04.1}"));
                std::fs::create_dir_all(&out).unwrap();
                let inputs = job.inputs();
                write_f64(&out.join("source.f64"), &inputs.source);
                write_f64(&out.join("target.f64"), &inputs.target);
                let m = (truth * inputs.frame_t_lidar.inverse()).to_homogeneous();
                let rows: Vec<String> =
                    (0..4).flat_map(|r| (0..4).map(move |c| (r, c))).map(|(r, c)| m[(r, c)].to_string()).collect();
                std::fs::write(out.join("truth.txt"), rows.join(" ") + "\n").unwrap();
                out
            });
            let o = job.run().unwrap();
            if let Some(out) = &dump {
                let (m, deg) = pose_error(&o.world_t_lidar, &truth);
                let ours = format!(
                    "{{\"accepted\": {}, \"error_m\": {m}, \"error_deg\": {deg}, \"ms\": {}}}\n",
                    o.report.accepted, o.report.total_ms
                );
                std::fs::write(out.join("ours.json"), ours).unwrap();
            }
            // The pose the attempt claims for the rig at its first scan (what the hint is about).
            let o_first = odom.first().map(|p| p.1).unwrap();
            let o_end = odom.iter().rev().find(|p| p.0 <= end).map(|p| p.1).unwrap();
            let start_of = |w: &Isometry3<f64>| w * o_end.inverse() * o_first;
            // How far the rig's LIO has drifted since its first scan (what a window that
            // starts there carries into the fit), against the truth's own motion.
            let t_first = l_t_w * pose_at(&gt_fpv, odom.first().map_or(end, |p| p.0)).unwrap();
            let (drift_m, drift_deg) = pose_error(&(t_first.inverse() * truth), &(o_first.inverse() * o_end));
            println!(
                "  lio drift since first: {drift_m:.3} m {drift_deg:.2} deg; robot now {:.3} m {:.2} deg (at most {robot_max_deg:.2} deg)",
                robot_err.0, robot_err.1
            );
            let hint = core.start_hint().copied().unwrap_or_else(Isometry3::identity);
            let true_xy = truth.translation.vector;
            println!(
                "== t {:5.1} s (truth x {:6.2} y {:5.2}) tracking {} {} source pts, {} seeds, {:.0} ms",
                t_s,
                true_xy.x,
                true_xy.y,
                o.tracking,
                o.report.source_points,
                o.report.seeds.len(),
                o.report.total_ms
            );
            let attempts_ms: f64 = o.report.attempts.iter().map(|a| a.ndt_ms + a.icp_ms).sum();
            let verify_ms: f64 = o.report.attempts.iter().map(|a| a.verify_ms).sum();
            println!(
                "  time ms: reduce {:.0} seeds {:.0} attempts {:.0} checks {:.0} rest {:.0} (correlative stage {:.0})",
                o.report.source_reduce_ms,
                o.report.seed_ms,
                attempts_ms,
                verify_ms,
                o.report.total_ms - o.report.source_reduce_ms - o.report.seed_ms - attempts_ms - verify_ms,
                o.report.correlative_ms
            );
            for (i, a) in o.report.attempts.iter().enumerate() {
                let w = a.pose * o.frame_t_lidar;
                let (em, ed) = pose_error(&w, &truth);
                let off_now = (w.translation.vector - hint.translation.vector).norm();
                let off_start = (start_of(&w).translation.vector - hint.translation.vector).norm();
                println!(
                    "  att{i} seed {:+4.0} deg [{:+.1},{:+.1}]: err {:6.2} m {:6.1} deg | {} | gate now {:5.2} start {:5.2} | acc {} {}",
                    a.seed_yaw_offset_deg,
                    a.seed_shift_m[0],
                    a.seed_shift_m[1],
                    em,
                    ed,
                    fit(a),
                    off_now,
                    off_start,
                    a.accepted,
                    Reasons(&a.rejected_because)
                );
                if let Some(k) = &a.known_fit {
                    println!("      known here: share {:.3} score {:.3}", k.known_share, k.score_on_known);
                }
                for r in &a.rivals {
                    let (tm, td) = pose_error(&(r.pose * o.frame_t_lidar), &truth);
                    println!(
                        "      rival {:5.1} m {:4.0} deg (truth {:5.2} m {:5.1} deg): score {:.3} known {:.3} on known {:.3}",
                        r.off_m, r.off_deg, tm, td, r.score, r.fit.known_share, r.fit.score_on_known
                    );
                }
                for p in &a.alternatives {
                    println!(
                        "      alt seed {:+4.0}: moved {:.2} m {:.1} deg rms {:.4} inl {:.3}",
                        p.yaw_deg, p.moved_m, p.moved_deg, p.rms_residual_m, p.inlier_ratio
                    );
                }
            }
            // Where the seed nearest the truth ranked.
            let truth_frame = truth * o.frame_t_lidar.inverse();
            if let Some((rank, s, d)) = o
                .report
                .seeds
                .iter()
                .enumerate()
                .map(|(i, s)| (i, s, pose_error(&s.pose, &truth_frame)))
                .min_by(|a, b| (a.2 .0 + a.2 .1 / 10.0).total_cmp(&(b.2 .0 + b.2 .1 / 10.0)))
            {
                let best = o.report.seeds.first().map_or(0.0, |s| s.score);
                println!(
                    "  nearest seed to truth: rank {rank}/{} yaw {:+.0} shift [{:+.1},{:+.1}] {:.2} m {:.1} deg, score {:.3} (best {:.3})",
                    o.report.seeds.len(),
                    s.yaw_offset_deg,
                    s.shift_m[0],
                    s.shift_m[1],
                    d.0,
                    d.1,
                    s.score,
                    best
                );
            }
            let global: Vec<_> = o
                .report
                .seeds
                .iter()
                .enumerate()
                .filter(|(_, s)| matches!(s.origin, SeedOrigin::Global { .. } | SeedOrigin::Correlative { .. }))
                .map(|(i, s)| {
                    let (m, d) = pose_error(&s.pose, &truth_frame);
                    format!("#{i} {m:.1}m/{d:.0}deg {:?} {:.3}", s.origin, s.score)
                })
                .collect();
            println!("  global seeds (rank, off truth, votes, score): {}", global.join(" | "));
            // One attempt from the truth: NDT 1 m then ICP, the same acceptance and consistency check.
            let cfg = AlignConfig {
                reseed_yaw_step_deg: 0.0,
                ndt_resolutions_m: vec![1.0],
                seed_levels: 1,
                ndt_max_iterations: if std::env::var("TRUTH_NO_NDT").is_ok() {
                    0
                } else {
                    truth_align.ndt_max_iterations
                },
                ..truth_align.clone()
            };
            let t = truth_job.with_guess(truth, cfg).run().unwrap();
            if let Some(a) = t.report.attempts.first() {
                let w = a.pose * t.frame_t_lidar;
                let (em, ed) = pose_error(&w, &truth);
                let d = truth.inverse() * w;
                let (r, p, y) = d.rotation.euler_angles();
                let dw = w.translation.vector - truth.translation.vector;
                println!(
                    "  from truth: settles {:.3} m {:.2} deg [world {:+.3} {:+.3} {:+.3} rpy {:+.2} {:+.2} {:+.2}] | {} hops {} | acc {} {}",
                    em,
                    ed,
                    dw.x,
                    dw.y,
                    dw.z,
                    r.to_degrees(),
                    p.to_degrees(),
                    y.to_degrees(),
                    fit(a),
                    a.verify_hops,
                    a.accepted,
                    Reasons(&a.rejected_because)
                );
            }
            let (chosen_m, chosen_deg) = pose_error(&o.world_t_lidar, &truth);
            if std::env::var("NEVER_APPLY").is_ok() {
                // Every job a first alignment: how the global search's answers vary over time.
                let w_t_o = o.world_t_lidar * o.odom_t_lidar.inverse();
                println!(
                    "  SUMMARY t {t_s:5.1} acc {} err {chosen_m:6.2} m {chosen_deg:6.1} deg world_t_odom {:+7.2} {:+7.2} {:+7.1}",
                    o.report.accepted,
                    w_t_o.translation.x,
                    w_t_o.translation.y,
                    w_t_o.rotation.euler_angles().2.to_degrees()
                );
                core.remember(&o);
                let _ =
                    core.apply(Err(starc_pipeline::PipelineError::BadFile { format: "diag", reason: String::new() }));
                continue;
            }
            let verdict = core.apply(Ok(o));
            println!("  verdict {verdict:?} (chosen {chosen_m:.2} m {chosen_deg:.1} deg off truth)");
        }
    }
}

/// Little-endian f64 x, y, z triples (the peers' input format, tests/peers/align_peers.py).
fn write_f64(path: &std::path::Path, pts: &[nalgebra::Vector3<f64>]) {
    let bytes: Vec<u8> = pts.iter().flat_map(|p| [p.x, p.y, p.z]).flat_map(f64::to_le_bytes).collect();
    std::fs::write(path, bytes).unwrap();
}

/// An attempt's fit: RMS residual, inlier ratio, last update, degeneracy index, and the share
/// of rays the free-space check found blocked ("-" where it did not run).
fn fit(a: &Attempt) -> String {
    let m = &a.metrics;
    format!(
        "rms {:.4} inl {:.3} upd {:.1e} deg {:.2e} blk {}",
        m.rms_residual_m,
        m.inlier_ratio,
        m.update_norm,
        m.degeneracy_index,
        a.free_space.as_ref().map_or("-".to_string(), |f| format!("{:.3}", f.blocked_ratio))
    ) + &a
        .overlap
        .map_or(String::new(), |o| format!(" ovl {}/{}/{} r {:.3}", o.explained, o.contradicted, o.points, o.ratio()))
}
