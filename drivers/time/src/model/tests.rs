//! Synthetic devices with known offset, skew and latency: the model must recover the mapping
//! to within a few microseconds where a least-squares fit through the same pairs is off by the
//! mean latency and bent by its spikes.

use super::*;

struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    /// Transport latency: a 150 us floor, exponential jitter (mean 400 us), 2 % spikes of 5-20 ms.
    fn latency_ns(&mut self) -> f64 {
        let mut l = 150_000.0 - 400_000.0 * self.unit().ln();
        if self.unit() < 0.02 {
            l += 5e6 + 15e6 * self.unit();
        }
        l
    }
}

const HOST0: u64 = 1_780_000_000_000_000_000;
const FLOOR_NS: f64 = 150_000.0;

/// A device whose clock reads `device(t) = dev0 + (t - HOST0) * (1 + skew)` at host time t.
struct Device {
    clock: Clock,
    dev0: u64,
    skew: f64,
}

impl Device {
    /// Integer arithmetic around dev0: an f64 near 1.8e18 ns would round to 256 ns.
    fn at(&self, t: u64) -> u64 {
        self.dev0 + ((t - HOST0) as f64 * (1.0 + self.skew)).round() as u64
    }
}

/// Feeds `seconds` of pairs at `rate_hz`; returns the worst mapping error (ns) over the last
/// second of samples and the least-squares fit's, both against the floor-latency truth.
fn run(model: &mut ClockModel, dev: &Device, seconds: f64, rate_hz: f64, rng: &mut Rng, start_s: f64) -> (f64, f64) {
    let n = (seconds * rate_hz) as u64;
    let mut pairs = Vec::new();
    for k in 0..n {
        let t = HOST0 + ((start_s + k as f64 / rate_hz) * 1e9) as u64;
        let device_ns = dev.at(t);
        let device_stamp = if dev.clock == Clock::Pps { device_ns % 1_000_000_000 } else { device_ns };
        let host = t + rng.latency_ns() as u64;
        model
            .observe(Stamp::new(device_stamp, dev.clock), Stamp::new(host, Clock::Host))
            .unwrap_or_else(|e| panic!("{e}"));
        pairs.push((t, device_ns, device_stamp, host));
    }
    // Least squares of host on device, for comparison.
    let (x0, y0) = (pairs[0].1 as f64, pairs[0].3 as f64);
    let m = pairs.len() as f64;
    let (sx, sy) = pairs.iter().fold((0.0, 0.0), |(a, b), p| (a + (p.1 as f64 - x0), b + (p.3 as f64 - y0)));
    let (mx, my) = (sx / m, sy / m);
    let (sxx, sxy) = pairs.iter().fold((0.0, 0.0), |(a, b), p| {
        let (x, y) = (p.1 as f64 - x0 - mx, p.3 as f64 - y0 - my);
        (a + x * x, b + x * y)
    });
    let ls_slope = sxy / sxx;
    let mut worst = 0.0f64;
    let mut worst_ls = 0.0f64;
    for &(t, device_ns, device_stamp, host) in pairs.iter().rev().take(rate_hz as usize) {
        let truth = t as i128 + FLOOR_NS as i128;
        let mapped = model
            .to_host_near(Stamp::new(device_stamp, dev.clock), Some(host))
            .ok()
            .flatten()
            .map(|s| s.ns as i128)
            .unwrap_or(i128::MAX / 2);
        worst = worst.max((mapped - truth).abs() as f64);
        let ls = y0 + my + ls_slope * (device_ns as f64 - x0 - mx);
        worst_ls = worst_ls.max((ls - truth as f64).abs());
    }
    (worst, worst_ls)
}

