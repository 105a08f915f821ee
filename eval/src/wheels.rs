//! The simulated base's wheels: its feedback layout from a run's scenario, and its wheel
//! odometry from the run's `robot_can.log` (on the Avias' PTP clock), for the offline mission,
//! the live nodes and the benches alike.

use crate::error::{EvalError, Result};
use starc_bridge::wheels::{read_wheel_log, MotorFeedback, WheelFeedback};
use starc_hil::sim::scenario::{MotorProtocol, Robot, Scenario};
use starc_pipeline::lio::WheelSample;
use std::path::Path;

/// The base the scenario's robot has: its wheel layout and motor controllers.
pub fn sim_wheel_feedback(robot: &Robot) -> WheelFeedback {
    let motors = match robot.motors {
        MotorProtocol::C620 => MotorFeedback::C620,
        MotorProtocol::Cia402 => MotorFeedback::Cia402,
    };
    WheelFeedback::plain(starc_hil::sim::wheels::default_geometry(robot.wheels), motors)
}

/// The base of the run in `dir`, from its scenario.toml.
pub fn run_wheel_feedback(dir: &Path) -> Result<WheelFeedback> {
    let path = dir.join("scenario.toml");
    let (scenario, _) = Scenario::load(&path.to_string_lossy())
        .map_err(|e| EvalError::BadFile { path: path.clone(), reason: e.to_string() })?;
    Ok(sim_wheel_feedback(scenario.robot.get_ref()))
}

/// The wheel odometry of the run in `dir`, decoded with `base`.
pub fn run_wheel_samples(dir: &Path, base: &WheelFeedback) -> Result<Vec<WheelSample>> {
    read_wheel_log(&dir.join("robot_can.log"), base, 0).map_err(|e| EvalError::Input(e.to_string()))
}
