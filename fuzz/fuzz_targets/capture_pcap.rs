#![no_main]
//! Classic pcap: reading never panics; whatever is read is summarized, and what the pcap writer
//! accepts reads back unchanged.
use libfuzzer_sys::fuzz_target;
use starc_livox::capture::summary::Summarizer;
use starc_livox::capture::{self, Capture, CaptureFormat, Datagram, PcapWriter, TsPrecision};

fuzz_target!(|data: &[u8]| {
    let Ok(cap) = Capture::from_bytes_as(data.to_vec(), CaptureFormat::Pcap) else { return };
    check(cap);
});

fn check(cap: Capture) {
    let got: Vec<Datagram> = cap.map_while(Result::ok).collect();
    let mut summary = Summarizer::new();
    got.iter().for_each(|d| summary.observe(d));
    let _ = summary.finish(CaptureFormat::Pcap, Default::default(), None, None);
    let Ok(mut writer) = PcapWriter::new(Vec::new(), TsPrecision::Nano) else { return };
    let written: Vec<&Datagram> = got.iter().filter(|d| writer.write_datagram(d).is_ok()).collect();
    let Ok(bytes) = writer.finish() else { return };
    let back: Vec<Datagram> = capture::from_bytes(bytes).map(|c| c.map_while(Result::ok).collect()).unwrap_or_default();
    assert_eq!(back.len(), written.len());
    for (b, w) in back.iter().zip(written) {
        assert_eq!(b, w);
    }
}
