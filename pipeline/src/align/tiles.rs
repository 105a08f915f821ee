//! A compact binary format for sending the prepared map to the rig incrementally: the map cut
//! into cubic tiles keyed by their voxel, each tile a self-contained, versioned, length-checked
//! and CRC'd message, so a rig can take tiles in any order, drop stale versions and refuse
//! damaged ones.
//!
//! One tile, little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 4 | magic `STMT` |
//! | 2 | format (1) |
//! | 2 | tile edge, cm (1..=10000) |
//! | 2 | quantization step, mm (1..=1000); coordinates are steps from the tile's min corner |
//! | 2 | reserved (0) |
//! | 12 | tile key: i32 x, y, z (the tile spans `key * edge .. (key + 1) * edge`) |
//! | 4 | tile version (the sender increments it when the tile changes) |
//! | 4 | point count n |
//! | 10 n | per point: u16 x, y, z (steps), i8 nx, ny, nz (normal x 127; all 0: none), u8 reserved (0) |
//! | 4 | CRC-32 (ISO-HDLC, as zlib) of everything before it |
//!
//! At 1 cm steps a 4 m tile holds coordinates up to 400 steps: u16 leaves room for tiles up to
//! 655 m at 1 cm. 10 bytes per point against 24 (three f64) or 48 with normals.

use super::geometry::Vec3;
use crate::voxel_hash::{key_of, Key, KeyMap};
use crate::PipelineError;

const MAGIC: &[u8; 4] = b"STMT";
const FORMAT: u16 = 1;
const HEADER_LEN: usize = 32;
const POINT_LEN: usize = 10;
const CRC_LEN: usize = 4;
/// Largest tile the parser accepts (points), so a forged count cannot ask for a huge buffer.
pub const MAX_TILE_POINTS: u32 = 1 << 20;
const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// One decoded tile.
#[derive(Clone, Debug, PartialEq)]
pub struct Tile {
    pub key: Key,
    pub version: u32,
    pub edge_m: f64,
    pub step_m: f64,
    /// Points in the map frame and their normals (None where the sender had none).
    pub points: Vec<Vec3>,
    pub normals: Vec<Option<Vec3>>,
}

fn bad(reason: impl Into<String>) -> PipelineError {
    PipelineError::BadFile { format: "map tile", reason: reason.into() }
}

/// Cuts `points` (with `normals`, same length) into tiles of `edge_m` at `step_m` quantization,
/// each encoded with `version`. Tiles come out sorted by key.
pub fn encode_tiles(
    points: &[Vec3],
    normals: &[Option<Vec3>],
    edge_m: f64,
    step_m: f64,
    version: u32,
) -> Result<Vec<(Key, Vec<u8>)>, PipelineError> {
    let edge_cm = (edge_m * 100.0).round();
    let step_mm = (step_m * 1000.0).round();
    if !(1.0..=10_000.0).contains(&edge_cm) || !(1.0..=1000.0).contains(&step_mm) {
        return Err(bad(format!("tile edge {edge_m} m or step {step_m} m out of range")));
    }
    let (edge_m, step_m) = (edge_cm / 100.0, step_mm / 1000.0);
    if edge_m / step_m > f64::from(u16::MAX) {
        return Err(bad(format!("a {edge_m} m tile at {step_m} m steps does not fit u16 coordinates")));
    }
    let inv = 1.0 / edge_m;
    let mut tiles: KeyMap<Vec<usize>> = KeyMap::default();
    for (i, p) in points.iter().enumerate() {
        if p.iter().all(|v| v.is_finite()) {
            tiles.entry(key_of(p, inv)).or_default().push(i);
        }
    }
    let mut keys: Vec<Key> = tiles.keys().copied().collect();
    keys.sort_unstable();
    let mut out = Vec::with_capacity(keys.len());
    for key in keys {
        let chunk = tiles.get(&key).map_or(&[][..], Vec::as_slice);
        if chunk.len() > MAX_TILE_POINTS as usize {
            return Err(bad(format!("tile {key:?} holds {} points (at most {MAX_TILE_POINTS})", chunk.len())));
        }
        {
            let mut b = Vec::with_capacity(HEADER_LEN + chunk.len() * POINT_LEN + CRC_LEN);
            b.extend_from_slice(MAGIC);
            b.extend_from_slice(&FORMAT.to_le_bytes());
            b.extend_from_slice(&(edge_cm as u16).to_le_bytes());
            b.extend_from_slice(&(step_mm as u16).to_le_bytes());
            b.extend_from_slice(&0u16.to_le_bytes());
            for k in [key.0, key.1, key.2] {
                b.extend_from_slice(&k.to_le_bytes());
            }
            b.extend_from_slice(&version.to_le_bytes());
            b.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
            let origin = Vec3::new(f64::from(key.0), f64::from(key.1), f64::from(key.2)) * edge_m;
            let max_step = (edge_m / step_m).floor();
            for &i in chunk {
                let Some(p) = points.get(i) else { continue };
                for v in (p - origin).iter() {
                    let q = (v / step_m).round().clamp(0.0, max_step) as u16;
                    b.extend_from_slice(&q.to_le_bytes());
                }
                let n = normals.get(i).copied().flatten().filter(|n| n.iter().all(|v| v.is_finite()));
                for v in n.map_or([0.0; 3], |n| [n.x, n.y, n.z]) {
                    b.push(((v * 127.0).round().clamp(-127.0, 127.0) as i8) as u8);
                }
                b.push(0);
            }
            let crc = CRC32.checksum(&b);
            b.extend_from_slice(&crc.to_le_bytes());
            out.push((key, b));
        }
    }
    Ok(out)
}

