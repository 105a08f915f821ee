#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;
use crate::PipelineError;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use std::path::PathBuf;

fn pose(x: f64, y: f64, z: f64, yaw_deg: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()))
}

fn close(a: &Isometry3<f64>, b: &Isometry3<f64>, tol: f64) -> bool {
    let d = a.inverse() * b;
    d.translation.vector.norm() < tol && d.rotation.angle() < tol
}

#[test]
fn buffer_interpolates_on_se3_and_refuses_outside() {
    let mut b = PoseBuffer::new(100);
    assert!(matches!(b.at(5), Err(PipelineError::PoseOutOfRange { len: 0, .. })));
    b.push(1_000, pose(0.0, 0.0, 0.0, 0.0)).unwrap();
    b.push(2_000, pose(2.0, -4.0, 1.0, 90.0)).unwrap();
    b.push(4_000, pose(4.0, -4.0, 1.0, 90.0)).unwrap();
    // Exact at stored times, halfway in between: lerp + slerp.
    assert!(close(&b.at(2_000).unwrap(), &pose(2.0, -4.0, 1.0, 90.0), 1e-12));
    assert!(close(&b.at(1_500).unwrap(), &pose(1.0, -2.0, 0.5, 45.0), 1e-12));
    assert!(close(&b.at(1_250).unwrap(), &pose(0.5, -1.0, 0.25, 22.5), 1e-12));
    assert!(close(&b.at(3_000).unwrap(), &pose(3.0, -4.0, 1.0, 90.0), 1e-12));
    for t in [999, 4_001, 0, u64::MAX] {
        match b.at(t) {
            Err(PipelineError::PoseOutOfRange { t_ns, first_ns: 1_000, last_ns: 4_000, len: 3 }) => assert_eq!(t_ns, t),
            other => panic!("{t}: {other:?}"),
        }
    }
    // Order and finiteness are checked.
    assert!(matches!(b.push(4_000, pose(0.0, 0.0, 0.0, 0.0)), Err(PipelineError::BadPose { .. })));
    assert!(matches!(b.push(5_000, pose(f64::NAN, 0.0, 0.0, 0.0)), Err(PipelineError::BadPose { .. })));
    assert_eq!(b.len(), 3);
}

#[test]
fn buffer_slerps_the_short_way_and_drops_the_oldest() {
    let mut b = PoseBuffer::new(3);
    b.push(0, pose(0.0, 0.0, 0.0, 170.0)).unwrap();
    b.push(10, pose(0.0, 0.0, 0.0, -170.0)).unwrap();
    // Across ±180: the middle is 180, not 0.
    let mid = b.at(5).unwrap();
    assert!((mid.rotation.angle().to_degrees() - 180.0).abs() < 1e-9, "{}", mid.rotation.angle().to_degrees());
    b.push(20, pose(1.0, 0.0, 0.0, 0.0)).unwrap();
    b.push(30, pose(2.0, 0.0, 0.0, 0.0)).unwrap();
    assert_eq!(b.len(), 3);
    assert_eq!(b.span_ns(), Some((10, 30)));
    assert!(b.at(5).is_err());
}

/// The rig's odometry: it walks along its own x at 1 m/s, turning 10 deg/s, from 0 to 5 s at 100 Hz.
fn rig_odometry(t_ns: u64) -> Isometry3<f64> {
    let t = t_ns as f64 * 1e-9;
    pose(t, 0.2 * t, 0.0, 10.0 * t)
}

