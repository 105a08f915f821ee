//! PCD v0.7 files (the Point Cloud Library's format): `ascii`, `binary` and, for reading,
//! `binary_compressed` (LZF, fields stored one after the other).
//!
//! Fields `x y z` are required; `intensity` (or `reflectivity`), `offset_time` (u32 ns),
//! `line` (or `ring`) and `tag` are read when present; any other field is skipped. Known fields
//! must have COUNT 1 and may have any TYPE/SIZE. The start time travels in a comment line
//! `# starc start_ns <ns> clock <name>`, which other PCD readers ignore.

use super::{capped_capacity, parse_start_comment, split_line, start_comment, CloudPoint, PointCloud, Scalar, Target};
use crate::PipelineError;
use starc_time::Stamp;
use std::io::Write as _;

const FORMAT: &str = "PCD";
/// LZF turns at most 3 input bytes into 264 output bytes; a larger claimed ratio is a lie.
const LZF_MAX_RATIO: u64 = 88;

/// Encodings this writer produces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Ascii,
    Binary,
}

/// The DATA line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Data {
    Ascii,
    Binary,
    BinaryCompressed,
}

/// A field the reader stores: where it is and how to read it.
#[derive(Clone, Copy, Debug)]
struct Known {
    target: Target,
    scalar: Scalar,
    /// Byte offset inside a point record (binary) or token index (ascii).
    offset: usize,
}

struct Header {
    known: Vec<Known>,
    /// Bytes of one point (binary) or values per line (ascii).
    point_size: usize,
    tokens_per_point: usize,
    points: u64,
    data: Data,
    start: Option<Stamp>,
}

fn bad_header(line: usize, reason: impl Into<String>) -> PipelineError {
    PipelineError::BadHeader { format: FORMAT, line, reason: reason.into() }
}

fn bad_file(reason: impl Into<String>) -> PipelineError {
    PipelineError::BadFile { format: FORMAT, reason: reason.into() }
}

fn parse_words<T: std::str::FromStr>(
    words: std::str::SplitWhitespace<'_>,
    line: usize,
    key: &str,
) -> Result<Vec<T>, PipelineError> {
    words.map(|w| w.parse::<T>().map_err(|_| bad_header(line, format!("{key}: bad value {w:?}")))).collect()
}

fn parse_one<T: std::str::FromStr>(
    mut words: std::str::SplitWhitespace<'_>,
    line: usize,
    key: &str,
) -> Result<T, PipelineError> {
    let w = words.next().ok_or_else(|| bad_header(line, format!("{key} has no value")))?;
    w.parse::<T>().map_err(|_| bad_header(line, format!("{key}: bad value {w:?}")))
}

fn scalar_of(ty: &str, size: usize) -> Option<Scalar> {
    Some(match (ty, size) {
        ("F", 4) => Scalar::F32,
        ("F", 8) => Scalar::F64,
        ("I", 1) => Scalar::I8,
        ("I", 2) => Scalar::I16,
        ("I", 4) => Scalar::I32,
        ("I", 8) => Scalar::I64,
        ("U", 1) => Scalar::U8,
        ("U", 2) => Scalar::U16,
        ("U", 4) => Scalar::U32,
        ("U", 8) => Scalar::U64,
        _ => return None,
    })
}

