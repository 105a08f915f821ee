//! The simulated Avia: the Risley pattern cast into the world from the moving sensor, with
//! range noise, reflectivity from albedo and incidence, range limits, several echoes where the
//! beam straddles an edge, and a label for every return. It is a [`PointSource`], so the mock
//! device packetizes and stamps it exactly as it does any other scene.

use crate::avia::{FiringRequest, PointSource};
use crate::rng::{hash2, SplitMix64};
use crate::sim::human::Body;
use crate::sim::imu::{ImuSim, GRAVITY_M_S2};
use crate::sim::motion::Motion;
use crate::sim::pattern::AviaPattern;
use crate::sim::scenario::AviaModel;
use crate::sim::shapes::{Hit, V3};
use crate::sim::world::World;
use nalgebra::{Isometry3, UnitQuaternion};
use starc_livox::data::{ImuSample, Return};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Label of an empty return.
pub const LABEL_EMPTY: u16 = u16::MAX;
/// Highest reflectivity byte of a diffuse (Lambertian) surface; above is retro-reflective.
const DIFFUSE_MAX: f64 = 150.0;

/// The labels of one point packet's returns, firing-major like the returns themselves.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PacketLabels {
    /// Device time of the packet's first firing.
    pub first_ns: u64,
    pub labels: Vec<u16>,
}

/// A simulated Avia on a moving platform.
pub struct AviaSim {
    world: Arc<World>,
    motion: Arc<dyn Motion>,
    model: AviaModel,
    imu: ImuSim,
    seed: u64,
    /// Where the labels of each filled packet go (the device owns the source, so the runner
    /// reads them through this).
    labels: Option<LabelSink>,
    /// Sub-beam offsets (azimuth, elevation) in degrees sampled across the beam's footprint.
    sub_beams: Vec<(f64, f64)>,
    /// Scratch for the echoes of one firing (kept to spare an allocation per firing).
    hits: Vec<(Hit, V3, V3)>,
    casts: Arc<AtomicU64>,
}

/// Labels shared between a source and whoever writes them out.
pub type LabelSink = Arc<Mutex<Vec<PacketLabels>>>;

