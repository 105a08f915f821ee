//! OMG CDR (XCDR1, little endian) as ROS 2 puts it on the wire and in bags.
//!
//! A payload starts with a 4-byte encapsulation header (`00 01 00 00` for little-endian plain
//! CDR); every primitive is then aligned to its own size counted from the end of that header.
//! Strings are a `u32` length that includes the terminating NUL, the bytes, the NUL. Sequences
//! are a `u32` element count then the elements; fixed arrays have no count.
//!
//! The reader takes untrusted bytes: every length is checked against what is left before
//! anything is read or allocated, and it returns [`PipelineError::BadCdr`] instead of panicking.

use crate::PipelineError;

/// Encapsulation header of little-endian plain CDR (representation id 0x0001, options 0).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Builds one CDR payload.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl CdrWriter {
    pub fn new() -> Self {
        Self::with_capacity(64)
    }

    pub fn with_capacity(bytes: usize) -> Self {
        let mut buf = Vec::with_capacity(bytes.saturating_add(CDR_LE_HEADER.len()));
        buf.extend_from_slice(&CDR_LE_HEADER);
        Self { buf }
    }

    /// The finished payload, header included.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - CDR_LE_HEADER.len();
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A sequence or string length. CDR cannot say more than `u32::MAX`; callers keep to that
    /// (a longer one is refused before anything is written, see [`check_len`]).
    pub fn len(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }

    pub fn string(&mut self, s: &str) {
        self.len(s.len() + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// `uint8[]`: count then the raw bytes.
    pub fn bytes(&mut self, b: &[u8]) {
        self.len(b.len());
        self.buf.extend_from_slice(b);
    }

    pub fn f64_array(&mut self, values: &[f64]) {
        for &v in values {
            self.f64(v);
        }
    }

    /// Reserves room for `n` more raw bytes (large point-cloud payloads).
    pub fn reserve(&mut self, n: usize) {
        self.buf.reserve(n);
    }
}

/// Refuses a length CDR cannot encode (sequences and strings count in `u32`).
pub fn check_len(type_name: &'static str, what: &str, n: usize) -> Result<(), PipelineError> {
    if n >= u32::MAX as usize {
        return Err(PipelineError::Recording {
            reason: format!("{type_name}.{what} has {n} elements; CDR allows < 2^32"),
        });
    }
    Ok(())
}

/// Reads one CDR payload. `type_name` only labels errors.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    body: &'a [u8],
    pos: usize,
    type_name: &'static str,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header: only little-endian plain CDR is accepted (what every
    /// ROS 2 middleware on x86 and ARM writes).
    pub fn new(payload: &'a [u8], type_name: &'static str) -> Result<Self, PipelineError> {
        let Some((header, body)) = payload.split_first_chunk::<4>() else {
            return Err(PipelineError::BadCdr {
                type_name,
                offset: 0,
                reason: format!("{} bytes, shorter than the 4-byte encapsulation header", payload.len()),
            });
        };
        match header {
            [0x00, 0x01, _, _] => Ok(Self { body, pos: 0, type_name }),
            [0x00, 0x00, _, _] => {
                Err(PipelineError::BadCdr { type_name, offset: 0, reason: "big-endian CDR is not supported".into() })
            }
            [a, b, _, _] => Err(PipelineError::BadCdr {
                type_name,
                offset: 0,
                reason: format!("encapsulation {a:02x}{b:02x} is not plain CDR"),
            }),
        }
    }

    fn err(&self, reason: impl Into<String>) -> PipelineError {
        PipelineError::BadCdr { type_name: self.type_name, offset: self.pos + 4, reason: reason.into() }
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.body.len().saturating_sub(self.pos)
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], PipelineError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.body.len());
        let Some(end) = end else {
            return Err(self.err(format!("{what} needs {n} bytes, {} left", self.remaining())));
        };
        let out = self.body.get(self.pos..end).ok_or_else(|| self.err(format!("{what}: out of range")))?;
        self.pos = end;
        Ok(out)
    }

    fn align(&mut self, n: usize, what: &str) -> Result<(), PipelineError> {
        let pad = (n - self.pos % n) % n;
        self.take(pad, what).map(|_| ())
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], PipelineError> {
        self.align(N, what)?;
        let b = self.take(N, what)?;
        b.try_into().map_err(|_| self.err(format!("{what}: short read")))
    }

    pub fn u8(&mut self, what: &str) -> Result<u8, PipelineError> {
        Ok(self.array::<1>(what)?[0])
    }

    pub fn bool(&mut self, what: &str) -> Result<bool, PipelineError> {
        match self.u8(what)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(self.err(format!("{what}: {v} is not a bool"))),
        }
    }

    pub fn u32(&mut self, what: &str) -> Result<u32, PipelineError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    pub fn i32(&mut self, what: &str) -> Result<i32, PipelineError> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }

    pub fn f32(&mut self, what: &str) -> Result<f32, PipelineError> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }

    pub fn f64(&mut self, what: &str) -> Result<f64, PipelineError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// A sequence count, refused when even `min_elem_bytes` per element would overrun the
    /// payload (so no allocation is ever sized by an untrusted count).
    pub fn seq_len(&mut self, what: &str, min_elem_bytes: usize) -> Result<usize, PipelineError> {
        let n = self.u32(what)? as usize;
        if n.saturating_mul(min_elem_bytes.max(1)) > self.remaining() {
            return Err(self.err(format!("{what}: {n} elements cannot fit in {} bytes", self.remaining())));
        }
        Ok(n)
    }

    pub fn string(&mut self, what: &str) -> Result<String, PipelineError> {
        let n = self.u32(what)? as usize;
        if n == 0 {
            // Some writers encode "" as length 0 without a NUL; accept it.
            return Ok(String::new());
        }
        let raw = self.take(n, what)?;
        let Some((&0, text)) = raw.split_last() else {
            return Err(self.err(format!("{what}: string not NUL-terminated")));
        };
        String::from_utf8(text.to_vec()).map_err(|_| self.err(format!("{what}: not UTF-8")))
    }

    /// `uint8[]`, borrowed from the payload.
    pub fn bytes(&mut self, what: &str) -> Result<&'a [u8], PipelineError> {
        let n = self.u32(what)? as usize;
        self.take(n, what)
    }

    pub fn f64_array<const N: usize>(&mut self, what: &str) -> Result<[f64; N], PipelineError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn alignment_counts_from_after_the_header() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.f64(1.5);
        w.string("ab");
        w.u32(9);
        let b = w.into_bytes();
        // header, u8, 7 pad, f64 at body offset 8, string len at 16, "ab\0" at 20..23, pad to 24, u32
        assert_eq!(&b[..4], &CDR_LE_HEADER);
        assert_eq!(b[4], 7);
        assert_eq!(&b[5..12], &[0; 7]);
        assert_eq!(f64::from_le_bytes(b[12..20].try_into().unwrap()), 1.5);
        assert_eq!(u32::from_le_bytes(b[20..24].try_into().unwrap()), 3);
        assert_eq!(&b[24..27], b"ab\0");
        assert_eq!(b[27], 0);
        assert_eq!(u32::from_le_bytes(b[28..32].try_into().unwrap()), 9);
        assert_eq!(b.len(), 32);

        let mut r = CdrReader::new(&b, "test").unwrap();
        assert_eq!(r.u8("a").unwrap(), 7);
        assert_eq!(r.f64("b").unwrap(), 1.5);
        assert_eq!(r.string("c").unwrap(), "ab");
        assert_eq!(r.u32("d").unwrap(), 9);
        assert_eq!(r.remaining(), 0);
    }

    #[test]
    fn refuses_bad_input_without_panicking() {
        assert!(CdrReader::new(&[0, 1], "t").is_err());
        assert!(CdrReader::new(&[0, 0, 0, 0], "t").is_err());
        assert!(CdrReader::new(&[0, 7, 0, 0], "t").is_err());
        // a string claiming 4 GB
        let mut r = CdrReader::new(&[0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff, b'a'], "t").unwrap();
        assert!(matches!(r.string("s"), Err(PipelineError::BadCdr { offset: 8, .. })));
        // a string without its NUL
        let mut r = CdrReader::new(&[0, 1, 0, 0, 2, 0, 0, 0, b'a', b'b'], "t").unwrap();
        assert!(r.string("s").is_err());
        // a sequence count larger than the payload could hold
        let mut r = CdrReader::new(&[0, 1, 0, 0, 0, 0, 0, 0x10], "t").unwrap();
        assert!(r.seq_len("q", 1).is_err());
        // a bool that is neither 0 nor 1
        let mut r = CdrReader::new(&[0, 1, 0, 0, 2], "t").unwrap();
        assert!(r.bool("b").is_err());
        // truncated f64
        let mut r = CdrReader::new(&[0, 1, 0, 0, 1, 2, 3], "t").unwrap();
        assert!(r.f64("x").is_err());
    }
}
