//! How things move: the omni base between waypoints, the responder walking (with the bounce and
//! sway of a gait), and people patrolling their paths.
//!
//! Every motion is an analytic, twice-differentiable function of time: each leg follows a
//! minimum-jerk profile (rest to rest, peak speed and acceleration within the limits), and the
//! gait terms are sinusoids of the distance walked scaled by the speed. The IMUs differentiate
//! these functions, so what they measure is exactly the motion the LiDARs see.

use crate::sim::driven::DrivenTrack;
use crate::sim::scenario::{Mount, Person, Responder, Robot};
use crate::sim::shapes::V3;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use std::f64::consts::{PI, TAU};

/// Peak speed of a minimum-jerk leg is this times distance / duration.
const MJ_PEAK_SPEED: f64 = 1.875;
/// Peak acceleration of a minimum-jerk leg is this times distance / duration^2.
const MJ_PEAK_ACCEL: f64 = 5.7735;
/// Turning rate of a person turning on the spot (deg/s).
const PERSON_TURN_DEG_S: f64 = 120.0;
/// Walking acceleration limit (m/s^2).
const WALK_ACCEL_M_S2: f64 = 1.2;
/// Length of one step (m): one bounce per step, one sway period per stride of two steps.
const STEP_M: f64 = 0.7;

/// Position along a minimum-jerk leg (0..1) at normalised time `tau` (0..1).
fn min_jerk(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
}

/// Its derivative with respect to `tau`.
fn min_jerk_rate(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    30.0 * t * t * (1.0 - t) * (1.0 - t)
}

/// Distance along a walking ramp, in units of cruising speed times ramp time (0..0.5): the
/// integral of [`min_jerk`], which is the ramp's speed (0..1 of the cruising speed), so that the
/// acceleration starts and ends at zero.
fn ramp_distance(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * t * (2.5 - 3.0 * t + t * t)
}

/// How a leg goes from rest to rest.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LegProfile {
    /// One minimum-jerk profile over the whole leg: the speed peaks at its middle only, so a
    /// long leg starts very gently (an 8 m leg at 1.2 m/s reaches half that after 2.9 s).
    #[default]
    MinJerk,
    /// As people walk: up to the speed within a smooth ramp at the acceleration limit (1.6 s to
    /// 1 m/s at 1.2 m/s^2), on at that speed, and down the same way; turns on the spot stay
    /// minimum-jerk.
    Walk,
}

/// One leg of a route: rest at `from` until `t0`, move to `to` by `t1`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Leg {
    t0: f64,
    t1: f64,
    from: [f64; 3],
    to: [f64; 3],
    /// Distance walked before this leg.
    s0: f64,
    /// A walking leg's cruising speed and the length of each of its two ramps; none: minimum
    /// jerk over the whole leg.
    walk: Option<(f64, f64)>,
}

impl Leg {
    /// The share of the leg done (0..1) and the speed over the ground, `t` into it.
    fn progress(&self, t: f64, d: f64) -> (f64, f64) {
        let dur = self.t1 - self.t0;
        match self.walk {
            // Only legs that move walk (`Route::with_profile`): d > 0.
            Some((cruise, ramp)) => {
                let (s, v) = if t < ramp {
                    (cruise * ramp * ramp_distance(t / ramp), cruise * min_jerk(t / ramp))
                } else if t <= dur - ramp {
                    (cruise * ramp * 0.5 + cruise * (t - ramp), cruise)
                } else {
                    let left = dur - t;
                    (d - cruise * ramp * ramp_distance(left / ramp), cruise * min_jerk(left / ramp))
                };
                ((s / d).clamp(0.0, 1.0), v)
            }
            None => {
                let tau = t / dur;
                (min_jerk(tau), d * min_jerk_rate(tau) / dur)
            }
        }
    }
}

/// A walking leg of `d` m: its cruising speed, ramp time and duration (the ramps' peak
/// acceleration is 1.875 times cruise / ramp, as the minimum-jerk profile's).
fn walk_leg(d: f64, max_speed: f64, max_accel: f64) -> (f64, f64, f64) {
    let cruise = max_speed.min((d * max_accel / MJ_PEAK_SPEED).sqrt());
    let ramp = MJ_PEAK_SPEED * cruise / max_accel;
    (cruise, ramp, d / cruise + ramp)
}

