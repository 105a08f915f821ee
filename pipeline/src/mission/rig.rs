//! The rig's side of the mission, sans-IO: its own LIO, its scans over a window aligned to the
//! robot's map (NDT + ICP with yaw reseeding), re-registered every few seconds, and the world
//! pose composed from the alignment and the rig's odometry, corrected in bounded steps.
//!
//! Alignment takes tens to hundreds of milliseconds, so it is handed out as an [`AlignJob`] that
//! the caller runs where it likes (inline offline, on a worker thread live) and hands back with
//! [`RigCore::apply`].

use super::place::{ScanPlacer, ScanPoses};
use super::recent_voxels::RecentVoxels;
use super::rig_history::{with_history, RigHistory};
use super::waiting::Waiting;
use crate::align::{
    filter_window, AggregateStats, AlignConfig, AlignFailure, AlignReport, Aligner, Coverage, ExclusionBox,
    PlacedPoint, Ray, Reasons, Rejection, WindowConfig,
};
use crate::ar::OrientedBox;
use crate::lio::{ImuNoise, ImuSample, Lio, LioConfig, LioScan, ScanOutput, UpdateConfig};
use crate::pose::{PoseBuffer, WorldPose, WorldPoseConfig};
use crate::PipelineError;
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use std::collections::VecDeque;
use std::sync::Arc;

/// How long a first alignment must be found again before it is used, by default (s).
pub const CONFIRM_FIRST_S: f64 = 2.0;

/// How the rig's side runs; the defaults are what `starc sim` measures.
#[derive(Clone, Debug)]
pub struct RigCoreConfig {
    pub lio: LioConfig,
    /// The first alignment (seed search).
    pub align: AlignConfig,
    /// Re-registration from the current world pose: one attempt, no seed search.
    pub track: AlignConfig,
    pub world: WorldPoseConfig,
    /// The first alignment waits for this much of the rig's own map.
    pub first_window_ns: u64,
    /// Until the first alignment, each retry uses all of the rig's scans so far, up to this long:
    /// a longer window sees more of the building and aliases less.
    pub max_first_window_ns: u64,
    /// Until the first alignment, each retry also takes what the earlier searches' windows held
    /// (reduced, moving points left out), up to this long before it: the rooms the responder
    /// walked through can tell a symmetric building's mirror from the truth where the last
    /// `max_first_window_ns` alone cannot. 0 (none) by default: 30 s placed one development
    /// building sooner but changed no test-set count, and kept the lab's rerun from aligning
    /// (docs/align.md).
    pub first_history_ns: u64,
    pub track_window_ns: u64,
    pub retry_ns: u64,
    pub reregister_ns: u64,
    /// The window's aggregation: moving points left out, then voxels of `window.voxel_m` (the
    /// robot's map comes reduced to the same size).
    pub window: WindowConfig,
    /// People the robot reports are left out of the window in boxes this much larger than
    /// theirs on every side (arms, the scan's smear).
    pub people_margin_m: f64,
    /// The robot's map must hold this many voxels before the rig tries.
    pub min_map_points: usize,
    /// A first alignment farther than this from the expected start is refused (only with a
    /// start hint).
    pub start_gate_m: f64,
    /// This many re-registrations in a row refused for contradicting the robot's map (points
    /// where the robot saw through, rays through its surfaces) mean the alignment was wrong:
    /// the rig is placed nowhere again and searches from scratch (0: never).
    pub lose_after_contradictions: u32,
    /// A first alignment is a candidate until independent searches (every `retry_ns`, each on
    /// the rig's whole window so far) have found it again, `confirm_min_searches` in all and
    /// none finding another place between them, over at least this long; then it is applied (0:
    /// the first accepted search is applied at once). A refused search between them leaves the
    /// candidate standing: a window that decided nothing says nothing against it.
    /// A single attempt from the candidate would not do: it passes the tests wherever the window
    /// fits well enough, and a wrong candidate mostly does; it must stay the search's best.
    /// One window can fit a place it is not (a room like another, a flipped symmetric hall):
    /// such a coincidence rarely survives the rig's next metres.
    pub confirm_span_ns: u64,
    /// The searches that must have found a first alignment before it is applied (with
    /// `confirm_span_ns`).
    pub confirm_min_searches: u32,
    /// Two searches agree when they place the rig's odometry frame within this of each other.
    pub confirm_agree_m: f64,
    pub confirm_agree_deg: f64,
    /// The view draws the rig's points of this long (the newest per `view_voxel_m` voxel;
    /// 0: the newest scan alone).
    pub view_keep_ns: u64,
    pub view_voxel_m: f64,
}

