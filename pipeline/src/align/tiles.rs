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
//! | 2 | format (1: surfaces; 2: surfaces and coverage) |
//! | 2 | tile edge, cm (1..=10000) |
//! | 2 | quantization step, mm (1..=1000); coordinates are steps from the tile's min corner |
//! | 2 | vectors: 0, each point's vector is its surface normal; 1, the unit vector from the point towards the sensor that first saw it |
//! | 12 | tile key: i32 x, y, z (the tile spans `key * edge .. (key + 1) * edge`) |
//! | 4 | tile version (the sender increments it when the tile changes) |
//! | 4 | point count n |
//! | 10 n | per point: u16 x, y, z (steps), i8 vx, vy, vz (its vector x 127; all 0: none), u8 reserved (0) |
//! | format 2 only: 2 | coverage voxel, mm (1..=10000; the tile edge is a whole number m of them) |
//! | 2 | m, voxels along the tile's edge (1..=64) |
//! | 2 | crossings: every voxel set below was crossed by at least this many of the robot's rays |
//! | 2 | reserved (0) |
//! | ceil(m³ / 8) | one bit per voxel, x fastest, then y, then z (LSB first); the pad bits 0 |
//! | 4 | CRC-32 (ISO-HDLC, as zlib) of everything before it |
//!
//! The robot's map sends, as each point's vector, the direction towards its sensor (vectors
//! 1): which side of a wall the robot saw, so that the rig does not pair the wall's other face
//! with it ([`super::SeenFrom`]). A prepared map sends its normals (vectors 0).
//!
//! Format 2 carries the space the robot's rays crossed (see [`super::Coverage`]) beside its
//! surfaces, so a rig on the link judges a registration by its overlap with what the robot saw,
//! as an offline run does. A 4 m tile of 0.25 m voxels adds 520 bytes.
//!
//! At 1 cm steps a 4 m tile holds coordinates up to 400 steps: u16 leaves room for tiles up to
//! 655 m at 1 cm. 10 bytes per point against 24 (three f64) or 48 with normals.

use super::geometry::Vec3;
use super::Coverage;
use crate::voxel_hash::{key_of, Key, KeyMap};
use crate::PipelineError;

const MAGIC: &[u8; 4] = b"STMT";
const FORMAT: u16 = 1;
const FORMAT_COVERED: u16 = 2;
/// The header's `vectors`: each point's vector is its normal, or the direction towards its sensor.
const VECTORS_NORMALS: u16 = 0;
const VECTORS_TOWARDS_SENSOR: u16 = 1;
const HEADER_LEN: usize = 32;
const COVERAGE_HEADER_LEN: usize = 8;
/// Most coverage voxels along a tile's edge (a 32 KiB bit field).
const MAX_COVERAGE_PER_EDGE: u16 = 64;
const POINT_LEN: usize = 10;
const CRC_LEN: usize = 4;
/// Largest tile the parser accepts (points), so a forged count cannot ask for a huge buffer.
pub const MAX_TILE_POINTS: u32 = 1 << 20;
const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// What a tile's per-point vectors are (the header's `vectors`), with them: one per point,
/// None where there is none.
#[derive(Clone, Copy, Debug)]
pub enum TileVectors<'a> {
    /// Surface normals (a prepared map's).
    Normals(&'a [Option<Vec3>]),
    /// The direction from each point towards the sensor that first saw it (the robot's map).
    TowardsSensor(&'a [Option<Vec3>]),
}

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
    /// For each point, the direction towards the sensor that saw it (None where not sent).
    pub towards_sensor: Vec<Option<Vec3>>,
    /// The space the robot's rays crossed in this tile (format 2).
    pub coverage: Option<TileCoverage>,
}

/// A tile's share of the robot's coverage: the voxels crossed at least `min_crossings` times.
#[derive(Clone, Debug, PartialEq)]
pub struct TileCoverage {
    pub voxel_m: f64,
    pub min_crossings: u16,
    /// Voxel keys in the coverage's grid (cells of `voxel_m` with a corner at the origin).
    pub voxels: Vec<Key>,
}

fn bad(reason: impl Into<String>) -> PipelineError {
    PipelineError::BadFile { format: "map tile", reason: reason.into() }
}

