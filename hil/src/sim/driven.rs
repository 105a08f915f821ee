//! The base's path when something drives it (the explorer over CAN in `starc sim --explore`)
//! instead of its scripted waypoints: the body twist its wheels really turn at is integrated
//! into knots, one per `dt_s`, and read back between them by cubic Hermite interpolation of
//! position and velocity. The LiDAR and the IMUs read the path as they read a scripted one; the
//! IMUs difference it over 1 ms, so the velocity must be continuous (the motors' lag makes it
//! so) and the knots must stay a few milliseconds ahead of the simulator's clock.
//!
//! The track is shared: the closed loop appends while the simulator's devices read.

use crate::sim::motion::RouteState;
use std::sync::{Arc, Mutex, MutexGuard};

/// One knot: position and heading (unwrapped), world velocity and yaw rate, distance so far.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Knot {
    x: f64,
    y: f64,
    yaw: f64,
    vx: f64,
    vy: f64,
    wz: f64,
    distance_m: f64,
}

#[derive(Debug)]
struct Knots {
    t0_s: f64,
    dt_s: f64,
    knots: Vec<Knot>,
}

/// A path appended one knot at a time; clones share it.
#[derive(Clone, Debug)]
pub struct DrivenTrack {
    inner: Arc<Mutex<Knots>>,
}

impl DrivenTrack {
    /// Standing at `start` (x, y, yaw rad) until `t0_s`, then a knot every `dt_s` as they come.
    pub fn new(start: [f64; 3], t0_s: f64, dt_s: f64) -> Self {
        let first = Knot { x: start[0], y: start[1], yaw: start[2], ..Knot::default() };
        let dt_s = if dt_s.is_finite() && dt_s > 0.0 { dt_s } else { 1e-3 };
        Self { inner: Arc::new(Mutex::new(Knots { t0_s, dt_s, knots: vec![first] })) }
    }

    fn lock(&self) -> MutexGuard<'_, Knots> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Time of the last knot: the path is known up to here.
    pub fn end_s(&self) -> f64 {
        let k = self.lock();
        k.t0_s + (k.knots.len() - 1) as f64 * k.dt_s
    }

    /// The next knot, after the base moved for one `dt_s` at the body twist (vx, vy m/s forward
    /// and left, wz rad/s) its wheels turned at; a twist that is not finite counts as standing.
    pub fn push(&self, body: [f64; 3]) {
        let body = if body.iter().all(|v| v.is_finite()) { body } else { [0.0; 3] };
        let mut k = self.lock();
        let dt = k.dt_s;
        let Some(&last) = k.knots.last() else { return };
        let yaw = last.yaw + body[2] * dt;
        let (s, c) = yaw.sin_cos();
        let (vx, vy) = (c * body[0] - s * body[1], s * body[0] + c * body[1]);
        // Trapezoidal in the world velocity: the same rule the interpolation assumes.
        let (x, y) = (last.x + 0.5 * (last.vx + vx) * dt, last.y + 0.5 * (last.vy + vy) * dt);
        let distance_m = last.distance_m + (x - last.x).hypot(y - last.y);
        k.knots.push(Knot { x, y, yaw, vx, vy, wz: body[2], distance_m });
    }

    /// Where the base is at `t` (s): standing at the start before the first knot and at the
    /// last knot after it.
    pub fn at(&self, t: f64) -> RouteState {
        let k = self.lock();
        let u = ((t - k.t0_s) / k.dt_s).max(0.0);
        let i = u.floor() as usize;
        let state = |n: &Knot, speed: f64| RouteState {
            x: n.x,
            y: n.y,
            yaw_rad: n.yaw,
            speed_m_s: speed,
            distance_m: n.distance_m,
        };
        let (Some(a), Some(b)) = (k.knots.get(i), k.knots.get(i + 1)) else {
            return k.knots.last().map_or(state(&Knot::default(), 0.0), |n| state(n, n.vx.hypot(n.vy)));
        };
        let s = u - i as f64;
        let h = |p0: f64, v0: f64, p1: f64, v1: f64| hermite(s, k.dt_s, p0, v0, p1, v1);
        let (vx, vy) = (a.vx + (b.vx - a.vx) * s, a.vy + (b.vy - a.vy) * s);
        RouteState {
            x: h(a.x, a.vx, b.x, b.vx),
            y: h(a.y, a.vy, b.y, b.vy),
            yaw_rad: h(a.yaw, a.wz, b.yaw, b.wz),
            speed_m_s: vx.hypot(vy),
            distance_m: a.distance_m + (b.distance_m - a.distance_m) * s,
        }
    }
}

/// Cubic Hermite between (p0, v0) and (p1, v1) over an interval of `dt`, at fraction `s`.
fn hermite(s: f64, dt: f64, p0: f64, v0: f64, p1: f64, v1: f64) -> f64 {
    let (s2, s3) = (s * s, s * s * s);
    (2.0 * s3 - 3.0 * s2 + 1.0) * p0 + (s3 - 2.0 * s2 + s) * dt * v0 + (-2.0 * s3 + 3.0 * s2) * p1 + (s3 - s2) * dt * v1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_steady_turn_is_followed_between_its_knots() {
        let track = DrivenTrack::new([1.0, 2.0, 0.5], 3.0, 1e-3);
        for _ in 0..2000 {
            track.push([0.4, 0.0, 0.5]);
        }
        assert!((track.end_s() - 5.0).abs() < 1e-9);
        // A circle of radius 0.8 m: heading 0.5 + 0.5 t, centre to the left of the start. The
        // track starts at rest, so the first millisecond lags by half a step (0.2 mm).
        let centre = (1.0 - 0.8 * 0.5f64.sin(), 2.0 + 0.8 * 0.5f64.cos());
        for t in [3.0, 3.2345, 4.0005, 4.9999] {
            let p = track.at(t);
            let yaw = 0.5 + 0.5 * (t - 3.0);
            let want = (centre.0 + 0.8 * yaw.sin(), centre.1 - 0.8 * yaw.cos());
            assert!((p.x - want.0).abs() < 3e-4 && (p.y - want.1).abs() < 3e-4, "{t}: {p:?} {want:?}");
            let speed = if t > 3.001 { 0.4 } else { 0.0 };
            assert!((p.yaw_rad - yaw).abs() < 1e-9 && (p.speed_m_s - speed).abs() < 1e-6, "{p:?}");
        }
        // Before the start it stands; past the last knot it holds there.
        assert_eq!((track.at(0.0).x, track.at(0.0).speed_m_s), (1.0, 0.0));
        assert_eq!(track.at(9.0).x, track.at(5.0).x);
    }

    #[test]
    fn a_twist_that_is_not_finite_stands() {
        let track = DrivenTrack::new([0.0; 3], 0.0, 0.01);
        track.push([f64::NAN, 1.0, 0.0]);
        assert_eq!((track.at(0.01).x, track.at(0.01).y), (0.0, 0.0));
    }
}
