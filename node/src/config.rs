//! `robot.toml` and `fpv.toml`: what each node runs (examples in config/, every key documented
//! there).

use crate::error::{NodeError, Result};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::Deserialize;
use starc_link::LinkConfig;
use starc_livox::live::DriverConfig;
use starc_pipeline::ar::{CameraModel, RenderConfig};
use starc_pipeline::lio::{LioConfig, LioFile};
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};

/// The robot node: its Avia, the LIO, detection, the map it shares, the link, a recording.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotNodeConfig {
    /// The Livox driver (host address and ports, discovery, devices to connect to).
    #[serde(default)]
    pub livox: DriverConfig,
    /// The robot's Avia; none: the first device whose data arrives. It is also the one device
    /// the driver accepts (added to `livox.accept_ips`) unless `[livox]` names others.
    #[serde(default)]
    pub lidar_ip: Option<Ipv4Addr>,
    /// A LIO config file (config/lio.toml); none: the defaults (internal IMU).
    #[serde(default)]
    pub lio: Option<PathBuf>,
    /// The person detector (`[detect]`: `kind = "trees" | "geometric" | "pointpillars"` and any field of
    /// config/detect.toml); none: the defaults.
    #[serde(default)]
    pub detect: starc_pipeline::detect::DetectConfig,
    /// Changed map tiles go to the rig this often.
    #[serde(default = "default_map_period_ms")]
    pub map_period_ms: u64,
    /// The base's wheels for the LIO (`[wheels]`: its bus and its driver's config); none: the
    /// LIO runs on the LiDAR and IMU alone.
    #[serde(default)]
    pub wheels: Option<crate::wheels::WheelsConfig>,
    /// Record the robot's points, IMU, poses and detections (MCAP, ROS 2 types) here.
    #[serde(default)]
    pub record: Option<PathBuf>,
    /// With `record`: `fdatasync` every chunk (once a second), so a power cut loses no more
    /// than a crash does; costs a disk flush a second.
    #[serde(default)]
    pub record_fsync: bool,
    pub link: LinkConfig,
    /// The ROS 2 bridge (docs/ros2.md): off unless `enabled`.
    #[serde(default)]
    pub ros2: starc_link::ros2::Ros2Config,
    /// The robot explores on its own (`[explore]`, docs/explore.md): off unless `enabled`.
    #[serde(default)]
    pub explore: Option<crate::explore::ExploreNodeConfig>,
}

fn default_map_period_ms() -> u64 {
    1000
}

/// Where the responder is expected to start, in the robot's map frame.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartPose {
    pub position_m: [f64; 3],
    #[serde(default)]
    pub yaw_deg: f64,
}

impl StartPose {
    pub fn isometry(&self) -> Isometry3<f64> {
        let [x, y, z] = self.position_m;
        Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::from_euler_angles(0.0, 0.0, self.yaw_deg.to_radians()),
        )
    }
}

/// The camera on the rig: intrinsics and its pose on the rig's LiDAR.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraMountConfig {
    #[serde(flatten)]
    pub model: CameraModel,
    /// Camera (optical frame: x right, y down, z forward) in the LiDAR frame.
    pub translation_m: [f64; 3],
    /// The same rotation as a quaternion (x, y, z, w).
    pub quaternion_xyzw: [f64; 4],
}

impl CameraMountConfig {
    pub fn lidar_t_camera(&self) -> Result<Isometry3<f64>> {
        let [x, y, z, w] = self.quaternion_xyzw;
        let q = nalgebra::Quaternion::new(w, x, y, z);
        let n = q.norm();
        if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
            return Err(NodeError::Config(format!("camera.quaternion_xyzw must be a unit quaternion (norm {n})")));
        }
        let [tx, ty, tz] = self.translation_m;
        Ok(Isometry3::from_parts(Translation3::new(tx, ty, tz), UnitQuaternion::from_quaternion(q)))
    }
}

