#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::font::{draw_text, glyph, ADVANCE, GLYPH_H, GLYPH_W};
use super::*;
use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};

/// The camera 1.5 m above the world origin, looking along world +x (optical x = world -y,
/// optical y = world -z).
fn camera_pose() -> Isometry3<f64> {
    let r = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.5), q)
}

fn aligned() -> ArStatus {
    ArStatus { aligned: true, detection_age_ms: Some(40.0), link: "OK".into(), text: String::new() }
}

fn person_at(points: &[[f64; 3]], age_ns: u64) -> ArPerson {
    ArPerson {
        points_world: points.iter().map(|p| Vector3::new(p[0], p[1], p[2])).collect(),
        bbox: None,
        age_ns,
        pose: None,
    }
}

fn count(frame: &ArFrame, colour: [u8; 3]) -> usize {
    frame.rgb.chunks_exact(3).filter(|px| *px == colour).count()
}

#[test]
fn projects_known_points() {
    let cam = CameraModel::default();
    assert_eq!(cam.project(&Vector3::new(0.0, 0.0, 5.0)), Some((320.0, 240.0)));
    assert_eq!(cam.project(&Vector3::new(1.0, -0.5, 2.0)), Some((550.0, 125.0)));
    // Behind, too near, not a number.
    assert_eq!(cam.project(&Vector3::new(0.0, 0.0, -3.0)), None);
    assert_eq!(cam.project(&Vector3::new(0.0, 0.0, 0.04)), None);
    assert_eq!(cam.project(&Vector3::new(f64::NAN, 0.0, 2.0)), None);
    // Outside the image: right, below, and exactly on the right border (pixel 640 does not exist).
    assert_eq!(cam.project(&Vector3::new(10.0, 0.0, 1.0)), None);
    assert_eq!(cam.project(&Vector3::new(0.0, 3.0, 1.0)), None);
    assert_eq!(cam.project(&Vector3::new(320.0 / 460.0, 0.0, 1.0)), None);
    assert!(cam.project(&Vector3::new(319.9 / 460.0, 0.0, 1.0)).is_some());
}

#[test]
fn projects_people_through_the_camera_pose() {
    let cam = CameraModel::default();
    let people =
        [person_at(&[[5.0, 0.0, 1.5], [5.0, -1.0, 1.5], [-5.0, 0.0, 1.5]], 0), person_at(&[[4.0, 0.0, 2.5]], 0)];
    let mut out = Vec::new();
    project_people(&cam, &camera_pose(), &people, &mut out);
    // The point behind the camera is dropped.
    assert_eq!(out.len(), 3, "{out:?}");
    assert_eq!(out[0], ProjectedPoint { u: 320.0, v: 240.0, depth_m: 5.0, person: 0 });
    // World -y is to the right, world +z is up.
    assert!((out[1].u - 412.0).abs() < 1e-9 && (out[1].v - 240.0).abs() < 1e-9, "{:?}", out[1]);
    assert!((out[2].u - 320.0).abs() < 1e-9 && (out[2].v - 125.0).abs() < 1e-9 && out[2].person == 1, "{:?}", out[2]);
}