/// The tile edge (cm) and quantization step (mm) the format holds for `edge_m` and `step_m`,
/// when it can hold them.
fn tile_sizes(edge_m: f64, step_m: f64) -> Result<(f64, f64), PipelineError> {
    let edge_cm = (edge_m * 100.0).round();
    let step_mm = (step_m * 1000.0).round();
    if !(1.0..=10_000.0).contains(&edge_cm) || !(1.0..=1000.0).contains(&step_mm) {
        return Err(bad(format!("tile edge {edge_m} m or step {step_m} m out of range")));
    }
    if (edge_cm / 100.0) / (step_mm / 1000.0) > f64::from(u16::MAX) {
        return Err(bad(format!("a {edge_m} m tile at {step_m} m steps does not fit u16 coordinates")));
    }
    Ok((edge_cm, step_mm))
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
    let (edge_cm, _) = tile_sizes(edge_m, step_m)?;
    let edge_m = edge_cm / 100.0;
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
        let pts: Vec<Vec3> = chunk.iter().filter_map(|&i| points.get(i).copied()).collect();
        let nrm: Vec<Option<Vec3>> = chunk.iter().map(|&i| normals.get(i).copied().flatten()).collect();
        out.push((key, encode_tile(key, &pts, TileVectors::Normals(&nrm), edge_m, step_m, version, None)?));
    }
    Ok(out)
}

/// One tile `key` of `edge_m` holding `points` (all inside it; with `vectors`, one per point)
/// at `step_m` quantization; with `coverage` (the robot's, and the crossings a voxel needs) in
/// format 2.
pub fn encode_tile(
    key: Key,
    points: &[Vec3],
    vectors: TileVectors,
    edge_m: f64,
    step_m: f64,
    version: u32,
    coverage: Option<(&Coverage, u16)>,
) -> Result<Vec<u8>, PipelineError> {
    let (values, kind) = match vectors {
        TileVectors::Normals(v) => (v, VECTORS_NORMALS),
        TileVectors::TowardsSensor(v) => (v, VECTORS_TOWARDS_SENSOR),
    };
    let (edge_cm, step_mm) = tile_sizes(edge_m, step_m)?;
    let (edge_m, step_m) = (edge_cm / 100.0, step_mm / 1000.0);
    if points.len() > MAX_TILE_POINTS as usize {
        return Err(bad(format!("tile {key:?} holds {} points (at most {MAX_TILE_POINTS})", points.len())));
    }
    let format = if coverage.is_some() { FORMAT_COVERED } else { FORMAT };
    let mut b = Vec::with_capacity(HEADER_LEN + points.len() * POINT_LEN + CRC_LEN);
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&format.to_le_bytes());
    b.extend_from_slice(&(edge_cm as u16).to_le_bytes());
    b.extend_from_slice(&(step_mm as u16).to_le_bytes());
    b.extend_from_slice(&kind.to_le_bytes());
    for k in [key.0, key.1, key.2] {
        b.extend_from_slice(&k.to_le_bytes());
    }
    b.extend_from_slice(&version.to_le_bytes());
    b.extend_from_slice(&(points.len() as u32).to_le_bytes());
    let origin = Vec3::new(f64::from(key.0), f64::from(key.1), f64::from(key.2)) * edge_m;
    let max_step = (edge_m / step_m).floor();
    for (i, p) in points.iter().enumerate() {
        for v in (p - origin).iter() {
            let q = (v / step_m).round().clamp(0.0, max_step) as u16;
            b.extend_from_slice(&q.to_le_bytes());
        }
        let n = values.get(i).copied().flatten().filter(|n| n.iter().all(|v| v.is_finite()));
        let n = n.and_then(|n| n.try_normalize(1e-12));
        for v in n.map_or([0.0; 3], |n| [n.x, n.y, n.z]) {
            b.push(((v * 127.0).round().clamp(-127.0, 127.0) as i8) as u8);
        }
        b.push(0);
    }
    if let Some((coverage, min_crossings)) = coverage {
        encode_coverage(&mut b, key, edge_cm, coverage, min_crossings)?;
    }
    let crc = CRC32.checksum(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    Ok(b)
}

