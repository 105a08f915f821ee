//! Point clouds and their files: PCD v0.7 ([`pcd`]), PLY ([`ply`]) and KITTI `.bin` ([`kitti`]).
//!
//! A [`PointCloud`] is one scan: points in metres in the sensor frame, each with its firing time
//! as an offset from the cloud's start (so a de-skew stage can use it), its laser line and its
//! Livox tag. Readers take untrusted bytes and return [`PipelineError`]s; they never panic and
//! never allocate more than the file's own size justifies.
//!
//! ```no_run
//! use starc_pipeline::cloud::{self, CloudFormat};
//! # fn main() -> Result<(), starc_pipeline::PipelineError> {
//! let cloud = cloud::read("scan.pcd".as_ref())?;
//! cloud::write("scan.ply".as_ref(), &cloud, CloudFormat::PlyBinary)?;
//! # Ok(()) }
//! ```

pub mod kitti;
pub mod pcd;
pub mod ply;

use crate::PipelineError;
use serde::{Deserialize, Serialize};
use starc_time::{Clock, Stamp};
use std::path::Path;
use std::str::FromStr;

/// One point of a cloud.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CloudPoint {
    pub x_m: f32,
    pub y_m: f32,
    pub z_m: f32,
    /// Intensity or reflectivity as the sensor reports it (Livox: 0-255).
    pub intensity: f32,
    /// Firing time after the cloud's start.
    pub offset_ns: u32,
    /// Laser line (0-5 on the Avia).
    pub line: u8,
    /// Livox tag (return number and noise confidences); 0 where unknown.
    pub tag: u8,
}

impl CloudPoint {
    pub const fn xyz(x_m: f32, y_m: f32, z_m: f32) -> Self {
        Self { x_m, y_m, z_m, intensity: 0.0, offset_ns: 0, line: 0, tag: 0 }
    }

    /// (0, 0, 0) is how Livox files mark a firing without a return.
    pub fn is_zero(&self) -> bool {
        self.x_m == 0.0 && self.y_m == 0.0 && self.z_m == 0.0
    }
}

/// A point cloud, typically one scan of one device.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointCloud {
    /// Time of offset 0, when known. PCD and PLY keep it in a `starc` comment; KITTI loses it.
    pub start: Option<Stamp>,
    pub points: Vec<CloudPoint>,
}

impl PointCloud {
    pub fn new(start: Option<Stamp>, points: Vec<CloudPoint>) -> Self {
        Self { start, points }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Absolute firing time of point `i`, when the start is known.
    pub fn point_time(&self, i: usize) -> Option<Stamp> {
        let p = self.points.get(i)?;
        let start = self.start?;
        Some(Stamp::new(start.ns.saturating_add(u64::from(p.offset_ns)), start.clock))
    }

    /// Axis-aligned bounds `(min, max)` of the finite points, or `None` when there are none.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let mut it = self.points.iter().map(|p| [p.x_m, p.y_m, p.z_m]).filter(|v| v.iter().all(|c| c.is_finite()));
        let first = it.next()?;
        Some(it.fold((first, first), |(mut lo, mut hi), v| {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
            (lo, hi)
        }))
    }
}

/// A file format and encoding to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CloudFormat {
    PcdBinary,
    PcdAscii,
    PlyBinary,
    PlyAscii,
    /// KITTI velodyne `.bin`: x, y, z, intensity as f32, nothing else.
    Kitti,
}

impl CloudFormat {
    pub const ALL: [CloudFormat; 5] = [Self::PcdBinary, Self::PcdAscii, Self::PlyBinary, Self::PlyAscii, Self::Kitti];

    pub fn kind(self) -> FileKind {
        match self {
            Self::PcdBinary | Self::PcdAscii => FileKind::Pcd,
            Self::PlyBinary | Self::PlyAscii => FileKind::Ply,
            Self::Kitti => FileKind::Kitti,
        }
    }

    /// File-name extension, without the dot.
    pub fn extension(self) -> &'static str {
        self.kind().extension()
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::PcdBinary => "pcd",
            Self::PcdAscii => "pcd-ascii",
            Self::PlyBinary => "ply",
            Self::PlyAscii => "ply-ascii",
            Self::Kitti => "kitti",
        }
    }
}

