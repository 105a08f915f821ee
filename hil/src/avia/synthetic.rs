//! A synthetic scene: an 8 x 6 x 3 m room with a box in it, seen by an Avia at a fixed pose
//! through a rosette (Risley-prism-like) scan pattern of 6 lines.
//!
//! Room frame: x in [0, 8] (the Avia looks along +x), y in [-3, 3], z in [0, 3] (floor at 0).
//! The Avia sits at (0.6, 0.2, 1.1) with its axes along the room's. A 1 m box stands on the floor
//! at x 3.5-4.5, y -1.3 to -0.3. Rays through the open doorway in the far wall or the open window
//! in the left wall return nothing (empty returns). Ranges carry 1 cm (1 sigma) noise and
//! reflectivity depends on the surface. Every return is a pure function of (seed, firing time,
//! line), so a run is reproducible whatever the packet boundaries.

use crate::avia::source::{FiringRequest, PointSource};
use crate::rng::{hash2, SplitMix64};
use starc_livox::data::packet::AVIA_LINES;
use starc_livox::data::{ImuSample, Return};

/// Horizontal half field of view of the Avia (70.4 deg total).
pub const HALF_FOV_H_DEG: f64 = 35.2;
/// Vertical half field of view of the Avia (77.2 deg total).
pub const HALF_FOV_V_DEG: f64 = 38.6;
/// Rotation rates of the two virtual prisms (counter-rotating, incommensurate: the pattern never
/// repeats, like the Avia's non-repetitive scan).
const PRISM_HZ: [f64; 2] = [83.17, -57.29];
/// Angular spread of the 6 lines (degrees per line, horizontal and vertical).
const LINE_STEP_DEG: [f64; 2] = [0.3, 0.9];
/// Range noise, 1 sigma.
const RANGE_SIGMA_M: f64 = 0.01;
/// A beam this close to a box edge also returns from what lies behind (dual/triple returns).
const EDGE_M: f64 = 0.03;
/// Echoes closer than this merge into one.
const MIN_ECHO_SEPARATION_M: f64 = 0.3;
const IMU_SALT: u64 = 0x1A2B_3C4D_5E6F_7081;

#[derive(Clone, Copy, Debug, PartialEq)]
struct Aabb {
    min: [f64; 3],
    max: [f64; 3],
}

/// An opening in a wall: rays leaving the room through it find nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Opening {
    /// The wall: axis (0 x, 1 y) and side (true: the max side).
    axis: usize,
    max_side: bool,
    /// Extent along the wall's first free axis and along z.
    along: (f64, f64),
    z: (f64, f64),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Surface {
    Floor,
    Ceiling,
    SideWall,
    FarWall,
    BackWall,
    Box,
}

impl Surface {
    fn reflectivity(self) -> f64 {
        match self {
            Self::Floor => 25.0,
            Self::Ceiling => 60.0,
            Self::SideWall => 75.0,
            Self::FarWall => 90.0,
            Self::BackWall => 70.0,
            Self::Box => 140.0,
        }
    }
}

/// The synthetic room scene.
#[derive(Clone, Debug)]
pub struct SyntheticScene {
    seed: u64,
    sensor: [f64; 3],
    room: Aabb,
    obstacle: Aabb,
    openings: [Opening; 2],
}

