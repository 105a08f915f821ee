//! The rig's pose in the world: composition of the registration with the rig's odometry, and
//! drift correction applied in bounded steps.
//!
//! Frames: `w` the world (the robot's map frame, whatever device booted first), `o` the rig's
//! odometry frame (where its LIO started), `fpv` the rig's LiDAR. The rig's LIO gives `oT_fpv(t)`;
//! an accepted registration gives `wT_fpv(tk)`, hence `wT_o = wT_fpv(tk) · oT_fpv(tk)⁻¹` and
//! `wT_fpv(t) = wT_o · oT_fpv(t) = wT_fpv(tk) · ΔT_fpv(tk → t)` (the paper's composition).
//! A later registration gives a new `wT_o` (the LIO has drifted); the applied one moves towards it
//! by at most `max_step_m` / `max_step_deg` per rendered frame, measured at the rig, so the
//! overlay slides instead of jumping.

use super::buffer::PoseBuffer;
use crate::PipelineError;
use nalgebra::{Isometry3, Matrix6, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector6};
use serde::{Deserialize, Serialize};

/// Settings (TOML, `config/world_pose.toml`); every field has a default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorldPoseConfig {
    /// Rig odometry poses kept (10 s at 200 Hz by default): a registration must refer to a time
    /// still inside, and so must every render time.
    pub buffer_len: usize,
    /// Largest correction applied per rendered frame, at the rig (translation, m; rotation, deg).
    /// 5 mm and 0.1 deg per frame at 30 Hz: 15 cm/s and 3 deg/s, below what a viewer notices
    /// against a walking responder's own motion, and far above LIO drift rates.
    pub max_step_m: f64,
    pub max_step_deg: f64,
    /// A correction larger than this is applied at once: it is a re-localisation, not drift, and
    /// sliding there would show a wrong overlay for seconds.
    pub snap_m: f64,
    pub snap_deg: f64,
    /// A registration farther than this from the pose in use is refused: LIO does not drift
    /// metres in one re-registration period, so such a result is a false match (a symmetric
    /// room, a corridor), not a correction.
    pub refuse_m: f64,
    pub refuse_deg: f64,
    /// Per-direction fusion ([`WorldPose::push_registration_constrained`]): along each
    /// eigen-direction of the registration's normalised information matrix (eigenvalue λ, unit-free,
    /// 0 to 1/3), the correction takes the share λ / (λ + `half_gain_info`) of what the
    /// registration says and keeps the LIO's pose for the rest. A hall's axis (λ ≈ 0.01) then moves
    /// by a sixth of a registration's claim, a room's well-seen walls (λ ≈ 0.1-0.3) by two thirds
    /// or more; repeated registrations converge where they agree. 0: follow every registration.
    pub half_gain_info: f64,
    /// Innovation gate (0: off): a registration that would slide the correction is refused when
    /// it moves the rig (against the latest target, at the rig's latest pose) by more than
    /// `gate_m + gate_m_per_s` times the seconds since the last registration taken. The LIO
    /// drifts centimetres per second at most, so a larger claim over a short time is more likely
    /// the registration's error (a window bent by the LIO, a hall's axis) than drift; the bound
    /// grows with time, so a real drift is taken once it has had time to build up.
    pub gate_m: f64,
    pub gate_m_per_s: f64,
}

impl Default for WorldPoseConfig {
    fn default() -> Self {
        Self {
            buffer_len: 2000,
            max_step_m: 0.005,
            max_step_deg: 0.1,
            snap_m: 1.0,
            snap_deg: 10.0,
            refuse_m: 3.0,
            refuse_deg: 30.0,
            half_gain_info: 0.05,
            gate_m: 0.0,
            gate_m_per_s: 0.0,
        }
    }
}

impl WorldPoseConfig {
    pub fn from_toml(text: &str) -> Result<Self, PipelineError> {
        let c: Self = toml::from_str(text)
            .map_err(|e| PipelineError::BadFile { format: "world pose config", reason: e.to_string() })?;
        let positive = [c.max_step_m, c.max_step_deg, c.snap_m, c.snap_deg, c.refuse_m, c.refuse_deg];
        if c.buffer_len < 2
            || positive.iter().any(|v| !(v.is_finite() && *v > 0.0))
            || [c.half_gain_info, c.gate_m, c.gate_m_per_s].iter().any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return Err(PipelineError::BadFile {
                format: "world pose config",
                reason:
                    "buffer_len must be at least 2, the steps and snap limits positive, half_gain_info not negative"
                        .into(),
            });
        }
        Ok(c)
    }
}

