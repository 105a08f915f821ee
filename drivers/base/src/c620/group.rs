//! A group of C620 ESCs driven as wheels: a PI velocity loop per wheel on the host (the C620
//! takes current commands), feedback time-outs, and the two command frames.

use crate::c620::frame::{current_to_raw, CommandGroup, CurrentCommand, Feedback, M3508_GEAR_RATIO};
use crate::error::{BaseError, Result};
use crate::motor::{elapsed_ms, MotorPhase, WheelState};
use crate::safety::{DriveMode, Fault};
use serde::{Deserialize, Serialize};
use starc_can::CanFrame;
use starc_time::Stamp;

/// C620 settings from the config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct C620Config {
    /// Rotor turns per wheel turn (M3508: 3591/187).
    pub gear_ratio: f64,
    /// Proportional gain, amperes per rad/s of wheel-rate error.
    pub kp_a_per_rad_s: f64,
    /// Integral gain, amperes per rad of accumulated error.
    pub ki_a_per_rad: f64,
    /// Current limit, at most 20 A.
    pub max_current_a: f64,
}

impl Default for C620Config {
    fn default() -> Self {
        Self { gear_ratio: M3508_GEAR_RATIO, kp_a_per_rad_s: 0.5, ki_a_per_rad: 5.0, max_current_a: 10.0 }
    }
}

impl C620Config {
    pub fn validate(&self) -> Result<()> {
        if !(self.gear_ratio.is_finite() && self.gear_ratio > 0.0) {
            return Err(BaseError::config("motors.c620.gear_ratio", "must be > 0"));
        }
        if !(self.max_current_a.is_finite() && self.max_current_a > 0.0 && self.max_current_a <= 20.0) {
            return Err(BaseError::config("motors.c620.max_current_a", "must be in (0, 20]"));
        }
        if !(self.kp_a_per_rad_s.is_finite()
            && self.kp_a_per_rad_s >= 0.0
            && self.ki_a_per_rad.is_finite()
            && self.ki_a_per_rad >= 0.0)
        {
            return Err(BaseError::config("motors.c620", "gains must be finite and >= 0"));
        }
        Ok(())
    }
}

/// PI with a clamped integrator (no wind-up past the current limit).
#[derive(Clone, Debug, Default)]
struct Pi {
    integral: f64,
}

impl Pi {
    fn step(&mut self, c: &C620Config, error: f64, dt_s: f64) -> f64 {
        if c.ki_a_per_rad > 0.0 {
            let bound = c.max_current_a / c.ki_a_per_rad;
            self.integral = (self.integral + error * dt_s).clamp(-bound, bound);
        }
        (c.kp_a_per_rad_s * error + c.ki_a_per_rad * self.integral).clamp(-c.max_current_a, c.max_current_a)
    }
}

#[derive(Clone, Debug)]
struct Wheel {
    esc: u8,
    sign: f64,
    pi: Pi,
    feedback: Option<(Feedback, Stamp)>,
    timed_out: bool,
    state: WheelState,
}

/// The ESCs of one base.
#[derive(Clone, Debug)]
pub struct C620Group {
    config: C620Config,
    feedback_timeout_ms: u64,
    wheels: Vec<Wheel>,
    started: Option<Stamp>,
    last_tick: Option<Stamp>,
    /// Feedback frames that did not parse.
    pub malformed: u64,
}

impl C620Group {
    /// `escs`: (ESC id 1-8, inverted) per wheel, in kinematics order.
    pub fn new(config: C620Config, escs: &[(u8, bool)], feedback_timeout_ms: u64) -> Result<Self> {
        config.validate()?;
        let mut wheels = Vec::new();
        for (i, &(esc, invert)) in escs.iter().enumerate() {
            if CommandGroup::of(esc).is_none() {
                return Err(BaseError::config("motors.wheels.id", format!("C620 ESC id {esc} is not 1-8")));
            }
            if escs.iter().filter(|(e, _)| *e == esc).count() > 1 {
                return Err(BaseError::config("motors.wheels.id", format!("ESC id {esc} used twice")));
            }
            wheels.push(Wheel {
                esc,
                sign: if invert { -1.0 } else { 1.0 },
                pi: Pi::default(),
                feedback: None,
                timed_out: false,
                state: WheelState::new(i, esc),
            });
        }
        Ok(Self { config, feedback_timeout_ms, wheels, started: None, last_tick: None, malformed: 0 })
    }

    /// Takes a frame if it is feedback from one of our ESCs.
    pub fn handle_frame(&mut self, frame: &CanFrame, now: Stamp) -> bool {
        let raw = frame.id().raw();
        if frame.id().is_extended() || !(0x201..=0x208).contains(&raw) {
            return false;
        }
        match Feedback::parse(frame) {
            Ok(fb) => {
                let Some(w) = self.wheels.iter_mut().find(|w| w.esc == fb.esc) else { return false };
                let rate = w.sign * fb.output_rad_s(self.config.gear_ratio);
                w.feedback = Some((fb, now));
                w.state.measured_rad_s = Some(rate);
                w.state.current_a = Some(w.sign * fb.current_a());
                w.state.temperature_c = Some(f64::from(fb.temperature_c));
                w.state.last_feedback = Some(now);
                true
            }
            Err(e) => {
                self.malformed += 1;
                tracing::debug!("C620: {e}");
                true
            }
        }
    }

