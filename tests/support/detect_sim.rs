//! The person detector against the simulator's truth: a run's robot returns read back from its
//! pcap (as a real capture), moved into the world with the true pose at each firing, joined with
//! their labels; windows of them fed to a detector and matched against people.csv.
//! Shared by tests/detect_sim.rs and starc-hil's benches/detect.rs; it reads people.csv itself
//! (and the trajectory with `starc_hil::tum`) because starc-hil's bench cannot depend on
//! starc-eval, which depends on starc-hil.

use nalgebra::{Point3, Vector3};
use starc_hil::sim::lidar::LABEL_EMPTY;
use starc_hil::sim::run::{run, SimOptions};
use starc_hil::sim::scenario::Scenario;
use starc_hil::sim::truth::read_labels;
use starc_hil::tum::{pose_at, read_tum};
use starc_livox::capture;
use starc_livox::data::DataPacket;
use starc_pipeline::detect::eval::{match_window, Counts, MatchRule, TruthPerson};
use starc_pipeline::detect::{DetectWindow, Detection, Detector, WindowPoint};
use starc_time::{Clock, Stamp};
use std::collections::HashMap;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::Path;
use std::time::Instant;

const ROBOT_DATA: SocketAddrV4 = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 101), 60001);

/// Runs a shipped scenario without the camera.
pub fn simulate(name: &str, secs: Option<f64>, seed: u64, dir: &Path) {
    let (scenario, text) = Scenario::load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
    let opts = SimOptions { out: dir.to_path_buf(), duration_s: secs, seed, realtime: false, camera: false };
    run(&scenario, &text, &opts, &mut |_, _| {}).unwrap_or_else(|e| panic!("{name}: {e}"));
}

/// One person's row of people.csv.
pub struct PersonRow {
    pub t_ns: u64,
    pub label: u16,
    pub pose: String,
    pub centre: Vector3<f64>,
    pub size: Vector3<f64>,
    pub yaw_rad: f64,
}

/// The robot's returns of a run, in the world, in firing order, with their labels.
pub struct SimRun {
    pub points: Vec<WindowPoint>,
    pub labels: Vec<u16>,
    pub truth: Vec<(u64, nalgebra::Isometry3<f64>)>,
    pub people: Vec<PersonRow>,
}

pub fn load(dir: &Path) -> SimRun {
    let truth = read_tum(&dir.join("gt_robot.tum")).unwrap();
    let labels: HashMap<u64, Vec<u16>> =
        read_labels(&std::fs::read(dir.join("labels_robot.bin")).unwrap()).unwrap().into_iter().collect();
    let people = std::fs::read_to_string(dir.join("people.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let (s, frac) = f[0].split_once('.').unwrap();
            let t_ns = s.parse::<u64>().unwrap() * 1_000_000_000 + format!("{frac:0<9}").parse::<u64>().unwrap();
            let v: Vec<f64> = f[4..11].iter().map(|x| x.parse().unwrap()).collect();
            PersonRow {
                t_ns,
                label: f[1].parse().unwrap(),
                pose: f[3].to_string(),
                centre: Vector3::new(v[0], v[1], v[2]),
                size: Vector3::new(v[3], v[4], v[5]),
                yaw_rad: v[6],
            }
        })
        .collect();
    let (mut points, mut out_labels, mut decoded) = (Vec::new(), Vec::new(), Vec::new());
    for d in capture::open(&dir.join("avia.pcap")).unwrap() {
        let d = d.unwrap();
        if d.src != Some(ROBOT_DATA) {
            continue;
        }
        let packet = DataPacket::parse(&d.payload).unwrap();
        decoded.clear();
        packet.decode_points(&mut decoded);
        let t0 = packet.header.timestamp.ns;
        let l = labels[&t0].iter().copied().filter(|&x| x != LABEL_EMPTY);
        for (p, label) in decoded.iter().zip(l) {
            let t = t0 + u64::from(p.offset_ns);
            let w = pose_at(&truth, t).unwrap().transform_point(&Point3::new(
                f64::from(p.x_m),
                f64::from(p.y_m),
                f64::from(p.z_m),
            ));
            points.push(WindowPoint { x_m: w.x as f32, y_m: w.y as f32, z_m: w.z as f32, t_ns: t });
            out_labels.push(label);
        }
    }
    SimRun { points, labels: out_labels, truth, people }
}

