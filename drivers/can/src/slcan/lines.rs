//! Splits an slcan byte stream into lines: CR ends a line, BEL is an error reply on its own.

/// Longest line we accept: `T` + 8 id + 1 dlc + 16 data + 4 stamp = 30; anything much longer
/// is garbage.
pub const MAX_LINE: usize = 64;

/// One item of the stream.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Line {
    /// The bytes before a CR (possibly empty: a bare CR is the "ok" reply).
    Text(Vec<u8>),
    /// A BEL: the other side refused the last command. Bytes before it on the same line are
    /// dropped (a Lawicel adapter sends BEL alone).
    Bell,
    /// More than [`MAX_LINE`] bytes without CR or BEL; they were dropped up to the next end.
    Overlong,
}

/// Accumulates bytes and yields complete lines.
#[derive(Debug, Default)]
pub struct LineSplitter {
    buf: Vec<u8>,
    overflowed: bool,
}

impl LineSplitter {
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes; complete lines are appended to `out`.
    pub fn push(&mut self, bytes: &[u8], out: &mut Vec<Line>) {
        for &b in bytes {
            match b {
                b'\r' => {
                    if std::mem::take(&mut self.overflowed) {
                        out.push(Line::Overlong);
                    } else {
                        out.push(Line::Text(std::mem::take(&mut self.buf)));
                    }
                    self.buf.clear();
                }
                0x07 => {
                    if std::mem::take(&mut self.overflowed) {
                        out.push(Line::Overlong);
                    }
                    self.buf.clear();
                    out.push(Line::Bell);
                }
                // Linux's slcan and some adapters end lines with CR LF; a stray LF is noise.
                b'\n' if self.buf.is_empty() => {}
                _ if self.overflowed => {}
                _ if self.buf.len() >= MAX_LINE => {
                    self.overflowed = true;
                    self.buf.clear();
                }
                _ => self.buf.push(b),
            }
        }
    }

    /// Bytes waiting for their end of line.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_on_cr_and_bel_across_pushes() {
        let mut s = LineSplitter::new();
        let mut out = Vec::new();
        s.push(b"t20", &mut out);
        assert!(out.is_empty());
        s.push(b"10\r\r\x07z\r\n", &mut out);
        assert_eq!(out, vec![Line::Text(b"t2010".to_vec()), Line::Text(vec![]), Line::Bell, Line::Text(b"z".to_vec())]);
    }

    #[test]
    fn overlong_lines_are_dropped_and_reported_once() {
        let mut s = LineSplitter::new();
        let mut out = Vec::new();
        s.push(&[b'x'; 200], &mut out);
        s.push(b"\rV1013\r", &mut out);
        assert_eq!(out, vec![Line::Overlong, Line::Text(b"V1013".to_vec())]);
        assert_eq!(s.pending(), 0);
    }
}
