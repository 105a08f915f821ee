//! A three-wheel omni base on an slcan port, as TOML, for the tests that drive the mock motors.

use std::path::Path;

/// The base's config: `protocol` ("c620" or "cia402"), the wheels' ids (`{ id = 1 }, ...`),
/// acceleration limits (m/s^2, rad/s^2), and `extra` lines appended (a `[motors.cia402]`
/// table, ...).
pub fn slcan_base_toml(port: &Path, protocol: &str, ids: &str, accel: (f64, f64), extra: &str) -> String {
    format!(
        r#"
watchdog_ms = 200
[can]
transport = "slcan"
port = "{}"
status_poll_ms = 100
[kinematics]
model = "omni3"
wheel_radius_m = 0.05
center_to_wheel_m = 0.2
[limits]
max_vx_m_s = 1.0
max_vy_m_s = 1.0
max_wz_rad_s = 2.0
max_accel_m_s2 = {:?}
max_alpha_rad_s2 = {:?}
max_wheel_rad_s = 40.0
[motors]
protocol = "{protocol}"
wheels = [{ids}]
{extra}
"#,
        port.display(),
        accel.0,
        accel.1
    )
}
