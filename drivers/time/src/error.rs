use crate::Clock;
use thiserror::Error;

/// Everything that can go wrong in the time crate.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum TimeError {
    #[error("clock model for {expected} stamps was given a {got} stamp")]
    WrongClock { expected: Clock, got: Clock },
    #[error("clock model: the host side of a pair must be a host stamp, got {0}")]
    NotHost(Clock),
    #[error("clock model: configuration {0}")]
    BadConfig(&'static str),
}
