//! The AR projection against the simulator's camera: points on a simulated person's surface
//! (as the robot's LiDAR would see them, from another viewpoint) are projected with
//! `starc_pipeline::ar` through the simulator's camera pose, and must land inside the person's
//! see-through mask rendered by `starc_hil::sim::camera` (which ray-casts every pixel). A
//! camera pose off by a few degrees must visibly fail the same check.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use starc_hil::sim::camera::{write_png, PinholeCamera};
use starc_hil::sim::human::Body;
use starc_hil::sim::motion::pose_xyz_rpy;
use starc_hil::sim::scenario::{Camera, Scenario};
use starc_hil::sim::world::World;
use starc_pipeline::ar::{
    mask_inlier_ratio, project_people, read_mask_png, render, ArPerson, ArStatus, CameraModel, RenderConfig,
    COLOUR_PERSON,
};

/// Two people behind a closed wall: one facing the rig, one side-on and further away.
const SCENE: &str = r#"
name = "ar camera"
[[walls]]
from = [4, -4]
to = [4, 4]
[[people]]
name = "facing"
at = [6, 0.4]
yaw_deg = 180
[[people]]
name = "side-on"
at = [8, -1.5]
yaw_deg = 90
[robot]
waypoints = [[0, 0, 0]]
[responder]
waypoints = [[0, 0]]
"#;

/// Surface points of `body` as a LiDAR at `origin` sees them: a grid of rays aimed across the
/// body's bounding box, keeping the hits.
fn surface_points(body: &Body, origin: Vector3<f64>) -> Vec<Vector3<f64>> {
    let (lo, hi) = (body.bounds.min, body.bounds.max);
    let mut points = Vec::new();
    for i in 0..40 {
        for j in 0..40 {
            for k in 0..3 {
                let f = |a: f64, b: f64, s: f64| a + (b - a) * s;
                let (si, sj, sk) = (f64::from(i) / 39.0, f64::from(j) / 39.0, f64::from(k) / 2.0);
                let target = Vector3::new(f(lo.x, hi.x, sk), f(lo.y, hi.y, si), f(lo.z, hi.z, sj));
                let d = (target - origin).normalize();
                if let Some(hit) = body.cast(&origin, &d, &d.map(|x| 1.0 / x), 100.0) {
                    points.push(origin + d * hit.t);
                }
            }
        }
    }
    points
}

fn camera_model(c: &Camera) -> CameraModel {
    CameraModel { width: c.width_px, height: c.height_px, fx: c.fx_px, fy: c.fy_px, cx: c.cx_px, cy: c.cy_px }
}

