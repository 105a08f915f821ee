//! Drawing one AR frame: background, the rig's own points by depth, box wireframes, each
//! person's distance label or edge arrow, people in red on top, the status line.

use super::font::{draw_text, GLYPH_H};
use super::{project_people, ArFrame, ArPerson, ArStatus, CameraModel, OrientedBox, RenderConfig, NEAR_M};
use nalgebra::{Isometry3, Point3, Vector3};

/// A person with a fresh detection.
pub const COLOUR_PERSON: [u8; 3] = [255, 0, 0];
/// A person whose detection is older than `stale_after_ms`: the same hue, dimmed.
pub const COLOUR_PERSON_STALE: [u8; 3] = [128, 16, 16];
const COLOUR_BACKGROUND: [u8; 3] = [10, 10, 14];
const COLOUR_BAR: [u8; 3] = [0, 0, 0];
const COLOUR_ALIGNED: [u8; 3] = [60, 220, 90];
const COLOUR_NOT_ALIGNED: [u8; 3] = [255, 170, 0];
const COLOUR_TEXT: [u8; 3] = [225, 225, 225];
/// The rig's points: bright blue-grey when near, fading to near-background at `max_depth_m`.
const COLOUR_RIG_NEAR: [f64; 3] = [170.0, 190.0, 230.0];
const COLOUR_RIG_FAR: [f64; 3] = [30.0, 34.0, 50.0];
/// The largest square a rig point is drawn as (pixels), however near.
pub const MAX_SPLAT_PX: usize = 6;
/// No side of a frame is larger than this (a corrupt camera model must not allocate gigabytes).
const MAX_SIDE_PX: u32 = 8192;

/// The 8 corners of a box; corner `i` takes the `+` half-size along axis `k` when bit `k` of
/// `i` is set (axes: length along the heading, width, height).
pub fn box_corners(b: &OrientedBox) -> [Vector3<f64>; 8] {
    let (s, c) = b.yaw_rad.sin_cos();
    let half = b.size_m / 2.0;
    std::array::from_fn(|i| {
        let sign = |k: usize| if i & (1 << k) != 0 { 1.0 } else { -1.0 };
        let (x, y, z) = (sign(0) * half.x, sign(1) * half.y, sign(2) * half.z);
        b.centre_m + Vector3::new(c * x - s * y, s * x + c * y, z)
    })
}

/// The 12 edges of a box as pairs of [`box_corners`] indices (corners one bit apart).
pub const BOX_EDGES: [(usize, usize); 12] =
    [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)];

/// The responder's first-person frame. See the module documentation for what is drawn; when
/// `status.aligned` is false, people are not drawn (their pose in the camera is unknown) and
/// the status line says so.
pub fn render(
    camera: &CameraModel,
    world_t_camera: &Isometry3<f64>,
    rig_points_world: &[Vector3<f64>],
    people: &[ArPerson],
    status: &ArStatus,
    cfg: &RenderConfig,
) -> ArFrame {
    render_in(camera, world_t_camera, rig_points_world, &Isometry3::identity(), people, status, cfg)
}

