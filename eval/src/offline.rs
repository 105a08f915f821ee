//! The offline mission: [`OfflineMission`] driven over a mission's inputs in time order, scored
//! against the simulator's truth when there is one, and its outputs written: report.json (or
//! replay.json without truth), the AR frames, and the three trajectories as TUM files.
//! `starc mission`, `starc eval`, `starc rerun` and the mission bench call [`run`].

use crate::{quantiles, summary, LatencyReport, MemoryReport, Quantiles, Scorer, Truth};
use crate::{EvalError, Result};
use nalgebra::Isometry3;
use starc_hil::tum::tum_line;
use starc_pipeline::align::AlignConfig;
use starc_pipeline::ar::{CameraModel, RenderConfig};
use starc_pipeline::lio::LioConfig;
use starc_pipeline::mission::{
    AlignVerdict, FrameTime, MissionEvent, MissionInput, OfflineMission, RigCoreConfig, RigSide, RigSideConfig,
    RobotCore, RobotCoreConfig, Side, HOLD_NS,
};
use starc_pipeline::timing::{peak_rss_mib, Stopwatch};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where the rig's first alignment is seeded.
pub enum Start {
    /// The rig's true start moved `hint_m` and turned `hint_deg` (a simulated run; this reads
    /// the truth, so such a run is not a test-set figure).
    FromTruth { hint_m: f64, hint_deg: f64 },
    /// A pose in the robot's map (fpv.toml's `expected_start`).
    At(Isometry3<f64>),
    /// No hint: the responder may start anywhere the robot has mapped (the scored setting).
    Anywhere,
}

/// One offline run of both sides.
pub struct Offline {
    pub out: PathBuf,
    pub frames_every: u64,
    pub camera: CameraModel,
    pub lidar_t_camera: Isometry3<f64>,
    pub start: Start,
    pub start_gate_m: f64,
    /// A first alignment is applied once searches have found it again over this long
    /// (`RigCoreConfig::confirm_span_ns`; 0: at once).
    pub confirm_first_s: f64,
    /// The rig's acceptance judges the overlap with the robot's coverage (see
    /// `OfflineMission::with_coverage`).
    pub coverage: bool,
    /// The robot's core (its LIO, detector and the filters on what it sends).
    pub robot: RobotCoreConfig,
    /// The rig's first-alignment search (`RigCoreConfig::align`; `--align-config`).
    pub rig_align: AlignConfig,
    /// The rig's LIO (`RigCoreConfig::lio`; `--rig-lio-config`).
    pub rig_lio: LioConfig,
    /// With the simulator's truth: the camera frames rendered and scored into report.json.
    /// Without: a frame after every rig scan, and replay.json with what needs no truth.
    pub truth: Option<Truth>,
    /// Compute times measured on the wall clock; off, every time reads 0 and the outputs of
    /// a run depend on its inputs alone (a rerun is byte-identical).
    pub wall_timing: bool,
    /// Run the rig's alignment (off: the robot's figures alone, detection and odometry, in a
    /// fraction of the time; the rig is never aligned).
    pub align: bool,
}

impl Offline {
    /// A simulated run scored against its truth, the rig seeded as `starc mission` seeds it by
    /// default (the true start moved 1 m and turned 20 deg, gated at 2 m): this reads the truth,
    /// so it is for development figures, never the test set.
    pub fn scored_with_hint(truth: Truth, out: PathBuf, frames_every: u64, wall_timing: bool) -> Self {
        Self {
            out,
            frames_every,
            camera: truth.mount.camera.clone(),
            lidar_t_camera: truth.mount.lidar_t_camera,
            start: Start::FromTruth { hint_m: 1.0, hint_deg: 20.0 },
            start_gate_m: 2.0,
            confirm_first_s: starc_pipeline::mission::CONFIRM_FIRST_S,
            coverage: true,
            robot: RobotCoreConfig::default(),
            rig_align: RigCoreConfig::default().align,
            rig_lio: RigCoreConfig::default().lio,
            truth: Some(truth),
            wall_timing,
            align: true,
        }
    }
}

