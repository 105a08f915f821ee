//! The few lines a scored run prints: every figure of report.json that a reader looks at first.

use crate::report::Report;
use std::fmt::Write as _;

/// The report as a short text, one line per part (inlier ratio, overlay, detection, alignment,
/// the rig's and the robot's pose errors, latency and memory).
pub fn summary(r: &Report) -> String {
    let mut o = String::new();
    let pct = |v: f64| if v.is_finite() { format!("{:.1} %", v * 100.0) } else { "n/a".into() };
    let _ = writeln!(o, "mission {} ({}, {:.1} s):", r.scenario, r.mode, r.duration_s);
    let i = &r.inlier_ratio;
    let _ = writeln!(
        o,
        "  inlier ratio (person points in the see-through masks): {} over {} frames (through the true camera pose: {})",
        pct(i.pooled),
        i.frames_scored,
        pct(i.pooled_true_pose)
    );
    let v = &r.overlay;
    let _ = writeln!(
        o,
        "  overlay (people detected in the last second): person coverage {} over {} (frame, person) pairs; \
         people behind walls shown {} of {} pairs ({} of the {} in frames drawn aligned)",
        pct(v.person_coverage),
        v.coverage_pairs,
        pct(v.people_shown),
        v.shown_pairs,
        pct(v.people_shown_aligned),
        v.shown_pairs_aligned
    );
    let d = &r.detection;
    let _ = writeln!(
        o,
        "  detection: precision {:.3}, recall {:.3} ({} true, {} false, {} missed over {} windows)",
        d.precision, d.recall, d.true_positives, d.false_positives, d.misses, d.windows
    );
    let a = &r.alignment;
    match (a.first_accepted_after_s, a.first_error_m, a.first_error_deg) {
        (Some(t), Some(m), Some(deg)) => {
            let _ = writeln!(
                o,
                "  alignment: first accepted {t:.1} s after the rig started, {:.1} cm / {deg:.2} deg off the truth; \
                 {} of {} attempts accepted, {:.0} ms median",
                m * 100.0,
                a.accepted,
                a.attempts,
                a.time_ms.p50
            );
        }
        _ => {
            let _ = writeln!(o, "  alignment: none accepted in {} attempts: nothing was drawn", a.attempts);
        }
    }
    let _ = writeln!(o, "  {}", map_sight_line(a));
    let e = &r.rig_pose_error;
    let _ = writeln!(
        o,
        "  rig world pose error: {:.1} cm median, {:.1} cm p99; {:.2} deg median",
        e.translation_m.p50 * 100.0,
        e.translation_m.p99 * 100.0,
        e.rotation_deg.p50
    );
    let e = &r.robot_pose_error;
    let _ = writeln!(
        o,
        "  robot LIO pose error (from its first pose): {:.1} cm median, {:.1} cm p99, {:.1} cm max, {:.1} cm RMSE; \
         {:.2} deg median, {:.2} deg max",
        e.translation_m.p50 * 100.0,
        e.translation_m.p99 * 100.0,
        e.translation_m.max * 100.0,
        e.rmse_m * 100.0,
        e.rotation_deg.p50,
        e.rotation_deg.max
    );
    if let Some(e) = &r.rig_lio_error {
        let drift = e.drift.as_ref().map_or(String::new(), |d| {
            format!("; {} drift stretches (10 cm within 5 s), {} of them unflagged", d.stretches, d.silent)
        });
        let _ = writeln!(
            o,
            "  rig LIO pose error (its own odometry, from its first pose): {:.1} cm median, {:.1} cm max, {:.1} cm RMSE{drift}",
            e.translation_m.p50 * 100.0,
            e.translation_m.max * 100.0,
            e.rmse_m * 100.0,
        );
    }
    let x = &r.exploration;
    if let Some([t_s, _]) = x.area_by_time.last() {
        let _ = writeln!(
            o,
            "  exploration ({} route): {:.1} m^2 of traversable floor known after {:.0} s",
            x.route, x.area_m2, t_s
        );
    }
    let l = &r.latency_ms;
    let _ = writeln!(
        o,
        "  latency (p50 / p99): L_SLAM {:.1} / {:.1} ms, L_comm {:.1} / {:.1} ms, L_viz {:.1} / {:.1} ms, total {:.1} / {:.1} ms{}; \
         peak memory {:.0} MiB",
        l.slam_p50,
        l.slam_p99,
        l.comm_p50,
        l.comm_p99,
        l.viz_p50,
        l.viz_p99,
        l.total_p50,
        l.total_p99,
        if r.mode == "offline" { " (compute only: no link in this path)" } else { "" },
        r.memory.peak_rss_mib.unwrap_or(f64::NAN)
    );
    o
}

/// When the rig first saw the robot's map, and the alignment goal against it.
fn map_sight_line(a: &crate::AlignmentReport) -> String {
    let m = &a.map_sight;
    let wrong = format!("{} accepted more than 10 cm or 1 deg off", a.accepted_wrong);
    match (m.sees_map_after_s, m.right_within_10s) {
        (Some(s), Some(ok)) => format!(
            "map in view: first {s:.0} s after the rig started ({} of {} s); right within 10 s of it: {}; {wrong}",
            m.seconds_seeing_map,
            m.seconds_judged,
            if ok { "yes" } else { "no" }
        ),
        _ if m.seconds_judged == 0 => format!("map in view: not measured (a live run); {wrong}"),
        _ => format!(
            "map in view: never (at most {:.0} % of a second's returns on it): no alignment could be asked for; {wrong}",
            m.best_share * 100.0
        ),
    }
}
