//! What a mission is scored against: the ground truth a `starc sim` run writes (TUM
//! trajectories, people's boxes, the camera's frames, see-through and visible masks, the
//! mountings, the robot's per-return labels), read back, and [`Truth`], all of one run.

use crate::error::{read, read_text, EvalError, Result};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use starc_hil::tum::{parse_ns, pose_at, tum_pose};
use starc_hil::HilError;
use starc_pipeline::ar::{read_mask_png, CameraModel};
use std::path::{Path, PathBuf};

pub use starc_hil::tum::Trajectory;

fn bad_line(path: &Path, index: usize, expected: &'static str) -> EvalError {
    EvalError::BadLine { path: path.to_path_buf(), line: index + 1, expected }
}

/// A TUM trajectory ([`starc_hil::tum::read_tum`]) of at least two poses.
pub fn read_tum(path: &Path) -> Result<Trajectory> {
    let out = starc_hil::tum::read_tum(path).map_err(|e| match e {
        HilError::Read { path, source } => EvalError::Read { path, source },
        HilError::TumLine { path, line, expected } => EvalError::BadLine { path, line, expected },
        other => EvalError::BadFile { path: path.to_path_buf(), reason: other.to_string() },
    })?;
    if out.len() < 2 {
        return Err(EvalError::BadFile { path: path.to_path_buf(), reason: "fewer than two poses".into() });
    }
    Ok(out)
}

/// The trajectory at `t` ([`pose_at`]: interpolated, clamped to its ends); the identity for an
/// empty one, which [`read_tum`] never returns.
pub fn at(traj: &[(u64, Isometry3<f64>)], t: u64) -> Isometry3<f64> {
    pose_at(traj, t).unwrap_or_else(Isometry3::identity)
}

/// A true person's posture (people.csv's `pose`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum TruePose {
    Standing,
    Sitting,
    Crouching,
    Lying,
}

impl TruePose {
    pub const ALL: [TruePose; 4] = [TruePose::Standing, TruePose::Sitting, TruePose::Crouching, TruePose::Lying];

    pub fn name(self) -> &'static str {
        match self {
            TruePose::Standing => "standing",
            TruePose::Sitting => "sitting",
            TruePose::Crouching => "crouching",
            TruePose::Lying => "lying",
        }
    }

    /// The class index of the learned detector's head (docs/pillars.md).
    pub fn class_index(self) -> usize {
        self as usize
    }

    fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == s)
    }
}

/// One person's box at one time (people.csv).
#[derive(Clone, Debug, PartialEq)]
pub struct PersonBox {
    pub t_ns: u64,
    pub pose: TruePose,
    pub label: u16,
    pub centre_m: Vector3<f64>,
    pub size_m: Vector3<f64>,
    pub yaw_rad: f64,
}

