//! Clock models: map a device's timestamps (PTP, GPS, PPS or its free-running clock) onto the
//! host clock, so IMU, LiDAR and wheel samples taken at the same instant get the same host time.
//!
//! Input: pairs (device stamp, host receive stamp). The receive stamp is late by the transport
//! latency, which is never below some floor and often well above it (queues, interrupts,
//! scheduling). So the pairs, drawn as `host - device` against device time, lie on or above a
//! line whose slope is the skew and whose height is offset + minimum latency. The model fits
//! that lower envelope, not the cloud's middle: the line below all points that is closest to
//! them in total (a linear program whose optimum is the edge of the points' lower convex hull
//! spanning their mean device time). Latency spikes, however large, cannot pull it.
//!
//! The mapped time is "when the sample would have arrived over an idle link"; subtract a known
//! fixed latency (`fixed_latency_ns`) to get the sampling instant itself.

use crate::error::TimeError;
use crate::{Clock, Stamp};
use std::collections::{HashMap, VecDeque};

const NS_PER_S: i128 = 1_000_000_000;

#[derive(Clone, Debug, PartialEq)]
pub struct ClockModelConfig {
    /// Pairs kept at most.
    pub max_pairs: usize,
    /// Pairs older than this (device time) are forgotten, so a drifting skew is followed.
    pub window_ns: u64,
    /// Pairs needed before the slope is trusted; fewer give an offset-only model.
    pub min_pairs_for_skew: usize,
    /// Known constant latency (sampling to host receive) taken off every mapped stamp.
    pub fixed_latency_ns: i64,
}

impl Default for ClockModelConfig {
    fn default() -> Self {
        Self { max_pairs: 4096, window_ns: 60 * 1_000_000_000, min_pairs_for_skew: 8, fixed_latency_ns: 0 }
    }
}

/// The current fit: host = device + offset_ns + skew * (device - device_ref_ns) - fixed latency.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockFit {
    pub device_ref_ns: u64,
    /// host - device at `device_ref_ns` on the envelope, ns (a GPS/PTP device: near 0 or -37 s).
    pub offset_ns: f64,
    /// Device clock rate error against the host: host runs (1 + skew) per device second.
    pub skew: f64,
    pub pairs: usize,
    /// Mean height of the pairs above the envelope: the typical latency beyond the minimum.
    pub mean_excess_latency_ns: f64,
}

impl ClockFit {
    pub fn skew_ppb(&self) -> f64 {
        self.skew * 1e9
    }
}

/// A PPS stamp (ns since the last pulse) made whole with the second that puts it nearest the host
/// time it was received at; right while the device and host agree to within half a second.
pub fn unwrap_pps(pps_ns: u64, host_ns: u64) -> u64 {
    let within = (pps_ns % NS_PER_S as u64) as i128;
    let seconds = ((host_ns as i128 - within) as f64 / NS_PER_S as f64).round() as i128;
    u64::try_from(seconds * NS_PER_S + within).unwrap_or(0)
}

/// One device's clock against the host clock.
#[derive(Clone, Debug)]
pub struct ClockModel {
    source: Clock,
    cfg: ClockModelConfig,
    /// (device ns, host ns), device ns unwrapped for PPS.
    pairs: VecDeque<(u64, u64)>,
    fit: Option<ClockFit>,
}

impl ClockModel {
    pub fn new(source: Clock, cfg: ClockModelConfig) -> Result<Self, TimeError> {
        if cfg.max_pairs < 2 || cfg.min_pairs_for_skew < 2 {
            return Err(TimeError::BadConfig("max_pairs and min_pairs_for_skew must be at least 2"));
        }
        Ok(Self { source, cfg, pairs: VecDeque::new(), fit: None })
    }

    pub fn source(&self) -> Clock {
        self.source
    }

    /// Adds one (device, host receive) pair.
    pub fn observe(&mut self, device: Stamp, host: Stamp) -> Result<(), TimeError> {
        if device.clock != self.source {
            return Err(TimeError::WrongClock { expected: self.source, got: device.clock });
        }
        if host.clock != Clock::Host {
            return Err(TimeError::NotHost(host.clock));
        }
        let device_ns = if self.source == Clock::Pps { unwrap_pps(device.ns, host.ns) } else { device.ns };
        self.pairs.push_back((device_ns, host.ns));
        while self.pairs.len() > self.cfg.max_pairs {
            self.pairs.pop_front();
        }
        let newest = self.pairs.iter().map(|p| p.0).max().unwrap_or(device_ns);
        while let Some(&(d, _)) = self.pairs.front() {
            if newest.saturating_sub(d) <= self.cfg.window_ns || self.pairs.len() <= 2 {
                break;
            }
            self.pairs.pop_front();
        }
        self.fit = None;
        Ok(())
    }

    /// The fit over the pairs in the window (computed on demand).
    pub fn fit(&mut self) -> Option<ClockFit> {
        if self.fit.is_none() {
            self.fit = envelope_fit(&self.pairs, self.cfg.min_pairs_for_skew);
        }
        self.fit
    }