/// The rig's gyro noise density for its LIO (rad/s per sqrt(Hz); config/lio_rig.toml). The
/// LIO's generic 0.1 (400 times the BMI088's density) let the scans of a sparse view turn the
/// rig's attitude, and gravity then leaked into its position; a helmet or a hand turns faster
/// and more sharply than a wheeled base (the robot's 0.001), so the margin stays wider: 0.01,
/// measured on development buildings (docs/lio.md, "The rig's gyro noise").
pub const RIG_GYRO_NOISE_RAD_S: f64 = 0.01;
/// The variance the rig's LIO gives one point-to-plane residual (m^2; config/lio_rig.toml). As
/// for the robot ([`super::robot::ROBOT_RESIDUAL_VAR_M2`]) one scan's residuals are not
/// independent, and a helmet's scans also carry its quick turns' de-skew errors: 0.03 (17 cm).
pub const RIG_RESIDUAL_VAR_M2: f64 = 0.03;
/// Directions of the rig's pose a scan constrains less than this (normalised information) take
/// no update, and the scan is reported `degenerate` (config/lio_rig.toml): a wall and a floor
/// alone leave a walker's motion along the wall to the IMU, and say so. The generic 1e-4 only
/// drops what a scene does not see at all.
pub const RIG_MIN_DIRECTION_INFO: f64 = 0.001;
/// The rig's accelerometer bias (1 sigma, m/s^2; config/lio_rig.toml) that its still start
/// takes for gravity, tied to the gravity in the filter's start (`lio::start`): the BMI088's
/// turn-on spread as the simulator draws it (docs/lio.md, "The rig's accelerometer bias").
pub const RIG_ACC_BIAS_SIGMA_M_S2: f64 = 0.05;
/// A scan of the rig that matched still holds its velocity at zero where the IMU has been still
/// and the world acceleration stayed under this RMS (m/s^2; config/lio_rig.toml): a helmet stands
/// still often while its scans hold its pose but barely its velocity (docs/lio.md, "Fine voxels
/// where the view is small").
pub const RIG_STILL_MAX_ACC_M_S2: f64 = 0.1;
/// That limit is widened by this many sigmas of the world-acceleration error the rig's filter
/// expects from its own attitude, bias and gravity (config/lio_rig.toml): after a turn, a bias
/// its still start took for gravity reads as a steady acceleration (docs/lio.md, "A still helmet
/// after a turn").
pub const RIG_STILL_ACC_SIGMAS: f64 = 1.0;
/// ... with the acceleration's change over the window weighing this many times its mean: a walk
/// that sets off ramps up, the filter's own error is steady.
pub const RIG_STILL_CHANGE_WEIGHT: f64 = 3.0;
/// A rig held still keeps its velocity at zero within this (m/s; config/lio_rig.toml): a standing
/// head sways by about 2 cm/s, not the generic 5.
pub const RIG_STILL_SIGMA_M_S: f64 = 0.02;
/// The rig's scans are reduced on finer voxels until they keep this many centroids
/// (config/lio_rig.toml): a helmet often sees a wall within a metre and little else.
pub const RIG_SCAN_MIN_POINTS: usize = 1000;
/// A rig scan whose residuals' RMS exceeds this (m; config/lio_rig.toml) weighs less by the
/// square of the excess (docs/lio.md, "A scan that fits loosely weighs less").
pub const RIG_FIT_RMS_REF_M: f64 = 0.02;

impl RigCoreConfig {
    /// The rig's LIO settings: the defaults with [`RIG_GYRO_NOISE_RAD_S`],
    /// [`RIG_RESIDUAL_VAR_M2`], [`RIG_MIN_DIRECTION_INFO`], [`RIG_ACC_BIAS_SIGMA_M_S2`],
    /// [`RIG_STILL_MAX_ACC_M_S2`], [`RIG_STILL_ACC_SIGMAS`], [`RIG_STILL_CHANGE_WEIGHT`],
    /// [`RIG_STILL_SIGMA_M_S`], [`RIG_SCAN_MIN_POINTS`] and [`RIG_FIT_RMS_REF_M`].
    pub fn rig_lio() -> LioConfig {
        LioConfig {
            acc_bias_sigma_m_s2: RIG_ACC_BIAS_SIGMA_M_S2,
            still_max_acc_m_s2: RIG_STILL_MAX_ACC_M_S2,
            still_acc_sigmas: RIG_STILL_ACC_SIGMAS,
            still_change_weight: RIG_STILL_CHANGE_WEIGHT,
            still_sigma_m_s: RIG_STILL_SIGMA_M_S,
            scan_min_points: RIG_SCAN_MIN_POINTS,
            noise: ImuNoise { gyro_rad_s: RIG_GYRO_NOISE_RAD_S, ..ImuNoise::default() },
            update: UpdateConfig {
                residual_var_m2: RIG_RESIDUAL_VAR_M2,
                min_direction_info: RIG_MIN_DIRECTION_INFO,
                fit_rms_ref_m: RIG_FIT_RMS_REF_M,
                ..UpdateConfig::default()
            },
            ..LioConfig::default()
        }
    }
}

impl Default for RigCoreConfig {
    fn default() -> Self {
        Self {
            lio: Self::rig_lio(),
            align: AlignConfig::default(),
            // A re-registration must be well conditioned: a borderline one (a corridor's axis)
            // moves a good odometry pose more than it corrects it, so the index alone decides.
            track: AlignConfig {
                min_degeneracy_index: 0.02,
                pinned_slides_m: Vec::new(),
                reseed_yaw_step_deg: 0.0,
                ndt_resolutions_m: vec![2.0, 1.0],
                seed_levels: 1,
                ..AlignConfig::default()
            },
            world: WorldPoseConfig::default(),
            first_window_ns: 3_000_000_000,
            max_first_window_ns: 10_000_000_000,
            first_history_ns: 0,
            track_window_ns: 3_000_000_000,
            retry_ns: 1_000_000_000,
            reregister_ns: 5_000_000_000,
            window: WindowConfig::default(),
            people_margin_m: 0.15,
            min_map_points: 1000,
            start_gate_m: 2.0,
            lose_after_contradictions: 3,
            confirm_span_ns: (CONFIRM_FIRST_S * 1e9) as u64,
            confirm_min_searches: 3,
            confirm_agree_m: 0.3,
            confirm_agree_deg: 3.0,
            view_keep_ns: 3_000_000_000,
            view_voxel_m: 0.08,
        }
    }
}

impl RigCoreConfig {
    /// These settings with a first alignment confirmed over `s` seconds (0, negative or not
    /// finite: applied at once).
    pub fn with_confirm_first_s(mut self, s: f64) -> Self {
        self.confirm_span_ns = if s.is_finite() && s > 0.0 { (s * 1e9).round() as u64 } else { 0 };
        self
    }

    /// These settings with every compute time measured on `stopwatch` (LIO and alignment).
    pub fn with_stopwatch(mut self, stopwatch: crate::timing::Stopwatch) -> Self {
        self.lio.stopwatch = stopwatch;
        self.align.stopwatch = stopwatch;
        self.track.stopwatch = stopwatch;
        self
    }
}

/// One registration of the rig's window against the robot's map, ready to run anywhere: it
/// holds what it needs (shared scans, a copy of the odometry), so building the window, the
/// costly part besides the registration, runs wherever the job does.
#[derive(Clone)]
pub struct AlignJob {
    pub end_ns: u64,
    pub tracking: bool,
    window_ns: u64,
    window: WindowConfig,
    /// People to leave out, in the rig's odometry frame.
    people: Vec<ExclusionBox>,
    scans: Vec<Arc<LioScan>>,
    /// The earlier searches' windows, in the rig's odometry frame (empty once aligned).
    history: Arc<Vec<Vector3<f64>>>,
    /// Whether the window is handed back for the history (a first search with the history on).
    keep_window: bool,
    odom: PoseBuffer,
    target: Arc<Vec<Vector3<f64>>>,
    target_seen_from: Arc<Vec<Vector3<f64>>>,
    coverage: Option<Arc<Coverage>>,
    config: AlignConfig,
    lidar_pose: Isometry3<f64>,
    guess_world_t_lidar: Isometry3<f64>,
}

