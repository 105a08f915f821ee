//! Scoring a STARC mission against the simulator's truth: the readers of what `starc sim`
//! writes, the scorer the offline and live missions feed, and report.json.
//!
//! - [`truth`]: TUM trajectories, people.csv, camera frames and masks, the camera mounting, the
//!   robot's per-return labels, and [`Truth`], all of one run.
//! - [`score`]: [`Scorer`], fed the run's events (robot poses, detections, alignments, AR
//!   frames), finished into a [`Report`].
//! - [`detection`]: the true people of a detection window; [`overlay`]: person coverage and
//!   people shown, which drawing fewer points cannot raise.
//! - [`report`]: report.json's types; [`summary()`]: the lines printed; [`quantiles()`].
//! - [`svg_plot`]: small SVG plots; [`plots`]: the report's three.
//! - [`offline`]: the offline mission (both sides in one process) run, scored and written.
//! - [`batch`]: many runs at once (`starc eval`): rows, summaries per family, strip plots.
//!
//! ```no_run
//! # fn f(dir: &std::path::Path, out: &std::path::Path) -> Result<(), starc_eval::EvalError> {
//! use starc_eval::{summary, LatencyReport, MemoryReport, Scorer, Truth};
//! let mut score = Scorer::new(Truth::load(dir)?);
//! // ... score.robot_pose(..), score.detection(..), score.alignment(..), score.frame(..) ...
//! let memory = MemoryReport { peak_rss_mib: None, note: None };
//! let report = score.finish("offline", LatencyReport::default(), &[], memory, 0.0, out)?;
//! print!("{}", summary(&report));
//! # Ok(()) }
//! ```

pub mod ap;
pub mod batch;
pub mod clusters;
pub mod dataset;
pub mod detection;
pub mod drift;
pub mod error;
pub mod explore_loop;
pub mod explore_sim;
pub mod map_sight;
pub mod odometry;
pub mod offline;
pub mod overlay;
pub mod plots;
pub mod quantiles;
pub mod report;
pub mod score;
pub mod summary;
pub mod svg_plot;
pub mod truth;
pub mod wheels;

pub use error::{EvalError, Result};
pub use quantiles::{quantiles, Quantiles};
pub use report::{
    AlignmentReport, DetectionReport, InlierReport, LatencyReport, MapSightReport, MemoryReport, OverlayReport,
    PoseErrorReport, Report, RobotPoseErrorReport,
};
pub use score::Scorer;
pub use summary::summary;
pub use truth::{CameraFrame, CameraMount, Mask, PersonBox, PersonReturns, Trajectory, TruePose, Truth};