/// The rig node: its Avia, its LIO, alignment to the robot's map, the AR view and its outputs.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FpvNodeConfig {
    #[serde(default)]
    pub livox: DriverConfig,
    #[serde(default)]
    pub lidar_ip: Option<Ipv4Addr>,
    #[serde(default)]
    pub lio: Option<PathBuf>,
    /// An AR render config file (config/ar.toml); none: the defaults.
    #[serde(default)]
    pub render: Option<PathBuf>,
    pub camera: CameraMountConfig,
    /// Seeds and gates the first alignment; none: the robot's map origin (the responder starts
    /// where the robot started).
    #[serde(default)]
    pub expected_start: Option<StartPose>,
    /// A first alignment farther than this from the expected start is refused; `inf` (TOML
    /// `start_gate_m = inf`): no gate, any first alignment is taken.
    #[serde(default = "default_start_gate_m")]
    pub start_gate_m: f64,
    /// A first alignment is applied once independent searches have found it again, without a
    /// refusal between them, over this long (s; 0: the first accepted one at once). One window
    /// can fit a room like another; that rarely survives the next seconds (docs/align.md).
    #[serde(default = "default_confirm_first_s")]
    pub confirm_first_s: f64,
    /// Both LiDARs on one PTP clock (the robot's grandmaster): detections are placed in time by
    /// their LiDAR stamps. False: through the hosts' clocks and the link's offset estimate.
    #[serde(default = "yes")]
    pub shared_lidar_clock: bool,
    #[serde(default)]
    pub view: starc_view::ViewConfig,
    /// Record the rig's points, IMU, world pose and AR frames here.
    #[serde(default)]
    pub record: Option<PathBuf>,
    /// With `record`: `fdatasync` every chunk, as for the robot.
    #[serde(default)]
    pub record_fsync: bool,
    /// With `record`: keep every Nth AR frame in the recording.
    #[serde(default = "default_record_frames_every")]
    pub record_frames_every: u64,
    pub link: LinkConfig,
    /// The ROS 2 bridge (docs/ros2.md): off unless `enabled`.
    #[serde(default)]
    pub ros2: starc_link::ros2::Ros2Config,
}

/// The driver's config with the node's own Avia named in it (`accept_ips`), so that a config
/// giving only `lidar_ip` takes that device and no other one that broadcasts on the network.
pub fn driver_for(livox: &DriverConfig, lidar_ip: Option<Ipv4Addr>) -> DriverConfig {
    let mut livox = livox.clone();
    if let Some(ip) = lidar_ip {
        if !livox.accept_ips.contains(&ip) {
            livox.accept_ips.push(ip);
        }
    }
    livox
}

fn yes() -> bool {
    true
}

fn default_start_gate_m() -> f64 {
    2.0
}

fn default_confirm_first_s() -> f64 {
    starc_pipeline::mission::CONFIRM_FIRST_S
}

fn default_record_frames_every() -> u64 {
    5
}

fn read(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|source| NodeError::Read { path: path.into(), source })
}

/// A node config file; relative paths inside it are taken from the file's directory.
pub fn load<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = read(path)?;
    toml::from_str(&text).map_err(|source| NodeError::Toml { path: path.into(), source })
}

pub fn lio_config(path: Option<&Path>) -> Result<LioConfig> {
    let Some(path) = path else { return Ok(LioConfig::default()) };
    let bad = |source| NodeError::File { path: path.into(), source };
    LioFile::from_toml(&read(path)?).and_then(|f| f.to_config()).map_err(bad)
}

pub fn render_config(path: Option<&Path>) -> Result<RenderConfig> {
    let Some(path) = path else { return Ok(RenderConfig::default()) };
    RenderConfig::from_toml(&read(path)?).map_err(|source| NodeError::File { path: path.into(), source })
}

/// A path in a config file, taken from the file's directory when relative.
fn rel(config: &Path, p: &mut Option<PathBuf>) {
    if let (Some(path), Some(dir)) = (p.as_mut(), config.parent()) {
        if path.is_relative() {
            *path = dir.join(&*path);
        }
    }
}

/// The `[link]` table of a node config: the link's own checks (plain TCP beyond loopback
/// refused unless `insecure = true`, TLS files named), the error naming the file.
fn check_link(link: &LinkConfig, config: &Path) -> Result<()> {
    link.validate().map_err(|source| NodeError::LinkConfig { path: config.into(), source })
}

fn check_ros2(ros2: &starc_link::ros2::Ros2Config, config: &Path) -> Result<()> {
    ros2.validate().map_err(|source| NodeError::LinkConfig { path: config.into(), source })
}

/// The link's relative paths (zenoh_config, [link.tls] files) taken from the config's folder.
fn rel_link(config: &Path, link: &mut LinkConfig) {
    if let Some(dir) = config.parent() {
        link.resolve_paths(dir);
    }
}