/// How well a registration pins down each direction of the rig's pose: the normalised
/// point-to-plane information matrix in the rig's LiDAR frame (`AlignMetrics::information`),
/// over (rotation about `centre_m` times `radius_m`, translation).
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint {
    pub information: Matrix6<f64>,
    pub centre_m: Vector3<f64>,
    pub radius_m: f64,
}

impl Constraint {
    /// From the aligner's report (`AlignMetrics::information`, `information_centre_m`,
    /// `information_radius_m`); `None` when it is not finite or the radius is not positive.
    pub fn from_rows(rows: &[[f64; 6]; 6], centre_m: [f64; 3], radius_m: f64) -> Option<Self> {
        let information = Matrix6::from_fn(|i, j| rows.get(i).and_then(|r| r.get(j)).copied().unwrap_or(f64::NAN));
        let ok = information.iter().all(|v| v.is_finite())
            && centre_m.iter().all(|v| v.is_finite())
            && radius_m.is_finite()
            && radius_m > 0.0;
        ok.then(|| Self { information, centre_m: Vector3::from(centre_m), radius_m })
    }

    /// The part of `e` (a correction of the rig's pose, applied on the right: `pose · e`) that
    /// this constraint supports: per eigen-direction the share λ / (λ + `half_gain`).
    pub fn filter(&self, e: &Isometry3<f64>, half_gain: f64) -> Isometry3<f64> {
        if half_gain <= 0.0 {
            return *e;
        }
        let c = self.centre_m;
        let rho = self.radius_m;
        // e as a twist about c: p -> c + R (p - c) + t_c.
        let w = e.rotation.scaled_axis();
        let t_c = e.rotation * c + e.translation.vector - c;
        let x = Vector6::new(w.x * rho, w.y * rho, w.z * rho, t_c.x, t_c.y, t_c.z);
        let eig = SymmetricEigen::new(self.information);
        let gains = eig.eigenvalues.map(|l| {
            let l = l.max(0.0);
            l / (l + half_gain)
        });
        let kept = eig.eigenvectors * Matrix6::from_diagonal(&gains) * eig.eigenvectors.transpose() * x;
        let rot = UnitQuaternion::from_scaled_axis(Vector3::new(kept[0], kept[1], kept[2]) / rho);
        let t = c + Vector3::new(kept[3], kept[4], kept[5]) - rot * c;
        Isometry3::from_parts(Translation3::from(t), rot)
    }
}

/// Whether the rig's pose in the world is known yet.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum WorldPoseState {
    /// No accepted registration yet: the rig runs in its odometry frame, nothing is rendered.
    Unaligned,
    /// Aligned; the correction in use has reached the latest registration.
    Aligned,
    /// Aligned; the correction in use is still sliding towards the latest registration.
    Correcting,
}

/// What a registration did to the world pose.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum RegistrationOutcome {
    /// The first one: applied at once.
    Initial,
    /// Within the snap limits: the correction slides to it frame by frame.
    Sliding,
    /// Past the snap limits (a re-localisation): applied at once.
    Snapped,
    /// Past the refuse limits: ignored as a false match.
    Refused,
}

/// What one frame's step did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct CorrectionStep {
    /// The step applied at the rig (m, deg).
    pub step_m: f64,
    pub step_deg: f64,
    /// What is left after it (m, deg).
    pub remaining_m: f64,
    pub remaining_deg: f64,
}

/// The rig's world pose: its odometry, the correction in use (`wT_o`) and the target one.
#[derive(Clone, Debug)]
pub struct WorldPose {
    config: WorldPoseConfig,
    odom: PoseBuffer,
    applied: Option<Isometry3<f64>>,
    target: Option<Isometry3<f64>>,
    /// Registrations taken, how many of them snapped, how many were refused (of those, how
    /// many by the innovation gate).
    pub registrations: u32,
    pub snaps: u32,
    pub refused: u32,
    pub gated: u32,
    /// When the last registration was taken (for the gate).
    last_taken_ns: Option<u64>,
}

