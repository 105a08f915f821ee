//! The sans-IO mock against the driver's own decoders: rates, commands, config writes, noise,
//! faults.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::imu::device::{DeviceConfig, ImuDevice};
use crate::imu::faults::ImuFaultConfig;
use crate::imu::sensor::SensorModel;
use crate::imu::source::{Motion, Still};
use starc_imu::mip::command::{MipReply, ReplyData, NACK_BAD_PARAMETER, NACK_UNKNOWN_COMMAND};
use starc_imu::mip::{FormatEntry, Function, MipCommand, PacketWriter};
use starc_imu::timing::{LatencyModel, Timestamper};
use starc_imu::witmotion::ConfigWrite;
use starc_imu::{GapDetector, ImuDecoder, ImuEvent, ImuSample, Protocol, STANDARD_GRAVITY_M_S2};
use starc_time::{Clock, Stamp};

struct Bench {
    device: ImuDevice<Still>,
    decoder: ImuDecoder,
    t_ns: u64,
    events: Vec<ImuEvent>,
}

impl Bench {
    fn new(config: DeviceConfig) -> Self {
        let z_up = config.protocol == Protocol::WitMotion;
        let decoder = ImuDecoder::new(config.protocol, Timestamper::new(LatencyModel::new(0, 0)));
        let mut device = ImuDevice::new(config, Still(Motion::still(z_up)));
        let mut decoder = decoder;
        // The sample at power-on (t = 0) is decoded but not part of any counted second.
        let mut out = Vec::new();
        device.poll(0, &mut out);
        decoder.push(&out, Stamp::new(0, Clock::Host), &mut Vec::new());
        Self { device, decoder, t_ns: 0, events: Vec::new() }
    }

    /// Runs the device for `seconds` in 1 ms steps, decoding everything it sends.
    fn run(&mut self, seconds: f64) {
        let end = self.t_ns + (seconds * 1e9) as u64;
        let mut out = Vec::new();
        while self.t_ns < end {
            self.t_ns += 1_000_000;
            self.device.poll(self.t_ns, &mut out);
            self.decoder.push(&out, Stamp::new(self.t_ns, Clock::Host), &mut self.events);
            out.clear();
        }
    }

    fn send(&mut self, bytes: &[u8]) {
        let mut out = Vec::new();
        self.device.receive(bytes, self.t_ns, &mut out);
        self.decoder.push(&out, Stamp::new(self.t_ns, Clock::Host), &mut self.events);
    }

    fn command(&mut self, c: &MipCommand) -> MipReply {
        self.events.clear();
        self.send(&c.to_bytes().unwrap());
        self.events
            .iter()
            .find_map(|e| match e {
                ImuEvent::MipReply(r) => Some(r.clone()),
                _ => None,
            })
            .unwrap_or_else(|| panic!("no reply to {c:?}"))
    }

    fn samples(&self) -> Vec<&ImuSample> {
        self.events
            .iter()
            .filter_map(|e| match e {
                ImuEvent::Sample(s) => Some(s),
                _ => None,
            })
            .collect()
    }

    /// Samples decoded in the next `seconds`.
    fn count(&mut self, seconds: f64) -> usize {
        self.events.clear();
        self.run(seconds);
        self.samples().len()
    }
}

#[test]
fn mip_streams_at_its_rate_and_answers_every_command() {
    let mut b = Bench::new(DeviceConfig::new(Protocol::Mip));
    assert_eq!(b.count(1.0), 100);
    assert!(b.command(&MipCommand::Ping).is_ack());
    assert!(b.command(&MipCommand::SetIdle).is_ack());
    assert_eq!(b.count(0.5), 0, "idle: no data");
    assert!(b.command(&MipCommand::Resume).is_ack());
    assert_eq!(b.count(0.5), 50);
    let base = b.command(&MipCommand::GetImuBaseRate);
    assert_eq!(base.data, Some(ReplyData::ImuBaseRate(1000)));
    // 500 Hz (decimation 2) of accel + gyro is 17 kB/s: more than 115200 baud carries.
    assert!(b.command(&MipCommand::UartBaudRate(Function::Apply(921_600))).is_ack());
    let entries =
        vec![FormatEntry { descriptor: 0x04, decimation: 2 }, FormatEntry { descriptor: 0x05, decimation: 2 }];
    assert!(b.command(&MipCommand::ImuMessageFormat(Function::Apply(entries.clone()))).is_ack());
    assert_eq!(b.count(1.0), 500);
    let read = b.command(&MipCommand::ImuMessageFormat(Function::Read));
    assert_eq!(read.data, Some(ReplyData::ImuMessageFormat(entries)));
    // Unknown fields and zero decimations are refused.
    let bad = vec![FormatEntry { descriptor: 0x99, decimation: 1 }];
    assert_eq!(b.command(&MipCommand::ImuMessageFormat(Function::Apply(bad))).code, NACK_BAD_PARAMETER);
    assert_eq!(b.device.baud(), 921_600);
    assert_eq!(b.command(&MipCommand::UartBaudRate(Function::Read)).data, Some(ReplyData::UartBaudRate(921_600)));
    assert_eq!(b.command(&MipCommand::UartBaudRate(Function::Apply(12_345))).code, NACK_BAD_PARAMETER);
    // A command the mock does not know (get device info, 0x01 0x03).
    let mut w = PacketWriter::new(0x01);
    w.field(0x03, &[]).unwrap();
    b.events.clear();
    b.send(&w.to_bytes());
    assert!(matches!(b.events.as_slice(), [ImuEvent::MipReply(r)] if r.code == NACK_UNKNOWN_COMMAND && r.command == 3));
    let s = b.device.stats();
    assert_eq!((s.acks, s.nacks, s.rate_changes, s.baud_changes), (8, 3, 1, 1));
}

