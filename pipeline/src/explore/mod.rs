//! Exploration by frontiers (the paper's auditorium trial: the robot maps the building before
//! the responder goes in), sans-IO: an occupancy grid of the floor from the robot's placed
//! scans ([`OccupancyGrid`]) and the frontiers between its known floor and the unknown
//! ([`frontiers`]), the floor the base can use and the travel over it ([`usable`], [`Costs`]),
//! and the frontier worth going to ([`choose_goal`]), and the twist that drives the omni base
//! along the way, slowed for what the live scan sees ([`LocalController`]); and the loop of
//! them, sweeps, blacklisting and the way home included ([`Explorer`]); and the explorer on a
//! robot's LIO poses and wheel odometry ([`Pilot`]).

mod control;
mod explorer;
mod frontier;
mod occupancy;
mod pilot;
mod plan;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_control;
#[cfg(test)]
mod tests_explorer;

pub use control::{clearance_m, BodyTwist, ControlConfig, ControlState, ControlStep, LocalController, Pose2};
pub use explorer::{ExploreConfig, ExploreState, ExploreStep, Explorer};
pub use frontier::{frontiers, is_frontier, Frontier};
pub use occupancy::{Cell, OccupancyConfig, OccupancyGrid};
pub use pilot::{base_pose, between, compose, Pilot, PilotConfig};
pub use plan::{choose_goal, usable, viewpoint, Costs, GoalChoice, PlanConfig};
