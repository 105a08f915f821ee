//! A mission's inputs, both devices in time order, from either source: a capture of both Avias
//! (a `starc sim` pcap, or a real one: scans assembled here), or the nodes' MCAP recordings
//! (`/robot/...` and `/fpv/...` topics, merged by time).

use crate::livox::{lio_scan, packet_imu};
use crate::recorded::{recorded, Recorded};
use crate::BridgeError;
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_livox::ports::DEVICE_CMD_PORT;
use starc_livox::scan::{ScanAssembler, ScanConfig};
use starc_pipeline::lio::{ImuSample, LioScan};
use starc_pipeline::mission::{MissionInput as Input, Side};
use starc_pipeline::record::{self, ReadMode};
use std::collections::VecDeque;
use std::net::Ipv4Addr;
use std::path::{Path, PathBuf};

/// Items of an input stream.
pub type Inputs = Box<dyn Iterator<Item = Result<Input, BridgeError>> + Send>;

/// Both Avias of a capture: `robot` and `rig` are their source addresses; others are skipped.
pub fn from_capture(path: &Path, robot: Ipv4Addr, rig: Ipv4Addr) -> Result<Inputs, BridgeError> {
    let mut cap = capture::open(path).map_err(|source| BridgeError::Capture { path: path.into(), source })?;
    let mut assemblers = [assembler()?, assembler()?];
    let mut ready: VecDeque<Input> = VecDeque::new();
    let path = path.to_path_buf();
    Ok(Box::new(std::iter::from_fn(move || loop {
        if let Some(i) = ready.pop_front() {
            return Some(Ok(i));
        }
        let d = match cap.next()? {
            Ok(d) => d,
            Err(source) => return Some(Err(BridgeError::Capture { path: path.clone(), source })),
        };
        let Some(src) = d.src else { continue };
        let side = match *src.ip() {
            ip if ip == robot => Side::Robot,
            ip if ip == rig => Side::Rig,
            _ => continue,
        };
        let Ok(packet) = DataPacket::parse(&d.payload) else { continue };
        if let Some(s) = packet_imu(&packet) {
            ready.push_back(Input::Imu(side, s));
        } else if !packet.is_imu() {
            let mut done = Vec::new();
            assemblers[usize::from(side == Side::Rig)].push(&packet, None, &mut done);
            ready.extend(done.iter().map(|s| Input::Scan(side, lio_scan(s))));
        }
    })))
}

fn assembler() -> Result<ScanAssembler, BridgeError> {
    ScanAssembler::new(ScanConfig::default()).map_err(BridgeError::Scan)
}

/// One Avia's IMU samples and scans from a capture.
#[derive(Default)]
pub struct AviaInputs {
    pub imu: Vec<ImuSample>,
    pub scans: Vec<LioScan>,
}

/// Everything the Avia at `avia` sent in a capture, decoded (control traffic skipped): for
/// `starc lio`, the benches and the tests that feed one LIO directly.
pub fn decode_avia(path: &Path, avia: Ipv4Addr) -> Result<AviaInputs, BridgeError> {
    let cap = capture::open(path).map_err(|source| BridgeError::Capture { path: path.into(), source })?;
    let mut assembler = assembler()?;
    let (mut out, mut done) = (AviaInputs::default(), Vec::new());
    for d in cap {
        let d = d.map_err(|source| BridgeError::Capture { path: path.into(), source })?;
        let (Some(src), Some(dst)) = (d.src, d.dst) else { continue };
        if *src.ip() != avia || src.port() == DEVICE_CMD_PORT || dst.port() == DEVICE_CMD_PORT {
            continue;
        }
        let Ok(packet) = DataPacket::parse(&d.payload) else { continue };
        match packet_imu(&packet) {
            Some(s) => out.imu.push(s),
            None if !packet.is_imu() => assembler.push(&packet, None, &mut done),
            None => {}
        }
    }
    out.scans = done.iter().map(lio_scan).collect();
    Ok(out)
}

/// One recording's inputs, in file order.
fn recording(path: PathBuf) -> Result<Inputs, BridgeError> {
    let period_ns = (ScanConfig::default().period_ms * 1e6) as u64;
    let messages = record::reader::open(&path, ReadMode::Recover)
        .map_err(|source| BridgeError::Recording { path: path.clone(), source })?;
    Ok(Box::new(messages.filter_map(move |m| {
        let m = match m {
            Ok(m) => m,
            Err(source) => return Some(Err(BridgeError::Recording { path: path.clone(), source })),
        };
        match recorded(&m, period_ns) {
            Ok(Some(Recorded::Imu(dev, s))) => side(&dev).map(|d| Ok(Input::Imu(d, s))),
            Ok(Some(Recorded::Scan(dev, s))) => side(&dev).map(|d| Ok(Input::Scan(d, s))),
            Ok(Some(Recorded::Wheel(dev, w))) => side(&dev).map(|d| Ok(Input::Wheel(d, w))),
            Ok(None) => None,
            Err(e) => Some(Err(e)),
        }
    })))
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
pub fn from_recordings(paths: &[PathBuf]) -> Result<Inputs, BridgeError> {
    let mut streams = Vec::new();
    for p in paths {
        streams.push(recording(p.clone())?.peekable());
    }
    Ok(Box::new(std::iter::from_fn(move || {
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
    })))
}

/// Whether `path` starts with the MCAP magic (a node's recording, not a capture).
pub fn is_mcap(path: &Path) -> bool {
    let mut head = [0u8; 8];
    std::fs::File::open(path).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head)).is_ok()
        && head[..] == *record::scan::MAGIC
}
