#![no_main]
//! WitMotion: the stream decoder never panics on any bytes in any chunking and keeps its buffer
//! bounded; every byte is either in a good frame or counted as skipped; frames and config writes
//! that parse re-encode to the same bytes.
use libfuzzer_sys::fuzz_target;
use starc_imu::timing::{LatencyModel, Timestamper};
use starc_imu::witmotion::{ConfigDecoder, ConfigWrite, WitDecoder, WitFrame};
use starc_time::{Clock, Stamp};

fuzz_target!(|data: &[u8]| {
    let Some((&split, bytes)) = data.split_first() else { return };
    let mut d = WitDecoder::new(Timestamper::new(LatencyModel::new(115_200, 1_000_000)));
    let mut out = Vec::new();
    let step = usize::from(split % 32) + 1;
    for (i, chunk) in bytes.chunks(step).enumerate() {
        d.push(chunk, Stamp::new(i as u64 * 1_000, Clock::Host), &mut out);
        assert!(d.buffered() <= 1024);
    }
    let s = d.stats();
    assert_eq!(s.skipped_bytes + 11 * s.frames + d.buffered() as u64, bytes.len() as u64);
    assert_eq!(s.samples + s.incomplete, out.len() as u64);
    for e in &out {
        if let starc_imu::ImuEvent::Sample(sample) = e {
            assert!(sample.gyro_rad_s.iter().chain(sample.accel_m_s2.iter()).all(|v| v.is_finite()));
        }
    }
    if let Ok(f) = WitFrame::parse(bytes) {
        assert_eq!(&f.encode()[..], &bytes[..11]);
    }
    if let Ok(w) = ConfigWrite::parse(bytes) {
        assert_eq!(&w.encode()[..], &bytes[..5]);
    }
    let mut writes = Vec::new();
    let mut c = ConfigDecoder::new();
    c.push(bytes, &mut writes);
    assert!(writes.len() <= bytes.len() / 5);
});