impl std::fmt::Display for CloudFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for CloudFormat {
    type Err = PipelineError;

    /// `pcd` and `ply` are binary; `pcd-ascii`, `ply-ascii`, `kitti` (or `bin`) name the others.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.to_ascii_lowercase();
        match lower.as_str() {
            "bin" => Ok(Self::Kitti),
            "pcd-binary" => Ok(Self::PcdBinary),
            "ply-binary" => Ok(Self::PlyBinary),
            _ => Self::ALL
                .into_iter()
                .find(|f| f.name() == lower)
                .ok_or_else(|| PipelineError::UnknownFormat { path: format!("format name {s:?}") }),
        }
    }
}

/// The file families, each read whatever its encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FileKind {
    Pcd,
    Ply,
    Kitti,
}

impl FileKind {
    pub fn extension(self) -> &'static str {
        match self {
            Self::Pcd => "pcd",
            Self::Ply => "ply",
            Self::Kitti => "bin",
        }
    }

    /// Tells the family from the first bytes (PCD, PLY) or else the file name's extension
    /// (KITTI files have no magic).
    pub fn detect(bytes: &[u8], path: Option<&Path>) -> Option<Self> {
        if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
            return Some(Self::Ply);
        }
        if [&b"# .PCD"[..], b"VERSION", b"FIELDS"].iter().any(|m| bytes.starts_with(m)) {
            return Some(Self::Pcd);
        }
        let ext = path?.extension()?.to_str()?.to_ascii_lowercase();
        [Self::Pcd, Self::Ply, Self::Kitti].into_iter().find(|k| k.extension() == ext)
    }
}

/// Reads a point cloud of the given family from bytes.
pub fn read_bytes(bytes: &[u8], kind: FileKind) -> Result<PointCloud, PipelineError> {
    match kind {
        FileKind::Pcd => pcd::read_bytes(bytes),
        FileKind::Ply => ply::read_bytes(bytes),
        FileKind::Kitti => kitti::read_bytes(bytes),
    }
}

/// Encodes a point cloud.
pub fn to_bytes(cloud: &PointCloud, format: CloudFormat) -> Vec<u8> {
    let mut out = Vec::new();
    match format {
        CloudFormat::PcdBinary => pcd::encode(cloud, pcd::Encoding::Binary, &mut out),
        CloudFormat::PcdAscii => pcd::encode(cloud, pcd::Encoding::Ascii, &mut out),
        CloudFormat::PlyBinary => ply::encode(cloud, ply::Encoding::BinaryLittleEndian, &mut out),
        CloudFormat::PlyAscii => ply::encode(cloud, ply::Encoding::Ascii, &mut out),
        CloudFormat::Kitti => kitti::encode(cloud, &mut out),
    }
    out
}

/// Reads a point-cloud file, telling its format by its first bytes or else its extension.
pub fn read(path: &Path) -> Result<PointCloud, PipelineError> {
    let bytes = std::fs::read(path).map_err(|e| PipelineError::io(format!("reading {}", path.display()), e))?;
    let kind = FileKind::detect(&bytes, Some(path))
        .ok_or_else(|| PipelineError::UnknownFormat { path: path.display().to_string() })?;
    read_bytes(&bytes, kind)
}

/// Writes a point-cloud file (the path is used as given, whatever its extension).
pub fn write(path: &Path, cloud: &PointCloud, format: CloudFormat) -> Result<(), PipelineError> {
    std::fs::write(path, to_bytes(cloud, format))
        .map_err(|e| PipelineError::io(format!("writing {}", path.display()), e))
}

// ---- shared by the PCD and PLY readers -------------------------------------------------------

