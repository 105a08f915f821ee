//! Steering a clock with clock_adjtime: only for a slave started with an explicit
//! `--adjust-clock`, never by default and never in tests (they would move the machine's time).

use crate::error::{PtpError, Result};
use std::fs::File;
use std::os::fd::AsRawFd;
use std::path::PathBuf;

/// Which clock to steer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AdjustTarget {
    /// The system clock (CLOCK_REALTIME).
    Realtime,
    /// A PTP hardware clock, e.g. /dev/ptp0.
    Phc(PathBuf),
}

impl std::str::FromStr for AdjustTarget {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "realtime" | "CLOCK_REALTIME" => Ok(Self::Realtime),
            p if p.starts_with("/dev/ptp") => Ok(Self::Phc(PathBuf::from(p))),
            other => Err(format!("{other}: say `realtime` or a /dev/ptpN path")),
        }
    }
}

/// An open clock that can be stepped and have its frequency set.
pub struct ClockAdjuster {
    clock_id: libc::clockid_t,
    name: String,
    /// Keeps the PHC's descriptor (its clock id is derived from it) open.
    _phc: Option<File>,
}

/// The dynamic clock id of an open PHC descriptor: ((~fd) << 3) | CLOCKFD, as the kernel's
/// posix-clock API defines it.
fn fd_to_clock_id(fd: i32) -> libc::clockid_t {
    ((!fd) << 3) | 3
}

impl ClockAdjuster {
    pub fn open(target: &AdjustTarget) -> Result<Self> {
        match target {
            AdjustTarget::Realtime => {
                Ok(Self { clock_id: libc::CLOCK_REALTIME, name: "CLOCK_REALTIME".into(), _phc: None })
            }
            AdjustTarget::Phc(path) => {
                let file = std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .open(path)
                    .map_err(|e| PtpError::io(format!("open {}", path.display()), e))?;
                let clock_id = fd_to_clock_id(file.as_raw_fd());
                Ok(Self { clock_id, name: path.display().to_string(), _phc: Some(file) })
            }
        }
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    fn adjtime(&self, tx: &mut libc::timex, what: &str) -> Result<()> {
        // SAFETY: clock_adjtime reads and writes the timex we own.
        let ret = unsafe { libc::clock_adjtime(self.clock_id, tx) };
        if ret < 0 {
            return Err(PtpError::io(
                format!("clock_adjtime {what} on {}", self.name),
                std::io::Error::last_os_error(),
            ));
        }
        Ok(())
    }

    /// Moves the clock by `offset_ns` at once (ADJ_SETOFFSET).
    pub fn step(&self, offset_ns: i64) -> Result<()> {
        // SAFETY: timex is plain data; zeroed is valid.
        let mut tx: libc::timex = unsafe { std::mem::zeroed() };
        tx.modes = libc::ADJ_SETOFFSET | libc::ADJ_NANO;
        let (mut s, mut ns) = (offset_ns / 1_000_000_000, offset_ns % 1_000_000_000);
        if ns < 0 {
            s -= 1;
            ns += 1_000_000_000;
        }
        tx.time.tv_sec = s as libc::time_t;
        tx.time.tv_usec = ns as libc::suseconds_t;
        self.adjtime(&mut tx, "step")
    }

    /// Runs the clock `ppb` faster than nominal (ADJ_FREQUENCY; units of 2^-16 ppm).
    pub fn set_frequency(&self, ppb: f64) -> Result<()> {
        // SAFETY: timex is plain data; zeroed is valid.
        let mut tx: libc::timex = unsafe { std::mem::zeroed() };
        tx.modes = libc::ADJ_FREQUENCY;
        tx.freq = (ppb / 1000.0 * 65536.0).round() as libc::c_long;
        self.adjtime(&mut tx, "frequency")
    }
}