#[test]
fn a_person_behind_a_wall_is_drawn_red_on_top() {
    let cam = CameraModel::default();
    // A wall of rig points 3 m ahead, the person 5 m ahead: the person must still show.
    let wall: Vec<_> = (-20..=20)
        .flat_map(|i| (-20..=20).map(move |j| Vector3::new(3.0, f64::from(i) * 0.02, 1.5 + f64::from(j) * 0.02)))
        .collect();
    let people = [person_at(&[[5.0, 0.0, 1.5], [5.0, -1.0, 1.0]], 0)];
    let cfg = RenderConfig::default();
    let frame = render(&cam, &camera_pose(), &wall, &people, &aligned(), &cfg);
    assert_eq!(frame.pixel(320, 240), Some(COLOUR_PERSON));
    // Point radius 2: the disc reaches 2 px out, not 3.
    assert_eq!(frame.pixel(322, 240), Some(COLOUR_PERSON));
    assert_ne!(frame.pixel(323, 240), Some(COLOUR_PERSON));
    // Second point: u = 320 + 460 / 5, v = 240 + 460 * 0.5 / 5.
    assert_eq!(frame.pixel(412, 286), Some(COLOUR_PERSON));
    // The wall is drawn around the person, in the rig's blue-grey (blue dominant).
    // Wall point (3, -0.06, 1.44): u = 320 + 460 * 0.06 / 3, v = 240 + 460 * 0.06 / 3.
    let wall_px = frame.pixel(329, 249).unwrap();
    assert!(wall_px[2] > wall_px[0] && wall_px[2] > 100, "{wall_px:?}");
    // Two discs of radius 2 (dx^2 + dy^2 <= 6: 21 pixels each).
    assert_eq!(count(&frame, COLOUR_PERSON), 42);
}

#[test]
fn box_wireframe_lands_on_the_projected_edges() {
    let cam = CameraModel::default();
    let bbox = OrientedBox { centre_m: Vector3::new(5.0, 0.0, 1.5), size_m: Vector3::new(0.5, 1.0, 1.0), yaw_rad: 0.0 };
    let people = [ArPerson { points_world: Vec::new(), bbox: Some(bbox), age_ns: 0, pose: None }];
    let frame = render(&cam, &camera_pose(), &[], &people, &aligned(), &RenderConfig::default());
    // Front face at 4.75 m: vertical edges at u = 320 +- 460 * 0.5 / 4.75 = 320 +- 48.42.
    assert_eq!(frame.pixel(368, 240), Some(COLOUR_PERSON));
    assert_eq!(frame.pixel(271, 240), Some(COLOUR_PERSON));
    // Back face at 5.25 m: u = 320 + 43.81.
    assert_eq!(frame.pixel(363, 240), Some(COLOUR_PERSON));
    // Top edge of the front face: v = 240 - 48.42.
    assert_eq!(frame.pixel(320, 191), Some(COLOUR_PERSON));
    // Inside the box nothing is drawn.
    assert_ne!(frame.pixel(320, 240), Some(COLOUR_PERSON));
    // Off when configured off.
    let cfg = RenderConfig { draw_boxes: false, ..RenderConfig::default() };
    let frame = render(&cam, &camera_pose(), &[], &people, &aligned(), &cfg);
    assert_eq!(count(&frame, COLOUR_PERSON), 0);
}

#[test]
fn a_box_around_the_camera_is_clipped_without_panicking() {
    let cam = CameraModel::default();
    let bbox = OrientedBox { centre_m: Vector3::new(0.0, 0.0, 1.5), size_m: Vector3::new(4.0, 4.0, 2.0), yaw_rad: 0.7 };
    let far = OrientedBox { centre_m: Vector3::new(1e9, -1e9, 1.5), size_m: Vector3::new(1.0, 1.0, 1.0), yaw_rad: 0.0 };
    let people = [
        ArPerson { points_world: vec![], bbox: Some(bbox), age_ns: 0, pose: None },
        ArPerson { points_world: vec![], bbox: Some(far), age_ns: 0, pose: None },
    ];
    let frame = render(&cam, &camera_pose(), &[], &people, &aligned(), &RenderConfig::default());
    // The walls of the box in front of the camera are visible.
    assert!(count(&frame, COLOUR_PERSON) > 100);
}

#[test]
fn stale_people_are_dimmed() {
    let cam = CameraModel::default();
    let cfg = RenderConfig::default();
    let people = [person_at(&[[5.0, 0.0, 1.5]], 600_000_000), person_at(&[[5.0, -1.0, 1.5]], 100_000_000)];
    let frame = render(&cam, &camera_pose(), &[], &people, &aligned(), &cfg);
    assert_eq!(frame.pixel(320, 240), Some(COLOUR_PERSON_STALE));
    assert_eq!(frame.pixel(412, 240), Some(COLOUR_PERSON));
}