/// people.csv: a header, then
/// `time_s,label,name,pose,centre_x_m,centre_y_m,centre_z_m,length_m,width_m,height_m,yaw_rad`.
pub fn read_people(path: &Path) -> Result<Vec<PersonBox>> {
    let text = read_text(path)?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize| f.get(i).and_then(|s| s.parse::<f64>().ok());
        let (Some(t), Some(label), Some(pose), Some(cx), Some(cy), Some(cz), Some(l), Some(w), Some(h), Some(yaw)) = (
            f.first().and_then(|s| parse_ns(s)),
            f.get(1).and_then(|s| s.parse::<u16>().ok()),
            f.get(3).and_then(|s| TruePose::parse(s)),
            num(4),
            num(5),
            num(6),
            num(7),
            num(8),
            num(9),
            num(10),
        ) else {
            return Err(bad_line(
                path,
                n,
                "time_s,label,name,pose (standing|sitting|crouching|lying),centre xyz,length,width,height,yaw",
            ));
        };
        out.push(PersonBox {
            t_ns: t,
            pose,
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
#[derive(Clone, Debug, PartialEq)]
pub struct CameraFrame {
    pub index: u64,
    pub t_ns: u64,
    pub world_t_camera: Isometry3<f64>,
}

/// camera/frames.csv: a header, then `frame,time_s,tx,ty,tz,qx,qy,qz,qw`.
pub fn read_frames(path: &Path) -> Result<Vec<CameraFrame>> {
    let text = read_text(path)?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let v: Vec<f64> = f.iter().skip(2).filter_map(|s| s.parse().ok()).collect();
        let (Some(index), Some(t), Some(p)) =
            (f.first().and_then(|s| s.parse::<u64>().ok()), f.get(1).and_then(|s| parse_ns(s)), tum_pose(&v))
        else {
            return Err(bad_line(path, n, "frame,time_s,tx,ty,tz,qx,qy,qz,qw"));
        };
        out.push(CameraFrame { index, t_ns: t, world_t_camera: p });
    }
    Ok(out)
}

/// The camera's intrinsics and its pose on the rig's LiDAR, from extrinsics.json.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraMount {
    pub camera: CameraModel,
    /// `T_lidar_camera`: camera (optical frame) points into the rig LiDAR's frame.
    pub lidar_t_camera: Isometry3<f64>,
}

/// extrinsics.json's `camera` (intrinsics) and `fpv_lidar_camera` (the mounting).
pub fn read_camera(path: &Path) -> Result<CameraMount> {
    let text = read_text(path)?;
    let j: serde_json::Value =
        serde_json::from_str(&text).map_err(|source| EvalError::Json { path: path.to_path_buf(), source })?;
    let bad = |reason: &str| EvalError::BadFile { path: path.to_path_buf(), reason: reason.into() };
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
        return Err(bad("no camera intrinsics or fpv_lidar_camera mounting"));
    };
    let lidar_t_camera = match (t.as_slice(), q.as_slice()) {
        ([tx, ty, tz], [qx, qy, qz, qw]) => tum_pose(&[*tx, *ty, *tz, *qx, *qy, *qz, *qw]),
        _ => None,
    }
    .ok_or_else(|| bad("bad fpv_lidar_camera"))?;
    let camera = CameraModel {
        width: u32::try_from(width).unwrap_or(0),
        height: u32::try_from(height).unwrap_or(0),
        fx,
        fy,
        cx,
        cy,
    };
    camera.validate().map_err(|source| EvalError::Pipeline { path: path.to_path_buf(), source })?;
    Ok(CameraMount { camera, lidar_t_camera })
}

/// One frame's person mask: row-major, one byte per pixel, the person's label (1..=250) or 0.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<u8>,
}

/// An 8-bit greyscale PNG mask; `None` when the file does not exist.
pub fn read_mask(path: &Path) -> Result<Option<Mask>> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(EvalError::Read { path: path.to_path_buf(), source }),
    };
    let (width, height, pixels) =
        read_mask_png(&bytes).map_err(|source| EvalError::Pipeline { path: path.to_path_buf(), source })?;
    Ok(Some(Mask { width, height, pixels }))
}

/// The simulator's per-return labels of the robot's Avia (`labels_robot.bin`), kept as the
/// returns on each person per point packet: which people a detection window's returns hit.
pub struct PersonReturns {
    /// (PTP time of the packet's first firing, (person label, returns on them)), in time order.
    packets: Vec<(u64, Vec<(u16, u32)>)>,
}

impl PersonReturns {
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = read(path)?;
        let records = starc_hil::sim::truth::read_labels(&bytes).ok_or_else(|| EvalError::BadFile {
            path: path.to_path_buf(),
            reason: "not a STARC labels file (version 1)".into(),
        })?;
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

/// What the simulator wrote about a run.
pub struct Truth {
    pub dir: PathBuf,
    pub scenario: String,
    pub gt_robot: Trajectory,
    pub gt_fpv: Trajectory,
    pub people: Vec<PersonBox>,
    pub frames: Vec<CameraFrame>,
    pub mount: CameraMount,
    /// Which people the robot's returns hit (`labels_robot.bin`); without it, a person's returns
    /// are those of the window inside their box grown by 0.1 m, the floor and furniture included.
    pub robot_returns: Option<PersonReturns>,
    /// What the closed loop of `starc sim --explore` wrote (`exploration.json`): the robot
    /// explored instead of following its waypoints. `None` for a scripted run.
    pub explored: Option<serde_json::Value>,
}

impl Truth {
    /// Everything a scored mission needs from a `starc sim` output directory.
    pub fn load(dir: &Path) -> Result<Self> {
        let scenario = std::fs::read_to_string(dir.join("scenario.toml"))
            .ok()
            .and_then(|t| t.lines().find_map(|l| l.strip_prefix("name = ").map(|n| n.trim_matches('"').to_string())))
            .unwrap_or_default();
        let frames_path = dir.join("camera/frames.csv");
        if !frames_path.exists() {
            return Err(EvalError::NoCameraFrames { path: frames_path });
        }
        let labels = dir.join("labels_robot.bin");
        let robot_returns = if labels.exists() {
            Some(PersonReturns::read(&labels)?)
        } else {
            tracing::warn!(
                "{}: no labels_robot.bin; a person counts as visible by the returns inside their box",
                dir.display()
            );
            None
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            scenario,
            gt_robot: read_tum(&dir.join("gt_robot.tum"))?,
            gt_fpv: read_tum(&dir.join("gt_fpv.tum"))?,
            people: read_people(&dir.join("people.csv"))?,
            frames: read_frames(&frames_path)?,
            mount: read_camera(&dir.join("extrinsics.json"))?,
            robot_returns,
            explored: read_explored(&dir.join("exploration.json"))?,
        })
    }