/// What a job registers (see [`AlignJob::inputs`]).
pub struct AlignInputs {
    /// The window's points in its frame.
    pub source: Vec<Vector3<f64>>,
    /// The registered frame to the rig's LiDAR at the job's end (as
    /// [`AlignOutcome::frame_t_lidar`]).
    pub frame_t_lidar: Isometry3<f64>,
    /// The robot's map.
    pub target: Arc<Vec<Vector3<f64>>>,
}

/// A job's window, ready to register.
struct PreparedWindow {
    source: Vec<Vector3<f64>>,
    /// The window's own points (without the history), in the rig's odometry frame, when kept.
    fresh_odom: Vec<Vector3<f64>>,
    rays: Vec<Ray>,
    /// The window's frame in the rig's odometry.
    frame: Isometry3<f64>,
    kept: AggregateStats,
}

/// A job's result.
pub struct AlignOutcome {
    pub end_ns: u64,
    pub tracking: bool,
    /// What the window's aggregation kept and left out (people, moving points).
    pub window: AggregateStats,
    pub report: AlignReport,
    /// The rig's LiDAR pose in the robot's world, as registered.
    pub world_t_lidar: Isometry3<f64>,
    /// The registered window's frame to the rig's LiDAR at `end_ns`: any attempt's `pose` times
    /// this is the LiDAR's pose that attempt claims.
    pub frame_t_lidar: Isometry3<f64>,
    /// The rig's odometry pose at `end_ns` (what the window was built with).
    pub odom_t_lidar: Isometry3<f64>,
    /// The window's own points (its history left out), in the rig's odometry frame: the history
    /// of the searches after it (empty unless `RigCoreConfig::first_history_ns` keeps one).
    pub window_odom: Vec<Vector3<f64>>,
}

impl AlignJob {
    /// The same window registered from another guess of the LiDAR's world pose with other
    /// settings (diagnosis: e.g. one attempt from the true pose).
    pub fn with_guess(mut self, guess_world_t_lidar: Isometry3<f64>, config: AlignConfig) -> Self {
        self.guess_world_t_lidar = guess_world_t_lidar;
        self.config = config;
        self
    }

    /// The window as the registration takes it: its points (moving points and people left out,
    /// reduced) and a sample of its rays, in the window's frame; that frame in the rig's
    /// odometry; what the aggregation kept.
    fn source(&self) -> PreparedWindow {
        // The window in a gravity-aligned frame at the rig; both sides reduced alike, so that a
        // surface weighs the same in the window as in the map (thinning one side's floor and
        // ceiling alone biases the fit along them: see docs/align.md).
        let (placed, rays, frame) = window(&self.scans, &self.odom, self.end_ns, self.window_ns);
        let inv = frame.inverse();
        let (fresh, kept) = filter_window(&placed, &rays, &inv, &self.people, &self.window);
        drop(placed);
        let fresh_odom = if self.keep_window {
            fresh.iter().map(|p| (frame * Point3::from(*p)).coords).collect()
        } else {
            Vec::new()
        };
        let source = with_history(fresh, &self.history, &inv, self.window.voxel_m);
        let rays: Vec<Ray> = rays
            .iter()
            .map(|(_, r)| Ray {
                origin: (inv * Point3::from(r.origin)).coords,
                end: (inv * Point3::from(r.end)).coords,
            })
            .collect();
        PreparedWindow { source, fresh_odom, rays, frame, kept }
    }

    /// The registration's inputs, for peers and diagnosis.
    pub fn inputs(&self) -> AlignInputs {
        let w = self.source();
        AlignInputs {
            source: w.source,
            frame_t_lidar: w.frame.inverse() * self.lidar_pose,
            target: Arc::clone(&self.target),
        }
    }

    pub fn run(self) -> Result<AlignOutcome, PipelineError> {
        let PreparedWindow { source, fresh_odom, rays, frame, kept } = self.source();
        tracing::debug!(
            end_ns = self.end_ns,
            points_in = kept.points_in,
            people_boxes = self.people.len(),
            excluded_people = kept.excluded_boxes,
            excluded_moving = kept.excluded_moving,
            points_out = kept.points_out,
            "rig window"
        );
        let mut aligner = Aligner::new_seen_from(&self.target, &self.target_seen_from, self.config)?;
        if let Some(c) = self.coverage {
            aligner = aligner.with_coverage(c);
        }
        let guess = self.guess_world_t_lidar * self.lidar_pose.inverse() * frame;
        let report = aligner.align_with_rays(&source, &rays, &guess);
        // The registered frame back to the rig's LiDAR pose in the world.
        let frame_t_lidar = frame.inverse() * self.lidar_pose;
        let world_t_lidar = report.pose * frame_t_lidar;
        // Every full attempt, for `RUST_LOG=starc_pipeline=debug`: the failure sentence names
        // only the best one.
        for a in &report.attempts {
            let claimed = a.pose * frame_t_lidar;
            let m = &a.metrics;
            tracing::debug!(
                end_ns = self.end_ns,
                tracking = self.tracking,
                seed_yaw_deg = a.seed_yaw_offset_deg,
                seed_shift_m = ?a.seed_shift_m,
                x_m = claimed.translation.x,
                y_m = claimed.translation.y,
                yaw_deg = claimed.rotation.euler_angles().2.to_degrees(),
                rms_m = m.rms_residual_m,
                inliers = m.inlier_ratio,
                degeneracy = m.degeneracy_index,
                rays_blocked = a.free_space.as_ref().map_or(f64::NAN, |f| f.blocked_ratio),
                accepted = a.accepted,
                why = %Reasons(&a.rejected_because),
                "rig alignment attempt"
            );
        }
        Ok(AlignOutcome {
            end_ns: self.end_ns,
            tracking: self.tracking,
            window: kept,
            report,
            world_t_lidar,
            frame_t_lidar,
            odom_t_lidar: self.lidar_pose,
            window_odom: fresh_odom,
        })
    }
}

