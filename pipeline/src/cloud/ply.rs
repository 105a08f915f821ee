//! PLY files (Stanford polygon format): `ascii`, `binary_little_endian` and, for reading,
//! `binary_big_endian`.
//!
//! Points come from the `vertex` element: `x y z` are required (any scalar type, usually float or
//! double); `intensity` (also `scalar_intensity` as CloudCompare writes it, or `reflectivity`),
//! `offset_time` (ns), `line` (or `ring`) and `tag` are read when present; other properties,
//! list properties included, are skipped, and so are elements before `vertex`. Elements after it
//! (faces) are not read. The start time travels in a `comment starc start_ns <ns> clock <name>`.

use super::{capped_capacity, parse_start_comment, split_line, start_comment, CloudPoint, PointCloud, Scalar, Target};
use crate::PipelineError;
use starc_time::Stamp;
use std::io::Write as _;

const FORMAT: &str = "PLY";

/// Encodings this writer produces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Ascii,
    BinaryLittleEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Body {
    Ascii,
    Binary { big_endian: bool },
}

#[derive(Clone, Copy, Debug)]
enum Prop {
    Scalar { scalar: Scalar, target: Option<Target> },
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Prop>,
}

impl Element {
    fn is_vertex(&self) -> bool {
        self.name == "vertex"
    }

    /// The fewest bytes a binary row can take (lists may be empty).
    fn min_row_size(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p {
                Prop::Scalar { scalar, .. } => scalar.size(),
                Prop::List { count, .. } => count.size(),
            })
            .sum()
    }

    fn fixed_row_size(&self) -> Option<usize> {
        self.props.iter().all(|p| matches!(p, Prop::Scalar { .. })).then(|| self.min_row_size())
    }
}

fn bad_header(line: usize, reason: impl Into<String>) -> PipelineError {
    PipelineError::BadHeader { format: FORMAT, line, reason: reason.into() }
}

fn scalar_of(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

struct Header<'a> {
    body: Body,
    elements: Vec<Element>,
    start: Option<Stamp>,
    data: &'a [u8],
}

fn parse_header(bytes: &[u8]) -> Result<Header<'_>, PipelineError> {
    let (first, mut rest) = split_line(bytes);
    if first != b"ply" {
        return Err(bad_header(1, "the file does not start with \"ply\""));
    }
    let mut line_no = 1usize;
    let mut body = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut start = None;
    loop {
        if rest.is_empty() {
            return Err(bad_header(line_no, "the header ends without end_header"));
        }
        let (line, after) = split_line(rest);
        rest = after;
        line_no += 1;
        let text = std::str::from_utf8(line).map_err(|_| bad_header(line_no, "not text"))?;
        let mut words = text.split_whitespace();
        let Some(key) = words.next() else { continue };
        match key {
            "end_header" => break,
            "comment" => {
                let after_key = text.trim_start().get(key.len()..).unwrap_or_default();
                start = parse_start_comment(after_key.trim()).or(start);
            }
            "obj_info" => {}
            "format" => {
                body = Some(match words.next() {
                    Some("ascii") => Body::Ascii,
                    Some("binary_little_endian") => Body::Binary { big_endian: false },
                    Some("binary_big_endian") => Body::Binary { big_endian: true },
                    other => return Err(bad_header(line_no, format!("unknown format {other:?}"))),
                });
            }
            "element" => {
                let (Some(name), Some(count)) = (words.next(), words.next()) else {
                    return Err(bad_header(line_no, "element needs a name and a count"));
                };
                let count =
                    count.parse::<u64>().map_err(|_| bad_header(line_no, format!("bad element count {count:?}")))?;
                elements.push(Element { name: name.to_owned(), count, props: Vec::new() });
            }
            "property" => {
                let element = elements.last_mut().ok_or_else(|| bad_header(line_no, "property before any element"))?;
                let words: Vec<&str> = words.collect();
                let prop = match words.as_slice() {
                    ["list", count, item, _name] => {
                        let count = scalar_of(count)
                            .filter(|s| !matches!(s, Scalar::F32 | Scalar::F64))
                            .ok_or_else(|| bad_header(line_no, format!("bad list count type {count:?}")))?;
                        let item = scalar_of(item).ok_or_else(|| bad_header(line_no, format!("bad type {item:?}")))?;
                        Prop::List { count, item }
                    }
                    [ty, name] => {
                        let scalar = scalar_of(ty).ok_or_else(|| bad_header(line_no, format!("bad type {ty:?}")))?;
                        let target = if element.is_vertex() { Target::from_name(name) } else { None };
                        Prop::Scalar { scalar, target }
                    }
                    _ => return Err(bad_header(line_no, format!("bad property line {text:?}"))),
                };
                element.props.push(prop);
            }
            _ => return Err(bad_header(line_no, format!("unknown keyword {key:?}"))),
        }
    }
    let body = body.ok_or_else(|| bad_header(line_no, "no format line"))?;
    Ok(Header { body, elements, start, data: rest })
}