impl AviaSim {
    pub fn new(world: Arc<World>, motion: Arc<dyn Motion>, model: AviaModel, imu: ImuSim, seed: u64) -> Self {
        let [h, v] = model.divergence_deg;
        let sub_beams = vec![(-h / 2.0, 0.0), (h / 2.0, 0.0), (0.0, v / 2.0)];
        Self {
            world,
            motion,
            model,
            imu,
            seed,
            labels: None,
            sub_beams,
            hits: Vec::new(),
            casts: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Collects the labels of every packet filled into `sink`.
    pub fn with_labels(mut self, sink: LabelSink) -> Self {
        self.labels = Some(sink);
        self
    }

    /// A counter of the rays cast, readable while the device owns the source.
    pub fn cast_counter(&self) -> Arc<AtomicU64> {
        self.casts.clone()
    }

    fn echo(&self, d_sensor: &V3, hit: &Hit, rng: &mut SplitMix64, d_world: &V3) -> Option<(Return, u16)> {
        let range = hit.t + rng.normal() * self.model.range_sigma_m;
        let albedo = f64::from(hit.albedo);
        // Dark surfaces fade out first: the return power falls as albedo / range^2.
        let max_range = self.model.max_range_m * albedo.min(1.0).sqrt();
        if range < self.model.min_range_m || range > max_range {
            return None;
        }
        let cos_i = hit.normal.dot(d_world).abs();
        let reflectivity = if albedo > 1.0 {
            (DIFFUSE_MAX + 1.0 + (albedo - 1.0) * 100.0).min(255.0)
        } else {
            (albedo * cos_i * DIFFUSE_MAX).clamp(1.0, DIFFUSE_MAX)
        };
        let p = d_sensor * range;
        Some((
            Return { x_m: p.x as f32, y_m: p.y as f32, z_m: p.z as f32, reflectivity: reflectivity as u8, tag: 0 },
            hit.label,
        ))
    }
}

/// Which of `n` distinct echoes (nearest first) is return `i` of `echoes`: first and last (dual),
/// first, middle and last (triple); none where there are too few.
fn echo_index(echoes: usize, n: usize, i: usize) -> Option<usize> {
    match (echoes, i) {
        _ if n == 0 => None,
        (_, 0) => Some(0),
        (3, 1) => (n > 2).then_some(1),
        _ => (n > 1 && i + 1 == echoes).then_some(n - 1),
    }
}

/// Appends a return and its label, or an empty return.
fn emit(out: &mut Vec<Return>, labels: &mut Vec<u16>, echo: Option<(Return, u16)>) {
    let (r, label) = echo.unwrap_or((Return::EMPTY, LABEL_EMPTY));
    out.push(r);
    labels.push(label);
}

/// Direction of a beam turned by small azimuth and elevation offsets (deg).
fn offset_direction(t_ns: u64, line: usize, d_az: f64, d_el: f64) -> V3 {
    let (az, el) = AviaPattern::angles_deg(t_ns, line);
    let (sa, ca) = (az + d_az).to_radians().sin_cos();
    let (se, ce) = (el + d_el).to_radians().sin_cos();
    V3::new(ce * ca, ce * sa, se)
}

impl PointSource for AviaSim {
    fn fill(&mut self, req: &FiringRequest, out: &mut Vec<Return>) {
        let echoes = req.echoes.max(1);
        let n = req.firings;
        let t_first = req.first_ns as f64 * 1e-9;
        let t_last = req.firing_ns(n.saturating_sub(1)) as f64 * 1e-9;
        let (pose_a, pose_b) = (self.motion.lidar_pose(t_first), self.motion.lidar_pose(t_last));
        // People move millimetres within one packet: pose them once.
        let bodies: Vec<Body> = self.world.bodies_at((t_first + t_last) / 2.0);
        let mut labels = Vec::with_capacity(n * echoes);
        let mut rng = SplitMix64::new(hash2(self.seed, req.first_ns));
        let max_cast = self.model.max_range_m;
        for k in 0..n {
            let t_ns = req.firing_ns(k);
            let line = AviaPattern::line_of(req, k);
            let f = if n > 1 { k as f64 / (n - 1) as f64 } else { 0.0 };
            let origin = pose_a.translation.vector.lerp(&pose_b.translation.vector, f);
            let rot: UnitQuaternion<f64> = pose_a.rotation.slerp(&pose_b.rotation, f);
            let d_sensor = offset_direction(t_ns, line, 0.0, 0.0);
            let d_world = rot * d_sensor;
            let centre = self.world.cast(&origin, &d_world, max_cast, &bodies);
            self.casts.fetch_add(1, Ordering::Relaxed);
            if echoes == 1 {
                emit(out, &mut labels, centre.and_then(|h| self.echo(&d_sensor, &h, &mut rng, &d_world)));
                continue;
            }
            // Several echoes: what the rest of the beam's footprint sees, nearest first, echoes
            // closer than the separation merged into the nearer one.
            let mut hits = std::mem::take(&mut self.hits);
            hits.clear();
            hits.extend(centre.map(|h| (h, d_sensor, d_world)));
            for &(da, de) in &self.sub_beams {
                let ds = offset_direction(t_ns, line, da, de);
                let dw = rot * ds;
                self.casts.fetch_add(1, Ordering::Relaxed);
                if let Some(h) = self.world.cast(&origin, &dw, max_cast, &bodies) {
                    hits.push((h, ds, dw));
                }
            }
            hits.sort_by(|a, b| a.0.t.total_cmp(&b.0.t));
            let separation = self.model.min_echo_separation_m;
            hits.dedup_by(|later, kept| later.0.t - kept.0.t < separation);
            for i in 0..echoes {
                let echo = echo_index(echoes, hits.len(), i)
                    .and_then(|k| hits.get(k))
                    .and_then(|(h, ds, dw)| self.echo(ds, h, &mut rng, dw))
                    .map(|(mut r, label)| {
                        r.tag = ((i as u8 + 1) & 0x3) << 4;
                        (r, label)
                    });
                emit(out, &mut labels, echo);
            }
            self.hits = hits;
        }
        if let Some(sink) = &self.labels {
            // A poisoned lock only means a writer panicked; the labels are still whole.
            let mut guard = sink.lock().unwrap_or_else(|e| e.into_inner());
            guard.push(PacketLabels { first_ns: req.first_ns, labels });
        }
    }

    fn imu(&mut self, t_ns: u64) -> ImuSample {
        let m = self.imu.sample(t_ns as f64 * 1e-9);
        let g = |v: V3| [(v.x / GRAVITY_M_S2) as f32, (v.y / GRAVITY_M_S2) as f32, (v.z / GRAVITY_M_S2) as f32];
        ImuSample {
            gyro_rad_s: [m.gyro_rad_s.x as f32, m.gyro_rad_s.y as f32, m.gyro_rad_s.z as f32],
            acc_g: g(m.accel_m_s2),
        }
    }
}

/// The Avia's internal IMU in its LiDAR frame (as in FAST-LIO's Avia configuration: LiDAR at
/// (0.04165, 0.02326, -0.0284) m in the IMU frame, axes aligned).
pub fn avia_lidar_imu() -> Isometry3<f64> {
    Isometry3::translation(-0.04165, -0.02326, 0.0284)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn echoes_are_first_last_or_first_middle_last() {
        let picks = |echoes, n| (0..echoes).map(|i| echo_index(echoes, n, i)).collect::<Vec<_>>();
        assert_eq!(picks(2, 0), [None, None]);
        assert_eq!(picks(2, 1), [Some(0), None]);
        assert_eq!(picks(2, 4), [Some(0), Some(3)]);
        assert_eq!(picks(3, 1), [Some(0), None, None]);
        assert_eq!(picks(3, 2), [Some(0), None, Some(1)]);
        assert_eq!(picks(3, 4), [Some(0), Some(1), Some(3)]);
    }
}