    /// One control period: checks feedback ages, runs the loops, appends the command frames.
    pub fn tick(
        &mut self,
        now: Stamp,
        mode: DriveMode,
        targets: &[f64],
        out: &mut Vec<CanFrame>,
        faults: &mut Vec<Fault>,
    ) {
        let started = *self.started.get_or_insert(now);
        let dt_s = self.last_tick.map(|t| elapsed_ms(now, t) as f64 * 1e-3).unwrap_or(0.0).min(0.1);
        self.last_tick = Some(now);
        let mut low = CurrentCommand { group: CommandGroup::Low, raw: [0; 4] };
        let mut high = CurrentCommand { group: CommandGroup::High, raw: [0; 4] };
        let (mut use_low, mut use_high) = (false, false);
        for (i, w) in self.wheels.iter_mut().enumerate() {
            let silent_ms = elapsed_ms(now, w.feedback.map(|(_, t)| t).unwrap_or(started));
            let fresh = silent_ms <= self.feedback_timeout_ms;
            if !fresh && !w.timed_out {
                w.timed_out = true;
                faults.push(Fault::FeedbackTimeout { wheel: i, motor: w.esc, silent_ms });
            }
            let target = match mode {
                DriveMode::Run => targets.get(i).copied().unwrap_or(0.0),
                DriveMode::Brake | DriveMode::Halt => 0.0,
            };
            let current_a = match (mode, fresh, w.state.measured_rad_s) {
                (DriveMode::Halt, _, _) | (_, false, _) | (_, _, None) => {
                    w.pi = Pi::default();
                    0.0
                }
                // No fresh command (the watchdog): only current that opposes the wheel's motion,
                // proportional to it, so it falls to zero as the wheel stops. The integral is
                // dropped: wound up while driving (or against a blocked wheel) it would go on
                // pushing with nobody commanding.
                (DriveMode::Brake, true, Some(measured)) => {
                    w.pi = Pi::default();
                    let max = self.config.max_current_a;
                    (-self.config.kp_a_per_rad_s * measured).clamp(-max, max)
                }
                (DriveMode::Run, true, Some(measured)) => w.pi.step(&self.config, target - measured, dt_s),
            };
            w.state.target_rad_s = target;
            w.state.phase = if w.timed_out {
                MotorPhase::Faulted
            } else if w.feedback.is_some() {
                MotorPhase::Running
            } else {
                MotorPhase::Silent
            };
            let raw = current_to_raw(w.sign * current_a);
            if let Some((group, slot)) = CommandGroup::of(w.esc) {
                let (cmd, used) = match group {
                    CommandGroup::Low => (&mut low, &mut use_low),
                    CommandGroup::High => (&mut high, &mut use_high),
                };
                if let Some(r) = cmd.raw.get_mut(slot) {
                    *r = raw;
                }
                *used = true;
            }
        }
        for (cmd, used) in [(low, use_low), (high, use_high)] {
            if used {
                if let Ok(f) = cmd.to_frame() {
                    out.push(f);
                }
            }
        }
    }

    /// Operator clear: feedback time-outs may fire again.
    pub fn clear(&mut self) {
        for w in &mut self.wheels {
            w.timed_out = false;
            w.pi = Pi::default();
        }
    }

    /// Measured wheel rates, when every wheel has fresh feedback.
    pub fn measured(&self, now: Stamp) -> Option<Vec<f64>> {
        self.wheels
            .iter()
            .map(|w| match (w.state.measured_rad_s, w.feedback) {
                (Some(r), Some((_, t))) if elapsed_ms(now, t) <= self.feedback_timeout_ms => Some(r),
                _ => None,
            })
            .collect()
    }

    pub fn wheel_states(&self) -> Vec<WheelState> {
        self.wheels.iter().map(|w| w.state.clone()).collect()
    }

