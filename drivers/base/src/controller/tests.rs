//! The controller with C620 ESCs simulated in the test: commands, watchdog, faults, clear.

use super::*;
use crate::c620::{CurrentCommand, Feedback};
use crate::config::BaseConfig;
use starc_can::RxFrame;
use starc_time::Clock;

/// A three-wheel C620 base (also the runner tests' base).
pub(crate) const CONFIG: &str = r#"
watchdog_ms = 200
[can]
transport = "socketcan"
interface = "can0"
[kinematics]
model = "omni3"
wheel_radius_m = 0.05
center_to_wheel_m = 0.2
[limits]
max_vx_m_s = 1.0
max_vy_m_s = 1.0
max_wz_rad_s = 2.0
max_accel_m_s2 = 100.0
max_alpha_rad_s2 = 100.0
max_wheel_rad_s = 50.0
[motors]
protocol = "c620"
wheels = [{ id = 1 }, { id = 2 }, { id = 3 }]
"#;

fn at_ms(ms: u64) -> Stamp {
    Stamp::new(ms * 1_000_000, Clock::Host)
}

/// Three ideal motors: the wheel rate follows current with a 20 ms time constant.
struct Plant {
    rate: [f64; 3],
}

impl Plant {
    fn step(&mut self, frames: &[CanFrame], dt: f64) {
        for f in frames {
            if let Ok(cmd) = CurrentCommand::parse(f) {
                for (r, raw) in self.rate.iter_mut().zip(cmd.raw) {
                    let target = crate::c620::frame::raw_to_current(raw) * 5.0;
                    *r += (target - *r) * (dt / 0.02).min(1.0);
                }
            }
        }
    }

    fn feedback(&self, now: Stamp) -> Vec<BusEvent> {
        self.rate
            .iter()
            .enumerate()
            .filter_map(|(i, r)| {
                let rpm = r * crate::c620::frame::M3508_GEAR_RATIO * 60.0 / std::f64::consts::TAU;
                let fb = Feedback {
                    esc: i as u8 + 1,
                    angle_raw: 0,
                    rotor_rpm: rpm as i16,
                    current_raw: 0,
                    temperature_c: 30,
                };
                fb.to_frame().ok().map(|frame| BusEvent::Frame(RxFrame { frame, host: now, device: None }))
            })
            .collect()
    }
}

fn base() -> Base {
    let config = BaseConfig::from_toml(CONFIG).unwrap_or_else(|e| panic!("{e}"));
    Base::new(config).unwrap_or_else(|e| panic!("{e}"))
}

/// Runs `ms` milliseconds; `silent` wheels send no feedback; commands every 50 ms when `drive`.
fn run(b: &mut Base, p: &mut Plant, from: u64, ms: u64, drive: Option<Twist>, silent: &[usize]) {
    for t in (from..from + ms).step_by(10) {
        if let Some(twist) = drive {
            if t % 50 == 0 {
                b.command(twist, at_ms(t));
            }
        }
        for (i, e) in p.feedback(at_ms(t)).into_iter().enumerate() {
            if !silent.contains(&i) {
                b.handle(&e);
            }
        }
        let mut out = Vec::new();
        b.tick(at_ms(t), &mut out);
        p.step(&out, 0.01);
    }
}

#[test]
fn follows_a_command_and_integrates_odometry() {
    let (mut b, mut p) = (base(), Plant { rate: [0.0; 3] });
    run(&mut b, &mut p, 0, 1000, Some(Twist::new(0.5, 0.0, 0.0)), &[]);
    let s = b.status();
    assert_eq!(s.mode, DriveMode::Run);
    assert!(s.faults.is_empty(), "{:?}", s.faults);
    let odo = s.odometry.unwrap_or_else(|| panic!("no odometry"));
    assert!((odo.twist.vx_m_s - 0.5).abs() < 0.05, "{odo:?}");
    assert!(odo.x_m > 0.3 && odo.y_m.abs() < 0.05, "{odo:?}");
}

#[test]
fn watchdog_brakes_then_a_command_resumes() {
    let (mut b, mut p) = (base(), Plant { rate: [0.0; 3] });
    run(&mut b, &mut p, 0, 500, Some(Twist::new(0.0, 0.0, 1.0)), &[]);
    assert!(b.drain_events().iter().all(|e| !matches!(e, BaseEvent::WatchdogTripped { .. })));
    run(&mut b, &mut p, 500, 600, None, &[]);
    let events = b.drain_events();
    assert_eq!(events.iter().filter(|e| matches!(e, BaseEvent::WatchdogTripped { .. })).count(), 1, "{events:?}");
    assert_eq!(b.status().mode, DriveMode::Brake);
    assert!(p.rate.iter().all(|r| r.abs() < 0.2), "{:?}", p.rate);
    run(&mut b, &mut p, 1100, 100, Some(Twist::new(0.0, 0.0, 1.0)), &[]);
    assert_eq!(b.status().mode, DriveMode::Run);
}

#[test]
fn feedback_loss_latches_until_cleared() {
    let (mut b, mut p) = (base(), Plant { rate: [0.0; 3] });
    run(&mut b, &mut p, 0, 300, Some(Twist::new(0.3, 0.0, 0.0)), &[]);
    run(&mut b, &mut p, 300, 300, Some(Twist::new(0.3, 0.0, 0.0)), &[1]);
    let s = b.status();
    assert_eq!(s.mode, DriveMode::Halt);
    assert!(matches!(s.faults.as_slice(), [Fault::FeedbackTimeout { wheel: 1, motor: 2, .. }]), "{:?}", s.faults);
    // Feedback back, commands flowing: still halted until the operator clears.
    run(&mut b, &mut p, 600, 200, Some(Twist::new(0.3, 0.0, 0.0)), &[]);
    assert_eq!(b.status().mode, DriveMode::Halt);
    assert!(b.clear_faults(at_ms(800)).is_ok());
    run(&mut b, &mut p, 800, 200, Some(Twist::new(0.3, 0.0, 0.0)), &[]);
    assert_eq!(b.status().mode, DriveMode::Run);
    assert!(b.status().faults.is_empty());
}

#[test]
fn estop_halts_and_blocks_clear_while_pressed() {
    let (mut b, mut p) = (base(), Plant { rate: [0.0; 3] });
    run(&mut b, &mut p, 0, 300, Some(Twist::new(0.3, 0.0, 0.0)), &[]);
    b.set_estop(true, at_ms(300));
    let mut out = Vec::new();
    b.tick(at_ms(310), &mut out);
    assert!(out.iter().all(|f| f.data().iter().all(|&x| x == 0)), "zero current at once");
    assert!(b.clear_faults(at_ms(320)).is_err());
    b.set_estop(false, at_ms(330));
    assert_eq!(b.status().mode, DriveMode::Halt);
    assert!(b.clear_faults(at_ms(340)).is_ok());
}

#[test]
fn bus_faults_stop_the_base() {
    let mut b = base();
    let fault = starc_can::BusFault::SlcanFlags { flags: starc_can::slcan::StatusFlags(0x80) };
    b.handle(&BusEvent::Fault { fault, host: at_ms(1) });
    assert!(matches!(b.status().faults.as_slice(), [Fault::Bus { .. }]));
}
