//! Small scenes that tests in several crates share.

/// A wall at x = 4 with a 1 m door at y = 1.5, someone hidden behind the wall (label 1) and
/// someone in the doorway (label 2), both facing the origin; no floor, no robot or responder
/// (add `[robot]` and `[responder]` tables after it).
pub const WALL_AND_DOORWAY: &str = r#"
name = "wall and doorway"
[[walls]]
from = [4, -3]
to = [4, 3]
doors = [{ at_m = 4.5, width_m = 1.0 }]
[[people]]
name = "hidden"
at = [6, 0]
yaw_deg = 180
[[people]]
name = "in the doorway"
at = [6, 1.5]
yaw_deg = 180
"#;