/// What a run without truth writes to replay.json.
#[derive(serde::Serialize)]
pub struct ReplayReport {
    pub mode: &'static str,
    pub robot_scans: usize,
    pub rig_scans: usize,
    pub detection_windows: usize,
    pub people_detected: usize,
    pub alignment_attempts: usize,
    pub alignment_accepted: usize,
    pub first_accepted_after_s: Option<f64>,
    pub compute_ms: Quantiles,
    pub frames: usize,
    pub peak_rss_mib: Option<f64>,
    pub wall_s: f64,
}

/// Runs the mission over `inputs` and writes its outputs into `run.out`; what it printed is
/// returned (the summary lines).
pub fn run<E: std::fmt::Display>(
    inputs: impl Iterator<Item = std::result::Result<MissionInput, E>>,
    run: Offline,
) -> Result<String> {
    let mut state = Run::new(run)?;
    let mut events = Vec::new();
    for input in inputs {
        let input = input.map_err(|e| EvalError::Input(e.to_string()))?;
        state.score_rig_scan(&input);
        state.mission.push(input, &mut events);
        for ev in events.drain(..) {
            state.take(ev);
        }
        if let Some(ev) = state.cfg.align.then(|| state.mission.align()).flatten() {
            state.take(ev);
        }
        state.frames()?;
    }
    state.finish()
}

/// A run in progress: the mission, and what it has given so far.
struct Run {
    cfg: Offline,
    mission: OfflineMission,
    score: Option<Scorer>,
    started: Instant,
    hint_set: bool,
    robot_tum: Vec<String>,
    rig_tum: Vec<String>,
    world_tum: Vec<String>,
    slam_ms: Vec<f64>,
    viz_ms: Vec<f64>,
    detection_windows: usize,
    people_detected: usize,
    first_accept_ns: Option<u64>,
    next_frame: usize,
    frames: usize,
    rig_new: bool,
}

impl Run {
    fn new(mut cfg: Offline) -> Result<Self> {
        let ar_dir = cfg.out.join("ar");
        std::fs::create_dir_all(&ar_dir).map_err(|source| EvalError::Write { path: ar_dir, source })?;
        let pipeline = |source| EvalError::Pipeline { path: cfg.out.clone(), source };
        let stopwatch = Stopwatch::wall_if(cfg.wall_timing);
        let robot_cfg = cfg.robot.clone().with_stopwatch(stopwatch);
        let core = RigCoreConfig {
            start_gate_m: cfg.start_gate_m,
            align: cfg.rig_align.clone(),
            lio: cfg.rig_lio.clone(),
            ..RigCoreConfig::default()
        }
        .with_confirm_first_s(cfg.confirm_first_s)
        .with_stopwatch(stopwatch);
        let rig_cfg = RigSideConfig {
            core,
            camera: cfg.camera.clone(),
            lidar_t_camera: cfg.lidar_t_camera,
            render: RenderConfig::default(),
            hold_ns: HOLD_NS,
        };
        let mut mission =
            OfflineMission::new(RobotCore::new(robot_cfg).map_err(pipeline)?, RigSide::new(rig_cfg).map_err(pipeline)?)
                .with_coverage(cfg.coverage);
        let hint_set = match cfg.start {
            Start::At(p) => {
                mission.rig_mut().core_mut().set_start_hint(p);
                true
            }
            Start::FromTruth { .. } | Start::Anywhere => false,
        };
        Ok(Self {
            score: cfg.truth.take().map(Scorer::new),
            cfg,
            mission,
            started: Instant::now(),
            hint_set,
            robot_tum: Vec::new(),
            rig_tum: Vec::new(),
            world_tum: Vec::new(),
            slam_ms: Vec::new(),
            viz_ms: Vec::new(),
            detection_windows: 0,
            people_detected: 0,
            first_accept_ns: None,
            next_frame: 0,
            frames: 0,
            rig_new: false,
        })
    }