/// Where something is on its route at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RouteState {
    pub x: f64,
    pub y: f64,
    pub yaw_rad: f64,
    /// Speed over the ground.
    pub speed_m_s: f64,
    /// Distance travelled since the start.
    pub distance_m: f64,
}

/// A sequence of rest-to-rest legs in (x, y, yaw).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Route {
    legs: Vec<Leg>,
    start: [f64; 3],
}

impl Route {
    /// A route through `waypoints` (x, y, yaw rad) starting to move at `t_start`, each leg as short
    /// as the limits allow, pausing `pause_s` after each.
    fn new(
        waypoints: &[[f64; 3]],
        t_start: f64,
        max_speed: f64,
        max_accel: f64,
        max_yaw_rate: f64,
        pause_s: f64,
    ) -> Self {
        Self::with_profile(waypoints, t_start, [max_speed, max_accel, max_yaw_rate], pause_s, LegProfile::MinJerk)
    }

    /// The same with legs that move (not turns on the spot) shaped by `profile`; `limits` are the
    /// speed, acceleration and yaw rate.
    fn with_profile(waypoints: &[[f64; 3]], t_start: f64, limits: [f64; 3], pause_s: f64, profile: LegProfile) -> Self {
        let [max_speed, max_accel, max_yaw_rate] = limits;
        let start = waypoints.first().copied().unwrap_or([0.0; 3]);
        let mut legs = Vec::new();
        let mut t = t_start;
        let mut s = 0.0;
        let mut from = start;
        for &wp in waypoints.iter().skip(1) {
            let to = [wp[0], wp[1], from[2] + wrap_pi(wp[2] - from[2])];
            let d = (to[0] - from[0]).hypot(to[1] - from[1]);
            let dyaw = (to[2] - from[2]).abs();
            let min_jerk_s = (MJ_PEAK_SPEED * d / max_speed)
                .max((MJ_PEAK_ACCEL * d / max_accel).sqrt())
                .max(MJ_PEAK_SPEED * dyaw / max_yaw_rate)
                .max(1e-3);
            // A walk that also turns more than its ramps allow stays minimum-jerk (the responder's
            // walks never turn: it turns on the spot first).
            let walk = (profile == LegProfile::Walk && d > 1e-6)
                .then(|| walk_leg(d, max_speed, max_accel))
                .filter(|&(_, _, walk_s)| walk_s >= MJ_PEAK_SPEED * dyaw / max_yaw_rate);
            let (duration, walk) = match walk {
                Some((cruise, ramp, walk_s)) => (walk_s, Some((cruise, ramp))),
                None => (min_jerk_s, None),
            };
            legs.push(Leg { t0: t, t1: t + duration, from, to, s0: s, walk });
            t += duration + pause_s;
            s += d;
            from = to;
        }
        Self { legs, start }
    }

    /// The end of the last leg.
    pub fn end_s(&self) -> f64 {
        self.legs.last().map_or(0.0, |l| l.t1)
    }

    pub fn at(&self, t: f64) -> RouteState {
        let rest = |p: [f64; 3], s: f64| RouteState { x: p[0], y: p[1], yaw_rad: p[2], speed_m_s: 0.0, distance_m: s };
        let i = self.legs.partition_point(|l| l.t0 <= t);
        if i == 0 {
            return rest(self.start, 0.0);
        }
        let Some(leg) = self.legs.get(i - 1) else { return rest(self.start, 0.0) };
        let d = (leg.to[0] - leg.from[0]).hypot(leg.to[1] - leg.from[1]);
        if t >= leg.t1 {
            return rest(leg.to, leg.s0 + d);
        }
        let (f, speed_m_s) = leg.progress(t - leg.t0, d);
        let lerp = |k: usize| leg.from[k] + (leg.to[k] - leg.from[k]) * f;
        RouteState { x: lerp(0), y: lerp(1), yaw_rad: lerp(2), speed_m_s, distance_m: leg.s0 + d * f }
    }
}

/// (-pi, pi]
fn wrap_pi(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI {
        w + TAU
    } else {
        w
    }
}

/// A pose from position and roll, pitch, yaw (rad; z-y-x order).
pub fn pose_xyz_rpy(p: V3, roll: f64, pitch: f64, yaw: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(p), UnitQuaternion::from_euler_angles(roll, pitch, yaw))
}

