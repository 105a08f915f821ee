//! How the robot moves in a loop run: driven by the explorer through its base ([`Driven`]), or
//! along its scripted waypoints ([`Scripted`]: the baseline, its grid, coverage and contacts
//! measured the same way).

use super::bus::{BaseInTheLoop, STEP_NS};
use crate::{EvalError, Result};
use starc_base::kinematics::Kinematics;
use starc_bridge::wheels::{WheelDecoder, WheelFeedback};
use starc_can::CanFrame;
use starc_hil::sim::driven::DrivenTrack;
use starc_hil::sim::motion::{RobotMotion, RouteState};
use starc_hil::sim::scenario::Robot;
use starc_hil::sim::wheels::WheelOdometry;

/// The wheels' odometry comes this often on a scripted route (as the run's robot_can.log).
pub(super) const SCRIPTED_WHEEL_NS: u64 = 10_000_000;

/// The explorer's base: the driver over the bus to the mock controllers, the track their
/// true speeds drive.
pub(super) struct Driven {
    pub track: DrivenTrack,
    pub bus: BaseInTheLoop,
    pub kinematics: Kinematics,
    pub wheels: WheelDecoder,
    /// The next motor step (simulator clock).
    pub motor_ns: u64,
    pub next_control_ns: u64,
    pub frames: Vec<CanFrame>,
}

/// The scripted route, and the wheels' odometry measured on it (the simulator's wheel model,
/// slip included).
pub(super) struct Scripted {
    pub motion: RobotMotion,
    pub odometry: WheelOdometry,
    pub next_ns: u64,
}

pub(super) enum Body {
    Driven(Box<Driven>),
    Scripted(Box<Scripted>),
}

impl Body {
    /// The explorer's base for `robot`, its driver set up as `base` says.
    pub fn driven(robot: &Robot, base: &starc_base::BaseConfig, seed: u64) -> Result<Self> {
        let start = robot.waypoints.first().ok_or_else(|| EvalError::Input("the robot has no start pose".into()))?;
        let kinematics = Kinematics::new(&base.kinematics).map_err(|e| EvalError::Input(format!("base: {e}")))?;
        let wheels = WheelDecoder::new(&WheelFeedback::from_base(base)).map_err(EvalError::Input)?;
        Ok(Body::Driven(Box::new(Driven {
            track: DrivenTrack::new([start[0], start[1], start[2].to_radians()], 0.0, STEP_NS as f64 * 1e-9),
            bus: BaseInTheLoop::new(base.clone(), seed)?,
            kinematics,
            wheels,
            motor_ns: 0,
            next_control_ns: 0,
            frames: Vec::new(),
        })))
    }

    /// `robot` on its waypoints.
    pub fn scripted(robot: &Robot, seed: u64) -> Result<Self> {
        let odometry = WheelOdometry::new(robot.wheels, seed).map_err(|e| EvalError::Input(e.to_string()))?;
        Ok(Body::Scripted(Box::new(Scripted { motion: RobotMotion::new(robot), odometry, next_ns: 0 })))
    }

    /// Where the base truly is at `t_s` (the scorer's).
    pub fn truth_at(&self, t_s: f64) -> RouteState {
        match self {
            Body::Driven(d) => d.track.at(t_s),
            Body::Scripted(s) => s.motion.state_at(t_s),
        }
    }

    /// The track the simulator moves the robot along; none: its waypoints.
    pub fn track(&self) -> Option<DrivenTrack> {
        match self {
            Body::Driven(d) => Some(d.track.clone()),
            Body::Scripted(_) => None,
        }
    }
}
