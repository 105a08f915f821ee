//! One module per subcommand; each has `Args` (or `Command`) and `run`.

pub mod demo;
pub mod devices;
pub mod export;
pub mod inspect;
pub mod livox;
pub mod mock;
pub mod replay;
