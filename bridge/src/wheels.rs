//! The base's wheel feedback as the LIO takes it: a `candump -l` log of the motor controllers'
//! feedback (DJI C620 `0x201..`, or CiA 402 TPDO1 `0x181..`), one frame per wheel per cycle,
//! turned into the base's planar twist by the base driver's own kinematics.

use crate::{BridgeError, Inputs};
use starc_base::c620::frame::M3508_GEAR_RATIO;
use starc_base::c620::Feedback;
use starc_base::cia402::{Cia402Config, VelocityStatus};
use starc_base::config::{BaseConfig, Protocol};
use starc_base::kinematics::{Kinematics, KinematicsConfig};
use starc_can::candump::parse_line;
use starc_can::CanFrame;
use starc_pipeline::lio::{Clock, WheelSample};
use starc_pipeline::mission::{MissionInput, Side};
use std::path::Path;

/// Which motor controllers the log's feedback comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotorFeedback {
    /// DJI C620 ESCs with M3508 motors: rotor rpm through the gearbox.
    C620,
    /// CiA 402 drives: actual velocity in the drive's units.
    Cia402,
}

/// How a base's feedback frames map to its wheels: the base driver's own settings.
#[derive(Clone, Debug, PartialEq)]
pub struct WheelFeedback {
    pub kinematics: KinematicsConfig,
    pub motors: MotorFeedback,
    /// Per wheel, in kinematics order: its ESC or CANopen node id, and whether its motor turns
    /// the other way for a positive wheel rate.
    pub wheels: Vec<(u8, bool)>,
    /// C620: rotor turns per wheel turn.
    pub gear_ratio: f64,
    /// CiA 402: drive velocity units per wheel rad/s.
    pub units_per_rad_s: f64,
}

impl WheelFeedback {
    /// The base as its driver's config file (config/base.toml) describes it.
    pub fn from_base(cfg: &BaseConfig) -> Self {
        Self {
            kinematics: cfg.kinematics.clone(),
            motors: match cfg.motors.protocol {
                Protocol::C620 => MotorFeedback::C620,
                Protocol::Cia402 => MotorFeedback::Cia402,
            },
            wheels: cfg.motors.wheels.iter().map(|w| (w.id, w.invert)).collect(),
            gear_ratio: cfg.motors.c620.gear_ratio,
            units_per_rad_s: cfg.motors.cia402.units_per_rad_s,
        }
    }

    /// Wheels 1..=n in kinematics order, none inverted, an M3508 gearbox or the drives' default
    /// units (the simulator's base).
    pub fn plain(kinematics: KinematicsConfig, motors: MotorFeedback) -> Self {
        let ids = 1..=u8::try_from(kinematics.wheel_count()).unwrap_or(u8::MAX);
        Self {
            kinematics,
            motors,
            wheels: ids.map(|id| (id, false)).collect(),
            gear_ratio: M3508_GEAR_RATIO,
            units_per_rad_s: Cia402Config::default().units_per_rad_s,
        }
    }

    /// Wheel index and wheel rate of one feedback frame, if it is one of this base's.
    fn wheel_rate(&self, frame: &CanFrame) -> Option<(usize, f64)> {
        let (id, rad_s) = match self.motors {
            MotorFeedback::C620 => {
                let f = Feedback::parse(frame).ok()?;
                (f.esc, f.output_rad_s(self.gear_ratio))
            }
            MotorFeedback::Cia402 => {
                let (node, v) = VelocityStatus::parse(frame).ok()?;
                (node, f64::from(v.actual_velocity) / self.units_per_rad_s)
            }
        };
        let wheel = self.wheels.iter().position(|(w, _)| *w == id)?;
        let invert = self.wheels.get(wheel).is_some_and(|(_, i)| *i);
        Some((wheel, if invert { -rad_s } else { rad_s }))
    }
}

/// The base's twist from its feedback frames as they come, one per cycle (every wheel heard
/// once), sans-IO: the log reader and the robot node's live feed both use it.
pub struct WheelDecoder {
    base: WheelFeedback,
    kin: Kinematics,
    cycle: Cycle,
}

