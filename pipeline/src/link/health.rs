//! The link's health from the peer's heartbeats, sans-IO: time comes in as host nanoseconds.
//!
//! `Up` while heartbeats arrive; `Stale` once none came for `stale_after_ms` (the rig keeps
//! drawing, greyed, with the last map and people); `Lost` after `lost_after_ms` (WiFi gone); back
//! to `Up` on the next heartbeat, which counts a resumption. Before the first heartbeat the link
//! is `Lost` (nothing heard) and that first one is no resumption.

use std::fmt;

use crate::PipelineError;

/// Thresholds, milliseconds since the last heartbeat.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthConfig {
    pub stale_after_ms: u64,
    pub lost_after_ms: u64,
}

impl HealthConfig {
    pub fn validate(&self) -> Result<(), PipelineError> {
        if self.stale_after_ms == 0 || self.lost_after_ms <= self.stale_after_ms {
            return Err(PipelineError::BadFile {
                format: "link health config",
                reason: format!(
                    "need 0 < stale_after_ms ({}) < lost_after_ms ({})",
                    self.stale_after_ms, self.lost_after_ms
                ),
            });
        }
        Ok(())
    }
}

/// Where the link stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LinkState {
    /// Heartbeats arrive.
    Up,
    /// None for `stale_after_ms`: what was received is still shown, marked stale.
    Stale,
    /// None for `lost_after_ms`, or none yet.
    Lost,
}

impl LinkState {
    pub fn name(self) -> &'static str {
        match self {
            LinkState::Up => "up",
            LinkState::Stale => "stale",
            LinkState::Lost => "lost",
        }
    }
}

impl fmt::Display for LinkState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The state machine.
#[derive(Clone, Debug)]
pub struct LinkHealth {
    cfg: HealthConfig,
    state: LinkState,
    last_heartbeat_ns: Option<u64>,
    /// Up -> Stale transitions.
    stalls: u64,
    /// Transitions into Lost from Up or Stale.
    drops: u64,
    /// Stale or Lost -> Up after the first Up.
    resumptions: u64,
    heartbeats: u64,
}

impl LinkHealth {
    pub fn new(cfg: HealthConfig) -> Result<Self, PipelineError> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            state: LinkState::Lost,
            last_heartbeat_ns: None,
            stalls: 0,
            drops: 0,
            resumptions: 0,
            heartbeats: 0,
        })
    }

    /// A heartbeat arrived at `now_ns`; returns the new state if it changed.
    pub fn on_heartbeat(&mut self, now_ns: u64) -> Option<LinkState> {
        // A silence that nobody ticked through still counts as a stall or a loss.
        self.tick(now_ns);
        self.heartbeats += 1;
        self.last_heartbeat_ns = Some(now_ns);
        if self.state == LinkState::Up {
            return None;
        }
        if self.heartbeats > 1 {
            self.resumptions += 1;
        }
        self.state = LinkState::Up;
        Some(LinkState::Up)
    }

    /// Time passes: returns the new state if it changed.
    pub fn tick(&mut self, now_ns: u64) -> Option<LinkState> {
        let last = self.last_heartbeat_ns?;
        let silent_ms = now_ns.saturating_sub(last) / 1_000_000;
        let next = if silent_ms >= self.cfg.lost_after_ms {
            LinkState::Lost
        } else if silent_ms >= self.cfg.stale_after_ms {
            LinkState::Stale
        } else {
            LinkState::Up
        };
        // Only silence moves the state down here; going up takes a heartbeat.
        let worse = matches!(
            (self.state, next),
            (LinkState::Up, LinkState::Stale) | (LinkState::Up | LinkState::Stale, LinkState::Lost)
        );
        if !worse {
            return None;
        }
        if next == LinkState::Stale {
            self.stalls += 1;
        } else {
            self.drops += 1;
        }
        self.state = next;
        Some(next)
    }

    pub fn state(&self) -> LinkState {
        self.state
    }

    /// Milliseconds since the last heartbeat at `now_ns`, None before the first.
    pub fn silent_ms(&self, now_ns: u64) -> Option<u64> {
        self.last_heartbeat_ns.map(|t| now_ns.saturating_sub(t) / 1_000_000)
    }

    /// Times the link went from Up to Stale.
    pub fn stalls(&self) -> u64 {
        self.stalls
    }

    /// Times the link was lost (after having been up).
    pub fn drops(&self) -> u64 {
        self.drops
    }

    /// Times it came back up after a stall or a loss.
    pub fn resumptions(&self) -> u64 {
        self.resumptions
    }

    pub fn heartbeats(&self) -> u64 {
        self.heartbeats
    }
}
