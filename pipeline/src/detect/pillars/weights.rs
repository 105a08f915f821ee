//! The STPW weights file (docs/pillars.md): named f32 tensors and a CRC-32 over them. Every
//! length is checked before it is used: a cut or altered file is an error, never a panic.

use crate::PipelineError;

const MAGIC: &[u8; 4] = b"STPW";
const VERSION: u32 = 1;
const FORMAT: &str = "STPW weights";
/// Bounds that keep a hostile header from asking for absurd allocations.
const MAX_TENSORS: u32 = 256;
const MAX_RANK: u8 = 4;
const MAX_VALUES: usize = 16 << 20;

static CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// One named tensor, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    pub name: String,
    pub dims: Vec<usize>,
    pub values: Vec<f32>,
}

/// Every tensor of a file, in file order.
#[derive(Clone, Debug, PartialEq)]
pub struct Weights {
    pub tensors: Vec<Tensor>,
}

fn bad(reason: impl Into<String>) -> PipelineError {
    PipelineError::BadFile { format: FORMAT, reason: reason.into() }
}

/// A cursor that refuses to read past the end.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], PipelineError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len()).ok_or(PipelineError::Truncated {
            format: FORMAT,
            what,
            need: n as u64,
            have: (self.bytes.len() - self.at) as u64,
        })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], PipelineError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }

    fn u8(&mut self, what: &'static str) -> Result<u8, PipelineError> {
        Ok(self.array::<1>(what)?[0])
    }

    fn u16(&mut self, what: &'static str) -> Result<u16, PipelineError> {
        Ok(u16::from_le_bytes(self.array(what)?))
    }

    fn u32(&mut self, what: &'static str) -> Result<u32, PipelineError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
}

impl Weights {
    pub fn parse(bytes: &[u8]) -> Result<Self, PipelineError> {
        let Some((body, crc)) = bytes.split_last_chunk::<4>() else {
            return Err(bad("shorter than its CRC"));
        };
        let (stored, computed) = (u32::from_le_bytes(*crc), CRC.checksum(body));
        if stored != computed {
            return Err(bad(format!("CRC {computed:08x}, the file says {stored:08x}")));
        }
        let mut r = Reader { bytes: body, at: 0 };
        if r.take(4, "magic")? != MAGIC {
            return Err(bad("not an STPW file (magic)"));
        }
        let version = r.u32("version")?;
        if version != VERSION {
            return Err(PipelineError::Unsupported { format: FORMAT, what: format!("version {version}") });
        }
        let count = r.u32("tensor count")?;
        if count > MAX_TENSORS {
            return Err(bad(format!("{count} tensors (at most {MAX_TENSORS})")));
        }
        let tensors = (0..count).map(|_| tensor(&mut r)).collect::<Result<Vec<_>, _>>()?;
        if r.at != body.len() {
            return Err(bad(format!("{} bytes after the last tensor", body.len() - r.at)));
        }
        Ok(Self { tensors })
    }

    /// The tensor called `name`.
    pub fn tensor(&self, name: &str) -> Result<&Tensor, PipelineError> {
        self.tensors.iter().find(|t| t.name == name).ok_or_else(|| bad(format!("no tensor {name}")))
    }

    /// The tensor called `name`, which must have the shape `dims`.
    pub fn get(&self, name: &str, dims: &[usize]) -> Result<&[f32], PipelineError> {
        let t = self.tensor(name)?;
        if t.dims != dims {
            return Err(bad(format!("{name} is {:?}, expected {dims:?}", t.dims)));
        }
        Ok(&t.values)
    }
}

fn tensor(r: &mut Reader<'_>) -> Result<Tensor, PipelineError> {
    let name_len = r.u16("name length")?;
    let name = std::str::from_utf8(r.take(usize::from(name_len), "name")?)
        .map_err(|_| bad("a tensor name is not UTF-8"))?
        .to_string();
    let rank = r.u8("rank")?;
    if rank > MAX_RANK {
        return Err(bad(format!("{name}: rank {rank} (at most {MAX_RANK})")));
    }
    let dims = (0..rank).map(|_| r.u32("dimension").map(|d| d as usize)).collect::<Result<Vec<_>, _>>()?;
    let count = dims
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .filter(|&n| n <= MAX_VALUES)
        .ok_or_else(|| bad(format!("{name}: {dims:?} holds more than {MAX_VALUES} values")))?;
    let raw = r.take(count * 4, "tensor values")?;
    let values: Vec<f32> = raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
    if values.iter().any(|v| !v.is_finite()) {
        return Err(bad(format!("{name} holds a value that is not finite")));
    }
    Ok(Tensor { name, dims, values })
}

/// Writes a file (tests, tools): the inverse of [`Weights::parse`].
pub fn encode(tensors: &[Tensor]) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend(VERSION.to_le_bytes());
    out.extend((tensors.len() as u32).to_le_bytes());
    for t in tensors {
        out.extend((t.name.len() as u16).to_le_bytes());
        out.extend(t.name.as_bytes());
        out.push(t.dims.len() as u8);
        for &d in &t.dims {
            out.extend((d as u32).to_le_bytes());
        }
        for v in &t.values {
            out.extend(v.to_le_bytes());
        }
    }
    let crc = CRC.checksum(&out);
    out.extend(crc.to_le_bytes());
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn sample() -> Vec<Tensor> {
        vec![
            Tensor { name: "a.weight".into(), dims: vec![2, 3], values: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0] },
            Tensor { name: "a.bias".into(), dims: vec![2], values: vec![-1.0, 0.5] },
        ]
    }

    #[test]
    fn a_file_reads_back_what_was_written() {
        let w = Weights::parse(&encode(&sample())).unwrap();
        assert_eq!(w.tensors, sample());
        assert_eq!(w.get("a.bias", &[2]).unwrap(), &[-1.0, 0.5]);
        assert!(w.get("a.bias", &[3]).is_err());
        assert!(w.get("b.bias", &[2]).is_err());
    }

    #[test]
    fn every_cut_and_every_flipped_byte_is_an_error() {
        let bytes = encode(&sample());
        for n in 0..bytes.len() {
            assert!(Weights::parse(&bytes[..n]).is_err(), "cut at {n}");
            let mut b = bytes.clone();
            b[n] ^= 0x10;
            assert!(Weights::parse(&b).is_err(), "flipped byte {n}");
        }
    }
}
