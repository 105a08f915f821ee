//! Captures: pcap, pcapng and .lvx, read as a stream of UDP datagrams (or .lvx packages).
//!
//! Each format has a sans-IO decoder ([`pcap::PcapDecoder`], [`pcapng::PcapngDecoder`],
//! [`lvx::LvxDecoder`]) that looks at the bytes it is given and answers with a [`Step`]: how many
//! bytes it needs, how many to drop, or where a record lies. [`Capture`] is the thin wrapper that
//! feeds them from a file (streamed in 256 KiB reads, never the whole file) or from memory, and
//! turns link-layer frames into [`Datagram`]s through [`net`].
//!
//! Lengths read from files are checked before use and never size an allocation beyond
//! [`MAX_RECORD_LEN`] (one packet) or [`MAX_BLOCK_LEN`] (one pcapng block).
//!
//! Writers: [`pcap::PcapWriter`] (Ethernet/IPv4/UDP frames) and [`lvx::LvxWriter`] (.lvx v1.1).

pub mod lvx;
pub mod net;
pub mod pcap;
pub mod pcapng;
pub mod summary;

use crate::error::{LivoxError, Result};
use serde::Serialize;
use starc_time::{Clock, Stamp};
use std::fs::File;
use std::io::Read;
use std::net::SocketAddrV4;
use std::ops::Range;
use std::path::Path;

pub use lvx::{LvxDevice, LvxHeader, LvxVersion, LvxWriter};
pub use pcap::{PcapHeader, PcapWriter, TsPrecision};
pub use pcapng::Interface;
pub use summary::{summarize, CaptureSummary};

/// Largest packet (captured bytes of one record) accepted from a file: libpcap's own limit.
pub const MAX_RECORD_LEN: usize = 256 * 1024;
/// Largest pcapng block accepted: a largest packet plus room for its header and options.
pub const MAX_BLOCK_LEN: usize = MAX_RECORD_LEN + 64 * 1024;
/// Bytes asked of the file per read.
const READ_CHUNK: usize = 256 * 1024;

/// One UDP datagram (pcap, pcapng) or one .lvx package.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Datagram {
    /// pcap/pcapng: capture time on [`Clock::Host`]. lvx: the data packet's own header stamp.
    pub time: Stamp,
    pub src: Option<SocketAddrV4>,
    pub dst: Option<SocketAddrV4>,
    /// lvx only: the package's device index.
    pub device_index: Option<u8>,
    /// The UDP payload (for lvx: the 18-byte data header and the points, as sent on the wire).
    pub payload: Vec<u8>,
}

impl Default for Datagram {
    fn default() -> Self {
        Self { time: Stamp::new(0, Clock::Host), src: None, dst: None, device_index: None, payload: Vec::new() }
    }
}

/// The container format of a capture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CaptureFormat {
    Pcap,
    Pcapng,
    Lvx,
}

impl CaptureFormat {
    pub fn name(self) -> &'static str {
        match self {
            Self::Pcap => "pcap",
            Self::Pcapng => "pcapng",
            Self::Lvx => "lvx",
        }
    }

    /// Recognises a capture from its first bytes (at least 4; .lvx needs 10).
    pub fn detect(head: &[u8]) -> Option<Self> {
        let magic = head.get(..4)?;
        if pcap::is_magic(magic) {
            Some(Self::Pcap)
        } else if magic == pcapng::SHB_TYPE.to_le_bytes() {
            Some(Self::Pcapng)
        } else if head.starts_with(lvx::SIGNATURE) {
            Some(Self::Lvx)
        } else {
            None
        }
    }
}

/// What the reader saw and skipped so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ReadStats {
    /// Packet records (pcap records, pcapng EPB/SPB/OPB) or .lvx packages read.
    pub records: u64,
    /// Datagrams handed out.
    pub datagrams: u64,
    /// Records that are not UDP over IPv4 (ARP, IPv6, TCP, ICMP ...), skipped.
    pub non_udp: u64,
    /// IPv4 fragments, skipped (Livox datagrams are never fragmented).
    pub fragments: u64,
    /// Records captured shorter than they were on the wire (incl_len < orig_len).
    pub truncated: u64,
    /// Records whose IPv4 or UDP header is inconsistent, skipped.
    pub malformed: u64,
    /// pcapng packets on an interface whose link type this reader does not decode, skipped.
    pub unsupported_link: u64,
    /// pcapng blocks without packets (statistics, name resolution, unknown types), skipped.
    pub skipped_blocks: u64,
    /// .lvx frames read.
    pub lvx_frames: u64,
}

