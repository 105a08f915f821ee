//! The LIO's health: which scans may correct the state, when the IMU alone carries it, and when
//! the filter counts itself lost and widens its search to find the map again.
//!
//! FAST-LIO2 applies every update it computes; in a long corridor or after a scan of sky, the
//! update pulls the state along directions the scan does not see, and the map that follows is
//! built from that wrong pose. Here a scan's update is judged first: too few plane matches, a
//! large residual, or a correction far beyond what the IMU's prediction allows, and the scan is
//! refused (the state keeps the IMU's prediction and the scan stays out of the map). Directions
//! the scan does not constrain never take an update at all (see `update.rs`).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HealthConfig {
    /// A scan with fewer plane matches than this cannot correct the state.
    pub min_matched: usize,
    /// A scan whose update did not settle and matched fewer than this share of its points is
    /// refused (a glitch, a scan from the wrong place); a settled update into new, unmapped
    /// space may match fewer and is kept.
    pub min_match_ratio: f64,
    /// RMS point-to-plane residual above which a scan is refused.
    pub max_rms_m: f64,
    /// A correction of the IMU's prediction larger than this (per scan) is refused.
    pub max_correction_m: f64,
    pub max_correction_deg: f64,
    /// After refusing scans for this long the filter is lost: the next scans are matched with a
    /// wider search and an inflated covariance until one is accepted.
    pub max_ride_s: f64,
    /// A filter lost only for want of matches (blind: a wall inside the minimum range, a turn
    /// in place) while the base's wheels measure widens its search and uncertainty as one whose
    /// scans contradicted it. false: nothing contradicted its prediction and the wheels and gyro
    /// carried it, so the uncertainty it propagated is the honest one; widened, the few matches
    /// of the first scan back move it as far as they like. Without wheels it always widens.
    pub blind_ride_widens: bool,
    /// A scan that corrected the state is still `degenerate` where the filter's own 1-sigma
    /// position uncertainty afterwards (the root of its covariance's trace) exceeds this: scans
    /// weighed little (a small view on fine voxels, a loose fit) hold the pose loosely while
    /// every direction still takes an update, and the error grows unseen (docs/lio.md, "Health
    /// from the filter's own uncertainty"). 0: off.
    pub max_pos_sigma_m: f64,
}

impl Default for HealthConfig {
    fn default() -> Self {
        Self {
            min_matched: 30,
            min_match_ratio: 0.5,
            max_rms_m: 0.15,
            max_correction_m: 0.3,
            max_correction_deg: 5.0,
            max_ride_s: 1.0,
            blind_ride_widens: false,
            max_pos_sigma_m: 0.1,
        }
    }
}

impl HealthConfig {
    pub fn validate(&self) -> Result<(), String> {
        let finite = [
            ("health.min_match_ratio", self.min_match_ratio),
            ("health.max_rms_m", self.max_rms_m),
            ("health.max_correction_m", self.max_correction_m),
            ("health.max_correction_deg", self.max_correction_deg),
            ("health.max_ride_s", self.max_ride_s),
            ("health.max_pos_sigma_m", self.max_pos_sigma_m),
        ];
        for (name, v) in finite {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be a number >= 0, not {v}"));
            }
        }
        Ok(())
    }
}

/// How the filter stands after a scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Health {
    /// The scan corrected every direction of the pose.
    Tracking,
    /// The scan corrected the state, but some directions took no update (see
    /// [`crate::lio::UpdateReport::weak_directions`]), or the filter stays unsure of its position
    /// afterwards ([`uncertain_axes`]); `weak_axes` names them.
    Degenerate,
    /// The scan was refused; the IMU carries the state.
    ImuOnly,
    /// The scan was refused; the base's wheels and the IMU carry the state.
    WheelOnly,
    /// Scans have been refused for longer than `max_ride_s`.
    Lost,
}

impl Health {
    /// Every health, in order of what the scan did for the state.
    pub const ALL: [Health; 5] = [Self::Tracking, Self::Degenerate, Self::WheelOnly, Self::ImuOnly, Self::Lost];

    /// The scan refused while the wheels held the state: wheel-only rather than IMU-only.
    pub fn with_wheels(self, wheels_applied: bool) -> Self {
        match self {
            Self::ImuOnly if wheels_applied => Self::WheelOnly,
            other => other,
        }
    }

    /// A scan it accepted after which the filter is unsure of its position ([`uncertain_axes`]):
    /// degenerate rather than tracking.
    pub fn with_uncertainty(self, unsure: bool) -> Self {
        match self {
            Self::Tracking if unsure => Self::Degenerate,
            other => other,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Tracking => "tracking",
            Self::Degenerate => "degenerate",
            Self::ImuOnly => "imu_only",
            Self::WheelOnly => "wheel_only",
            Self::Lost => "lost",
        }
    }
}