#[test]
fn mip_output_is_paced_by_the_baud_rate() {
    // 1000 Hz of accel + gyro + GPS time is 48 bytes a sample: 48 kB/s, more than 9600 baud.
    let mut config = DeviceConfig::new(Protocol::Mip);
    config.rate_hz = 1000.0;
    config.baud = 9600;
    let mut b = Bench::new(config);
    let n = b.count(1.0);
    assert!((18..=22).contains(&n), "960 B/s carries 20 samples of 48 B: {n}");
    assert!(b.device.stats().overruns > 900);
    b.command(&MipCommand::UartBaudRate(Function::Apply(921_600)));
    b.run(0.2);
    assert_eq!(b.count(1.0), 1000);
}

#[test]
fn still_device_reads_gravity_bias_and_noise() {
    let mut config = DeviceConfig::new(Protocol::Mip);
    config.rate_hz = 1000.0;
    config.baud = 921_600;
    let sensor = SensorModel::default();
    config.sensor = sensor;
    let mut b = Bench::new(config);
    b.run(4.0);
    let s = b.samples();
    assert_eq!(s.len(), 4000);
    let n = s.len() as f64;
    for axis in 0..3 {
        let mean_g = s.iter().map(|x| x.gyro_rad_s[axis]).sum::<f64>() / n;
        let std_g = (s.iter().map(|x| (x.gyro_rad_s[axis] - mean_g).powi(2)).sum::<f64>() / n).sqrt();
        assert!((mean_g - sensor.gyro_bias_rad_s[axis]).abs() < 3.0 * sensor.gyro_noise_rad_s / n.sqrt() + 1e-6);
        assert!((std_g / sensor.gyro_noise_rad_s - 1.0).abs() < 0.05, "gyro std {std_g}");
        let truth = if axis == 2 { -STANDARD_GRAVITY_M_S2 } else { 0.0 };
        let mean_a = s.iter().map(|x| x.accel_m_s2[axis]).sum::<f64>() / n;
        assert!(
            (mean_a - truth - sensor.accel_bias_m_s2[axis]).abs() < 3.0 * sensor.accel_noise_m_s2 / n.sqrt() + 1e-5
        );
    }
}

#[test]
fn witmotion_honours_writes_only_when_unlocked() {
    let mut b = Bench::new(DeviceConfig::new(Protocol::WitMotion));
    b.run(0.1);
    assert_eq!(b.count(1.0), 100);
    // A rate write without the unlock is ignored, as on the device.
    b.send(&ConfigWrite::rate(50.0).unwrap().encode());
    assert_eq!(b.count(1.0), 100);
    for w in ConfigWrite::rate(50.0).unwrap().unlocked() {
        b.send(&w);
    }
    b.run(0.05);
    assert_eq!(b.count(1.0), 50);
    // Quaternions on: samples carry them.
    for w in ConfigWrite::output_content(&[0x51, 0x52, 0x53, 0x59]).unlocked() {
        b.send(&w);
    }
    b.run(0.1);
    b.events.clear();
    b.run(0.2);
    assert!(b.samples().iter().all(|s| s.orientation_wxyz.is_some() && s.euler_rad.is_some()));
    for w in ConfigWrite::baud(921_600).unwrap().unlocked() {
        b.send(&w);
    }
    b.send(&ConfigWrite::save().encode());
    let s = b.device.stats();
    assert_eq!(b.device.baud(), 921_600);
    assert_eq!((s.locked_writes, s.rate_changes, s.baud_changes, s.saves), (1, 1, 1, 1));
    let g = b.samples()[0].accel_m_s2[2];
    assert!((g - STANDARD_GRAVITY_M_S2).abs() < 0.1, "z up: {g}");
}

#[test]
fn faults_show_up_in_the_decoder_counts() {
    for protocol in [Protocol::Mip, Protocol::WitMotion] {
        let mut config = DeviceConfig::new(protocol);
        config.baud = 921_600;
        config.faults =
            ImuFaultConfig { garbage: 0.05, drop: 0.03, corrupt: 0.02, silence_after_s: Some(20.0), seed: None };
        config.seed = 5;
        let mut b = Bench::new(config);
        b.run(22.0);
        let (dev, dec) = (b.device.stats(), b.decoder.stats());
        let f = dev.faults;
        assert_eq!(dev.samples, 2000, "{protocol}: silent after 20 s");
        assert_eq!(dev.sent + f.dropped, dev.samples);
        assert!(f.garbage_bursts > 50 && f.dropped > 30 && f.corrupted > 20, "{f:?}");
        // Each corrupted sample costs one checksum (and, for MIP, the sample).
        assert!(dec.bad_checksums >= f.corrupted, "{protocol}: {dec:?} {f:?}");
        let lost = dev.sent - dec.samples;
        match protocol {
            Protocol::Mip => assert_eq!(lost, f.corrupted, "{protocol}: {dec:?} {f:?}"),
            // A corrupted angle frame leaves the sample whole; garbage next to a corruption
            // may cost a neighbouring frame.
            Protocol::WitMotion => assert!(lost <= f.corrupted + f.garbage_bursts / 10, "{protocol}: {dec:?} {f:?}"),
        }
        // Gaps in the device's GPS time (MIP) or host time (WitMotion) find the lost samples.
        let mut gaps = GapDetector::new(Some(100.0));
        for s in b.samples() {
            gaps.observe(s.device_ns.unwrap_or(s.stamp.ns));
        }
        let lost_total = f.dropped + lost;
        assert!(gaps.dropped().abs_diff(lost_total) <= 2, "{protocol}: gaps {} lost {lost_total}", gaps.dropped());
    }
}
