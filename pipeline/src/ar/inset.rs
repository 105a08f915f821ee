//! A top-down map in a corner of the responder's view: the robot's map around the responder
//! (walls at the responder's height), heading-up, with the responder at the centre and each
//! person as a dot, so the way to them shows at a glance.

use super::labels::anchor;
use super::render::person_colour;
use super::{ArFrame, ArPerson, RenderConfig};
use nalgebra::{Isometry3, Vector3};
use std::sync::Arc;

/// Heights a cell records: 16 slices of 0.25 m from the map's lowest point (4 m).
const SLICES: usize = 16;
const SLICE_M: f64 = 0.25;
/// A raster holds at most this many cells (about 200 x 200 m at 0.1 m); a larger map is
/// rasterised coarser.
const MAX_CELLS: usize = 4_000_000;
/// The inset's height band around the rig (a helmet at 1.7 m or a hand at 1.2 m above the
/// floor: from 0.1-0.6 m above the floor to 1.5-2.0 m).
const BAND_BELOW_M: f64 = 1.1;
const BAND_ABOVE_M: f64 = 0.3;
const COLOUR_INSET_BACKGROUND: [u8; 3] = [0, 0, 0];
const COLOUR_INSET_WALL: [u8; 3] = [150, 160, 180];
const COLOUR_INSET_FRAME: [u8; 3] = [90, 90, 100];
const COLOUR_RESPONDER: [u8; 3] = [60, 220, 90];
/// The robot in the inset.
pub const COLOUR_ROBOT: [u8; 3] = [80, 150, 255];

/// The robot's map seen from above: per cell, which height slices hold a point.
pub struct MapRaster {
    cell_m: f64,
    x0: f64,
    y0: f64,
    z0: f64,
    width: usize,
    height: usize,
    slices: Vec<u16>,
}

impl MapRaster {
    /// `points` (world frame) at `cell_m` per cell (coarser where the map is too large); `None`
    /// for no finite point.
    pub fn from_points(points: &[Vector3<f64>], cell_m: f64) -> Option<Self> {
        let finite = || points.iter().filter(|p| p.iter().all(|v| v.is_finite()));
        let (mut lo, mut hi) = (Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY));
        for p in finite() {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if !lo.x.is_finite() {
            return None;
        }
        let mut cell_m = cell_m.max(0.01);
        let cells = |c: f64| (((hi.x - lo.x) / c) as usize + 1).saturating_mul(((hi.y - lo.y) / c) as usize + 1);
        while cells(cell_m) > MAX_CELLS {
            cell_m *= 2.0;
        }
        let (width, height) = (((hi.x - lo.x) / cell_m) as usize + 1, ((hi.y - lo.y) / cell_m) as usize + 1);
        let mut raster = Self { cell_m, x0: lo.x, y0: lo.y, z0: lo.z, width, height, slices: vec![0; width * height] };
        for p in finite() {
            let slice = ((p.z - lo.z) / SLICE_M) as usize;
            if let (Some(i), true) = (raster.index(p.x, p.y), slice < SLICES) {
                if let Some(c) = raster.slices.get_mut(i) {
                    *c |= 1 << slice;
                }
            }
        }
        Some(raster)
    }

    fn index(&self, x: f64, y: f64) -> Option<usize> {
        let (fx, fy) = ((x - self.x0) / self.cell_m, (y - self.y0) / self.cell_m);
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (ix, iy) = (fx as usize, fy as usize);
        (ix < self.width && iy < self.height).then(|| iy * self.width + ix)
    }

    /// The slices from `z_lo` to `z_hi` as a mask.
    fn band(&self, z_lo: f64, z_hi: f64) -> u16 {
        let slice = |z: f64| ((z - self.z0) / SLICE_M).floor().clamp(0.0, (SLICES - 1) as f64) as u32;
        let (a, b) = (slice(z_lo), slice(z_hi));
        (a..=b).fold(0u16, |m, s| m | (1 << s))
    }

    /// Whether the map holds a point in the cell at (x, y) within the band mask.
    fn occupied(&self, x: f64, y: f64, band: u16) -> bool {
        self.index(x, y).and_then(|i| self.slices.get(i)).is_some_and(|s| s & band != 0)
    }
}

