//! TUM trajectories: `time tx ty tz qx qy qz qw` per line, the time in seconds with nanosecond
//! digits, `#` comments. The one writer and reader of them (the simulator's ground truth, the
//! LIO's and the mission's poses, the scorer), and interpolation between their poses.
//!
//! Translations are written to the micrometre and quaternions to 1e-9, so that a file of the
//! same poses is the same bytes on every run; times are exact to the nanosecond.

use crate::error::{HilError, Result};
use crate::sim::truth::OutFile;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::path::Path;

/// (PTP ns, pose) samples, in time order.
pub type Trajectory = Vec<(u64, Isometry3<f64>)>;

/// A line of TUM text that does not parse: its number (from 1) and what was expected there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BadTumLine {
    pub line: usize,
    pub expected: &'static str,
}

/// One TUM line: `time tx ty tz qx qy qz qw`, time in seconds.
pub fn tum_line(time_ns: u64, pose: &Isometry3<f64>) -> String {
    let t = pose.translation.vector;
    let q = pose.rotation.coords; // (i, j, k, w)
    format!(
        "{}.{:09} {:.6} {:.6} {:.6} {:.9} {:.9} {:.9} {:.9}",
        time_ns / 1_000_000_000,
        time_ns % 1_000_000_000,
        t.x,
        t.y,
        t.z,
        q.x,
        q.y,
        q.z,
        q.w
    )
}

/// Writes `poses` as a TUM file, one [`tum_line`] each.
pub fn write_tum(path: &Path, poses: &[(u64, Isometry3<f64>)]) -> Result<()> {
    let mut out = OutFile::create(path)?;
    for (t, pose) in poses {
        out.line(&tum_line(*t, pose))?;
    }
    out.finish()
}

/// Reads a TUM file (see [`parse_tum`]); errors name the file, and the line where one fails.
pub fn read_tum(path: &Path) -> Result<Trajectory> {
    let text = std::fs::read_to_string(path).map_err(|source| HilError::Read { path: path.to_path_buf(), source })?;
    parse_tum(&text).map_err(|BadTumLine { line, expected }| HilError::TumLine {
        path: path.to_path_buf(),
        line,
        expected,
    })
}

/// The poses of TUM text, in the order of its lines; blank lines and `#` comments are skipped.
/// Each quaternion is normalized.
pub fn parse_tum(text: &str) -> std::result::Result<Trajectory, BadTumLine> {
    let mut out = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let bad = |expected| BadTumLine { line: index + 1, expected };
        let mut fields = trimmed.split_whitespace();
        let t = fields.next().and_then(parse_ns).ok_or(bad("a time in seconds with up to nine decimals"))?;
        let mut values = [0.0; 7];
        let mut n = 0;
        for field in fields {
            let slot = values.get_mut(n).ok_or(bad("eight fields: time tx ty tz qx qy qz qw"))?;
            *slot = field
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or(bad("finite numbers tx ty tz qx qy qz qw"))?;
            n += 1;
        }
        if n != values.len() {
            return Err(bad("eight fields: time tx ty tz qx qy qz qw"));
        }
        out.push((t, tum_pose(&values).ok_or(bad("a non-zero quaternion qx qy qz qw"))?));
    }
    Ok(out)
}

/// Seconds with up to nine decimals (`1767225600.000000001`) as nanoseconds, exactly; further
/// decimals are dropped. `None` past `u64` or when not a non-negative decimal number.
pub fn parse_ns(s: &str) -> Option<u64> {
    let (whole, frac) = s.split_once('.').unwrap_or((s, "0"));
    if !frac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let mut digits = frac.to_string();
    digits.truncate(9);
    while digits.len() < 9 {
        digits.push('0');
    }
    whole.parse::<u64>().ok()?.checked_mul(1_000_000_000)?.checked_add(digits.parse::<u64>().ok()?)
}

/// A pose from the seven numbers `tx ty tz qx qy qz qw`, the quaternion normalized; `None`
/// unless there are seven and the quaternion is not (near) zero.
pub fn tum_pose(v: &[f64]) -> Option<Isometry3<f64>> {
    let [tx, ty, tz, qx, qy, qz, qw] = v else { return None };
    let q = UnitQuaternion::try_new(Quaternion::new(*qw, *qx, *qy, *qz), 1e-9)?;
    Some(Isometry3::from_parts(Translation3::new(*tx, *ty, *tz), q))
}

