//! Where the sensor's field of view ends above, learned from the window itself: a cluster whose
//! top rows lie on that edge has been cut by it (a wall end or door jamb a metre from the robot
//! looks like a seated person 1.1 m tall), so its height is where the view ends.

use super::WindowPoint;
use nalgebra::{Isometry3, Point3, Vector3};

/// Azimuth bins of the envelope, deg.
const BIN_DEG: f64 = 2.0;
const BINS: usize = (360.0 / BIN_DEG) as usize;
/// Only points fired this close to the window's stamp: the sensor moves over the window, and
/// its pose at the stamp would smear near points' angles by degrees.
const RECENT_NS: u64 = 100_000_000;
/// A cluster is cut when at least this many of its recent points, and this share of them, lie
/// on the edge.
const MIN_EDGE_POINTS: usize = 10;
const MIN_EDGE_SHARE: f64 = 0.02;

/// The highest elevation seen per azimuth in the sensor's frame at the window's stamp.
pub struct FovEnvelope {
    sensor_t_world: Isometry3<f64>,
    max_elevation_deg: [f64; BINS],
    from_ns: u64,
}

impl FovEnvelope {
    pub fn new(points: &[WindowPoint], world_t_sensor: &Isometry3<f64>, stamp_ns: u64) -> Self {
        let mut env = Self {
            sensor_t_world: world_t_sensor.inverse(),
            max_elevation_deg: [f64::NEG_INFINITY; BINS],
            from_ns: stamp_ns.saturating_sub(RECENT_NS),
        };
        // Every recent point, not a subsample: at the sides of the view the rosette's upper edge
        // falls steeply and is swept by few returns, and a subsample can put the edge on the head
        // of a person sitting there.
        for p in points.iter().filter(|p| p.t_ns >= env.from_ns) {
            if let Some((bin, el)) = env.angles(p) {
                if let Some(m) = env.max_elevation_deg.get_mut(bin) {
                    *m = m.max(el);
                }
            }
        }
        env
    }

    /// Azimuth bin and elevation (deg) of a point in the sensor's frame.
    fn angles(&self, p: &WindowPoint) -> Option<(usize, f64)> {
        let (az, el) = az_el_deg(&in_sensor_frame(&self.sensor_t_world, p)?)?;
        Some((((az / BIN_DEG) as usize).min(BINS - 1), el))
    }

    /// Whether the cluster made of `indices` (into `points`) reaches the upper edge of the field
    /// of view within `margin_deg` (never with a margin of 0).
    pub fn cuts(&self, points: &[WindowPoint], indices: impl Iterator<Item = u32>, margin_deg: f64) -> bool {
        if margin_deg <= 0.0 {
            return false;
        }
        let (mut recent, mut on_edge) = (0usize, 0usize);
        for p in indices.filter_map(|i| points.get(i as usize)).filter(|p| p.t_ns >= self.from_ns) {
            recent += 1;
            let Some((bin, el)) = self.angles(p) else { continue };
            if self.max_elevation_deg.get(bin).is_some_and(|m| el >= m - margin_deg) {
                on_edge += 1;
            }
        }
        on_edge >= MIN_EDGE_POINTS && on_edge as f64 >= MIN_EDGE_SHARE * recent as f64
    }
}

/// A window point in the sensor's frame; `None` for one not finite or at the sensor itself.
pub(super) fn in_sensor_frame(sensor_t_world: &Isometry3<f64>, p: &WindowPoint) -> Option<Vector3<f64>> {
    let d = sensor_t_world.transform_point(&Point3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m))).coords;
    let range = d.norm();
    (range > 1e-3 && range.is_finite()).then_some(d)
}

/// Azimuth in [0, 360) and elevation of a direction in the sensor's frame, deg; `None` straight
/// up or down, where the azimuth is undefined.
pub(super) fn az_el_deg(d: &Vector3<f64>) -> Option<(f64, f64)> {
    let horizontal = d.x.hypot(d.y);
    (horizontal > 1e-6).then(|| (d.y.atan2(d.x).to_degrees().rem_euclid(360.0), d.z.atan2(horizontal).to_degrees()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pt(x: f64, y: f64, z: f64) -> WindowPoint {
        WindowPoint { x_m: x as f32, y_m: y as f32, z_m: z as f32, t_ns: 1_000 }
    }

    /// A sensor at 0.45 m whose view ends 36 deg above the horizon: a wall 5 m ahead seen up to
    /// that edge everywhere, a post 1 m ahead cut by it, a person-sized post 4 m ahead not.
    #[test]
    fn a_near_post_is_cut_and_a_far_one_is_not() {
        let tan = 36f64.to_radians().tan();
        let sensor = Isometry3::translation(0.0, 0.0, 0.45);
        let mut points = Vec::new();
        for k in 0..400 {
            let y = -3.0 + 6.0 * f64::from(k) / 400.0;
            for j in 0..=20 {
                points.push(pt(5.0, y, 0.45 + 5.0 * tan * f64::from(j) / 20.0));
            }
        }
        let mut post = |x: f64, y0: f64, z0: f64, z1: f64| -> Vec<u32> {
            let mut idx = Vec::new();
            for j in 0..=40 {
                for k in 0..5 {
                    points.push(pt(x, y0 + 0.05 * f64::from(k), z0 + (z1 - z0) * f64::from(j) / 40.0));
                    idx.push((points.len() - 1) as u32);
                }
            }
            idx
        };
        let near = post(1.0, -0.1, 0.45, 0.45 + tan);
        let far = post(4.0, 1.0, 0.1, 1.7);
        let env = FovEnvelope::new(&points, &sensor, 1_000);
        assert!(env.cuts(&points, near.iter().copied(), 2.0));
        assert!(!env.cuts(&points, far.iter().copied(), 2.0));
        assert!(!env.cuts(&points, near.iter().copied(), 0.0), "a margin of 0 turns the check off");
    }

    /// At the side of the view the edge is swept by a few returns among a person's many: the
    /// wall seen above their head in one return out of four still shows the view goes on.
    #[test]
    fn an_edge_seen_by_few_returns_is_still_learned() {
        let sensor = Isometry3::translation(0.0, 0.0, 0.45);
        let (mut points, mut person) = (Vec::new(), Vec::new());
        for k in 0..60u32 {
            let y = -3.6 + 0.01 * f64::from(k % 20);
            if k % 4 == 1 {
                points.push(pt(5.0, y, 0.45 + 5.0 * 17f64.to_radians().tan()));
            } else {
                // Head and shoulders, 5 m out, whose top is 9 deg up.
                let z = 1.05 + 0.19 * f64::from(k % 8) / 7.0;
                points.push(pt(5.0, y, z));
                person.push((points.len() - 1) as u32);
            }
        }
        let env = FovEnvelope::new(&points, &sensor, 1_000);
        assert!(!env.cuts(&points, person.iter().copied(), 1.0));
        // Without the wall, their top is the highest anything was seen there: cut.
        let alone: Vec<WindowPoint> = person.iter().map(|&i| points[i as usize]).collect();
        let env = FovEnvelope::new(&alone, &sensor, 1_000);
        assert!(env.cuts(&alone, 0..alone.len() as u32, 1.0));
    }

    #[test]
    fn degenerate_points_do_not_panic() {
        let points = vec![pt(0.0, 0.0, 0.45), pt(f64::NAN, 1.0, 1.0), pt(1e30, -1e30, 1e30)];
        let env = FovEnvelope::new(&points, &Isometry3::translation(0.0, 0.0, 0.45), 1_000);
        assert!(!env.cuts(&points, 0..5, 2.0));
    }
}