/// Reads a PLY file from bytes.
pub fn read_bytes(bytes: &[u8]) -> Result<PointCloud, PipelineError> {
    let Header { body, elements, start, data } = parse_header(bytes)?;
    let vertex_at = elements
        .iter()
        .position(Element::is_vertex)
        .ok_or(PipelineError::MissingField { format: FORMAT, field: "vertex element" })?;
    let vertex =
        elements.get(vertex_at).ok_or(PipelineError::MissingField { format: FORMAT, field: "vertex element" })?;
    for (target, field) in [(Target::X, "x"), (Target::Y, "y"), (Target::Z, "z")] {
        if !vertex.props.iter().any(|p| matches!(p, Prop::Scalar { target: Some(t), .. } if *t == target)) {
            return Err(PipelineError::MissingField { format: FORMAT, field });
        }
    }
    let before = elements.get(..vertex_at).unwrap_or_default();
    let points = match body {
        Body::Binary { big_endian } => {
            let mut r = BinaryReader { data, pos: 0, big_endian };
            for e in before {
                r.skip_element(e)?;
            }
            r.read_vertices(vertex)?
        }
        Body::Ascii => {
            let mut r = AsciiReader { tokens: tokens(data), index: 0 };
            for e in before {
                r.skip_element(e)?;
            }
            let capacity = capped_capacity(vertex.count, data.len(), 2 * vertex.props.len());
            r.read_vertices(vertex, capacity)?
        }
    };
    Ok(PointCloud { start, points })
}

struct BinaryReader<'a> {
    data: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl BinaryReader<'_> {
    fn truncated(&self, what: &'static str, need: usize) -> PipelineError {
        PipelineError::Truncated {
            format: FORMAT,
            what,
            need: need as u64,
            have: self.data.len().saturating_sub(self.pos) as u64,
        }
    }

    #[inline]
    fn value(&mut self, s: Scalar, what: &'static str) -> Result<f64, PipelineError> {
        let v =
            self.data.get(self.pos..).and_then(|b| s.read(b, self.big_endian)).ok_or(self.truncated(what, s.size()))?;
        self.pos += s.size();
        Ok(v)
    }

    /// Walks one row; `point` receives the targeted values.
    fn row(
        &mut self,
        props: &[Prop],
        mut point: Option<&mut CloudPoint>,
        what: &'static str,
    ) -> Result<(), PipelineError> {
        for prop in props {
            match *prop {
                Prop::Scalar { scalar, target } => match (target, point.as_deref_mut()) {
                    (Some(t), Some(p)) => {
                        let v = self.value(scalar, what)?;
                        t.set(p, v);
                    }
                    _ => {
                        if self.data.len().saturating_sub(self.pos) < scalar.size() {
                            return Err(self.truncated(what, scalar.size()));
                        }
                        self.pos += scalar.size();
                    }
                },
                Prop::List { count, item } => {
                    let n = self.value(count, what)?;
                    if n < 0.0 {
                        return Err(PipelineError::BadFile { format: FORMAT, reason: format!("list of {n} items") });
                    }
                    let bytes = (n as u64).saturating_mul(item.size() as u64);
                    let left = self.data.len().saturating_sub(self.pos);
                    if bytes > left as u64 {
                        return Err(PipelineError::Truncated { format: FORMAT, what, need: bytes, have: left as u64 });
                    }
                    self.pos += bytes as usize;
                }
            }
        }
        Ok(())
    }

    fn skip_element(&mut self, e: &Element) -> Result<(), PipelineError> {
        if e.props.is_empty() {
            return Ok(());
        }
        if let Some(row) = e.fixed_row_size() {
            let need = e.count.saturating_mul(row as u64);
            let left = self.data.len().saturating_sub(self.pos);
            if need > left as u64 {
                return Err(PipelineError::Truncated {
                    format: FORMAT,
                    what: "element before vertex",
                    need,
                    have: left as u64,
                });
            }
            self.pos += need as usize;
            return Ok(());
        }
        // Every row takes at least one byte, so this loop ends with the data.
        for _ in 0..e.count {
            self.row(&e.props, None, "element before vertex")?;
        }
        Ok(())
    }

    fn read_vertices(&mut self, v: &Element) -> Result<Vec<CloudPoint>, PipelineError> {
        let left = self.data.len().saturating_sub(self.pos);
        let min_row = v.min_row_size();
        if let Some(row) = v.fixed_row_size() {
            let need = v.count.saturating_mul(row as u64);
            if need > left as u64 {
                return Err(PipelineError::Truncated { format: FORMAT, what: "vertex data", need, have: left as u64 });
            }
        }
        let mut out = Vec::with_capacity(capped_capacity(v.count, left, min_row));
        for _ in 0..v.count {
            let mut p = CloudPoint::default();
            self.row(&v.props, Some(&mut p), "vertex data")?;
            out.push(p);
        }
        Ok(out)
    }
}