#[test]
fn people_are_not_drawn_when_not_aligned() {
    let cam = CameraModel::default();
    let bbox = OrientedBox { centre_m: Vector3::new(5.0, 0.0, 1.5), size_m: Vector3::new(0.5, 1.0, 1.0), yaw_rad: 0.0 };
    let people =
        [ArPerson { points_world: vec![Vector3::new(5.0, 0.0, 1.5)], bbox: Some(bbox), age_ns: 0, pose: None }];
    let rig = [Vector3::new(3.0, 0.2, 1.45)];
    let status = ArStatus { aligned: false, detection_age_ms: None, link: "OK".into(), text: "ICP RMS 0.31 M".into() };
    let frame = render(&cam, &camera_pose(), &rig, &people, &status, &RenderConfig::default());
    assert_eq!(count(&frame, COLOUR_PERSON), 0);
    assert_eq!(count(&frame, COLOUR_PERSON_STALE), 0);
    // The rig's own points are still drawn: u = 320 - 460 * 0.2 / 3 = 289.3, v = 247.7.
    assert_ne!(frame.pixel(289, 247), frame.pixel(100, 400));
    // The status line is in the warning colour.
    let orange = [255, 170, 0];
    assert!(count(&frame, orange) > 50);
    let ok = render(&cam, &camera_pose(), &rig, &people, &aligned(), &RenderConfig::default());
    assert_eq!(count(&ok, orange), 0);
}

#[test]
fn glyphs_are_drawn_bit_for_bit() {
    let mut frame = ArFrame::filled(40, 10, [0, 0, 0]);
    let end = draw_text(&mut frame, 1, 1, 1, [255, 255, 255], "A7");
    assert_eq!(end, 1 + 2 * ADVANCE);
    for (k, c) in ['A', '7'].into_iter().enumerate() {
        for row in 0..GLYPH_H {
            for col in 0..GLYPH_W {
                let on = glyph(c)[row as usize] & (1 << (GLYPH_W - 1 - col)) != 0;
                let px = frame.pixel(1 + k as u32 * ADVANCE + col, 1 + row).unwrap();
                assert_eq!(px == [255, 255, 255], on, "{c} row {row} col {col}");
            }
        }
    }
    // Lower case is drawn as upper case; every character the status line needs has its own glyph.
    assert_eq!(glyph('a'), glyph('A'));
    let unknown = glyph('~');
    for c in "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 .:-%/()_".chars() {
        assert_ne!(glyph(c), unknown, "{c}");
    }
    // Text past the right edge is dropped, not wrapped or panicking.
    draw_text(&mut frame, 30, 1, 3, [255, 0, 0], "WWWW");
}

#[test]
fn status_line_shows_its_fields() {
    let cam = CameraModel::default();
    let cfg = RenderConfig::default();
    let text_px = [225, 225, 225];
    // One line of 22 rows; free text goes on a second line (40 rows).
    let rows = |status: &ArStatus| if status.text.is_empty() { 22 } else { 40 };
    let bar = |frame: &ArFrame, rows: usize| -> Vec<u8> { frame.rgb[..640 * rows * 3].to_vec() };
    let base = render(&cam, &camera_pose(), &[], &[], &aligned(), &cfg);
    // "ALIGNED" in green, the rest in light grey.
    assert!(count(&base, [60, 220, 90]) > 100);
    assert!(count(&base, text_px) > 200);
    // Every field changes the pixels of the bar, and nothing but the bar.
    let variants = [
        ArStatus { detection_age_ms: Some(41.0), ..aligned() },
        ArStatus { detection_age_ms: None, ..aligned() },
        ArStatus { link: "LOST".into(), ..aligned() },
        ArStatus { text: "MAP 12/40".into(), ..aligned() },
    ];
    for status in variants {
        let other = render(&cam, &camera_pose(), &[], &[], &status, &cfg);
        let rows = rows(&status);
        assert_ne!(bar(&other, rows), bar(&base, rows), "{status:?}");
        assert_eq!(other.rgb[640 * rows * 3..], base.rgb[640 * rows * 3..]);
    }
}