fn u16_at(b: &[u8], at: usize) -> Result<u16, PipelineError> {
    b.get(at..at + 2).and_then(|s| s.try_into().ok()).map(u16::from_le_bytes).ok_or_else(|| bad("short"))
}

fn u32_at(b: &[u8], at: usize) -> Result<u32, PipelineError> {
    b.get(at..at + 4).and_then(|s| s.try_into().ok()).map(u32::from_le_bytes).ok_or_else(|| bad("short"))
}

/// Decodes one tile message: magic, format, sizes, exact length, CRC and every coordinate are
/// checked; any failure is a typed error, never a panic.
pub fn decode_tile(b: &[u8]) -> Result<Tile, PipelineError> {
    if b.len() < HEADER_LEN + CRC_LEN {
        return Err(PipelineError::Truncated {
            format: "map tile",
            what: "header",
            need: (HEADER_LEN + CRC_LEN) as u64,
            have: b.len() as u64,
        });
    }
    if b.get(0..4) != Some(&MAGIC[..]) {
        return Err(bad("bad magic (not a STARC map tile)"));
    }
    let format = u16_at(b, 4)?;
    if format != FORMAT {
        return Err(PipelineError::Unsupported { format: "map tile", what: format!("format {format}") });
    }
    let (edge_cm, step_mm, reserved) = (u16_at(b, 6)?, u16_at(b, 8)?, u16_at(b, 10)?);
    if !(1..=10_000).contains(&edge_cm) || !(1..=1000).contains(&step_mm) || reserved != 0 {
        return Err(bad(format!("edge {edge_cm} cm, step {step_mm} mm, reserved {reserved}")));
    }
    let key = (u32_at(b, 12)? as i32, u32_at(b, 16)? as i32, u32_at(b, 20)? as i32);
    let version = u32_at(b, 24)?;
    let count = u32_at(b, 28)?;
    if count > MAX_TILE_POINTS {
        return Err(bad(format!("{count} points (at most {MAX_TILE_POINTS})")));
    }
    let need = HEADER_LEN + count as usize * POINT_LEN + CRC_LEN;
    if b.len() != need {
        return Err(PipelineError::Truncated {
            format: "map tile",
            what: "points and CRC (length must match the count exactly)",
            need: need as u64,
            have: b.len() as u64,
        });
    }
    let body = b.get(..need - CRC_LEN).ok_or_else(|| bad("short"))?;
    let crc = u32_at(b, need - CRC_LEN)?;
    if CRC32.checksum(body) != crc {
        return Err(bad("CRC mismatch"));
    }
    let (edge_m, step_m) = (f64::from(edge_cm) / 100.0, f64::from(step_mm) / 1000.0);
    let max_step = (edge_m / step_m).floor();
    let origin = Vec3::new(f64::from(key.0), f64::from(key.1), f64::from(key.2)) * edge_m;
    let mut points = Vec::with_capacity(count as usize);
    let mut normals = Vec::with_capacity(count as usize);
    for i in 0..count as usize {
        let at = HEADER_LEN + i * POINT_LEN;
        let q = [u16_at(b, at)?, u16_at(b, at + 2)?, u16_at(b, at + 4)?];
        if q.iter().any(|&v| f64::from(v) > max_step) {
            return Err(bad(format!("point {i} lies outside its tile")));
        }
        let n = b.get(at + 6..at + 9).ok_or_else(|| bad("short"))?;
        points.push(origin + Vec3::new(f64::from(q[0]), f64::from(q[1]), f64::from(q[2])) * step_m);
        let n = Vec3::new(f64::from(n[0] as i8), f64::from(n[1] as i8), f64::from(n[2] as i8));
        normals.push((n.norm() > 0.0).then(|| n.normalize()));
    }
    Ok(Tile { key, version, edge_m, step_m, points, normals })
}

/// The rig's copy of the map: the newest version of every tile received.
#[derive(Clone, Debug, Default)]
pub struct TileMap {
    tiles: KeyMap<Tile>,
}

impl TileMap {
    /// Takes a tile message; returns whether it changed the map (older or equal versions of a tile
    /// already held are ignored). Damaged messages are errors and change nothing.
    pub fn apply(&mut self, bytes: &[u8]) -> Result<bool, PipelineError> {
        let tile = decode_tile(bytes)?;
        if self.tiles.get(&tile.key).is_some_and(|t| t.version >= tile.version) {
            return Ok(false);
        }
        self.tiles.insert(tile.key, tile);
        Ok(true)
    }

    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// All points and normals held, in tile-key order.
    pub fn points(&self) -> (Vec<Vec3>, Vec<Option<Vec3>>) {
        let mut keys: Vec<&Key> = self.tiles.keys().collect();
        keys.sort_unstable();
        let mut pts = Vec::new();
        let mut nrm = Vec::new();
        for k in keys {
            if let Some(t) = self.tiles.get(k) {
                pts.extend_from_slice(&t.points);
                nrm.extend_from_slice(&t.normals);
            }
        }
        (pts, nrm)
    }
}
