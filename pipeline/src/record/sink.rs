//! [`RetrySink`]: the recording's file, which rides out a full disk.
//!
//! A write that fails because the disk (or the quota) is full keeps its bytes in memory and
//! reports them written; every later write or flush first tries those bytes again. The file on
//! disk is therefore always a prefix of the recording's byte stream: never a hole, never a chunk
//! written twice, so a reader in recover mode reads every chunk that made it. While bytes are
//! held the recorder takes no new messages (it counts them), so the memory held stays one chunk.

use std::io::{self, Seek, SeekFrom, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// What a [`RetrySink`] holds, readable while the MCAP writer owns the sink.
#[derive(Debug, Default)]
pub struct SinkGauge {
    held_bytes: AtomicU64,
    full_events: AtomicU64,
}

impl SinkGauge {
    /// Bytes waiting for room on the disk.
    pub fn held_bytes(&self) -> u64 {
        self.held_bytes.load(Ordering::Relaxed)
    }

    /// Writes refused for lack of room (each retried later).
    pub fn full_events(&self) -> u64 {
        self.full_events.load(Ordering::Relaxed)
    }
}

/// Whether `e` means "no room now" (a disk or quota that may free up), not a broken file.
pub fn is_disk_full(e: &io::Error) -> bool {
    matches!(e.kind(), io::ErrorKind::StorageFull | io::ErrorKind::QuotaExceeded)
}

/// A writer that holds back what a full disk refused and retries it first.
#[derive(Debug)]
pub struct RetrySink<W> {
    inner: W,
    /// Bytes accepted but not yet on disk, in order.
    held: Vec<u8>,
    /// Bytes on disk: the logical position is this plus `held`.
    written: u64,
    gauge: Arc<SinkGauge>,
}

impl<W: Write> RetrySink<W> {
    pub fn new(inner: W, written: u64) -> Self {
        Self { inner, held: Vec::new(), written, gauge: Arc::default() }
    }

    pub fn gauge(&self) -> Arc<SinkGauge> {
        self.gauge.clone()
    }

    pub fn held_bytes(&self) -> usize {
        self.held.len()
    }

    fn note_full(&mut self) {
        self.gauge.full_events.fetch_add(1, Ordering::Relaxed);
    }

    fn note_held(&self) {
        self.gauge.held_bytes.store(self.held.len() as u64, Ordering::Relaxed);
    }

    pub fn get_ref(&self) -> &W {
        &self.inner
    }

    /// Tries the held bytes again; they stay held (and this returns `Ok`) while the disk is
    /// full. Any other error is returned.
    pub fn retry(&mut self) -> io::Result<()> {
        let result = self.write_held();
        self.note_held();
        result
    }

    fn write_held(&mut self) -> io::Result<()> {
        while !self.held.is_empty() {
            match self.inner.write(&self.held) {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    self.held.drain(..n);
                    self.written += n as u64;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if is_disk_full(&e) => {
                    self.note_full();
                    return Ok(());
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    fn position(&self) -> u64 {
        self.written + self.held.len() as u64
    }
}

impl<W: Write> Write for RetrySink<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.retry()?;
        if !self.held.is_empty() {
            self.held.extend_from_slice(buf);
            self.note_held();
            return Ok(buf.len());
        }
        match self.inner.write(buf) {
            Ok(n) => {
                self.written += n as u64;
                Ok(n)
            }
            Err(e) if is_disk_full(&e) => {
                self.note_full();
                self.held.extend_from_slice(buf);
                self.note_held();
                Ok(buf.len())
            }
            Err(e) => Err(e),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        self.retry()?;
        if self.held.is_empty() {
            self.inner.flush()
        } else {
            Ok(())
        }
    }
}

/// Only "where am I" is answered while bytes are held (the MCAP writer asks it for its
/// offsets); a real seek first needs everything on disk.
impl<W: Write + Seek> Seek for RetrySink<W> {
    fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
        if pos == SeekFrom::Current(0) {
            return Ok(self.position());
        }
        self.retry()?;
        if !self.held.is_empty() {
            return Err(io::Error::new(io::ErrorKind::StorageFull, "seeking a recording whose disk is full"));
        }
        self.written = self.inner.seek(pos)?;
        Ok(self.written)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::io::Cursor;

    /// A disk with `room` bytes free; the test frees more.
    struct Disk {
        bytes: Cursor<Vec<u8>>,
        room: usize,
    }

    impl Write for Disk {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            if self.room == 0 {
                return Err(io::ErrorKind::StorageFull.into());
            }
            let n = buf.len().min(self.room);
            self.room -= n;
            self.bytes.write(&buf[..n])
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Seek for Disk {
        fn seek(&mut self, pos: SeekFrom) -> io::Result<u64> {
            self.bytes.seek(pos)
        }
    }

    #[test]
    fn a_full_disk_holds_the_bytes_and_writes_them_in_order_once_there_is_room() {
        let mut sink = RetrySink::new(Disk { bytes: Cursor::new(Vec::new()), room: 10 }, 0);
        let stream: Vec<u8> = (0..100u8).collect();
        // 10 fit, the rest of the first write and everything after it is held.
        sink.write_all(&stream[..30]).unwrap();
        sink.write_all(&stream[30..60]).unwrap();
        assert_eq!((sink.get_ref().bytes.get_ref().len(), sink.held_bytes()), (10, 50));
        assert_eq!(sink.stream_position().unwrap(), 60);
        assert!(sink.gauge().full_events() >= 1 && sink.gauge().held_bytes() == 50);
        sink.flush().unwrap();
        // Room again: the held bytes go first, then the new ones, in order.
        sink.inner.room = 1000;
        sink.write_all(&stream[60..]).unwrap();
        sink.flush().unwrap();
        assert_eq!(sink.held_bytes(), 0);
        assert_eq!(sink.get_ref().bytes.get_ref(), &stream);
        assert_eq!(sink.stream_position().unwrap(), 100);
    }

    /// A recorder on a disk that is always full (/dev/full): nothing panics, every message is
    /// refused and counted, memory stays at the header, and finishing says why it failed.
    #[test]
    fn a_recorder_on_a_full_disk_counts_what_it_drops_and_says_so_at_the_end() {
        use crate::record::{Recorder, RecorderOptions};
        use starc_time::{Clock, Stamp};
        let mut rec = Recorder::create("/dev/full".as_ref(), RecorderOptions::default()).unwrap();
        for i in 0..500u64 {
            rec.imu(Stamp::new(1_000_000_000 + i * 5_000_000, Clock::Ptp), [0.0; 3], [0.0, 0.0, 9.81]).unwrap();
        }
        let stats = rec.stats();
        assert_eq!((stats.messages, stats.dropped_disk_full), (0, 500), "{stats:?}");
        assert!(stats.disk_full_events >= 500, "{stats:?}");
        let e = rec.finish().unwrap_err();
        assert!(e.to_string().contains("disk is full"), "{e}");
    }

    #[test]
    fn other_errors_are_not_held() {
        struct Broken;
        impl Write for Broken {
            fn write(&mut self, _: &[u8]) -> io::Result<usize> {
                Err(io::ErrorKind::PermissionDenied.into())
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        let mut sink = RetrySink::new(Broken, 0);
        assert!(sink.write(b"x").is_err());
        assert_eq!(sink.held_bytes(), 0);
    }
}