/// Whitespace-separated tokens of an ascii body.
fn tokens(data: &[u8]) -> impl Iterator<Item = &[u8]> {
    data.split(|b| b.is_ascii_whitespace()).filter(|t| !t.is_empty())
}

struct AsciiReader<I> {
    tokens: I,
    /// Row being read, for messages.
    index: u64,
}

impl<'a, I: Iterator<Item = &'a [u8]>> AsciiReader<I> {
    fn bad(&self, reason: impl Into<String>) -> PipelineError {
        PipelineError::BadPoint { format: FORMAT, index: self.index, reason: reason.into() }
    }

    fn token(&mut self) -> Result<&'a [u8], PipelineError> {
        self.tokens.next().ok_or_else(|| self.bad("the file ends inside the data"))
    }

    fn value(&mut self, s: Scalar) -> Result<f64, PipelineError> {
        let tok = self.token()?;
        std::str::from_utf8(tok)
            .ok()
            .and_then(|t| s.parse(t))
            .ok_or_else(|| self.bad(format!("bad value {:?}", String::from_utf8_lossy(tok))))
    }

    fn row(&mut self, props: &[Prop], mut point: Option<&mut CloudPoint>) -> Result<(), PipelineError> {
        for prop in props {
            match *prop {
                Prop::Scalar { scalar, target } => match (target, point.as_deref_mut()) {
                    (Some(t), Some(p)) => {
                        let v = self.value(scalar)?;
                        t.set(p, v);
                    }
                    _ => {
                        self.token()?;
                    }
                },
                Prop::List { count, .. } => {
                    let n = self.value(count)?;
                    if n < 0.0 {
                        return Err(self.bad(format!("list of {n} items")));
                    }
                    // Each item is a token, so this loop ends with the data.
                    for _ in 0..n as u64 {
                        self.token()?;
                    }
                }
            }
        }
        Ok(())
    }

    fn skip_element(&mut self, e: &Element) -> Result<(), PipelineError> {
        if e.props.is_empty() {
            return Ok(());
        }
        for i in 0..e.count {
            self.index = i;
            self.row(&e.props, None)?;
        }
        Ok(())
    }

    fn read_vertices(&mut self, v: &Element, capacity: usize) -> Result<Vec<CloudPoint>, PipelineError> {
        let mut out = Vec::with_capacity(capacity);
        for i in 0..v.count {
            self.index = i;
            let mut p = CloudPoint::default();
            self.row(&v.props, Some(&mut p))?;
            out.push(p);
        }
        Ok(out)
    }
}