/// Voxels along a tile's edge of `edge_cm` for coverage voxels of `voxel_mm`, when whole and
/// within bounds.
fn voxels_per_edge(edge_cm: u16, voxel_mm: u16) -> Option<u16> {
    let edge_mm = u32::from(edge_cm) * 10;
    let voxel_mm = u32::from(voxel_mm);
    let m = edge_mm.checked_div(voxel_mm)?;
    (m * voxel_mm == edge_mm && (1..=u32::from(MAX_COVERAGE_PER_EDGE)).contains(&m)).then_some(m as u16)
}

/// The coverage section of tile `key`: the bit of every voxel crossed at least `min_crossings`
/// times.
fn encode_coverage(
    b: &mut Vec<u8>,
    key: Key,
    edge_cm: f64,
    coverage: &Coverage,
    min_crossings: u16,
) -> Result<(), PipelineError> {
    let voxel_mm = (coverage.voxel_m() * 1000.0).round();
    let m = (1.0..=10_000.0)
        .contains(&voxel_mm)
        .then(|| voxels_per_edge(edge_cm as u16, voxel_mm as u16))
        .flatten()
        .ok_or_else(|| {
            bad(format!("a {} m tile is no whole number of {} m coverage voxels", edge_cm / 100.0, coverage.voxel_m()))
        })?;
    b.extend_from_slice(&(voxel_mm as u16).to_le_bytes());
    b.extend_from_slice(&m.to_le_bytes());
    b.extend_from_slice(&min_crossings.to_le_bytes());
    b.extend_from_slice(&0u16.to_le_bytes());
    let mut bits = vec![0u8; coverage_bytes(m)];
    let first = first_voxel(key, m).ok_or_else(|| bad(format!("tile {key:?}: its voxel keys overflow")))?;
    let m = i32::from(m);
    let mut i = 0usize;
    for z in 0..m {
        for y in 0..m {
            for x in 0..m {
                let voxel = (first.0 + x, first.1 + y, first.2 + z);
                if coverage.crossings_of(&voxel) >= min_crossings.max(1) {
                    if let Some(byte) = bits.get_mut(i / 8) {
                        *byte |= 1 << (i % 8);
                    }
                }
                i += 1;
            }
        }
    }
    b.extend_from_slice(&bits);
    Ok(())
}

/// The key of the first coverage voxel of tile `key` at `m` voxels per edge, when every voxel
/// of the tile has a key (i32).
fn first_voxel(key: Key, m: u16) -> Option<Key> {
    let first = |k: i32| k.checked_mul(i32::from(m)).filter(|f| f.checked_add(i32::from(m)).is_some());
    Some((first(key.0)?, first(key.1)?, first(key.2)?))
}

fn coverage_bytes(per_edge: u16) -> usize {
    (usize::from(per_edge).pow(3)).div_ceil(8)
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
    if format != FORMAT && format != FORMAT_COVERED {
        return Err(PipelineError::Unsupported { format: "map tile", what: format!("format {format}") });
    }
    let (edge_cm, step_mm, vectors) = (u16_at(b, 6)?, u16_at(b, 8)?, u16_at(b, 10)?);
    let vectors_ok = vectors == VECTORS_NORMALS || vectors == VECTORS_TOWARDS_SENSOR;
    if !(1..=10_000).contains(&edge_cm) || !(1..=1000).contains(&step_mm) || !vectors_ok {
        return Err(bad(format!("edge {edge_cm} cm, step {step_mm} mm, vectors {vectors}")));
    }
    let key = (u32_at(b, 12)? as i32, u32_at(b, 16)? as i32, u32_at(b, 20)? as i32);
    let version = u32_at(b, 24)?;
    let count = u32_at(b, 28)?;
    if count > MAX_TILE_POINTS {
        return Err(bad(format!("{count} points (at most {MAX_TILE_POINTS})")));
    }
    let points_end = HEADER_LEN + count as usize * POINT_LEN;
    let per_edge = if format == FORMAT_COVERED { Some(coverage_header(b, points_end, edge_cm)?) } else { None };
    let need = points_end + per_edge.map_or(0, |(_, m, _)| COVERAGE_HEADER_LEN + coverage_bytes(m)) + CRC_LEN;
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
    let coverage = match per_edge {
        Some((voxel_mm, m, min_crossings)) => Some(decode_coverage(b, points_end, key, voxel_mm, m, min_crossings)?),
        None => None,
    };
    let none = vec![None; normals.len()];
    let (normals, towards_sensor) = if vectors == VECTORS_TOWARDS_SENSOR { (none, normals) } else { (normals, none) };
    Ok(Tile { key, version, edge_m, step_m, points, normals, towards_sensor, coverage })
}

