//! A checked scanner of an MCAP data section: schemas, channels and messages, inside chunks or
//! not, in file order.
//!
//! We read with this rather than the `mcap` crate's `MessageStream` because that one sizes
//! buffers by lengths taken from the file (a flipped byte in a chunk aborts the process on an
//! allocation failure). Here every length is checked against the bytes present, a chunk's
//! declared uncompressed size is capped before anything is allocated, and chunk CRCs are
//! verified. Only what a reader needs is parsed; indexes and the summary are skipped.

use crate::PipelineError;
use std::collections::{BTreeMap, VecDeque};
use std::io::Read;

/// The bytes an MCAP file starts and ends with.
pub use mcap::MAGIC;

const OP_FOOTER: u8 = 0x02;
const OP_SCHEMA: u8 = 0x03;
const OP_CHANNEL: u8 = 0x04;
const OP_MESSAGE: u8 = 0x05;
const OP_CHUNK: u8 = 0x06;
const OP_DATA_END: u8 = 0x0F;

/// LZ4 cannot expand a block by more than about 255x; a claim beyond this is damage.
const MAX_LZ4_RATIO: u64 = 256;
/// No chunk we write comes near this; a larger claim is refused before allocating.
pub const MAX_CHUNK_BYTES: u64 = 1 << 30;
/// Room reserved up front for a decompressed chunk (default chunks are 4 MiB).
const PREALLOCATE_MAX: u64 = 16 << 20;

/// CRC-32 as MCAP uses it (zlib's), slice-by-16: the byte-wise table made CRC checks half the
/// read time.
static CHUNK_CRC: crc::Crc<u32, crc::Table<16>> = crc::Crc::<u32, crc::Table<16>>::new(&crc::CRC_32_ISO_HDLC);

/// One message with its channel's description.
#[derive(Clone, Debug, PartialEq)]
pub struct ScannedMessage {
    pub topic: String,
    pub schema_name: String,
    pub encoding: String,
    pub sequence: u32,
    pub log_ns: u64,
    pub publish_ns: u64,
    pub payload: Vec<u8>,
}

#[derive(Clone, Debug)]
struct Channel {
    topic: String,
    schema_id: u16,
    encoding: String,
}

fn bad(offset: usize, reason: impl Into<String>) -> PipelineError {
    PipelineError::BadFile { format: "MCAP", reason: format!("at byte {offset}: {}", reason.into()) }
}

/// A little-endian cursor over one record body; `base` is the body's offset for messages.
struct Body<'a> {
    b: &'a [u8],
    pos: usize,
    base: usize,
}

impl<'a> Body<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], PipelineError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.b.len());
        let out = end.and_then(|e| self.b.get(self.pos..e));
        let Some(out) = out else {
            return Err(bad(self.base + self.pos, format!("{what} needs {n} bytes, {} left", self.b.len() - self.pos)));
        };
        self.pos += n;
        Ok(out)
    }
    fn arr<const N: usize>(&mut self, what: &str) -> Result<[u8; N], PipelineError> {
        let at = self.base + self.pos;
        self.take(N, what)?.try_into().map_err(|_| bad(at, what))
    }
    fn u16(&mut self, what: &str) -> Result<u16, PipelineError> {
        Ok(u16::from_le_bytes(self.arr(what)?))
    }
    fn u32(&mut self, what: &str) -> Result<u32, PipelineError> {
        Ok(u32::from_le_bytes(self.arr(what)?))
    }
    fn u64(&mut self, what: &str) -> Result<u64, PipelineError> {
        Ok(u64::from_le_bytes(self.arr(what)?))
    }
    fn string(&mut self, what: &str) -> Result<String, PipelineError> {
        let n = self.u32(what)? as usize;
        let at = self.base + self.pos;
        let b = self.take(n, what)?;
        String::from_utf8(b.to_vec()).map_err(|_| bad(at, format!("{what} is not UTF-8")))
    }
    fn rest(&mut self) -> &'a [u8] {
        let out = self.b.get(self.pos..).unwrap_or_default();
        self.pos = self.b.len();
        out
    }
}

/// A record's opcode, body, and the offset just past it.
type RawRecord<'a> = (u8, &'a [u8], usize);

/// Splits `op (1) | length (8) | body` at `pos`; `Ok(None)` at the exact end of `buf`.
fn record(buf: &[u8], pos: usize) -> Result<Option<RawRecord<'_>>, PipelineError> {
    if pos == buf.len() {
        return Ok(None);
    }
    let head = buf.get(pos..pos.saturating_add(9)).ok_or_else(|| PipelineError::Truncated {
        format: "MCAP",
        what: "record header",
        need: 9,
        have: (buf.len() - pos) as u64,
    })?;
    let op = head[0];
    let len = u64::from_le_bytes([head[1], head[2], head[3], head[4], head[5], head[6], head[7], head[8]]);
    let start = pos + 9;
    let have = (buf.len() - start) as u64;
    if len > have {
        return Err(PipelineError::Truncated { format: "MCAP", what: "record", need: len, have });
    }
    let end = start + len as usize;
    let body = buf.get(start..end).ok_or_else(|| bad(pos, "record out of range"))?;
    Ok(Some((op, body, end)))
}

