//! Where each person is, at a glance: a label with their distance, posture (and, once their
//! detection is stale, its age) over each person in view, and an arrow at the frame's edge, with the
//! distance, for each person outside it (behind the responder, or off to a side).

use super::font::{draw_text, ADVANCE, GLYPH_H};
use super::render::person_colour;
use super::{ArFrame, ArPerson, CameraModel, RenderConfig};
use crate::detect::PersonPose;
use nalgebra::{Isometry3, Point3, Vector3};

/// Labels: light text on a dark plate, readable over the rig's points and the red overlay.
pub const COLOUR_LABEL: [u8; 3] = [255, 236, 160];
const COLOUR_PLATE: [u8; 3] = [0, 0, 0];
/// Arrow length and half width, and how far in from the frame's edge it sits (pixels).
const ARROW_LEN_PX: f64 = 14.0;
const ARROW_HALF_PX: f64 = 7.0;
const EDGE_INSET_PX: f64 = 18.0;

/// Where a person is: their box's centre, or the mean of their points; `None` without either.
pub fn anchor(p: &ArPerson) -> Option<Vector3<f64>> {
    if let Some(b) = &p.bbox {
        return Some(b.centre_m);
    }
    let n = p.points_world.len();
    (n > 0).then(|| p.points_world.iter().sum::<Vector3<f64>>() / n as f64)
}

/// The top of a person above their anchor: the box's top, or their highest point.
fn top(p: &ArPerson, anchor: &Vector3<f64>) -> Vector3<f64> {
    let z = match &p.bbox {
        Some(b) => b.centre_m.z + b.size_m.z / 2.0,
        None => p.points_world.iter().map(|q| q.z).fold(anchor.z, f64::max),
    };
    Vector3::new(anchor.x, anchor.y, z)
}

/// "4.2 M", then the posture when it is known ("4.2 M LYING"), then the age once the detection
/// is older than `stale_ns` ("4.2 M LYING 3.5 S").
pub fn label_text(distance_m: f64, pose: Option<PersonPose>, age_ns: u64, stale_ns: f64) -> String {
    let mut text = format!("{distance_m:.1} M");
    if let Some(pose) = pose {
        text.push(' ');
        text.push_str(posture_word(pose));
    }
    if age_ns as f64 > stale_ns {
        text.push_str(&format!(" {:.1} S", age_ns as f64 * 1e-9));
    }
    text
}

/// The posture as the label shows it: one word a responder reads at a glance (`Low` covers
/// sitting and crouching, which the detector does not tell apart).
pub fn posture_word(pose: PersonPose) -> &'static str {
    match pose {
        PersonPose::Upright => "STANDING",
        PersonPose::Low => "SITTING",
        PersonPose::Lying => "LYING",
    }
}

/// Each person's label (in view) or edge arrow (out of view, in the person's colour).
pub fn draw_people_labels(
    frame: &mut ArFrame,
    camera: &CameraModel,
    world_t_camera: &Isometry3<f64>,
    people: &[ArPerson],
    cfg: &RenderConfig,
) {
    let stale_ns = cfg.stale_after_ms * 1e6;
    let camera_t_world = world_t_camera.inverse();
    let scale = super::render::status_scale(frame.width);
    for p in people {
        let Some(a) = anchor(p) else { continue };
        let c = camera_t_world.transform_point(&Point3::from(a)).coords;
        let text = label_text(c.norm(), p.pose, p.age_ns, stale_ns);
        match camera.project(&c) {
            Some((u, v)) => {
                // Over the person's head where that is in view, else over their middle; and above
                // their whole box on screen (a lying person seen from above reaches higher in the
                // image than the top of their box's centre), so the label hides none of them.
                let head = camera_t_world.transform_point(&Point3::from(top(p, &a))).coords;
                let (u, v) = camera.project(&head).unwrap_or((u, v));
                let v = box_top_px(camera, &camera_t_world, p).map_or(v, |top| top.min(v));
                let (_, h) = text_size(&text, scale);
                plate_text(frame, u, v - h - 6.0, scale, &text);
            }
            None => {
                let (tip, dir) = edge_point(frame, camera, &c);
                draw_arrow(frame, tip, dir, person_colour(p, cfg));
                // The distance just inside the arrow's base, clear of it.
                let (w, h) = text_size(&text, scale);
                let centre =
                    (tip.0 - dir.0 * (ARROW_LEN_PX + w / 2.0 + 6.0), tip.1 - dir.1 * (ARROW_LEN_PX + h / 2.0 + 6.0));
                plate_text(frame, centre.0, centre.1 - h / 2.0, scale, &text);
            }
        }
    }
}

