//! What the simulator writes, the readers read back equal: TUM trajectories (written by
//! `starc_hil::tum::tum_line`), and a short simulator run's people.csv, camera frames,
//! camera mounting, masks and labels against the simulator's own models.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use starc_eval::truth::{read_camera, read_frames, read_people, read_tum, PersonReturns, Truth};
use starc_hil::sim::camera::PinholeCamera;
use starc_hil::sim::lan::AviaLink;
use starc_hil::sim::lidar::LABEL_EMPTY;
use starc_hil::sim::motion::{Motion, ResponderMotion, RobotMotion};
use starc_hil::sim::run::{run, SimOptions};
use starc_hil::sim::scenario::Scenario;
use starc_hil::sim::truth::read_labels;
use starc_hil::sim::world::World;
use starc_hil::tum::tum_line;

/// A wall with a door, someone behind it and someone in the doorway; the robot and the
/// responder face them.
fn scenario_text() -> String {
    format!(
        "{}[robot]\nwaypoints = [[0, -1, 0]]\n[responder]\nwaypoints = [[0, 0], [2, 0]]\n",
        starc_hil::sim::fixtures::WALL_AND_DOORWAY
    )
}

/// The largest distance and angle (rad) between two poses.
fn apart(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    ((a.translation.vector - b.translation.vector).norm(), a.rotation.angle_to(&b.rotation))
}

#[test]
fn tum_lines_read_back_as_written() {
    let poses: Vec<(u64, Isometry3<f64>)> = (0..20u64)
        .map(|i| {
            let f = i as f64;
            let q = UnitQuaternion::from_euler_angles(0.1 * f, -0.05 * f, 0.3 * f - 2.0);
            (
                1_767_225_600_000_000_001 + i * 5_000_123,
                Isometry3::from_parts(Translation3::new(f, -2.5 * f, 0.123456), q),
            )
        })
        .collect();
    let text: String = std::iter::once("# time tx ty tz qx qy qz qw".to_string())
        .chain(poses.iter().map(|(t, p)| tum_line(*t, p)))
        .map(|l| l + "\n")
        .collect();
    let file = tempfile::NamedTempFile::new().unwrap();
    std::fs::write(file.path(), text).unwrap();
    let back = read_tum(file.path()).unwrap();
    assert_eq!(back.len(), poses.len());
    for ((t, p), (tb, pb)) in poses.iter().zip(&back) {
        assert_eq!(t, tb, "times are exact to the nanosecond");
        let (m, rad) = apart(p, pb);
        assert!(m < 1e-6 && rad < 1e-8, "{m} m, {rad} rad");
    }
}