    fn take(&mut self, ev: MissionEvent) {
        match ev {
            MissionEvent::RobotPose { end_ns, pose, lio_ms, health } => {
                if let Some(sc) = self.score.as_mut() {
                    sc.robot_pose(end_ns, &pose, Some(health));
                    if sc.explored_due(end_ns) {
                        if let Some(grid) = self.mission.robot().floor_grid() {
                            sc.explored(end_ns, grid.traversable_area_m2());
                        }
                    }
                }
                self.robot_tum.push(tum_line(end_ns, &pose));
                self.slam_ms.push(lio_ms);
            }
            MissionEvent::Detection(det) => {
                // The robot reports a scan's detection after its pose: it adds to that scan's time.
                if let Some(ms) = self.slam_ms.last_mut() {
                    *ms += det.detect_ms;
                }
                self.detection_windows += 1;
                self.people_detected += det.found.len();
                if let Some(sc) = self.score.as_mut() {
                    sc.detection(&det);
                }
            }
            MissionEvent::RigStarted { first_ns } => {
                if let Some(sc) = self.score.as_mut() {
                    sc.rig_started(first_ns);
                }
            }
            MissionEvent::RigPose { end_ns, odom, world, health } => {
                self.rig_new = true;
                if let Some(sc) = self.score.as_mut() {
                    sc.rig_lio_pose(end_ns, &odom, health);
                }
                self.rig_tum.push(tum_line(end_ns, &odom));
                if let Some(w) = world {
                    self.world_tum.push(tum_line(end_ns, &w));
                }
                self.seed_from_truth();
            }
            MissionEvent::Alignment { end_ns, world_t_lidar, total_ms, verdict } => {
                tracing::info!(%verdict, "rig alignment");
                let accepted = matches!(verdict, AlignVerdict::Accepted { .. });
                let first_ns = self.mission.rig().core().first_ns().unwrap_or(end_ns);
                if accepted && self.first_accept_ns.is_none() {
                    self.first_accept_ns = Some(end_ns.saturating_sub(first_ns));
                }
                if let Some(sc) = self.score.as_mut() {
                    sc.alignment(end_ns, &world_t_lidar, total_ms, accepted);
                }
            }
        }
    }

    /// A rig scan for the scorer's measure of when the rig first sees the robot's map.
    fn score_rig_scan(&mut self, input: &MissionInput) {
        let (MissionInput::Scan(Side::Rig, scan), Some(sc), true) = (input, self.score.as_mut(), self.cfg.align) else {
            return;
        };
        let robot = self.mission.robot_mut();
        let len = robot.map_len();
        sc.rig_scan(scan, len, || robot.map_points());
    }

    /// `--hint truth`: the rig's start from the truth, once the robot's first pose has tied the
    /// LIO's world to the truth's.
    fn seed_from_truth(&mut self) {
        let (Start::FromTruth { hint_m, hint_deg }, false) = (&self.cfg.start, self.hint_set) else { return };
        let (Some(sc), Some(first)) = (self.score.as_ref(), self.mission.rig().core().first_ns()) else { return };
        let Some(l_t_w) = sc.lio_t_world() else { return };
        let hint = sc.truth.start_hint(&l_t_w, first, *hint_m, *hint_deg);
        self.mission.rig_mut().core_mut().set_start_hint(hint);
        self.hint_set = true;
    }

