//! The one voxel grid of the pipeline: its key ([`Key`], [`key_of`]), its downsampler
//! ([`voxel_downsample`], [`VoxelMeans`]) and the hasher of its maps ([`VoxelHashMap`]), shared
//! by the LIO (scan reduction, iVox map), alignment, the detector and the robot's map.
//!
//! Keys multiply by the inverse cell size (one multiplication per axis instead of a division:
//! keys are taken several times per point per registration iteration). With a power-of-two
//! cell (the LIO's 0.5 m) this is exactly a division; otherwise a coordinate within an ulp or
//! two of a voxel face may land in the neighbouring voxel, the same for every caller.
//!
//! The hasher: the standard SipHash guards against adversarial keys, which voxel coordinates of
//! our own making are not, and costs several times more per lookup: the LIO update alone does
//! tens of thousands of lookups per scan.

use nalgebra::Vector3;
use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

/// A voxel: the cell's integer coordinates along x, y and z.
pub type Key = (i32, i32, i32);

/// A map keyed by voxel.
pub type KeyMap<V> = VoxelHashMap<Key, V>;

/// Voxel of `p` in the grid of cells `1 / inv_cell_m` wide with a corner at the origin;
/// coordinates beyond ±2^31 cells saturate (harmless: such points match nothing).
#[inline]
pub fn key_of(p: &Vector3<f64>, inv_cell_m: f64) -> Key {
    (floor_i32(p.x * inv_cell_m), floor_i32(p.y * inv_cell_m), floor_i32(p.z * inv_cell_m))
}

/// One point per occupied voxel of `voxel_m`, the centroid of its points, sorted by [`Key`] (so
/// that runs repeat exactly). A `voxel_m` that is not positive keeps every point.
pub fn voxel_downsample<'a>(points: impl IntoIterator<Item = &'a Vector3<f64>>, voxel_m: f64) -> Vec<Vector3<f64>> {
    let points = points.into_iter();
    if voxel_m.is_nan() || voxel_m <= 0.0 {
        return points.copied().collect();
    }
    let mut means = VoxelMeans::new(voxel_m);
    for p in points {
        means.add(p);
    }
    means.finish()
}

/// [`voxel_downsample`] of every `stride`-th point (0 counts as 1): a window of millions of
/// returns puts dozens in every voxel of the ICP's size, and a share of them gives the same
/// voxels for a share of the time.
pub fn voxel_downsample_every(points: &[Vector3<f64>], voxel_m: f64, stride: usize) -> Vec<Vector3<f64>> {
    voxel_downsample(points.iter().step_by(stride.max(1)), voxel_m)
}

/// [`voxel_downsample`] of points given one at a time (no buffer of them all).
pub struct VoxelMeans {
    inv: f64,
    sums: KeyMap<(Vector3<f64>, u32)>,
}

impl VoxelMeans {
    /// Voxels of `voxel_m` (at least 1 mm).
    pub fn new(voxel_m: f64) -> Self {
        Self { inv: 1.0 / voxel_m.max(1e-3), sums: KeyMap::default() }
    }

    pub fn add(&mut self, p: &Vector3<f64>) {
        let e = self.sums.entry(key_of(p, self.inv)).or_insert((Vector3::zeros(), 0));
        e.0 += p;
        e.1 += 1;
    }

    /// One point per voxel, the mean of its points (summed in the order given), sorted by key.
    pub fn finish(self) -> Vec<Vector3<f64>> {
        let mut cells: Vec<(Key, Vector3<f64>)> =
            self.sums.into_iter().map(|(k, (s, n))| (k, s / f64::from(n))).collect();
        cells.sort_unstable_by_key(|c| c.0);
        cells.into_iter().map(|c| c.1).collect()
    }
}

/// Multiply-rotate mixing of each written integer (the FxHash scheme).
#[derive(Clone, Copy, Debug, Default)]
pub struct VoxelHasher(u64);

const SEED: u64 = 0x51_7c_c1_b7_27_22_0a_95;

impl Hasher for VoxelHasher {
    /// Array keys (`[i32; 3]`) arrive here as one byte slice: mixed a word at a time, they take
    /// a quarter of the multiplications of mixing each byte, on a path taken for every lookup.
    fn write(&mut self, bytes: &[u8]) {
        let mut words = bytes.chunks_exact(4);
        for w in &mut words {
            if let Ok(word) = <[u8; 4]>::try_from(w) {
                self.add(u64::from(u32::from_le_bytes(word)));
            }
        }
        for b in words.remainder() {
            self.add(u64::from(*b));
        }
    }

    fn write_u32(&mut self, v: u32) {
        self.add(u64::from(v));
    }

    fn write_usize(&mut self, v: usize) {
        self.add(v as u64);
    }

    fn write_i32(&mut self, v: i32) {
        self.add(u64::from(v as u32));
    }

