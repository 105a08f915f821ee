//! `[explore]` in robot.toml: the robot explores on its own (docs/explore.md). The node's LIO
//! poses and placed scans, and its wheels' twists, go to the [`Pilot`]; every control period
//! its twist goes to the base driver, the one base driver the node runs.
//!
//! Teleop takes over at any time: a `/cmd_vel` twist (`[ros2] cmd_vel`) holds the explorer and
//! drives the base itself, through the same driver, its limits and its watchdog. When
//! `/cmd_vel` falls silent the base is told to stop once; the explorer resumes
//! `resume_after_s` after the last twist, or never (the default: an operator who took over
//! decides, by restarting the node). The node's end halts the base; a node that dies leaves
//! the base's own watchdog to brake it.

use crate::error::{NodeError, Result};
use serde::Deserialize;
use starc_base::config::BaseConfig;
use starc_base::runner::{open_bus, spawn, BaseHandle};
use starc_base::{Base, Twist};
use starc_pipeline::explore::{ExploreConfig, ExploreState, Pilot, PilotConfig};
use std::path::{Path, PathBuf};

/// `[explore]` in robot.toml.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExploreNodeConfig {
    /// Off unless set: a base that moves on its own is asked for, never a default.
    #[serde(default)]
    pub enabled: bool,
    /// The base driver's config (config/base.toml).
    pub base_config: PathBuf,
    /// The LiDAR's optical centre over the floor the base stands on (m).
    pub lidar_height_m: f64,
    /// The LiDAR's minimum range (the Avia's: 1 m).
    #[serde(default = "default_min_range_m")]
    pub lidar_min_range_m: f64,
    /// The explorer's control rate (Hz); the base's watchdog needs a command within its period.
    #[serde(default = "default_control_hz")]
    pub control_hz: f64,
    /// After teleop, exploring resumes this long after the last `/cmd_vel` twist (s); absent:
    /// never.
    #[serde(default)]
    pub resume_after_s: Option<f64>,
}

fn default_min_range_m() -> f64 {
    1.0
}

fn default_control_hz() -> f64 {
    20.0
}

/// Every how many of a placed scan's returns go into the explorer's grid.
const SCAN_STRIDE: usize = 2;

impl ExploreNodeConfig {
    /// What the types let through but the robot cannot use.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(NodeError::Config(format!("[explore] {what}")));
        if !(self.lidar_height_m.is_finite() && self.lidar_height_m > 0.0 && self.lidar_height_m <= 3.0) {
            return bad(format!("lidar_height_m must be over 0 and at most 3 m (got {})", self.lidar_height_m));
        }
        if !(self.lidar_min_range_m.is_finite() && self.lidar_min_range_m >= 0.0) {
            return bad(format!("lidar_min_range_m must be 0 or more (got {})", self.lidar_min_range_m));
        }
        if !(self.control_hz.is_finite() && (1.0..=100.0).contains(&self.control_hz)) {
            return bad(format!("control_hz must be 1 to 100 (got {})", self.control_hz));
        }
        if self.resume_after_s.is_some_and(|s| !(s.is_finite() && s >= 0.0)) {
            return bad(format!("resume_after_s must be 0 or more seconds (got {:?})", self.resume_after_s));
        }
        Ok(())
    }

    /// The pilot this config describes, the explorer's other settings at their defaults.
    pub fn pilot(&self) -> PilotConfig {
        PilotConfig {
            explore: ExploreConfig::default(),
            lidar_height_m: self.lidar_height_m,
            scan_stride: SCAN_STRIDE,
            lidar_min_range_m: self.lidar_min_range_m,
        }
    }

    pub fn period(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(1.0 / self.control_hz)
    }

    /// Relative paths are taken from the config file's folder.
    pub fn resolve_paths(&mut self, config: &Path) {
        if let (true, Some(dir)) = (self.base_config.is_relative(), config.parent()) {
            self.base_config = dir.join(&self.base_config);
        }
    }
}

/// Who drives the base at an instant (host clock), sans-IO.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arbiter {
    resume_after_ns: Option<u64>,
    silent_after_ns: u64,
    last_teleop_ns: Option<u64>,
    /// The stop after teleop fell silent has been sent.
    stopped: bool,
}

/// What the base is told this control period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Turn {
    /// The explorer drives.
    Explorer,
    /// Teleop fell silent: one stop.
    Stop,
    /// Teleop has it (or had it, and the explorer is not to resume): nothing.
    Nothing,
}