/// What became of an alignment.
#[derive(Clone, Debug, PartialEq)]
pub enum AlignVerdict {
    Accepted {
        first: bool,
    },
    /// Every attempt was refused, for these reasons.
    Refused(AlignFailure),
    /// The job could not run or its result could not be used (a message for people: nothing
    /// branches on it).
    Failed {
        error: String,
    },
    /// A re-registration refused for contradicting the map, the last of
    /// `lose_after_contradictions` in a row: the alignment is dropped and the search starts over.
    Lost(AlignFailure),
    /// Passed its tests, and is a candidate until more searches agree (`searches` so far, over
    /// `span_ns` of `needed_ns`).
    Candidate {
        searches: u32,
        span_ns: u64,
        needed_ns: u64,
    },
    /// Passed its tests, but puts the rig's start (its first odometry pose, carried by the
    /// odometry to the registered pose) `off_m` from the expected start.
    FarFromStart {
        off_m: f64,
    },
}

impl std::fmt::Display for AlignVerdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Accepted { first: true } => f.write_str("accepted (first)"),
            Self::Accepted { first: false } => f.write_str("accepted"),
            Self::Refused(why) => write!(f, "refused: {why}"),
            Self::Lost(why) => write!(f, "lost: the map contradicts the alignment again ({why}); searching anew"),
            Self::Failed { error } => write!(f, "failed: {error}"),
            Self::Candidate { searches, span_ns, needed_ns } => write!(
                f,
                "candidate: {searches} search(es) agree over {:.1} of {:.1} s",
                *span_ns as f64 * 1e-9,
                *needed_ns as f64 * 1e-9
            ),
            Self::FarFromStart { off_m } => write!(f, "refused: {off_m:.2} m from the expected start"),
        }
    }
}

pub struct RigCore {
    cfg: RigCoreConfig,
    lio: Lio,
    placer: ScanPlacer,
    outs: Vec<ScanOutput>,
    world: WorldPose,
    odom: PoseBuffer,
    scans: VecDeque<Arc<LioScan>>,
    first_ns: Option<u64>,
    /// The odometry's pose at `first_ns`: where the rig started, in its own frame.
    first_pose: Isometry3<f64>,
    next_align_ns: u64,
    in_flight: bool,
    /// Where the responder is expected to start (none: anywhere the robot has mapped).
    start_hint: Option<Isometry3<f64>>,
    map: Arc<Vec<Vector3<f64>>>,
    /// For each map point, the direction towards the robot's sensor that saw it (empty: not
    /// known; see [`Aligner::new_seen_from`]).
    map_seen_from: Arc<Vec<Vector3<f64>>>,
    map_raw_len: usize,
    coverage: Option<Arc<Coverage>>,
    pub attempts: usize,
    pub accepted: usize,
    /// Re-registrations refused in a row for contradicting the map, and alignments dropped.
    contradicted_in_row: u32,
    pub lost: usize,
    /// What the rig waits for before a world pose, from the last registration (see [`Self::waiting`]).
    waiting_for: Option<Waiting>,
    /// The first alignment waiting for confirmation.
    candidate: Option<Candidate>,
    /// What the first searches' windows held (see `RigCoreConfig::first_history_ns`).
    history: RigHistory,
    /// What the view draws of the rig's surroundings.
    view: RecentVoxels,
    /// `view`'s points grouped by block, rebuilt once per scan: the frame draws them in this
    /// order, so consecutive points land near each other on screen and in the depth buffer.
    view_sorted: Vec<Vector3<f64>>,
}

/// A first alignment that passed its tests, waiting for later searches to agree.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    first_end_ns: u64,
    world_t_odom: Isometry3<f64>,
    searches: u32,
}

impl RigCore {
    pub fn new(cfg: RigCoreConfig) -> Result<Self, PipelineError> {
        cfg.align.validate()?;
        cfg.track.validate()?;
        Ok(Self {
            lio: Lio::new(cfg.lio.clone()),
            world: WorldPose::new(cfg.world.clone()),
            placer: ScanPlacer::default(),
            outs: Vec::new(),
            odom: PoseBuffer::new(100_000),
            scans: VecDeque::new(),
            first_ns: None,
            first_pose: Isometry3::identity(),
            next_align_ns: 0,
            in_flight: false,
            start_hint: None,
            map: Arc::new(Vec::new()),
            map_seen_from: Arc::new(Vec::new()),
            map_raw_len: 0,
            coverage: None,
            attempts: 0,
            accepted: 0,
            contradicted_in_row: 0,
            lost: 0,
            waiting_for: None,
            candidate: None,
            history: RigHistory::new(cfg.window.voxel_m, cfg.first_history_ns),
            view: RecentVoxels::new(cfg.view_voxel_m, cfg.view_keep_ns),
            view_sorted: Vec::new(),
            cfg,
        })
    }

    /// Where the responder is expected to start, in the robot's world (a marked entry point, a
    /// hand-off next to the robot): the LiDAR's pose at the rig's first odometry pose. Until the
    /// first alignment, the odometry carries it to the rig's current pose to seed the search, and
    /// a result is refused when the start it implies (the result carried back by the odometry)
    /// lies more than `start_gate_m` from it: the responder may have walked far since.
    /// Without a hint the search starts from the world's origin, favours no seed for being near
    /// it, and takes a first alignment anywhere.
    pub fn set_start_hint(&mut self, world_t_lidar: Isometry3<f64>) {
        self.start_hint = Some(world_t_lidar);
    }

    pub fn start_hint(&self) -> Option<&Isometry3<f64>> {
        self.start_hint.as_ref()
    }

    /// The rig's odometry frame in the world, as the start hint places it. Without one, the
    /// world's own axes: both frames are levelled by gravity, so the search starts level
    /// (the rig's first pose may be tilted: a helmet looking down).
    fn hint_world_t_odom(&self) -> Isometry3<f64> {
        self.start_hint.map_or_else(Isometry3::identity, |h| h * self.first_pose.inverse())
    }