impl RobotNodeConfig {
    /// Reads `path`, takes its relative paths from its folder, and checks it.
    pub fn from_file(path: &Path) -> Result<Self> {
        let mut cfg: Self = load(path)?;
        cfg.resolve_paths(path);
        check_link(&cfg.link, path)?;
        check_ros2(&cfg.ros2, path)?;
        cfg.detect.validate().map_err(|e| NodeError::Config(format!("{}: [detect] {e}", path.display())))?;
        cfg.check_explore().map_err(|e| NodeError::Config(format!("{}: {e}", path.display())))?;
        Ok(cfg)
    }

    /// `[explore]` checked, and one driver per base: with the explorer on, `/cmd_vel` drives
    /// the explorer's base, so `[ros2] base_config`, if given, must name the same file.
    pub fn check_explore(&self) -> Result<()> {
        let Some(e) = self.explore.as_ref().filter(|e| e.enabled) else { return Ok(()) };
        e.validate()?;
        match &self.ros2.base_config {
            Some(b) if self.ros2.cmd_vel && *b != e.base_config => Err(NodeError::Config(format!(
                "[ros2] base_config {} and [explore] base_config {} differ: one base, one driver",
                b.display(),
                e.base_config.display()
            ))),
            _ => Ok(()),
        }
    }

    /// Relative paths in the file are relative to the file.
    pub fn resolve_paths(&mut self, config: &Path) {
        rel(config, &mut self.lio);
        rel(config, &mut self.detect.pillars.model);
        rel(config, &mut self.record);
        rel_link(config, &mut self.link);
        self.ros2.resolve_paths(config.parent().unwrap_or(Path::new(".")));
        if let Some(w) = self.wheels.as_mut() {
            w.resolve_paths(config);
        }
        if let Some(e) = self.explore.as_mut() {
            e.resolve_paths(config);
        }
    }
}

impl FpvNodeConfig {
    /// What the types let through but the node cannot use: a start gate that is not a positive
    /// distance or `inf` (no gate), a confirmation time that is not 0 to 600 s.
    pub fn validate(&self) -> Result<()> {
        if self.start_gate_m.is_nan() || self.start_gate_m <= 0.0 {
            return Err(NodeError::Config(format!(
                "start_gate_m must be a positive distance, or inf for no gate (got {})",
                self.start_gate_m
            )));
        }
        if !(self.confirm_first_s.is_finite() && (0.0..=600.0).contains(&self.confirm_first_s)) {
            return Err(NodeError::Config(format!(
                "confirm_first_s must be 0 to 600 seconds (got {})",
                self.confirm_first_s
            )));
        }
        Ok(())
    }

    /// Whether a first alignment anywhere is taken (`start_gate_m = inf`).
    pub fn no_start_gate(&self) -> bool {
        self.start_gate_m == f64::INFINITY
    }

    /// Reads `path`, takes its relative paths from its folder, and checks it.
    pub fn from_file(path: &Path) -> Result<Self> {
        let mut cfg: Self = load(path)?;
        cfg.resolve_paths(path);
        cfg.validate()?;
        check_link(&cfg.link, path)?;
        check_ros2(&cfg.ros2, path)?;
        if cfg.ros2.cmd_vel {
            return Err(NodeError::Config(format!(
                "{}: [ros2] cmd_vel drives the robot's base: the rig has none",
                path.display()
            )));
        }
        Ok(cfg)
    }

