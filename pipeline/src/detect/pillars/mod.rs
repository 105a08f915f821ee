//! The learned detector: a small PointPillars with a centre-heatmap head, trained on generated
//! development buildings (scripts/train/pillars.py) and run here on the CPU. docs/pillars.md is
//! the contract between the dataset, the training and this inference.

pub mod decode;
mod detector;
mod frame;
pub mod grid;
pub mod net;
pub mod npy;
pub mod weights;

pub use detector::{PillarsDetector, PillarsTimes};
pub use frame::ModelFrame;