/// Whether `tail` (the last 37 bytes or more of a file) ends like a finished MCAP: a footer
/// record, then the magic.
pub fn is_finished(tail: &[u8]) -> bool {
    let n = tail.len();
    n >= 37
        && tail.get(n - 8..) == Some(MAGIC)
        && tail.get(n - 37) == Some(&OP_FOOTER)
        && tail.get(n - 36..n - 28) == Some(&20u64.to_le_bytes()[..])
}

/// Scans the data section of an MCAP from any reader of known length (a file, or bytes in
/// memory); memory use is one record (a chunk, 4 MiB by default) at a time.
pub struct Scanner<R: Read> {
    src: R,
    /// Bytes consumed so far, and the total the source holds.
    pos: u64,
    len: u64,
    schemas: BTreeMap<u16, (String, String)>,
    channels: BTreeMap<u16, Channel>,
    pending: VecDeque<ScannedMessage>,
    data_end: bool,
    failed: bool,
}

fn io_err(e: std::io::Error) -> PipelineError {
    PipelineError::io("reading the recording", e)
}

/// Reads up to `buf.len()` bytes; fewer only at the end of the source.
fn read_full<R: Read>(src: &mut R, buf: &mut [u8]) -> Result<usize, PipelineError> {
    let mut n = 0;
    while n < buf.len() {
        match src.read(buf.get_mut(n..).unwrap_or_default()) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(io_err(e)),
        }
    }
    Ok(n)
}

impl<'a> Scanner<&'a [u8]> {
    /// Scans bytes held in memory.
    pub fn from_bytes(buf: &'a [u8]) -> Result<Self, PipelineError> {
        Self::new(buf, buf.len() as u64)
    }
}

impl<R: Read> Scanner<R> {
    /// `len` is the source's total size (a file's length): no record may claim more.
    pub fn new(mut src: R, len: u64) -> Result<Self, PipelineError> {
        let mut magic = [0u8; 8];
        let n = read_full(&mut src, &mut magic)?;
        if n < magic.len() {
            return Err(PipelineError::Truncated { format: "MCAP", what: "magic", need: 8, have: n as u64 });
        }
        if magic[..] != *MAGIC {
            return Err(bad(0, "no MCAP magic"));
        }
        Ok(Self {
            src,
            pos: MAGIC.len() as u64,
            len,
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            pending: VecDeque::new(),
            data_end: false,
            failed: false,
        })
    }

    /// The next top-level record: `None` at the exact end of the source.
    fn read_record(&mut self) -> Result<Option<(u8, Vec<u8>, u64)>, PipelineError> {
        let mut head = [0u8; 9];
        let n = read_full(&mut self.src, &mut head)?;
        if n == 0 {
            return Ok(None);
        }
        if n < head.len() {
            return Err(PipelineError::Truncated { format: "MCAP", what: "record header", need: 9, have: n as u64 });
        }
        let [op, l @ ..] = head;
        let len = u64::from_le_bytes(l);
        let base = self.pos + 9;
        let have = self.len.saturating_sub(base);
        if len > have {
            return Err(PipelineError::Truncated { format: "MCAP", what: "record", need: len, have });
        }
        // `len` is within what the source holds (checked above), so reserving it is bounded
        let mut body = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
        (&mut self.src).take(len).read_to_end(&mut body).map_err(io_err)?;
        if (body.len() as u64) < len {
            return Err(PipelineError::Truncated {
                format: "MCAP",
                what: "record",
                need: len,
                have: body.len() as u64,
            });
        }
        self.pos = base + len;
        Ok(Some((op, body, base)))
    }