#[test]
fn unaligned_until_the_first_registration_then_composes() {
    let mut w = WorldPose::new(WorldPoseConfig::default());
    assert_eq!(w.state(), WorldPoseState::Unaligned);
    // The rig booted first: its odometry runs, no world pose yet.
    for k in 0..=200u64 {
        w.push_odometry(k * 10_000_000, rig_odometry(k * 10_000_000)).unwrap();
    }
    assert_eq!(w.world_pose(1_000_000_000).unwrap(), None);
    // A registration referring to a time the buffer does not hold is refused.
    assert!(matches!(
        w.push_registration(3_000_000_000, pose(0.0, 0.0, 0.0, 0.0)),
        Err(PipelineError::PoseOutOfRange { .. })
    ));
    // The robot's world: the rig's odometry frame sits at (5, 2, 0.3), turned 30 deg.
    let w_t_o = pose(5.0, 2.0, 0.3, 30.0);
    let t0 = 1_000_000_000;
    assert_eq!(w.push_registration(t0, w_t_o * rig_odometry(t0)).unwrap(), RegistrationOutcome::Initial);
    assert_eq!(w.state(), WorldPoseState::Aligned);
    for k in 100..=200u64 {
        let t = k * 10_000_000 + 5_000_000 * u64::from(k < 200);
        let got = w.world_pose(t).unwrap().unwrap();
        // wT_fpv(t) = wT_fpv(t0) · ΔT(t0 → t).
        let delta = w.odometry().at(t0).unwrap().inverse() * w.odometry().at(t).unwrap();
        assert!(close(&got, &(w_t_o * rig_odometry(t0) * delta), 1e-9), "t {t}");
        assert!(close(&got, &(w_t_o * rig_odometry(t)), 1e-6), "t {t}");
    }
    assert!(matches!(w.world_pose(2_000_000_001), Err(PipelineError::PoseOutOfRange { .. })));
}

#[test]
fn drift_correction_slides_in_bounded_steps_and_snaps_when_far() {
    let config = WorldPoseConfig { max_step_m: 0.01, max_step_deg: 0.2, ..WorldPoseConfig::default() };
    let mut w = WorldPose::new(config.clone());
    for k in 0..=100u64 {
        w.push_odometry(k * 10_000_000, rig_odometry(k * 10_000_000)).unwrap();
    }
    let w_t_o = pose(5.0, 2.0, 0.3, 30.0);
    w.push_registration(500_000_000, w_t_o * rig_odometry(500_000_000)).unwrap();
    // The LIO drifted: the new registration says the odometry frame is 12 cm and 1.5 deg off.
    let drifted = w_t_o * pose(0.08, -0.09, 0.0, 1.5);
    let outcome = w.push_registration(900_000_000, drifted * rig_odometry(900_000_000)).unwrap();
    assert_eq!((outcome, w.state()), (RegistrationOutcome::Sliding, WorldPoseState::Correcting));
    let now = 1_000_000_000;
    // Seen at the rig, the correction is the 1.5 deg plus what that turn does to the rig's offset.
    let odo = rig_odometry(now);
    let e = (w.correction().unwrap() * odo).inverse() * (drifted * odo);
    let expected = (e.translation.vector.norm() / config.max_step_m)
        .max(e.rotation.angle().to_degrees() / config.max_step_deg)
        .ceil() as u32;
    let mut before = w.world_pose(now).unwrap().unwrap();
    let mut frames = 0;
    while w.state() == WorldPoseState::Correcting {
        let s = w.step_frame();
        let after = w.world_pose(now).unwrap().unwrap();
        let d = before.inverse() * after;
        // The rendered pose never moves more than one step per frame.
        assert!(d.translation.vector.norm() <= config.max_step_m + 1e-9, "{s:?}");
        assert!(d.rotation.angle().to_degrees() <= config.max_step_deg + 1e-9, "{s:?}");
        before = after;
        frames += 1;
        assert!(frames < 100, "never converged: {s:?}");
    }
    assert!(expected >= 8, "at least 1.5 deg at 0.2 deg per frame");
    assert_eq!(frames, expected);
    assert!(close(&w.correction().unwrap(), &drifted, 1e-9));
    assert_eq!(w.snaps, 0);
    // A 2 m re-localisation snaps; a 5 m one is refused as a false match.
    let refused = drifted * pose(5.0, 0.0, 0.0, 0.0);
    let outcome = w.push_registration(950_000_000, refused * rig_odometry(950_000_000)).unwrap();
    assert_eq!((outcome, w.refused), (RegistrationOutcome::Refused, 1));
    assert!(close(&w.correction().unwrap(), &drifted, 1e-9));
    let far = drifted * pose(2.0, 0.0, 0.0, 0.0);
    let outcome = w.push_registration(950_000_000, far * rig_odometry(950_000_000)).unwrap();
    assert_eq!((outcome, w.state(), w.snaps), (RegistrationOutcome::Snapped, WorldPoseState::Aligned, 1));
    let p = w.world_pose(now).unwrap().unwrap();
    assert!((p.translation.vector - (far * rig_odometry(now)).translation.vector).norm() < 1e-9);
}

