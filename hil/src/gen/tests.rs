use super::*;
use crate::sim::route_check::check_routes;

#[test]
fn a_hundred_seeds_generate_valid_buildings_with_clear_routes() {
    let mut per_family = std::collections::BTreeMap::new();
    for seed in 0..100 {
        let g = match generate(seed, None) {
            Ok(g) => g,
            Err(e) => panic!("seed {seed}: {e}"),
        };
        let again = Scenario::parse(&g.text, "again");
        assert!(again.is_ok(), "seed {seed}: {:?}", again.err());
        let violations = check_routes(&g.scenario);
        assert!(violations.is_empty(), "seed {seed}: {}", violations[0]);
        assert!((1..=8).contains(&g.people), "seed {seed}: {} people", g.people);
        let floor = g.scenario.floors.first().map(|f| f.get_ref().clone());
        for p in &g.scenario.people {
            let p = p.get_ref();
            let on = floor.as_ref().is_some_and(|f| {
                (f.min[0] + 1.0..f.max[0] - 1.0).contains(&p.at[0])
                    && (f.min[1] + 1.0..f.max[1] - 1.0).contains(&p.at[1])
            });
            assert!(on, "seed {seed}: {} at {:?} is outside the building", p.name, p.at);
        }
        assert!(g.scenario.robot.get_ref().waypoints.len() >= 2, "seed {seed}: the robot does not move");
        assert!(g.scenario.responder.get_ref().waypoints.len() >= 2, "seed {seed}: the responder does not move");
        *per_family.entry(g.family).or_insert(0) += 1;
    }
    assert_eq!(per_family.len(), Family::ALL.len(), "{per_family:?}");
}

#[test]
fn the_same_seed_gives_the_same_file_and_families_differ() {
    let a = generate(7, Some(Family::Flat)).map(|g| g.text).unwrap_or_default();
    let b = generate(7, Some(Family::Flat)).map(|g| g.text).unwrap_or_default();
    assert!(!a.is_empty() && a == b);
    let c = generate(8, Some(Family::Flat)).map(|g| g.text).unwrap_or_default();
    assert_ne!(a, c);
    for family in Family::ALL {
        let g = generate(3, Some(family));
        assert!(g.as_ref().is_ok_and(|g| g.family == family), "{family}: {:?}", g.err());
    }
}

#[test]
fn families_parse_by_name_and_test_seeds_start_at_1000() {
    assert_eq!("warehouse".parse::<Family>(), Ok(Family::Warehouse));
    assert!("castle".parse::<Family>().is_err_and(|e| e.contains("flat, office")));
    assert!(!is_test_seed(999) && is_test_seed(1000));
}