/// Parses the header; returns it and the data section.
fn parse_header(bytes: &[u8]) -> Result<(Header, &[u8]), PipelineError> {
    let mut rest = bytes;
    let mut line_no = 0usize;
    let (mut names, mut sizes, mut types, mut counts) = (None::<Vec<String>>, None::<Vec<usize>>, None, None);
    let (mut width, mut height, mut points) = (None::<u64>, None::<u64>, None::<u64>);
    let mut start = None;
    let data = loop {
        if rest.is_empty() {
            return Err(bad_header(line_no, "the header ends without a DATA line"));
        }
        let (line, after) = split_line(rest);
        rest = after;
        line_no += 1;
        let text = std::str::from_utf8(line).map_err(|_| bad_header(line_no, "not text"))?.trim();
        if let Some(comment) = text.strip_prefix('#') {
            start = parse_start_comment(comment.trim()).or(start);
            continue;
        }
        let mut words = text.split_whitespace();
        let Some(key) = words.next() else { continue };
        match key.to_ascii_uppercase().as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => names = Some(words.map(str::to_owned).collect()),
            "SIZE" => sizes = Some(parse_words(words, line_no, "SIZE")?),
            "TYPE" => types = Some(words.map(str::to_ascii_uppercase).collect::<Vec<_>>()),
            "COUNT" => counts = Some(parse_words(words, line_no, "COUNT")?),
            "WIDTH" => width = Some(parse_one(words, line_no, "WIDTH")?),
            "HEIGHT" => height = Some(parse_one(words, line_no, "HEIGHT")?),
            "POINTS" => points = Some(parse_one(words, line_no, "POINTS")?),
            "DATA" => {
                let kind = words.next().unwrap_or_default();
                break match kind.to_ascii_lowercase().as_str() {
                    "ascii" => Data::Ascii,
                    "binary" => Data::Binary,
                    "binary_compressed" => Data::BinaryCompressed,
                    _ => return Err(bad_header(line_no, format!("unknown DATA encoding {kind:?}"))),
                };
            }
            _ => return Err(bad_header(line_no, format!("unknown keyword {key:?}"))),
        }
    };
    let names = names.ok_or_else(|| bad_header(line_no, "no FIELDS line"))?;
    let sizes = sizes.ok_or_else(|| bad_header(line_no, "no SIZE line"))?;
    let types = types.ok_or_else(|| bad_header(line_no, "no TYPE line"))?;
    let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
    if names.is_empty() || sizes.len() != names.len() || types.len() != names.len() || counts.len() != names.len() {
        return Err(bad_header(
            line_no,
            format!(
                "FIELDS, SIZE, TYPE and COUNT disagree ({}, {}, {}, {} entries)",
                names.len(),
                sizes.len(),
                types.len(),
                counts.len()
            ),
        ));
    }
    let points = match (points, width, height) {
        (Some(p), Some(w), Some(h)) if w.checked_mul(h) != Some(p) => {
            return Err(bad_header(line_no, format!("POINTS {p} is not WIDTH {w} x HEIGHT {h}")))
        }
        (Some(p), _, _) => p,
        (None, Some(w), h) => {
            w.checked_mul(h.unwrap_or(1)).ok_or_else(|| bad_header(line_no, "WIDTH x HEIGHT overflows"))?
        }
        (None, None, _) => return Err(bad_header(line_no, "neither POINTS nor WIDTH")),
    };
    let mut known = Vec::new();
    let (mut offset, mut tokens) = (0usize, 0usize);
    for (((name, &size), ty), &count) in names.iter().zip(&sizes).zip(&types).zip(&counts) {
        let scalar =
            scalar_of(ty, size).ok_or_else(|| bad_header(line_no, format!("field {name}: TYPE {ty} SIZE {size}")))?;
        if count == 0 {
            return Err(bad_header(line_no, format!("field {name} has COUNT 0")));
        }
        if let Some(target) = Target::from_name(name) {
            if count != 1 {
                return Err(PipelineError::Unsupported {
                    format: FORMAT,
                    what: format!("field {name} with COUNT {count}"),
                });
            }
            let at = if data == Data::Ascii { tokens } else { offset };
            known.push(Known { target, scalar, offset: at });
        }
        let width = size.checked_mul(count).ok_or_else(|| bad_header(line_no, "field size overflows"))?;
        offset = offset.checked_add(width).ok_or_else(|| bad_header(line_no, "point size overflows"))?;
        tokens = tokens.checked_add(count).ok_or_else(|| bad_header(line_no, "COUNT overflows"))?;
    }
    for (target, field) in [(Target::X, "x"), (Target::Y, "y"), (Target::Z, "z")] {
        if !known.iter().any(|k| k.target == target) {
            return Err(PipelineError::MissingField { format: FORMAT, field });
        }
    }
    Ok((Header { known, point_size: offset, tokens_per_point: tokens, points, data, start }, rest))
}

