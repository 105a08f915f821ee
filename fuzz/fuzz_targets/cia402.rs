#![no_main]
//! CANopen / CiA 402 frames: NMT, heartbeat, SDO both ways, EMCY, PDOs and the host-side node
//! state machine never panic on any frame; SDO messages that parse re-encode to the same value.
use libfuzzer_sys::fuzz_target;
use starc_base::cia402::nmt::{parse_heartbeat, NmtCommand};
use starc_base::cia402::{
    Cia402Config, Cia402Node, Emergency, SdoRequest, SdoResponse, VelocityCommand, VelocityStatus,
};
use starc_base::DriveMode;
use starc_can::{CanFrame, CanId};
use starc_time::{Clock, Stamp};

fuzz_target!(|data: &[u8]| {
    let mut node = Cia402Node::new(0, 5, false, Cia402Config::default(), 100);
    node.start(Stamp::new(0, Clock::Host));
    let mut faults = Vec::new();
    let mut out = Vec::new();
    for (k, chunk) in data.chunks(11).enumerate() {
        let Some((head, rest)) = chunk.split_first_chunk::<2>() else { break };
        let Ok(id) = CanId::standard(u16::from_le_bytes(*head) & 0x7FF) else { continue };
        let payload = rest.get(..rest.len().min(8)).unwrap_or(&[]);
        let Ok(frame) = CanFrame::new(id, payload) else { continue };
        let _ = NmtCommand::parse(&frame);
        let _ = parse_heartbeat(&frame);
        let _ = Emergency::parse(&frame);
        let _ = VelocityCommand::parse(&frame);
        let _ = VelocityStatus::parse(&frame);
        if let Ok((n, req)) = SdoRequest::parse(&frame) {
            assert_eq!(req.to_frame(n).ok().and_then(|f| SdoRequest::parse(&f).ok()), Some((n, req)));
        }
        if let Ok((n, resp)) = SdoResponse::parse(&frame) {
            assert_eq!(resp.to_frame(n).ok().and_then(|f| SdoResponse::parse(&f).ok()), Some((n, resp)));
        }
        let now = Stamp::new(k as u64 * 3_000_000, Clock::Host);
        node.handle_frame(&frame, now, &mut faults);
        node.tick(now, DriveMode::Run, 1.0, &mut out, &mut faults);
    }
});
