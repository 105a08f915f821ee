//! The scorer of a closed-loop run: contacts of the base with the world (from the true track),
//! the floor the explorer has come to know over time and its share of the floor the base could
//! reach ([`Reachable`]), its planning time, the bus's counters.
//! It reads the simulator's truth; the loop's decisions never see what it computes.

use super::bus::BusCounts;
use super::reach::Reachable;
use crate::explore_sim::disc_hit;
use crate::{quantiles, Quantiles};
use starc_hil::sim::motion::RouteState;
use starc_hil::sim::scenario::Scenario;
use starc_hil::sim::world::World;
use starc_pipeline::explore::{between, compose, Explorer, Pose2};

/// The base's contact is checked this often.
const CONTACT_EVERY_NS: u64 = 50_000_000;
/// The known floor is sampled this often.
const AREA_EVERY_NS: u64 = 1_000_000_000;

/// What a closed-loop run did: `DIR/exploration.json`, and report.json's
/// `exploration.closed_loop`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LoopReport {
    /// "closed_loop": the explorer drove the simulated base over CAN on its LIO's poses;
    /// "scripted": the robot followed its waypoints, its grid built the same way.
    pub mode: &'static str,
    /// Traversable floor the explorer's grid knows (m²), each second of simulator time.
    pub timeline: Vec<(f64, f64)>,
    pub final_area_m2: f64,
    /// The floor the base could reach from its start (m², the simulator's truth: 0.1 m cells
    /// its disc fits in, flooded from the start), and the share of it the explorer's grid
    /// knows as traversable each second (from the LIO's first pose on), and when that share
    /// first reached 95 % (null: never).
    pub reachable_m2: f64,
    pub coverage: Vec<(f64, f64)>,
    pub coverage_95_s: Option<f64>,
    /// When the explorer was back home with nothing left (simulator time), if it was.
    pub done_s: Option<f64>,
    /// Checks (every 50 ms) in which the base's disc touched a surface or a person, and the
    /// separate contacts they made.
    pub contact_periods: usize,
    pub contacts: usize,
    /// Where each contact began.
    pub contact_log: Vec<Contact>,
    /// The true track's length.
    pub distance_m: f64,
    /// The explorer's control steps, planning included (ms, wall time).
    pub step_ms: Quantiles,
    /// Goals given up.
    pub blacklisted: usize,
    pub bus: BusCounts,
    /// Faults the base driver latched (the base halts on one).
    pub base_faults: usize,
}

/// The start of one contact: when, where the base's centre truly was, and what it touched.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Contact {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
    /// 0: the building (walls, furniture); k: person k (as in people.csv).
    pub label: u16,
    /// The lowest of the heights checked (0.1, 0.5, 1.0 m) at which it touched.
    pub height_m: f64,
}

pub(super) struct Score {
    world: World,
    reach: Reachable,
    /// Where the explorer's grid (the LIO's world) lies in the simulator's.
    world_from_grid: Option<[f64; 3]>,
    coverage: Vec<(f64, f64)>,
    radius_m: f64,
    next_contact_ns: u64,
    next_area_ns: u64,
    timeline: Vec<(f64, f64)>,
    touching: bool,
    contact_log: Vec<Contact>,
    contact_periods: usize,
    last_xy: Option<[f64; 2]>,
    distance_m: f64,
    step_ms: Vec<f64>,
    done_s: Option<f64>,
    now_ns: u64,
}

impl Score {
    pub(super) fn new(scenario: &Scenario, radius_m: f64, start: [f64; 2]) -> Self {
        let world = World::new(scenario);
        let reach = Reachable::from_truth(scenario, &world, start, radius_m, 0.0);
        Self {
            world,
            reach,
            world_from_grid: None,
            coverage: Vec::new(),
            radius_m,
            next_contact_ns: 0,
            next_area_ns: 0,
            timeline: Vec::new(),
            touching: false,
            contact_log: Vec::new(),
            contact_periods: 0,
            last_xy: None,
            distance_m: 0.0,
            step_ms: Vec::new(),
            done_s: None,
            now_ns: 0,
        }
    }

    /// At simulator time `t_ns`, the base truly at `s`: contacts and distance, the known floor.
    pub(super) fn sample(&mut self, s: &RouteState, explorer: Option<&Explorer>, t_ns: u64) {
        self.now_ns = t_ns;
        if t_ns >= self.next_contact_ns {
            self.next_contact_ns = t_ns + CONTACT_EVERY_NS;
            let t_s = t_ns as f64 * 1e-9;
            if let Some([x, y]) = self.last_xy {
                self.distance_m += (s.x - x).hypot(s.y - y);
            }
            self.last_xy = Some([s.x, s.y]);
            let now = disc_hit(&self.world, &self.world.bodies_at(t_s), [s.x, s.y], self.radius_m);
            if let Some((label, height_m)) = now {
                self.contact_periods += 1;
                if !self.touching {
                    self.contact_log.push(Contact { t_s, x_m: s.x, y_m: s.y, label, height_m });
                }
            }
            self.touching = now.is_some();
        }
        if t_ns >= self.next_area_ns {
            self.next_area_ns = t_ns + AREA_EVERY_NS;
            let area = explorer.map_or(0.0, |e| e.grid().traversable_area_m2());
            self.timeline.push((t_ns as f64 * 1e-9, area));
            if let (Some(e), Some(tie)) = (explorer, self.world_from_grid) {
                self.coverage.push((t_ns as f64 * 1e-9, self.reach.coverage(e.grid(), tie)));
            }
        }
    }

    /// The LIO's first pose of the base and the true one at the same instant: they tie the
    /// explorer's grid to the world.
    pub(super) fn tie(&mut self, lio: &Pose2, truth: &Pose2) {
        if self.world_from_grid.is_none() {
            // truth = world_from_grid ∘ lio
            let origin = Pose2 { x_m: 0.0, y_m: 0.0, yaw_rad: 0.0 };
            let w = compose(truth, &between(lio, &origin));
            self.world_from_grid = Some([w.x_m, w.y_m, w.yaw_rad]);
        }
    }

    /// One control step that took `ms`; `done` when the explorer is back home with nothing left.
    pub(super) fn control_step(&mut self, ms: f64, done: bool) {
        self.step_ms.push(ms);
        if done && self.done_s.is_none() {
            self.done_s = Some(self.now_ns as f64 * 1e-9);
        }
    }

    pub(super) fn report(
        &self,
        mode: &'static str,
        explorer: Option<&Explorer>,
        bus: BusCounts,
        base_faults: usize,
    ) -> LoopReport {
        LoopReport {
            mode,
            timeline: self.timeline.clone(),
            final_area_m2: explorer.map_or(0.0, |e| e.grid().traversable_area_m2()),
            reachable_m2: self.reach.area_m2(),
            coverage: self.coverage.clone(),
            coverage_95_s: self.coverage.iter().find(|c| c.1 >= 0.95).map(|c| c.0),
            done_s: self.done_s,
            contact_periods: self.contact_periods,
            contacts: self.contact_log.len(),
            contact_log: self.contact_log.clone(),
            distance_m: self.distance_m,
            step_ms: quantiles(&self.step_ms),
            blacklisted: explorer.map_or(0, |e| e.blacklist().len()),
            bus,
            base_faults,
        }
    }
}
