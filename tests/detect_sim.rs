//! The person detector on a short simulator run: a furnished room with a person in each pose
//! (standing, sitting on a chair, crouching, lying), a table, clutter and walls, seen by the
//! robot's Avia through the pcap as a real capture. Precision, recall and the share of detected
//! points labelled as a person must stay within bounds a broken detector would miss.

#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "support/detect_sim.rs"]
#[allow(dead_code)] // the bench uses the timing half
mod detect_sim;

use starc_hil::sim::run::{run, SimOptions};
use starc_hil::sim::scenario::Scenario;
use starc_pipeline::detect::eval::MatchRule;
use starc_pipeline::detect::pillars::PillarsDetector;
use starc_pipeline::detect::{DetectConfig, DetectorKind, GeometricDetector};

const ROOM: &str = r#"
name = "detect test room"
duration_s = 2.6
[[floors]]
min = [-1, -1]
max = [11, 9]
ceiling_m = 2.7
[[walls]]
from = [0, 0]
to = [10, 0]
[[walls]]
from = [10, 0]
to = [10, 8]
doors = [{ at_m = 4.0, state = "closed" }]
[[walls]]
from = [10, 8]
to = [0, 8]
[[walls]]
from = [0, 8]
to = [0, 0]
[[boxes]]
name = "table"
at = [7.5, 5.2]
size_m = [1.4, 0.7, 0.75]
[[boxes]]
name = "chair"
at = [6.15, 3.0]
size_m = [0.45, 0.45, 0.45]
material = "fabric"
[[clutter]]
min = [7.0, 1.2]
max = [9.0, 2.6]
count = 5
seed = 3
[[people]]
name = "standing"
at = [5.0, 5.6]
yaw_deg = 180
[[people]]
name = "sitting"
pose = "sitting"
at = [6.0, 3.0]
yaw_deg = 180
[[people]]
name = "crouching"
pose = "crouching"
at = [4.5, 2.8]
yaw_deg = 150
[[people]]
name = "victim"
pose = "lying"
at = [3.5, 4.2]
yaw_deg = 90
[robot]
static_s = 5.0
waypoints = [[1.0, 4.0, 0]]
[responder]
waypoints = [[0.5, 0.5]]
"#;

/// The room, simulated and read back.
fn room_run() -> detect_sim::SimRun {
    let scenario = Scenario::parse(ROOM, "inline").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let opts = SimOptions { out: dir.path().to_path_buf(), duration_s: None, seed: 4, realtime: false, camera: false };
    run(&scenario, ROOM, &opts, &mut |_, _| {}).unwrap();
    detect_sim::load(dir.path())
}

fn report(ev: &detect_sim::Evaluation) {
    let c = ev.counts;
    let mut poses: Vec<String> = ev.per_pose.iter().map(|(k, (f, v))| format!("{k} {f}/{v}")).collect();
    poses.sort();
    eprintln!(
        "{} windows: TP {} FP {} misses {} ignored {}; precision {:.3} recall {:.3} [{}]; person points {:.1} %",
        ev.windows,
        c.true_positives,
        c.false_positives,
        c.misses,
        c.ignored,
        c.precision(),
        c.recall(),
        poses.join(", "),
        100.0 * ev.purity()
    );
    for (t, d) in &ev.false_positives {
        eprintln!("  FP at {t}: {:?} {:?} size {:?}", d.pose, d.centre_m, d.size_m);
    }
}

