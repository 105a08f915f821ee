//! What the device sees: the [`PointSource`] trait behind every scene.
//!
//! The streamer owns the device's firing clock and packetizing (data type, firings per packet,
//! time stamps); a source only says what each firing returns and what the IMU measures. Sources
//! with their own timing (replays) may move the next packet or IMU sample later than the nominal
//! time, which keeps gaps of a recording.

use starc_livox::data::{ImuSample, Return};

/// One point packet's worth of firings, asked of a source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FiringRequest {
    /// Index of the first firing since streaming started (line of firing k is k % 6).
    pub first_index: u64,
    /// Device time (ns, free-running clock) of the first firing.
    pub first_ns: u64,
    /// Spacing of firings (4167 ns on the Avia).
    pub interval_ns: u32,
    /// Firings in the packet (96 single, 48 dual, 30 triple).
    pub firings: usize,
    /// Returns per firing (1, 2 or 3).
    pub echoes: usize,
}

impl FiringRequest {
    /// Device time of firing `k` of this request.
    pub fn firing_ns(&self, k: usize) -> u64 {
        self.first_ns + k as u64 * u64::from(self.interval_ns)
    }
}

/// A scene seen by the mock LiDAR. Coordinates are metres in the sensor frame (x forward, y left,
/// z up); an empty return is [`Return::EMPTY`].
pub trait PointSource: Send {
    /// Called when streaming (re)starts at device time `t_ns`.
    fn start(&mut self, t_ns: u64) {
        let _ = t_ns;
    }

    /// Device time of the next point packet's first firing. `nominal_ns` is where the device's
    /// firing clock puts it; returning a later time leaves a gap (the result is clamped to at
    /// least `nominal_ns`).
    fn next_firing_ns(&mut self, nominal_ns: u64) -> u64 {
        nominal_ns
    }

    /// Appends `req.firings * req.echoes` returns, firing-major, to `out` (the streamer pads or
    /// truncates to that count).
    fn fill(&mut self, req: &FiringRequest, out: &mut Vec<Return>);

    /// Device time of the next IMU sample; `nominal_ns` is 5 ms after the previous one.
    fn next_imu_ns(&mut self, nominal_ns: u64) -> u64 {
        nominal_ns
    }

    /// The IMU sample at device time `t_ns` (acceleration in g, rates in rad/s).
    fn imu(&mut self, t_ns: u64) -> ImuSample;
}

impl<S: PointSource + ?Sized> PointSource for Box<S> {
    fn start(&mut self, t_ns: u64) {
        (**self).start(t_ns);
    }
    fn next_firing_ns(&mut self, nominal_ns: u64) -> u64 {
        (**self).next_firing_ns(nominal_ns)
    }
    fn fill(&mut self, req: &FiringRequest, out: &mut Vec<Return>) {
        (**self).fill(req, out);
    }
    fn next_imu_ns(&mut self, nominal_ns: u64) -> u64 {
        (**self).next_imu_ns(nominal_ns)
    }
    fn imu(&mut self, t_ns: u64) -> ImuSample {
        (**self).imu(t_ns)
    }
}
