//! Reading a recording back: messages in file order, decoded into the types of [`super::msgs`].
//!
//! [`ReadMode::Strict`] reports any damage as an error. [`ReadMode::Recover`] reads a file that
//! lost its end (crash, full disk, pulled cable) up to the last complete chunk and then stops,
//! keeping the reason in [`Messages::stopped_by`]. Nothing here panics on bad bytes; the
//! container is parsed by [`super::scan`].

use super::msgs::{
    CanFrameMsg, CompressedImage, Imu, MarkerArray, Odometry, PointCloud2, PointField, RosMessage, TfMessage,
};
use super::scan::{is_finished, Scanner};
use crate::cloud::{CloudPoint, PointCloud};
use crate::PipelineError;
use serde::Serialize;
use starc_time::{Clock, Stamp};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

/// How damage is handled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadMode {
    /// The file must be a complete MCAP; damage is an error item.
    Strict,
    /// Read what is readable and stop quietly at the first damage (end missing, torn chunk).
    Recover,
}

/// One message as stored.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedMessage {
    pub topic: String,
    /// The schema name, `pkg/msg/Type`.
    pub type_name: String,
    /// The channel's message encoding (`cdr` for ROS 2).
    pub encoding: String,
    pub sequence: u32,
    pub log_ns: u64,
    pub publish_ns: u64,
    pub payload: Vec<u8>,
}

/// A decoded message of a type we record.
#[derive(Clone, Debug, PartialEq)]
pub enum Decoded {
    PointCloud2(PointCloud2),
    Imu(Box<Imu>),
    Odometry(Box<Odometry>),
    Tf(TfMessage),
    MarkerArray(MarkerArray),
    CompressedImage(CompressedImage),
    CanFrame(CanFrameMsg),
}

impl RecordedMessage {
    /// Decodes the payload by its schema name.
    pub fn decode(&self) -> Result<Decoded, PipelineError> {
        if self.encoding != "cdr" {
            return Err(PipelineError::Unsupported {
                format: "MCAP",
                what: format!("message encoding `{}` on {}", self.encoding, self.topic),
            });
        }
        let p = &self.payload;
        Ok(match self.type_name.as_str() {
            PointCloud2::TYPE_NAME => Decoded::PointCloud2(PointCloud2::from_cdr(p)?),
            Imu::TYPE_NAME => Decoded::Imu(Box::new(Imu::from_cdr(p)?)),
            Odometry::TYPE_NAME => Decoded::Odometry(Box::new(Odometry::from_cdr(p)?)),
            TfMessage::TYPE_NAME => Decoded::Tf(TfMessage::from_cdr(p)?),
            MarkerArray::TYPE_NAME => Decoded::MarkerArray(MarkerArray::from_cdr(p)?),
            CompressedImage::TYPE_NAME => Decoded::CompressedImage(CompressedImage::from_cdr(p)?),
            CanFrameMsg::TYPE_NAME => Decoded::CanFrame(CanFrameMsg::from_cdr(p)?),
            other => return Err(PipelineError::Unsupported { format: "MCAP", what: format!("message type {other}") }),
        })
    }
}

/// Messages of a recording in file order, from a file ([`open`]) or bytes ([`messages`]).
pub struct Messages<R: Read> {
    scanner: Scanner<R>,
    mode: ReadMode,
    stopped_by: Option<String>,
}

impl<R: Read> Messages<R> {
    /// Why a [`ReadMode::Recover`] read ended before the end of the data (`None`: it did not).
    pub fn stopped_by(&self) -> Option<&str> {
        self.stopped_by.as_deref()
    }
}

/// Iterates the messages of an MCAP held in memory. Fails only when `bytes` is not an MCAP.
pub fn messages(bytes: &[u8], mode: ReadMode) -> Result<Messages<&[u8]>, PipelineError> {
    Ok(Messages { scanner: Scanner::from_bytes(bytes)?, mode, stopped_by: None })
}

