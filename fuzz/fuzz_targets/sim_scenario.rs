#![no_main]
//! Scenario files (`starc sim FILE`, and what `starc gen` writes): any text either parses into a
//! scenario or is refused with an error; a parsed one gets through the route check, the floor
//! plan and its picture without a panic.
use libfuzzer_sys::fuzz_target;
use starc_hil::sim::plan_svg::plan_svg;
use starc_hil::sim::route_check::check_routes;
use starc_hil::sim::scenario::Scenario;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(s) = Scenario::parse(text, "fuzz") {
        // Keep each run short: the check walks every leg in 2 cm steps.
        let legs = s.robot.get_ref().waypoints.len() + s.responder.get_ref().waypoints.len();
        if legs < 64 && s.walls.len() + s.boxes.len() + s.furniture.len() < 256 {
            let _ = check_routes(&s);
            let _ = plan_svg(&s);
        }
    }
});