/// Cell of the map's top-down raster.
const INSET_CELL_M: f64 = 0.1;

/// What the inset draws besides the responder and the people: the robot's map, rasterised
/// when it changes and only while an inset is drawn, and the robot's newest position.
#[derive(Default)]
pub struct MapInset {
    raster: Option<MapRaster>,
    /// The map the raster was made of (compared by pointer: the rig core hands over a new one
    /// whenever the robot's map changed).
    raster_of: Option<Arc<Vec<Vector3<f64>>>>,
    robot: Option<Vector3<f64>>,
}

impl MapInset {
    /// The robot's newest pose (its LiDAR in its world); a non-finite one is ignored.
    pub fn set_robot_pose(&mut self, world_t_lidar: &Isometry3<f64>) {
        let p = world_t_lidar.translation.vector;
        if p.iter().all(|v| v.is_finite()) {
            self.robot = Some(p);
        }
    }

    /// Draws the inset (`cfg.inset_px`; 0: nothing) for a responder at `world_t_rig`, with the
    /// robot's `map` (world frame) and `people`.
    pub fn draw(
        &mut self,
        frame: &mut ArFrame,
        map: &Arc<Vec<Vector3<f64>>>,
        world_t_rig: &Isometry3<f64>,
        people: &[ArPerson],
        cfg: &RenderConfig,
    ) {
        if cfg.inset_px == 0 {
            return;
        }
        if !self.raster_of.as_ref().is_some_and(|m| Arc::ptr_eq(m, map)) {
            self.raster = MapRaster::from_points(map, INSET_CELL_M);
            self.raster_of = Some(Arc::clone(map));
        }
        let dots: Vec<_> = people.iter().filter_map(|p| anchor(p).map(|a| (a, person_colour(p, cfg)))).collect();
        let layout = InsetLayout { side_px: cfg.inset_px, range_m: cfg.inset_range_m, north_up: cfg.inset_north_up };
        let robot = self.robot.map(|p| (p, COLOUR_ROBOT));
        draw_inset(frame, self.raster.as_ref(), world_t_rig, &dots, robot, layout);
    }
}

/// Where the inset goes and what it shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InsetLayout {
    /// Side of the inset, pixels (0: none).
    pub side_px: u32,
    /// From the centre to the inset's edge, metres.
    pub range_m: f64,
    /// The map's +y up (as Foxglove and RViz show the map), the responder's arrow turning;
    /// otherwise heading-up, the map turning.
    pub north_up: bool,
}