    /// The camera frames both devices have passed (with truth), or a frame after the rig's
    /// newest scan (without).
    fn frames(&mut self) -> Result<()> {
        let rig_new = std::mem::take(&mut self.rig_new);
        let Some(sc) = self.score.as_mut() else {
            return if rig_new { self.replay_frame() } else { Ok(()) };
        };
        let horizon = self.mission.horizon_ns().unwrap_or(0);
        while let Some(f) = sc.truth.frames.get(self.next_frame).filter(|f| f.t_ns <= horizon).cloned() {
            self.next_frame += 1;
            let t0 = self.cfg.wall_timing.then(Instant::now);
            let view = self.mission.rig_mut().render(FrameTime::at(f.t_ns), "offline", true);
            let render_ms = t0.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3);
            self.viz_ms.push(render_ms);
            self.frames += 1;
            let every = self.cfg.frames_every.max(1);
            let keep = (self.cfg.frames_every > 0 && f.index.is_multiple_of(every)).then(|| self.cfg.out.join("ar"));
            sc.frame(&f, &view, render_ms, keep.as_deref())?;
        }
        Ok(())
    }

    fn replay_frame(&mut self) -> Result<()> {
        let Some((t_ns, _)) = self.mission.rig().core().last() else { return Ok(()) };
        let t0 = self.cfg.wall_timing.then(Instant::now);
        let view = self.mission.rig_mut().render(FrameTime::at(t_ns), "replay", true);
        self.viz_ms.push(t0.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3));
        if self.cfg.frames_every > 0 && self.frames.is_multiple_of(self.cfg.frames_every as usize) {
            let path = self.cfg.out.join("ar").join(format!("{:06}.png", self.frames));
            let png = view.frame.to_png().map_err(|source| EvalError::Pipeline { path: path.clone(), source })?;
            crate::error::write(&path, png)?;
        }
        self.frames += 1;
        Ok(())
    }

    fn finish(self) -> Result<String> {
        let out = &self.cfg.out;
        if self.robot_tum.is_empty() || self.mission.rig().core().last().is_none() {
            let side = if self.robot_tum.is_empty() { "the robot" } else { "the rig" };
            return Err(EvalError::NoPoses { side });
        }
        write_tum(out, "robot.tum", &self.robot_tum)?;
        write_tum(out, "rig.tum", &self.rig_tum)?;
        write_tum(out, "rig_world.tum", &self.world_tum)?;
        let viz_p50 = quantiles(&self.viz_ms).p50;
        let total: Vec<f64> = self.slam_ms.iter().map(|s| s + viz_p50).collect();
        let wall_s = if self.cfg.wall_timing { self.started.elapsed().as_secs_f64() } else { 0.0 };
        let peak = if self.cfg.wall_timing { peak_rss_mib() } else { None };
        if let Some(sc) = self.score {
            let latency = LatencyReport::from_parts(&self.slam_ms, &[], &self.viz_ms, &total);
            let memory = MemoryReport { peak_rss_mib: peak, note: None };
            let report = sc.finish("offline", latency, &total, memory, wall_s, out)?;
            return Ok(format!(
                "{}  wrote {} (report.json, frames.csv, ar/, plots/, robot.tum, rig.tum, rig_world.tum)\n",
                summary(&report),
                out.display()
            ));
        }
        let rig = self.mission.rig().core();
        let r = ReplayReport {
            mode: "replay",
            robot_scans: self.robot_tum.len(),
            rig_scans: self.rig_tum.len(),
            detection_windows: self.detection_windows,
            people_detected: self.people_detected,
            alignment_attempts: rig.attempts,
            alignment_accepted: rig.accepted,
            first_accepted_after_s: self.first_accept_ns.map(|ns| ns as f64 * 1e-9),
            compute_ms: quantiles(&total),
            frames: self.frames,
            peak_rss_mib: peak,
            wall_s,
        };
        let path = out.join("replay.json");
        let json = serde_json::to_string_pretty(&r).map_err(|source| EvalError::Json { path: path.clone(), source })?;
        crate::error::write(&path, json + "\n")?;
        let first =
            r.first_accepted_after_s.map_or(String::new(), |t| format!(" (first {t:.1} s after the rig started)"));
        Ok(format!(
            "replay: robot {} scans, {} detection windows ({} people); rig {} scans, {} of {} alignments accepted{first}; {} AR frames\n  wrote {} (replay.json, ar/, robot.tum, rig.tum, rig_world.tum)\n",
            r.robot_scans, r.detection_windows, r.people_detected, r.rig_scans, r.alignment_accepted, r.alignment_attempts, r.frames, out.display()
        ))
    }
}

fn write_tum(out: &Path, name: &str, lines: &[String]) -> Result<()> {
    crate::error::write(&out.join(name), lines.join("\n") + "\n")
}
