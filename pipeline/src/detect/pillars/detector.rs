//! [`PillarsDetector`]: a window into the model frame, pillars, the network, peaks and rotated
//! NMS, and the boxes back in the world with the points inside them.

use super::decode::{peaks, rotated_nms, ModelBox};
use super::grid::{pillarize, GRID_TENSOR};
use super::net::{Net, NetTimes};
use super::weights::Weights;
use super::ModelFrame;
use crate::detect::{DetectConfig, DetectWindow, Detection, Detector, FloorModel, PersonPose, PillarsConfig};
use crate::PipelineError;
use nalgebra::Vector3;
use std::time::Instant;

/// The weights the program was built with (trained by scripts/train/pillars.py).
const BUILT_IN: &[u8] = include_bytes!("../../../../config/models/pillars.stpw");
/// A person's points start this far above the floor (their feet's returns are the floor's).
const PERSON_MIN_HEIGHT_M: f64 = 0.05;

/// The learned person detector (docs/pillars.md).
pub struct PillarsDetector {
    net: Net,
    detect_cfg: DetectConfig,
    cfg: PillarsConfig,
    last_floor: Option<FloorModel>,
    last_times: PillarsTimes,
}

/// Where one window's time went (ms), for the benchmark's split.
#[derive(Clone, Copy, Debug, Default)]
pub struct PillarsTimes {
    /// The floor estimate and the points into the model frame.
    pub frame_ms: f64,
    pub pillarize_ms: f64,
    pub net: NetTimes,
    pub decode_ms: f64,
    /// Each box's points.
    pub points_ms: f64,
}

impl PillarsDetector {
    /// The detector with the weights `cfg.pillars.model` names, or the built-in ones.
    pub fn new(cfg: &DetectConfig) -> Result<Self, PipelineError> {
        let bytes = match &cfg.pillars.model {
            Some(path) => {
                std::fs::read(path).map_err(|e| PipelineError::io(format!("reading {}", path.display()), e))?
            }
            None => BUILT_IN.to_vec(),
        };
        Self::from_weights(&Weights::parse(&bytes)?, cfg)
    }

    pub fn from_weights(weights: &Weights, cfg: &DetectConfig) -> Result<Self, PipelineError> {
        let grid = weights.get("grid", &[GRID_TENSOR.len()])?;
        if grid.iter().zip(&GRID_TENSOR).any(|(a, b)| (a - b).abs() > 1e-5) {
            return Err(PipelineError::BadFile {
                format: "STPW weights",
                reason: format!("trained for the grid {grid:?}, this program pillarizes {GRID_TENSOR:?}"),
            });
        }
        Ok(Self {
            net: Net::load(weights)?,
            detect_cfg: cfg.clone(),
            cfg: cfg.pillars.clone(),
            last_floor: None,
            last_times: PillarsTimes::default(),
        })
    }

    pub fn last_times(&self) -> PillarsTimes {
        self.last_times
    }

    /// The boxes of one window's model-frame points (before they go back to the world).
    pub fn model_boxes(&mut self, model_points: &[[f32; 3]]) -> Vec<ModelBox> {
        let t0 = Instant::now();
        let pillars = pillarize(model_points);
        let t1 = Instant::now();
        let features = self.net.pillar_features(&pillars);
        let canvas = Net::canvas(&pillars, &features);
        let t2 = Instant::now();
        let head = self.net.backbone(&canvas);
        let t3 = Instant::now();
        let boxes = rotated_nms(peaks(&head, self.cfg.min_score as f32), self.cfg.nms_iou);
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        self.last_times.pillarize_ms = ms(t0, t1);
        self.last_times.net = NetTimes { pfn_ms: ms(t1, t2), backbone_ms: ms(t2, t3) };
        self.last_times.decode_ms = ms(t3, Instant::now());
        boxes
    }
}

/// The indices of the model-frame points inside `b` and above the floor.
fn points_in(b: &ModelBox, model_points: &[[f32; 3]]) -> Vec<u32> {
    let (s, c) = b.yaw_rad.sin_cos();
    let half = b.size_m.map(|v| v / 2.0);
    model_points
        .iter()
        .enumerate()
        .filter(|(_, p)| {
            let (dx, dy, z) = (f64::from(p[0]) - b.centre_m[0], f64::from(p[1]) - b.centre_m[1], f64::from(p[2]));
            let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
            z >= PERSON_MIN_HEIGHT_M && u.abs() <= half[0] && v.abs() <= half[1] && (z - b.centre_m[2]).abs() <= half[2]
        })
        .map(|(i, _)| i as u32)
        .collect()
}

fn pose_of(class: usize) -> PersonPose {
    match class {
        0 => PersonPose::Upright,
        3 => PersonPose::Lying,
        _ => PersonPose::Low,
    }
}

impl Detector for PillarsDetector {
    fn name(&self) -> &'static str {
        "pointpillars"
    }

    fn detect(&mut self, window: &DetectWindow<'_>, out: &mut Vec<Detection>) {
        let t0 = Instant::now();
        let frame = ModelFrame::of_window(window, &self.detect_cfg, self.cfg.sensor_height_m);
        self.last_floor = Some(*frame.floor());
        let model_points: Vec<[f32; 3]> = window.points.iter().map(|p| frame.point_to_model(p)).collect();
        self.last_times.frame_ms = (Instant::now() - t0).as_secs_f64() * 1e3;
        let boxes = self.model_boxes(&model_points);
        let t1 = Instant::now();
        for b in boxes {
            out.push(Detection {
                stamp: window.stamp,
                centre_m: frame.to_world(b.centre_m),
                size_m: Vector3::from(b.size_m),
                yaw_rad: frame.yaw_rad() + b.yaw_rad,
                score: b.score,
                pose: pose_of(b.class),
                point_indices: points_in(&b, &model_points),
            });
        }
        self.last_times.points_ms = (Instant::now() - t1).as_secs_f64() * 1e3;
    }

    fn last_floor(&self) -> Option<FloorModel> {
        self.last_floor
    }
}
