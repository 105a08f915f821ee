//! One module per subcommand; each has `Args` (or `Command`) and `run`.

pub mod align;
pub mod base;
pub mod dataset;
pub mod demo;
pub mod detector_arg;
pub mod devices;
pub mod eval;
pub mod explore;
pub mod export;
pub mod fpv;
pub mod gen;
pub mod imu;
pub mod inspect;
pub mod link;
pub mod lio;
pub mod livox;
pub mod mission;
pub mod mock;
pub mod ptp;
pub mod rates;
pub mod replay;
pub mod rerun;
pub mod robot;
pub mod sim;
mod sim_live;

/// The tokio runtime every async subcommand runs on; two workers match the target machines.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?)
}