    /// The settings of the next registration: tracking once aligned; the seed search before,
    /// which without a start hint gives the guess no head start over the other seeds.
    fn job_config(&self, aligned: bool) -> AlignConfig {
        if aligned {
            return self.cfg.track.clone();
        }
        let mut config = self.cfg.align.clone();
        if self.start_hint.is_none() {
            config.seed_prior_margin = 0.0;
        }
        config
    }

    /// The robot's map (already one point per voxel of `voxel_m`, in its world); replaces the
    /// previous one.
    pub fn set_map(&mut self, points: Vec<Vector3<f64>>) {
        self.set_map_seen_from(points, Vec::new());
    }

    /// [`Self::set_map`] with, for each point, the direction from it towards the robot's
    /// sensor that saw it (zero where not known; another length: none known).
    pub fn set_map_seen_from(&mut self, points: Vec<Vector3<f64>>, towards_sensor: Vec<Vector3<f64>>) {
        self.map_raw_len = points.len();
        self.map = Arc::new(points);
        self.map_seen_from = Arc::new(towards_sensor);
    }

    /// The robot's map as of the last [`Self::set_map`] (a new `Arc` each time).
    pub fn map(&self) -> &Arc<Vec<Vector3<f64>>> {
        &self.map
    }

    pub fn map_len(&self) -> usize {
        self.map_raw_len
    }

    /// The space the robot's rays crossed, beside its map: acceptance then judges the overlap
    /// (see [`Aligner::with_coverage`]). Without it, the inlier ratio over the whole window.
    pub fn set_coverage(&mut self, coverage: Arc<Coverage>) {
        self.coverage = Some(coverage);
    }

    pub fn push_imu(&mut self, sample: ImuSample, out: &mut Vec<ScanOutput>) {
        self.lio.push_imu(sample, &mut self.outs);
        self.drain(out);
    }

    pub fn push_scan(&mut self, scan: LioScan, out: &mut Vec<ScanOutput>) {
        let shared = Arc::new(scan);
        self.placer.pending(Arc::clone(&shared));
        self.scans.push_back(Arc::clone(&shared));
        self.lio.push_scan(shared, &mut self.outs);
        self.drain(out);
    }

    fn drain(&mut self, out: &mut Vec<ScanOutput>) {
        let outs = std::mem::take(&mut self.outs);
        let new_view = !outs.is_empty();
        for o in outs {
            let placed = self.placer.place(&o);
            let points: Vec<Vector3<f64>> = placed.iter().map(|p| p.xyz()).collect();
            self.view.add(&points, o.end_ns);
            let _ = self.world.push_odometry(o.end_ns, o.lidar_pose);
            let _ = self.odom.push(o.end_ns, o.lidar_pose);
            if self.first_ns.is_none() {
                self.first_ns = Some(o.end_ns);
                self.first_pose = o.lidar_pose;
            }
            while self.scans.front().is_some_and(|s| s.end_ns + self.cfg.max_first_window_ns < o.end_ns) {
                self.scans.pop_front();
            }
            out.push(o);
        }
        // Reordered once per batch of scans, after all of them are in.
        if new_view {
            self.view.points_by_block(&mut self.view_sorted);
        }
    }

    /// The rig's points of the last `view_keep_ns`, one per voxel, in its odometry frame: what
    /// the view draws of the surroundings.
    pub fn view_points(&self) -> impl Iterator<Item = &Vector3<f64>> {
        self.view_sorted.iter()
    }

    pub fn first_ns(&self) -> Option<u64> {
        self.first_ns
    }

    /// End time and odometry pose of the newest scan.
    pub fn last(&self) -> Option<(u64, Isometry3<f64>)> {
        self.placer.last()
    }

    pub fn world(&self) -> &WorldPose {
        &self.world
    }

    pub fn world_mut(&mut self) -> &mut WorldPose {
        &mut self.world
    }

    pub fn aligned(&self) -> bool {
        self.world.correction().is_some()
    }

    /// What the rig waits for while it has no world pose: the map, the first registration, or
    /// what the last refused one lacked (for the status line).
    pub fn waiting(&self) -> Waiting {
        if self.map_raw_len <= self.cfg.min_map_points {
            return Waiting::Map;
        }
        self.waiting_for.unwrap_or(Waiting::FirstAttempt)
    }

    /// Whether a registration is due by time (the caller then hands over the newest map).
    pub fn wants_map(&self) -> bool {
        let (Some((end_ns, _)), Some(first)) = (self.placer.last(), self.first_ns) else { return false };
        let wait_ns = if self.aligned() { self.cfg.track_window_ns } else { self.cfg.first_window_ns };
        !self.in_flight && end_ns >= first + wait_ns && end_ns >= self.next_align_ns
    }

    /// The next registration, when one is due after the newest scan and none is running.
    /// `people_world` gives the people the robot sees now, in the world (asked only when a job
    /// is due); once the rig is placed in the world, their points are left out of the window.
    pub fn next_job(&mut self, people_world: impl FnOnce() -> Vec<OrientedBox>) -> Option<AlignJob> {
        if !self.wants_map() || self.map_raw_len <= self.cfg.min_map_points {
            return None;
        }
        let (end_ns, lidar_pose) = self.placer.last()?;
        let first = self.first_ns?;
        let aligned = self.aligned();
        let wait_ns = if aligned { self.cfg.track_window_ns } else { self.cfg.first_window_ns };
        let window_ns = if aligned { wait_ns } else { (end_ns - first).min(self.cfg.max_first_window_ns) };
        let from = end_ns.saturating_sub(window_ns);
        let scans = self.scans.iter().filter(|s| s.end_ns >= from && s.start_ns <= end_ns).cloned().collect();
        // Without a world pose the responder is taken to have started at the expected start and
        // moved as the odometry says since; the yaw grid does the rest.
        let guess =
            self.world.world_pose(end_ns).ok().flatten().unwrap_or_else(|| self.hint_world_t_odom() * lidar_pose);
        let people = if aligned { self.people_in_odometry(end_ns, &lidar_pose, &people_world()) } else { Vec::new() };
        self.attempts += 1;
        self.in_flight = true;
        self.next_align_ns = end_ns + if aligned { self.cfg.reregister_ns } else { self.cfg.retry_ns };
        Some(AlignJob {
            end_ns,
            tracking: aligned,
            window_ns,
            window: self.cfg.window.clone(),
            people,
            scans,
            history: if aligned { Arc::new(Vec::new()) } else { self.history.points() },
            keep_window: !aligned && self.cfg.first_history_ns > 0,
            odom: self.odom.clone(),
            target: Arc::clone(&self.map),
            target_seen_from: Arc::clone(&self.map_seen_from),
            coverage: self.coverage.clone(),
            config: self.job_config(aligned),
            lidar_pose,
            guess_world_t_lidar: guess,
        })
    }