    /// The frames that stop every ESC (zero current), for shutdown.
    pub fn halt_frames(&self) -> Vec<CanFrame> {
        let mut out = Vec::new();
        for group in [CommandGroup::Low, CommandGroup::High] {
            if self.wheels.iter().any(|w| CommandGroup::of(w.esc).map(|(g, _)| g) == Some(group)) {
                if let Ok(f) = (CurrentCommand { group, raw: [0; 4] }).to_frame() {
                    out.push(f);
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_time::Clock;

    fn at_ms(ms: u64) -> Stamp {
        Stamp::new(ms * 1_000_000, Clock::Host)
    }

    fn feedback(esc: u8, rotor_rpm: i16) -> CanFrame {
        Feedback { esc, angle_raw: 0, rotor_rpm, current_raw: 0, temperature_c: 30 }
            .to_frame()
            .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn commands_go_to_the_right_slots_with_inversion() -> Result<()> {
        let mut g = C620Group::new(
            C620Config { ki_a_per_rad: 0.0, kp_a_per_rad_s: 1.0, ..Default::default() },
            &[(1, false), (2, true), (5, false)],
            100,
        )?;
        for esc in [1, 2, 5] {
            assert!(g.handle_frame(&feedback(esc, 0), at_ms(0)));
        }
        assert!(!g.handle_frame(&feedback(3, 0), at_ms(0)), "ESC 3 is not ours");
        let (mut out, mut faults) = (Vec::new(), Vec::new());
        g.tick(at_ms(1), DriveMode::Run, &[2.0, 2.0, -1.0], &mut out, &mut faults);
        assert!(faults.is_empty());
        let low = CurrentCommand::parse(out.first().unwrap_or_else(|| panic!("no frame")))?;
        let high = CurrentCommand::parse(out.get(1).unwrap_or_else(|| panic!("no frame")))?;
        assert_eq!(low.raw, [current_to_raw(2.0), current_to_raw(-2.0), 0, 0]);
        assert_eq!(high.raw, [current_to_raw(-1.0), 0, 0, 0]);
        out.clear();
        g.tick(at_ms(2), DriveMode::Halt, &[2.0, 2.0, -1.0], &mut out, &mut faults);
        assert!(out.iter().all(|f| f.data().iter().all(|&b| b == 0)));
        Ok(())
    }

    #[test]
    fn silence_raises_one_timeout_per_wheel_until_cleared() -> Result<()> {
        let mut g = C620Group::new(C620Config::default(), &[(1, false), (2, false)], 100)?;
        let (mut out, mut faults) = (Vec::new(), Vec::new());
        g.tick(at_ms(0), DriveMode::Run, &[1.0, 1.0], &mut out, &mut faults);
        g.handle_frame(&feedback(1, 1000), at_ms(50));
        g.handle_frame(&feedback(2, 1000), at_ms(50));
        g.tick(at_ms(120), DriveMode::Run, &[1.0, 1.0], &mut out, &mut faults);
        assert!(faults.is_empty());
        assert!(g.measured(at_ms(120)).is_some());
        g.handle_frame(&feedback(1, 1000), at_ms(150));
        g.tick(at_ms(160), DriveMode::Run, &[1.0, 1.0], &mut out, &mut faults);
        g.tick(at_ms(170), DriveMode::Run, &[1.0, 1.0], &mut out, &mut faults);
        assert_eq!(faults, vec![Fault::FeedbackTimeout { wheel: 1, motor: 2, silent_ms: 110 }]);
        assert!(g.measured(at_ms(170)).is_none());
        g.clear();
        g.tick(at_ms(180), DriveMode::Run, &[1.0, 1.0], &mut out, &mut faults);
        assert_eq!(faults.len(), 2, "fires again after a clear while still silent");
        Ok(())
    }

    #[test]
    fn without_a_fresh_command_only_braking_current_is_sent() -> Result<()> {
        let mut g = C620Group::new(C620Config::default(), &[(1, false), (2, true)], 100)?;
        let (mut out, mut faults) = (Vec::new(), Vec::new());
        let currents = |out: &[CanFrame]| out.last().and_then(|f| CurrentCommand::parse(f).ok()).map(|c| c.raw);
        // Driving against wheels that do not turn (blocked): the integral winds up.
        for t in 0..50 {
            g.handle_frame(&feedback(1, 0), at_ms(t * 10));
            g.handle_frame(&feedback(2, 0), at_ms(t * 10));
            g.tick(at_ms(t * 10), DriveMode::Run, &[5.0, 5.0], &mut out, &mut faults);
        }
        let driving = currents(&out).unwrap_or_default();
        assert!(driving[0] > 0 && driving[1] < 0, "{driving:?}");
        // The watchdog fired (Brake): standing wheels get no current at all, wound-up integral
        // or not.
        g.handle_frame(&feedback(1, 0), at_ms(500));
        g.handle_frame(&feedback(2, 0), at_ms(500));
        g.tick(at_ms(500), DriveMode::Brake, &[5.0, 5.0], &mut out, &mut faults);
        assert_eq!(currents(&out), Some([0, 0, 0, 0]));
        // Turning wheels get current against their motion only (ESC 2 inverted).
        g.handle_frame(&feedback(1, 2000), at_ms(510));
        g.handle_frame(&feedback(2, 2000), at_ms(510));
        g.tick(at_ms(510), DriveMode::Brake, &[5.0, 5.0], &mut out, &mut faults);
        let braking = currents(&out).unwrap_or_default();
        assert!(braking[0] < 0 && braking[1] < 0, "{braking:?}");
        assert!(faults.is_empty(), "{faults:?}");
        Ok(())
    }

    #[test]
    fn bad_ids_are_refused() {
        assert!(C620Group::new(C620Config::default(), &[(0, false)], 100).is_err());
        assert!(C620Group::new(C620Config::default(), &[(1, false), (1, true)], 100).is_err());
        assert!(C620Group::new(C620Config { max_current_a: 30.0, ..Default::default() }, &[(1, false)], 100).is_err());
    }
}