/// A 6-vector mount (x, y, z m; roll, pitch, yaw deg) as a pose.
pub fn mount_pose(m: &[f64; 6]) -> Isometry3<f64> {
    pose_xyz_rpy(V3::new(m[0], m[1], m[2]), m[3].to_radians(), m[4].to_radians(), m[5].to_radians())
}

/// Something whose LiDAR moves: the pose of the LiDAR in the world at time `t` (s).
pub trait Motion: Send + Sync {
    fn lidar_pose(&self, t: f64) -> Isometry3<f64>;
}

/// The omni base: translates and turns at once, LiDAR on a mast.
#[derive(Clone, Debug)]
pub struct RobotMotion {
    route: Route,
    /// Driven in a closed loop instead of along `route` (which is then empty).
    driven: Option<DrivenTrack>,
    lidar_height_m: f64,
    lidar_pitch_rad: f64,
}

impl RobotMotion {
    pub fn new(r: &Robot) -> Self {
        let waypoints: Vec<[f64; 3]> = r.waypoints.iter().map(|w| [w[0], w[1], w[2].to_radians()]).collect();
        let route = Route::new(
            &waypoints,
            r.start_s + r.static_s,
            r.max_speed_m_s,
            r.max_accel_m_s2,
            r.max_yaw_rate_deg_s.to_radians(),
            r.pause_s,
        );
        Self { route, driven: None, lidar_height_m: r.lidar_height_m, lidar_pitch_rad: r.lidar_pitch_deg.to_radians() }
    }

    /// The robot `r` (its mast), moved along `track` instead of its waypoints.
    pub fn driven(r: &Robot, track: DrivenTrack) -> Self {
        Self {
            route: Route::default(),
            driven: Some(track),
            lidar_height_m: r.lidar_height_m,
            lidar_pitch_rad: r.lidar_pitch_deg.to_radians(),
        }
    }

    /// Where the base is at `t`, scripted or driven.
    pub fn state_at(&self, t: f64) -> RouteState {
        match &self.driven {
            Some(track) => track.at(t),
            None => self.route.at(t),
        }
    }

    /// The scripted route (empty for a driven robot).
    pub fn route(&self) -> &Route {
        &self.route
    }

    /// The base's pose on the floor.
    pub fn base_pose(&self, t: f64) -> Isometry3<f64> {
        let s = self.state_at(t);
        pose_xyz_rpy(V3::new(s.x, s.y, 0.0), 0.0, 0.0, s.yaw_rad)
    }
}

impl Motion for RobotMotion {
    fn lidar_pose(&self, t: f64) -> Isometry3<f64> {
        let mast = pose_xyz_rpy(V3::new(0.0, 0.0, self.lidar_height_m), 0.0, self.lidar_pitch_rad, 0.0);
        self.base_pose(t) * mast
    }
}

/// The responder: turns on the spot towards the next waypoint, walks there, pauses; the rig
/// bounces and sways with the gait.
#[derive(Clone, Debug)]
pub struct ResponderMotion {
    route: Route,
    speed_m_s: f64,
    height_m: f64,
    pitch_rad: f64,
    /// Gait amplitudes (bounce m, yaw, roll, pitch rad) at full walking speed.
    gait: [f64; 4],
    /// A handheld rig also wanders slowly (amplitude rad).
    hand_drift_rad: f64,
}

impl ResponderMotion {
    pub fn new(r: &Responder) -> Self {
        let first_heading = match (r.waypoints.first(), r.waypoints.get(1)) {
            (Some(a), Some(b)) => (b[1] - a[1]).atan2(b[0] - a[0]),
            _ => 0.0,
        };
        let mut heading = r.yaw_deg.map_or(first_heading, f64::to_radians);
        let mut points: Vec<[f64; 3]> = Vec::new();
        if let Some(a) = r.waypoints.first() {
            points.push([a[0], a[1], heading]);
        }
        for pair in r.waypoints.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let towards = (b[1] - a[1]).atan2(b[0] - a[0]);
            heading += wrap_pi(towards - heading);
            // Turn on the spot, then walk.
            points.push([a[0], a[1], heading]);
            points.push([b[0], b[1], heading]);
        }
        let route = Route::with_profile(
            &points,
            r.start_s + r.static_s,
            [r.speed_m_s, WALK_ACCEL_M_S2, PERSON_TURN_DEG_S.to_radians()],
            r.pause_s,
            r.legs,
        );
        let (height, gait, drift) = match r.mount {
            Mount::Helmet => (1.80, [0.025, 3.0f64.to_radians(), 1.5f64.to_radians(), 1.0f64.to_radians()], 0.0),
            Mount::Handheld => {
                (1.35, [0.03, 5.0f64.to_radians(), 2.5f64.to_radians(), 2.0f64.to_radians()], 1.5f64.to_radians())
            }
        };
        Self {
            route,
            speed_m_s: r.speed_m_s,
            height_m: r.rig_height_m.unwrap_or(height),
            pitch_rad: r.rig_pitch_deg.to_radians(),
            gait,
            hand_drift_rad: drift,
        }
    }

    pub fn route(&self) -> &Route {
        &self.route
    }
}