/// Streams the messages of a recording file (one chunk in memory at a time).
pub fn open(path: &Path, mode: ReadMode) -> Result<Messages<BufReader<File>>, PipelineError> {
    let file = File::open(path).map_err(|e| PipelineError::io(format!("opening {}", path.display()), e))?;
    let len = file.metadata().map_err(|e| PipelineError::io(format!("reading {}", path.display()), e))?.len();
    Ok(Messages { scanner: Scanner::new(BufReader::with_capacity(1 << 20, file), len)?, mode, stopped_by: None })
}

impl<R: Read> Iterator for Messages<R> {
    type Item = Result<RecordedMessage, PipelineError>;

    fn next(&mut self) -> Option<Self::Item> {
        match self.scanner.next_message()? {
            Ok(m) => Some(Ok(RecordedMessage {
                topic: m.topic,
                type_name: m.schema_name,
                encoding: m.encoding,
                sequence: m.sequence,
                log_ns: m.log_ns,
                publish_ns: m.publish_ns,
                payload: m.payload,
            })),
            Err(e) => match self.mode {
                ReadMode::Strict => Some(Err(e)),
                ReadMode::Recover => {
                    self.stopped_by = Some(e.to_string());
                    None
                }
            },
        }
    }
}

/// Reads a whole recording file into memory (then use [`messages`]).
pub fn read_file(path: &Path) -> Result<Vec<u8>, PipelineError> {
    std::fs::read(path).map_err(|e| PipelineError::io(format!("reading {}", path.display()), e))
}

/// One topic of a recording.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct TopicSummary {
    pub type_name: String,
    pub messages: u64,
    pub first_ns: u64,
    pub last_ns: u64,
}

/// What a recording holds, counted by reading every message (works on damaged files too).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RecordingSummary {
    pub messages: u64,
    pub topics: BTreeMap<String, TopicSummary>,
    /// First and last log time over all messages.
    pub start_ns: Option<u64>,
    pub end_ns: Option<u64>,
    /// The file ends with its summary, footer and magic (it was finished).
    pub finished: bool,
    /// Why reading stopped early (damage after the last readable chunk).
    pub stopped_by: Option<String>,
}

/// Counts topics, messages and the time span of bytes in memory; a damaged recording is read
/// as far as it goes.
pub fn summarize(bytes: &[u8]) -> Result<RecordingSummary, PipelineError> {
    let tail = bytes.get(bytes.len().saturating_sub(37)..).unwrap_or_default();
    Ok(count(messages(bytes, ReadMode::Recover)?, is_finished(tail)))
}

/// [`summarize`] for a file, streamed.
pub fn summarize_file(path: &Path) -> Result<RecordingSummary, PipelineError> {
    let ctx = |e| PipelineError::io(format!("reading {}", path.display()), e);
    let mut file = File::open(path).map_err(ctx)?;
    let len = file.metadata().map_err(ctx)?.len();
    let mut tail = Vec::new();
    file.seek(SeekFrom::Start(len.saturating_sub(37))).map_err(ctx)?;
    file.read_to_end(&mut tail).map_err(ctx)?;
    Ok(count(open(path, ReadMode::Recover)?, is_finished(&tail)))
}

fn count<R: Read>(mut it: Messages<R>, finished: bool) -> RecordingSummary {
    let mut s = RecordingSummary { finished, ..RecordingSummary::default() };
    for m in it.by_ref().flatten() {
        s.messages += 1;
        s.start_ns = Some(s.start_ns.map_or(m.log_ns, |t| t.min(m.log_ns)));
        s.end_ns = Some(s.end_ns.map_or(m.log_ns, |t| t.max(m.log_ns)));
        let t = s.topics.entry(m.topic).or_insert_with(|| TopicSummary {
            type_name: m.type_name,
            messages: 0,
            first_ns: m.log_ns,
            last_ns: m.log_ns,
        });
        t.messages += 1;
        t.first_ns = t.first_ns.min(m.log_ns);
        t.last_ns = t.last_ns.max(m.log_ns);
    }
    s.stopped_by = it.stopped_by().map(str::to_string);
    s
}

