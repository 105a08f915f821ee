//! What `starc mission` scores against: the ground truth a `starc sim` run writes (TUM
//! trajectories, people's boxes, the camera's frames and see-through masks, the mountings).

use anyhow::{bail, Context};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use starc_pipeline::ar::CameraModel;
use std::path::Path;

/// (PTP ns, pose) samples of a TUM file, in time order.
pub type Trajectory = Vec<(u64, Isometry3<f64>)>;

fn parse_ns(s: &str) -> Option<u64> {
    let (whole, frac) = s.split_once('.').unwrap_or((s, "0"));
    let mut digits = frac.to_string();
    digits.truncate(9);
    while digits.len() < 9 {
        digits.push('0');
    }
    whole.parse::<u64>().ok()?.checked_mul(1_000_000_000)?.checked_add(digits.parse::<u64>().ok()?)
}

fn pose(v: &[f64]) -> Option<Isometry3<f64>> {
    let [tx, ty, tz, qx, qy, qz, qw] = v else { return None };
    let q = UnitQuaternion::try_new(Quaternion::new(*qw, *qx, *qy, *qz), 1e-9)?;
    Some(Isometry3::from_parts(Translation3::new(*tx, *ty, *tz), q))
}

pub fn read_tum(path: &Path) -> anyhow::Result<Trajectory> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#')) {
        let f: Vec<&str> = line.split_whitespace().collect();
        let t = f.first().and_then(|s| parse_ns(s));
        let v: Option<Vec<f64>> = f.get(1..).map(|r| r.iter().filter_map(|x| x.parse().ok()).collect());
        match (t, v.as_deref().and_then(pose)) {
            (Some(t), Some(p)) => out.push((t, p)),
            _ => bail!("{} line {}: not a TUM pose line", path.display(), n + 1),
        }
    }
    if out.len() < 2 {
        bail!("{}: fewer than two poses", path.display());
    }
    Ok(out)
}

/// The trajectory at `t`, interpolated (clamped to its ends).
pub fn at(traj: &Trajectory, t: u64) -> Isometry3<f64> {
    let i = traj.partition_point(|(s, _)| *s <= t).clamp(1, traj.len().saturating_sub(1).max(1));
    match (traj.get(i - 1), traj.get(i)) {
        (Some((ta, a)), Some((tb, b))) => {
            let f = if tb > ta { ((t as f64 - *ta as f64) / (*tb as f64 - *ta as f64)).clamp(0.0, 1.0) } else { 0.0 };
            a.lerp_slerp(b, f)
        }
        (Some((_, a)), None) => *a,
        _ => Isometry3::identity(),
    }
}

/// One person's box at one time (people.csv).
#[derive(Clone, Debug)]
pub struct PersonBox {
    pub t_ns: u64,
    pub label: u16,
    pub centre_m: Vector3<f64>,
    pub size_m: Vector3<f64>,
    pub yaw_rad: f64,
}

pub fn read_people(path: &Path) -> anyhow::Result<Vec<PersonBox>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize| f.get(i).and_then(|s| s.parse::<f64>().ok());
        let (Some(t), Some(label), Some(cx), Some(cy), Some(cz), Some(l), Some(w), Some(h), Some(yaw)) = (
            f.first().and_then(|s| parse_ns(s)),
            f.get(1).and_then(|s| s.parse::<u16>().ok()),
            num(4),
            num(5),
            num(6),
            num(7),
            num(8),
            num(9),
            num(10),
        ) else {
            bail!(
                "{} line {}: expected time_s,label,name,pose,centre xyz,length,width,height,yaw",
                path.display(),
                n + 1
            );
        };
        out.push(PersonBox {
            t_ns: t,
            label,
            centre_m: Vector3::new(cx, cy, cz),
            size_m: Vector3::new(l, w, h),
            yaw_rad: yaw,
        });
    }
    Ok(out)
}

/// The people's boxes at the 10 Hz sample nearest `t`.
pub fn people_at(people: &[PersonBox], t: u64) -> Vec<PersonBox> {
    let Some(nearest) = people.iter().map(|p| p.t_ns).min_by_key(|s| s.abs_diff(t)) else { return Vec::new() };
    people.iter().filter(|p| p.t_ns == nearest).cloned().collect()
}

/// One camera frame: its index, PTP time and true camera pose (frames.csv).
#[derive(Clone, Debug)]
pub struct CameraFrame {
    pub index: u64,
    pub t_ns: u64,
    pub world_t_camera: Isometry3<f64>,
}

pub fn read_frames(path: &Path) -> anyhow::Result<Vec<CameraFrame>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let v: Vec<f64> = f.iter().skip(2).filter_map(|s| s.parse().ok()).collect();
        let (Some(index), Some(t), Some(p)) =
            (f.first().and_then(|s| s.parse::<u64>().ok()), f.get(1).and_then(|s| parse_ns(s)), pose(&v))
        else {
            bail!("{} line {}: expected frame,time_s,tx,ty,tz,qx,qy,qz,qw", path.display(), n + 1);
        };
        out.push(CameraFrame { index, t_ns: t, world_t_camera: p });
    }
    Ok(out)
}

/// The camera's intrinsics and its pose on the rig's LiDAR, from extrinsics.json.
pub struct CameraMount {
    pub camera: CameraModel,
    /// `T_lidar_camera`: camera (optical frame) points into the rig LiDAR's frame.
    pub lidar_t_camera: Isometry3<f64>,
}

