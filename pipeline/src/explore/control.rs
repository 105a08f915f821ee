//! Local control of the omni base along a planned path, sans-IO: one call per control period
//! takes the robot's pose, the path (world x, y), the live scan's obstacles (body x, y) and the
//! period, and returns the body twist to command and what the controller is doing.
//!
//! The base is holonomic, but its Avia sees only 70 deg ahead: the controller drives towards a
//! point `lookahead_m` along the path and turns to face the way it moves, and it translates only
//! as fast as the direction of travel lies inside the view (`view_half_deg`), so it never moves
//! into space the live scan cannot see. Speed is capped so that the base can stop, at
//! `max_accel_m_s2`, short of the nearest obstacle on its way (the base a disc of
//! `robot_radius_m`, kept `stop_margin_m` clear). Where something close slows or blocks the way
//! (a doorway's post beside the base), directions up to `swerve_deg` off it are tried; what
//! stands on the path itself stops the base, and going round it is the planner's. Speeding up
//! and turning up are limited per period; slowing for an obstacle is not (the base driver's
//! own limiter still shapes what the motors get).

/// Less room than this on the way (m) is standing: a speed cap of a few cm/s moves nothing.
const BLOCKED_M: f64 = 0.005;
/// The step between the directions tried beside a blocked way.
const SWERVE_STEP_DEG: f64 = 5.0;

/// Settings of the local controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlConfig {
    pub max_speed_m_s: f64,
    pub max_turn_rad_s: f64,
    /// Speeding up, and the braking distance the speed cap assumes.
    pub max_accel_m_s2: f64,
    pub max_alpha_rad_s2: f64,
    /// The point driven towards lies this far along the path from the point nearest the robot.
    pub lookahead_m: f64,
    /// The path's end is reached within this.
    pub goal_tolerance_m: f64,
    /// The base as a disc, for the clearance to obstacles.
    pub robot_radius_m: f64,
    /// Clearance kept to every obstacle the base moves towards, ahead or passing beside it: the
    /// base is taken `stop_margin_m` wider, and stands when that touches something on its way.
    pub stop_margin_m: f64,
    /// Half the LiDAR's horizontal view (deg): travel outside it is slowed to nothing at twice it.
    pub view_half_deg: f64,
    /// Turn rate per radian of heading error (1/s).
    pub heading_gain: f64,
    /// Directions up to this far off the way (deg) are tried, and the one making the most speed
    /// along the way is taken: a doorway's post passed close, or a way at the view's edge
    /// travelled nearer its middle. Going round what stands on the path is the planner's: the base stops
    /// ([`ControlState::Blocked`]) and the caller plans again with it in the grid. 0: only the
    /// way itself.
    pub swerve_deg: f64,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self {
            max_speed_m_s: 0.5,
            max_turn_rad_s: 1.0,
            max_accel_m_s2: 0.5,
            max_alpha_rad_s2: 2.0,
            lookahead_m: 0.6,
            goal_tolerance_m: 0.15,
            robot_radius_m: 0.3,
            stop_margin_m: 0.1,
            // The Avia's 70.4 deg, less a margin for the body's own width.
            view_half_deg: 30.0,
            heading_gain: 1.5,
            swerve_deg: 45.0,
        }
    }
}

/// The robot's pose on the floor: world position (m) and heading (rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose2 {
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
}

impl Pose2 {
    /// The pose after `twist` (body frame) held for `dt_s`, the heading turned at its end: one
    /// control period of an omni base, to first order.
    pub fn after(&self, twist: &BodyTwist, dt_s: f64) -> Pose2 {
        let (s, c) = self.yaw_rad.sin_cos();
        Pose2 {
            x_m: self.x_m + (c * twist.vx_m_s - s * twist.vy_m_s) * dt_s,
            y_m: self.y_m + (s * twist.vx_m_s + c * twist.vy_m_s) * dt_s,
            yaw_rad: self.yaw_rad + twist.wz_rad_s * dt_s,
        }
    }

    /// A world point (x, y) in the body frame at this pose.
    pub fn to_body(&self, w: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.yaw_rad.sin_cos();
        let (dx, dy) = (w[0] - self.x_m, w[1] - self.y_m);
        [c * dx + s * dy, -s * dx + c * dy]
    }
}

/// A body twist: forward, left (m/s), counter-clockwise (rad/s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BodyTwist {
    pub vx_m_s: f64,
    pub vy_m_s: f64,
    pub wz_rad_s: f64,
}

impl BodyTwist {
    pub const ZERO: BodyTwist = BodyTwist { vx_m_s: 0.0, vy_m_s: 0.0, wz_rad_s: 0.0 };