impl SyntheticScene {
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            sensor: [0.6, 0.2, 1.1],
            room: Aabb { min: [0.0, -3.0, 0.0], max: [8.0, 3.0, 3.0] },
            obstacle: Aabb { min: [3.5, -1.3, 0.0], max: [4.5, -0.3, 1.0] },
            openings: [
                // Doorway in the far wall.
                Opening { axis: 0, max_side: true, along: (0.8, 1.8), z: (0.0, 2.1) },
                // Window in the left wall.
                Opening { axis: 1, max_side: true, along: (5.5, 7.5), z: (1.0, 2.2) },
            ],
        }
    }

    /// The beam direction (unit vector, sensor frame) of `line` at device time `t_ns`.
    pub fn direction(t_ns: u64, line: u8) -> [f64; 3] {
        let (az, el) = Self::angles_deg(t_ns, line);
        let (sa, ca) = az.to_radians().sin_cos();
        let (se, ce) = el.to_radians().sin_cos();
        [ce * ca, ce * sa, se]
    }

    /// (azimuth, elevation) in degrees of `line` at `t_ns`: the sum of two counter-rotating
    /// prism deflections (a rose curve) scaled to the field of view, plus the line's offset.
    pub fn angles_deg(t_ns: u64, line: u8) -> (f64, f64) {
        // Phases from whole and fractional seconds separately keep precision over long runs.
        let secs = (t_ns / 1_000_000_000) as f64;
        let frac = (t_ns % 1_000_000_000) as f64 * 1e-9;
        let phase = |hz: f64| std::f64::consts::TAU * ((hz * secs).fract() + hz * frac);
        let (s1, c1) = phase(PRISM_HZ[0]).sin_cos();
        let (s2, c2) = (phase(PRISM_HZ[1]) + 0.7).sin_cos();
        let (u, v) = (0.5 * (c1 + c2), 0.5 * (s1 + s2));
        let k = f64::from(line) - (f64::from(AVIA_LINES) - 1.0) / 2.0;
        let spread = (f64::from(AVIA_LINES) - 1.0) / 2.0;
        let az = (HALF_FOV_H_DEG - spread * LINE_STEP_DEG[0]) * u + k * LINE_STEP_DEG[0];
        let el = (HALF_FOV_V_DEG - spread * LINE_STEP_DEG[1]) * v + k * LINE_STEP_DEG[1];
        (az, el)
    }

    /// Distance to the first surface along `d` and that surface, or `None` when the ray leaves
    /// through an opening. `skip_box` looks past the box.
    fn cast(&self, d: [f64; 3], skip_box: bool) -> Option<(f64, Surface)> {
        let o = self.sensor;
        // Leaving the room: the nearest bounding plane ahead.
        let mut t_room = f64::INFINITY;
        let mut hit = (0usize, false);
        for axis in 0..3 {
            if d[axis] > 1e-12 {
                let t = (self.room.max[axis] - o[axis]) / d[axis];
                if t < t_room {
                    t_room = t;
                    hit = (axis, true);
                }
            } else if d[axis] < -1e-12 {
                let t = (self.room.min[axis] - o[axis]) / d[axis];
                if t < t_room {
                    t_room = t;
                    hit = (axis, false);
                }
            }
        }
        if !t_room.is_finite() {
            return None;
        }
        if !skip_box {
            if let Some(t) = self.enter_box(o, d) {
                if t < t_room {
                    return Some((t, Surface::Box));
                }
            }
        }
        let p = [o[0] + t_room * d[0], o[1] + t_room * d[1], o[2] + t_room * d[2]];
        for w in &self.openings {
            if w.axis == hit.0 && w.max_side == hit.1 {
                let along = p[1 - w.axis];
                if along >= w.along.0 && along <= w.along.1 && p[2] >= w.z.0 && p[2] <= w.z.1 {
                    return None;
                }
            }
        }
        let surface = match hit {
            (2, false) => Surface::Floor,
            (2, true) => Surface::Ceiling,
            (0, true) => Surface::FarWall,
            (0, false) => Surface::BackWall,
            _ => Surface::SideWall,
        };
        Some((t_room, surface))
    }

    /// Entry distance into the box (slab method), if ahead of the sensor.
    fn enter_box(&self, o: [f64; 3], d: [f64; 3]) -> Option<f64> {
        let (mut t_in, mut t_out) = (0.0f64, f64::INFINITY);
        for axis in 0..3 {
            let (lo, hi) = (self.obstacle.min[axis], self.obstacle.max[axis]);
            if d[axis].abs() < 1e-12 {
                if o[axis] < lo || o[axis] > hi {
                    return None;
                }
                continue;
            }
            let (a, b) = ((lo - o[axis]) / d[axis], (hi - o[axis]) / d[axis]);
            t_in = t_in.max(a.min(b));
            t_out = t_out.min(a.max(b));
        }
        (t_out >= t_in && t_in > 0.0).then_some(t_in)
    }

    /// Whether a point on the box lies within `EDGE_M` of one of its edges.
    fn near_box_edge(&self, p: [f64; 3]) -> bool {
        let close = (0..3)
            .filter(|&a| (p[a] - self.obstacle.min[a]).abs() < EDGE_M || (p[a] - self.obstacle.max[a]).abs() < EDGE_M)
            .count();
        close >= 2
    }

    fn make_return(d: [f64; 3], range: f64, surface: Surface, rng: &mut SplitMix64, tag: u8) -> Return {
        let r = range + RANGE_SIGMA_M * rng.normal();
        let refl = (surface.reflectivity() + 4.0 * rng.normal()).clamp(1.0, 255.0);
        Return {
            x_m: (d[0] * r) as f32,
            y_m: (d[1] * r) as f32,
            z_m: (d[2] * r) as f32,
            reflectivity: refl.round() as u8,
            tag,
        }
    }

    /// The returns of one firing, `echoes` of them, appended to `out`.
    pub fn firing(&self, t_ns: u64, line: u8, echoes: usize, out: &mut Vec<Return>) {
        let d = Self::direction(t_ns, line);
        let mut rng = SplitMix64::new(hash2(self.seed, t_ns ^ (u64::from(line) << 60)));
        let tag = |echo: usize| if echoes > 1 { ((echo as u8 + 1) & 0b11) << 4 } else { 0 };
        let start = out.len();
        if let Some((range, surface)) = self.cast(d, false) {
            out.push(Self::make_return(d, range, surface, &mut rng, tag(0)));
            if echoes > 1 && surface == Surface::Box {
                let p = [self.sensor[0] + range * d[0], self.sensor[1] + range * d[1], self.sensor[2] + range * d[2]];
                if self.near_box_edge(p) {
                    // Echoes closer than the pulse can separate merge into the first.
                    match self.cast(d, true) {
                        Some((behind, s)) if behind - range > MIN_ECHO_SEPARATION_M => {
                            out.push(Self::make_return(d, behind, s, &mut rng, tag(1)));
                        }
                        _ => {}
                    }
                }
            }
        }
        out.resize(start + echoes, Return::EMPTY);
    }
}

