//! Exploration as one loop, sans-IO: placed scans grow the grid ([`Explorer::add_scan`]), and
//! once per control period ([`Explorer::step`]) the explorer turns the grid into the base's
//! twist. It sweeps a full turn where it stands (the Avia sees 70 deg), chooses the frontier
//! worth most, drives the planned way there, sweeps again, and so on; a goal it cannot reach
//! (blocked, or no nearer for `stuck_s`) is blacklisted; when no frontier can be reached it
//! drives back to where it started. An operator's stop holds it until released.

use super::control::{BodyTwist, ControlConfig, ControlState, LocalController, Pose2};
use super::frontier::{frontiers, is_frontier};
use super::occupancy::{OccupancyConfig, OccupancyGrid};
use super::plan::{choose_goal, usable, viewpoint, Costs, PlanConfig};
use nalgebra::Vector3;
use std::collections::VecDeque;
use std::f64::consts::TAU;

/// The remembered returns are kept one per cell of this size (m).
const MEMORY_CELL_M: f64 = 0.05;
/// Remembered returns and the grid's occupied cells this near the base reach the controller (m).
const NEAR_M: f64 = 1.5;

/// A viewpoint this near where the base last swept shows nothing the sweep did not (m).
const SAME_PLACE_M: f64 = 0.5;

/// Settings of the loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExploreConfig {
    pub occupancy: OccupancyConfig,
    pub plan: PlanConfig,
    pub control: ControlConfig,
    /// Frontiers of fewer cells are left out.
    pub min_frontier_cells: usize,
    /// The way is planned again this often (s): the grid grows as the base drives.
    pub replan_s: f64,
    /// A goal the base has come no nearer to (by `progress_m`) for this long is blacklisted.
    pub stuck_s: f64,
    pub progress_m: f64,
    /// A full turn in place at the start and at every goal reached.
    pub sweep: bool,
    /// Drive back to the start once no frontier can be reached.
    pub return_home: bool,
    /// The body-band returns of this many of the latest scans are kept and handed to the
    /// controller with the caller's obstacles (0: none).
    pub memory_scans: usize,
    /// A frontier is looked at from between these distances (m), not driven onto: a real
    /// LiDAR sees nothing nearer than its minimum range, so unknown space right beside the
    /// base stays unknown however long it stands there. (0, 0): driven onto, as an ideal
    /// sensor allows.
    pub view_from_m: (f64, f64),
    /// Where the base starts, the floor within this that nothing was seen in is taken as free
    /// floor once the first sweep is done ([`OccupancyGrid::assume_blind_floor`]): the ring a
    /// real LiDAR cannot see around itself (0: none).
    pub blind_radius_m: f64,
}

impl Default for ExploreConfig {
    fn default() -> Self {
        Self {
            occupancy: OccupancyConfig::default(),
            plan: PlanConfig::default(),
            control: ControlConfig::default(),
            min_frontier_cells: 5,
            replan_s: 1.0,
            stuck_s: 6.0,
            progress_m: 0.2,
            sweep: true,
            return_home: true,
            // 4 s at the Avia's 5 Hz of placed scans in the tests and `starc explore`.
            memory_scans: 20,
            blind_radius_m: 0.0,
            view_from_m: (0.0, 0.0),
        }
    }
}

/// What the explorer is doing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ExploreState {
    /// Turning in place to look around; `turned_rad` so far.
    Sweeping { turned_rad: f64 },
    /// Driving to a frontier's goal (world x, y).
    Going { goal_m: [f64; 2] },
    /// No frontier left that can be reached: driving back to the start.
    Returning,
    /// Back at the start with nothing left to explore, or nowhere to go: standing.
    Done,
    /// Held by the operator: standing until released.
    Stopped,
}

/// The command of one period and what the explorer is doing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExploreStep {
    pub twist: BodyTwist,
    pub state: ExploreState,
    /// What the local controller said (None while sweeping, done or stopped).
    pub control: Option<ControlState>,
}

