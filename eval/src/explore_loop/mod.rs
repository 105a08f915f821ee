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

pub mod bus;
mod score;

use crate::{EvalError, Result};
use bus::{BaseInTheLoop, BusCounts, STEP_NS};
use nalgebra::Vector3;
use starc_base::config::{Protocol, WheelConfig};
use starc_base::kinematics::Kinematics;
use starc_base::{BaseConfig, Twist};
use starc_bridge::livox::{lio_scan, packet_imu};
use starc_bridge::wheels::{WheelDecoder, WheelFeedback};
use starc_hil::error::HilError;
use starc_hil::sim::driven::DrivenTrack;
use starc_hil::sim::lan::{AviaLink, Wire};
use starc_hil::sim::run::{RobotDriver, ROBOT_AVIA_IP};
use starc_hil::sim::scenario::{MotorProtocol, Robot, Scenario};
use starc_livox::data::DataPacket;
use starc_livox::ports::DEVICE_CMD_PORT;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::explore::{ExploreConfig, ExploreState, Pilot, PilotConfig};
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
    track: DrivenTrack,
    bus: BaseInTheLoop,
    kinematics: Kinematics,
    /// The next motor step (simulator clock).
    motor_ns: u64,
    next_control_ns: u64,
    wheels: WheelDecoder,
    core: RobotCore,
    assembler: ScanAssembler,
    pilot: Pilot,
    steps: Vec<RobotStep>,
    frames: Vec<starc_can::CanFrame>,
    score: score::Score,
}

impl ExploreLoop {
    /// The loop for `scenario`'s robot, starting where its first waypoint puts it.
    pub fn new(scenario: &Scenario, cfg: LoopConfig) -> Result<Self> {
        let robot = scenario.robot.get_ref();
        let start = robot.waypoints.first().ok_or_else(|| EvalError::Input("the robot has no start pose".into()))?;
        let kinematics = Kinematics::new(&cfg.base.kinematics).map_err(|e| EvalError::Input(format!("base: {e}")))?;
        let wheels = WheelDecoder::new(&WheelFeedback::from_base(&cfg.base)).map_err(EvalError::Input)?;
        let assembler = ScanAssembler::new(ScanConfig::default()).map_err(|e| EvalError::Input(e.to_string()))?;
        Ok(Self {
            track: DrivenTrack::new([start[0], start[1], start[2].to_radians()], 0.0, STEP_NS as f64 * 1e-9),
            bus: BaseInTheLoop::new(cfg.base.clone(), cfg.seed)?,
            kinematics,
            motor_ns: 0,
            next_control_ns: 0,
            wheels,
            core: RobotCore::new(cfg.robot.clone()).map_err(|e| EvalError::Input(e.to_string()))?,
            assembler,
            pilot: Pilot::new(cfg.pilot),
            steps: Vec::new(),
            frames: Vec::new(),
            score: score::Score::new(scenario, cfg.pilot.explore.control.robot_radius_m),
            cfg,
        })
    }

    /// What the run came to, once the simulator is done.
    pub fn report(&self) -> LoopReport {
        self.score.report(self.pilot.explorer(), self.bus.counts(), self.bus.status().faults.len())
    }

    /// The bus's counters so far.
    pub fn bus_counts(&self) -> BusCounts {
        self.bus.counts()
    }

    /// One motor step at `sim_ns`: the bus, the wheels' odometry, a control step when due, and
    /// the track moved by the wheels' true speeds.
    fn motor_step(&mut self, sim_ns: u64) {
        let ptp_ns = sim_ns.saturating_add_signed(AviaLink::ptp_offset_ns());
        self.frames.clear();
        self.bus.step(sim_ns, ptp_ns, &mut self.frames);
        for f in &self.frames {
            if let Some(tw) = self.wheels.push(ptp_ns, f) {
                let s = WheelSample {
                    t_ns: tw.t_ns,
                    clock: Clock::Ptp,
                    vx_m_s: tw.vx_m_s,
                    vy_m_s: tw.vy_m_s,
                    wz_rad_s: tw.wz_rad_s,
                };
                self.core.push_wheel(s);
                self.pilot.on_wheels(tw.t_ns, tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s);
            }
        }
        if sim_ns >= self.next_control_ns {
            let dt_s = 1.0 / self.cfg.control_hz;
            self.next_control_ns = sim_ns + (dt_s * 1e9) as u64;
            let t0 = Instant::now();
            if let Some(step) = self.pilot.step(ptp_ns, dt_s) {
                self.score.control_step(t0.elapsed().as_secs_f64() * 1e3, step.state == ExploreState::Done);
                let tw = step.twist;
                self.bus.command(Twist::new(tw.vx_m_s, tw.vy_m_s, tw.wz_rad_s), ptp_ns);
            }
        }
        let body = self.kinematics.body_twist(&self.bus.true_wheel_rad_s()).unwrap_or(Twist::ZERO);
        self.track.push([body.vx_m_s, body.vy_m_s, body.wz_rad_s]);
    }

    /// The robot's LIO outputs since the last call: each placed scan to the pilot.
    fn take_steps(&mut self) {
        let placed = self.core.take_unmapped();
        for (step, scan) in self.steps.drain(..).zip(placed) {
            let points: Vec<Vector3<f64>> = scan.points.iter().map(|p| p.xyz()).collect();
            self.pilot.on_scan(step.output.end_ns, &step.output.lidar_pose, &points);
        }
    }
}

impl RobotDriver for ExploreLoop {
    fn track(&self) -> DrivenTrack {
        self.track.clone()
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
        while self.motor_ns <= t_ns + LOOKAHEAD_NS {
            self.motor_step(self.motor_ns);
            self.motor_ns += STEP_NS;
        }
        self.score.sample(&self.track, self.pilot.explorer(), t_ns);
        if self.track.end_s() * 1e9 < (t_ns + 2_000_000) as f64 {
            return Err(HilError::Driver(format!("the track ends before {} ns", t_ns + 2_000_000)));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