impl Motion for ResponderMotion {
    fn lidar_pose(&self, t: f64) -> Isometry3<f64> {
        let s = self.route.at(t);
        let k = (s.speed_m_s / self.speed_m_s).clamp(0.0, 1.5);
        // Stride phase: one sway period per two steps, one bounce per step.
        let phi = PI * s.distance_m / STEP_M;
        let [bounce, yaw_a, roll_a, pitch_a] = self.gait;
        let drift = self.hand_drift_rad * (TAU * 0.31 * t).sin();
        let z = self.height_m + k * bounce * (2.0 * phi).cos();
        pose_xyz_rpy(
            V3::new(s.x, s.y, z),
            k * roll_a * phi.sin(),
            self.pitch_rad + k * pitch_a * (2.0 * phi).sin() + 0.5 * drift,
            s.yaw_rad + k * yaw_a * phi.sin() + drift,
        )
    }
}

/// A person in the scene: fixed, or walking a path back and forth.
#[derive(Clone, Debug)]
pub struct PersonMotion {
    route: Route,
    speed_m_s: f64,
    cycle_s: f64,
}

impl PersonMotion {
    pub fn new(p: &Person) -> Self {
        let yaw = p.yaw_deg.to_radians();
        let mut xy: Vec<[f64; 2]> = vec![p.at];
        xy.extend(p.path.iter().copied());
        if p.patrol && xy.len() > 1 {
            let back: Vec<[f64; 2]> = xy.iter().rev().skip(1).copied().collect();
            xy.extend(back);
        }
        let mut heading = match xy.get(1) {
            Some(b) if !p.path.is_empty() => (b[1] - p.at[1]).atan2(b[0] - p.at[0]),
            _ => yaw,
        };
        let mut points = vec![[p.at[0], p.at[1], heading]];
        for pair in xy.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            heading += wrap_pi((b[1] - a[1]).atan2(b[0] - a[0]) - heading);
            points.push([a[0], a[1], heading]);
            points.push([b[0], b[1], heading]);
        }
        let route = Route::new(&points, 0.0, p.speed_m_s, WALK_ACCEL_M_S2, PERSON_TURN_DEG_S.to_radians(), 0.5);
        let cycle_s = if p.patrol && !p.path.is_empty() { route.end_s() + 0.5 } else { 0.0 };
        Self { route, speed_m_s: p.speed_m_s, cycle_s }
    }

    /// Position on the floor, heading, and stride swing (-1..1) at `t`.
    pub fn at(&self, t: f64) -> (f64, f64, f64, f64) {
        let t = if self.cycle_s > 0.0 { t.rem_euclid(self.cycle_s) } else { t };
        let s = self.route.at(t);
        let k = (s.speed_m_s / self.speed_m_s).clamp(0.0, 1.0);
        (s.x, s.y, s.yaw_rad, k * (PI * s.distance_m / STEP_M).sin())
    }

    pub fn moves(&self) -> bool {
        self.cycle_s > 0.0 || self.route.end_s() > 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legs_respect_the_limits_and_arrive() {
        let route = Route::new(&[[0.0, 0.0, 0.0], [4.0, 0.0, 1.0], [4.0, 3.0, 1.0]], 2.0, 0.5, 0.5, 0.8, 1.0);
        let mut prev = route.at(0.0);
        let mut v_max: f64 = 0.0;
        let mut a_max: f64 = 0.0;
        let dt = 0.001;
        let mut t = 0.0;
        while t < route.end_s() + 1.0 {
            let s = route.at(t);
            v_max = v_max.max(s.speed_m_s);
            a_max = a_max.max((s.speed_m_s - prev.speed_m_s).abs() / dt);
            prev = s;
            t += dt;
        }
        assert!(v_max <= 0.5 + 1e-6 && v_max > 0.45, "{v_max}");
        assert!(a_max <= 0.5 + 1e-3, "{a_max}");
        let end = route.at(route.end_s() + 5.0);
        assert!((end.x - 4.0).abs() < 1e-9 && (end.y - 3.0).abs() < 1e-9 && (end.distance_m - 7.0).abs() < 1e-9);
        let before = route.at(1.99);
        assert_eq!((before.x, before.speed_m_s), (0.0, 0.0));
    }

    /// The route's speed and acceleration over `[t0, t1]`, by differences of its positions
    /// every `dt` s (checks that the reported speed is the position's rate, and the limits).
    fn speed_and_accel_peaks(route: &Route, t0: f64, t1: f64) -> (f64, f64, f64) {
        let dt = 0.001;
        let (mut v_max, mut a_max, mut rate_err): (f64, f64, f64) = (0.0, 0.0, 0.0);
        let mut t = t0;
        while t < t1 {
            let (a, b) = (route.at(t), route.at(t + dt));
            let rate = (b.x - a.x).hypot(b.y - a.y) / dt;
            rate_err = rate_err.max((rate - 0.5 * (a.speed_m_s + b.speed_m_s)).abs());
            v_max = v_max.max(a.speed_m_s);
            a_max = a_max.max((b.speed_m_s - a.speed_m_s).abs() / dt);
            t += dt;
        }
        (v_max, a_max, rate_err)
    }

    #[test]
    fn a_walking_leg_is_at_its_speed_within_a_ramp_and_arrives() {
        let waypoints = [[0.0, 0.0, 0.0], [8.0, 0.0, 0.0]];
        let walk = Route::with_profile(&waypoints, 1.0, [1.2, 1.2, 2.0], 0.5, LegProfile::Walk);
        let min_jerk = Route::new(&waypoints, 1.0, 1.2, 1.2, 2.0, 0.5);
        // Ramps of 1.875 s, 8 m at 1.2 m/s: 6.67 s plus one ramp.
        assert!((walk.end_s() - (1.0 + 8.0 / 1.2 + 1.875)).abs() < 1e-9, "{}", walk.end_s());
        let (v_max, a_max, rate_err) = speed_and_accel_peaks(&walk, 0.0, walk.end_s() + 1.0);
        assert!((v_max - 1.2).abs() < 1e-6, "{v_max}");
        assert!(a_max <= 1.2 + 1e-3 && a_max > 1.1, "{a_max}");
        assert!(rate_err < 1e-3, "the speed is the position's rate: {rate_err}");
        // A second in, the walker is at half its speed; the minimum-jerk leg at a tenth.
        assert!((walk.at(2.0).speed_m_s - 0.6).abs() < 0.15, "{:?}", walk.at(2.0));
        assert!(min_jerk.at(2.0).speed_m_s < 0.15, "{:?}", min_jerk.at(2.0));
        let end = walk.at(walk.end_s() + 1.0);
        assert!((end.x - 8.0).abs() < 1e-9 && end.speed_m_s == 0.0 && (end.distance_m - 8.0).abs() < 1e-9);
        // A leg too short to reach the speed turns round at a lower one, still smoothly.
        let short =
            Route::with_profile(&[[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]], 0.0, [1.2, 1.2, 2.0], 0.0, LegProfile::Walk);
        let (v_short, a_short, err_short) = speed_and_accel_peaks(&short, 0.0, short.end_s() + 0.5);
        assert!(v_short < 1.2 && a_short <= 1.2 + 1e-3 && err_short < 1e-3, "{v_short} {a_short} {err_short}");
        assert!((short.at(10.0).x - 0.5).abs() < 1e-9);
    }

    #[test]
    fn yaw_takes_the_short_way_round() {
        let route = Route::new(&[[0.0, 0.0, 3.0], [0.0, 0.0, -3.0]], 0.0, 1.0, 1.0, 1.0, 0.0);
        let end = route.at(100.0);
        assert!((end.yaw_rad - (3.0 + wrap_pi(-6.0))).abs() < 1e-9, "{}", end.yaw_rad);
        assert!((wrap_pi(end.yaw_rad) - (-3.0)).abs() < 1e-9);
    }
}
