//! Exploration by frontiers (the paper's auditorium trial: the robot maps the building before
//! the responder goes in), sans-IO: an occupancy grid of the floor from the robot's placed
//! scans ([`OccupancyGrid`]) and the frontiers between its known floor and the unknown
//! ([`frontiers`]), the floor the base can use and the travel over it ([`usable`], [`Costs`]),
//! and the frontier worth going to ([`choose_goal`]). Local control and driving the base come
//! on top of these.

mod frontier;
mod occupancy;
mod plan;
#[cfg(test)]
mod tests;

pub use frontier::{frontiers, is_frontier, Frontier};
pub use occupancy::{Cell, OccupancyConfig, OccupancyGrid};
pub use plan::{choose_goal, usable, Costs, GoalChoice, PlanConfig};