#[test]
fn a_simulator_run_reads_back_equal() {
    let dir = tempfile::tempdir().unwrap();
    let text = scenario_text();
    let scenario = Scenario::parse(&text, "round trip").unwrap();
    let opts =
        SimOptions { out: dir.path().to_path_buf(), duration_s: Some(0.5), seed: 1, realtime: false, camera: true };
    let summary = run(&scenario, &text, &opts, &mut |_, _| {}).unwrap();
    let offset = AviaLink::ptp_offset_ns();
    let sim_s = |ptp_ns: u64| ptp_ns.checked_add_signed(-offset).unwrap() as f64 * 1e-9;
    let world = World::new(&scenario);

    // Both trajectories, against the motions they were sampled from (200 Hz from 0 s).
    let robot = RobotMotion::new(scenario.robot.get_ref());
    let responder = ResponderMotion::new(scenario.responder.get_ref());
    for (file, motion) in [("gt_robot.tum", &robot as &dyn Motion), ("gt_fpv.tum", &responder as &dyn Motion)] {
        let traj = read_tum(&dir.path().join(file)).unwrap();
        assert_eq!(traj.len(), 101, "{file}: 200 Hz over 0.5 s");
        for (k, (t, pose)) in traj.iter().enumerate() {
            assert_eq!(*t, (k as u64 * 5_000_000).checked_add_signed(offset).unwrap());
            let (m, rad) = apart(pose, &motion.lidar_pose(sim_s(*t)));
            assert!(m < 1e-6 && rad < 1e-8, "{file} pose {k}: {m} m, {rad} rad");
        }
    }

    // People's boxes at 10 Hz, every person at every sample.
    let people = read_people(&dir.path().join("people.csv")).unwrap();
    assert_eq!(people.len(), 6 * world.people.len());
    for (i, p) in people.iter().enumerate() {
        let sample = (i / world.people.len()) as u64 * 100_000_000;
        assert!(p.t_ns.abs_diff(sample.checked_add_signed(offset).unwrap()) < 1_000, "time within 1 us");
        let model = world.people.iter().find(|m| m.label == p.label).unwrap();
        let body = model.body_at(sample as f64 * 1e-9);
        assert!((p.centre_m - body.box_centre).amax() < 1e-4, "{:?} {:?}", p.centre_m, body.box_centre);
        assert!((p.size_m - body.box_size).amax() < 1e-4);
        assert!((p.yaw_rad - body.yaw_rad).abs() < 1e-5);
    }

    // The camera's intrinsics and mounting.
    let camera = PinholeCamera::new(scenario.camera.clone());
    let mount = read_camera(&dir.path().join("extrinsics.json")).unwrap();
    let c = &scenario.camera;
    assert_eq!((mount.camera.width, mount.camera.height), (c.width_px, c.height_px));
    assert_eq!(
        (mount.camera.fx, mount.camera.fy, mount.camera.cx, mount.camera.cy),
        (c.fx_px, c.fy_px, c.cx_px, c.cy_px)
    );
    let (m, rad) = apart(&mount.lidar_t_camera, &camera.lidar_camera);
    assert!(m < 1e-12 && rad < 1e-12, "{m} m, {rad} rad");

    // The camera frames: numbered in order, at the camera's rate, posed as the rig's camera.
    let frames = read_frames(&dir.path().join("camera/frames.csv")).unwrap();
    assert_eq!(frames.len() as u64, summary.camera_frames);
    assert!(frames.len() >= 5, "{} frames in 0.5 s", frames.len());
    let period_ns = (1e9 / c.rate_hz).round() as u64;
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f.index, k as u64);
        let due = k as u64 * period_ns;
        let t = f.t_ns.checked_add_signed(-offset).unwrap();
        assert!(t >= due && t < due + 100_000, "frame {k} at {t} ns, due {due} ns (one 0.1 ms step)");
        let (m, rad) = apart(&f.world_t_camera, &(responder.lidar_pose(sim_s(f.t_ns)) * camera.lidar_camera));
        assert!(m < 1e-6 && rad < 1e-8, "frame {k}: {m} m, {rad} rad");
    }

    // Truth::load reads it all; its masks are the camera's.
    let truth = Truth::load(dir.path()).unwrap();
    assert_eq!(truth.scenario, "wall and doorway");
    assert_eq!(truth.frames, frames);
    assert_eq!(truth.mount, mount);
    for f in [&frames[0], &frames[frames.len() - 1]] {
        let ts = sim_s(f.t_ns);
        let masks = camera.render(&world, &world.bodies_at(ts), &responder.lidar_pose(ts));
        let see = truth.see_through(f.index).unwrap().unwrap();
        let visible = truth.visible(f.index).unwrap().unwrap();
        assert_eq!((see.width, see.height, &see.pixels), (masks.width, masks.height, &masks.see_through));
        assert_eq!(visible.pixels, masks.visible);
        let (hidden_see, hidden_visible) = masks.count(1);
        assert!(hidden_see > 0 && hidden_visible == 0, "the person behind the wall is in the see-through mask only");
    }
    assert_eq!(truth.see_through(frames.len() as u64).unwrap(), None, "past the last frame");

    // The robot's labels: the returns on each person, as the file counts them.
    let returns = PersonReturns::read(&dir.path().join("labels_robot.bin")).unwrap();
    let raw = read_labels(&std::fs::read(dir.path().join("labels_robot.bin")).unwrap()).unwrap();
    for m in &world.people {
        let counted: usize =
            raw.iter().flat_map(|(_, l)| l.iter()).filter(|&&l| l == m.label && l != LABEL_EMPTY).count();
        assert_eq!(returns.on_person(m.label, 0, u64::MAX), counted, "person {}", m.label);
    }
}
