//! Mock C620 ESCs with M3508 motors, sans-IO: current commands in, 1 kHz feedback out.
//!
//! The output shaft speed follows `k * current` (2.5 rad/s per A: 20 A gives about 480 rpm, the
//! M3508's no-load speed) with a first-order lag; feedback reports the rotor (x 3591/187).

use crate::motors::dynamics::FirstOrder;
use starc_base::c620::frame::{
    current_to_raw, raw_to_current, CurrentCommand, Feedback, ANGLE_COUNTS, M3508_GEAR_RATIO,
};
use starc_can::CanFrame;
use std::f64::consts::TAU;

/// Output rad/s per ampere at steady state.
pub const RAD_S_PER_A: f64 = 2.5;

#[derive(Clone, Debug)]
struct Esc {
    id: u8,
    current_a: f64,
    speed: FirstOrder,
    rotor_turns: f64,
    /// Stopped sending feedback (injected fault).
    dead: bool,
}

/// Up to eight ESCs on one bus.
#[derive(Clone, Debug)]
pub struct MockC620 {
    escs: Vec<Esc>,
    period_ns: u64,
    next_feedback_ns: u64,
    last_step_ns: Option<u64>,
    pub commands: u64,
}

impl MockC620 {
    pub fn new(ids: &[u8], feedback_hz: f64, tau_s: f64) -> Self {
        let period_ns = if feedback_hz > 0.0 { (1e9 / feedback_hz) as u64 } else { u64::MAX };
        Self {
            escs: ids
                .iter()
                .map(|&id| Esc { id, current_a: 0.0, speed: FirstOrder::new(tau_s), rotor_turns: 0.0, dead: false })
                .collect(),
            period_ns: period_ns.max(1),
            next_feedback_ns: 0,
            last_step_ns: None,
            commands: 0,
        }
    }

    /// A frame on the bus.
    pub fn on_frame(&mut self, frame: &CanFrame) {
        let Ok(cmd) = CurrentCommand::parse(frame) else { return };
        self.commands += 1;
        for esc in &mut self.escs {
            if let Some((group, slot)) = starc_base::c620::CommandGroup::of(esc.id) {
                if group == cmd.group {
                    esc.current_a = raw_to_current(cmd.raw.get(slot).copied().unwrap_or(0));
                }
            }
        }
    }

    /// ESC `id` stops sending feedback and its motor coasts.
    pub fn kill(&mut self, id: u8) {
        for esc in self.escs.iter_mut().filter(|e| e.id == id) {
            esc.dead = true;
        }
    }

    /// Output-shaft speeds in rad/s.
    pub fn speeds(&self) -> Vec<(u8, f64)> {
        self.escs.iter().map(|e| (e.id, e.speed.value)).collect()
    }

    /// Advances the motors to `now_ns` and appends the feedback frames due.
    pub fn poll(&mut self, now_ns: u64, out: &mut Vec<CanFrame>) {
        let dt = self.last_step_ns.map(|t| now_ns.saturating_sub(t) as f64 * 1e-9).unwrap_or(0.0);
        self.last_step_ns = Some(now_ns);
        for esc in &mut self.escs {
            let target = if esc.dead { 0.0 } else { esc.current_a * RAD_S_PER_A };
            let before = esc.speed.value;
            let after = esc.speed.step(target, dt);
            esc.rotor_turns += 0.5 * (before + after) * dt / TAU * M3508_GEAR_RATIO;
        }
        // Feedback is due every period. A late wake-up (the host timer is only good to about a
        // millisecond) sends the missed ones at once, up to a few; after a longer stall the
        // schedule restarts from now.
        let mut due = 0;
        while self.next_feedback_ns <= now_ns && due < 5 {
            due += 1;
            self.next_feedback_ns += self.period_ns;
        }
        if self.next_feedback_ns <= now_ns {
            self.next_feedback_ns = (now_ns / self.period_ns + 1) * self.period_ns;
        }
        for _ in 0..due {
            self.push_feedback(out);
        }
    }

    fn push_feedback(&self, out: &mut Vec<CanFrame>) {
        for esc in self.escs.iter().filter(|e| !e.dead) {
            let rotor_rpm = esc.speed.value * M3508_GEAR_RATIO * 60.0 / TAU;
            let angle = (esc.rotor_turns.rem_euclid(1.0) * f64::from(ANGLE_COUNTS)) as u16 % ANGLE_COUNTS;
            let fb = Feedback {
                esc: esc.id,
                angle_raw: angle,
                rotor_rpm: rotor_rpm.round().clamp(-32768.0, 32767.0) as i16,
                current_raw: current_to_raw(esc.current_a),
                temperature_c: (30.0 + esc.current_a.abs() * 0.5) as u8,
            };
            if let Ok(f) = fb.to_frame() {
                out.push(f);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use starc_base::c620::CommandGroup;

    #[test]
    fn current_spins_the_motor_and_feedback_flows_at_the_rate() {
        let mut m = MockC620::new(&[1, 2, 5], 1000.0, 0.05);
        let cmd = CurrentCommand { group: CommandGroup::Low, raw: [current_to_raw(4.0), current_to_raw(-2.0), 0, 0] };
        m.on_frame(&cmd.to_frame().unwrap_or_else(|e| panic!("{e}")));
        let mut out = Vec::new();
        for ms in 0..=500u64 {
            m.poll(ms * 1_000_000, &mut out);
        }
        assert_eq!(out.len(), 501 * 3);
        let last: Vec<Feedback> = out.iter().rev().take(3).filter_map(|f| Feedback::parse(f).ok()).collect();
        let by_id = |id: u8| last.iter().find(|f| f.esc == id).copied().unwrap_or_else(|| panic!("no {id}"));
        // 4 A -> 10 rad/s at the output after 10 tau.
        assert!((by_id(1).output_rad_s(M3508_GEAR_RATIO) - 10.0).abs() < 0.05, "{:?}", by_id(1));
        assert!((by_id(2).output_rad_s(M3508_GEAR_RATIO) + 5.0).abs() < 0.05);
        assert_eq!(by_id(5).rotor_rpm, 0);
        // Late, uneven wake-ups still give 1 kHz on average.
        let mut late = MockC620::new(&[1], 1000.0, 0.05);
        let mut n = Vec::new();
        for k in 0..400u64 {
            late.poll(k * 2_500_000 + (k % 3) * 300_000, &mut n);
        }
        assert!((995..=1001).contains(&n.len()), "{}", n.len());
        m.kill(2);
        out.clear();
        m.poll(501_000_000, &mut out);
        assert_eq!(out.len(), 2);
    }
}
