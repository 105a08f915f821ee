//! The trees' following on synthetic scenes: a person the trees confirmed is found again where
//! they merge with something beside them, for a while.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::tests::{cylinder, detect_at, room};
use super::*;

const S: u64 = 1_000_000_000;

/// Someone standing at (4, 1), 1.72 m tall.
fn standing(p: &mut Vec<WindowPoint>) {
    cylinder(p, [4.0, 0.9], 0.08, [0.0, 0.85]);
    cylinder(p, [4.0, 1.1], 0.08, [0.0, 0.85]);
    cylinder(p, [4.0, 1.0], 0.18, [0.85, 1.45]);
    cylinder(p, [4.0, 1.0], 0.1, [1.45, 1.72]);
}

fn alone() -> Vec<WindowPoint> {
    let mut p = room(true);
    standing(&mut p);
    p
}

/// The same person with a plant (0.44 m across, 1.2 m tall) touching their side: one cluster.
fn beside_a_plant() -> Vec<WindowPoint> {
    let mut p = alone();
    cylinder(&mut p, [4.0, 1.45], 0.22, [0.0, 1.2]);
    p
}

fn near_them(found: &[Detection]) -> usize {
    found.iter().filter(|d| (d.centre_m.x - 4.0).hypot(d.centre_m.y - 1.0) < 0.3).count()
}

/// Confirms them alone five times, 0.1 s apart; the time of the next window.
fn confirmed(det: &mut GeometricDetector) -> u64 {
    for k in 0..5 {
        let found = detect_at(det, alone(), S + k * S / 10);
        assert_eq!(near_them(&found), 1, "the trees take them alone for a person: {found:#?}");
    }
    S + S / 2
}

#[test]
fn a_person_merged_with_a_plant_is_found_again_where_they_were_confirmed() {
    let fresh = detect_at(&mut GeometricDetector::new(DetectConfig::default()).unwrap(), beside_a_plant(), S);
    assert!(fresh.is_empty(), "merged and never seen alone, the cluster is no one: {fresh:#?}");

    let mut det = GeometricDetector::new(DetectConfig::default()).unwrap();
    let t = confirmed(&mut det);
    let found = detect_at(&mut det, beside_a_plant(), t);
    assert_eq!(found.len(), 1, "{found:#?}");
    assert_eq!(near_them(&found), 1, "{found:#?}");
    assert_eq!(found[0].pose, PersonPose::Upright);
    assert!(found[0].score >= 0.3 && found[0].score <= 1.0);
    // What was found again is them: every point handed out lies in their box, none on the plant.
    let points = beside_a_plant();
    for &i in &found[0].point_indices {
        let p = points[i as usize];
        assert!(found[0].contains(&p.xyz(), 0.01), "{p:?} outside {:?}", found[0]);
        assert!(f64::from(p.y_m) < 1.25, "a point of the plant: {p:?}");
    }
}

#[test]
fn finding_again_needs_a_recent_confirmation_and_can_be_turned_off() {
    // Found again is no confirmation: 1.5 s (`follow_s`) after the last one, nobody.
    let mut det = GeometricDetector::new(DetectConfig::default()).unwrap();
    let t = confirmed(&mut det);
    assert_eq!(near_them(&detect_at(&mut det, beside_a_plant(), t + S / 2)), 1);
    assert_eq!(near_them(&detect_at(&mut det, beside_a_plant(), t + 9 * S / 10)), 1);
    assert!(detect_at(&mut det, beside_a_plant(), t + 16 * S / 10).is_empty(), "followed too long");

    // Three confirmations are one too few.
    let mut fewer = GeometricDetector::new(DetectConfig::default()).unwrap();
    for k in 0..3 {
        detect_at(&mut fewer, alone(), S + k * S / 10);
    }
    assert!(detect_at(&mut fewer, beside_a_plant(), S + 3 * S / 10).is_empty());

    for off in [
        TreesConfig { carve: false, ..TreesConfig::default() },
        TreesConfig { follow_min_score: TreesConfig::default().min_score, ..TreesConfig::default() },
    ] {
        let mut det = GeometricDetector::new(DetectConfig { trees: off.clone(), ..DetectConfig::default() }).unwrap();
        let t = confirmed(&mut det);
        assert!(detect_at(&mut det, beside_a_plant(), t).is_empty(), "{off:?}");
    }
}

#[test]
fn someone_found_is_not_looked_for_again() {
    // Seen alone again, they are found once, not a second time by their box.
    let mut det = GeometricDetector::new(DetectConfig::default()).unwrap();
    let t = confirmed(&mut det);
    let found = detect_at(&mut det, alone(), t);
    assert_eq!(found.len(), 1, "{found:#?}");
}
