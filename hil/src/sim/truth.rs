//! Ground-truth files: per-point labels, people's boxes, and the buffered writer they and the
//! TUM trajectories ([`crate::tum`]) share (so that a failed write names its file).

use crate::error::{HilError, Result};
use crate::sim::lidar::PacketLabels;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Magic of a labels file.
pub const LABELS_MAGIC: &[u8; 8] = b"STARCLBL";
pub const LABELS_VERSION: u32 = 1;

/// A buffered output file that knows its name.
pub struct OutFile {
    path: PathBuf,
    out: BufWriter<File>,
}

impl OutFile {
    pub fn create(path: &Path) -> Result<Self> {
        let file = File::create(path).map_err(|e| out_err(path, e))?;
        Ok(Self { path: path.to_path_buf(), out: BufWriter::new(file) })
    }

    pub fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.out.write_all(bytes).map_err(|e| out_err(&self.path, e))
    }

    pub fn line(&mut self, text: &str) -> Result<()> {
        self.write(text.as_bytes())?;
        self.write(b"\n")
    }

    pub fn finish(mut self) -> Result<()> {
        self.out.flush().map_err(|e| out_err(&self.path, e))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

pub fn out_err(path: &Path, e: impl std::fmt::Display) -> HilError {
    HilError::Output { path: path.to_path_buf(), reason: e.to_string() }
}

/// One packet's record of the labels file (see [`LabelsWriter`]); `None` past 65535 returns.
pub fn labels_record(first_ns: u64, labels: &[u16]) -> Option<Vec<u8>> {
    let n = u16::try_from(labels.len()).ok()?;
    let mut bytes = Vec::with_capacity(10 + labels.len() * 2);
    bytes.extend_from_slice(&first_ns.to_le_bytes());
    bytes.extend_from_slice(&n.to_le_bytes());
    for l in labels {
        bytes.extend_from_slice(&l.to_le_bytes());
    }
    Some(bytes)
}

/// Writes the labels file: `STARCLBL`, u32 version, then per point packet: u64 PTP time of the
/// packet's first firing (as in its header), u16 returns, then that many u16 labels
/// (0 building, k person k, 0xFFFF empty return). Little-endian.
pub struct LabelsWriter {
    file: OutFile,
    ptp_offset_ns: i64,
    packets: u64,
}

impl LabelsWriter {
    pub fn create(path: &Path, ptp_offset_ns: i64) -> Result<Self> {
        let mut file = OutFile::create(path)?;
        file.write(LABELS_MAGIC)?;
        file.write(&LABELS_VERSION.to_le_bytes())?;
        Ok(Self { file, ptp_offset_ns, packets: 0 })
    }

    pub fn write(&mut self, p: &PacketLabels) -> Result<()> {
        let t = p.first_ns.saturating_add_signed(self.ptp_offset_ns);
        let bytes =
            labels_record(t, &p.labels).ok_or_else(|| out_err(self.file.path(), "packet of over 65535 returns"))?;
        self.file.write(&bytes)?;
        self.packets += 1;
        Ok(())
    }

    pub fn packets(&self) -> u64 {
        self.packets
    }

    pub fn finish(self) -> Result<()> {
        self.file.finish()
    }
}

/// Reads a labels file back (tests and evaluation tools): (PTP ns, labels) per packet.
pub fn read_labels(bytes: &[u8]) -> Option<Vec<(u64, Vec<u16>)>> {
    let rest = bytes.strip_prefix(LABELS_MAGIC.as_slice())?;
    let (version, mut rest) = rest.split_first_chunk::<4>()?;
    if u32::from_le_bytes(*version) != LABELS_VERSION {
        return None;
    }
    let mut out = Vec::new();
    while !rest.is_empty() {
        let (t, r) = rest.split_first_chunk::<8>()?;
        let (n, r) = r.split_first_chunk::<2>()?;
        let n = usize::from(u16::from_le_bytes(*n));
        let body = r.get(..n * 2)?;
        let labels = body.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
        out.push((u64::from_le_bytes(*t), labels));
        rest = r.get(n * 2..)?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_round_trip() {
        let dir = std::env::temp_dir().join(format!("starc-labels-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join("l.bin");
        let written = (|| -> Result<()> {
            let mut w = LabelsWriter::create(&path, 1000)?;
            w.write(&PacketLabels { first_ns: 5, labels: vec![0, 1, u16::MAX] })?;
            w.write(&PacketLabels { first_ns: 9, labels: vec![] })?;
            w.finish()
        })();
        assert!(written.is_ok(), "{written:?}");
        let back = std::fs::read(&path).ok().and_then(|b| read_labels(&b));
        assert_eq!(back, Some(vec![(1005, vec![0, 1, u16::MAX]), (1009, vec![])]));
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(read_labels(b"STARCLBL\x01\x00\x00\x00\x01"), None);
    }
}