/// The 1-sigma position uncertainty from the position variances (the covariance's diagonal):
/// the root of their sum, as `ScanOutput::pos_sigma_m` reports it.
pub fn pos_sigma_m(pos_var: &Vector3<f64>) -> f64 {
    pos_var.sum().max(0.0).sqrt()
}

/// The position axes the filter is unsure of after a scan: `None` while its 1-sigma position
/// uncertainty ([`pos_sigma_m`] of `pos_var`, the position covariance's diagonal) is within
/// `max_pos_sigma_m` (or the check is off); otherwise the world axes (bits 3, 4, 5 of
/// [`crate::lio::UpdateReport::weak_axes`]: x, y, z) whose variance is at least half that of
/// the most uncertain one.
pub fn uncertain_axes(cfg: &HealthConfig, pos_var: &Vector3<f64>) -> Option<u8> {
    let sigma_m = pos_sigma_m(pos_var);
    if cfg.max_pos_sigma_m <= 0.0 || sigma_m.is_nan() || sigma_m <= cfg.max_pos_sigma_m {
        return None;
    }
    let most = pos_var.max();
    Some((0..3).filter(|&k| pos_var[k] >= 0.5 * most).fold(0u8, |m, k| m | (1 << (3 + k))))
}

/// Why a scan was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Refusal {
    TooFewMatches,
    LargeResidual,
    PoorFit,
    LargeCorrection,
    /// The update came out non-finite (NaN or infinity in the state).
    NonFinite,
}

impl Refusal {
    pub fn name(self) -> &'static str {
        match self {
            Self::TooFewMatches => "too_few_matches",
            Self::LargeResidual => "large_residual",
            Self::PoorFit => "poor_fit",
            Self::LargeCorrection => "large_correction",
            Self::NonFinite => "non_finite",
        }
    }
}

/// The verdict on one scan's update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verdict {
    pub health: Health,
    pub refused: Option<Refusal>,
}

/// What one scan's update did: plane matches and their RMS, the correction it applied to the
/// IMU's prediction, and the directions it left to the IMU.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScanFit {
    pub matched: usize,
    /// Points that entered the update.
    pub used: usize,
    pub converged: bool,
    pub rms_m: f64,
    pub correction_m: f64,
    pub correction_deg: f64,
    pub weak_directions: usize,
}

/// Remembers since when scans are refused.
#[derive(Clone, Debug, Default)]
pub struct HealthMonitor {
    refusing_since_ns: Option<u64>,
    lost: bool,
    /// A scan of the current run of refusals was refused for what it said (not for silence).
    contradicted: bool,
    pub scans_refused: u64,
    pub times_lost: u64,
}

impl HealthMonitor {
    /// Whether the next update should search wider (the filter is lost).
    pub fn is_lost(&self) -> bool {
        self.lost
    }

    /// Whether the current run of refusals holds one refused for what it said (a residual, a
    /// correction, a poor fit) rather than only for too few matches.
    pub fn contradicted(&self) -> bool {
        self.contradicted
    }