/// Encodes a cloud as one `vertex` element: `x y z intensity` (float), `offset_time` (uint, ns),
/// `line`, `tag` (uchar).
pub fn encode(cloud: &PointCloud, encoding: Encoding, out: &mut Vec<u8>) {
    let n = cloud.points.len();
    let format = match encoding {
        Encoding::Ascii => "ascii",
        Encoding::BinaryLittleEndian => "binary_little_endian",
    };
    let _ = writeln!(out, "ply\nformat {format} 1.0\ncomment written by STARC");
    if let Some(start) = cloud.start {
        let _ = writeln!(out, "comment {}", start_comment(start));
    }
    let _ = write!(
        out,
        "element vertex {n}\nproperty float x\nproperty float y\nproperty float z\nproperty float intensity\n\
         property uint offset_time\nproperty uchar line\nproperty uchar tag\nend_header\n"
    );
    match encoding {
        Encoding::BinaryLittleEndian => {
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

    #[test]
    fn both_encodings_round_trip_exactly() {
        let cloud = sample_cloud();
        for enc in [Encoding::BinaryLittleEndian, Encoding::Ascii] {
            let mut bytes = Vec::new();
            encode(&cloud, enc, &mut bytes);
            assert_eq!(read_bytes(&bytes).unwrap(), cloud, "{enc:?}");
        }
    }

    #[test]
    fn doubles_lists_and_elements_before_vertex_are_handled() {
        let mut b = b"ply\r\nformat binary_big_endian 1.0\r\ncomment hello\r\nelement camera 1\r\n\
            property list uchar int ids\r\nproperty float f\r\nelement vertex 2\r\nproperty double x\r\n\
            property double y\r\nproperty list ushort float normals\r\nproperty double z\r\n\
            property ushort scalar_Intensity\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\n\
            end_header\r\n"
            .to_vec();
        b.extend_from_slice(&[2, 0, 0, 0, 1, 0, 0, 0, 2]);
        b.extend_from_slice(&1.5f32.to_be_bytes());
        for (x, y, z, i, normals) in [(1.0f64, -2.0f64, 3.25f64, 40u16, 0u16), (1e-3, 7.0, -8.0, 65535, 2)] {
            b.extend_from_slice(&x.to_be_bytes());
            b.extend_from_slice(&y.to_be_bytes());
            b.extend_from_slice(&normals.to_be_bytes());
            for _ in 0..normals {
                b.extend_from_slice(&0.5f32.to_be_bytes());
            }
            b.extend_from_slice(&z.to_be_bytes());
            b.extend_from_slice(&i.to_be_bytes());
        }
        b.extend_from_slice(&[3, 0, 0, 0, 0]); // a truncated face: never read
        let c = read_bytes(&b).unwrap();
        assert_eq!(c.start, None);
        assert_eq!(
            c.points,
            vec![
                CloudPoint { intensity: 40.0, ..CloudPoint::xyz(1.0, -2.0, 3.25) },
                CloudPoint { intensity: 65535.0, ..CloudPoint::xyz(1e-3, 7.0, -8.0) },
            ]
        );
    }

    #[test]
    fn ascii_with_lists() {
        let b = b"ply\nformat ascii 1.0\nelement junk 2\nproperty list uchar float v\nelement vertex 2\n\
            property float x\nproperty list int int n\nproperty float y\nproperty float z\nend_header\n\
            3 1 2 3\n0\n1 2 7 8 2 2\n-1 0 -2 -3\n"
            .to_vec();
        let c = read_bytes(&b).unwrap();
        assert_eq!(c.points, vec![CloudPoint::xyz(1.0, 2.0, 2.0), CloudPoint::xyz(-1.0, -2.0, -3.0)]);
    }

    #[test]
    fn bad_files_are_typed_errors() {
        let head = "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
            property float z\nend_header\n";
        let mut ok = head.as_bytes().to_vec();
        ok.extend_from_slice(&[0; 24]);
        assert_eq!(read_bytes(&ok).unwrap().len(), 2);
        assert!(matches!(read_bytes(&ok[..ok.len() - 1]), Err(PipelineError::Truncated { .. })));
        let huge = head.replace("vertex 2", "vertex 18446744073709551615");
        assert!(matches!(read_bytes(huge.as_bytes()), Err(PipelineError::Truncated { .. })));
        let huge = head.replace("vertex 2", "vertex 4000000000").replace("binary_little_endian", "ascii");
        assert!(matches!(read_bytes(huge.as_bytes()), Err(PipelineError::BadPoint { .. })));
        let no_z = head.replace("property float z\n", "");
        assert!(matches!(read_bytes(no_z.as_bytes()), Err(PipelineError::MissingField { field: "z", .. })));
        let no_vertex = head.replace("vertex", "face");
        assert!(matches!(read_bytes(no_vertex.as_bytes()), Err(PipelineError::MissingField { .. })));
        // A list with a huge count before the vertices.
        let mut list = b"ply\nformat binary_little_endian 1.0\nelement e 3\nproperty list uint int a\n\
            element vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
            .to_vec();
        list.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(read_bytes(&list), Err(PipelineError::Truncated { .. })));
        // Many rows of an element without properties take no time and no memory.
        let empty_rows = head.replace("element vertex", "element nothing 18446744073709551615\nelement vertex");
        assert_eq!(read_bytes(format!("{empty_rows}{}", "\0".repeat(24)).as_bytes()).unwrap().len(), 2);
        for b in [
            "".to_owned(),
            "plx\n".to_owned(),
            "ply\nformat binary_little_endian 1.0\n".to_owned(),
            head.replace("format binary_little_endian 1.0\n", ""),
            head.replace("binary_little_endian", "binary_middle_endian"),
            head.replace("float y", "quad y"),
            head.replace("property float y", "property float"),
            head.replace("element vertex 2", "element vertex -2"),
            head.replace("element vertex 2\n", "property float w\nelement vertex 2\n"),
            head.replace("float x", "list float int x"),
            head.replace("ply\n", "ply\nbogus\n"),
        ] {
            assert!(matches!(read_bytes(b.as_bytes()), Err(PipelineError::BadHeader { .. })), "{b}");
        }
        let ascii = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
            property float z\nend_header\n1 2 x\n";
        assert!(matches!(read_bytes(ascii.as_bytes()), Err(PipelineError::BadPoint { index: 0, .. })));
    }
}