impl WorldPose {
    pub fn new(config: WorldPoseConfig) -> Self {
        Self {
            odom: PoseBuffer::new(config.buffer_len),
            config,
            applied: None,
            target: None,
            registrations: 0,
            snaps: 0,
            refused: 0,
            gated: 0,
            last_taken_ns: None,
        }
    }

    pub fn state(&self) -> WorldPoseState {
        match (&self.applied, &self.target) {
            (Some(a), Some(t)) if a != t => WorldPoseState::Correcting,
            (Some(_), _) => WorldPoseState::Aligned,
            _ => WorldPoseState::Unaligned,
        }
    }

    /// Forgets the alignment (the rig is placed nowhere again), keeping the odometry: for a
    /// registration that later evidence shows was wrong.
    pub fn lose(&mut self) {
        self.applied = None;
        self.target = None;
        self.last_taken_ns = None;
    }

    /// The rig's odometry `oT_fpv` at `t_ns` (from its LIO; strictly increasing times).
    pub fn push_odometry(&mut self, t_ns: u64, o_t_fpv: Isometry3<f64>) -> Result<(), PipelineError> {
        self.odom.push(t_ns, o_t_fpv)
    }

    pub fn odometry(&self) -> &PoseBuffer {
        &self.odom
    }

    /// An accepted registration: the rig's LiDAR pose in the world at `t_ns` (the time the
    /// registered window refers to, inside the odometry buffer). The first one is applied at once;
    /// later ones become the target the correction slides to, or snap past the snap limits, or
    /// are refused past the refuse limits (measured at the rig's latest odometry pose).
    pub fn push_registration(
        &mut self,
        t_ns: u64,
        w_t_fpv: Isometry3<f64>,
    ) -> Result<RegistrationOutcome, PipelineError> {
        let o_t_fpv = self.odom.at(t_ns)?;
        let w_t_o = unit(&(unit(&w_t_fpv) * o_t_fpv.inverse()));
        let c = &self.config;
        let outcome = match (&self.applied, self.odom.latest()) {
            (None, _) | (_, None) => RegistrationOutcome::Initial,
            (Some(applied), Some((_, now))) => {
                let (m, deg) = at_rig(applied, &w_t_o, &now);
                if m > c.refuse_m || deg > c.refuse_deg {
                    RegistrationOutcome::Refused
                } else if m > c.snap_m || deg > c.snap_deg {
                    RegistrationOutcome::Snapped
                } else if self.gated_out(t_ns, &w_t_o, &now) {
                    self.gated += 1;
                    RegistrationOutcome::Refused
                } else {
                    RegistrationOutcome::Sliding
                }
            }
        };
        match outcome {
            RegistrationOutcome::Refused => {
                self.refused += 1;
                return Ok(outcome);
            }
            RegistrationOutcome::Initial => self.applied = Some(w_t_o),
            RegistrationOutcome::Snapped => {
                self.snaps += 1;
                self.applied = Some(w_t_o);
            }
            RegistrationOutcome::Sliding => {}
        }
        self.registrations += 1;
        self.target = Some(w_t_o);
        self.last_taken_ns = Some(t_ns);
        Ok(outcome)
    }

    /// Whether the innovation gate refuses `w_t_o` (see [`WorldPoseConfig::gate_m`]).
    fn gated_out(&self, t_ns: u64, w_t_o: &Isometry3<f64>, now: &Isometry3<f64>) -> bool {
        let c = &self.config;
        let (Some(target), Some(last)) = (self.target, self.last_taken_ns) else { return false };
        if c.gate_m <= 0.0 {
            return false;
        }
        let (m, _) = at_rig(&target, w_t_o, now);
        m > c.gate_m + c.gate_m_per_s * t_ns.saturating_sub(last) as f64 * 1e-9
    }