    fn write_u64(&mut self, v: u64) {
        self.add(v);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

impl VoxelHasher {
    fn add(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(SEED);
    }
}

/// `v.floor() as i32`, the same for every input (saturating, NaN to 0), without a call: the
/// x86-64 baseline has no SSE4.1 `roundsd`, so `floor` is a libm call, and voxel keys take
/// three per point (a few percent of the mission's CPU time in perf).
#[inline]
pub fn floor_i32(v: f64) -> i32 {
    let t = v as i32;
    if f64::from(t) > v {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// The 26 neighbours of a voxel, faces first, then edges, then corners: the order in which the
/// nearest point they could hold usually grows, so that a nearest-neighbour search bounded by
/// [`gap2`] skips the later ones.
pub const NEIGHBOURS: [Key; 26] = {
    let mut out = [(0, 0, 0); 26];
    let mut n = 0;
    let mut moved = 1;
    while moved <= 3 {
        let mut dx = -1;
        while dx <= 1 {
            let mut dy = -1;
            while dy <= 1 {
                let mut dz = -1;
                while dz <= 1 {
                    if (dx != 0) as i32 + (dy != 0) as i32 + (dz != 0) as i32 == moved {
                        out[n] = (dx, dy, dz);
                        n += 1;
                    }
                    dz += 1;
                }
                dy += 1;
            }
            dx += 1;
        }
        moved += 1;
    }
    out
};

/// Squared distance from `q` (in voxel `key` of edge `cell_m`) to the nearest point of the voxel
/// `offset` away (0 for its own): no point of that voxel is nearer.
#[inline]
pub fn gap2(q: [f64; 3], key: Key, cell_m: f64, offset: Key) -> f64 {
    let axis = |v: f64, k: i32, d: i32| {
        // Into [0, cell]: the key's product and this difference round apart at a voxel's faces.
        let below = (v - f64::from(k) * cell_m).clamp(0.0, cell_m);
        match d {
            -1 => below * below,
            1 => (cell_m - below) * (cell_m - below),
            _ => 0.0,
        }
    };
    axis(q[0], key.0, offset.0) + axis(q[1], key.1, offset.1) + axis(q[2], key.2, offset.2)
}

pub type VoxelHashMap<K, V> = HashMap<K, V, BuildHasherDefault<VoxelHasher>>;
pub type VoxelHashSet<K> = HashSet<K, BuildHasherDefault<VoxelHasher>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbours_are_each_offset_once_faces_first() {
        let mut seen: Vec<_> = NEIGHBOURS.to_vec();
        let moved = |d: &(i32, i32, i32)| (d.0 != 0) as i32 + (d.1 != 0) as i32 + (d.2 != 0) as i32;
        assert!(NEIGHBOURS.windows(2).all(|w| moved(&w[0]) <= moved(&w[1])));
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), 26);
        assert!(!seen.contains(&(0, 0, 0)));
    }

    #[test]
    fn gap2_is_the_distance_to_the_neighbouring_voxel() {
        // In voxel (0, 0, 0) of 1 m at (0.2, 0.7, 0.5): 0.2 m to x's lower face, 0.3 m to y's upper.
        let q = [0.2, 0.7, 0.5];
        assert_eq!(gap2(q, (0, 0, 0), 1.0, (0, 0, 0)), 0.0);
        assert!((gap2(q, (0, 0, 0), 1.0, (-1, 0, 0)) - 0.04).abs() < 1e-12);
        assert!((gap2(q, (0, 0, 0), 1.0, (-1, 1, 0)) - 0.13).abs() < 1e-12);
        assert!((gap2(q, (0, 0, 0), 1.0, (1, 1, 1)) - (0.64 + 0.09 + 0.25)).abs() < 1e-12);
    }

    #[test]
    fn downsampling_keeps_one_centroid_per_voxel_in_key_order() {
        let pts = [Vector3::new(1.2, 0.0, 0.0), Vector3::new(-0.7, 0.0, 0.0), Vector3::new(1.4, 0.0, 0.0)];
        let c = voxel_downsample(&pts, 0.5);
        assert_eq!(c.len(), 2);
        assert!((c[0].x + 0.7).abs() < 1e-12 && (c[1].x - 1.3).abs() < 1e-12, "{c:?}");
        assert_eq!(voxel_downsample(&pts, 0.0), pts.to_vec(), "no voxel size keeps every point");
        let every2 = voxel_downsample_every(&pts, 0.5, 2);
        assert!(every2.len() == 1 && (every2[0].x - 1.3).abs() < 1e-12, "the first and third points: {every2:?}");
        assert_eq!(key_of(&Vector3::new(-0.25, 0.5, 1.0), 2.0), (-1, 1, 2), "faces belong to the voxel above");
    }

    #[test]
    fn floor_i32_is_floor_then_cast() {
        let edges = [0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 1e-300, -1e-300, 2147483647.5, -2147483648.5, 3e9, -3e9];
        let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MAX, f64::MIN, f64::EPSILON];
        let steps = (-2000..2000).map(|i| f64::from(i) * 0.0137);
        for v in edges.into_iter().chain(specials).chain(steps) {
            assert_eq!(floor_i32(v), v.floor() as i32, "{v}");
        }
    }

    #[test]
    fn neighbouring_keys_spread_over_buckets() {
        let mut m: VoxelHashMap<(i32, i32, i32), u32> = VoxelHashMap::default();
        for x in -10..10 {
            for y in -10..10 {
                for z in -3..3 {
                    m.insert((x, y, z), 1);
                }
            }
        }
        assert_eq!(m.len(), 2400);
        assert_eq!(m.get(&(-10, 9, -3)), Some(&1));
        let hash = |k: (i32, i32, i32)| {
            let mut h = VoxelHasher::default();
            std::hash::Hash::hash(&k, &mut h);
            h.finish()
        };
        assert_ne!(hash((0, 0, 1)), hash((0, 1, 0)));
        assert_ne!(hash((1, 0, 0)), hash((0, 1, 0)));
        let hash_array = |k: [i32; 3]| {
            let mut h = VoxelHasher::default();
            std::hash::Hash::hash(&k, &mut h);
            h.finish()
        };
        assert_ne!(hash_array([0, 0, 1]), hash_array([0, 1, 0]));
        assert_ne!(hash_array([-1, 0, 0]), hash_array([0, 0, -1]));
    }
}