#[test]
fn png_round_trip() {
    let cam = CameraModel { width: 64, height: 48, fx: 50.0, fy: 50.0, cx: 32.0, cy: 24.0 };
    let people = [person_at(&[[5.0, 0.0, 1.5]], 0)];
    let frame =
        render(&cam, &camera_pose(), &[Vector3::new(3.0, 0.5, 1.0)], &people, &aligned(), &RenderConfig::default());
    let bytes = frame.to_png().unwrap();
    let mut reader = png::Decoder::new(bytes.as_slice()).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.width, info.height, info.color_type), (64, 48, png::ColorType::Rgb));
    assert_eq!(&buf[..info.buffer_size()], frame.rgb.as_slice());
    assert_eq!(frame.pixel(32, 24), Some(COLOUR_PERSON));
    assert_eq!(frame.pixel(64, 0), None);
}

fn grey_png(width: u32, height: u32, pixels: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, width, height);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().unwrap();
    w.write_image_data(pixels).unwrap();
    w.finish().unwrap();
    out
}

#[test]
fn mask_png_reads_back_and_bad_bytes_are_errors() {
    let pixels: Vec<u8> = (0..7 * 5).map(|i| (i * 7) as u8).collect();
    let bytes = grey_png(7, 5, &pixels);
    assert_eq!(read_mask_png(&bytes).unwrap(), (7, 5, pixels));
    // Truncated, corrupted, empty.
    for cut in [0, 8, 20, 40, bytes.len() / 2] {
        assert!(read_mask_png(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    let mut flipped = bytes.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x55;
    assert!(read_mask_png(&flipped).is_err());
    // An RGB image is not a label mask.
    let rgb = ArFrame::filled(4, 4, [1, 2, 3]).to_png().unwrap();
    assert!(matches!(read_mask_png(&rgb), Err(crate::PipelineError::Unsupported { .. })));
}

#[test]
fn mask_inlier_ratio_counts_points_in_the_mask() {
    let (w, h) = (20u32, 10u32);
    // A person occupies columns 5..10, rows 2..8.
    let mask: Vec<u8> =
        (0..h).flat_map(|v| (0..w).map(move |u| u8::from((5..10).contains(&u) && (2..8).contains(&v)))).collect();
    let p = |u: f64, v: f64| ProjectedPoint { u, v, depth_m: 3.0, person: 0 };
    let points =
        [p(5.0, 2.0), p(9.99, 7.99), p(7.5, 5.5), p(10.0, 5.0), p(4.99, 5.0), p(0.0, 0.0), p(25.0, 5.0), p(-0.5, 1.0)];
    assert_eq!(mask_inlier_ratio(&points, &mask, w, h), (3, 6));
    // A mask shorter than promised: missing pixels are unset, nothing panics.
    // Only row 0, row 1 and half of row 2 remain: the first point (index 45) is still inside.
    assert_eq!(mask_inlier_ratio(&points, &mask[..50], w, h), (1, 6));
}

#[test]
fn shipped_config_is_the_default() {
    let shipped = RenderConfig::from_toml(include_str!("../../../config/ar.toml")).unwrap();
    assert_eq!(shipped, RenderConfig::default());
    assert!(RenderConfig::from_toml("draw_box = true").is_err());
    assert!(RenderConfig::from_toml("max_depth_m = 0.0").is_err());
    assert!(RenderConfig::from_toml("stale_after_ms = -1.0").is_err());
    assert_eq!(RenderConfig::from_toml("").unwrap(), RenderConfig::default());
    assert!(CameraModel::default().validate().is_ok());
    assert!(CameraModel { fx: 0.0, ..CameraModel::default() }.validate().is_err());
    assert!(toml::from_str::<CameraModel>("width = 1\nheight = 1\nfx = 1.0\nfy = 1.0\ncx = 0.0\ncy = 0.0\nk1 = 0.1")
        .is_err());
}

#[test]
fn label_text_gives_the_distance_the_posture_and_a_stale_age() {
    use super::labels::label_text;
    use crate::detect::PersonPose;
    assert_eq!(label_text(4.96, None, 100_000_000, 500e6), "5.0 M");
    assert_eq!(label_text(12.34, None, 2_100_000_000, 500e6), "12.3 M 2.1 S");
    assert_eq!(label_text(3.0, Some(PersonPose::Lying), 0, 500e6), "3.0 M LYING");
    assert_eq!(label_text(3.0, Some(PersonPose::Low), 900_000_000, 500e6), "3.0 M SITTING 0.9 S");
    assert_eq!(label_text(3.0, Some(PersonPose::Upright), 0, 500e6), "3.0 M STANDING");
}

/// The label plate's text pixels above a person in view, and none with labels off.
#[test]
fn a_person_in_view_is_labelled_with_their_distance() {
    use super::labels::COLOUR_LABEL;
    let cam = CameraModel::default();
    let bbox = OrientedBox { centre_m: Vector3::new(5.0, 0.0, 1.5), size_m: Vector3::new(0.5, 0.5, 1.8), yaw_rad: 0.0 };
    let people = [ArPerson { points_world: vec![], bbox: Some(bbox), age_ns: 0, pose: None }];
    let frame = render(&cam, &camera_pose(), &[], &people, &aligned(), &RenderConfig::default());
    // "5.0 M" at scale 2, centred on u = 320, just over the box's top (z 2.4 m: v = 240 - 460 *
    // 0.9 / 5 = 157): text rows 137-151.
    let label: usize = (130..160)
        .flat_map(|v| (280..360).map(move |u| (u, v)))
        .filter(|&(u, v)| frame.pixel(u, v) == Some(COLOUR_LABEL))
        .count();
    assert!(label > 40, "{label} label pixels");
    assert_eq!(count(&frame, COLOUR_LABEL), label, "label pixels elsewhere");
    let cfg = RenderConfig { label_people: false, ..RenderConfig::default() };
    let frame = render(&cam, &camera_pose(), &[], &people, &aligned(), &cfg);
    assert_eq!(count(&frame, COLOUR_LABEL), 0);
}

/// A person lying on the floor 4-6 m ahead, seen from eye height: their far end is higher on
/// screen than the top of their box's centre, and the label still sits above all of them.
#[test]
fn a_lying_persons_label_sits_above_their_whole_body() {
    use super::labels::COLOUR_LABEL;
    use crate::detect::PersonPose;
    let cam = CameraModel::default();
    let bbox = OrientedBox { centre_m: Vector3::new(5.0, 0.0, 0.2), size_m: Vector3::new(1.8, 0.5, 0.4), yaw_rad: 0.0 };
    let points: Vec<Vector3<f64>> = (0..=18)
        .flat_map(|i| (0..=4).map(move |k| Vector3::new(4.1 + 0.1 * f64::from(i), 0.0, 0.1 * f64::from(k))))
        .collect();
    let person = ArPerson { points_world: points, bbox: Some(bbox), age_ns: 0, pose: Some(PersonPose::Lying) };
    let cfg = RenderConfig { draw_boxes: false, ..RenderConfig::default() };
    let frame = render(&cam, &camera_pose(), &[], &[person], &aligned(), &cfg);
    let frame = &frame;
    let rows_of =
        |colour| (0..frame.height).filter(move |&v| (0..frame.width).any(|u| frame.pixel(u, v) == Some(colour)));
    let body_top = rows_of(COLOUR_PERSON).min().unwrap();
    let label_bottom = rows_of(COLOUR_LABEL).max().unwrap();
    // The far end's top (5.9 m, 0.4 m high) is at v = 240 + 460 * 1.1 / 5.9 = 326; the box
    // centre's top at 341.
    assert!((320..330).contains(&body_top), "body from row {body_top}");
    assert!(label_bottom < body_top, "label down to row {label_bottom}, body from row {body_top}");
}

/// A person to the responder's left (world +y) gets an arrow at the left edge; one behind gets
/// one too, and nothing is drawn in the middle of the frame.
#[test]
fn people_out_of_view_get_an_arrow_at_the_edge() {
    use super::labels::COLOUR_LABEL;
    let cam = CameraModel::default();
    let left = person_at(&[[0.0, 5.0, 1.5]], 0);
    let frame = render(&cam, &camera_pose(), &[], &[left], &aligned(), &RenderConfig::default());
    let arrow_left = (0..40)
        .flat_map(|u| (200..280).map(move |v| (u, v)))
        .filter(|&(u, v)| frame.pixel(u, v) == Some(COLOUR_PERSON))
        .count();
    assert!(arrow_left > 50, "{arrow_left} arrow pixels at the left edge");
    assert_eq!(frame.pixel(320, 240), Some([10, 10, 14]));
    assert!(count(&frame, COLOUR_LABEL) > 20, "the distance beside the arrow");
    // Behind: the arrow at the bottom edge, pointing down (turn around).
    let behind = person_at(&[[-5.0, 0.0, 1.5]], 0);
    let frame = render(&cam, &camera_pose(), &[], &[behind], &aligned(), &RenderConfig::default());
    let arrow_bottom = (280..360)
        .flat_map(|u| (440..480).map(move |v| (u, v)))
        .filter(|&(u, v)| frame.pixel(u, v) == Some(COLOUR_PERSON))
        .count();
    assert!(arrow_bottom > 50, "{arrow_bottom} arrow pixels at the bottom edge");
    assert_eq!(frame.pixel(320, 240), Some([10, 10, 14]));
}

/// A near rig point is drawn as a square (`point_size_m` wide in the world, at most
/// `MAX_SPLAT_PX`), a far one as one pixel; nearer points win where squares overlap.
#[test]
fn rig_points_are_squares_that_shrink_with_depth() {
    use super::render::MAX_SPLAT_PX;
    let cam = CameraModel::default();
    let background = [10, 10, 14];
    let drawn = |points: &[Vector3<f64>]| {
        let frame = render(&cam, &camera_pose(), points, &[], &aligned(), &RenderConfig::default());
        frame.rgb.chunks_exact(3).skip(640 * 30).filter(|px| *px != background).count()
    };
    // 1 m ahead: 0.04 * 460 / 1 = 18 px, capped.
    assert_eq!(drawn(&[Vector3::new(1.0, 0.0, 1.5)]), MAX_SPLAT_PX * MAX_SPLAT_PX);
    // 9.2 m: 2 px; 20 m: 1 px.
    assert_eq!(drawn(&[Vector3::new(9.2, 0.0, 1.5)]), 4);
    assert_eq!(drawn(&[Vector3::new(20.0, 0.0, 1.5)]), 1);
    let near_over_far = render(
        &cam,
        &camera_pose(),
        &[Vector3::new(20.0, 0.0, 1.5), Vector3::new(1.0, 0.0, 1.5)],
        &[],
        &aligned(),
        &RenderConfig::default(),
    );
    let far_shade =
        render(&cam, &camera_pose(), &[Vector3::new(20.0, 0.0, 1.5)], &[], &aligned(), &RenderConfig::default());
    assert_ne!(near_over_far.pixel(320, 240), far_shade.pixel(320, 240));
}
