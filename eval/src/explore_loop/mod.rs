//! The closed loop of `starc sim SCENARIO --explore`: the explorer drives the simulated robot.
//!
//! The robot's side runs as on the robot: its Avia's packets (from the simulator's virtual
//! network, as its host receives them) are decoded and assembled into scans, the robot's LIO
//! ([`RobotCore`], the mission's own) places them, the wheels' feedback from the base's bus is
//! its wheel odometry, and the [`Pilot`] turns the LIO's poses and placed scans into the
//! explorer's twist, which the base driver sends over CAN (slcan bytes) to the mock motor
//! controllers ([`bus`]). The motors' true speeds, through the base's kinematics, move the
//! simulated robot ([`DrivenTrack`]), and the Avia mock scans from where it has got to.
//!
//! The motors run [`LOOKAHEAD_NS`] ahead of the sensors, as the simulator asks
//! ([`RobotDriver`]): what the robot decides from a scan acts that much later, as a real
//! pipeline's latency would make it.
//!
//! The scorer's part ([`score`]) reads the simulator's world and the true track to count
//! contacts; nothing the robot decides reads them.

mod body;
pub mod bus;
mod reach;
mod score;

use crate::{EvalError, Result};
use body::{Body, SCRIPTED_WHEEL_NS};
use bus::{BusCounts, STEP_NS};
use starc_base::config::{Protocol, WheelConfig};
use starc_base::{BaseConfig, Twist};
use starc_bridge::livox::{lio_scan, packet_imu};
use starc_hil::error::HilError;
use starc_hil::sim::driven::DrivenTrack;
use starc_hil::sim::lan::{AviaLink, Wire};
use starc_hil::sim::run::{RobotDriver, ROBOT_AVIA_IP};
use starc_hil::sim::scenario::{MotorProtocol, Robot, Scenario};
use starc_livox::data::DataPacket;
use starc_livox::ports::DEVICE_CMD_PORT;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::explore::{base_pose, ExploreConfig, ExploreState, Pilot, PilotConfig, Pose2};
use starc_pipeline::lio::{Clock, WheelSample};
use starc_pipeline::mission::{RobotCore, RobotCoreConfig, RobotStep};
use std::time::Instant;

pub use score::LoopReport;

/// Every how many of a placed scan's returns go into the explorer's grid.
const SCAN_STRIDE: usize = 2;
/// The Avia's minimum range (its datasheet).
const AVIA_MIN_RANGE_M: f64 = 1.0;
/// The explorer's control rate.
const CONTROL_HZ: f64 = 20.0;

/// How far the motors (and the track) run ahead of the sensors.
pub const LOOKAHEAD_NS: u64 = 20_000_000;

/// Settings of the loop.
#[derive(Clone, Debug)]
pub struct LoopConfig {
    pub pilot: PilotConfig,
    /// The base driver's settings; its kinematics are also the simulated base's.
    pub base: BaseConfig,
    /// The explorer plans this often (Hz).
    pub control_hz: f64,
    pub robot: RobotCoreConfig,
    pub seed: u64,
    /// The robot follows its scripted waypoints instead, measured the same way (the baseline).
    pub scripted: bool,
}

impl LoopConfig {
    /// The loop for `robot` (a scenario's): the base driver's `template` settings
    /// (config/base.toml) made to match the simulated base ([`sim_base_config`]), the
    /// explorer's defaults, the mission's robot core.
    pub fn for_robot(robot: &Robot, template: BaseConfig, seed: u64) -> Self {
        Self {
            pilot: PilotConfig {
                explore: ExploreConfig::default(),
                lidar_height_m: robot.lidar_height_m,
                scan_stride: SCAN_STRIDE,
                lidar_min_range_m: AVIA_MIN_RANGE_M,
            },
            base: sim_base_config(robot, template),
            control_hz: CONTROL_HZ,
            robot: RobotCoreConfig::default(),
            seed,
            scripted: false,
        }
    }
}

