#![no_main]
//! .lvx: reading never panics; whatever is read is summarized, and the packages the writer accepts
//! read back in order with their device index and bytes.
use libfuzzer_sys::fuzz_target;
use starc_livox::capture::summary::Summarizer;
use starc_livox::capture::{self, Capture, CaptureFormat, Datagram, LvxWriter};

fuzz_target!(|data: &[u8]| {
    let Ok(mut cap) = Capture::from_bytes_as(data.to_vec(), CaptureFormat::Lvx) else { return };
    let header = cap.lvx_header().cloned();
    let got: Vec<Datagram> = (&mut cap).map_while(Result::ok).collect();
    let mut summary = Summarizer::new();
    got.iter().for_each(|d| summary.observe(d));
    let _ = summary.finish(CaptureFormat::Lvx, *cap.stats(), header.clone(), None);
    let Some(header) = header else { return };
    let duration = header.frame_duration_ms.unwrap_or(50).max(1);
    let Ok(mut writer) = LvxWriter::new(Vec::new(), duration, &header.devices) else { return };
    let written: Vec<&Datagram> =
        got.iter().filter(|d| d.device_index.is_some_and(|i| writer.write_packet(i, &d.payload).is_ok())).collect();
    let Ok(bytes) = writer.finish() else { return };
    let back: Vec<Datagram> = match capture::from_bytes(bytes) {
        Ok(c) => c.map(|d| d.ok()).collect::<Option<Vec<_>>>().unwrap_or_default(),
        Err(e) => panic!("our own .lvx does not open: {e}"),
    };
    assert_eq!(back.len(), written.len());
    for (b, w) in back.iter().zip(written) {
        assert_eq!((b.device_index, &b.payload, b.time), (w.device_index, &w.payload, w.time));
    }
});