/// The explorer; see the module's documentation.
pub struct Explorer {
    cfg: ExploreConfig,
    grid: OccupancyGrid,
    controller: LocalController,
    state: ExploreState,
    held: bool,
    home_m: [f64; 2],
    path: Vec<[f64; 2]>,
    blacklist: Vec<[f64; 2]>,
    planned_at_s: f64,
    /// The nearest the base has come to the goal, and when.
    best: (f64, f64),
    last_yaw: Option<f64>,
    /// The latest scans' body-band returns (world x, y).
    memory: VecDeque<Vec<[f64; 2]>>,
    /// The first sweep is done (the start's blind floor assumed).
    swept_home: bool,
    /// Where the last sweep was made.
    swept_at: Option<[f64; 2]>,
}

impl Explorer {
    /// An explorer starting at `home` (world x, y), its grid centred there. `None` for a grid
    /// the settings cannot make ([`OccupancyGrid::new`]).
    pub fn new(cfg: ExploreConfig, home: [f64; 2]) -> Option<Self> {
        let grid = OccupancyGrid::new(cfg.occupancy, home)?;
        // Without sweeps, the start's is taken as done: the first step plans.
        let state = ExploreState::Sweeping { turned_rad: if cfg.sweep { 0.0 } else { TAU } };
        Some(Self {
            cfg,
            grid,
            controller: LocalController::new(cfg.control),
            state,
            held: false,
            home_m: home,
            path: Vec::new(),
            blacklist: Vec::new(),
            planned_at_s: f64::NEG_INFINITY,
            best: (f64::INFINITY, 0.0),
            last_yaw: None,
            memory: VecDeque::new(),
            swept_home: false,
            swept_at: None,
        })
    }

    pub fn grid(&self) -> &OccupancyGrid {
        &self.grid
    }

    /// Where the base started (world x, y): where it comes back to.
    pub fn home(&self) -> [f64; 2] {
        self.home_m
    }

    pub fn state(&self) -> ExploreState {
        if self.held {
            ExploreState::Stopped
        } else {
            self.state
        }
    }

    /// Goals given up on (world x, y).
    pub fn blacklist(&self) -> &[[f64; 2]] {
        &self.blacklist
    }

    /// The way being driven (world x, y), empty when none.
    pub fn path(&self) -> &[[f64; 2]] {
        &self.path
    }