    /// Like [`Self::push_registration`], but a registration that would slide the correction moves
    /// it only along the directions `constraint` pins down (see
    /// [`WorldPoseConfig::half_gain_info`]); the rest stays with the LIO. The correction is taken
    /// from the latest target (not the one still sliding), so repeated registrations that agree
    /// converge on it. Initial, snapped and refused registrations behave as before.
    pub fn push_registration_constrained(
        &mut self,
        t_ns: u64,
        w_t_fpv: Isometry3<f64>,
        constraint: &Constraint,
    ) -> Result<RegistrationOutcome, PipelineError> {
        let base = self.target.or(self.applied);
        let Some(base) = base else { return self.push_registration(t_ns, w_t_fpv) };
        let w_t_fpv = unit(&w_t_fpv);
        let o_t_fpv = self.odom.at(t_ns)?;
        let predicted = base * o_t_fpv;
        // Classified on the full registration (snap and refuse judge what it claims); a sliding
        // one only sets the target, which is then replaced by its supported part.
        let outcome = self.push_registration(t_ns, w_t_fpv)?;
        if outcome == RegistrationOutcome::Sliding {
            let kept = constraint.filter(&(predicted.inverse() * w_t_fpv), self.config.half_gain_info);
            self.target = Some(unit(&(predicted * kept * o_t_fpv.inverse())));
        }
        Ok(outcome)
    }

    /// Moves the correction in use one rendered frame towards the latest registration, by at most
    /// the configured step at the rig's latest odometry pose. Call once per rendered frame.
    pub fn step_frame(&mut self) -> CorrectionStep {
        let (Some(applied), Some(target), Some((_, now))) = (self.applied, self.target, self.odom.latest()) else {
            return CorrectionStep::default();
        };
        // The correction seen from the rig: E = (applied·now)⁻¹ · (target·now).
        let from = applied * now;
        let e = from.inverse() * (target * now);
        let (m, deg) = (e.translation.vector.norm(), e.rotation.angle().to_degrees());
        let f = [(m, self.config.max_step_m), (deg, self.config.max_step_deg)]
            .iter()
            .map(|&(have, max)| if have > max { max / have } else { 1.0 })
            .fold(1.0f64, f64::min);
        let (step, remaining) = if f >= 1.0 {
            self.applied = Some(target);
            (e, Isometry3::identity())
        } else {
            let step = Isometry3::from_parts(
                Translation3::from(e.translation.vector * f),
                UnitQuaternion::from_scaled_axis(e.rotation.scaled_axis() * f),
            );
            self.applied = Some(unit(&(from * step * now.inverse())));
            (step, step.inverse() * e)
        };
        CorrectionStep {
            step_m: step.translation.vector.norm(),
            step_deg: step.rotation.angle().to_degrees(),
            remaining_m: remaining.translation.vector.norm(),
            remaining_deg: remaining.rotation.angle().to_degrees(),
        }
    }

    /// `wT_fpv` at `t_ns` (a render time inside the odometry buffer): `None` while unaligned;
    /// an error outside the buffer.
    pub fn world_pose(&self, t_ns: u64) -> Result<Option<Isometry3<f64>>, PipelineError> {
        let o_t_fpv = self.odom.at(t_ns)?;
        Ok(self.applied.map(|w_t_o| w_t_o * o_t_fpv))
    }

    /// The correction in use (`wT_o`), once aligned.
    pub fn correction(&self) -> Option<Isometry3<f64>> {
        self.applied
    }

    /// The correction the one in use is sliding towards (the latest registration's `wT_o`).
    pub fn target_correction(&self) -> Option<Isometry3<f64>> {
        self.target
    }
}

/// The pose with its rotation renormalised. A quaternion off unit length (a guess interpolated
/// by lerp, say) scales every vector it turns by its squared norm, and products compound it: a
/// 0.996 guess became 0.973 after a dozen registrations in the drift bench and put the rig metres
/// off; so every pose that enters, and every product kept, is renormalised.
pub(crate) fn unit(p: &Isometry3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(p.translation, UnitQuaternion::new_normalize(*p.rotation.quaternion()))
}

/// How far apart two world corrections put the rig at odometry pose `now` (m, deg).
fn at_rig(a: &Isometry3<f64>, b: &Isometry3<f64>, now: &Isometry3<f64>) -> (f64, f64) {
    let e = (a * now).inverse() * (b * now);
    (e.translation.vector.norm(), e.rotation.angle().to_degrees())
}