/// The coverage section's header after the points: voxel size (mm), voxels per edge, crossings.
fn coverage_header(b: &[u8], at: usize, edge_cm: u16) -> Result<(u16, u16, u16), PipelineError> {
    let (voxel_mm, m, min_crossings, reserved) =
        (u16_at(b, at)?, u16_at(b, at + 2)?, u16_at(b, at + 4)?, u16_at(b, at + 6)?);
    let whole = (1..=10_000).contains(&voxel_mm) && voxels_per_edge(edge_cm, voxel_mm) == Some(m);
    if !whole || reserved != 0 {
        return Err(bad(format!(
            "coverage of {voxel_mm} mm voxels, {m} per edge of a {edge_cm} cm tile, reserved {reserved}"
        )));
    }
    Ok((voxel_mm, m, min_crossings))
}

/// The voxels whose bits are set in the coverage section at `at` (header included).
fn decode_coverage(
    b: &[u8],
    at: usize,
    key: Key,
    voxel_mm: u16,
    m: u16,
    min_crossings: u16,
) -> Result<TileCoverage, PipelineError> {
    let n = usize::from(m).pow(3);
    let bits =
        b.get(at + COVERAGE_HEADER_LEN..at + COVERAGE_HEADER_LEN + coverage_bytes(m)).ok_or_else(|| bad("short"))?;
    let first = first_voxel(key, m).ok_or_else(|| bad(format!("tile {key:?}: its voxel keys overflow")))?;
    let m = i32::from(m);
    let mut voxels = Vec::new();
    for (i, byte) in bits.iter().enumerate() {
        for bit in 0..8 {
            if byte & (1 << bit) == 0 {
                continue;
            }
            let v = i * 8 + bit;
            if v >= n {
                return Err(bad("coverage pad bits set"));
            }
            let v = v as i32;
            voxels.push((first.0 + v % m, first.1 + (v / m) % m, first.2 + v / (m * m)));
        }
    }
    Ok(TileCoverage { voxel_m: f64::from(voxel_mm) / 1000.0, min_crossings, voxels })
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

    /// The robot's coverage as its tiles carry it (none without format-2 tiles): each voxel
    /// sent counts as crossed its tile's `min_crossings` times. Tiles with another voxel size
    /// than the first are left out.
    pub fn coverage(&self) -> Option<Coverage> {
        let mut out: Option<Coverage> = None;
        for t in self.in_key_order().filter_map(|t| t.coverage.as_ref()) {
            let c = out.get_or_insert_with(|| Coverage::new(t.voxel_m));
            if (c.voxel_m() - t.voxel_m).abs() > 1e-9 {
                continue;
            }
            for v in &t.voxels {
                c.set_crossings(*v, t.min_crossings);
            }
        }
        out
    }

    /// All points held, in tile-key order, and for each the direction towards the sensor that
    /// saw it (zero where the tile did not say).
    pub fn points_seen_from(&self) -> (Vec<Vec3>, Vec<Vec3>) {
        let (mut pts, mut towards) = (Vec::new(), Vec::new());
        for t in self.in_key_order() {
            pts.extend_from_slice(&t.points);
            towards.extend(t.towards_sensor.iter().map(|d| d.unwrap_or_else(Vec3::zeros)));
        }
        (pts, towards)
    }

    /// The tiles held, sorted by key (so that a map's points come out the same every time).
    fn in_key_order(&self) -> impl Iterator<Item = &Tile> {
        let mut keys: Vec<&Key> = self.tiles.keys().collect();
        keys.sort_unstable();
        keys.into_iter().filter_map(|k| self.tiles.get(k))
    }

    /// All points and normals held, in tile-key order.
    pub fn points(&self) -> (Vec<Vec3>, Vec<Option<Vec3>>) {
        let (mut pts, mut nrm) = (Vec::new(), Vec::new());
        for t in self.in_key_order() {
            pts.extend_from_slice(&t.points);
            nrm.extend_from_slice(&t.normals);
        }
        (pts, nrm)
    }
}
