//! Render time of one AR frame (`starc_pipeline::ar::render`): 640 x 480, ~20k rig points (a
//! room's walls, floor and ceiling around the responder), ~2k person points in 3 people behind a
//! wall, box wireframes and the status line on. Also the PNG encoding of the frame (what a
//! display stream or a saved frame costs on top) and the projection alone.
//!
//! Run with `cargo bench -p starc-pipeline --bench ar_render`. Each case renders 400 frames,
//! the camera swaying a little from frame to frame, and prints median and p99 of the per-frame
//! times (single thread). `AR_BENCH_PNG=frame.png` also writes the scene's frame.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use starc_pipeline::ar::{
    project_people, render, ArPerson, ArStatus, CameraModel, OrientedBox, ProjectedPoint, RenderConfig,
};
use starc_pipeline::detect::PersonPose;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// xorshift64*: every run measures the same scene.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

/// A 12 x 8 x 2.7 m room around the responder at the origin: points on the walls, floor and
/// ceiling, plus a dividing wall at x = 4 m (the one the people are behind).
fn rig_points(rng: &mut Rng, n: usize) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|i| match i % 6 {
            0 => Vector3::new(rng.range(-2.0, 10.0), rng.range(-4.0, 4.0), 0.0),
            1 => Vector3::new(rng.range(-2.0, 10.0), rng.range(-4.0, 4.0), 2.7),
            2 => Vector3::new(rng.range(-2.0, 10.0), 4.0, rng.range(0.0, 2.7)),
            3 => Vector3::new(rng.range(-2.0, 10.0), -4.0, rng.range(0.0, 2.7)),
            _ => Vector3::new(4.0, rng.range(-4.0, 4.0), rng.range(0.0, 2.7)),
        })
        .collect()
}

/// People behind the wall, standing, sitting and lying: points in a box each (length, width,
/// height).
fn people(rng: &mut Rng, per_person: usize) -> Vec<ArPerson> {
    [
        (6.0, 0.5, [0.4, 0.5, 1.75], PersonPose::Upright),
        (7.5, -1.8, [0.6, 0.5, 1.2], PersonPose::Low),
        (8.5, 2.0, [1.75, 0.5, 0.35], PersonPose::Lying),
    ]
    .iter()
    .map(|&(x, y, [l, w, h], pose)| {
        let size = Vector3::new(l, w, h);
        let centre = Vector3::new(x, y, h / 2.0);
        let points_world = (0..per_person)
            .map(|_| {
                centre
                    + Vector3::new(
                        rng.range(-l / 2.0, l / 2.0),
                        rng.range(-w / 2.0, w / 2.0),
                        rng.range(-h / 2.0, h / 2.0),
                    )
            })
            .collect();
        ArPerson {
            points_world,
            bbox: Some(OrientedBox { centre_m: centre, size_m: size, yaw_rad: 0.3 }),
            age_ns: 80_000_000,
            pose: Some(pose),
        }
    })
    .collect()
}

/// The camera at eye height looking along +x, yawed by `yaw_rad`.
fn pose(yaw_rad: f64) -> Isometry3<f64> {
    let optical = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    let optical = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(optical));
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 1.6),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_rad) * optical,
    )
}

fn percentile(sorted: &[Duration], q: f64) -> Duration {
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted.get(i).copied().unwrap_or_default()
}

fn report(name: &str, mut times: Vec<Duration>) {
    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "{name:<34} median {:7.3} ms   p99 {:7.3} ms   max {:7.3} ms   ({} frames)",
        ms(percentile(&times, 0.5)),
        ms(percentile(&times, 0.99)),
        ms(percentile(&times, 1.0)),
        times.len()
    );
}

fn main() {
    const FRAMES: usize = 400;
    let mut rng = Rng(0x05ee_da12);
    let camera = CameraModel::default();
    let rig = rig_points(&mut rng, 20_000);
    let people = people(&mut rng, 700);
    let human_points: usize = people.iter().map(|p| p.points_world.len()).sum();
    let status =
        ArStatus { aligned: true, detection_age_ms: Some(80.0), link: "OK".into(), text: "MAP 123/400".into() };
    let cfg = RenderConfig::default();
    let sway = |i: usize| 0.15 * (i as f64 * 0.05).sin();

    let mut projected: Vec<ProjectedPoint> = Vec::new();
    project_people(&camera, &pose(0.0), &people, &mut projected);
    let frame = render(&camera, &pose(0.0), &rig, &people, &status, &cfg);
    // `AR_BENCH_PNG=path` keeps the scene's frame (docs/img/ar_bench_frame.png is one).
    if let Some(path) = std::env::var_os("AR_BENCH_PNG") {
        match frame.to_png().map(|png| std::fs::write(&path, png)) {
            Ok(Ok(())) => println!("frame written to {}", path.to_string_lossy()),
            Ok(Err(e)) => println!("frame not written: {e}"),
            Err(e) => println!("frame not encoded: {e}"),
        }
    }
    let lit = frame.rgb.chunks_exact(3).filter(|px| *px != [10, 10, 14]).count();
    println!(
        "scene: {} x {}, {} rig points, {} person points ({} in view), {} of {} pixels drawn",
        camera.width,
        camera.height,
        rig.len(),
        human_points,
        projected.len(),
        lit,
        camera.width * camera.height
    );

    // Warm-up (page faults, caches), then the measured frames.
    for i in 0..20 {
        black_box(render(&camera, &pose(sway(i)), &rig, &people, &status, &cfg));
    }
    let mut render_times = Vec::with_capacity(FRAMES);
    let mut png_times = Vec::with_capacity(FRAMES);
    let mut png_bytes = 0;
    for i in 0..FRAMES {
        let t0 = Instant::now();
        let frame = render(&camera, &pose(sway(i)), &rig, &people, &status, &cfg);
        let t1 = Instant::now();
        let png = frame.to_png();
        let t2 = Instant::now();
        png_bytes = png.map(|b| b.len()).unwrap_or(0);
        render_times.push(t1 - t0);
        png_times.push(t2 - t1);
    }
    let mut project_times = Vec::with_capacity(FRAMES);
    for i in 0..FRAMES {
        projected.clear();
        let t0 = Instant::now();
        project_people(&camera, &pose(sway(i)), &people, &mut projected);
        project_times.push(t0.elapsed());
        black_box(&projected);
    }
    report("render (640x480, 20k + 2.1k pts)", render_times);
    report("to_png (fast compression)", png_times);
    report("project_people (2.1k pts)", project_times);
    println!("PNG size: {png_bytes} bytes");
}