/// The base driver's settings for the simulated base of `robot`: `template` with the
/// scenario's wheel layout and geometry, its motor controllers, and wheel ids 1..n, none
/// inverted, as an engineer sets the driver up for the base in front of them.
pub fn sim_base_config(robot: &Robot, mut template: BaseConfig) -> BaseConfig {
    template.kinematics = starc_hil::sim::wheels::default_geometry(robot.wheels);
    template.motors.protocol = match robot.motors {
        MotorProtocol::C620 => Protocol::C620,
        MotorProtocol::Cia402 => Protocol::Cia402,
    };
    let n = u8::try_from(template.kinematics.wheel_count()).unwrap_or(u8::MAX);
    template.motors.wheels = (1..=n).map(|id| WheelConfig { id, invert: false }).collect();
    template
}

/// See the module's documentation.
pub struct ExploreLoop {
    cfg: LoopConfig,
    body: Body,
    core: RobotCore,
    assembler: ScanAssembler,
    pilot: Pilot,
    steps: Vec<RobotStep>,
    score: score::Score,
}

impl ExploreLoop {
    /// The loop for `scenario`'s robot, starting where its first waypoint puts it: driven by
    /// the explorer, or with `cfg.scripted` along its waypoints, measured the same way.
    pub fn new(scenario: &Scenario, cfg: LoopConfig) -> Result<Self> {
        let robot = scenario.robot.get_ref();
        let start = robot.waypoints.first().ok_or_else(|| EvalError::Input("the robot has no start pose".into()))?;
        let body = match cfg.scripted {
            true => Body::scripted(robot, cfg.seed)?,
            false => Body::driven(robot, &cfg.base, cfg.seed)?,
        };
        let assembler = ScanAssembler::new(ScanConfig::default()).map_err(|e| EvalError::Input(e.to_string()))?;
        Ok(Self {
            body,
            core: RobotCore::new(cfg.robot.clone()).map_err(|e| EvalError::Input(e.to_string()))?,
            assembler,
            pilot: Pilot::new(cfg.pilot),
            steps: Vec::new(),
            score: score::Score::new(scenario, cfg.pilot.explore.control.robot_radius_m, [start[0], start[1]]),
            cfg,
        })
    }

    /// What the run came to, once the simulator is done.
    pub fn report(&self) -> LoopReport {
        match &self.body {
            Body::Driven(d) => {
                self.score.report("closed_loop", self.pilot.explorer(), d.bus.counts(), d.bus.status().faults.len())
            }
            Body::Scripted(_) => self.score.report("scripted", self.pilot.explorer(), BusCounts::default(), 0),
        }
    }

    /// A wheel twist measured at `t_ns` (PTP), to the LIO and the pilot.
    fn wheel(&mut self, t_ns: u64, [vx_m_s, vy_m_s, wz_rad_s]: [f64; 3]) {
        self.core.push_wheel(WheelSample { t_ns, clock: Clock::Ptp, vx_m_s, vy_m_s, wz_rad_s });
        self.pilot.on_wheels(t_ns, vx_m_s, vy_m_s, wz_rad_s);
    }

    /// One motor step at `sim_ns`: the bus, the wheels' odometry, a control step when due, and
    /// the track moved by the wheels' true speeds.
    fn motor_step(&mut self, sim_ns: u64) {
        let Body::Driven(d) = &mut self.body else { return };
        let ptp_ns = sim_ns.saturating_add_signed(AviaLink::ptp_offset_ns());
        d.frames.clear();
        d.bus.step(sim_ns, ptp_ns, &mut d.frames);
        let twists: Vec<_> = d.frames.iter().filter_map(|f| d.wheels.push(ptp_ns, f)).collect();
        let control = sim_ns >= d.next_control_ns;
        let dt_s = 1.0 / self.cfg.control_hz;
        if control {
            d.next_control_ns = sim_ns + (dt_s * 1e9) as u64;
        }
        for tw in twists {
            self.wheel(tw.t_ns, [tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s]);
        }
        let t0 = Instant::now();
        let step = if control { self.pilot.step(ptp_ns, dt_s) } else { None };
        let Body::Driven(d) = &mut self.body else { return };
        if let Some(step) = step {
            self.score.control_step(t0.elapsed().as_secs_f64() * 1e3, step.state == ExploreState::Done);
            let tw = step.twist;
            d.bus.command(Twist::new(tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s), ptp_ns);
        }
        let body = d.kinematics.body_twist(&d.bus.true_wheel_rad_s()).unwrap_or(Twist::ZERO);
        d.track.push([body.vx_m_s, body.vy_m_s, body.wz_rad_s]);
    }