    /// Takes a job's result: accepted registrations go into the world pose; a first alignment
    /// must also land near the expected start.
    pub fn apply(&mut self, outcome: Result<AlignOutcome, PipelineError>) -> AlignVerdict {
        self.in_flight = false;
        let o = match outcome {
            Ok(o) => o,
            Err(e) => return AlignVerdict::Failed { error: e.to_string() },
        };
        self.remember(&o);
        if !o.report.accepted {
            let failure = o.report.failure.unwrap_or(AlignFailure::NoAttempt);
            return self.refused(o.tracking, failure);
        }
        if o.tracking {
            self.contradicted_in_row = 0;
        }
        let first = !self.aligned();
        if let (true, Some(hint)) = (first, &self.start_hint) {
            let off_m = start_offset_m(&o.world_t_lidar, &o.odom_t_lidar, &self.first_pose, hint);
            if off_m > self.cfg.start_gate_m {
                self.candidate = None;
                return AlignVerdict::FarFromStart { off_m };
            }
        }
        if first {
            let world_t_odom = o.world_t_lidar * o.odom_t_lidar.inverse();
            if let Some(pending) = self.confirm(o.end_ns, world_t_odom) {
                return pending;
            }
        }
        if let Err(e) = self.world.push_registration(o.end_ns, o.world_t_lidar) {
            return AlignVerdict::Failed { error: e.to_string() };
        }
        self.accepted += 1;
        AlignVerdict::Accepted { first }
    }

    /// Keeps a search's window for the searches after it (what [`Self::apply`] does first; a
    /// diagnosis that never applies a result calls it itself). Re-registrations are not kept.
    pub fn remember(&mut self, o: &AlignOutcome) {
        if !o.tracking {
            self.history.merge(&o.window_odom, o.end_ns);
        }
    }

    /// A first alignment that passed its tests joins the candidate it agrees with (or starts a
    /// new one); `None` once the agreeing searches span `confirm_span_ns`, else the verdict.
    fn confirm(&mut self, end_ns: u64, world_t_odom: Isometry3<f64>) -> Option<AlignVerdict> {
        let needed_ns = self.cfg.confirm_span_ns;
        if needed_ns == 0 {
            return None;
        }
        let agrees = |c: &Candidate| {
            let (m, deg) = crate::align::pose_error(&c.world_t_odom, &world_t_odom);
            m <= self.cfg.confirm_agree_m && deg <= self.cfg.confirm_agree_deg
        };
        let c = match self.candidate {
            Some(c) if agrees(&c) => Candidate { world_t_odom, searches: c.searches + 1, ..c },
            _ => Candidate { first_end_ns: end_ns, world_t_odom, searches: 1 },
        };
        let span_ns = end_ns.saturating_sub(c.first_end_ns);
        if span_ns >= needed_ns && c.searches >= self.cfg.confirm_min_searches {
            self.candidate = None;
            return None;
        }
        self.candidate = Some(c);
        let verdict = AlignVerdict::Candidate { searches: c.searches, span_ns, needed_ns };
        self.waiting_for = Some(Waiting::Confirming { searches: c.searches });
        Some(verdict)
    }

    /// A refused registration; a re-registration refused for contradicting the map counts
    /// towards dropping the alignment.
    fn refused(&mut self, tracking: bool, failure: AlignFailure) -> AlignVerdict {
        if !self.aligned() {
            self.waiting_for = Some(Waiting::from_failure(&failure));
        }
        let contradicts = failure
            .because()
            .iter()
            .any(|r| matches!(r, Rejection::Contradicted { .. } | Rejection::SeesThroughMap { .. }));
        if !tracking || !self.aligned() {
            return AlignVerdict::Refused(failure);
        }
        self.contradicted_in_row = if contradicts { self.contradicted_in_row.saturating_add(1) } else { 0 };
        let limit = self.cfg.lose_after_contradictions;
        if limit == 0 || self.contradicted_in_row < limit {
            return AlignVerdict::Refused(failure);
        }
        self.world.lose();
        self.contradicted_in_row = 0;
        self.lost += 1;
        // Search again at the next scan, not after the re-registration interval.
        self.next_align_ns = 0;
        AlignVerdict::Lost(failure)
    }

    /// `people_world` as exclusion boxes in the rig's odometry frame (none before the rig is
    /// placed in the world).
    fn people_in_odometry(
        &self,
        end_ns: u64,
        odom_t_lidar: &Isometry3<f64>,
        people_world: &[OrientedBox],
    ) -> Vec<ExclusionBox> {
        let Ok(Some(world_t_lidar)) = self.world.world_pose(end_ns) else { return Vec::new() };
        let odom_t_world = odom_t_lidar * world_t_lidar.inverse();
        // Both frames are gravity-aligned: between them a turn about the vertical.
        let turn_rad = odom_t_world.rotation.euler_angles().2;
        let grow = Vector3::repeat(2.0 * self.cfg.people_margin_m.max(0.0));
        people_world
            .iter()
            .map(|b| ExclusionBox {
                centre: (odom_t_world * Point3::from(b.centre_m)).coords,
                size_m: b.size_m + grow,
                yaw_rad: b.yaw_rad + turn_rad,
            })
            .collect()
    }
}

/// How far from the expected start `hint` a registered pose `world_t_lidar` (the odometry's
/// `odom_t_lidar` at the same time) puts the rig's first odometry pose `first_pose`: the
/// registration carried back by the odometry to the start, which is what the hint is about.
fn start_offset_m(
    world_t_lidar: &Isometry3<f64>,
    odom_t_lidar: &Isometry3<f64>,
    first_pose: &Isometry3<f64>,
    hint: &Isometry3<f64>,
) -> f64 {
    let start = world_t_lidar * odom_t_lidar.inverse() * first_pose;
    (start.translation.vector - hint.translation.vector).norm()
}