impl Arbiter {
    /// `silent_after_ns`: teleop is silent this long after its last twist (`[ros2]
    /// cmd_vel_timeout_ms`).
    pub fn new(resume_after_s: Option<f64>, silent_after_ns: u64) -> Self {
        let resume_after_ns = resume_after_s.map(|s| (s.max(0.0) * 1e9) as u64);
        Self { resume_after_ns, silent_after_ns, last_teleop_ns: None, stopped: false }
    }

    /// A teleop twist at `now_ns`.
    pub fn teleop(&mut self, now_ns: u64) {
        self.last_teleop_ns = Some(now_ns);
        self.stopped = false;
    }

    /// Whether teleop has the base (its last twist not yet followed by a resume).
    pub fn teleop_has_it(&self, now_ns: u64) -> bool {
        self.last_teleop_ns.is_some_and(|t| self.resume_after_ns.is_none_or(|r| now_ns < t.saturating_add(r)))
    }

    /// The control period at `now_ns`.
    pub fn turn(&mut self, now_ns: u64) -> Turn {
        let Some(last) = self.last_teleop_ns else { return Turn::Explorer };
        if !self.teleop_has_it(now_ns) {
            return Turn::Explorer;
        }
        if !self.stopped && now_ns >= last.saturating_add(self.silent_after_ns) {
            self.stopped = true;
            return Turn::Stop;
        }
        Turn::Nothing
    }
}

/// What the explorer did in a live run.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ExploreSummary {
    pub control_steps: u64,
    pub teleop_twists: u64,
    /// Traversable floor the explorer's grid knew at the end (m²).
    pub area_m2: f64,
    pub final_state: Option<String>,
    pub blacklisted: usize,
}

/// The explorer driving a base, teleop beside it.
pub struct ExploreDrive {
    pilot: Pilot,
    base: BaseHandle,
    arbiter: Arbiter,
    dt_s: f64,
    summary: ExploreSummary,
}

impl ExploreDrive {
    /// Opens the base `cfg.base_config` names. `teleop_silent_ms`: `[ros2] cmd_vel_timeout_ms`.
    pub async fn open(cfg: &ExploreNodeConfig, teleop_silent_ms: u64) -> Result<Self> {
        let path = &cfg.base_config;
        let base_cfg = BaseConfig::load(path)
            .map_err(|e| NodeError::Config(format!("[explore] base_config {}: {e}", path.display())))?;
        let (bus, options) =
            open_bus(&base_cfg.can).await.map_err(|e| NodeError::Config(format!("the base's bus: {e}")))?;
        let base = Base::new(base_cfg).map_err(|e| NodeError::Config(format!("the base: {e}")))?;
        let (handle, _events) = spawn(bus, base, options);
        tracing::info!(config = %path.display(), "the explorer drives the base");
        Ok(Self::with_base(cfg, handle, teleop_silent_ms))
    }

    /// The same, on a base already running.
    pub fn with_base(cfg: &ExploreNodeConfig, base: BaseHandle, teleop_silent_ms: u64) -> Self {
        Self {
            pilot: Pilot::new(cfg.pilot()),
            base,
            arbiter: Arbiter::new(cfg.resume_after_s, teleop_silent_ms.saturating_mul(1_000_000)),
            dt_s: 1.0 / cfg.control_hz,
            summary: ExploreSummary::default(),
        }
    }

    pub fn pilot(&self) -> &Pilot {
        &self.pilot
    }

    pub fn base(&self) -> &BaseHandle {
        &self.base
    }

    /// A placed scan (LiDAR clock).
    pub fn on_scan(
        &mut self,
        end_ns: u64,
        lidar_pose: &nalgebra::Isometry3<f64>,
        points: impl IntoIterator<Item = nalgebra::Vector3<f64>>,
    ) {
        self.pilot.on_scan(end_ns, lidar_pose, points);
    }

    /// The wheels' twist (LiDAR clock).
    pub fn on_wheels(&mut self, t_ns: u64, vx_m_s: f64, vy_m_s: f64, wz_rad_s: f64) {
        self.pilot.on_wheels(t_ns, vx_m_s, vy_m_s, wz_rad_s);
    }