impl PointSource for SyntheticScene {
    fn fill(&mut self, req: &FiringRequest, out: &mut Vec<Return>) {
        out.reserve(req.firings * req.echoes);
        for k in 0..req.firings {
            let line = ((req.first_index + k as u64) % u64::from(AVIA_LINES)) as u8;
            self.firing(req.firing_ns(k), line, req.echoes, out);
        }
    }

    /// At rest: 1 g up, gyro noise only.
    fn imu(&mut self, t_ns: u64) -> ImuSample {
        let mut rng = SplitMix64::new(hash2(self.seed ^ IMU_SALT, t_ns));
        let mut n = |sigma: f64| (sigma * rng.normal()) as f32;
        ImuSample { gyro_rad_s: [n(0.002), n(0.002), n(0.002)], acc_g: [n(0.003), n(0.003), 1.0 + n(0.003)] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(first_index: u64, firings: usize, echoes: usize) -> FiringRequest {
        FiringRequest { first_index, first_ns: 1_000_000 + first_index * 4167, interval_ns: 4167, firings, echoes }
    }

    #[test]
    fn pattern_stays_in_the_field_of_view_and_covers_it() {
        let (mut min_az, mut max_az, mut min_el, mut max_el) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        // A 6 x 6 grid over the FOV; count the cells hit in 0.5 s.
        let mut cells = [[false; 6]; 6];
        for k in 0..120_000u64 {
            let (az, el) = SyntheticScene::angles_deg(k * 4167, (k % 6) as u8);
            assert!(az.abs() <= HALF_FOV_H_DEG + 1e-9 && el.abs() <= HALF_FOV_V_DEG + 1e-9, "{az} {el}");
            min_az = min_az.min(az);
            max_az = max_az.max(az);
            min_el = min_el.min(el);
            max_el = max_el.max(el);
            let i = (((az + HALF_FOV_H_DEG) / (2.0 * HALF_FOV_H_DEG)) * 6.0).clamp(0.0, 5.0) as usize;
            let j = (((el + HALF_FOV_V_DEG) / (2.0 * HALF_FOV_V_DEG)) * 6.0).clamp(0.0, 5.0) as usize;
            cells[i][j] = true;
        }
        assert!(max_az - min_az > 60.0 && max_el - min_el > 65.0, "{min_az} {max_az} {min_el} {max_el}");
        // A disc covers the inner cells; the corners of the rectangle stay dark, as on an Avia.
        let hit = cells.iter().flatten().filter(|&&c| c).count();
        assert!(hit >= 28, "{hit} cells of 36");
    }

    #[test]
    fn returns_hit_the_room_the_box_and_sometimes_nothing() {
        let mut scene = SyntheticScene::new(7);
        let mut out = Vec::new();
        let r = req(0, 96 * 2500, 1);
        scene.fill(&r, &mut out);
        assert_eq!(out.len(), 96 * 2500);
        let empty = out.iter().filter(|p| **p == Return::EMPTY).count();
        let boxed = out.iter().filter(|p| p.reflectivity > 120).count();
        assert!(empty > 100 && empty < out.len() / 5, "{empty} empty");
        assert!(boxed > 1000, "{boxed} box returns");
        for p in out.iter().filter(|p| **p != Return::EMPTY) {
            let range = (p.x_m * p.x_m + p.y_m * p.y_m + p.z_m * p.z_m).sqrt();
            assert!(range > 1.0 && range < 8.5, "{p:?}");
            assert!(p.x_m > 0.0);
            assert_eq!(p.tag, 0);
        }
    }

    #[test]
    fn multi_returns_behind_box_edges_and_tags() {
        let mut scene = SyntheticScene::new(7);
        let mut out = Vec::new();
        scene.fill(&req(0, 30 * 8000, 3), &mut out);
        let second = out.chunks_exact(3).filter(|f| f[1] != Return::EMPTY).count();
        assert!(second > 10, "{second} second returns");
        for f in out.chunks_exact(3) {
            assert_eq!(f[2], Return::EMPTY);
            if f[0] != Return::EMPTY {
                assert_eq!(f[0].tag, 0x10);
            }
            if f[1] != Return::EMPTY {
                assert_eq!(f[1].tag, 0x20);
                let r = |p: &Return| (p.x_m * p.x_m + p.y_m * p.y_m + p.z_m * p.z_m).sqrt();
                assert!(r(&f[1]) > r(&f[0]));
            }
        }
    }

    #[test]
    fn deterministic_per_seed_and_independent_of_batching() {
        let mut a = SyntheticScene::new(3);
        let mut b = SyntheticScene::new(3);
        let mut one = Vec::new();
        a.fill(&req(0, 192, 1), &mut one);
        let mut two = Vec::new();
        b.fill(&req(0, 96, 1), &mut two);
        b.fill(&req(96, 96, 1), &mut two);
        assert_eq!(one, two);
        let mut c = SyntheticScene::new(4);
        let mut three = Vec::new();
        c.fill(&req(0, 192, 1), &mut three);
        assert_ne!(one, three);
        assert_eq!(a.imu(5), b.imu(5));
        let g = a.imu(10).acc_g[2];
        assert!((g - 1.0).abs() < 0.05);
    }
}