    /// Judges one scan's update.
    pub fn judge(&mut self, cfg: &HealthConfig, end_ns: u64, fit: &ScanFit) -> Verdict {
        // A lost filter expects a large correction: that is what finding the map again looks like.
        let refused = if fit.matched < cfg.min_matched {
            Some(Refusal::TooFewMatches)
        } else if fit.rms_m > cfg.max_rms_m {
            Some(Refusal::LargeResidual)
        } else if !fit.converged && (fit.matched as f64) < cfg.min_match_ratio * fit.used as f64 {
            Some(Refusal::PoorFit)
        } else if !self.lost && (fit.correction_m > cfg.max_correction_m || fit.correction_deg > cfg.max_correction_deg)
        {
            Some(Refusal::LargeCorrection)
        } else {
            None
        };
        if let Some(why) = refused {
            self.contradicted |= why != Refusal::TooFewMatches;
            self.scans_refused += 1;
            let since = *self.refusing_since_ns.get_or_insert(end_ns);
            if !self.lost && end_ns.saturating_sub(since) as f64 * 1e-9 >= cfg.max_ride_s {
                self.lost = true;
                self.times_lost += 1;
            }
            let health = if self.lost { Health::Lost } else { Health::ImuOnly };
            return Verdict { health, refused };
        }
        self.refusing_since_ns = None;
        self.lost = false;
        self.contradicted = false;
        let health = if fit.weak_directions > 0 { Health::Degenerate } else { Health::Tracking };
        Verdict { health, refused: None }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_turn_into_lost_after_the_ride_time_and_a_good_scan_clears_it() {
        let cfg = HealthConfig::default();
        let mut m = HealthMonitor::default();
        let fit = |matched, rms_m, correction_m, correction_deg, weak_directions| ScanFit {
            matched,
            used: 600,
            converged: true,
            rms_m,
            correction_m,
            correction_deg,
            weak_directions,
        };
        let good = |m: &mut HealthMonitor, t: u64| m.judge(&cfg, t, &fit(500, 0.02, 0.01, 0.1, 0));
        assert_eq!(good(&mut m, 0).health, Health::Tracking);
        let v = m.judge(&cfg, 100_000_000, &fit(5, 0.02, 0.0, 0.0, 0));
        assert_eq!((v.health, v.refused), (Health::ImuOnly, Some(Refusal::TooFewMatches)));
        let v = m.judge(&cfg, 600_000_000, &fit(500, 0.02, 1.0, 0.0, 0));
        assert_eq!((v.health, v.refused), (Health::ImuOnly, Some(Refusal::LargeCorrection)));
        let v = m.judge(&cfg, 1_100_000_000, &fit(500, 0.5, 0.0, 0.0, 0));
        assert_eq!((v.health, v.refused), (Health::Lost, Some(Refusal::LargeResidual)));
        assert!(m.is_lost());
        // Lost: a large correction is how the map is found again.
        let v = m.judge(&cfg, 1_200_000_000, &fit(500, 0.03, 1.0, 3.0, 2));
        assert_eq!((v.health, v.refused), (Health::Degenerate, None));
        assert!(!m.is_lost());
        assert_eq!((m.scans_refused, m.times_lost), (3, 1));
        // An unsettled update that matched a third of its points is a glitch; settled, it is new space.
        let poor = ScanFit { matched: 200, used: 600, converged: false, rms_m: 0.05, ..ScanFit::default() };
        assert_eq!(m.judge(&cfg, 1_300_000_000, &poor).refused, Some(Refusal::PoorFit));
        let new_space = ScanFit { converged: true, ..poor };
        assert_eq!(m.judge(&cfg, 1_400_000_000, &new_space).refused, None);
    }

    #[test]
    fn an_accepted_scan_is_degraded_where_the_filter_is_unsure_of_its_position() {
        let cfg = HealthConfig::default();
        let unsure = |var: Vector3<f64>| uncertain_axes(&cfg, &var);
        // 3 cm each way: sure enough.
        assert_eq!(unsure(Vector3::repeat(0.03f64.powi(2))), None);
        // 12 cm along x, 3 cm across: unsure, along x.
        let along_x = Vector3::new(0.12f64.powi(2), 0.03f64.powi(2), 0.03f64.powi(2));
        assert_eq!(unsure(along_x), Some(1 << 3));
        // 7 cm along x and y: 9.9 cm in all, within the limit; 8 cm along both: over it, both named.
        let flat = |s: f64| Vector3::new(s * s, s * s, 0.0);
        assert_eq!(unsure(flat(0.07)), None);
        assert_eq!(unsure(flat(0.08)), Some((1 << 3) | (1 << 4)));
        // Off.
        let off = HealthConfig { max_pos_sigma_m: 0.0, ..cfg.clone() };
        assert_eq!(uncertain_axes(&off, &along_x), None);
        assert!(HealthConfig { max_pos_sigma_m: -1.0, ..HealthConfig::default() }.validate().is_err());
        // Only a scan that was accepted and tracked becomes degenerate.
        assert_eq!(Health::Tracking.with_uncertainty(true), Health::Degenerate);
        assert_eq!(Health::Tracking.with_uncertainty(false), Health::Tracking);
        assert_eq!(Health::ImuOnly.with_uncertainty(true), Health::ImuOnly);
    }

    #[test]
    fn only_a_refusal_for_what_the_scan_said_contradicts_the_prediction() {
        let cfg = HealthConfig::default();
        let mut m = HealthMonitor::default();
        let silent = ScanFit { matched: 5, used: 40, converged: true, ..ScanFit::default() };
        for k in 0..15 {
            m.judge(&cfg, k * 100_000_000, &silent);
        }
        assert!(m.is_lost() && !m.contradicted(), "a blind ride is lost but not contradicted");
        let off = ScanFit { matched: 300, used: 400, converged: true, rms_m: 0.5, ..ScanFit::default() };
        m.judge(&cfg, 1_600_000_000, &off);
        assert!(m.contradicted());
        m.judge(&cfg, 1_700_000_000, &silent);
        assert!(m.contradicted(), "stays contradicted until a scan is accepted");
        let good = ScanFit { matched: 300, used: 400, converged: true, rms_m: 0.02, ..ScanFit::default() };
        assert_eq!(m.judge(&cfg, 1_800_000_000, &good).refused, None);
        assert!(!m.is_lost() && !m.contradicted());
    }
}