/// [`render`] with the rig's points in a frame of their own placed at `world_t_points` (the
/// rig's odometry frame and its correction into the world), so that they are moved into the
/// camera in one step and never copied.
pub fn render_in<'a>(
    camera: &CameraModel,
    world_t_camera: &Isometry3<f64>,
    rig_points: impl IntoIterator<Item = &'a Vector3<f64>>,
    world_t_points: &Isometry3<f64>,
    people: &[ArPerson],
    status: &ArStatus,
    cfg: &RenderConfig,
) -> ArFrame {
    let (w, h) = (camera.width.min(MAX_SIDE_PX), camera.height.min(MAX_SIDE_PX));
    let mut frame = ArFrame::filled(w, h, COLOUR_BACKGROUND);
    let camera_t_world = world_t_camera.inverse();
    draw_rig_points(&mut frame, camera, &(camera_t_world * world_t_points), rig_points, cfg);
    if status.aligned {
        let colour = |p: &ArPerson| person_colour(p, cfg);
        if cfg.draw_boxes {
            for p in people {
                if let Some(b) = &p.bbox {
                    draw_box(&mut frame, camera, &camera_t_world, b, colour(p));
                }
            }
        }
        if cfg.label_people {
            super::labels::draw_people_labels(&mut frame, camera, world_t_camera, people, cfg);
        }
        let mut projected = Vec::with_capacity(people.iter().map(|p| p.points_world.len()).sum());
        project_people(camera, world_t_camera, people, &mut projected);
        // Fresh people last: where a stale overlay and a fresh one overlap, the fresh one shows.
        for stale_pass in [true, false] {
            for q in &projected {
                let c = people.get(q.person).map_or(COLOUR_PERSON, colour);
                if (c == COLOUR_PERSON_STALE) == stale_pass {
                    frame.disc(q.u, q.v, cfg.point_radius_px, c);
                }
            }
        }
    }
    draw_status(&mut frame, status, cfg);
    frame
}

/// A person's colour: red, dimmed once their detection is older than `stale_after_ms`.
pub fn person_colour(p: &ArPerson, cfg: &RenderConfig) -> [u8; 3] {
    if p.age_ns as f64 > cfg.stale_after_ms * 1e6 {
        COLOUR_PERSON_STALE
    } else {
        COLOUR_PERSON
    }
}

/// The rig's own points, nearest wins, each a square `point_size_m` wide, shaded by depth. The
/// hot loop of a frame (tens of thousands of points): a rotation matrix instead of the
/// quaternion, the shades from a table, depth in millimetres, the pixels written straight into
/// the buffers.
fn draw_rig_points<'a>(
    frame: &mut ArFrame,
    camera: &CameraModel,
    camera_t_points: &Isometry3<f64>,
    points: impl IntoIterator<Item = &'a Vector3<f64>>,
    cfg: &RenderConfig,
) {
    let (w, h) = (frame.width as usize, frame.height as usize);
    // Depth in millimetres: half the bytes of an f32 buffer, so that more of it stays in the
    // cache (the loop is memory-bound: points far apart in the list land far apart in it).
    let mut depth = vec![u16::MAX; w * h];
    let r = camera_t_points.rotation.to_rotation_matrix().into_inner();
    let t = camera_t_points.translation.vector;
    let shades = shade_table();
    let to_shade = (SHADES - 1) as f64 / cfg.shade_depth_m;
    let (wf, hf) = (w as f64, h as f64);
    let splat_m = cfg.point_size_m * camera.fx;
    for p in points {
        let z = r.m31 * p.x + r.m32 * p.y + r.m33 * p.z + t.z;
        // Also refuses NaN.
        if !(z >= NEAR_M && z <= cfg.max_depth_m) {
            continue;
        }
        let inv_z = 1.0 / z;
        let u = camera.fx * (r.m11 * p.x + r.m12 * p.y + r.m13 * p.z + t.x) * inv_z + camera.cx;
        let v = camera.fy * (r.m21 * p.x + r.m22 * p.y + r.m23 * p.z + t.y) * inv_z + camera.cy;
        if !(u >= 0.0 && u < wf && v >= 0.0 && v < hf) {
            continue;
        }
        let (x, y) = (u as usize, v as usize);
        let zf = (z * 1000.0).min(f64::from(u16::MAX - 1)) as u16;
        // Hidden at its own pixel: the whole square is (a nearer point drew over it).
        if depth.get(y * w + x).is_none_or(|d| zf >= *d) {
            continue;
        }
        let shade = shades[((z * to_shade) as usize).min(SHADES - 1)];
        let side = ((splat_m * inv_z) as usize).clamp(1, MAX_SPLAT_PX);
        let (x0, x1) = (x.saturating_sub(side / 2), (x + side.div_ceil(2)).min(w));
        for sy in y.saturating_sub(side / 2)..(y + side.div_ceil(2)).min(h) {
            let row = sy * w;
            for i in row + x0..row + x1 {
                if let (Some(d), Some(px)) = (depth.get_mut(i), frame.rgb.get_mut(3 * i..3 * i + 3)) {
                    if zf < *d {
                        *d = zf;
                        px.copy_from_slice(&shade);
                    }
                }
            }
        }
    }
}