pub fn read_camera(path: &Path) -> anyhow::Result<CameraMount> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let j: serde_json::Value = serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let c = &j["camera"];
    let m = &j["fpv_lidar_camera"];
    let num = |v: &serde_json::Value| v.as_f64();
    let t: Option<Vec<f64>> = m["translation_m"].as_array().map(|a| a.iter().filter_map(num).collect());
    let q: Option<Vec<f64>> = m["quaternion_xyzw"].as_array().map(|a| a.iter().filter_map(num).collect());
    let (Some(width), Some(height), Some(fx), Some(fy), Some(cx), Some(cy), Some(t), Some(q)) = (
        c["width_px"].as_u64(),
        c["height_px"].as_u64(),
        num(&c["fx_px"]),
        num(&c["fy_px"]),
        num(&c["cx_px"]),
        num(&c["cy_px"]),
        t,
        q,
    ) else {
        bail!("{}: no camera intrinsics or fpv_lidar_camera mounting", path.display());
    };
    let (Some(lidar_t_camera), true) = (
        pose(&[
            t.first().copied().unwrap_or(0.0),
            t.get(1).copied().unwrap_or(0.0),
            t.get(2).copied().unwrap_or(0.0),
            q.first().copied().unwrap_or(0.0),
            q.get(1).copied().unwrap_or(0.0),
            q.get(2).copied().unwrap_or(0.0),
            q.get(3).copied().unwrap_or(1.0),
        ]),
        t.len() == 3 && q.len() == 4,
    ) else {
        bail!("{}: bad fpv_lidar_camera", path.display());
    };
    let camera = CameraModel {
        width: u32::try_from(width).unwrap_or(0),
        height: u32::try_from(height).unwrap_or(0),
        fx,
        fy,
        cx,
        cy,
    };
    camera.validate().map_err(|e| anyhow::anyhow!("{}: camera: {e}", path.display()))?;
    Ok(CameraMount { camera, lidar_t_camera })
}

/// The simulator's per-return labels of the robot's Avia (`labels_robot.bin`), kept as the
/// returns on each person per point packet: which people a detection window's returns hit.
pub struct PersonReturns {
    /// (PTP time of the packet's first firing, (person label, returns on them)), in time order.
    packets: Vec<(u64, Vec<(u16, u32)>)>,
}

impl PersonReturns {
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let records = starc_hil::sim::truth::read_labels(&bytes)
            .with_context(|| format!("{}: not a STARC labels file (version 1)", path.display()))?;
        let mut packets: Vec<(u64, Vec<(u16, u32)>)> = records
            .into_iter()
            .map(|(t_ns, labels)| {
                let mut on_people: Vec<(u16, u32)> = Vec::new();
                for l in labels.into_iter().filter(|&l| l != 0 && l != starc_hil::sim::lidar::LABEL_EMPTY) {
                    match on_people.iter_mut().find(|(k, _)| *k == l) {
                        Some((_, n)) => *n += 1,
                        None => on_people.push((l, 1)),
                    }
                }
                (t_ns, on_people)
            })
            .collect();
        packets.sort_by_key(|(t, _)| *t);
        Ok(Self { packets })
    }

    /// The returns on person `label` of the packets first fired in `[from_ns, to_ns]` (a
    /// window's edges are exact to one packet, under half a millisecond on an Avia).
    pub fn on_person(&self, label: u16, from_ns: u64, to_ns: u64) -> usize {
        let a = self.packets.partition_point(|(t, _)| *t < from_ns);
        let b = self.packets.partition_point(|(t, _)| *t <= to_ns);
        self.packets
            .get(a..b)
            .unwrap_or_default()
            .iter()
            .flat_map(|(_, people)| people.iter())
            .filter(|(k, _)| *k == label)
            .map(|(_, n)| *n as usize)
            .sum()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A labels file of (first firing ns, labels) packets, as `starc sim` writes it.
    pub(crate) fn labels_file(packets: &[(u64, &[u16])]) -> tempfile::NamedTempFile {
        use starc_hil::sim::truth::{labels_record, LABELS_MAGIC, LABELS_VERSION};
        let mut bytes = LABELS_MAGIC.to_vec();
        bytes.extend_from_slice(&LABELS_VERSION.to_le_bytes());
        for (t, labels) in packets {
            bytes.extend(labels_record(*t, labels).unwrap());
        }
        let file = tempfile::NamedTempFile::new().unwrap();
        std::fs::write(file.path(), bytes).unwrap();
        file
    }

    #[test]
    fn person_returns_count_the_labelled_returns_of_the_window_only() {
        let empty = starc_hil::sim::lidar::LABEL_EMPTY;
        // Out of order on purpose: the file is sorted on reading.
        let file = labels_file(&[(300, &[2, 2, 0]), (100, &[1, 1, 0, empty, 2]), (200, &[0, 0, 1])]);
        let r = PersonReturns::read(file.path()).unwrap();
        assert_eq!(r.on_person(1, 100, 300), 3);
        assert_eq!(r.on_person(2, 100, 300), 3);
        assert_eq!(r.on_person(1, 150, 300), 1, "the packet first fired at 100 is before the window");
        assert_eq!(r.on_person(2, 100, 299), 1, "nor is the one at 300 in a window ending at 299");
        assert_eq!(r.on_person(3, 0, 1_000), 0, "nobody labelled 3");
        assert_eq!(r.on_person(1, 300, 100), 0, "an empty window");
    }

    #[test]
    fn a_bad_labels_file_is_an_error() {
        let file = tempfile::NamedTempFile::new().unwrap();
        std::fs::write(file.path(), b"STARCLBL\x01\x00\x00\x00\x05").unwrap();
        assert!(PersonReturns::read(file.path()).is_err());
        assert!(PersonReturns::read(Path::new("/nonexistent/labels_robot.bin")).is_err());
    }
}
