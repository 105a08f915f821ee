//! The offline mission's inputs, in time order, from either source: a capture of both Avias
//! (a `starc sim` pcap: scans assembled here), or the nodes' MCAP recordings (`/robot/...` and
//! `/fpv/...` topics, merged by time).

use super::lio_input::{internal_imu, lio_scan, recorded, Recorded};
use super::mission::{FPV_AVIA, ROBOT_AVIA};
use anyhow::Context;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::lio::{ImuSample, LioScan};
use starc_pipeline::record::{self, ReadMode};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Robot,
    Rig,
}

pub enum Input {
    Imu(Side, ImuSample),
    Scan(Side, LioScan),
}

impl Input {
    /// When the input is complete: a scan at its end, an IMU sample at its time.
    fn time_ns(&self) -> u64 {
        match self {
            Input::Imu(_, s) => s.t_ns,
            Input::Scan(_, s) => s.end_ns,
        }
    }
}

/// Both Avias of a simulated run's capture.
pub fn from_capture(path: &Path) -> anyhow::Result<impl Iterator<Item = anyhow::Result<Input>>> {
    let cap = capture::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut robot = ScanAssembler::new(ScanConfig::default()).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut rig = ScanAssembler::new(ScanConfig::default()).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut ready: VecDeque<Input> = VecDeque::new();
    let mut cap = cap;
    Ok(std::iter::from_fn(move || loop {
        if let Some(i) = ready.pop_front() {
            return Some(Ok(i));
        }
        let d = match cap.next()? {
            Ok(d) => d,
            Err(e) => return Some(Err(e.into())),
        };
        let Some(src) = d.src else { continue };
        let side = match *src.ip() {
            ip if ip == ROBOT_AVIA => Side::Robot,
            ip if ip == FPV_AVIA => Side::Rig,
            _ => continue,
        };
        let Ok(packet) = DataPacket::parse(&d.payload) else { continue };
        if let Some(s) = internal_imu(&packet) {
            ready.push_back(Input::Imu(side, s));
        } else if !packet.is_imu() {
            let mut done = Vec::new();
            if side == Side::Robot { &mut robot } else { &mut rig }.push(&packet, None, &mut done);
            ready.extend(done.iter().map(|s| Input::Scan(side, lio_scan(s))));
        }
    }))
}

/// One recording's inputs, in file order.
fn recording(path: PathBuf) -> anyhow::Result<impl Iterator<Item = anyhow::Result<Input>>> {
    let period_ns = (ScanConfig::default().period_ms * 1e6) as u64;
    let messages =
        record::reader::open(&path, ReadMode::Recover).with_context(|| format!("opening {}", path.display()))?;
    Ok(messages.filter_map(move |m| {
        let m = match m {
            Ok(m) => m,
            Err(e) => return Some(Err(anyhow::anyhow!("{}: {e}", path.display()))),
        };
        match recorded(&m, period_ns) {
            Ok(Some(Recorded::Imu(dev, s))) => side(&dev).map(|d| Ok(Input::Imu(d, s))),
            Ok(Some(Recorded::Scan(dev, s))) => side(&dev).map(|d| Ok(Input::Scan(d, s))),
            Ok(None) => None,
            Err(e) => Some(Err(e)),
        }
    }))
}

fn side(device: &str) -> Option<Side> {
    match device {
        "robot" => Some(Side::Robot),
        "fpv" | "rig" => Some(Side::Rig),
        _ => None,
    }
}

/// The nodes' recordings merged by time (each file is in time order, near enough: the LIO
/// buffers what arrives a little out of order).
pub fn from_recordings(paths: &[PathBuf]) -> anyhow::Result<impl Iterator<Item = anyhow::Result<Input>>> {
    let mut streams = Vec::new();
    for p in paths {
        let s: Box<dyn Iterator<Item = anyhow::Result<Input>>> = Box::new(recording(p.clone())?);
        streams.push(s.peekable());
    }
    Ok(std::iter::from_fn(move || {
        let mut best: Option<(usize, u64)> = None;
        for (i, s) in streams.iter_mut().enumerate() {
            let t = match s.peek() {
                None => continue,
                Some(Ok(input)) => input.time_ns(),
                Some(Err(_)) => 0,
            };
            if best.is_none_or(|(_, b)| t < b) {
                best = Some((i, t));
            }
        }
        let (i, _) = best?;
        streams.get_mut(i)?.next()
    }))
}