    /// Relative paths in the file are relative to the file.
    pub fn resolve_paths(&mut self, config: &Path) {
        rel(config, &mut self.lio);
        rel(config, &mut self.render);
        rel(config, &mut self.record);
        rel(config, &mut self.view.png_dir);
        rel_link(config, &mut self.link);
        self.ros2.resolve_paths(config.parent().unwrap_or(Path::new(".")));
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn shipped(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../config").join(name)
    }

    #[test]
    fn shipped_robot_config_loads() {
        let path = shipped("robot.toml");
        let cfg = RobotNodeConfig::from_file(&path).unwrap();
        assert_eq!(cfg.lidar_ip, Some(Ipv4Addr::new(192, 168, 1, 101)));
        // The driver is told to take that Avia alone, not any device that broadcasts.
        let driver = driver_for(&cfg.livox, cfg.lidar_ip);
        assert_eq!(driver.accept_ips, vec![Ipv4Addr::new(192, 168, 1, 101)]);
        assert!(!driver.accept_any_device && driver.accept_codes.is_empty());
        assert!(!cfg.link.multicast_scouting);
        // Mutual TLS on, with the files `starc link certs` writes to config/certs by default.
        assert!(!cfg.link.insecure);
        assert!(cfg.link.listen.iter().all(|e| e.starts_with("tls/")), "{:?}", cfg.link.listen);
        let tls = cfg.link.tls.as_ref().unwrap();
        assert!(tls.mutual);
        assert_eq!(tls.root_ca, shipped("certs/ca.pem"));
        assert_eq!(tls.cert.as_deref(), Some(shipped("certs/robot.pem").as_path()));
        assert_eq!(tls.key.as_deref(), Some(shipped("certs/robot.key").as_path()));
        // The LIO file it names exists and parses.
        lio_config(cfg.lio.as_deref()).unwrap();
    }

    #[test]
    fn shipped_fpv_config_loads_and_its_camera_looks_forward() {
        let path = shipped("fpv.toml");
        let cfg = FpvNodeConfig::from_file(&path).unwrap();
        render_config(cfg.render.as_deref()).unwrap();
        assert!(cfg.link.connect.iter().all(|e| e.starts_with("tls/")), "{:?}", cfg.link.connect);
        let tls = cfg.link.tls.as_ref().unwrap();
        assert!(tls.mutual && tls.verify_name && !cfg.link.insecure);
        assert_eq!(tls.cert.as_deref(), Some(shipped("certs/rig.pem").as_path()));
        let t = cfg.camera.lidar_t_camera().unwrap();
        // The camera's optical axis (z) is the LiDAR's forward (x), its image down (y) is down.
        let forward = t.rotation * nalgebra::Vector3::z();
        let down = t.rotation * nalgebra::Vector3::y();
        assert!((forward - nalgebra::Vector3::x()).norm() < 1e-9, "{forward}");
        assert!((down + nalgebra::Vector3::z()).norm() < 1e-9, "{down}");
        assert!(cfg.shared_lidar_clock);
    }

    #[test]
    fn loopback_configs_load_and_stay_on_loopback() {
        // config/loopback/: the nodes as separate processes on a `starc sim lab` run (docs/nodes.md).
        let path = shipped("loopback/robot.toml");
        let mut robot: RobotNodeConfig = load(&path).unwrap();
        robot.resolve_paths(&path);
        let path = shipped("loopback/fpv.toml");
        let mut fpv: FpvNodeConfig = load(&path).unwrap();
        fpv.resolve_paths(&path);
        // The mocks' addresses of `starc sim`, each node listening for its own mock's broadcasts.
        assert_eq!(robot.lidar_ip, Some(Ipv4Addr::new(127, 0, 7, 1)));
        assert_eq!(fpv.lidar_ip, Some(Ipv4Addr::new(127, 0, 7, 2)));
        for d in [&robot.livox, &fpv.livox] {
            assert!(d.host_ip.is_loopback());
            assert!(d.broadcast_listen.is_some_and(|a| a.ip().is_loopback()));
        }
        assert_ne!(robot.livox.broadcast_listen, fpv.livox.broadcast_listen);
        assert_ne!(robot.livox.data_port, fpv.livox.data_port);
        assert_ne!(robot.livox.cmd_port, fpv.livox.cmd_port);
        // The rig connects where the robot listens, on loopback, without multicast scouting.
        assert!(!robot.link.multicast_scouting && !fpv.link.multicast_scouting);
        assert_eq!(robot.link.listen, fpv.link.connect);
        assert!(robot.link.listen.iter().all(|e| e.starts_with("tcp/127.0.0.1:")), "{:?}", robot.link.listen);
        // The lab's camera looks along the LiDAR's x, as the shipped rig's does.
        let t = fpv.camera.lidar_t_camera().unwrap();
        assert!((t.rotation * nalgebra::Vector3::z() - nalgebra::Vector3::x()).norm() < 1e-9);
        assert!(fpv.expected_start.is_some() && fpv.shared_lidar_clock);
        assert!(robot.record.is_none() && fpv.record.is_none() && fpv.view.http_bind.is_none());
    }

    #[test]
    fn no_expected_start_and_no_gate_load_and_validate() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fpv.toml");
        let camera = "[camera]\nwidth = 640\nheight = 480\nfx = 460.0\nfy = 460.0\ncx = 320.0\ncy = 240.0\n\
                      translation_m = [0.0, 0.0, 0.05]\nquaternion_xyzw = [0.0, 0.0, 0.0, 1.0]\n[link]\n";
        std::fs::write(&path, format!("start_gate_m = inf\n{camera}")).unwrap();
        let cfg: FpvNodeConfig = load(&path).unwrap();
        cfg.validate().unwrap();
        assert!(cfg.expected_start.is_none() && cfg.no_start_gate());
        // Absent, the gate is 2 m; NaN, zero or negative it is an error.
        std::fs::write(&path, camera).unwrap();
        let cfg: FpvNodeConfig = load(&path).unwrap();
        assert_eq!(cfg.start_gate_m, 2.0);
        assert!(!cfg.no_start_gate());
        for bad in ["nan", "0.0", "-1.0"] {
            std::fs::write(&path, format!("start_gate_m = {bad}\n{camera}")).unwrap();
            let e = load::<FpvNodeConfig>(&path).unwrap().validate().unwrap_err();
            assert!(e.to_string().contains("start_gate_m"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_wheels_table_takes_the_base_drivers_config() {
        let dir = tempfile::tempdir().unwrap();
        let base = shipped("base.toml");
        let path = dir.path().join("robot.toml");
        let text =
            format!("[wheels]\nbase_config = {base:?}\ncan = \"can0\"\n\n[link]\nlisten = [\"tcp/127.0.0.1:7447\"]\n");
        std::fs::write(&path, text).unwrap();
        let cfg = RobotNodeConfig::from_file(&path).unwrap();
        let wheels = cfg.wheels.unwrap();
        assert_eq!(wheels.can.as_deref(), Some("can0"));
        let feedback = wheels.feedback().unwrap();
        assert_eq!(feedback.wheels.len(), feedback.kinematics.wheel_count());
        std::fs::write(&path, "[wheels]\ncan = \"can0\"\nbogus = 1\n[link]\n").unwrap();
        assert!(RobotNodeConfig::from_file(&path).is_err());
    }

    #[test]
    fn an_explore_table_names_the_base_relative_to_the_file_and_shares_it_with_teleop() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("robot.toml");
        let explore = "[explore]\nenabled = true\nbase_config = \"base.toml\"\nlidar_height_m = 0.45\n";
        std::fs::write(&path, format!("{explore}\n[link]\nlisten = [\"tcp/127.0.0.1:7447\"]\n")).unwrap();
        let cfg = RobotNodeConfig::from_file(&path).unwrap();
        let e = cfg.explore.unwrap();
        assert!(e.enabled && e.base_config == dir.path().join("base.toml") && e.resume_after_s.is_none());
        // /cmd_vel beside it must drive the same base, through the explorer's driver.
        let mut cfg = RobotNodeConfig::from_file(&path).unwrap();
        cfg.ros2.cmd_vel = true;
        cfg.ros2.base_config = Some(dir.path().join("other.toml"));
        let err = cfg.check_explore().unwrap_err().to_string();
        assert!(err.contains("one base, one driver"), "{err}");
        cfg.ros2.base_config = Some(dir.path().join("base.toml"));
        cfg.check_explore().unwrap();
        // A bad value names the table.
        std::fs::write(&path, "[explore]\nenabled = true\nbase_config = \"b\"\nlidar_height_m = -1.0\n[link]\n")
            .unwrap();
        let err = RobotNodeConfig::from_file(&path).unwrap_err().to_string();
        assert!(err.contains("[explore] lidar_height_m"), "{err}");
    }

    #[test]
    fn unknown_keys_and_bad_quaternions_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let bad = dir.path().join("robot.toml");
        std::fs::write(&bad, "lidar_ipp = \"1.2.3.4\"\n[link]\n").unwrap();
        let e = load::<RobotNodeConfig>(&bad).unwrap_err();
        assert!(format!("{e:#}").contains("lidar_ipp"), "{e:#}");
        let cam = CameraMountConfig {
            model: CameraModel::default(),
            translation_m: [0.0; 3],
            quaternion_xyzw: [0.0, 0.0, 0.0, 2.0],
        };
        assert!(cam.lidar_t_camera().is_err());
    }
}
