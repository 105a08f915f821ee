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

/// Three mock CiA 402 drives (ids 1-3) behind slcan on a pty at `dir/can`, and `dir/base.toml`,
/// which drives them with acceleration limits `accel` (m/s^2, rad/s^2).
#[allow(dead_code)] // not every test that includes this file starts drives
pub async fn cia402_drives(dir: &Path, accel: (f64, f64)) -> (starc_hil::motors::MockMotors, std::path::PathBuf) {
    use starc_hil::motors::{MockMotors, MockMotorsConfig, MockProtocol};
    let can = dir.join("can");
    let config = MockMotorsConfig {
        protocol: MockProtocol::Cia402,
        port: can.clone(),
        ids: vec![1, 2, 3],
        ..Default::default()
    };
    let mock = MockMotors::spawn(config).await.unwrap_or_else(|e| panic!("mock drives: {e}"));
    let base_toml = dir.join("base.toml");
    std::fs::write(&base_toml, slcan_base_toml(&can, "cia402", "{ id = 1 }, { id = 2 }, { id = 3 }", accel, ""))
        .unwrap_or_else(|e| panic!("{e}"));
    (mock, base_toml)
}
