//! The Avia's scan pattern: a Risley-prism rosette fitted to a real Avia frame.
//!
//! Two prisms spinning in opposite directions at incommensurate rates deflect the six lasers
//! along a rose curve that never repeats; the six lines are the same curve shifted by a small
//! fixed angle each. The constants were fitted (least squares over the firing time, line and
//! direction of each of the 2,813 returns) to the real frame in shared/data/livox/avia_frame.pcd
//! by tests/peers/fit_avia_pattern.py: a median angular residual of 0.60 deg (p90 1.12 deg).
//! The fitted rosette spans about 73 x 75 deg against the datasheet's 70.4 x 77.2 deg; the real
//! frame only has returns below the horizon, so its upper half is extrapolated.

use crate::avia::FiringRequest;

/// Rotation rates of the two prisms (Hz; opposite signs: counter-rotating).
pub const PRISM_HZ: [f64; 2] = [131.2339, -40.7885];
/// Phases of the prisms at device time zero (rad).
const PRISM_PHASE_RAD: [f64; 2] = [3.3317, -2.8625];
/// Share of the deflection from the first prism (0.5 would be identical wedges).
const PRISM_WEIGHT: f64 = 0.5167;
/// Radial stretch of the rosette (deflection grows faster than linearly towards the rim, as a
/// prism's does): angle = amplitude * w * (1 + k |w|^2).
const RIM_STRETCH: f64 = 0.2189;
/// Half amplitudes of the rosette (azimuth, elevation), deg.
const AMPLITUDE_DEG: [f64; 2] = [29.9222, 28.5894];
/// Centre of line 0's rosette (azimuth, elevation), deg.
const CENTRE_DEG: [f64; 2] = [-0.2211, -2.6879];
/// Offset of each line from line 0 (azimuth, elevation), deg.
const LINE_OFFSET_DEG: [[f64; 2]; 6] =
    [[0.0, 0.0], [-0.0334, 1.0615], [-0.1504, 2.1104], [-0.2665, 3.1498], [-0.3504, 4.1987], [-0.3752, 5.2327]];

/// The Avia's horizontal field of view, deg.
pub const FOV_H_DEG: f64 = 70.4;
/// The Avia's vertical field of view, deg.
pub const FOV_V_DEG: f64 = 77.2;

/// Direction of the Avia's beams in its own frame (x forward, y left, z up).
#[derive(Clone, Copy, Debug, Default)]
pub struct AviaPattern;

impl AviaPattern {
    /// (azimuth, elevation) in degrees of `line` (0..6) at device time `t_ns`.
    pub fn angles_deg(t_ns: u64, line: usize) -> (f64, f64) {
        // Whole and fractional seconds apart keep the phase exact over days of device time.
        let secs = (t_ns / 1_000_000_000) as f64;
        let frac = (t_ns % 1_000_000_000) as f64 * 1e-9;
        let phase = |i: usize| {
            let hz = PRISM_HZ[i];
            std::f64::consts::TAU * ((hz * secs).fract() + hz * frac) + PRISM_PHASE_RAD[i]
        };
        let (s1, c1) = phase(0).sin_cos();
        let (s2, c2) = phase(1).sin_cos();
        let re = PRISM_WEIGHT * c1 + (1.0 - PRISM_WEIGHT) * c2;
        let im = PRISM_WEIGHT * s1 + (1.0 - PRISM_WEIGHT) * s2;
        let stretch = 1.0 + RIM_STRETCH * (re * re + im * im);
        let (re, im) = (re * stretch, im * stretch);
        let offset = LINE_OFFSET_DEG[line % LINE_OFFSET_DEG.len()];
        (CENTRE_DEG[0] + AMPLITUDE_DEG[0] * re + offset[0], CENTRE_DEG[1] + AMPLITUDE_DEG[1] * im + offset[1])
    }

    /// Unit direction of `line` at `t_ns`.
    pub fn direction(t_ns: u64, line: usize) -> [f64; 3] {
        let (az, el) = Self::angles_deg(t_ns, line);
        let (sa, ca) = az.to_radians().sin_cos();
        let (se, ce) = el.to_radians().sin_cos();
        [ce * ca, ce * sa, se]
    }

    /// Line of firing `k` of a request (the Avia fires its lines in turn).
    pub fn line_of(req: &FiringRequest, k: usize) -> usize {
        ((req.first_index + k as u64) % 6) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Share of the cells of a 0.5 deg grid over the elliptical field of view hit after `secs`.
    fn coverage(secs: f64) -> f64 {
        let (w, h) = (FOV_H_DEG / 2.0, FOV_V_DEG / 2.0);
        let (nx, ny) = ((FOV_H_DEG / 0.5) as usize, (FOV_V_DEG / 0.5) as usize);
        let mut hit = vec![false; nx * ny];
        let firings = (secs / 4167e-9) as u64;
        for k in 0..firings {
            let (az, el) = AviaPattern::angles_deg(k * 4167, (k % 6) as usize);
            let (i, j) = (((az + w) / 0.5).floor(), ((el + h) / 0.5).floor());
            if i >= 0.0 && j >= 0.0 && (i as usize) < nx && (j as usize) < ny {
                hit[j as usize * nx + i as usize] = true;
            }
        }
        let mut inside = 0usize;
        let mut covered = 0usize;
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = ((i as f64 + 0.5) * 0.5 - w, (j as f64 + 0.5) * 0.5 - h);
                // Cells well inside the ellipse: the rosette's rim is round, like the real one's.
                if (x / (w - 1.0)).powi(2) + (y / (h - 1.0)).powi(2) <= 1.0 {
                    inside += 1;
                    covered += usize::from(hit[j * nx + i]);
                }
            }
        }
        covered as f64 / inside as f64
    }

    #[test]
    fn coverage_grows_with_integration_time() {
        let c: Vec<f64> = [0.1, 0.2, 0.5, 1.0].iter().map(|&s| coverage(s)).collect();
        eprintln!("coverage of the field of view after 0.1, 0.2, 0.5, 1 s: {c:.3?}");
        assert!(c.windows(2).all(|w| w[1] > w[0]), "{c:?}");
        assert!(c[0] > 0.4 && c[0] < 0.8, "0.1 s covers {:.2}", c[0]);
        assert!(c[3] > 0.97, "1 s covers only {:.3}", c[3]);
    }

    #[test]
    fn spans_the_avias_field_of_view() {
        let (mut az_lo, mut az_hi, mut el_lo, mut el_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for k in 0..240_000u64 {
            let (az, el) = AviaPattern::angles_deg(k * 4167 + 123_456_789_000, (k % 6) as usize);
            (az_lo, az_hi, el_lo, el_hi) = (az_lo.min(az), az_hi.max(az), el_lo.min(el), el_hi.max(el));
        }
        assert!((az_hi - az_lo - FOV_H_DEG).abs() < 3.0, "azimuth {az_lo:.1}..{az_hi:.1}");
        assert!((el_hi - el_lo - FOV_V_DEG).abs() < 3.0, "elevation {el_lo:.1}..{el_hi:.1}");
    }
}