    /// A teleop twist at host time `host_ns`: the explorer is held, the base takes the twist.
    pub async fn teleop(&mut self, twist: Twist, host_ns: u64) -> Result<()> {
        self.arbiter.teleop(host_ns);
        self.summary.teleop_twists += 1;
        if let Some(e) = self.pilot.explorer_mut() {
            e.hold();
        }
        self.base.command(twist).await.map_err(|e| NodeError::Config(format!("the base: {e}")))
    }

    /// One control period at host time `host_ns`, LiDAR time `lidar_ns` (none before the first
    /// scan: nothing is sent, and the base's watchdog keeps it braked).
    pub async fn control(&mut self, host_ns: u64, lidar_ns: Option<u64>) -> Result<()> {
        let twist = match self.arbiter.turn(host_ns) {
            Turn::Nothing => return Ok(()),
            Turn::Stop => Twist::ZERO,
            Turn::Explorer => {
                let Some(lidar_ns) = lidar_ns else { return Ok(()) };
                if let Some(e) = self.pilot.explorer_mut().filter(|e| e.state() == ExploreState::Stopped) {
                    e.release();
                }
                let Some(step) = self.pilot.step(lidar_ns, self.dt_s) else { return Ok(()) };
                self.summary.control_steps += 1;
                Twist::new(step.twist.vx_m_s, step.twist.vy_m_s, step.twist.wz_rad_s)
            }
        };
        self.base.command(twist).await.map_err(|e| NodeError::Config(format!("the base: {e}")))
    }

    /// Halts the base and says what was done.
    pub async fn finish(mut self) -> ExploreSummary {
        if let Some(e) = self.pilot.explorer() {
            self.summary.area_m2 = e.grid().traversable_area_m2();
            self.summary.final_state = Some(format!("{:?}", e.state()));
            self.summary.blacklisted = e.blacklist().len();
        }
        if let Err(e) = self.base.stop().await {
            tracing::warn!("the base: {e}");
        }
        self.summary
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn teleop_takes_over_and_one_stop_follows_its_silence() {
        let mut a = Arbiter::new(None, 500 * MS);
        assert_eq!(a.turn(0), Turn::Explorer);
        a.teleop(1000 * MS);
        assert_eq!(a.turn(1200 * MS), Turn::Nothing);
        assert_eq!(a.turn(1500 * MS), Turn::Stop);
        assert_eq!(a.turn(1550 * MS), Turn::Nothing);
        // Without resume_after_s the explorer never gets the base back.
        assert_eq!(a.turn(3_600_000 * MS), Turn::Nothing);
        assert!(a.teleop_has_it(3_600_000 * MS));
    }

    #[test]
    fn the_explorer_resumes_after_the_set_time_and_teleop_can_take_over_again() {
        let mut a = Arbiter::new(Some(5.0), 500 * MS);
        a.teleop(1000 * MS);
        assert_eq!(a.turn(1600 * MS), Turn::Stop);
        assert_eq!(a.turn(5999 * MS), Turn::Nothing);
        assert_eq!(a.turn(6000 * MS), Turn::Explorer);
        a.teleop(7000 * MS);
        assert_eq!(a.turn(7100 * MS), Turn::Nothing);
        assert_eq!(a.turn(7500 * MS), Turn::Stop);
    }

    fn config(text: &str) -> Result<ExploreNodeConfig> {
        let cfg: ExploreNodeConfig = toml::from_str(text).map_err(|e| NodeError::Config(e.to_string()))?;
        cfg.validate().map(|()| cfg)
    }

    #[test]
    fn the_table_is_checked() {
        let ok = config("enabled = true\nbase_config = \"base.toml\"\nlidar_height_m = 0.45\n");
        assert!(ok.is_ok_and(|c| c.enabled && c.control_hz == 20.0 && c.resume_after_s.is_none()));
        for bad in [
            "base_config = \"b\"\nlidar_height_m = 0.0\n",
            "base_config = \"b\"\nlidar_height_m = nan\n",
            "base_config = \"b\"\nlidar_height_m = 0.5\ncontrol_hz = 0.5\n",
            "base_config = \"b\"\nlidar_height_m = 0.5\nresume_after_s = -1.0\n",
            "base_config = \"b\"\nlidar_height_m = 0.5\nspeed = 3\n",
            "lidar_height_m = 0.5\n",
        ] {
            assert!(config(bad).is_err(), "{bad}");
        }
    }
}