    pub fn speed_m_s(&self) -> f64 {
        self.vx_m_s.hypot(self.vy_m_s)
    }
}

/// What one control step decided.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ControlState {
    /// Moving along the path (the twist may be slowed by the view or an obstacle).
    Driving,
    /// Turning in place towards the way to go, which lies outside the view.
    Turning,
    /// An obstacle on the way is within `stop_margin_m` of the base (`clearance_m` between
    /// them along the way): standing, turning only.
    Blocked { clearance_m: f64 },
    /// Within `goal_tolerance_m` of the path's end: standing.
    Arrived,
    /// No path, or a pose, path point or period that is not finite: standing.
    Idle,
}

/// The command of one control step and why.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlStep {
    pub twist: BodyTwist,
    pub state: ControlState,
}

/// The local controller; it remembers the last command to limit speeding up.
#[derive(Clone, Debug)]
pub struct LocalController {
    cfg: ControlConfig,
    last: BodyTwist,
}

impl LocalController {
    pub fn new(cfg: ControlConfig) -> Self {
        Self { cfg, last: BodyTwist::ZERO }
    }

    pub fn config(&self) -> &ControlConfig {
        &self.cfg
    }

    /// Forget the last command (after a stop the base stands, so the next one starts from 0).
    pub fn reset(&mut self) {
        self.last = BodyTwist::ZERO;
    }

    /// One control period of `dt_s`: the twist towards the path from `pose`, with `obstacles`
    /// in the body frame (x, y): the live scan's returns in the body band, and what the
    /// occupancy grid holds around the base (the Avia does not see beside it, as in a doorway).
    pub fn step(&mut self, pose: &Pose2, path: &[[f64; 2]], obstacles: &[[f64; 2]], dt_s: f64) -> ControlStep {
        let finite = [pose.x_m, pose.y_m, pose.yaw_rad, dt_s].iter().all(|v| v.is_finite()) && dt_s > 0.0;
        let Some(end) = path.last().filter(|_| finite && path.iter().flatten().all(|v| v.is_finite())) else {
            return self.stand(ControlState::Idle);
        };
        if (end[0] - pose.x_m).hypot(end[1] - pose.y_m) <= self.cfg.goal_tolerance_m {
            return self.stand(ControlState::Arrived);
        }
        // The way to go, in the body frame.
        let way = pose.to_body(lookahead(path, [pose.x_m, pose.y_m], self.cfg.lookahead_m));
        let bearing = way[1].atan2(way[0]);
        let distance = way[0].hypot(way[1]);
        let wanted_turn = (self.cfg.heading_gain * bearing).clamp(-self.cfg.max_turn_rad_s, self.cfg.max_turn_rad_s);
        // Stop at the goal, and short of anything on the way; where something close or the view
        // slows the way, a direction up to `swerve_deg` off it that makes more progress is taken
        // (towards the view's middle, or past a post).
        let arrive = (2.0 * self.cfg.max_accel_m_s2 * distance).sqrt();
        let straight = self.heading_for(bearing, bearing, arrive, obstacles);
        let best = swerves(self.cfg.swerve_deg)
            .map(|off| self.heading_for(bearing + off, bearing, arrive, obstacles))
            .fold(straight, |a, b| if b.progress > a.progress + 1e-12 { b } else { a });
        let turning = view_factor(bearing, self.cfg.view_half_deg.to_radians()) <= 0.0;
        // The way out of the view: turn to it first, whatever a swerve would make of it.
        let speed = if turning { 0.0 } else { best.speed };
        let (sin_b, cos_b) = best.bearing.sin_cos();
        let wanted = BodyTwist { vx_m_s: cos_b * speed, vy_m_s: sin_b * speed, wz_rad_s: wanted_turn };
        let state = if turning {
            ControlState::Turning
        } else if best.progress <= 0.0 {
            ControlState::Blocked { clearance_m: straight.room + self.cfg.stop_margin_m }
        } else {
            ControlState::Driving
        };
        self.last = self.limited(wanted, dt_s);
        ControlStep { twist: self.last, state }
    }

    /// Travel at `bearing` (body frame) when the way lies at `way`: the speed the view, the
    /// room to the nearest obstacle (the base grown by `stop_margin_m`) and `arrive` allow, and
    /// the speed it makes along the way.
    fn heading_for(&self, bearing: f64, way: f64, arrive: f64, obstacles: &[[f64; 2]]) -> Heading {
        let c = &self.cfg;
        let dir = [bearing.cos(), bearing.sin()];
        let room = clearance_m(obstacles, dir, c.robot_radius_m + c.stop_margin_m);
        let stoppable = if room <= BLOCKED_M { 0.0 } else { (2.0 * c.max_accel_m_s2 * room).sqrt() };
        let speed = (c.max_speed_m_s * view_factor(bearing, c.view_half_deg.to_radians())).min(stoppable).min(arrive);
        Heading { bearing, speed, room, progress: speed * (bearing - way).cos() }
    }