    /// Up to the step at `t_ns`: the motors (driven: 20 ms ahead), or the scripted route's
    /// wheel odometry (every 10 ms, up to `t_ns`).
    fn advance(&mut self, t_ns: u64) -> starc_hil::error::Result<()> {
        match &mut self.body {
            Body::Driven(_) => {
                while let Body::Driven(d) = &mut self.body {
                    if d.motor_ns > t_ns + LOOKAHEAD_NS {
                        break;
                    }
                    let at = d.motor_ns;
                    d.motor_ns += STEP_NS;
                    self.motor_step(at);
                }
                if let Body::Driven(d) = &self.body {
                    if d.track.end_s() * 1e9 < (t_ns + 2_000_000) as f64 {
                        return Err(HilError::Driver(format!("the track ends before {} ns", t_ns + 2_000_000)));
                    }
                }
            }
            Body::Scripted(s) => {
                let mut measured = Vec::new();
                while s.next_ns <= t_ns {
                    let r = s.odometry.sample(&s.motion, s.next_ns as f64 * 1e-9);
                    measured.push((s.next_ns.saturating_add_signed(AviaLink::ptp_offset_ns()), r.body));
                    s.next_ns += SCRIPTED_WHEEL_NS;
                }
                for (t, body) in measured {
                    self.wheel(t, body);
                }
            }
        }
        Ok(())
    }

    /// The robot's LIO outputs since the last call: each placed scan to the pilot.
    fn take_steps(&mut self) {
        let placed = self.core.take_unmapped();
        for (step, scan) in self.steps.drain(..).zip(placed) {
            // The scorer ties the grid to the world at the first pose (the truth is its alone).
            let o = &step.output;
            let sim_s = o.end_ns.saturating_add_signed(-AviaLink::ptp_offset_ns()) as f64 * 1e-9;
            let truth = self.body.truth_at(sim_s);
            let lio = base_pose(&o.lidar_pose);
            self.score.tie(&lio, &Pose2 { x_m: truth.x, y_m: truth.y, yaw_rad: truth.yaw_rad });
            self.pilot.on_scan(o.end_ns, &o.lidar_pose, scan.points.iter().map(|p| p.xyz()));
        }
    }
}

impl RobotDriver for ExploreLoop {
    fn track(&self) -> Option<DrivenTrack> {
        self.body.track()
    }

    fn on_wire(&mut self, w: &Wire<'_>) -> starc_hil::error::Result<()> {
        if *w.src.ip() != ROBOT_AVIA_IP || w.src.port() == DEVICE_CMD_PORT || w.dst.port() == DEVICE_CMD_PORT {
            return Ok(());
        }
        let Ok(packet) = DataPacket::parse(w.payload) else { return Ok(()) };
        if let Some(s) = packet_imu(&packet) {
            self.core.push_imu(s, &mut self.steps);
        } else if !packet.is_imu() {
            let mut done = Vec::new();
            self.assembler.push(&packet, None, &mut done);
            for scan in &done {
                self.core.push_scan(lio_scan(scan), &mut self.steps);
            }
        }
        self.take_steps();
        Ok(())
    }

    fn before_step(&mut self, t_ns: u64) -> starc_hil::error::Result<()> {
        self.advance(t_ns)?;
        let truth = self.body.truth_at(t_ns as f64 * 1e-9);
        self.score.sample(&truth, self.pilot.explorer(), t_ns);
        Ok(())
    }
}

#[cfg(test)]
mod tests;