/// The pose at `t_ns` of a trajectory in time order: interpolated between the samples around it
/// (linear in translation, slerp in rotation), the first or last pose outside them, the one pose
/// of a one-pose trajectory; `None` for an empty one.
pub fn pose_at(traj: &[(u64, Isometry3<f64>)], t_ns: u64) -> Option<Isometry3<f64>> {
    let i = traj.partition_point(|(s, _)| *s <= t_ns).clamp(1, traj.len().saturating_sub(1).max(1));
    match (traj.get(i - 1), traj.get(i)) {
        (Some((ta, a)), Some((tb, b))) => {
            let f =
                if tb > ta { ((t_ns as f64 - *ta as f64) / (*tb as f64 - *ta as f64)).clamp(0.0, 1.0) } else { 0.0 };
            Some(a.lerp_slerp(b, f))
        }
        (Some((_, a)), None) => Some(*a),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn apart(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
        ((a.translation.vector - b.translation.vector).norm(), a.rotation.angle_to(&b.rotation))
    }

    #[test]
    fn a_line_is_the_time_then_the_pose() {
        let pose = Isometry3::translation(1.0, -2.0, 0.5);
        assert_eq!(
            tum_line(1_767_225_600_000_000_001, &pose),
            "1767225600.000000001 1.000000 -2.000000 0.500000 0.000000000 0.000000000 0.000000000 1.000000000"
        );
    }

    #[test]
    fn written_poses_read_back_the_same() {
        // Translations on the file's micrometre grid come back to 1e-9; rotations to the file's
        // nine decimals of each quaternion component.
        let poses: Trajectory = (0..50u64)
            .map(|i| {
                let f = i as f64;
                let q = UnitQuaternion::from_euler_angles(0.1 * f, -0.05 * f, 0.3 * f - 2.0);
                let t = Translation3::new(f * 0.123_457, -2.5 * f, -0.000_001 * f);
                (1_767_225_600_000_000_001 + i * 5_000_123, Isometry3::from_parts(t, q))
            })
            .collect();
        let dir = std::env::temp_dir().join(format!("starc-tum-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("poses.tum");
        write_tum(&path, &poses).unwrap();
        let back = read_tum(&path).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(back.len(), poses.len());
        for ((t, p), (tb, pb)) in poses.iter().zip(&back) {
            assert_eq!(t, tb, "times are exact to the nanosecond");
            let (m, rad) = apart(p, pb);
            assert!(m < 1e-9 && rad < 2e-9, "{m} m, {rad} rad");
            let dq = (p.rotation.coords - pb.rotation.coords).amax();
            assert!(dq < 1e-9, "quaternion components {dq} apart");
        }
    }

    #[test]
    fn comments_and_blank_lines_are_skipped_and_quaternions_normalized() {
        let poses = parse_tum("# time tx ty tz qx qy qz qw\n\n  1.5 1 2 3 0 0 0 2\n2 0 0 0 0 0 1 0\n").unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].0, 1_500_000_000);
        assert_eq!(poses[0].1, Isometry3::translation(1.0, 2.0, 3.0));
        assert_eq!(poses[1].0, 2_000_000_000);
        assert!((poses[1].1.rotation.angle() - std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn a_bad_line_is_named_with_what_was_expected() {
        let line = |text: &str| parse_tum(text).unwrap_err().line;
        assert_eq!(line("# c\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0\n"), 3, "seven fields");
        assert_eq!(line("1.0 0 0 0 0 0 0 1 9\n"), 1, "nine fields");
        assert_eq!(line("x 0 0 0 0 0 0 1\n"), 1, "a bad time");
        assert_eq!(line("-1.0 0 0 0 0 0 0 1\n"), 1, "a negative time");
        assert_eq!(line("1.0 0 0 y 0 0 0 1\n"), 1, "a bad number");
        assert_eq!(line("1.0 0 0 NaN 0 0 0 1\n"), 1, "not finite");
        assert_eq!(line("1.0 0 0 0 0 0 0 0\n"), 1, "a zero quaternion");
        let e = read_tum(Path::new("/nonexistent/x.tum")).unwrap_err();
        assert!(matches!(e, HilError::Read { .. }), "{e}");
        let dir = std::env::temp_dir().join(format!("starc-tum-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bad.tum");
        std::fs::write(&path, "1.0 0 0 0 0 0 0 1\n2.0 0 0\n").unwrap();
        let e = read_tum(&path).unwrap_err();
        let _ = std::fs::remove_dir_all(&dir);
        assert!(matches!(e, HilError::TumLine { line: 2, .. }), "{e}");
        assert!(e.to_string().contains("bad.tum line 2"), "{e}");
    }

    #[test]
    fn times_parse_exactly_to_the_nanosecond() {
        assert_eq!(parse_ns("1767225600.000000001"), Some(1_767_225_600_000_000_001));
        assert_eq!(parse_ns("1767225600.5"), Some(1_767_225_600_500_000_000));
        assert_eq!(parse_ns("12"), Some(12_000_000_000));
        assert_eq!(parse_ns("1.0000000019"), Some(1_000_000_001), "past nine decimals: dropped");
        assert_eq!(parse_ns("1.-5"), None);
        assert_eq!(parse_ns("x.5"), None);
        assert_eq!(parse_ns("99999999999999999999.0"), None, "overflow");
    }

    #[test]
    fn poses_between_samples_are_interpolated_and_clamped_outside() {
        let traj = vec![(10, Isometry3::translation(0.0, 0.0, 0.0)), (20, Isometry3::translation(1.0, 0.0, 0.0))];
        let x = |t| pose_at(&traj, t).unwrap().translation.x;
        assert!((x(15) - 0.5).abs() < 1e-12);
        assert_eq!(x(10), 0.0);
        assert_eq!(x(20), 1.0);
        assert_eq!(x(0), 0.0);
        assert_eq!(x(99), 1.0);
        let turn = vec![
            (0, Isometry3::identity()),
            (100, Isometry3::rotation(nalgebra::Vector3::z() * std::f64::consts::FRAC_PI_2)),
        ];
        assert!((pose_at(&turn, 50).unwrap().rotation.angle() - std::f64::consts::FRAC_PI_4).abs() < 1e-12, "slerp");
        assert_eq!(pose_at(&traj[..1], 99), Some(traj[0].1), "one pose");
        let same_time = vec![(5, Isometry3::translation(1.0, 0.0, 0.0)), (5, Isometry3::translation(2.0, 0.0, 0.0))];
        assert_eq!(pose_at(&same_time, 5).map(|p| p.translation.x), Some(1.0), "no division by zero");
        assert_eq!(pose_at(&[], 5), None);
    }
}
