//! DJI M3508 motors with C620 ESCs: the frames ([`frame`]) and a wheel group with host-side
//! velocity loops ([`group`]).

pub mod frame;
pub mod group;

pub use frame::{CommandGroup, CurrentCommand, Feedback};
pub use group::{C620Config, C620Group};