/// The base's planar twist (x forward, y left, counter-clockwise), at the time of the first
/// frame of its cycle, on whatever clock the frames' times were.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaseTwist {
    pub t_ns: u64,
    pub vx_m_s: f64,
    pub vy_m_s: f64,
    pub wz_rad_s: f64,
}

impl WheelDecoder {
    /// Refuses a base whose wheel ids do not match its kinematics (the reason in words).
    pub fn new(base: &WheelFeedback) -> Result<Self, String> {
        let kin = Kinematics::new(&base.kinematics).map_err(|e| e.to_string())?;
        if base.wheels.len() != kin.wheel_count() {
            return Err(format!("{} wheel ids for {} wheels", base.wheels.len(), kin.wheel_count()));
        }
        let cycle = Cycle::new(kin.wheel_count());
        Ok(Self { base: base.clone(), kin, cycle })
    }

    /// One frame at `t_ns`; the twist once its cycle is complete. Frames that are not this
    /// base's feedback (commands, other nodes) are ignored.
    pub fn push(&mut self, t_ns: u64, frame: &CanFrame) -> Option<BaseTwist> {
        let (wheel, rad_s) = self.base.wheel_rate(frame)?;
        let (t_ns, rates) = self.cycle.add(t_ns, wheel, rad_s)?;
        let tw = self.kin.body_twist(&rates)?;
        Some(BaseTwist { t_ns, vx_m_s: tw.vx_m_s, vy_m_s: tw.vy_m_s, wz_rad_s: tw.wz_rad_s })
    }
}

/// The wheels' twists from a log, one per cycle (stamped by its first frame, moved by
/// `offset_ns` onto the LiDAR's PTP clock); lines that are not this base's feedback are skipped.
pub fn read_wheel_log(path: &Path, base: &WheelFeedback, offset_ns: i64) -> Result<Vec<WheelSample>, BridgeError> {
    let text = std::fs::read_to_string(path).map_err(|source| BridgeError::Io { path: path.into(), source })?;
    let bad = |reason: String| BridgeError::WheelLog { path: path.into(), reason };
    let mut decoder = WheelDecoder::new(base).map_err(bad)?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let logged = parse_line(line).map_err(|e| bad(format!("line {}: {e}", n + 1)))?;
        if let Some(tw) = decoder.push(logged.t_ns, &logged.frame) {
            out.push(WheelSample {
                t_ns: tw.t_ns.saturating_add_signed(offset_ns),
                clock: Clock::Ptp,
                vx_m_s: tw.vx_m_s,
                vy_m_s: tw.vy_m_s,
                wz_rad_s: tw.wz_rad_s,
            });
        }
    }
    if out.is_empty() {
        return Err(bad(format!("no complete cycle of {} wheels' feedback", decoder.kin.wheel_count())));
    }
    Ok(out)
}

/// One cycle's rates, complete once every wheel has reported.
struct Cycle {
    first_ns: Option<u64>,
    rates: Vec<Option<f64>>,
}

impl Cycle {
    fn new(wheels: usize) -> Self {
        Self { first_ns: None, rates: vec![None; wheels] }
    }

    /// Adds a wheel's rate; the cycle's time and rates once all wheels are in. A wheel seen
    /// twice before the others starts a new cycle (a frame of the last one was lost).
    fn add(&mut self, t_ns: u64, wheel: usize, rad_s: f64) -> Option<(u64, Vec<f64>)> {
        if self.rates.get(wheel).is_some_and(Option::is_some) {
            *self = Self::new(self.rates.len());
        }
        *self.rates.get_mut(wheel)? = Some(rad_s);
        let first = *self.first_ns.get_or_insert(t_ns);
        let rates: Option<Vec<f64>> = self.rates.iter().copied().collect();
        let rates = rates?;
        *self = Self::new(self.rates.len());
        Some((first, rates))
    }
}

