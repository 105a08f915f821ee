//! Admission for the network views (browser and Foxglove): every TCP connection is counted the
//! moment it is accepted, before a byte of HTTP or WebSocket handshake is read, against a cap on
//! all connections and a cap per source address. A connection must send its whole request (the
//! HTTP head, or the WebSocket upgrade) within the request deadline or it is closed; and while
//! the server is full, the connection that has waited longest without a request is closed to make
//! room for the new one. So sockets that connect and say nothing, or trickle half a request
//! (slowloris), cost a bounded number of file descriptors and tasks and never lock real viewers
//! out. Only once its request is read does a connection compete for one of the server's serving
//! slots (the browser's 8, Foxglove's 16).

use serde::Serialize;
use std::collections::{BTreeSet, HashMap};
use std::future::Future;
use std::net::IpAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;
use tokio::sync::oneshot;

/// The caps a server applies at accept time (`[view]` keys `max_connections`,
/// `max_connections_per_address`, `request_timeout_ms`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConnLimits {
    /// Connections held at once: those still sending their request plus those being served.
    pub max_connections: usize,
    /// Of those, from one source address.
    pub max_per_address: usize,
    /// Time a connection has to send its whole request, from accept.
    pub request_timeout: Duration,
}

/// `max_connections` when not configured.
pub const DEFAULT_MAX_CONNECTIONS: usize = 64;
/// `max_connections_per_address` when not configured: a browser holds the stream and polls the
/// status (two or three at once); a Foxglove client holds one.
pub const DEFAULT_MAX_PER_ADDRESS: usize = 8;
/// `request_timeout_ms` when not configured: a phone on a weak WiFi link sends a few hundred
/// bytes of request in well under a second.
pub const DEFAULT_REQUEST_TIMEOUT_MS: u64 = 3000;

impl Default for ConnLimits {
    fn default() -> Self {
        Self {
            max_connections: DEFAULT_MAX_CONNECTIONS,
            max_per_address: DEFAULT_MAX_PER_ADDRESS,
            request_timeout: Duration::from_millis(DEFAULT_REQUEST_TIMEOUT_MS),
        }
    }
}

/// What a server's gate has seen: counters since it started, and the connections held now.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ConnCounts {
    /// Connections taken from the listener (every one below is also counted here).
    pub accepted: u64,
    /// Closed at once: `max_connections` held and none of them still waiting for its request.
    pub refused_full: u64,
    /// Closed at once: `max_connections_per_address` held from that address.
    pub refused_per_address: u64,
    /// Closed without a whole request to make room for a newer connection.
    pub evicted: u64,
    /// Closed without a whole request within `request_timeout_ms`.
    pub timed_out: u64,
    /// Requests refused for a missing (401) or wrong (403) token.
    pub unauthorized: u64,
    /// Requests refused because every serving slot was taken (503).
    pub busy: u64,
    /// Connections held now.
    pub held: u64,
    /// Of those, still sending their request.
    pub pending: u64,
}

/// Why a connection was closed at accept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Refusal {
    Full,
    PerAddress,
}

/// Why a connection's request was never read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Unread {
    TimedOut,
    Evicted,
}

#[derive(Default)]
struct Counters {
    accepted: AtomicU64,
    refused_full: AtomicU64,
    refused_per_address: AtomicU64,
    evicted: AtomicU64,
    timed_out: AtomicU64,
    unauthorized: AtomicU64,
    busy: AtomicU64,
}

struct Held {
    ip: IpAddr,
    /// Present while the connection waits for its request: firing it closes the connection.
    evict: Option<oneshot::Sender<()>>,
}

#[derive(Default)]
struct State {
    held: HashMap<u64, Held>,
    per_address: HashMap<IpAddr, usize>,
    /// Ids still waiting for their request; ids grow, so the first is the oldest.
    pending: BTreeSet<u64>,
    next_id: u64,
}

impl State {
    fn remove(&mut self, id: u64) -> Option<Held> {
        let held = self.held.remove(&id)?;
        self.pending.remove(&id);
        if let Some(n) = self.per_address.get_mut(&held.ip) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                self.per_address.remove(&held.ip);
            }
        }
        Some(held)
    }
}

/// One server's admission state; shared by its accept loop and its connection tasks.
pub(crate) struct Gate {
    limits: ConnLimits,
    state: Mutex<State>,
    counters: Counters,
}

