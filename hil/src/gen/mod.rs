//! Generated buildings for held-out evaluation: `generate(seed, family)` gives an ordinary
//! scenario file (flats, offices, warehouses, halls, labs) with furniture, people and routes
//! planned on the floor plan, checked as every scenario is ([`crate::sim::route_check`]).
//!
//! Seeds below [`TEST_SEEDS_FROM`] are for development and tuning; seeds from it up are the
//! test set, reported on and never tuned on (docs/eval.md).

pub mod families;
pub mod furnish;
pub mod grid;
pub mod layout;
pub mod people;
pub mod plan;
pub mod routes;

use crate::error::{HilError, Result};
use crate::rng::{hash2, SplitMix64};
use crate::sim::obstacles::{FloorPlan, Footprint, ObstacleKind};
use crate::sim::route_check::check_routes;
use crate::sim::scenario::Scenario;
use layout::Dice;
use plan::{Plan, PlanPerson, Routes};

/// The first seed of the test set.
pub const TEST_SEEDS_FROM: u64 = 1000;
/// Layouts tried per seed before giving up (a layout fails when no route reaches its people).
const ATTEMPTS: u64 = 40;
/// Room a person takes for the robot's and the responder's route planning.
const PERSON_HALF_M: f64 = 0.3;

/// A family of buildings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Family {
    Flat,
    Office,
    Warehouse,
    Hall,
    Lab,
}

impl Family {
    pub const ALL: [Family; 5] = [Family::Flat, Family::Office, Family::Warehouse, Family::Hall, Family::Lab];

    pub fn name(self) -> &'static str {
        match self {
            Family::Flat => "flat",
            Family::Office => "office",
            Family::Warehouse => "warehouse",
            Family::Hall => "hall",
            Family::Lab => "lab",
        }
    }

    /// The family a seed gets under `--family any`: in turn, so that any five seeds in a row
    /// hold one building of each family.
    pub fn of_seed(seed: u64) -> Family {
        Family::ALL[(seed % Family::ALL.len() as u64) as usize]
    }
}

impl std::str::FromStr for Family {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Family::ALL.into_iter().find(|f| f.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Family::ALL.iter().map(|f| f.name()).collect();
            format!("unknown family {s:?} (one of {}, or any)", names.join(", "))
        })
    }
}

impl std::fmt::Display for Family {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Whether a seed is in the test set.
pub fn is_test_seed(seed: u64) -> bool {
    seed >= TEST_SEEDS_FROM
}

/// A generated building: its scenario file's text and the scenario parsed from it.
#[derive(Clone, Debug)]
pub struct Generated {
    pub seed: u64,
    pub family: Family,
    /// Which layout of the seed was used (0 unless earlier ones had no routes).
    pub attempt: u64,
    pub text: String,
    pub scenario: Scenario,
    pub people: usize,
}

/// The building of `seed` in `family` (or the seed's own family when none).
pub fn generate(seed: u64, family: Option<Family>) -> Result<Generated> {
    let family = family.unwrap_or_else(|| Family::of_seed(seed));
    let mut last = String::new();
    for attempt in 0..ATTEMPTS {
        match try_layout(seed, family, attempt) {
            Ok(g) => return Ok(g),
            Err(e) => last = e.to_string(),
        }
    }
    Err(HilError::Scenario {
        origin: format!("generated {family} seed {seed}"),
        line: None,
        reason: format!("no valid layout in {ATTEMPTS} attempts; the last: {last}"),
    })
}

fn try_layout(seed: u64, family: Family, attempt: u64) -> Result<Generated> {
    let origin = format!("generated {family} seed {seed} attempt {attempt}");
    let mut d = Dice(SplitMix64::new(hash2(seed, attempt)));
    let building = families::build(&mut d, family);
    let mut plan = Plan {
        name: format!("{family}-{seed}"),
        description: format!("A generated {family} (seed {seed})"),
        floor: building.outline.inset(-1.0),
        ceiling_m: building.ceiling_m,
        floor_material: building.floor_material,
        walls: building.walls.clone(),
        regions: building.regions.clone(),
        furniture: building.furniture.items.clone(),
        people: Vec::new(),
        entry: building.entry,
        routes: Routes {
            robot: vec![building.entry],
            robot_speed_m_s: 0.5,
            responder: vec![[building.entry[0], building.entry[1]]],
            responder_start_s: 0.0,
            responder_speed_m_s: 1.0,
            duration_s: 30.0,
        },
    };
    let bare = FloorPlan::of(&Scenario::parse(&plan.to_toml(), &origin)?);
    plan.people = people::place(&mut d, &building, &grid::Grid::of(&bare));
    let mut floor = bare.clone();
    floor.obstacles.extend(plan.people.iter().flat_map(person_footprints));
    let routes = routes::plan(&mut d, (&building, &bare), &plan.people, &grid::Grid::of(&floor))
        .map_err(|e| HilError::Scenario { origin: origin.clone(), line: None, reason: e.to_string() })?;
    plan.routes = routes;
    let text = plan.to_toml();
    let scenario = Scenario::parse(&text, &origin)?;
    if let Some(v) = check_routes(&scenario).first() {
        return Err(HilError::Scenario { origin, line: None, reason: v.to_string() });
    }
    Ok(Generated { seed, family, attempt, text, scenario, people: plan.people.len() })
}

/// What a person takes of the floor for the routes: their spot (a lying person's length), and a
/// walker's whole walk.
fn person_footprints(p: &PlanPerson) -> Vec<Footprint> {
    let half = if p.pose == crate::sim::scenario::PoseKind::Lying { 1.0 } else { PERSON_HALF_M };
    let top_z_m = p.base_z_m + p.height_m;
    let spot = Footprint {
        centre: p.at,
        half_m: [half, half],
        yaw_rad: 0.0,
        kind: ObstacleKind::Furniture,
        name: p.name.clone(),
        top_z_m,
    };
    let line: Vec<[f64; 2]> = std::iter::once(p.at).chain(p.path.iter().copied()).collect();
    let walks = line.windows(2).map(|w| {
        let (dx, dy) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
        Footprint {
            centre: [(w[0][0] + w[1][0]) / 2.0, (w[0][1] + w[1][1]) / 2.0],
            half_m: [dx.hypot(dy) / 2.0 + PERSON_HALF_M, PERSON_HALF_M],
            yaw_rad: dy.atan2(dx),
            kind: ObstacleKind::Furniture,
            name: p.name.clone(),
            top_z_m,
        }
    });
    std::iter::once(spot).chain(walks).collect()
}

#[cfg(test)]
mod tests;