/// A scalar type of a file field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::I64 | Self::U64 | Self::F64 => 8,
        }
    }

    /// Reads one value at the start of `b`; `None` when `b` is too short.
    #[inline]
    fn read(self, b: &[u8], big_endian: bool) -> Option<f64> {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b.get(..$n)?.try_into().ok()?;
                (if big_endian { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        Some(match self {
            Self::I8 => f64::from(*b.first()? as i8),
            Self::U8 => f64::from(*b.first()?),
            Self::I16 => rd!(i16, 2),
            Self::U16 => rd!(u16, 2),
            Self::I32 => rd!(i32, 4),
            Self::U32 => rd!(u32, 4),
            Self::I64 => rd!(i64, 8),
            Self::U64 => rd!(u64, 8),
            Self::F32 => rd!(f32, 4),
            Self::F64 => rd!(f64, 8),
        })
    }

    /// Parses one ascii value; f32 fields parse as f32 so that written values come back exactly.
    fn parse(self, tok: &str) -> Option<f64> {
        match self {
            Self::F32 => tok.parse::<f32>().ok().map(f64::from),
            Self::F64 => tok.parse::<f64>().ok(),
            Self::I8 | Self::I16 | Self::I32 | Self::I64 => tok.parse::<i64>().ok().map(|v| v as f64),
            Self::U8 | Self::U16 | Self::U32 | Self::U64 => tok.parse::<u64>().ok().map(|v| v as f64),
        }
    }
}

/// Where a file field goes in a [`CloudPoint`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Target {
    X,
    Y,
    Z,
    Intensity,
    OffsetNs,
    Line,
    Tag,
}

impl Target {
    /// Field names understood (case-insensitive); everything else is skipped.
    fn from_name(name: &str) -> Option<Self> {
        let n = name.to_ascii_lowercase();
        Some(match n.as_str() {
            "x" => Self::X,
            "y" => Self::Y,
            "z" => Self::Z,
            // CloudCompare writes scalar fields as `scalar_<name>`.
            "intensity" | "scalar_intensity" | "reflectivity" | "scalar_reflectivity" => Self::Intensity,
            // Name of the Livox ROS driver's CustomPoint field (ns after the frame start).
            "offset_time" => Self::OffsetNs,
            "line" | "ring" => Self::Line,
            "tag" => Self::Tag,
            _ => return None,
        })
    }

    /// Stores a value; integer fields saturate (NaN stores 0).
    #[inline]
    fn set(self, p: &mut CloudPoint, v: f64) {
        match self {
            Self::X => p.x_m = v as f32,
            Self::Y => p.y_m = v as f32,
            Self::Z => p.z_m = v as f32,
            Self::Intensity => p.intensity = v as f32,
            Self::OffsetNs => p.offset_ns = v as u32,
            Self::Line => p.line = v as u8,
            Self::Tag => p.tag = v as u8,
        }
    }
}

/// The `starc` comment holding the start time: `starc start_ns <ns> clock <name>`.
fn start_comment(start: Stamp) -> String {
    format!("starc start_ns {} clock {}", start.ns, start.clock.name())
}

/// Parses the text after the comment marker; `None` when it is not a `starc` comment.
fn parse_start_comment(text: &str) -> Option<Stamp> {
    let mut words = text.split_whitespace();
    if words.next()? != "starc" || words.next()? != "start_ns" {
        return None;
    }
    let ns = words.next()?.parse::<u64>().ok()?;
    if words.next()? != "clock" {
        return None;
    }
    let name = words.next()?;
    let clock =
        [Clock::Device, Clock::Ptp, Clock::Gps, Clock::Pps, Clock::Host].into_iter().find(|c| c.name() == name)?;
    Some(Stamp::new(ns, clock))
}

/// Splits off the first line (without its `\n` and any `\r`), returning it and the rest.
fn split_line(bytes: &[u8]) -> (&[u8], &[u8]) {
    match bytes.iter().position(|&b| b == b'\n') {
        Some(i) => {
            let (line, rest) = bytes.split_at(i);
            (line.strip_suffix(b"\r").unwrap_or(line), rest.get(1..).unwrap_or_default())
        }
        None => (bytes.strip_suffix(b"\r").unwrap_or(bytes), &[]),
    }
}

/// A capacity hint that never trusts a count beyond what `available_bytes` could hold.
fn capped_capacity(count: u64, available_bytes: usize, min_bytes_per_point: usize) -> usize {
    let fit = available_bytes / min_bytes_per_point.max(1);
    usize::try_from(count).unwrap_or(usize::MAX).min(fit)
}