/// Reads a PCD file from bytes.
pub fn read_bytes(bytes: &[u8]) -> Result<PointCloud, PipelineError> {
    let (header, body) = parse_header(bytes)?;
    let points = match header.data {
        Data::Ascii => read_ascii(&header, body)?,
        Data::Binary => {
            let need = header.points.saturating_mul(header.point_size as u64);
            if need > body.len() as u64 {
                return Err(PipelineError::Truncated {
                    format: FORMAT,
                    what: "binary data",
                    need,
                    have: body.len() as u64,
                });
            }
            // need <= body.len(), so the count fits in usize.
            let n = header.points as usize;
            let fields: Vec<(Known, usize)> = header.known.iter().map(|k| (*k, header.point_size)).collect();
            read_fixed(body, n, &fields)?
        }
        Data::BinaryCompressed => read_compressed(&header, body)?,
    };
    Ok(PointCloud { start: header.start, points })
}

/// Reads `n` points from fixed-layout data; value `i` of field `k` is at `k.offset + i * stride`.
fn read_fixed(data: &[u8], n: usize, fields: &[(Known, usize)]) -> Result<Vec<CloudPoint>, PipelineError> {
    let mut out = Vec::with_capacity(n.min(data.len()));
    for i in 0..n {
        let mut p = CloudPoint::default();
        for (k, stride) in fields {
            let v = i
                .checked_mul(*stride)
                .and_then(|o| o.checked_add(k.offset))
                .and_then(|o| data.get(o..))
                .and_then(|b| k.scalar.read(b, false))
                .ok_or(PipelineError::Truncated {
                    format: FORMAT,
                    what: "binary data",
                    need: (i as u64 + 1).saturating_mul(*stride as u64),
                    have: data.len() as u64,
                })?;
            k.target.set(&mut p, v);
        }
        out.push(p);
    }
    Ok(out)
}

fn read_compressed(header: &Header, body: &[u8]) -> Result<Vec<CloudPoint>, PipelineError> {
    if header.points == 0 {
        return Ok(Vec::new());
    }
    let word = |i: usize| body.get(i..i + 4).and_then(|b| b.try_into().ok()).map(u32::from_le_bytes);
    let (Some(compressed), Some(raw)) = (word(0), word(4)) else {
        return Err(PipelineError::Truncated {
            format: FORMAT,
            what: "binary_compressed sizes",
            need: 8,
            have: body.len() as u64,
        });
    };
    let data = body.get(8..).unwrap_or_default();
    let input = data.get(..compressed as usize).ok_or(PipelineError::Truncated {
        format: FORMAT,
        what: "binary_compressed data",
        need: u64::from(compressed),
        have: data.len() as u64,
    })?;
    let expected = header.points.saturating_mul(header.point_size as u64);
    if u64::from(raw) != expected {
        return Err(bad_file(format!(
            "binary_compressed holds {raw} bytes, {} points of {} bytes need {expected}",
            header.points, header.point_size
        )));
    }
    if expected > u64::from(compressed).saturating_mul(LZF_MAX_RATIO) {
        return Err(bad_file(format!("{compressed} compressed bytes cannot expand to {expected}")));
    }
    // expected <= 88 * compressed <= 88 * file size: a bounded allocation.
    let mut plain = Vec::with_capacity(expected as usize);
    lzf_decompress(input, &mut plain, expected as usize).map_err(|e| bad_file(format!("binary_compressed: {e}")))?;
    // Fields lie one after the other: field k's block starts at points * (its offset in a point).
    // Known fields have COUNT 1, so a value's stride is its scalar size.
    let n = header.points as usize;
    let fields: Vec<(Known, usize)> =
        header.known.iter().map(|k| (Known { offset: k.offset.saturating_mul(n), ..*k }, k.scalar.size())).collect();
    read_fixed(&plain, n, &fields)
}