#[test]
fn projected_person_points_land_in_the_simulated_mask() {
    let scenario = Scenario::parse(SCENE, "ar camera").unwrap();
    let world = World::new(&scenario);
    let bodies = world.bodies_at(0.0);
    assert_eq!(bodies.len(), 2);
    let camera = PinholeCamera::new(Camera::default());
    // The rig's LiDAR at eye height, turned a little so neither person sits at the image centre.
    let rig = pose_xyz_rpy(Vector3::new(0.0, 0.0, 1.6), 0.0, 0.03, -0.08);
    let masks = camera.render(&world, &bodies, &rig);
    // Hidden behind the wall: only the see-through mask has them.
    assert!(masks.count(1).0 > 1000 && masks.count(2).0 > 500, "{:?} {:?}", masks.count(1), masks.count(2));
    assert_eq!(masks.count(1).1 + masks.count(2).1, 0);

    let world_t_camera = rig * camera.lidar_camera;
    let model = camera_model(&camera.model);
    // Both projections agree point by point.
    for p in [Vector3::new(6.0, 0.3, 1.0), Vector3::new(8.0, -1.4, 0.2), Vector3::new(5.0, 1.0, 2.0)] {
        let theirs = camera.project(&world_t_camera, &p).unwrap();
        let ours = model.project(&world_t_camera.inverse_transform_point(&p.into()).coords).unwrap();
        assert!((theirs.0 - ours.0).abs() < 1e-9 && (theirs.1 - ours.1).abs() < 1e-9, "{theirs:?} {ours:?}");
    }

    // The robot sees the people from the side, 3 m to their left and lower down.
    let robot = Vector3::new(4.5, 3.0, 0.5);
    let people: Vec<ArPerson> = bodies
        .iter()
        .map(|b| ArPerson { points_world: surface_points(b, robot), bbox: None, age_ns: 0, pose: None })
        .collect();
    let (w, h) = (masks.width as usize, masks.height as usize);
    let ratio = |pose: &Isometry3<f64>, label: u8, person: usize, grow_px: usize| {
        let mut projected = Vec::new();
        project_people(&model, pose, &people, &mut projected);
        projected.retain(|p| p.person == person);
        // The person's own mask, grown by `grow_px` pixels (a square neighbourhood).
        let only: Vec<u8> = (0..w * h)
            .map(|i| {
                let (u, v) = (i % w, i / w);
                let near = |a: usize, n: usize| a.saturating_sub(grow_px)..(a + grow_px + 1).min(n);
                u8::from(near(v, h).any(|vv| near(u, w).any(|uu| masks.see_through[vv * w + uu] == label)))
            })
            .collect();
        mask_inlier_ratio(&projected, &only, masks.width, masks.height)
    };
    for (person, label) in [(0usize, 1u8), (1, 2)] {
        let (inside, in_image) = ratio(&world_t_camera, label, person, 0);
        let (inside_1px, _) = ratio(&world_t_camera, label, person, 1);
        eprintln!("person {label}: {inside} of {in_image} inside the mask, {inside_1px} within 1 px");
        assert!(in_image > 300, "person {label}: {in_image} points in the image");
        // Surface points project inside the silhouette, except at the rim: a mask pixel is set
        // when the ray through its centre hits, and limbs are only 3-4 px wide here. Within one
        // pixel of the mask, all of them.
        assert!(inside as f64 >= 0.88 * in_image as f64, "person {label}: {inside} of {in_image} inside");
        assert!(inside_1px as f64 >= 0.995 * in_image as f64, "person {label}: {inside_1px} of {in_image} within 1 px");
        // A camera pose 3 degrees off in yaw (about 24 px) must show as a clear drop.
        let off = world_t_camera
            * Isometry3::from_parts(Default::default(), UnitQuaternion::from_euler_angles(0.0, 0.05, 0.0));
        let (inside_off, in_image_off) = ratio(&off, label, person, 0);
        eprintln!("person {label}, pose 3 deg off: {inside_off} of {in_image_off} inside the mask");
        assert!(
            (inside_off as f64) < 0.7 * in_image_off as f64,
            "person {label}: {inside_off} of {in_image_off} with the pose off"
        );
    }

    // The rendered frame: red pixels are where the mask is (radius 0: one pixel per point).
    let cfg = RenderConfig { point_radius_px: 0, draw_boxes: false, ..RenderConfig::default() };
    let status = ArStatus { aligned: true, detection_age_ms: Some(50.0), link: "OK".into(), text: String::new() };
    let frame = render(&model, &world_t_camera, &[], &people, &status, &cfg);
    let (mut red, mut red_in_mask) = (0, 0);
    for (i, px) in frame.rgb.chunks_exact(3).enumerate() {
        if px == COLOUR_PERSON {
            red += 1;
            red_in_mask += usize::from(masks.see_through[i] > 0);
        }
    }
    eprintln!("render: {red_in_mask} of {red} red pixels in the mask");
    assert!(red > 500 && red_in_mask as f64 >= 0.88 * red as f64, "{red_in_mask} of {red} red pixels in the mask");

    // The mask files the simulator writes read back with the pipeline's decoder.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mask.png");
    write_png(&path, masks.width, masks.height, &masks.see_through).unwrap();
    let (w, h, pixels) = read_mask_png(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!((w, h), (masks.width, masks.height));
    assert_eq!(pixels, masks.see_through);
}