    /// One placed scan: the sensor's origin and its returns in the world.
    pub fn add_scan<'a>(&mut self, origin: &Vector3<f64>, points: impl IntoIterator<Item = &'a Vector3<f64>> + Clone) {
        self.grid.add_scan(origin, points.clone());
        self.remember(points);
    }

    /// Keeps the scan's returns in the body band, one per `MEMORY_CELL_M` cell, for the last
    /// `memory_scans` scans: what stood beside the base a moment ago, now out of the Avia's
    /// view and perhaps missing from the grid (a post whose returns split between two cells).
    fn remember<'a>(&mut self, points: impl IntoIterator<Item = &'a Vector3<f64>>) {
        let occ = &self.cfg.occupancy;
        let (lo, hi) = (occ.floor_z_m + occ.max_step_m, occ.floor_z_m + occ.body_height_m);
        let mut kept: Vec<[f64; 2]> = Vec::new();
        let mut cells = std::collections::HashSet::new();
        for p in points.into_iter().filter(|p| p.z > lo && p.z < hi && p.x.is_finite() && p.y.is_finite()) {
            let key = ((p.x / MEMORY_CELL_M).floor() as i64, (p.y / MEMORY_CELL_M).floor() as i64);
            if cells.insert(key) {
                kept.push([p.x, p.y]);
            }
        }
        self.memory.push_back(kept);
        while self.memory.len() > self.cfg.memory_scans {
            self.memory.pop_front();
        }
    }

    /// What the controller avoids besides the caller's obstacles, within `NEAR_M` of `pose`
    /// and in its body frame: the remembered returns, and the grid's occupied cells (the Avia
    /// does not see beside the base, as in a doorway).
    fn around(&self, pose: &Pose2) -> Vec<[f64; 2]> {
        let remembered = self.memory.iter().flatten().filter(|w| (w[0] - pose.x_m).hypot(w[1] - pose.y_m) < NEAR_M);
        let occupied = self.grid.occupied_near(pose.x_m, pose.y_m, NEAR_M);
        remembered.chain(occupied.iter()).map(|w| pose.to_body(*w)).collect()
    }

    /// The operator's stop: the base stands from the next step until [`Explorer::release`].
    pub fn hold(&mut self) {
        self.held = true;
        self.controller.reset();
    }

    pub fn release(&mut self) {
        self.held = false;
        self.planned_at_s = f64::NEG_INFINITY;
    }

    /// One control period at `now_s`: the twist for the base at `pose`. `obstacles` (body x,
    /// y) are what the caller knows beyond the placed scans (someone seen in a scan not placed
    /// yet); the explorer adds its memory and the grid's occupied cells around the base.
    pub fn step(&mut self, now_s: f64, pose: &Pose2, obstacles: &[[f64; 2]], dt_s: f64) -> ExploreStep {
        let turned = self.turned_since_last(pose.yaw_rad);
        if pose.x_m.is_finite() && pose.y_m.is_finite() {
            self.grid.mark_driven(pose.x_m, pose.y_m, self.cfg.control.robot_radius_m);
        }
        if self.held {
            return standing(ExploreState::Stopped);
        }
        match self.state {
            ExploreState::Sweeping { turned_rad } => {
                let turned_rad = turned_rad + turned;
                if turned_rad < TAU {
                    self.state = ExploreState::Sweeping { turned_rad };
                    let twist = BodyTwist { wz_rad_s: self.cfg.control.max_turn_rad_s, ..BodyTwist::ZERO };
                    return ExploreStep { twist, state: self.state, control: None };
                }
                if !self.swept_home && self.cfg.blind_radius_m > 0.0 {
                    self.grid.assume_blind_floor(self.home_m[0], self.home_m[1], self.cfg.blind_radius_m);
                }
                self.swept_home = true;
                self.swept_at = Some([pose.x_m, pose.y_m]);
                self.state = self.next_state(now_s, pose);
            }
            ExploreState::Going { .. } | ExploreState::Returning if now_s - self.planned_at_s >= self.cfg.replan_s => {
                self.replan(now_s, pose);
            }
            _ => {}
        }
        self.drive(now_s, pose, obstacles, dt_s)
    }

    /// The controller along the way, and what its outcome means for the loop.
    fn drive(&mut self, now_s: f64, pose: &Pose2, obstacles: &[[f64; 2]], dt_s: f64) -> ExploreStep {
        let goal = match self.state {
            ExploreState::Going { goal_m } => goal_m,
            ExploreState::Returning => self.home_m,
            _ => return standing(self.state),
        };
        let mut around = self.around(pose);
        around.extend_from_slice(obstacles);
        let step = self.controller.step(pose, &self.path, &around, dt_s);
        // Progress towards where the way ends (a frontier's viewpoint may lie away from it).
        let aim = self.path.last().copied().unwrap_or(goal);
        let distance = (aim[0] - pose.x_m).hypot(aim[1] - pose.y_m);
        if distance < self.best.0 - self.cfg.progress_m {
            self.best = (distance, now_s);
        }
        match (step.state, self.state) {
            (ControlState::Arrived, ExploreState::Going { .. }) => {
                self.state = if self.cfg.sweep {
                    ExploreState::Sweeping { turned_rad: 0.0 }
                } else {
                    self.next_state(now_s, pose)
                };
            }
            (ControlState::Arrived, _) => self.state = ExploreState::Done,
            (ControlState::Idle, _) => self.replan(now_s, pose),
            (_, ExploreState::Returning) if now_s - self.best.1 > self.cfg.stuck_s => self.state = self.nowhere(),
            _ if now_s - self.best.1 > self.cfg.stuck_s => {
                self.blacklist.push(goal);
                self.replan(now_s, pose);
            }
            _ => {}
        }
        ExploreStep { twist: step.twist, state: self.state, control: Some(step.state) }
    }

    /// The way is planned again: to the same goal while it is still a frontier's, else to the
    /// next one.
    fn replan(&mut self, now_s: f64, pose: &Pose2) {
        if let ExploreState::Going { goal_m } = self.state {
            let still = self.grid.cell_of(goal_m[0], goal_m[1]).is_some_and(|c| is_frontier(&self.grid, c))
                && !self.blacklist.contains(&goal_m);
            if still && self.way_to_view(pose, goal_m) {
                self.planned_at_s = now_s;
                return;
            }
        }
        self.state = self.next_state(now_s, pose);
    }

    /// Where to go from `pose`, its way planned: the best frontier, else home, else nowhere. A
    /// frontier there is no way to look at, or only from where the base has just swept, is
    /// blacklisted and the next one tried.
    fn next_state(&mut self, now_s: f64, pose: &Pose2) -> ExploreState {
        self.planned_at_s = now_s;
        self.best = (f64::INFINITY, now_s);
        let Some(costs) = self.costs_from(pose) else { return self.nowhere() };
        let found = frontiers(&self.grid, self.cfg.min_frontier_cells);
        while let Some(choice) = choose_goal(&self.grid, &found, &costs, &self.blacklist, &self.cfg.plan) {
            let goal_m = self.grid.centre_of(choice.goal);
            if self.plan_view(&costs, goal_m) {
                return ExploreState::Going { goal_m };
            }
            self.blacklist.push(goal_m);
        }
        let home = self.home_m;
        let at_home = (home[0] - pose.x_m).hypot(home[1] - pose.y_m) <= self.cfg.control.goal_tolerance_m;
        if self.cfg.return_home && !at_home && self.way_to(pose, home) {
            return ExploreState::Returning;
        }
        self.nowhere()
    }

    /// Plans the way from `pose` to where the frontier cell at `goal_m` is looked at from.
    fn way_to_view(&mut self, pose: &Pose2, goal_m: [f64; 2]) -> bool {
        match self.costs_from(pose) {
            Some(costs) => self.plan_view(&costs, goal_m),
            None => false,
        }
    }

    /// Sets the way (by `costs`) to where the frontier cell at `goal_m` is looked at from
    /// ([`ExploreConfig::view_from_m`]; the cell itself with (0, 0)); false when there is no
    /// such place, or it is where the base last swept (it has looked from there).
    fn plan_view(&mut self, costs: &Costs, goal_m: [f64; 2]) -> bool {
        let Some(target) = self.grid.cell_of(goal_m[0], goal_m[1]) else { return false };
        let (near, far) = self.cfg.view_from_m;
        let view = if far > 0.0 { viewpoint(&self.grid, costs, target, near, far) } else { Some(target) };
        let Some(view) = view else { return false };
        let [x, y] = self.grid.centre_of(view);
        if far > 0.0 && self.swept_at.is_some_and(|s| (s[0] - x).hypot(s[1] - y) < SAME_PLACE_M) {
            return false;
        }
        let path = self.world_path(costs, view);
        if path.is_empty() {
            return false;
        }
        self.path = path;
        true
    }

    fn nowhere(&mut self) -> ExploreState {
        self.path.clear();
        ExploreState::Done
    }

    /// Plans the way from `pose` to `goal`; false when it cannot be reached.
    fn way_to(&mut self, pose: &Pose2, goal: [f64; 2]) -> bool {
        let (Some(costs), Some(target)) = (self.costs_from(pose), self.grid.cell_of(goal[0], goal[1])) else {
            return false;
        };
        let path = self.world_path(&costs, target);
        if path.is_empty() {
            return false;
        }
        self.path = path;
        true
    }

    /// Travel costs over the usable floor from `pose` (None off the grid).
    fn costs_from(&self, pose: &Pose2) -> Option<Costs> {
        let robot = self.grid.cell_of(pose.x_m, pose.y_m)?;
        Some(Costs::from(&self.grid, &usable(&self.grid, robot, self.cfg.plan.robot_radius_m), robot))
    }

    /// The cheapest way to `goal` as cell centres (world x, y); empty when it was not reached.
    fn world_path(&self, costs: &Costs, goal: (usize, usize)) -> Vec<[f64; 2]> {
        costs.path_to(goal).into_iter().map(|c| self.grid.centre_of(c)).collect()
    }

    /// How far the base has turned since the last step (rad, unsigned).
    fn turned_since_last(&mut self, yaw_rad: f64) -> f64 {
        let turned = self.last_yaw.filter(|_| yaw_rad.is_finite()).map_or(0.0, |last| {
            let d = yaw_rad - last;
            d.sin().atan2(d.cos()).abs()
        });
        if yaw_rad.is_finite() {
            self.last_yaw = Some(yaw_rad);
        }
        turned
    }
}

fn standing(state: ExploreState) -> ExploreStep {
    ExploreStep { twist: BodyTwist::ZERO, state, control: None }
}