/// Draws the inset in the frame's lower right corner: the map's cells in the responder's
/// height band (`BAND_BELOW_M` below the rig to `BAND_ABOVE_M` above it, where walls, doors and
/// furniture are and floors and ceilings are not), heading-up (or the map's +y up with
/// `north_up`); the responder as a green arrow at the centre pointing where they face; each
/// person within range, and the robot, as a dot of its colour.
pub fn draw_inset(
    frame: &mut ArFrame,
    raster: Option<&MapRaster>,
    world_t_rig: &Isometry3<f64>,
    people: &[(Vector3<f64>, [u8; 3])],
    robot: Option<(Vector3<f64>, [u8; 3])>,
    layout: InsetLayout,
) {
    let side = layout.side_px.min(frame.width.saturating_sub(8)).min(frame.height.saturating_sub(8));
    if side < 16 || !(layout.range_m.is_finite() && layout.range_m > 0.0) {
        return;
    }
    let (x0, y0) = (frame.width - side - 4, frame.height - side - 4);
    frame.fill_rect(x0 - 1, y0 - 1, side + 2, side + 2, COLOUR_INSET_FRAME);
    frame.fill_rect(x0, y0, side, side, COLOUR_INSET_BACKGROUND);
    let here = world_t_rig.translation.vector;
    let forward = world_t_rig.rotation * Vector3::x();
    let heading = forward.y.atan2(forward.x);
    // The world direction that points up in the inset.
    let up_yaw = if layout.north_up { std::f64::consts::FRAC_PI_2 } else { heading };
    let (s, c) = up_yaw.sin_cos();
    let m_per_px = 2.0 * layout.range_m / f64::from(side);
    let half = f64::from(side) / 2.0;
    // Inset pixel (right, up from the centre, metres) to world: up is the heading, right is
    // its clockwise side.
    let to_world = |right: f64, up: f64| (here.x + c * up + s * right, here.y + s * up - c * right);
    if let Some(r) = raster {
        let band = r.band(here.z - BAND_BELOW_M, here.z + BAND_ABOVE_M);
        for j in 0..side {
            for i in 0..side {
                let (right, up) = ((f64::from(i) + 0.5 - half) * m_per_px, (half - f64::from(j) - 0.5) * m_per_px);
                let (x, y) = to_world(right, up);
                if r.occupied(x, y, band) {
                    frame.put(i64::from(x0 + i), i64::from(y0 + j), COLOUR_INSET_WALL);
                }
            }
        }
    }
    let centre = (f64::from(x0) + half, f64::from(y0) + half);
    for (p, colour) in people.iter().chain(robot.iter()) {
        let d = p - here;
        // World offset to (right, up) in the inset.
        let (up, right) = (c * d.x + s * d.y, s * d.x - c * d.y);
        if up.abs() < layout.range_m && right.abs() < layout.range_m {
            frame.disc(centre.0 + right / m_per_px, centre.1 - up / m_per_px, 3, *colour);
        }
    }
    // The responder: a small arrow where they face (straight up when heading-up), in pixels
    // (right, down).
    let dir = ((up_yaw - heading).sin(), -(heading - up_yaw).cos());
    let perp = (-dir.1, dir.0);
    let tip = (centre.0 + 7.0 * dir.0, centre.1 + 7.0 * dir.1);
    for k in 0..=8 {
        let f = f64::from(k) / 8.0 * 2.0 - 1.0;
        let base = (centre.0 - 5.0 * dir.0 + 5.0 * f * perp.0, centre.1 - 5.0 * dir.1 + 5.0 * f * perp.1);
        frame.line(tip, base, COLOUR_RESPONDER);
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A 10 x 10 m room's walls, 0 to 3 m high, every 5 cm.
    fn room() -> Vec<Vector3<f64>> {
        let mut out = Vec::new();
        for i in 0..=200 {
            let t = f64::from(i) * 0.05;
            for k in 0..=30 {
                let z = f64::from(k) * 0.1;
                out.extend([
                    Vector3::new(t, 0.0, z),
                    Vector3::new(t, 10.0, z),
                    Vector3::new(0.0, t, z),
                    Vector3::new(10.0, t, z),
                ]);
            }
        }
        out
    }

    fn pose(x: f64, y: f64, yaw_deg: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, y, 1.6),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()),
        )
    }

    const LAYOUT: InsetLayout = InsetLayout { side_px: 160, range_m: 8.0, north_up: false };

    /// Inset pixel (in the frame) of a point `right`, `up` metres from the centre.
    fn px(frame: &ArFrame, right: f64, up: f64) -> (u32, u32) {
        let (x0, y0) = (frame.width - 164, frame.height - 164);
        ((f64::from(x0) + 80.0 + right * 10.0) as u32, (f64::from(y0) + 80.0 - up * 10.0) as u32)
    }

    #[test]
    fn the_wall_ahead_is_up_whichever_way_the_responder_faces() {
        let raster = MapRaster::from_points(&room(), 0.1).unwrap();
        // At (5, 5) facing +x: the wall x = 10 is 5 m ahead (up); facing +y, the wall y = 10 is.
        for (yaw, ahead) in [(0.0, "x = 10"), (90.0, "y = 10"), (-90.0, "y = 0")] {
            let mut frame = ArFrame::filled(640, 480, [10, 10, 14]);
            draw_inset(&mut frame, Some(&raster), &pose(5.0, 5.0, yaw), &[], None, LAYOUT);
            let (u, v) = px(&frame, 0.0, 5.0);
            let wall_ahead = (v - 2..v + 3).any(|v| frame.pixel(u, v) == Some(COLOUR_INSET_WALL));
            assert!(wall_ahead, "facing {yaw} deg: the wall {ahead} is not up");
            // Nothing 2.5 m ahead (the room's middle), and the walls 5 m to either side.
            let (u, v) = px(&frame, 0.0, 2.5);
            assert_eq!(frame.pixel(u, v), Some(COLOUR_INSET_BACKGROUND));
            let (u, v) = px(&frame, 5.0, 2.5);
            assert!((u - 2..u + 3).any(|u| frame.pixel(u, v) == Some(COLOUR_INSET_WALL)), "facing {yaw}: right wall");
        }
    }

    #[test]
    fn north_up_keeps_the_map_still_and_turns_the_responders_arrow() {
        let raster = MapRaster::from_points(&room(), 0.1).unwrap();
        let north_up = InsetLayout { north_up: true, ..LAYOUT };
        // At (5, 5) facing +x (east) and facing -y: the wall y = 10 stays 5 m up either way.
        for (yaw, tip) in [(0.0, (6.0, 0.0)), (-90.0, (0.0, -6.0))] {
            let mut frame = ArFrame::filled(640, 480, [10, 10, 14]);
            draw_inset(&mut frame, Some(&raster), &pose(5.0, 5.0, yaw), &[], None, north_up);
            let (u, v) = px(&frame, 0.0, 5.0);
            assert!(
                (v - 2..v + 3).any(|v| frame.pixel(u, v) == Some(COLOUR_INSET_WALL)),
                "facing {yaw}: y = 10 not up"
            );
            // The arrow's tip points where the responder faces (0.6 m = 6 px from the centre),
            // and nothing of it is on the opposite side.
            let (u, v) = px(&frame, tip.0 / 10.0, tip.1 / 10.0);
            assert_eq!(frame.pixel(u, v), Some(COLOUR_RESPONDER), "facing {yaw}: tip");
            let (u, v) = px(&frame, -tip.0 / 10.0, -tip.1 / 10.0);
            assert_ne!(frame.pixel(u, v), Some(COLOUR_RESPONDER), "facing {yaw}: tail");
        }
    }

    #[test]
    fn people_are_dots_where_they_are_and_out_of_range_ones_are_left_out() {
        let mut frame = ArFrame::filled(640, 480, [10, 10, 14]);
        // Facing +y from (5, 5): a person at (3, 8) is 3 m ahead and 2 m to the left.
        let people = [(Vector3::new(3.0, 8.0, 1.0), [255, 0, 0]), (Vector3::new(50.0, 5.0, 1.0), [0, 0, 255])];
        let robot = Some((Vector3::new(5.0, 1.0, 0.5), COLOUR_ROBOT));
        draw_inset(&mut frame, None, &pose(5.0, 5.0, 90.0), &people, robot, LAYOUT);
        let (u, v) = px(&frame, -2.0, 3.0);
        assert_eq!(frame.pixel(u, v), Some([255, 0, 0]));
        // The robot 4 m behind.
        let (u, v) = px(&frame, 0.0, -4.0);
        assert_eq!(frame.pixel(u, v), Some(COLOUR_ROBOT));
        assert!(!frame.rgb.chunks_exact(3).any(|p| p == [0, 0, 255]));
        // The responder's arrow at the centre.
        let (u, v) = px(&frame, 0.0, 0.0);
        assert_eq!(frame.pixel(u, v), Some(COLOUR_RESPONDER));
        // Off: nothing drawn.
        let mut off = ArFrame::filled(640, 480, [10, 10, 14]);
        draw_inset(&mut off, None, &pose(5.0, 5.0, 0.0), &people, robot, InsetLayout { side_px: 0, ..LAYOUT });
        assert!(off.rgb.chunks_exact(3).all(|p| p == [10, 10, 14]));
    }

    #[test]
    fn rasters_of_no_points_or_huge_maps_stay_bounded() {
        assert!(MapRaster::from_points(&[], 0.1).is_none());
        assert!(MapRaster::from_points(&[Vector3::new(f64::NAN, 0.0, 0.0)], 0.1).is_none());
        let huge = MapRaster::from_points(&[Vector3::new(-1e6, -1e6, 0.0), Vector3::new(1e6, 1e6, 0.0)], 0.1).unwrap();
        assert!(huge.slices.len() <= MAX_CELLS);
    }
}