/// Figures of one detector over one run.
#[derive(Default)]
pub struct Evaluation {
    pub windows: usize,
    pub counts: Counts,
    /// Detected points, and those of them labelled as a person.
    pub detected_points: usize,
    pub person_points: usize,
    /// Time per window, microseconds.
    pub times_us: Vec<f64>,
    /// Per true pose (standing, sitting, crouching, lying): (found, visible).
    pub per_pose: HashMap<String, (usize, usize)>,
    /// False positives: (window end ns, detection).
    pub false_positives: Vec<(u64, Detection)>,
    /// Misses: (window end ns, person label, true pose, returns in the window).
    pub misses: Vec<(u64, u16, String, usize)>,
    /// Per person label: the most returns one window had of them.
    pub max_returns: HashMap<u16, usize>,
}

impl Evaluation {
    pub fn purity(&self) -> f64 {
        self.person_points as f64 / self.detected_points.max(1) as f64
    }

    /// (median, p99) of the time per window in ms.
    pub fn times_ms(&self) -> (f64, f64) {
        let mut t = self.times_us.clone();
        t.sort_by(f64::total_cmp);
        if t.is_empty() {
            return (0.0, 0.0);
        }
        (t[t.len() / 2] / 1e3, t[(t.len() * 99 / 100).min(t.len() - 1)] / 1e3)
    }
}

/// The window of returns fired in `[end - window_ns, end)`, and their labels.
pub fn window_at(run: &SimRun, end: u64, window_ns: u64) -> (DetectWindow<'_>, &[u16]) {
    let a = run.points.partition_point(|p| p.t_ns < end.saturating_sub(window_ns));
    let b = run.points.partition_point(|p| p.t_ns < end);
    let window = DetectWindow {
        stamp: Stamp::new(end, Clock::Ptp),
        sensor_pose: pose_at(&run.truth, end).unwrap(),
        points: &run.points[a..b],
    };
    (window, &run.labels[a..b])
}

/// Feeds windows of `window_ns` every `hop_ns` to the detector (the first starting at the
/// first return) and scores each at its end time against the people at the nearest 10 Hz row.
pub fn evaluate(run: &SimRun, det: &mut dyn Detector, window_ns: u64, hop_ns: u64, rule: &MatchRule) -> Evaluation {
    let mut ev = Evaluation::default();
    let (Some(first), Some(last)) = (run.points.first(), run.points.last()) else { return ev };
    let mut end = first.t_ns + window_ns;
    let mut found = Vec::new();
    while end <= last.t_ns {
        let (window, labels) = window_at(run, end, window_ns);
        found.clear();
        let t0 = Instant::now();
        det.detect(&window, &mut found);
        ev.times_us.push(t0.elapsed().as_secs_f64() * 1e6);

        let mut returns: HashMap<u16, usize> = HashMap::new();
        for &l in labels.iter().filter(|&&l| l != 0) {
            *returns.entry(l).or_default() += 1;
        }
        // The people.csv rows nearest in time to the window's end.
        let row_t = run.people.iter().map(|r| r.t_ns).min_by_key(|t| t.abs_diff(end)).unwrap_or(0);
        let rows: Vec<&PersonRow> = run.people.iter().filter(|r| r.t_ns == row_t).collect();
        let truth: Vec<TruthPerson> = rows
            .iter()
            .map(|r| TruthPerson {
                label: r.label,
                centre_m: r.centre,
                size_m: r.size,
                yaw_rad: r.yaw_rad,
                returns: returns.get(&r.label).copied().unwrap_or(0),
            })
            .collect();
        for (&l, &n) in &returns {
            let e = ev.max_returns.entry(l).or_default();
            *e = (*e).max(n);
        }
        let m = match_window(&found, &truth, rule);
        ev.counts.add(&m.counts);
        for r in rows.iter().filter(|r| returns.get(&r.label).copied().unwrap_or(0) >= rule.min_returns) {
            let e = ev.per_pose.entry(r.pose.clone()).or_default();
            e.1 += 1;
            e.0 += usize::from(!m.missed.contains(&r.label));
            if m.missed.contains(&r.label) {
                ev.misses.push((end, r.label, r.pose.clone(), returns.get(&r.label).copied().unwrap_or(0)));
            }
        }
        for (d, label) in found.iter().zip(&m.detection_label) {
            ev.detected_points += d.point_indices.len();
            ev.person_points +=
                d.point_indices.iter().filter(|&&i| labels.get(i as usize).is_some_and(|&l| l != 0)).count();
            if label.is_none() {
                ev.false_positives.push((end, d.clone()));
            }
        }
        ev.windows += 1;
        end += hop_ns;
    }
    ev
}