/// LZF (liblzf) decompression into `out`, which must end exactly `expected` bytes long.
fn lzf_decompress(input: &[u8], out: &mut Vec<u8>, expected: usize) -> Result<(), &'static str> {
    const PAST_END: &str = "compressed data ends inside an instruction";
    let mut i = 0usize;
    while let Some(&ctrl) = input.get(i) {
        i += 1;
        let ctrl = usize::from(ctrl);
        if ctrl < 32 {
            let len = ctrl + 1;
            let literal = input.get(i..i + len).ok_or(PAST_END)?;
            if out.len() + len > expected {
                return Err("data longer than declared");
            }
            out.extend_from_slice(literal);
            i += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(*input.get(i).ok_or(PAST_END)?);
                i += 1;
            }
            len += 2;
            let back = ((ctrl & 0x1f) << 8) + usize::from(*input.get(i).ok_or(PAST_END)?) + 1;
            i += 1;
            if back > out.len() {
                return Err("back reference before the start");
            }
            if out.len() + len > expected {
                return Err("data longer than declared");
            }
            let from = out.len() - back;
            if back >= len {
                out.extend_from_within(from..from + len);
            } else {
                // Overlapping copy: repeats the last `back` bytes.
                for k in from..from + len {
                    let b = out.get(k).copied().ok_or("back reference past the end")?;
                    out.push(b);
                }
            }
        }
    }
    if out.len() != expected {
        return Err("data shorter than declared");
    }
    Ok(())
}

fn read_ascii(header: &Header, body: &[u8]) -> Result<Vec<CloudPoint>, PipelineError> {
    let tokens_per_point = header.tokens_per_point;
    let mut out = Vec::with_capacity(capped_capacity(header.points, body.len(), tokens_per_point));
    let mut rest = body;
    let mut tokens: Vec<&str> = Vec::with_capacity(tokens_per_point.min(64));
    let mut index = 0u64;
    while index < header.points {
        if rest.is_empty() {
            return Err(PipelineError::BadPoint {
                format: FORMAT,
                index,
                reason: format!("the file ends; the header promised {} points", header.points),
            });
        }
        let (line, after) = split_line(rest);
        rest = after;
        let bad = |reason: String| PipelineError::BadPoint { format: FORMAT, index, reason };
        let text = std::str::from_utf8(line).map_err(|_| bad("not text".into()))?;
        tokens.clear();
        tokens.extend(text.split_whitespace());
        if tokens.is_empty() {
            continue;
        }
        if tokens.len() < tokens_per_point {
            return Err(bad(format!("{} values, expected {tokens_per_point}", tokens.len())));
        }
        let mut p = CloudPoint::default();
        for k in &header.known {
            let tok = tokens.get(k.offset).copied().unwrap_or_default();
            let v = k.scalar.parse(tok).ok_or_else(|| bad(format!("bad value {tok:?}")))?;
            k.target.set(&mut p, v);
        }
        out.push(p);
        index += 1;
    }
    Ok(out)
}

