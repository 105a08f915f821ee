#![no_main]
//! Link message parser: never panics on any bytes; what it accepts encodes again, and that
//! encoding decodes to the same message (byte for byte, poses up to quaternion renormalisation).
//! Random bytes almost never carry a right CRC, so each input is also tried as kind + payload
//! inside a well-formed frame, which sends the fuzzer into the per-kind parsers.
use libfuzzer_sys::fuzz_target;
use starc_pipeline::link::{decode, encode, LinkMessage};

fn crc32(bytes: &[u8]) -> u32 {
    // CRC-32/ISO-HDLC (zlib), bitwise: small and independent of the code under test.
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

fn check(data: &[u8]) {
    if let Ok(m) = decode(data) {
        let again = encode(&m).expect("a decoded message encodes");
        let back = decode(&again).expect("its encoding decodes");
        match (&m, &back) {
            (
                LinkMessage::RobotPose { stamp: a, world_t_lidar: p },
                LinkMessage::RobotPose { stamp: b, world_t_lidar: q },
            ) => {
                assert_eq!(a, b);
                assert_eq!(p.translation, q.translation);
                assert!(p.rotation.angle_to(&q.rotation) < 1e-9);
            }
            _ => {
                assert_eq!(m, back);
                assert_eq!(again, data, "a decoded frame re-encodes byte for byte");
            }
        }
    }
}

fuzz_target!(|data: &[u8]| {
    check(data);
    if let Some((&kind, payload)) = data.split_first() {
        let mut b = b"STLK".to_vec();
        b.push(1);
        b.push(kind % 8);
        b.extend_from_slice(&[0, 0]);
        b.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        b.extend_from_slice(payload);
        let crc = crc32(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        check(&b);
    }
});