impl Gate {
    pub(crate) fn new(limits: ConnLimits) -> Arc<Self> {
        Arc::new(Self { limits, state: Mutex::new(State::default()), counters: Counters::default() })
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // Nothing panics while the lock is held; a poisoned lock still holds consistent counts.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Counts a connection just accepted from `ip`. When the server is full, the oldest
    /// connection still waiting for its request is closed to make room (a real viewer sends its
    /// request within milliseconds, so it is never the oldest for long).
    pub(crate) fn admit(self: &Arc<Self>, ip: IpAddr) -> Result<Ticket, Refusal> {
        self.counters.accepted.fetch_add(1, Ordering::Relaxed);
        let mut state = self.state();
        if state.per_address.get(&ip).copied().unwrap_or(0) >= self.limits.max_per_address {
            self.counters.refused_per_address.fetch_add(1, Ordering::Relaxed);
            return Err(Refusal::PerAddress);
        }
        if state.held.len() >= self.limits.max_connections {
            let Some(oldest) = state.pending.first().copied() else {
                self.counters.refused_full.fetch_add(1, Ordering::Relaxed);
                return Err(Refusal::Full);
            };
            if let Some(victim) = state.remove(oldest) {
                if let Some(evict) = victim.evict {
                    // The victim's task may have ended on its own meanwhile; nothing to close then.
                    let _ = evict.send(());
                }
                self.counters.evicted.fetch_add(1, Ordering::Relaxed);
            }
        }
        let id = state.next_id;
        state.next_id += 1;
        let (evict, evicted) = oneshot::channel();
        state.held.insert(id, Held { ip, evict: Some(evict) });
        state.pending.insert(id);
        *state.per_address.entry(ip).or_insert(0) += 1;
        Ok(Ticket { gate: self.clone(), id, evicted: Some(evicted) })
    }

    pub(crate) fn count_unauthorized(&self) {
        self.counters.unauthorized.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn count_busy(&self) {
        self.counters.busy.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn counts(&self) -> ConnCounts {
        let c = &self.counters;
        let (held, pending) = {
            let state = self.state();
            (state.held.len() as u64, state.pending.len() as u64)
        };
        ConnCounts {
            accepted: c.accepted.load(Ordering::Relaxed),
            refused_full: c.refused_full.load(Ordering::Relaxed),
            refused_per_address: c.refused_per_address.load(Ordering::Relaxed),
            evicted: c.evicted.load(Ordering::Relaxed),
            timed_out: c.timed_out.load(Ordering::Relaxed),
            unauthorized: c.unauthorized.load(Ordering::Relaxed),
            busy: c.busy.load(Ordering::Relaxed),
            held,
            pending,
        }
    }
}

/// A connection's place in the count; dropping it (the connection's task ending) frees it.
pub(crate) struct Ticket {
    gate: Arc<Gate>,
    id: u64,
    evicted: Option<oneshot::Receiver<()>>,
}

impl Ticket {
    /// Runs `read` (reading the request) under the request deadline. It is cut short when the
    /// deadline passes or the gate evicts this connection; once it completes, the connection is
    /// no longer evictable.
    pub(crate) async fn read_request<T>(&mut self, read: impl Future<Output = T>) -> Result<T, Unread> {
        let Some(evicted) = self.evicted.take() else { return Err(Unread::Evicted) };
        let deadline = self.gate.limits.request_timeout;
        let read = tokio::select! {
            // The sender goes only when this connection is evicted (it lives in the gate until
            // then), so either outcome of the receiver means evicted.
            _ = evicted => return Err(Unread::Evicted),
            r = tokio::time::timeout(deadline, read) => r,
        };
        let Ok(value) = read else {
            self.gate.counters.timed_out.fetch_add(1, Ordering::Relaxed);
            return Err(Unread::TimedOut);
        };
        let mut state = self.gate.state();
        // Evicted in the same instant the request completed: it is already off the books.
        let Some(held) = state.held.get_mut(&self.id) else { return Err(Unread::Evicted) };
        held.evict = None;
        state.pending.remove(&self.id);
        Ok(value)
    }
}

impl Drop for Ticket {
    fn drop(&mut self) {
        self.gate.state().remove(self.id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits(max_connections: usize, max_per_address: usize) -> ConnLimits {
        ConnLimits { max_connections, max_per_address, request_timeout: Duration::from_millis(50) }
    }

    fn ip(last: u8) -> IpAddr {
        IpAddr::from([127, 0, 1, last])
    }

    #[test]
    fn the_per_address_cap_refuses_and_dropping_a_ticket_frees_its_place() {
        let gate = Gate::new(limits(10, 2));
        let a = gate.admit(ip(1));
        let b = gate.admit(ip(1));
        assert!(a.is_ok() && b.is_ok());
        assert_eq!(gate.admit(ip(1)).err(), Some(Refusal::PerAddress));
        assert!(gate.admit(ip(2)).is_ok(), "another address is not held back");
        drop(a);
        let c = gate.admit(ip(1));
        assert!(c.is_ok());
        let counts = gate.counts();
        assert_eq!((counts.accepted, counts.refused_per_address, counts.held), (5, 1, 2));
        drop((b, c));
        assert_eq!(gate.counts().held, 0);
    }

    #[tokio::test]
    async fn a_full_gate_evicts_the_oldest_pending_and_refuses_when_none_is_pending() {
        let gate = Gate::new(limits(2, 2));
        let mut first = gate.admit(ip(1)).map_err(|_| "first").unwrap_or_else(|e| panic!("{e}"));
        let mut second = gate.admit(ip(2)).map_err(|_| "second").unwrap_or_else(|e| panic!("{e}"));
        // The third evicts the first, which was waiting for its request.
        let mut third = gate.admit(ip(3)).map_err(|_| "third").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(first.read_request(async {}).await, Err(Unread::Evicted));
        assert_eq!(gate.counts().evicted, 1);
        // Second and third read their requests: now neither may be evicted, and a fourth is refused.
        assert_eq!(second.read_request(async { 2 }).await, Ok(2));
        assert_eq!(third.read_request(async { 3 }).await, Ok(3));
        assert_eq!(gate.admit(ip(4)).err(), Some(Refusal::Full));
        let counts = gate.counts();
        assert_eq!((counts.held, counts.pending, counts.refused_full), (2, 0, 1));
        drop(first);
        assert_eq!(gate.counts().held, 2, "an evicted ticket was already off the books");
    }

    #[tokio::test]
    async fn a_request_that_does_not_arrive_in_time_is_cut_and_counted() {
        let gate = Gate::new(limits(4, 4));
        let mut t = gate.admit(ip(1)).map_err(|_| "admit").unwrap_or_else(|e| panic!("{e}"));
        let never = std::future::pending::<()>();
        assert_eq!(t.read_request(never).await, Err(Unread::TimedOut));
        assert_eq!(gate.counts().timed_out, 1);
        drop(t);
        assert_eq!(gate.counts().held, 0);
    }
}