/// Encodes a cloud with fields `x y z intensity` (f32), `offset_time` (u32 ns), `line`, `tag` (u8).
pub fn encode(cloud: &PointCloud, encoding: Encoding, out: &mut Vec<u8>) {
    let n = cloud.points.len();
    out.extend_from_slice(b"# .PCD v0.7 - Point Cloud Data file format\n");
    if let Some(start) = cloud.start {
        let _ = writeln!(out, "# {}", start_comment(start));
    }
    let _ = write!(
        out,
        "VERSION 0.7\nFIELDS x y z intensity offset_time line tag\nSIZE 4 4 4 4 4 1 1\nTYPE F F F F U U U\n\
         COUNT 1 1 1 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {}\n",
        match encoding {
            Encoding::Ascii => "ascii",
            Encoding::Binary => "binary",
        }
    );
    match encoding {
        Encoding::Binary => {
            super::write_binary_records(cloud, out);
        }
        Encoding::Ascii => super::write_ascii_records(cloud, out),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::cloud::tests::sample_cloud;

    fn header(fields: &str, size: &str, ty: &str, count: &str, points: usize, data: &str) -> Vec<u8> {
        format!(
            "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\n\
             COUNT {count}\nWIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA {data}\n"
        )
        .into_bytes()
    }

    /// Valid LZF made of literal runs only.
    fn lzf_literals(data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        for chunk in data.chunks(32) {
            out.push(chunk.len() as u8 - 1);
            out.extend_from_slice(chunk);
        }
        out
    }

    #[test]
    fn both_encodings_round_trip_exactly() {
        let cloud = sample_cloud();
        for enc in [Encoding::Binary, Encoding::Ascii] {
            let mut bytes = Vec::new();
            encode(&cloud, enc, &mut bytes);
            assert_eq!(read_bytes(&bytes).unwrap(), cloud, "{enc:?}");
        }
        let mut empty = Vec::new();
        encode(&PointCloud::default(), Encoding::Binary, &mut empty);
        assert_eq!(read_bytes(&empty).unwrap(), PointCloud::default());
    }

    #[test]
    fn ascii_with_foreign_fields_and_types() {
        let mut b = header(
            "normal_x rgb x y z hist intensity ring",
            "4 4 8 8 8 4 2 2",
            "F U F F F F U U",
            "1 1 1 1 1 3 1 1",
            2,
            "ascii",
        );
        b.extend_from_slice(b"0.5 4278190080 1.5 -2.25 3 0.1 0.2 0.3 17 4\r\n\n  nan 0 4 5 6 0 0 0 65535 300\n");
        let c = read_bytes(&b).unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!(c.points[0], CloudPoint { intensity: 17.0, line: 4, ..CloudPoint::xyz(1.5, -2.25, 3.0) });
        // Integer fields saturate.
        assert_eq!(c.points[1], CloudPoint { intensity: 65535.0, line: 255, ..CloudPoint::xyz(4.0, 5.0, 6.0) });
    }

    #[test]
    fn binary_skips_unknown_fields_and_reads_any_type() {
        // x i16 (mm would need scaling: the reader takes values as they are), y f64, z u8, pad 3 x u8.
        let mut b = header("x pad y z tag", "2 1 8 1 4", "I U F U U", "1 3 1 1 1", 2, "binary");
        for (x, y, z, tag) in [(-7i16, 2.5f64, 9u8, 0x10u32), (300, -1e300, 255, 1000)] {
            b.extend_from_slice(&x.to_le_bytes());
            b.extend_from_slice(&[0xAA; 3]);
            b.extend_from_slice(&y.to_le_bytes());
            b.push(z);
            b.extend_from_slice(&tag.to_le_bytes());
        }
        b.extend_from_slice(b"trailing bytes are ignored");
        let c = read_bytes(&b).unwrap();
        assert_eq!(c.points[0], CloudPoint { tag: 0x10, ..CloudPoint::xyz(-7.0, 2.5, 9.0) });
        assert_eq!(c.points[1], CloudPoint { tag: 255, ..CloudPoint::xyz(300.0, f32::NEG_INFINITY, 255.0) });
    }

    #[test]
    fn binary_compressed_is_read() {
        let cloud = sample_cloud();
        let n = cloud.len();
        // Field-major layout: all x, all y, all z, all intensity.
        let mut plain = Vec::new();
        for get in
            [|p: &CloudPoint| p.x_m, |p: &CloudPoint| p.y_m, |p: &CloudPoint| p.z_m, |p: &CloudPoint| p.intensity]
        {
            for p in &cloud.points {
                plain.extend_from_slice(&get(p).to_le_bytes());
            }
        }
        let packed = lzf_literals(&plain);
        let mut b = header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", n, "binary_compressed");
        b.extend_from_slice(&(packed.len() as u32).to_le_bytes());
        b.extend_from_slice(&(plain.len() as u32).to_le_bytes());
        b.extend_from_slice(&packed);
        let c = read_bytes(&b).unwrap();
        assert_eq!(c.len(), n);
        for (a, e) in c.points.iter().zip(&cloud.points) {
            assert_eq!((a.x_m, a.y_m, a.z_m, a.intensity), (e.x_m, e.y_m, e.z_m, e.intensity));
        }
    }

    #[test]
    fn lzf_back_references() {
        // "abc" then a back reference of length 9 (ctrl len 7 -> +2) at distance 3: overlapping.
        let input = [2, b'a', b'b', b'c', (7 << 5) as u8, 0, 2];
        let mut out = Vec::new();
        lzf_decompress(&input, &mut out, 3 + 9).unwrap();
        assert_eq!(out, b"abcabcabcabc");
        // Long form: len 7 + extra 1 + 2 = 10 at distance 1.
        let mut out = Vec::new();
        lzf_decompress(&[0, b'z', 7 << 5, 1, 0], &mut out, 11).unwrap();
        assert_eq!(out, b"zzzzzzzzzzz");
        for (bad, expected) in [(&[0u8, b'z', 1 << 5, 1][..], 4), (&[1, b'z'][..], 2), (&[0, b'z', 7 << 5][..], 10)] {
            assert!(lzf_decompress(bad, &mut Vec::new(), expected).is_err(), "{bad:?}");
        }
        assert!(lzf_decompress(&[2, 1, 2, 3], &mut Vec::new(), 2).is_err());
        assert!(lzf_decompress(&[2, 1, 2, 3], &mut Vec::new(), 4).is_err());
    }

    #[test]
    fn bad_files_are_typed_errors() {
        let ok = header("x y z", "4 4 4", "F F F", "1 1 1", 1, "binary");
        let mut full = ok.clone();
        full.extend_from_slice(&[0; 12]);
        assert!(read_bytes(&full).is_ok());
        // Truncated data, and a huge POINTS that must not allocate.
        assert!(matches!(read_bytes(&full[..full.len() - 1]), Err(PipelineError::Truncated { .. })));
        let huge = header("x y z", "4 4 4", "F F F", "1 1 1", usize::MAX, "binary");
        assert!(matches!(read_bytes(&huge), Err(PipelineError::Truncated { .. })));
        let huge = header("x y z", "4 4 4", "F F F", "1 1 1", 4_000_000_000, "ascii");
        assert!(matches!(read_bytes(&huge), Err(PipelineError::BadPoint { .. })));
        let missing = header("x y intensity", "4 4 4", "F F F", "1 1 1", 0, "binary");
        assert!(matches!(read_bytes(&missing), Err(PipelineError::MissingField { field: "z", .. })));
        for b in [
            header("x y z", "4 4", "F F F", "1 1 1", 0, "binary"),
            header("x y z", "4 4 3", "F F F", "1 1 1", 0, "binary"),
            header("x y z", "4 4 4", "F F Q", "1 1 1", 0, "binary"),
            header("x y z", "4 4 4", "F F F", "1 0 1", 0, "binary"),
            header("x y z", "4 4 4", "F F F", "1 1 1", 0, "lzma"),
            b"VERSION 0.7\nFIELDS x y z\n".to_vec(),
            b"VERSION 0.7\nBOGUS 1\nDATA ascii\n".to_vec(),
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n".to_vec(),
            b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nDATA ascii\n".to_vec(),
            b"\xff\xfe".to_vec(),
            Vec::new(),
        ] {
            assert!(matches!(read_bytes(&b), Err(PipelineError::BadHeader { .. })), "{}", String::from_utf8_lossy(&b));
        }
        let multi = header("x y z", "4 4 4", "F F F", "2 1 1", 0, "binary");
        assert!(matches!(read_bytes(&multi), Err(PipelineError::Unsupported { .. })));
        let mut text = header("x y z", "4 4 4", "F F F", "1 1 1", 1, "ascii");
        text.extend_from_slice(b"1 2\n");
        assert!(matches!(read_bytes(&text), Err(PipelineError::BadPoint { index: 0, .. })));
        let mut text = header("x y z", "4 4 4", "F F F", "1 1 1", 1, "ascii");
        text.extend_from_slice(b"1 2 zz\n");
        assert!(matches!(read_bytes(&text), Err(PipelineError::BadPoint { index: 0, .. })));
        // A compressed body claiming an impossible expansion is refused before allocating.
        let mut bomb = header("x y z", "4 4 4", "F F F", "1 1 1", 300_000_000, "binary_compressed");
        bomb.extend_from_slice(&[4, 0, 0, 0]);
        bomb.extend_from_slice(&3_600_000_000u32.to_le_bytes());
        bomb.extend_from_slice(&[0, 0, 0, 0]);
        assert!(matches!(read_bytes(&bomb), Err(PipelineError::BadFile { .. })));
    }
}