/// What a sans-IO decoder asks of its caller, given the bytes at the front of its input.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Step {
    /// Give me at least this many bytes (always more than I was given).
    Need(usize),
    /// Drop this many bytes and call again (a header or a block without a packet).
    Skip(usize),
    /// A link-layer frame lies at `data` in the input; drop `consumed` bytes after using it.
    Frame(FrameRef),
    /// An .lvx package (data header and points) lies at `data`; drop `consumed` bytes afterwards.
    Package { consumed: usize, device_index: u8, data: Range<usize> },
}

/// Where a captured frame lies and what its record said about it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameRef {
    pub consumed: usize,
    /// Capture time, nanoseconds since the Unix epoch.
    pub time_ns: u64,
    pub link_type: u16,
    pub data: Range<usize>,
    /// Length on the wire (more than `data.len()` when the record was truncated).
    pub original_len: u64,
}

enum Decoder {
    Pcap(pcap::PcapDecoder),
    Pcapng(pcapng::PcapngDecoder),
    Lvx(lvx::LvxDecoder),
}

impl Decoder {
    fn new(format: CaptureFormat) -> Self {
        match format {
            CaptureFormat::Pcap => Self::Pcap(pcap::PcapDecoder::new()),
            CaptureFormat::Pcapng => Self::Pcapng(pcapng::PcapngDecoder::new()),
            CaptureFormat::Lvx => Self::Lvx(lvx::LvxDecoder::new()),
        }
    }

    fn step(&mut self, input: &[u8], stats: &mut ReadStats) -> Result<Step> {
        match self {
            Self::Pcap(d) => d.step(input),
            Self::Pcapng(d) => d.step(input, stats),
            Self::Lvx(d) => d.step(input, stats),
        }
    }

    fn header_done(&self) -> bool {
        match self {
            Self::Pcap(d) => d.header().is_some(),
            Self::Pcapng(d) => d.section_started(),
            Self::Lvx(d) => d.header_done(),
        }
    }

    fn at_boundary(&self) -> bool {
        match self {
            Self::Pcap(_) | Self::Pcapng(_) => true,
            Self::Lvx(d) => d.at_frame_boundary(),
        }
    }

    fn offset(&self) -> u64 {
        match self {
            Self::Pcap(d) => d.offset(),
            Self::Pcapng(d) => d.offset(),
            Self::Lvx(d) => d.offset(),
        }
    }
}

/// Bytes from a file (read on demand) or from memory.
struct Source {
    buf: Vec<u8>,
    start: usize,
    reader: Option<Box<dyn Read + Send>>,
}

impl Source {
    fn available(&self) -> &[u8] {
        self.buf.get(self.start..).unwrap_or(&[])
    }

    fn consume(&mut self, n: usize) {
        self.start = self.start.saturating_add(n).min(self.buf.len());
    }