/// `inputs` with `wheels` merged in by time, as the robot's: a wheel sample goes before any
/// input that completes at or after it, so the LIO has it when that scan's end comes.
pub fn with_wheels(inputs: Inputs, wheels: Vec<WheelSample>) -> Inputs {
    let mut inputs = inputs.peekable();
    let mut wheels = wheels.into_iter().peekable();
    Box::new(std::iter::from_fn(move || {
        let next_input_ns = match inputs.peek() {
            Some(Ok(i)) => Some(i.time_ns()),
            Some(Err(_)) => return inputs.next(),
            None => None,
        };
        match (wheels.peek(), next_input_ns) {
            (Some(w), Some(t)) if w.t_ns <= t => wheels.next().map(|w| Ok(MissionInput::Wheel(Side::Robot, w))),
            (Some(_), None) => wheels.next().map(|w| Ok(MissionInput::Wheel(Side::Robot, w))),
            _ => inputs.next(),
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    const OMNI3: KinematicsConfig =
        KinematicsConfig::Omni3 { wheel_radius_m: 0.05, center_to_wheel_m: 0.2, wheel_angles_deg: None };

    fn c620_line(t_us: u64, esc: u8, wheel_rad_s: f64) -> String {
        let rpm = (wheel_rad_s * M3508_GEAR_RATIO * 60.0 / std::f64::consts::TAU).round() as i16;
        let f = Feedback { esc, angle_raw: 0, rotor_rpm: rpm, current_raw: 0, temperature_c: 30 };
        let frame = f.to_frame().unwrap_or_else(|e| panic!("{e}"));
        format!("({}.{:06}) can0 {frame}", t_us / 1_000_000, t_us % 1_000_000)
    }

    #[test]
    fn a_log_of_three_omni_wheels_gives_the_body_twist() {
        let kin = Kinematics::new(&OMNI3).unwrap_or_else(|e| panic!("{e}"));
        // Driving straight ahead at 0.5 m/s: the wheel rates the base driver commands for it.
        let rates = kin.wheel_rates(starc_base::kinematics::Twist::new(0.5, 0.0, 0.0));
        let mut log = String::new();
        for cycle in 0..3u64 {
            for (i, w) in rates.iter().enumerate() {
                log += &(c620_line(1_000_000 + cycle * 10_000 + i as u64 * 130, i as u8 + 1, *w) + "\n");
            }
            log += "(1.000000) can0 700#05\n";
        }
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("robot_can.log");
        std::fs::write(&path, log).unwrap_or_else(|e| panic!("{e}"));
        let base = WheelFeedback::plain(OMNI3, MotorFeedback::C620);
        let got = read_wheel_log(&path, &base, 0).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(got.len(), 3);
        assert_eq!(got[1].t_ns, 1_010_000_000);
        // The C620 reports whole rotor rpm: a few mm/s of quantisation.
        assert!((got[0].vx_m_s - 0.5).abs() < 0.01 && got[0].vy_m_s.abs() < 0.01, "{:?}", got[0]);
    }

    #[test]
    fn wheels_go_before_the_inputs_they_precede() {
        use starc_pipeline::lio::ImuSample;
        let still =
            |t_ns| ImuSample { t_ns, clock: Clock::Ptp, gyro_rad_s: Default::default(), acc_m_s2: Default::default() };
        let imu = |t_ns| Ok(MissionInput::Imu(Side::Robot, still(t_ns)));
        let wheel = |t_ns| WheelSample { t_ns, clock: Clock::Ptp, vx_m_s: 0.0, vy_m_s: 0.0, wz_rad_s: 0.0 };
        let inputs: Inputs = Box::new(vec![imu(10), imu(20), imu(30)].into_iter());
        let merged: Vec<u64> =
            with_wheels(inputs, vec![wheel(5), wheel(20), wheel(40)]).map(|i| i.map_or(0, |i| i.time_ns())).collect();
        assert_eq!(merged, vec![5, 10, 20, 20, 30, 40]);
    }
}