#[test]
fn free_running_device_with_80_ppm_skew() {
    let mut rng = Rng(1);
    let mut model = ClockModel::new(Clock::Device, ClockModelConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    // An IMU counting from power-up, 80 ppm fast, sampled at 200 Hz for 20 s.
    let dev = Device { clock: Clock::Device, dev0: 12_345_678_901, skew: 80e-6 };
    let (worst, worst_ls) = run(&mut model, &dev, 20.0, 200.0, &mut rng, 0.0);
    let fit = model.fit().unwrap_or_else(|| panic!("no fit"));
    // host runs 1/(1+skew) per device second: skew_host_per_device = -80 ppm (to first order).
    let true_skew_ppb = (1.0 / (1.0 + 80e-6) - 1.0) * 1e9;
    let skew_err = fit.skew_ppb() - true_skew_ppb;
    println!(
        "free-running, 80 ppm, 4000 pairs: skew error {skew_err:+.1} ppb, worst mapping error {worst:.0} ns \
         (least squares {worst_ls:.0} ns), mean excess latency {:.0} ns",
        fit.mean_excess_latency_ns
    );
    assert!(skew_err.abs() < 200.0, "skew error {skew_err} ppb");
    assert!(worst < 5_000.0, "mapping error {worst} ns");
    assert!(worst_ls > 10.0 * worst, "least squares should be far worse: {worst_ls}");
}

#[test]
fn ptp_device_lands_37_s_back_on_utc() {
    let mut rng = Rng(2);
    let mut model = ClockModel::new(Clock::Ptp, ClockModelConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    // A LiDAR synced to our grandmaster: TAI = UTC + 37 s, 300 ns residual, 0.05 ppm wander.
    let dev = Device { clock: Clock::Ptp, dev0: HOST0 + 37_000_000_000 + 300, skew: 5e-8 };
    let (worst, _) = run(&mut model, &dev, 10.0, 100.0, &mut rng, 0.0);
    let fit = model.fit().unwrap_or_else(|| panic!("no fit"));
    println!("PTP, 1000 pairs: offset {:.0} ns, worst mapping error {worst:.0} ns", fit.offset_ns);
    assert!((fit.offset_ns + 37e9 - 300.0 - FLOOR_NS).abs() < 5_000.0, "{fit:?}");
    assert!(worst < 5_000.0, "{worst}");
}

#[test]
fn pps_stamps_are_made_whole() {
    assert_eq!(unwrap_pps(250_000_000, 1_000_000_000_300_000_000), 1_000_000_000_250_000_000);
    assert_eq!(unwrap_pps(990_000_000, 1_000_000_001_010_000_000), 1_000_000_000_990_000_000);
    let mut rng = Rng(3);
    let mut model = ClockModel::new(Clock::Pps, ClockModelConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    // ns since the last pulse of a GPS-disciplined device, 2 ms behind the host's UTC.
    let dev = Device { clock: Clock::Pps, dev0: HOST0 - 2_000_000, skew: 0.0 };
    let (worst, _) = run(&mut model, &dev, 5.0, 50.0, &mut rng, 0.0);
    println!("PPS, 250 pairs: worst mapping error {worst:.0} ns");
    assert!(worst < 5_000.0, "{worst}");
}

#[test]
fn the_window_follows_a_changing_skew() {
    let mut rng = Rng(4);
    let cfg = ClockModelConfig { window_ns: 10_000_000_000, ..ClockModelConfig::default() };
    let mut model = ClockModel::new(Clock::Device, cfg).unwrap_or_else(|e| panic!("{e}"));
    let warm = Device { clock: Clock::Device, dev0: 1_000_000_000_000, skew: 20e-6 };
    run(&mut model, &warm, 15.0, 100.0, &mut rng, 0.0);
    // The crystal warms up: 35 ppm from t = 15 s, continuous in time.
    let dev0 = warm.at(HOST0 + 15_000_000_000) - (15e9f64 * (1.0 + 35e-6)).round() as u64;
    let hot = Device { clock: Clock::Device, dev0, skew: 35e-6 };
    let (worst, _) = run(&mut model, &hot, 15.0, 100.0, &mut rng, 15.0);
    let fit = model.fit().unwrap_or_else(|| panic!("no fit"));
    println!("skew step 20 -> 35 ppm, 10 s window: skew now {:.0} ppb, worst error {worst:.0} ns", fit.skew_ppb());
    assert!((fit.skew_ppb() + 35_000.0).abs() < 300.0, "{fit:?}");
    assert!(worst < 5_000.0, "{worst}");
}

#[test]
fn imu_lidar_and_wheels_line_up() {
    let mut rng = Rng(5);
    let mut aligner = TimeAligner::new(ClockModelConfig::default());
    let streams = [
        ("imu", Device { clock: Clock::Device, dev0: 5_000_000_000, skew: 80e-6 }, 200.0),
        ("lidar", Device { clock: Clock::Ptp, dev0: HOST0 + 37_000_000_000, skew: 0.0 }, 100.0),
        ("wheels", Device { clock: Clock::Device, dev0: 77_000_000_000, skew: -30e-6 }, 50.0),
    ];
    for (name, dev, rate) in &streams {
        for k in 0..(10.0 * rate) as u64 {
            let t = HOST0 + (k as f64 / rate * 1e9) as u64;
            let host = t + rng.latency_ns() as u64;
            aligner
                .observe(name, Stamp::new(dev.at(t), dev.clock), Stamp::new(host, Clock::Host))
                .unwrap_or_else(|e| panic!("{e}"));
        }
    }
    // One instant, seen by all three: their mapped host times must agree.
    let t = HOST0 + 9_500_000_000;
    let mapped: Vec<i128> = streams
        .iter()
        .map(|(name, dev, _)| {
            aligner.to_host(name, Stamp::new(dev.at(t), dev.clock)).ok().flatten().map(|s| s.ns as i128).unwrap_or(0)
        })
        .collect();
    let spread = mapped.iter().max().unwrap_or(&0) - mapped.iter().min().unwrap_or(&0);
    println!("imu/lidar/wheels: one instant maps within {spread} ns across streams");
    assert!(spread < 5_000, "{mapped:?}");
    assert!(matches!(
        aligner.observe("imu", Stamp::new(1, Clock::Ptp), Stamp::new(2, Clock::Host)),
        Err(TimeError::WrongClock { expected: Clock::Device, got: Clock::Ptp })
    ));
}

#[test]
fn few_pairs_give_an_offset_and_bad_input_an_error() {
    let mut model = ClockModel::new(Clock::Gps, ClockModelConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(model.to_host(Stamp::new(5, Clock::Gps)), Ok(None));
    assert_eq!(
        model.observe(Stamp::new(1, Clock::Gps), Stamp::new(2, Clock::Ptp)),
        Err(TimeError::NotHost(Clock::Ptp))
    );
    model.observe(Stamp::new(1_000, Clock::Gps), Stamp::new(1_500, Clock::Host)).unwrap_or_else(|e| panic!("{e}"));
    model.observe(Stamp::new(2_000, Clock::Gps), Stamp::new(2_400, Clock::Host)).unwrap_or_else(|e| panic!("{e}"));
    // Offset only (lowest host - device = 400), slope untrusted with two pairs.
    assert_eq!(model.to_host(Stamp::new(3_000, Clock::Gps)), Ok(Some(Stamp::new(3_400, Clock::Host))));
    assert!(ClockModel::new(Clock::Gps, ClockModelConfig { max_pairs: 1, ..ClockModelConfig::default() }).is_err());
}
