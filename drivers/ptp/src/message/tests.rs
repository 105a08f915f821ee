//! Datagrams captured from linuxptp 3.1.1 (ptp4l -S -4 -E) between two network namespaces.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;

fn hex(s: &str) -> Vec<u8> {
    (0..s.len()).step_by(2).map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap()).collect()
}

const PTP4L_SYNC: &str = "0002002c00000200000000000000000000000000fa566bfffe6084b60001000000fd00000000000000000000";
const PTP4L_FOLLOW_UP: &str =
    "0802002c00000000000000000000000000000000fa566bfffe6084b60001000002fd00006b01600026ba5b2e";
const PTP4L_DELAY_RESP: &str =
    "0902003600000000000000000000000000000000fa566bfffe6084b600010000030000006b0160010b62c9c4323bf1fffe073b200001";
const PTP4L_ANNOUNCE: &str = "0b02004000000000000000000000000000000000fa566bfffe6084b60001000005fe0000000000000000000000250080f8feffff80fa566bfffe6084b60000a0";
const PTP4L_DELAY_REQ: &str =
    "0102002c00000000000000000000000000000000323bf1fffe073b2000010000017f00000000000000000000";

fn master_port() -> PortIdentity {
    PortIdentity { clock: ClockIdentity([0xfa, 0x56, 0x6b, 0xff, 0xfe, 0x60, 0x84, 0xb6]), port: 1 }
}

#[test]
fn ptp4l_sync_is_two_step_with_zero_origin() {
    let m = Message::parse(&hex(PTP4L_SYNC)).unwrap();
    assert_eq!(m.header.message_type, MessageType::Sync);
    assert_eq!(m.header.version, PtpVersion::V2_0);
    assert!(m.header.flags.two_step());
    assert_eq!(m.header.source, master_port());
    assert_eq!(m.header.source.to_string(), "fa566b.fffe.6084b6-1");
    assert_eq!(m.header.control, 0);
    assert_eq!(m.header.log_interval, -3);
    assert_eq!(m.body, Body::Sync { origin: PtpTimestamp::default() });
}

#[test]
fn ptp4l_follow_up_carries_the_precise_origin() {
    let m = Message::parse(&hex(PTP4L_FOLLOW_UP)).unwrap();
    assert_eq!(m.header.message_type, MessageType::FollowUp);
    assert_eq!(m.header.sequence_id, 0);
    assert_eq!(m.header.control, 2);
    let Body::FollowUp { precise_origin } = m.body else { panic!("{m:?}") };
    assert_eq!(precise_origin.seconds, 0x6b01_6000);
    assert_eq!(precise_origin.nanos, 0x26ba_5b2e);
}

#[test]
fn ptp4l_delay_resp_names_the_requester() {
    let m = Message::parse(&hex(PTP4L_DELAY_RESP)).unwrap();
    let Body::DelayResp { receive, requesting } = m.body else { panic!("{m:?}") };
    assert_eq!(requesting.to_string(), "323bf1.fffe.073b20-1");
    assert_eq!(receive.seconds, 0x6b01_6001);
    assert_eq!(m.header.log_interval, 0);
}

#[test]
fn ptp4l_announce_fields() {
    let m = Message::parse(&hex(PTP4L_ANNOUNCE)).unwrap();
    let Body::Announce(a) = m.body else { panic!("{m:?}") };
    assert_eq!(a.current_utc_offset, 37);
    assert_eq!(a.gm_priority1, 128);
    assert_eq!(a.gm_quality.clock_class, 248);
    assert_eq!(a.gm_quality.clock_accuracy, 0xfe);
    assert_eq!(a.gm_quality.offset_scaled_log_variance, 0xffff);
    assert_eq!(a.gm_priority2, 128);
    assert_eq!(a.gm_identity, master_port().clock);
    assert_eq!(a.steps_removed, 0);
    assert_eq!(a.time_source, time_source::INTERNAL_OSCILLATOR);
    assert!(!m.header.flags.ptp_timescale(), "ptp4l on CLOCK_REALTIME announces ARB time");
}