#[test]
fn config_example_loads_and_is_checked() {
    let text =
        std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../config/world_pose.toml")).unwrap();
    assert_eq!(WorldPoseConfig::from_toml(&text).unwrap(), WorldPoseConfig::default());
    assert_eq!(WorldPoseConfig::from_toml("").unwrap(), WorldPoseConfig::default());
    assert!(WorldPoseConfig::from_toml("max_step_m = 0\n").is_err());
    assert!(WorldPoseConfig::from_toml("bogus = 1\n").is_err());
}

/// Information that pins down everything but translation along the rig's x (a hall's axis).
fn hall_constraint() -> Constraint {
    let mut rows = [[0.0; 6]; 6];
    for (i, row) in rows.iter_mut().enumerate() {
        row[i] = if i == 3 { 0.0 } else { 0.2 };
    }
    Constraint::from_rows(&rows, [2.0, 0.0, 0.0], 3.0).unwrap()
}

#[test]
fn constraint_keeps_only_what_the_registration_pins_down() {
    let c = hall_constraint();
    // A correction of 10 cm along x (unconstrained) and 10 cm along y (constrained, gain 0.8).
    let e = pose(0.1, 0.1, 0.0, 0.0);
    let kept = c.filter(&e, 0.05);
    assert!(kept.translation.x.abs() < 1e-9, "{kept:?}");
    assert!((kept.translation.y - 0.08).abs() < 1e-9, "{kept:?}");
    // Half gain 0: the correction is followed in full.
    assert!(close(&c.filter(&e, 0.0), &e, 1e-12));
    // A rotation about the constrained axes is kept at the same share, about the centre.
    let turn =
        Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.0), UnitQuaternion::from_euler_angles(0.0, 0.0, 0.01));
    let kept = c.filter(&turn, 0.05);
    assert!((kept.rotation.angle() - 0.008).abs() < 1e-6, "{kept:?}");
    // Bad information is refused.
    let mut rows = [[0.0; 6]; 6];
    rows[0][0] = f64::NAN;
    assert!(Constraint::from_rows(&rows, [0.0; 3], 1.0).is_none());
    assert!(Constraint::from_rows(&[[0.0; 6]; 6], [0.0; 3], 0.0).is_none());
}

#[test]
fn constrained_registration_slides_only_along_pinned_directions() {
    let mut w = WorldPose::new(WorldPoseConfig::default());
    for k in 0..=100u64 {
        w.push_odometry(k * 10_000_000, rig_odometry(k * 10_000_000)).unwrap();
    }
    let w_t_o = pose(5.0, 2.0, 0.3, 30.0);
    let t = 900_000_000;
    w.push_registration(500_000_000, w_t_o * rig_odometry(500_000_000)).unwrap();
    // The registration claims the rig is 20 cm further along its own x (the hall's axis) and
    // 4 cm to its left.
    let claimed = w_t_o * rig_odometry(t) * pose(0.2, 0.04, 0.0, 0.0);
    let outcome = w.push_registration_constrained(t, claimed, &hall_constraint()).unwrap();
    assert_eq!(outcome, RegistrationOutcome::Sliding);
    let mut frames = 0;
    while w.state() == WorldPoseState::Correcting {
        w.step_frame();
        frames += 1;
        assert!(frames < 100);
    }
    let moved = (w_t_o * rig_odometry(t)).inverse() * w.world_pose(t).unwrap().unwrap();
    assert!(moved.translation.x.abs() < 1e-6, "the hall's axis stays with the LIO: {moved:?}");
    assert!((moved.translation.y - 0.04 * 0.8).abs() < 1e-6, "{moved:?}");
}