    /// The next message; `None` after the data-end record. A file that stops earlier is an
    /// error (`Truncated`), as is any damage; after an error the scanner stays stopped.
    pub fn next_message(&mut self) -> Option<Result<ScannedMessage, PipelineError>> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Some(Ok(m));
            }
            if self.data_end || self.failed {
                return None;
            }
            match self.step() {
                Ok(()) => {}
                Err(e) => {
                    self.failed = true;
                    return Some(Err(e));
                }
            }
        }
    }

    fn step(&mut self) -> Result<(), PipelineError> {
        let Some((op, body, base)) = self.read_record()? else {
            return Err(PipelineError::Truncated {
                format: "MCAP",
                what: "data section (the file ends before its data-end record: not finished)",
                need: 9,
                have: 0,
            });
        };
        let base = usize::try_from(base).unwrap_or(usize::MAX);
        match op {
            OP_DATA_END | OP_FOOTER => self.data_end = true,
            OP_CHUNK => self.chunk(&body, base)?,
            _ => self.inner_record(op, &body, base)?,
        }
        Ok(())
    }

    fn inner_record(&mut self, op: u8, body: &[u8], base: usize) -> Result<(), PipelineError> {
        let mut b = Body { b: body, pos: 0, base };
        match op {
            OP_SCHEMA => {
                let id = b.u16("schema id")?;
                let name = b.string("schema name")?;
                let encoding = b.string("schema encoding")?;
                // the definition text itself is not needed to decode our types
                self.schemas.insert(id, (name, encoding));
            }
            OP_CHANNEL => {
                let id = b.u16("channel id")?;
                let schema_id = b.u16("channel schema id")?;
                let topic = b.string("topic")?;
                let encoding = b.string("message encoding")?;
                self.channels.insert(id, Channel { topic, schema_id, encoding });
            }
            OP_MESSAGE => {
                let channel_id = b.u16("message channel id")?;
                let sequence = b.u32("sequence")?;
                let log_ns = b.u64("log time")?;
                let publish_ns = b.u64("publish time")?;
                let payload = b.rest().to_vec();
                let c =
                    self.channels.get(&channel_id).ok_or_else(|| bad(base, format!("unknown channel {channel_id}")))?;
                let schema_name = match c.schema_id {
                    0 => String::new(),
                    id => self
                        .schemas
                        .get(&id)
                        .map(|s| s.0.clone())
                        .ok_or_else(|| bad(base, format!("unknown schema {id}")))?,
                };
                self.pending.push_back(ScannedMessage {
                    topic: c.topic.clone(),
                    schema_name,
                    encoding: c.encoding.clone(),
                    sequence,
                    log_ns,
                    publish_ns,
                    payload,
                });
            }
            _ => {} // indexes, attachments, metadata: not needed to replay
        }
        Ok(())
    }

    fn chunk(&mut self, body: &[u8], base: usize) -> Result<(), PipelineError> {
        let mut b = Body { b: body, pos: 0, base };
        let _start = b.u64("chunk start time")?;
        let _end = b.u64("chunk end time")?;
        let uncompressed_size = b.u64("chunk uncompressed size")?;
        let crc = b.u32("chunk crc")?;
        let compression = b.string("chunk compression")?;
        let records_len = b.u64("chunk records length")?;
        let at = base + b.pos;
        let records = b.take(usize::try_from(records_len).map_err(|_| bad(at, "chunk too long"))?, "chunk records")?;
        let data: std::borrow::Cow<'_, [u8]> = match compression.as_str() {
            "" => {
                if uncompressed_size != records_len {
                    return Err(bad(
                        at,
                        format!("uncompressed chunk of {records_len} bytes claims {uncompressed_size}"),
                    ));
                }
                records.into()
            }
            "lz4" => {
                let cap = (records_len.saturating_mul(MAX_LZ4_RATIO)).min(MAX_CHUNK_BYTES);
                if uncompressed_size > cap {
                    return Err(bad(
                        at,
                        format!("chunk claims {uncompressed_size} bytes from {records_len} compressed"),
                    ));
                }
                // grows with what actually decompresses; the claim only bounds it
                let mut out = Vec::with_capacity(uncompressed_size.min(PREALLOCATE_MAX) as usize);
                let dec = lz4::Decoder::new(records).map_err(|e| bad(at, format!("lz4: {e}")))?;
                dec.take(uncompressed_size).read_to_end(&mut out).map_err(|e| bad(at, format!("lz4: {e}")))?;
                if out.len() as u64 != uncompressed_size {
                    return Err(bad(
                        at,
                        format!("chunk decompressed to {} bytes, header says {uncompressed_size}", out.len()),
                    ));
                }
                out.into()
            }
            other => {
                return Err(PipelineError::Unsupported { format: "MCAP", what: format!("chunk compression `{other}`") })
            }
        };
        if crc != 0 {
            let calculated = CHUNK_CRC.checksum(&data);
            if calculated != crc {
                return Err(bad(at, format!("chunk CRC {calculated:08x}, header says {crc:08x}")));
            }
        }
        // Messages queue behind any still pending, so file order is kept.
        let mut pos = 0;
        while let Some((op, body, end)) = record(&data, pos).map_err(|e| bad(at, format!("inside a chunk: {e}")))? {
            // offsets inside a compressed chunk do not map to the file; report the chunk's
            self.inner_record(op, body, at)?;
            pos = end;
        }
        Ok(())
    }
}
