#![no_main]
//! C620 frames: parsing never panics; what parses re-encodes to a frame that parses the same.
use libfuzzer_sys::fuzz_target;
use starc_base::c620::{CurrentCommand, Feedback};
use starc_can::{CanFrame, CanId};

fuzz_target!(|data: &[u8]| {
    let Some((&lo, rest)) = data.split_first() else { return };
    let id = 0x1F8 + u16::from(lo & 0x0F);
    let Ok(id) = CanId::standard(id) else { return };
    let payload = rest.get(..rest.len().min(8)).unwrap_or(&[]);
    let Ok(frame) = CanFrame::new(id, payload) else { return };
    if let Ok(fb) = Feedback::parse(&frame) {
        assert!(fb.angle_raw < 8192 && (1..=8).contains(&fb.esc));
        assert_eq!(fb.to_frame().ok().and_then(|f| Feedback::parse(&f).ok()), Some(fb));
        assert!(fb.output_rad_s(3591.0 / 187.0).is_finite());
    }
    if let Ok(cmd) = CurrentCommand::parse(&frame) {
        assert_eq!(cmd.to_frame().ok().and_then(|f| CurrentCommand::parse(&f).ok()), Some(cmd));
    }
});