#[test]
fn detector_finds_people_in_every_pose_in_a_furnished_room() {
    let sim = room_run();
    // The hand-set gates (the shipped file's settings, whichever detector it picks).
    let shipped = DetectConfig::from_toml(include_str!("../config/detect.toml")).unwrap();
    let cfg = DetectConfig { kind: DetectorKind::Geometric, ..shipped };
    let mut det = GeometricDetector::new(cfg).unwrap();
    let rule = MatchRule::default();
    let ev = detect_sim::evaluate(&sim, &mut det, 300_000_000, 100_000_000, &rule);
    report(&ev);
    let c = ev.counts;
    assert!(ev.windows >= 20, "{} windows", ev.windows);
    // Every pose is seen in every window (the robot stands still facing them all).
    for pose in ["standing", "sitting", "crouching", "lying"] {
        let (_, visible) = ev.per_pose.get(pose).copied().unwrap_or_default();
        assert!(visible * 10 >= ev.windows * 9, "{pose} visible in {visible} of {} windows", ev.windows);
    }
    assert!(c.precision() >= 0.95, "precision {:.3}", c.precision());
    assert!(c.recall() >= 0.9, "recall {:.3}", c.recall());
    assert!(ev.purity() >= 0.8, "person points {:.3}", ev.purity());

    // The room has decoys: with the box, slab and flatness gates off, furniture and clutter
    // pass for people (so the bounds above test the gates, not an empty scene).
    let loose = DetectConfig {
        kind: DetectorKind::Geometric,
        max_face_share: 1.0,
        max_planarity: 1.0,
        min_thickness_m: 0.001,
        lying_length_m: [0.3, 2.5],
        ..DetectConfig::default()
    };
    let mut det = GeometricDetector::new(loose).unwrap();
    let ev = detect_sim::evaluate(&sim, &mut det, 300_000_000, 100_000_000, &rule);
    eprintln!("gates off: FP {}, precision {:.3}", ev.counts.false_positives, ev.counts.precision());
    assert!(ev.counts.precision() < 0.9, "gates off, precision {:.3}", ev.counts.precision());
}

/// The learned detector with the shipped weights, on the same room (a building it never saw in
/// training: the generated development buildings are its data). It is weak (docs/detect.md):
/// here it finds the lying person and misses the others, so the bounds guard what it does today
/// (the lying person in nearly every window, few false positives, the points it hands on being
/// the person's), not the goal.
#[test]
fn pointpillars_finds_the_lying_person_in_the_furnished_room() {
    let sim = room_run();
    let cfg = DetectConfig { kind: DetectorKind::Pointpillars, ..DetectConfig::default() };
    let mut det = PillarsDetector::new(&cfg).unwrap();
    let ev = detect_sim::evaluate(&sim, &mut det, 300_000_000, 100_000_000, &MatchRule::default());
    report(&ev);
    assert!(ev.windows >= 20, "{} windows", ev.windows);
    let (found, visible) = ev.per_pose.get("lying").copied().unwrap_or_default();
    assert!(found * 10 >= visible * 9 && visible * 10 >= ev.windows * 9, "lying found in {found} of {visible} windows");
    assert!(ev.counts.precision() >= 0.5, "precision {:.3}", ev.counts.precision());
    assert!(ev.purity() >= 0.8, "person points {:.3}", ev.purity());
}

/// The learned cluster scorer with the shipped trees on the same room, which is none of the
/// generated buildings it learned from. Measured when the trees were shipped (2026-11-28): no
/// false positive, and every window's standing, crouching and lying person, but the sitting one
/// in 2 of 23 (merged with their chair, it looks like furniture to the trees). The bounds guard
/// what it does today, not the goal.
#[test]
fn trees_find_people_in_the_furnished_room() {
    let sim = room_run();
    let cfg = DetectConfig { kind: DetectorKind::Trees, ..DetectConfig::default() };
    let mut det = GeometricDetector::new(cfg).unwrap();
    let ev = detect_sim::evaluate(&sim, &mut det, 300_000_000, 100_000_000, &MatchRule::default());
    report(&ev);
    assert!(ev.windows >= 20, "{} windows", ev.windows);
    assert!(ev.counts.precision() >= 0.95, "precision {:.3}", ev.counts.precision());
    for pose in ["standing", "crouching", "lying"] {
        let (found, visible) = ev.per_pose.get(pose).copied().unwrap_or_default();
        assert!(found * 10 >= visible * 9 && visible > 0, "{pose} found in {found} of {visible} windows");
    }
    assert!(ev.purity() >= 0.8, "person points {:.3}", ev.purity());
}