/// Shades of the rig's points from 0 m to `shade_depth_m` (and beyond), in this many steps.
const SHADES: usize = 256;

fn shade_table() -> [[u8; 3]; SHADES] {
    std::array::from_fn(|i| {
        let t = i as f64 / (SHADES - 1) as f64;
        std::array::from_fn(|k| (COLOUR_RIG_NEAR[k] + (COLOUR_RIG_FAR[k] - COLOUR_RIG_NEAR[k]) * t) as u8)
    })
}

/// A box's 12 edges, each cut at the camera's near plane and then at the image border.
fn draw_box(
    frame: &mut ArFrame,
    camera: &CameraModel,
    camera_t_world: &Isometry3<f64>,
    b: &OrientedBox,
    colour: [u8; 3],
) {
    let corners = box_corners(b).map(|p| camera_t_world.transform_point(&Point3::from(p)).coords);
    for (i, j) in BOX_EDGES {
        let (Some(a), Some(b)) = (corners.get(i), corners.get(j)) else { continue };
        let Some((a, b)) = clip_near(*a, *b) else { continue };
        if let (Some(pa), Some(pb)) = (camera.project_unclipped(&a), camera.project_unclipped(&b)) {
            frame.line(pa, pb, colour);
        }
    }
}

/// The part of a camera-frame segment in front of the near plane.
fn clip_near(a: Vector3<f64>, b: Vector3<f64>) -> Option<(Vector3<f64>, Vector3<f64>)> {
    match (a.z >= NEAR_M, b.z >= NEAR_M) {
        (true, true) => Some((a, b)),
        (false, false) => None,
        (a_in, _) => {
            let t = (NEAR_M - a.z) / (b.z - a.z);
            let cut = a + (b - a) * t;
            let cut = Vector3::new(cut.x, cut.y, NEAR_M);
            Some(if a_in { (a, cut) } else { (cut, b) })
        }
    }
}

/// The status line across the top: alignment, detection age, link; free text (what an
/// unaligned rig waits for) on a second line, so the frame's width does not cut it off.
fn draw_status(frame: &mut ArFrame, status: &ArStatus, cfg: &RenderConfig) {
    let scale = status_scale(frame.width);
    let pad = 2 * scale;
    let line_h = GLYPH_H * scale + pad;
    let lines = if status.text.is_empty() { 1 } else { 2 };
    frame.fill_rect(0, 0, frame.width, lines * line_h + pad, COLOUR_BAR);
    let (label, colour) =
        if status.aligned { ("ALIGNED", COLOUR_ALIGNED) } else { ("NOT ALIGNED - PEOPLE HIDDEN", COLOUR_NOT_ALIGNED) };
    let x = draw_text(frame, pad, pad, scale, colour, label);
    let age = match status.detection_age_ms {
        Some(ms) if ms > cfg.stale_after_ms => format!("  DET {ms:.0} MS STALE"),
        Some(ms) => format!("  DET {ms:.0} MS"),
        None => "  DET --".to_string(),
    };
    draw_text(frame, x, pad, scale, COLOUR_TEXT, &format!("{age}  LINK {}", status.link));
    if !status.text.is_empty() {
        draw_text(frame, pad, pad + line_h, scale, COLOUR_TEXT, &status.text);
    }
}

/// Font scale of the status line: 2 on frames at least 400 px wide, else 1.
pub(crate) fn status_scale(width: u32) -> u32 {
    if width >= 400 {
        2
    } else {
        1
    }
}
