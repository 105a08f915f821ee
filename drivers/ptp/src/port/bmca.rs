//! BMCA-lite: keep the masters heard recently and pick the best by the 1588 data-set
//! comparison (priority1, class, accuracy, variance, priority2, identity; then steps removed and
//! sender port when two Announces name the same grandmaster).

use crate::message::{Announce, Flags, PortIdentity};
use std::cmp::Ordering;

/// A master whose Announces we hear.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ForeignMaster {
    pub port: PortIdentity,
    pub announce: Announce,
    pub flags: Flags,
    pub log_announce_interval: i8,
    /// Announces heard (a master qualifies with two, as 1588's FOREIGN_MASTER_THRESHOLD says).
    pub heard: u32,
    pub last_heard_ns: u64,
}

impl ForeignMaster {
    pub fn qualified(&self) -> bool {
        self.heard >= 2
    }
}

/// `Less` means `a` is the better master.
pub fn compare(a: &ForeignMaster, b: &ForeignMaster) -> Ordering {
    let (x, y) = (&a.announce, &b.announce);
    if x.gm_identity == y.gm_identity {
        return x.steps_removed.cmp(&y.steps_removed).then(a.port.cmp(&b.port));
    }
    let key = |m: &Announce| {
        (
            m.gm_priority1,
            m.gm_quality.clock_class,
            m.gm_quality.clock_accuracy,
            m.gm_quality.offset_scaled_log_variance,
            m.gm_priority2,
            m.gm_identity,
        )
    };
    key(x).cmp(&key(y))
}

/// At most this many masters are remembered: a flood of forged Announces cannot grow memory.
pub const MAX_FOREIGN: usize = 16;

/// The masters heard and the choice among them.
#[derive(Clone, Debug, Default)]
pub struct ForeignMasters {
    masters: Vec<ForeignMaster>,
}

impl ForeignMasters {
    /// Records an Announce from `port` heard at `now_ns`.
    pub fn heard(&mut self, port: PortIdentity, announce: Announce, flags: Flags, log_interval: i8, now_ns: u64) {
        if let Some(m) = self.masters.iter_mut().find(|m| m.port == port) {
            m.announce = announce;
            m.flags = flags;
            m.log_announce_interval = log_interval;
            m.heard = m.heard.saturating_add(1);
            m.last_heard_ns = now_ns;
            return;
        }
        if self.masters.len() >= MAX_FOREIGN {
            // Forget the one heard longest ago.
            if let Some(oldest) = self.masters.iter().enumerate().min_by_key(|(_, m)| m.last_heard_ns).map(|(i, _)| i) {
                self.masters.swap_remove(oldest);
            }
        }
        self.masters.push(ForeignMaster {
            port,
            announce,
            flags,
            log_announce_interval: log_interval,
            heard: 1,
            last_heard_ns: now_ns,
        });
    }

    /// Forgets masters silent for `timeout` of their announce intervals.
    pub fn expire(&mut self, now_ns: u64, timeout: u8) {
        self.masters.retain(|m| {
            let interval_ns = super::actions::log_interval(m.log_announce_interval).as_nanos() as u64;
            now_ns.saturating_sub(m.last_heard_ns) <= interval_ns.saturating_mul(timeout as u64)
        });
    }

    pub fn best(&self) -> Option<&ForeignMaster> {
        self.masters.iter().filter(|m| m.qualified()).min_by(|a, b| compare(a, b))
    }

    pub fn get(&self, port: &PortIdentity) -> Option<&ForeignMaster> {
        self.masters.iter().find(|m| &m.port == port)
    }

    pub fn len(&self) -> usize {
        self.masters.len()
    }

    pub fn is_empty(&self) -> bool {
        self.masters.is_empty()
    }
}