fn cloud_err(reason: impl Into<String>) -> PipelineError {
    PipelineError::BadFile { format: "PointCloud2", reason: reason.into() }
}

/// Offset of field `name` when present, checked to be of `datatype` and inside a point.
fn field_offset(msg: &PointCloud2, name: &str, datatype: u8, size: u32) -> Result<Option<usize>, PipelineError> {
    let Some(f) = msg.fields.iter().find(|f| f.name == name) else {
        return Ok(None);
    };
    if f.datatype != datatype {
        return Err(cloud_err(format!("field {name} has datatype {}, expected {datatype}", f.datatype)));
    }
    if f.offset.checked_add(size).is_none_or(|end| end > msg.point_step) {
        return Err(cloud_err(format!("field {name} at {} overruns a {}-byte point", f.offset, msg.point_step)));
    }
    Ok(Some(f.offset as usize))
}

fn get<const N: usize>(point: &[u8], offset: Option<usize>) -> Option<[u8; N]> {
    point.get(offset?..offset? + N)?.try_into().ok()
}

/// A `PointCloud2` back into a [`PointCloud`]: needs FLOAT32 x, y, z; reads `intensity`
/// (FLOAT32), `t` (UINT32 ns after the stamp), `line` and `tag` (UINT8) when present.
pub fn cloud_from_msg(msg: &PointCloud2, clock: Clock) -> Result<PointCloud, PipelineError> {
    if msg.is_bigendian {
        return Err(PipelineError::Unsupported { format: "PointCloud2", what: "big-endian data".into() });
    }
    let need = |name: &'static str| {
        field_offset(msg, name, PointField::FLOAT32, 4)?
            .ok_or(PipelineError::MissingField { format: "PointCloud2", field: name })
    };
    let (x, y, z) = (Some(need("x")?), Some(need("y")?), Some(need("z")?));
    let intensity = field_offset(msg, "intensity", PointField::FLOAT32, 4)?;
    let t = field_offset(msg, "t", PointField::UINT32, 4)?;
    let line = field_offset(msg, "line", PointField::UINT8, 1)?;
    let tag = field_offset(msg, "tag", PointField::UINT8, 1)?;

    let step = msg.point_step as usize;
    let row_bytes = (msg.width as usize).checked_mul(step).ok_or_else(|| cloud_err("width overflows"))?;
    if (msg.row_step as usize) < row_bytes {
        return Err(cloud_err(format!("row_step {} < width {} x point_step {step}", msg.row_step, msg.width)));
    }
    let total =
        (msg.height as usize).checked_mul(msg.row_step as usize).ok_or_else(|| cloud_err("height overflows"))?;
    if total > msg.data.len() {
        return Err(PipelineError::Truncated {
            format: "PointCloud2",
            what: "data",
            need: total as u64,
            have: msg.data.len() as u64,
        });
    }
    let mut points = Vec::with_capacity(total.checked_div(step).unwrap_or(0));
    for row in msg.data.chunks(msg.row_step.max(1) as usize).take(msg.height as usize) {
        for point in row.chunks(step.max(1)).take(msg.width as usize) {
            let f = |o| get::<4>(point, o).map(f32::from_le_bytes);
            let (Some(x_m), Some(y_m), Some(z_m)) = (f(x), f(y), f(z)) else {
                return Err(cloud_err("point shorter than its fields"));
            };
            points.push(CloudPoint {
                x_m,
                y_m,
                z_m,
                intensity: f(intensity).unwrap_or(0.0),
                offset_ns: get::<4>(point, t).map_or(0, u32::from_le_bytes),
                line: get::<1>(point, line).map_or(0, |b| b[0]),
                tag: get::<1>(point, tag).map_or(0, |b| b[0]),
            });
        }
    }
    let start = msg.header.stamp.to_ns().map(|ns| Stamp::new(ns, clock));
    Ok(PointCloud::new(start, points))
}