/// The highest row (smallest v) of a person's box on screen, when every corner is in front of
/// the camera.
fn box_top_px(camera: &CameraModel, camera_t_world: &Isometry3<f64>, p: &ArPerson) -> Option<f64> {
    let corners = super::box_corners(p.bbox.as_ref()?);
    corners.iter().try_fold(f64::INFINITY, |top, c| {
        let c = camera_t_world.transform_point(&Point3::from(*c)).coords;
        let (_, v) = camera.project_unclipped(&c)?;
        Some(top.min(v))
    })
}

/// Where the arrow to an out-of-view point sits (just inside the frame's edge) and the unit
/// direction it points in the image.
fn edge_point(frame: &ArFrame, camera: &CameraModel, c: &Vector3<f64>) -> ((f64, f64), (f64, f64)) {
    let (w, h) = (f64::from(frame.width), f64::from(frame.height));
    let (cx, cy) = (w / 2.0, h / 2.0);
    // In front: the direction of the projection. Beside or behind (a point behind the camera
    // projects mirrored): its x, y, and the farther behind, the more downward ("turn around").
    let (mut dx, mut dy) = match camera.project_unclipped(c) {
        Some((u, v)) => (u - cx, v - cy),
        None => (c.x, c.y.max(0.0) + (-c.z).max(0.0)),
    };
    let n = dx.hypot(dy);
    if !(n.is_finite() && n > 1e-9) {
        (dx, dy) = (0.0, 1.0);
    } else {
        (dx, dy) = (dx / n, dy / n);
    }
    let (half_w, half_h) = (cx - EDGE_INSET_PX, cy - EDGE_INSET_PX);
    let t = (half_w / dx.abs().max(1e-9)).min(half_h / dy.abs().max(1e-9));
    ((cx + dx * t, cy + dy * t), (dx, dy))
}

/// A filled triangle with its tip at `tip`, pointing along `dir`.
fn draw_arrow(frame: &mut ArFrame, tip: (f64, f64), dir: (f64, f64), colour: [u8; 3]) {
    let base = (tip.0 - dir.0 * ARROW_LEN_PX, tip.1 - dir.1 * ARROW_LEN_PX);
    let side = (-dir.1 * ARROW_HALF_PX, dir.0 * ARROW_HALF_PX);
    let (b1, b2) = ((base.0 + side.0, base.1 + side.1), (base.0 - side.0, base.1 - side.1));
    // Lines from the tip to each point of the base fill it.
    let steps = (2.0 * ARROW_HALF_PX) as i32 * 2;
    for k in 0..=steps {
        let f = f64::from(k) / f64::from(steps);
        let q = (b1.0 + (b2.0 - b1.0) * f, b1.1 + (b2.1 - b1.1) * f);
        frame.line(tip, q, colour);
    }
}

/// Width and height of `text` at `scale`, pixels.
fn text_size(text: &str, scale: u32) -> (f64, f64) {
    (f64::from(text.chars().count() as u32 * ADVANCE * scale), f64::from(GLYPH_H * scale))
}

/// `text` centred on `u`, its top at `v`, on a dark plate; kept inside the frame.
fn plate_text(frame: &mut ArFrame, u: f64, v: f64, scale: u32, text: &str) {
    let (w, h) = text_size(text, scale);
    let (width, height) = (w as u32, h as u32);
    let max_x = frame.width.saturating_sub(width + 2);
    let max_y = frame.height.saturating_sub(height + 2);
    let x = ((u - f64::from(width) / 2.0).max(2.0) as u32).min(max_x);
    let y = (v.max(2.0) as u32).min(max_y);
    frame.fill_rect(x.saturating_sub(2), y.saturating_sub(2), width + 4, height + 4, COLOUR_PLATE);
    draw_text(frame, x, y, scale, COLOUR_LABEL, text);
}