    /// A device stamp on the host clock. PPS stamps take their second from the newest pair, so
    /// map them within half a second of it, or use [`ClockModel::to_host_near`].
    pub fn to_host(&mut self, device: Stamp) -> Result<Option<Stamp>, TimeError> {
        let hint = self.pairs.back().map(|p| p.1);
        self.to_host_near(device, hint)
    }

    /// As [`ClockModel::to_host`], with the host time the stamp arrived at (or any host time
    /// within half a second of it) to pick a PPS stamp's second; other clocks ignore it.
    pub fn to_host_near(&mut self, device: Stamp, host_hint_ns: Option<u64>) -> Result<Option<Stamp>, TimeError> {
        if device.clock != self.source {
            return Err(TimeError::WrongClock { expected: self.source, got: device.clock });
        }
        if self.source == Clock::Host {
            return Ok(Some(device));
        }
        let device_ns = match (self.source, host_hint_ns) {
            (Clock::Pps, Some(host)) => unwrap_pps(device.ns, host),
            (Clock::Pps, None) => return Ok(None),
            _ => device.ns,
        };
        let Some(fit) = self.fit() else { return Ok(None) };
        let dx = device_ns as i128 - fit.device_ref_ns as i128;
        let host = device_ns as i128 + (fit.offset_ns + fit.skew * dx as f64).round() as i128
            - self.cfg.fixed_latency_ns as i128;
        Ok(u64::try_from(host).ok().map(|ns| Stamp::new(ns, Clock::Host)))
    }
}

/// Lower convex hull of points sorted by x (Andrew's monotone chain, lower half).
fn lower_hull(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut hull: Vec<(f64, f64)> = Vec::new();
    for &p in points {
        while hull.len() >= 2 {
            let (a, b) = (hull[hull.len() - 2], hull[hull.len() - 1]);
            // Pop b while a -> b -> p turns clockwise or is straight (b is not below a-p).
            let cross = (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0);
            if cross <= 0.0 {
                hull.pop();
            } else {
                break;
            }
        }
        hull.push(p);
    }
    hull
}

fn envelope_fit(pairs: &VecDeque<(u64, u64)>, min_pairs_for_skew: usize) -> Option<ClockFit> {
    let &(x0, h0) = pairs.front()?;
    let y0 = h0 as i128 - x0 as i128;
    // Relative coordinates keep f64 exact: x in ns since the first pair, y in ns around y0.
    let mut pts: Vec<(f64, f64)> =
        pairs.iter().map(|&(d, h)| ((d as i128 - x0 as i128) as f64, ((h as i128 - d as i128) - y0) as f64)).collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let n = pts.len() as f64;
    let mean_x = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let (slope, intercept) = {
        let hull = lower_hull(&pts);
        let span = hull.windows(2).find(|w| w[0].0 <= mean_x && mean_x <= w[1].0 && w[1].0 > w[0].0);
        match span {
            Some(w) if pts.len() >= min_pairs_for_skew => {
                let slope = (w[1].1 - w[0].1) / (w[1].0 - w[0].0);
                (slope, w[0].1 - slope * w[0].0)
            }
            // Too few pairs or one device instant: offset only, at the lowest point.
            _ => (0.0, pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min)),
        }
    };
    let excess = pts.iter().map(|p| p.1 - (intercept + slope * p.0)).sum::<f64>() / n;
    Some(ClockFit {
        device_ref_ns: x0,
        offset_ns: y0 as f64 + intercept,
        skew: slope,
        pairs: pairs.len(),
        mean_excess_latency_ns: excess,
    })
}

/// One clock model per stream ("imu", "lidar", "wheels", ...), so every stream's stamps land on
/// the same host clock.
#[derive(Clone, Debug, Default)]
pub struct TimeAligner {
    models: HashMap<String, ClockModel>,
    cfg: ClockModelConfig,
}

impl TimeAligner {
    pub fn new(cfg: ClockModelConfig) -> Self {
        Self { models: HashMap::new(), cfg }
    }

    /// A (device, host receive) pair of `stream`; the stream's model is made on first use with
    /// the device stamp's clock.
    pub fn observe(&mut self, stream: &str, device: Stamp, host: Stamp) -> Result<(), TimeError> {
        if !self.models.contains_key(stream) {
            let model = ClockModel::new(device.clock, self.cfg.clone())?;
            self.models.insert(stream.to_string(), model);
        }
        match self.models.get_mut(stream) {
            Some(m) => m.observe(device, host),
            None => Ok(()),
        }
    }

    pub fn to_host(&mut self, stream: &str, device: Stamp) -> Result<Option<Stamp>, TimeError> {
        match self.models.get_mut(stream) {
            Some(m) => m.to_host(device),
            None => Ok(None),
        }
    }

    pub fn fit(&mut self, stream: &str) -> Option<ClockFit> {
        self.models.get_mut(stream).and_then(|m| m.fit())
    }
}

#[cfg(test)]
mod tests;