#[test]
fn non_unit_rotations_are_renormalised() {
    // A registration whose quaternion is 3 % short (a lerped guess carried through the solver).
    let mut w = WorldPose::new(WorldPoseConfig::default());
    for k in 0..=100u64 {
        w.push_odometry(k * 10_000_000, rig_odometry(k * 10_000_000)).unwrap();
    }
    let w_t_o = pose(5.0, 2.0, 0.3, 30.0);
    let short = |p: Isometry3<f64>| {
        Isometry3::from_parts(p.translation, UnitQuaternion::new_unchecked(p.rotation.quaternion() * 0.97))
    };
    w.push_registration(500_000_000, short(w_t_o * rig_odometry(500_000_000))).unwrap();
    let later = short(w_t_o * pose(0.05, 0.0, 0.0, 0.5) * rig_odometry(900_000_000));
    w.push_registration_constrained(900_000_000, later, &hall_constraint()).unwrap();
    for _ in 0..200 {
        w.step_frame();
    }
    let q = w.correction().unwrap().rotation.quaternion().norm();
    assert!((q - 1.0).abs() < 1e-12, "{q}");
    let (m, _) = crate::align::pose_error(
        &w.world_pose(1_000_000_000).unwrap().unwrap(),
        &(w_t_o * rig_odometry(1_000_000_000)),
    );
    assert!(m < 0.1, "{m}");
    // Odometry poses are renormalised as they enter the buffer.
    let mut b = PoseBuffer::new(4);
    b.push(1, short(pose(1.0, 2.0, 3.0, 40.0))).unwrap();
    assert!((b.at(1).unwrap().rotation.quaternion().norm() - 1.0).abs() < 1e-12);
}

#[test]
fn innovation_gate_refuses_large_claims_soon_after_the_last() {
    let config = WorldPoseConfig { gate_m: 0.05, gate_m_per_s: 0.01, ..WorldPoseConfig::default() };
    let mut w = WorldPose::new(config);
    for k in 0..=2000u64 {
        w.push_odometry(k * 10_000_000, rig_odometry(k * 10_000_000)).unwrap();
    }
    let w_t_o = pose(5.0, 2.0, 0.3, 30.0);
    w.push_registration(1_000_000_000, w_t_o * rig_odometry(1_000_000_000)).unwrap();
    // 12 cm claimed 1 s later: beyond 5 cm + 1 cm/s.
    let claim = |t: u64| w_t_o * rig_odometry(t) * pose(0.12, 0.0, 0.0, 0.0);
    assert_eq!(w.push_registration(2_000_000_000, claim(2_000_000_000)).unwrap(), RegistrationOutcome::Refused);
    assert_eq!((w.refused, w.gated), (1, 1));
    // 4 cm is within the gate.
    let small = w_t_o * rig_odometry(3_000_000_000) * pose(0.04, 0.0, 0.0, 0.0);
    assert_eq!(w.push_registration(3_000_000_000, small).unwrap(), RegistrationOutcome::Sliding);
    // The same 12 cm (from the new target) 8 s after that: the gate has grown to 13 cm.
    let t = 11_000_000_000;
    let again = w.target_correction().unwrap() * rig_odometry(t) * pose(0.12, 0.0, 0.0, 0.0);
    assert_eq!(w.push_registration(t, again).unwrap(), RegistrationOutcome::Sliding);
    assert_eq!(w.gated, 1);
}