/// Every this many window points is also kept as a ray (sensor to point): the free-space check
/// walks a few hundred.
const RAY_STRIDE: usize = 32;

/// The rig's scans over `[end - window, end]` placed in the odometry frame, each point with its
/// firing time (from the window's start); a sample of their rays (in the odometry frame too,
/// with their times); and the window's frame (at the rig's position at `end`, with the
/// odometry's gravity-aligned axes).
fn window(
    scans: &[Arc<LioScan>],
    odom: &PoseBuffer,
    end_ns: u64,
    window_ns: u64,
) -> (Vec<PlacedPoint>, Vec<(u32, Ray)>, Isometry3<f64>) {
    let Ok(at_end) = odom.at(end_ns) else { return (Vec::new(), Vec::new(), Isometry3::identity()) };
    let frame = Isometry3::from_parts(at_end.translation, UnitQuaternion::identity());
    let from = end_ns.saturating_sub(window_ns);
    let mut out = Vec::new();
    let mut rays = Vec::new();
    for s in scans.iter().filter(|s| s.end_ns >= from && s.start_ns <= end_ns) {
        let poses = ScanPoses::new(s.start_ns, s.end_ns, |t| odom.at(t).ok());
        for p in s.points.iter().filter(|p| p.t_ns >= from && p.t_ns <= end_ns) {
            if p.x_m * p.x_m + p.y_m * p.y_m + p.z_m * p.z_m <= 0.25 {
                continue;
            }
            let Some(pose) = poses.at(p.t_ns) else { continue };
            let t_us = u32::try_from((p.t_ns - from) / 1000).unwrap_or(u32::MAX);
            let q = pose * Point3::new(f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m));
            if out.len() % RAY_STRIDE == 0 {
                rays.push((t_us, Ray { origin: pose.translation.vector, end: q.coords }));
            }
            out.push(PlacedPoint::new(u64::from(t_us), &q.coords));
        }
    }
    (out, rays, frame)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::{
        start_offset_m, RigCore, RigCoreConfig, RIG_ACC_BIAS_SIGMA_M_S2, RIG_FIT_RMS_REF_M, RIG_GYRO_NOISE_RAD_S,
        RIG_MIN_DIRECTION_INFO, RIG_RESIDUAL_VAR_M2, RIG_SCAN_MIN_POINTS, RIG_STILL_ACC_SIGMAS,
        RIG_STILL_CHANGE_WEIGHT, RIG_STILL_MAX_ACC_M_S2, RIG_STILL_SIGMA_M_S,
    };
    use crate::align::pose_xyz_yaw;
    use crate::ar::OrientedBox;
    use crate::lio::{LioConfig, LioFile};
    use nalgebra::Vector3;

    #[test]
    fn the_shipped_rig_lio_config_is_the_rigs_defaults() {
        let file = LioFile::from_toml(include_str!("../../../config/lio_rig.toml")).unwrap();
        assert_eq!(file.to_config().unwrap(), RigCoreConfig::rig_lio());
        assert_eq!(RigCoreConfig::default().lio, RigCoreConfig::rig_lio());
        // Everything but the gyro's noise, the update's residual variance and weak-direction
        // threshold, the accelerometer bias tied to gravity, the still hold on matched scans and
        // the scans' finer voxels is the LIO's generic default.
        let mut generic = LioConfig {
            acc_bias_sigma_m_s2: RIG_ACC_BIAS_SIGMA_M_S2,
            still_max_acc_m_s2: RIG_STILL_MAX_ACC_M_S2,
            still_acc_sigmas: RIG_STILL_ACC_SIGMAS,
            still_change_weight: RIG_STILL_CHANGE_WEIGHT,
            still_sigma_m_s: RIG_STILL_SIGMA_M_S,
            scan_min_points: RIG_SCAN_MIN_POINTS,
            ..LioConfig::default()
        };
        generic.noise.gyro_rad_s = RIG_GYRO_NOISE_RAD_S;
        generic.update.residual_var_m2 = RIG_RESIDUAL_VAR_M2;
        generic.update.min_direction_info = RIG_MIN_DIRECTION_INFO;
        generic.update.fit_rms_ref_m = RIG_FIT_RMS_REF_M;
        assert_eq!(RigCoreConfig::rig_lio(), generic);
    }

    #[test]
    fn people_are_carried_into_the_odometry_frame_once_the_rig_is_placed() {
        let mut rig = RigCore::new(RigCoreConfig::default()).unwrap();
        let person =
            OrientedBox { centre_m: Vector3::new(12.0, 3.0, 0.9), size_m: Vector3::new(0.5, 0.4, 1.8), yaw_rad: 0.3 };
        let odom_t_lidar = pose_xyz_yaw(1.0, 0.0, 1.5, 0.0);
        rig.world_mut().push_odometry(1_000, odom_t_lidar).unwrap();
        rig.world_mut().push_odometry(2_000, odom_t_lidar).unwrap();
        assert!(rig.people_in_odometry(2_000, &odom_t_lidar, &[person]).is_empty(), "not placed yet");
        // The odometry frame sits at (10, 0) in the world, turned 90 deg.
        let world_t_odom = pose_xyz_yaw(10.0, 0.0, 0.0, 90.0);
        rig.world_mut().push_registration(2_000, world_t_odom * odom_t_lidar).unwrap();
        let boxes = rig.people_in_odometry(2_000, &odom_t_lidar, &[person]);
        assert_eq!(boxes.len(), 1);
        let b = boxes[0];
        // (12, 3) in the world is (2, 3) from the odometry's origin; turned back 90 deg: (3, -2).
        assert!((b.centre - Vector3::new(3.0, -2.0, 0.9)).norm() < 1e-9, "{:?}", b.centre);
        assert!((b.yaw_rad - (0.3 - std::f64::consts::FRAC_PI_2)).abs() < 1e-9);
        assert!((b.size_m - Vector3::new(0.8, 0.7, 2.1)).norm() < 1e-9, "0.15 m more on every side");
        assert!(b.contains(&Vector3::new(3.0, -2.0, 0.0)));
    }

    #[test]
    fn contradicted_re_registrations_in_a_row_drop_the_alignment() {
        use super::AlignVerdict;
        use crate::align::{AlignFailure, Rejection};
        let mut rig = RigCore::new(RigCoreConfig::default()).unwrap();
        let odom_t_lidar = pose_xyz_yaw(1.0, 0.0, 1.5, 0.0);
        rig.world_mut().push_odometry(1_000, odom_t_lidar).unwrap();
        rig.world_mut().push_registration(1_000, pose_xyz_yaw(5.0, 2.0, 1.5, 40.0)).unwrap();
        let failure = |r: Rejection| AlignFailure::NoneAccepted {
            attempts: 1,
            seeds: 1,
            best_seed_yaw_deg: 0.0,
            because: vec![r],
        };
        let contradicted = || failure(Rejection::Contradicted { ratio: 0.8, min: 0.96, contradicted: 300 });
        let degenerate = failure(Rejection::Degenerate { index: 0.001, min: 0.02, slide: None });
        // Two contradictions, then a refusal that says nothing against the alignment: the count
        // starts over.
        assert!(matches!(rig.refused(true, contradicted()), AlignVerdict::Refused(_)));
        assert!(matches!(rig.refused(true, contradicted()), AlignVerdict::Refused(_)));
        assert!(matches!(rig.refused(true, degenerate), AlignVerdict::Refused(_)));
        assert!(matches!(rig.refused(true, contradicted()), AlignVerdict::Refused(_)));
        assert!(matches!(rig.refused(true, contradicted()), AlignVerdict::Refused(_)));
        assert!(rig.aligned());
        assert!(matches!(rig.refused(true, contradicted()), AlignVerdict::Lost(_)));
        assert!(!rig.aligned() && rig.lost == 1, "placed nowhere again");
        // Refusals of a search (not tracking) never count.
        assert!(matches!(rig.refused(false, contradicted()), AlignVerdict::Refused(_)));
    }

    #[test]
    fn a_first_alignment_waits_until_searches_agree_over_the_span() {
        use super::AlignVerdict;
        use crate::align::{AlignFailure, Rejection};
        let s = 1_000_000_000;
        // A 3 s span, whatever the default: the sequence below needs four searches to apply.
        let three_s = RigCoreConfig { confirm_span_ns: 3 * s, ..RigCoreConfig::default() };
        let mut rig = RigCore::new(three_s.clone()).unwrap();
        let here = pose_xyz_yaw(4.0, 2.0, 0.0, 30.0);
        let flipped = pose_xyz_yaw(9.0, 2.0, 0.0, -150.0);
        let candidate = |v: Option<AlignVerdict>| match v {
            Some(AlignVerdict::Candidate { searches, .. }) => searches,
            other => panic!("{other:?}"),
        };
        assert_eq!(candidate(rig.confirm(3 * s, here)), 1);
        // Within 0.3 m and 3 deg: the same candidate.
        assert_eq!(candidate(rig.confirm(4 * s, pose_xyz_yaw(4.1, 2.1, 0.0, 31.0))), 2);
        // Elsewhere: a new candidate, counted from now.
        assert_eq!(candidate(rig.confirm(5 * s, flipped)), 1);
        assert_eq!(candidate(rig.confirm(6 * s, here)), 1);
        assert_eq!(candidate(rig.confirm(7 * s, here)), 2);
        // A refused search between them leaves the candidate standing.
        let refused = AlignFailure::NoneAccepted {
            attempts: 3,
            seeds: 12,
            best_seed_yaw_deg: 0.0,
            because: vec![Rejection::Residual { rms_m: 0.2, max_m: 0.1 }],
        };
        assert!(matches!(rig.refused(false, refused), AlignVerdict::Refused(_)));
        assert_eq!(candidate(rig.confirm(8 * s, here)), 3);
        rig.set_map(vec![Vector3::zeros(); 1001]);
        assert_eq!(rig.waiting(), super::Waiting::Confirming { searches: 3 });
        // 3 s after the first (6 s), and three searches or more: applied.
        assert!(rig.confirm(9 * s, here).is_none());
        // The span alone does not do: two searches 5 s apart wait for a third.
        let mut rig = RigCore::new(three_s).unwrap();
        assert_eq!(candidate(rig.confirm(3 * s, here)), 1);
        assert_eq!(candidate(rig.confirm(8 * s, here)), 2);
        assert!(rig.confirm(9 * s, here).is_none());
        let mut at_once = RigCore::new(RigCoreConfig { confirm_span_ns: 0, ..RigCoreConfig::default() }).unwrap();
        assert!(at_once.confirm(3 * s, flipped).is_none(), "0: the first is applied");
    }

    #[test]
    fn the_start_gate_measures_where_the_rig_started_not_where_it_is() {
        // The rig started at the odometry's origin facing +x, then walked 10 m ahead and turned
        // 90 deg left; the hint puts the start at (2, 3) facing +y in the world.
        let first = pose_xyz_yaw(0.0, 0.0, 1.5, 0.0);
        let now = pose_xyz_yaw(10.0, 0.0, 1.5, 90.0);
        let hint = pose_xyz_yaw(2.0, 3.0, 1.5, 90.0);
        // A registration that agrees with the hint and the odometry: 10 m from the hint, but its
        // start is the hint's.
        let right = pose_xyz_yaw(2.0, 13.0, 1.5, 180.0);
        assert!(start_offset_m(&right, &now, &first, &hint) < 1e-9);
        // Half a metre along the walk: its start is half a metre off too.
        let near = pose_xyz_yaw(2.0, 13.5, 1.5, 180.0);
        assert!((start_offset_m(&near, &now, &first, &hint) - 0.5).abs() < 1e-9);
        // On the hint itself (a gate on the current pose would pass it) but turned the other
        // way: the start it implies lies the walk's 10 m away.
        let flipped = pose_xyz_yaw(2.0, 3.0, 1.5, 0.0);
        assert!((start_offset_m(&flipped, &now, &first, &hint) - 10.0).abs() < 1e-9);
    }
}