    /// Frame `index`'s see-through mask (people as if walls were glass), if the run wrote it.
    pub fn see_through(&self, index: u64) -> Result<Option<Mask>> {
        read_mask(&self.dir.join(format!("camera/see_through/{index:06}.png")))
    }

    /// Frame `index`'s visible-only mask (the pixels where a person is seen directly), if the
    /// run wrote it.
    pub fn visible(&self, index: u64) -> Result<Option<Mask>> {
        read_mask(&self.dir.join(format!("camera/visible/{index:06}.png")))
    }

    /// Where the responder is expected to start, in the robot's LIO world: the rig's true pose at
    /// `t_ns`, moved `hint_m` and turned `hint_deg` (standing for a marked entry point or a
    /// hand-off next to the robot).
    pub fn start_hint(&self, lio_t_world: &Isometry3<f64>, t_ns: u64, hint_m: f64, hint_deg: f64) -> Isometry3<f64> {
        let off = Isometry3::from_parts(
            Translation3::new(0.8 * hint_m, -0.6 * hint_m, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, hint_deg.to_radians()),
        );
        lio_t_world * at(&self.gt_fpv, t_ns) * off
    }
}

/// A closed loop's report, if the run has one.
fn read_explored(path: &Path) -> Result<Option<serde_json::Value>> {
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|source| EvalError::Read { path: path.into(), source })?;
    serde_json::from_str(&text).map(Some).map_err(|e| EvalError::BadFile { path: path.into(), reason: e.to_string() })
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
        assert!(matches!(PersonReturns::read(file.path()), Err(EvalError::BadFile { .. })));
        assert!(matches!(PersonReturns::read(Path::new("/nonexistent/labels_robot.bin")), Err(EvalError::Read { .. })));
    }

    #[test]
    fn a_bad_line_names_its_file_and_line() {
        let file = tempfile::NamedTempFile::new().unwrap();
        std::fs::write(file.path(), "# comment\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0\n").unwrap();
        match read_tum(file.path()) {
            Err(EvalError::BadLine { line, .. }) => assert_eq!(line, 3),
            other => panic!("{:?}", other.map(|t| t.len())),
        }
        std::fs::write(file.path(), "1.0 0 0 0 0 0 0 1\n").unwrap();
        assert!(matches!(read_tum(file.path()), Err(EvalError::BadFile { .. })), "one pose is not a trajectory");
        std::fs::write(file.path(), "frame,time_s\n0,1.0,0,0,0,0,0,0,0\n").unwrap();
        assert!(matches!(read_frames(file.path()), Err(EvalError::BadLine { line: 2, .. })), "a zero quaternion");
    }

    #[test]
    fn a_missing_mask_is_none_and_a_bad_one_an_error() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(read_mask(&dir.path().join("000000.png")).unwrap(), None);
        std::fs::write(dir.path().join("bad.png"), b"not a png").unwrap();
        assert!(matches!(read_mask(&dir.path().join("bad.png")), Err(EvalError::Pipeline { .. })));
    }

    #[test]
    fn the_trajectory_is_interpolated_and_clamped() {
        let traj = vec![(10, Isometry3::translation(0.0, 0.0, 0.0)), (20, Isometry3::translation(1.0, 0.0, 0.0))];
        assert!((at(&traj, 15).translation.x - 0.5).abs() < 1e-12);
        assert_eq!(at(&traj, 0).translation.x, 0.0);
        assert_eq!(at(&traj, 99).translation.x, 1.0);
    }
}