/// The point records both PCD and PLY writers use, binary little-endian: x y z intensity (f32),
/// offset_time (u32), line, tag (u8); 22 bytes a point.
fn write_binary_records(cloud: &PointCloud, out: &mut Vec<u8>) {
    out.reserve(cloud.points.len() * 22);
    for p in &cloud.points {
        for v in [p.x_m, p.y_m, p.z_m, p.intensity] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&p.offset_ns.to_le_bytes());
        out.extend_from_slice(&[p.line, p.tag]);
    }
}

/// The same records as text, one point a line.
fn write_ascii_records(cloud: &PointCloud, out: &mut Vec<u8>) {
    use std::io::Write;
    for p in &cloud.points {
        // `{}` prints the shortest text that parses back to the same f32.
        let _ = writeln!(out, "{} {} {} {} {} {} {}", p.x_m, p.y_m, p.z_m, p.intensity, p.offset_ns, p.line, p.tag);
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
pub(crate) mod tests {
    use super::*;

    /// A cloud exercising every field, with a start time and awkward values.
    pub(crate) fn sample_cloud() -> PointCloud {
        let mut points: Vec<CloudPoint> = (0..500u32)
            .map(|i| {
                let f = i as f32;
                CloudPoint {
                    x_m: f * 0.0137 - 3.3,
                    y_m: (f * 0.1).sin() * 12.5,
                    z_m: -f / 7.0,
                    intensity: (i % 256) as f32,
                    offset_ns: i * 4167,
                    line: (i % 6) as u8,
                    tag: (i % 4) as u8 * 0x10,
                }
            })
            .collect();
        points.push(CloudPoint { x_m: f32::MAX, y_m: f32::MIN_POSITIVE, z_m: -0.0, ..Default::default() });
        points.push(CloudPoint { x_m: 1e-30, y_m: 123456.79, z_m: 0.1, intensity: 0.5, ..Default::default() });
        points.push(CloudPoint::default());
        points.push(CloudPoint { offset_ns: u32::MAX, line: 255, tag: 255, ..CloudPoint::xyz(1.0, 2.0, 3.0) });
        PointCloud::new(Some(Stamp::new(1_700_000_000_123_456_789, Clock::Ptp)), points)
    }

    /// A fresh scratch directory under the system temp dir, removed on drop.
    pub(crate) struct Scratch(pub std::path::PathBuf);

    impl Scratch {
        pub(crate) fn new(name: &str) -> Self {
            let dir = std::env::temp_dir().join(format!("starc-cloud-{}-{name}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn shared_data() -> Option<std::path::PathBuf> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data");
        if dir.is_dir() {
            Some(dir)
        } else {
            println!("skipping: {} is absent", dir.display());
            None
        }
    }

    #[test]
    fn every_format_round_trips_through_a_file() {
        let dir = Scratch::new("round_trip");
        let cloud = sample_cloud();
        for format in CloudFormat::ALL {
            let path = dir.0.join(format!("cloud_{}.{}", format.name(), format.extension()));
            write(&path, &cloud, format).unwrap();
            let back = read(&path).unwrap();
            if format == CloudFormat::Kitti {
                // KITTI keeps x, y, z, intensity only.
                assert_eq!(back.start, None);
                assert_eq!(back.len(), cloud.len());
                for (a, b) in back.points.iter().zip(&cloud.points) {
                    let keep =
                        CloudPoint { x_m: b.x_m, y_m: b.y_m, z_m: b.z_m, intensity: b.intensity, ..Default::default() };
                    assert_eq!(*a, keep);
                }
            } else {
                assert_eq!(back, cloud, "{format}");
            }
        }
    }

    #[test]
    fn format_names_and_detection() {
        for f in CloudFormat::ALL {
            assert_eq!(f.name().parse::<CloudFormat>().ok(), Some(f));
        }
        assert_eq!("PLY".parse::<CloudFormat>().ok(), Some(CloudFormat::PlyBinary));
        assert!("las".parse::<CloudFormat>().is_err());
        assert_eq!(FileKind::detect(b"ply\nformat ascii 1.0\n", None), Some(FileKind::Ply));
        assert_eq!(FileKind::detect(b"VERSION 0.7\n", None), Some(FileKind::Pcd));
        assert_eq!(FileKind::detect(b"\0\0\0\0", Some(Path::new("a/000001.BIN"))), Some(FileKind::Kitti));
        assert_eq!(FileKind::detect(b"\0\0\0\0", Some(Path::new("a/cloud.xyz"))), None);
        assert_eq!(FileKind::detect(b"", None), None);
    }

    #[test]
    fn unknown_and_missing_files_are_typed_errors() {
        let dir = Scratch::new("errors");
        let p = dir.0.join("cloud.xyz");
        std::fs::write(&p, b"1 2 3\n").unwrap();
        assert!(matches!(read(&p), Err(PipelineError::UnknownFormat { .. })));
        assert!(matches!(read(&dir.0.join("absent.pcd")), Err(PipelineError::Io { .. })));
    }

    #[test]
    fn bounds_and_times() {
        let c = PointCloud::new(
            Some(Stamp::new(100, Clock::Ptp)),
            vec![
                CloudPoint::xyz(1.0, -2.0, 3.0),
                CloudPoint::xyz(f32::NAN, 0.0, 0.0),
                CloudPoint { offset_ns: 50, ..CloudPoint::xyz(-1.0, 5.0, 0.5) },
            ],
        );
        assert_eq!(c.bounds(), Some(([-1.0, -2.0, 0.5], [1.0, 5.0, 3.0])));
        assert_eq!(c.point_time(2), Some(Stamp::new(150, Clock::Ptp)));
        assert_eq!(c.point_time(3), None);
        assert_eq!(PointCloud::default().bounds(), None);
        assert_eq!(parse_start_comment(&start_comment(Stamp::new(7, Clock::Gps))), Some(Stamp::new(7, Clock::Gps)));
        assert_eq!(parse_start_comment("starc start_ns 7 clock martian"), None);
        assert_eq!(parse_start_comment("Created by CloudCompare"), None);
    }

    #[test]
    fn real_avia_frame_pcd() {
        let Some(dir) = shared_data() else { return };
        let cloud = read(&dir.join("livox/avia_frame.pcd")).unwrap();
        assert_eq!(cloud.len(), 24_000);
        assert_eq!(cloud.start, None);
        let returns: Vec<&CloudPoint> = cloud.points.iter().filter(|p| !p.is_zero()).collect();
        assert_eq!(returns.len(), 2_813);
        let (lo, hi) = cloud.bounds().unwrap();
        assert!(lo[0] >= 0.0 && hi[0] < 111.0, "x within {}..{}", lo[0], hi[0]);
        assert!(lo[1] > -45.0 && hi[1] < 75.0, "y within {}..{}", lo[1], hi[1]);
        assert!(lo[2] > -20.0 && hi[2] < 5.0, "z within {}..{}", lo[2], hi[2]);
        assert!(cloud.points.iter().all(|p| (0.0..=255.0).contains(&p.intensity)));
        assert!(cloud.points.iter().all(|p| p.line < 6 && p.tag <= 0x3f));
        assert!(returns.iter().any(|p| p.line == 5));
    }

    #[test]
    fn real_registration_plys() {
        let Some(dir) = shared_data() else { return };
        for (name, count) in [("source.ply", 69_792), ("target.ply", 69_088)] {
            let cloud = read(&dir.join("registration").join(name)).unwrap();
            assert_eq!(cloud.len(), count, "{name}");
            let (lo, hi) = cloud.bounds().unwrap();
            for k in 0..3 {
                assert!(lo[k] > -80.0 && hi[k] < 25.0 && hi[k] - lo[k] > 5.0, "{name} axis {k}: {lo:?} {hi:?}");
            }
            assert!(cloud.points.iter().all(|p| (0.0..=255.0).contains(&p.intensity)), "{name}");
            assert!(cloud.points.iter().any(|p| p.intensity > 100.0), "{name}: intensity was read");
            // Round trip the real data through every format.
            for format in CloudFormat::ALL {
                let back = read_bytes(&to_bytes(&cloud, format), format.kind()).unwrap();
                assert_eq!(back.points, cloud.points, "{name} via {format}");
            }
        }
    }
}