#[test]
fn ptp4l_delay_req() {
    let m = Message::parse(&hex(PTP4L_DELAY_REQ)).unwrap();
    assert_eq!(m.header.message_type, MessageType::DelayReq);
    assert_eq!(m.header.log_interval, 0x7f);
    assert_eq!(m.header.control, 1);
}

#[test]
fn captured_messages_encode_to_the_same_bytes() {
    for h in [PTP4L_SYNC, PTP4L_FOLLOW_UP, PTP4L_DELAY_RESP, PTP4L_ANNOUNCE, PTP4L_DELAY_REQ] {
        let bytes = hex(h);
        let m = Message::parse(&bytes).unwrap();
        assert_eq!(m.encode().unwrap(), bytes, "{:?}", m.header.message_type);
    }
}

#[test]
fn version_0x12_is_accepted_others_refused() {
    let mut b = hex(PTP4L_SYNC);
    b[1] = 0x12;
    let m = Message::parse(&b).unwrap();
    assert_eq!(m.header.version, PtpVersion::V2_1);
    assert_eq!(m.encode().unwrap(), b);
    for v in [0x01, 0x03, 0x22, 0x00, 0xff] {
        b[1] = v;
        assert!(matches!(Message::parse(&b), Err(PtpError::UnsupportedVersion(x)) if x == v), "{v:#x}");
    }
}

#[test]
fn lengths_are_checked() {
    let b = hex(PTP4L_ANNOUNCE);
    for n in 0..b.len() {
        assert!(Message::parse(&b[..n]).is_err(), "{n} bytes parsed");
    }
    // messageLength shorter than an Announce body.
    let mut short = b.clone();
    short[3] = 44;
    assert!(matches!(Message::parse(&short), Err(PtpError::LengthTooSmall { need: 64, .. })));
    // messageLength past the datagram.
    let mut long = b.clone();
    long[3] = 100;
    assert!(matches!(Message::parse(&long), Err(PtpError::LengthExceedsDatagram { declared: 100, actual: 64 })));
}

#[test]
fn trailing_tlvs_and_padding_are_ignored() {
    let mut b = hex(PTP4L_FOLLOW_UP);
    let plain = Message::parse(&b).unwrap();
    // A 1588-2019 style suffix TLV inside messageLength, then UDP padding outside it.
    b.extend_from_slice(&[0x00, 0x03, 0x00, 0x02, 0xaa, 0xbb]);
    b[3] = (44 + 6) as u8;
    b.extend_from_slice(&[0u8; 8]);
    assert_eq!(Message::parse(&b).unwrap(), plain);
}

#[test]
fn other_types_parse_but_do_not_encode() {
    let mut b = hex(PTP4L_DELAY_REQ);
    b[0] = 0x02; // Pdelay_Req
    let m = Message::parse(&b).unwrap();
    assert_eq!(m.body, Body::Other);
    assert!(matches!(m.encode(), Err(PtpError::NotEncodable("Pdelay_Req"))));
    for reserved in [0x4u8, 0x5, 0x6, 0x7, 0xe, 0xf] {
        b[0] = reserved;
        assert!(matches!(Message::parse(&b), Err(PtpError::ReservedMessageType(r)) if r == reserved));
    }
}

#[test]
fn flags_and_correction_round_trip() {
    let mut h = Header::new(MessageType::Sync, 7, master_port(), 0xbeef);
    h.flags = Flags::default()
        .with(Flags::TWO_STEP, true)
        .with(Flags::PTP_TIMESCALE, true)
        .with(Flags::UTC_OFFSET_VALID, true);
    h.correction = Correction(-123_456_789);
    h.log_interval = -7;
    let m = Message { header: h, body: Body::Sync { origin: PtpTimestamp { seconds: 1 << 40, nanos: 5 } } };
    let bytes = m.encode().unwrap();
    assert_eq!(&bytes[6..8], &[0x02, 0x0c]);
    assert_eq!(Message::parse(&bytes).unwrap(), m);
}
