//! One status line per second in ptp4l's words, so logs from both read the same:
//!
//! `starc-ptp[812.004]: master offset       -612 s2 freq   +1503 path delay      8123`
//!
//! - `master offset`: local clock minus master clock, ns (UTC-corrected for a PTP-timescale
//!   master), after subtracting the path delay;
//! - `s0`/`s1`/`s2`: no estimate yet / offset past the step threshold / tracking;
//! - `freq`: the local clock's frequency error against the master in ppb (positive: local fast);
//!   measure-only it is the slope of the offsets, steering it is the servo's output;
//! - `path delay`: the filtered mean one-way delay, ns.

use crate::port::{MasterStats, SlaveSample};

/// Seconds since boot (CLOCK_MONOTONIC), as ptp4l prefixes its lines.
pub fn uptime_s() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes one timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

pub fn slave_line(uptime_s: f64, s: &SlaveSample) -> String {
    format!(
        "starc-ptp[{uptime_s:.3}]: master offset {:10} s{} freq {:+7.0} path delay {:9}",
        s.offset_ns,
        s.state.code(),
        s.freq_ppb,
        s.path_delay_ns
    )
}

pub fn master_line(uptime_s: f64, s: &MasterStats) -> String {
    let client = s.last_client.map(|c| c.to_string()).unwrap_or_else(|| "none".into());
    format!(
        "starc-ptp[{uptime_s:.3}]: master sync {} follow_up {} announce {} delay_resp {} last client {client}",
        s.syncs, s.follow_ups, s.announces, s.delay_resps
    )
}

/// Reads `master offset N sK freq F path delay D` out of a ptp4l or starc-ptp line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OffsetLine {
    pub offset_ns: i64,
    pub state: u8,
    pub freq_ppb: f64,
    pub path_delay_ns: i64,
}

pub fn parse_offset_line(line: &str) -> Option<OffsetLine> {
    let rest = line.split("master offset").nth(1)?;
    let mut words = rest.split_whitespace();
    let offset_ns = words.next()?.parse().ok()?;
    let state = words.next()?.strip_prefix('s')?.parse().ok()?;
    if words.next()? != "freq" {
        return None;
    }
    let freq_ppb = words.next()?.parse().ok()?;
    if (words.next()?, words.next()?) != ("path", "delay") {
        return None;
    }
    let path_delay_ns = words.next()?.parse().ok()?;
    Some(OffsetLine { offset_ns, state, freq_ppb, path_delay_ns })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::PortIdentity;
    use crate::servo::ServoState;

    #[test]
    fn our_line_and_ptp4l_line_parse_alike() {
        let s = SlaveSample {
            master: PortIdentity::default(),
            offset_ns: -612,
            path_delay_ns: 8123,
            freq_ppb: 1503.4,
            state: ServoState::Locked,
            local_ns: 0,
            utc_offset_s: 37,
        };
        let ours = slave_line(812.0042, &s);
        assert_eq!(ours, "starc-ptp[812.004]: master offset       -612 s2 freq   +1503 path delay      8123");
        let theirs = "ptp4l[3339.123]: master offset        -81 s2 freq   +1342 path delay      1203";
        let a = parse_offset_line(&ours);
        let b = parse_offset_line(theirs);
        assert_eq!(a, Some(OffsetLine { offset_ns: -612, state: 2, freq_ppb: 1503.0, path_delay_ns: 8123 }));
        assert_eq!(b, Some(OffsetLine { offset_ns: -81, state: 2, freq_ppb: 1342.0, path_delay_ns: 1203 }));
        assert_eq!(parse_offset_line("ptp4l[1.0]: port 1: LISTENING to MASTER"), None);
    }
}