    fn stand(&mut self, state: ControlState) -> ControlStep {
        self.last = BodyTwist::ZERO;
        ControlStep { twist: BodyTwist::ZERO, state }
    }

    /// `wanted` with speeding up and turning up limited from the last command; slowing down is
    /// not limited (an obstacle decides how fast the base must stop).
    fn limited(&self, wanted: BodyTwist, dt_s: f64) -> BodyTwist {
        let c = &self.cfg;
        let mut out = wanted;
        let (dvx, dvy) = (wanted.vx_m_s - self.last.vx_m_s, wanted.vy_m_s - self.last.vy_m_s);
        let dv = dvx.hypot(dvy);
        let max_dv = c.max_accel_m_s2 * dt_s;
        if wanted.speed_m_s() > self.last.speed_m_s() && dv > max_dv {
            out.vx_m_s = self.last.vx_m_s + dvx * max_dv / dv;
            out.vy_m_s = self.last.vy_m_s + dvy * max_dv / dv;
        }
        let max_dw = c.max_alpha_rad_s2 * dt_s;
        if wanted.wz_rad_s.abs() > self.last.wz_rad_s.abs() {
            out.wz_rad_s = wanted.wz_rad_s.clamp(self.last.wz_rad_s - max_dw, self.last.wz_rad_s + max_dw);
        }
        out
    }
}

/// One direction of travel considered.
#[derive(Clone, Copy, Debug)]
struct Heading {
    bearing: f64,
    speed: f64,
    room: f64,
    progress: f64,
}

/// The swerves tried beside the way: every 5 deg out to `max_deg` each side, nearest first.
fn swerves(max_deg: f64) -> impl Iterator<Item = f64> {
    let n = (max_deg.max(0.0) / SWERVE_STEP_DEG).floor() as i32;
    (1..=n).flat_map(|k| [k, -k]).map(|k| (f64::from(k) * SWERVE_STEP_DEG).to_radians())
}

/// The point `ahead_m` along `path` from its point nearest `at` (the path's end when it is
/// shorter).
fn lookahead(path: &[[f64; 2]], at: [f64; 2], ahead_m: f64) -> [f64; 2] {
    let Some(&last) = path.last() else { return at };
    // The nearest point on the path: its segment and how far along it.
    let mut nearest = (0, 0.0, f64::INFINITY);
    for (i, pair) in path.windows(2).enumerate() {
        let (f, d) = project(pair[0], pair[1], at);
        if d < nearest.2 {
            nearest = (i, f, d);
        }
    }
    let mut left = ahead_m;
    for (i, pair) in path.windows(2).enumerate().skip(nearest.0) {
        let (a, b) = (pair[0], pair[1]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let from = if i == nearest.0 { nearest.1 * len } else { 0.0 };
        if len - from >= left && len > 0.0 {
            let f = (from + left) / len;
            return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])];
        }
        left -= len - from;
    }
    last
}

/// Where `p` projects onto the segment from `a` to `b` (0 at `a`, 1 at `b`, clamped), and its
/// distance from there.
fn project(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> (f64, f64) {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let f = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (f, (a[0] + f * dx - p[0]).hypot(a[1] + f * dy - p[1]))
}

/// How much of full speed travel at `bearing` (rad, body frame) may have: 1 inside the view's
/// half angle, falling linearly to 0 at twice it.
fn view_factor(bearing: f64, half: f64) -> f64 {
    let off = bearing.abs();
    if off <= half {
        1.0
    } else {
        (1.0 - (off - half) / half.max(1e-9)).max(0.0)
    }
}

/// How far the base (a disc of `radius_m` at the body origin) can move along the unit direction
/// `dir` before it touches one of `obstacles` (body x, y); infinity when none lies on the way.
/// An obstacle already inside the disc and ahead gives 0.
pub fn clearance_m(obstacles: &[[f64; 2]], dir: [f64; 2], radius_m: f64) -> f64 {
    obstacles
        .iter()
        .filter(|p| p[0].is_finite() && p[1].is_finite())
        .filter_map(|p| {
            let along = p[0] * dir[0] + p[1] * dir[1];
            let across = (p[0] * dir[1] - p[1] * dir[0]).abs();
            // Beside the way, or behind the base's centre: moving on never reaches it.
            if across >= radius_m || along < 0.0 {
                return None;
            }
            let reach = (radius_m * radius_m - across * across).sqrt();
            Some((along - reach).max(0.0))
        })
        .fold(f64::INFINITY, f64::min)
}