    /// Makes at least `want` bytes available; false when the input ends first. Callers cap `want`.
    fn fill(&mut self, want: usize) -> Result<bool> {
        loop {
            let have = self.buf.len().saturating_sub(self.start);
            if have >= want {
                return Ok(true);
            }
            let Some(reader) = self.reader.as_mut() else {
                return Ok(false);
            };
            if self.start > 0 {
                self.buf.drain(..self.start);
                self.start = 0;
            }
            let old = self.buf.len();
            self.buf.resize(old + (want - have).max(READ_CHUNK), 0);
            let read = match self.buf.get_mut(old..) {
                Some(tail) => reader.read(tail),
                None => Ok(0),
            };
            match read {
                Ok(n) => {
                    self.buf.truncate(old + n);
                    if n == 0 {
                        self.reader = None;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => self.buf.truncate(old),
                Err(e) => {
                    self.buf.truncate(old);
                    self.reader = None;
                    return Err(LivoxError::io("reading capture", e));
                }
            }
        }
    }
}

/// A capture being read: an iterator of datagrams.
pub struct Capture {
    format: CaptureFormat,
    source: Source,
    decoder: Decoder,
    stats: ReadStats,
    done: bool,
}

/// Opens a capture file, recognising pcap, pcapng or .lvx by its first bytes, and reads its headers.
pub fn open(path: &Path) -> Result<Capture> {
    let file = File::open(path).map_err(|e| LivoxError::io(format!("opening {}", path.display()), e))?;
    Capture::from_reader(Box::new(file))
}

/// A capture held in memory (tests, fuzzing).
pub fn from_bytes(bytes: Vec<u8>) -> Result<Capture> {
    Capture::from_bytes(bytes)
}

impl Capture {
    /// Streams a capture from any reader (a file, a pipe).
    pub fn from_reader(reader: Box<dyn Read + Send>) -> Result<Self> {
        let mut source = Source { buf: Vec::new(), start: 0, reader: Some(reader) };
        source.fill(16)?;
        let head = source.available();
        let format = CaptureFormat::detect(head)
            .ok_or_else(|| LivoxError::UnknownCaptureFormat(head.iter().take(16).copied().collect()))?;
        Self::start(source, format)
    }

    /// A capture held in memory; the format is recognised from its first bytes.
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self> {
        let format = CaptureFormat::detect(&bytes)
            .ok_or_else(|| LivoxError::UnknownCaptureFormat(bytes.iter().take(16).copied().collect()))?;
        Self::from_bytes_as(bytes, format)
    }

    /// A capture held in memory, read as `format` whatever its first bytes say (fuzzing).
    pub fn from_bytes_as(bytes: Vec<u8>, format: CaptureFormat) -> Result<Self> {
        Self::start(Source { buf: bytes, start: 0, reader: None }, format)
    }

    fn start(source: Source, format: CaptureFormat) -> Result<Self> {
        let mut capture =
            Self { format, source, decoder: Decoder::new(format), stats: ReadStats::default(), done: false };
        while !capture.decoder.header_done() {
            match capture.advance()? {
                Advance::Skipped => {}
                // Every decoder consumes its header before yielding records.
                Advance::Record(_) | Advance::End => {
                    return Err(LivoxError::MalformedCapture {
                        format: format.name(),
                        offset: 0,
                        reason: "no file header",
                    })
                }
            }
        }
        Ok(capture)
    }

    pub fn format(&self) -> CaptureFormat {
        self.format
    }

    pub fn stats(&self) -> &ReadStats {
        &self.stats
    }

    /// The pcap file header (pcap only).
    pub fn pcap_header(&self) -> Option<&PcapHeader> {
        match &self.decoder {
            Decoder::Pcap(d) => d.header(),
            _ => None,
        }
    }

    /// The interfaces of the current pcapng section (pcapng only).
    pub fn pcapng_interfaces(&self) -> Option<&[Interface]> {
        match &self.decoder {
            Decoder::Pcapng(d) => Some(d.interfaces()),
            _ => None,
        }
    }

    /// The .lvx headers and device list (lvx only).
    pub fn lvx_header(&self) -> Option<&LvxHeader> {
        match &self.decoder {
            Decoder::Lvx(d) => d.header(),
            _ => None,
        }
    }

    /// Reads the next datagram into `out`, reusing its payload buffer; false at the end.
    /// After an error the capture is finished.
    pub fn read_into(&mut self, out: &mut Datagram) -> Result<bool> {
        if self.done {
            return Ok(false);
        }
        loop {
            match self.advance() {
                Ok(Advance::Skipped) => {}
                Ok(Advance::Record(fill)) => {
                    if self.fill_datagram(fill, out) {
                        self.stats.datagrams += 1;
                        return Ok(true);
                    }
                }
                Ok(Advance::End) => {
                    self.done = true;
                    return Ok(false);
                }
                Err(e) => {
                    self.done = true;
                    return Err(e);
                }
            }
        }
    }

    /// Runs the decoder until it has a record or the input ends.
    fn advance(&mut self) -> Result<Advance> {
        loop {
            let step = self.decoder.step(self.source.available(), &mut self.stats)?;
            match step {
                Step::Need(n) => {
                    let have = self.source.available().len();
                    if n <= have {
                        // A decoder must ask for more than it has; refuse to spin.
                        return Err(LivoxError::MalformedCapture {
                            format: self.format.name(),
                            offset: self.decoder.offset(),
                            reason: "decoder made no progress",
                        });
                    }
                    if !self.source.fill(n)? {
                        let have = self.source.available().len();
                        if have == 0 && self.decoder.at_boundary() && self.decoder.header_done() {
                            return Ok(Advance::End);
                        }
                        return Err(LivoxError::CaptureTruncated {
                            format: self.format.name(),
                            offset: self.decoder.offset(),
                            need: n,
                            have,
                        });
                    }
                }
                Step::Skip(n) => {
                    self.source.consume(n);
                    return Ok(Advance::Skipped);
                }
                Step::Frame(frame) => return Ok(Advance::Record(Pending::Frame(frame))),
                Step::Package { consumed, device_index, data } => {
                    return Ok(Advance::Record(Pending::Package { consumed, device_index, data }))
                }
            }
        }
    }

    /// Turns a record into a datagram and consumes it; false when the record is skipped.
    fn fill_datagram(&mut self, pending: Pending, out: &mut Datagram) -> bool {
        self.stats.records += 1;
        let input = self.source.available();
        let kept = match pending {
            Pending::Frame(frame) => {
                let data = input.get(frame.data.clone()).unwrap_or(&[]);
                let truncated = frame.original_len > data.len() as u64;
                if truncated {
                    self.stats.truncated += 1;
                }
                let kept = match net::decode_link(frame.link_type, data) {
                    Ok(udp) => {
                        out.time = Stamp::new(frame.time_ns, Clock::Host);
                        out.src = Some(udp.src);
                        out.dst = Some(udp.dst);
                        out.device_index = None;
                        out.payload.clear();
                        out.payload.extend_from_slice(udp.payload);
                        true
                    }
                    Err(skip) => {
                        match skip {
                            net::Skip::NotUdp => self.stats.non_udp += 1,
                            net::Skip::Fragment => self.stats.fragments += 1,
                            net::Skip::UnsupportedLink => self.stats.unsupported_link += 1,
                            // A cut record's headers promise more than it holds; counted above.
                            net::Skip::Short if truncated => {}
                            net::Skip::Short | net::Skip::Malformed => self.stats.malformed += 1,
                        }
                        false
                    }
                };
                self.source.consume(frame.consumed);
                kept
            }
            Pending::Package { consumed, device_index, data } => {
                let bytes = input.get(data).unwrap_or(&[]);
                out.time = lvx::package_stamp(bytes);
                out.src = None;
                out.dst = None;
                out.device_index = Some(device_index);
                out.payload.clear();
                out.payload.extend_from_slice(bytes);
                self.source.consume(consumed);
                true
            }
        };
        kept
    }
}

enum Advance {
    Skipped,
    Record(Pending),
    End,
}

enum Pending {
    Frame(FrameRef),
    Package { consumed: usize, device_index: u8, data: Range<usize> },
}

impl Iterator for Capture {
    type Item = Result<Datagram>;

    fn next(&mut self) -> Option<Self::Item> {
        let mut datagram = Datagram::default();
        match self.read_into(&mut datagram) {
            Ok(true) => Some(Ok(datagram)),
            Ok(false) => None,
            Err(e) => Some(Err(e)),
        }
    }
}

/// Fixed-width readers in a chosen byte order; callers check lengths first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Endian {
    pub big: bool,
}

impl Endian {
    pub(crate) fn u16(self, b: &[u8], i: usize) -> u16 {
        let v = [b[i], b[i + 1]];
        if self.big {
            u16::from_be_bytes(v)
        } else {
            u16::from_le_bytes(v)
        }
    }

    pub(crate) fn u32(self, b: &[u8], i: usize) -> u32 {
        let v = [b[i], b[i + 1], b[i + 2], b[i + 3]];
        if self.big {
            u32::from_be_bytes(v)
        } else {
            u32::from_le_bytes(v)
        }
    }

    pub(crate) fn u64(self, b: &[u8], i: usize) -> u64 {
        let hi = u64::from(self.u32(b, i));
        let lo = u64::from(self.u32(b, i + 4));
        if self.big {
            (hi << 32) | lo
        } else {
            (lo << 32) | hi
        }
    }
}
