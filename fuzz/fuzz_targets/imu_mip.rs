#![no_main]
//! MIP: the stream decoder never panics on any bytes in any chunking, never holds more than the
//! protocol allows, every sample it emits has finite rates, accelerations and orientation and
//! re-encodes to a packet that decodes to the same raw values; packets and commands that parse
//! re-encode to themselves.
use libfuzzer_sys::fuzz_target;
use starc_imu::mip::packet::MAX_PACKET_LEN;
use starc_imu::mip::{MipCommand, MipData, MipDecoder, MipReply, Packet};
use starc_imu::timing::{LatencyModel, Timestamper};
use starc_imu::{ImuEvent, RawSample};
use starc_time::{Clock, Stamp};

fuzz_target!(|data: &[u8]| {
    let Some((&split, bytes)) = data.split_first() else { return };
    let mut d = MipDecoder::new(Timestamper::new(LatencyModel::new(115_200, 1_000_000)));
    let mut out = Vec::new();
    let step = usize::from(split % 64) + 1;
    for (i, chunk) in bytes.chunks(step).enumerate() {
        d.push(chunk, Stamp::new(i as u64 * 1_000, Clock::Host), &mut out);
        assert!(d.buffered() <= 4 * MAX_PACKET_LEN);
    }
    let s = d.stats();
    assert_eq!(s.bytes, bytes.len() as u64);
    assert!(s.skipped_bytes <= s.bytes);
    for e in &out {
        match e {
            ImuEvent::Sample(sample) => {
                assert!(sample.gyro_rad_s.iter().chain(sample.accel_m_s2.iter()).all(|v| v.is_finite()));
                assert!(sample.orientation_wxyz.is_none_or(|q| q.iter().all(|v| v.is_finite())));
                assert!(sample.euler_rad.is_none_or(|e| e.iter().all(|v| v.is_finite())));
                let RawSample::Mip(raw) = &sample.raw else { panic!("not MIP") };
                let mut b = Vec::new();
                raw.encode(&mut b).expect("a decoded sample re-encodes");
                let (p, _) = Packet::parse(&b).expect("re-encoded packet parses");
                let mut again = MipData::decode(&p).expect("re-encoded data decodes");
                again.unknown_fields = raw.unknown_fields;
                // NaN payloads compare unequal: compare the bytes instead.
                let mut b2 = Vec::new();
                again.encode(&mut b2).expect("encodes");
                assert_eq!(b, b2);
            }
            ImuEvent::MipReply(r) => {
                let mut b = Vec::new();
                if r.encode(&mut b).is_ok() {
                    let (p, _) = Packet::parse(&b).expect("re-encoded reply parses");
                    let mut replies = Vec::new();
                    MipReply::decode_all(&p, &mut replies).expect("re-encoded reply decodes");
                    assert_eq!(replies.first(), Some(r));
                }
            }
            ImuEvent::Incomplete(_) => {}
        }
    }
    // A command found at the start re-encodes to itself (the mock parses these).
    if let Ok((p, _)) = Packet::parse(bytes) {
        if let Ok(c) = MipCommand::decode(&p) {
            let b = c.to_bytes().expect("a decoded command re-encodes");
            let (p2, _) = Packet::parse(&b).expect("parses");
            assert_eq!(MipCommand::decode(&p2).ok(), Some(c));
        }
    }
});
