//! The tokio loop that drives one sans-IO port: datagrams and timestamps in, actions out.

use super::adjust::ClockAdjuster;
use super::socket::PtpSockets;
use super::timestamping::realtime_ns;
use crate::error::{PtpError, Result};
use crate::port::{Action, Port, Timer, TxTag};
use std::collections::{BTreeMap, VecDeque};
use std::future::Future;
use std::time::Duration;
use tokio::time::Instant;

/// A transmit stamp older than this is given up on (ptp4l waits 1 ms by default; software
/// stamps on a busy 2-core host can take longer).
const TX_STAMP_TIMEOUT: Duration = Duration::from_millis(100);

/// Counters of the transport itself.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TransportStats {
    pub rx_event: u64,
    pub rx_general: u64,
    /// Event datagrams without a kernel receive stamp (stamped from user space instead).
    pub rx_unstamped: u64,
    pub tx_stamps: u64,
    pub tx_stamps_lost: u64,
    pub send_errors: u64,
    pub clock_adjustments: u64,
}

struct Loop {
    sockets: PtpSockets,
    adjuster: Option<ClockAdjuster>,
    timers: BTreeMap<Timer, Instant>,
    pending_tx: VecDeque<(u32, TxTag, Instant)>,
    stats: TransportStats,
}

impl Loop {
    async fn apply(&mut self, port: &mut Port, actions: Vec<Action>) {
        let mut queue: VecDeque<Action> = actions.into();
        while let Some(action) = queue.pop_front() {
            match action {
                Action::ArmTimer { timer, after } => {
                    self.timers.insert(timer, Instant::now() + after);
                }
                Action::SendGeneral { data } => {
                    if let Err(e) = self.sockets.send_general(&data).await {
                        self.stats.send_errors += 1;
                        tracing::warn!("send on the general port: {e}");
                    }
                }
                Action::SendEvent { data, tag } => match self.sockets.send_event(&data).await {
                    Ok(id) => self.pending_tx.push_back((id, tag, Instant::now())),
                    Err(e) => {
                        self.stats.send_errors += 1;
                        tracing::warn!("send on the event port: {e}");
                    }
                },
                Action::StepClock { offset_ns } => match &self.adjuster {
                    Some(a) => match a.step(offset_ns) {
                        Ok(()) => {
                            self.stats.clock_adjustments += 1;
                            tracing::info!("stepped {} by {offset_ns} ns", a.name());
                        }
                        Err(e) => tracing::warn!("{e}"),
                    },
                    None => tracing::debug!("measure-only: not stepping by {offset_ns} ns"),
                },
                Action::SetFrequency { ppb } => match &self.adjuster {
                    Some(a) => match a.set_frequency(ppb) {
                        Ok(()) => self.stats.clock_adjustments += 1,
                        Err(e) => tracing::warn!("{e}"),
                    },
                    None => tracing::debug!("measure-only: not setting frequency {ppb:.0} ppb"),
                },
            }
            // Follow-ups of what we just did (a Follow_Up after a Sync's stamp) join the queue.
            let mut stamps = Vec::new();
            self.sockets.drain_tx_stamps(&mut stamps);
            for a in self.tx_stamps(port, stamps) {
                queue.push_back(a);
            }
        }
    }

    /// Hands transmit stamps to the port and returns what it wants done.
    fn tx_stamps(&mut self, port: &mut Port, stamps: Vec<(u32, super::timestamping::KernelStamps)>) -> Vec<Action> {
        let mut out = Vec::new();
        for (id, stamps) in stamps {
            let Some(pos) = self.pending_tx.iter().position(|(pid, _, _)| *pid == id) else { continue };
            let Some((_, tag, _)) = self.pending_tx.remove(pos) else { continue };
            match stamps.get(self.sockets.mode) {
                Some(ns) => {
                    self.stats.tx_stamps += 1;
                    out.extend(port.handle_tx_timestamp(tag, ns));
                }
                None => self.stats.tx_stamps_lost += 1,
            }
        }
        let now = Instant::now();
        while let Some((_, tag, at)) = self.pending_tx.front() {
            if now.duration_since(*at) < TX_STAMP_TIMEOUT {
                break;
            }
            tracing::warn!("no transmit timestamp for {tag:?} within {TX_STAMP_TIMEOUT:?}");
            self.stats.tx_stamps_lost += 1;
            self.pending_tx.pop_front();
        }
        out
    }
}

/// Runs `port` on `sockets` until `stop` completes. `on_status` is called once a second with the
/// port and the transport's counters. With `adjuster` (an explicit, non-default choice) the
/// slave's servo actions steer that clock; without it they are logged and dropped.
pub async fn run_port(
    mut port: Port,
    sockets: PtpSockets,
    adjuster: Option<ClockAdjuster>,
    mut on_status: impl FnMut(&Port, &TransportStats),
    stop: impl Future<Output = ()>,
) -> Result<(Port, TransportStats)> {
    let mut lp = Loop {
        sockets,
        adjuster,
        timers: BTreeMap::new(),
        pending_tx: VecDeque::new(),
        stats: TransportStats::default(),
    };
    let start = port.start();
    lp.apply(&mut port, start).await;
    let mut status = tokio::time::interval_at(Instant::now() + Duration::from_secs(1), Duration::from_secs(1));
    status.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut event_buf = vec![0u8; 2048];
    let mut general_buf = vec![0u8; 2048];
    tokio::pin!(stop);
    loop {
        let next_timer = lp.timers.iter().min_by_key(|(_, at)| **at).map(|(t, at)| (*t, *at));
        let timer_at = next_timer.map(|(_, at)| at).unwrap_or_else(|| Instant::now() + Duration::from_secs(3600));
        let waiting_tx = !lp.pending_tx.is_empty();
        let actions = tokio::select! {
            _ = &mut stop => break,
            r = lp.sockets.recv_event(&mut event_buf) => {
                let (n, stamps) = r.map_err(|e| PtpError::io("receive on the event port", e))?;
                lp.stats.rx_event += 1;
                let rx = stamps.get(lp.sockets.mode).unwrap_or_else(|| {
                    lp.stats.rx_unstamped += 1;
                    realtime_ns()
                });
                port.handle_event(event_buf.get(..n).unwrap_or_default(), rx)
            }
            r = lp.sockets.recv_general(&mut general_buf) => {
                let n = r.map_err(|e| PtpError::io("receive on the general port", e))?;
                lp.stats.rx_general += 1;
                port.handle_general(general_buf.get(..n).unwrap_or_default(), realtime_ns())
            }
            r = lp.sockets.tx_stamp_ready() => {
                r.map_err(|e| PtpError::io("error queue", e))?;
                let mut stamps = Vec::new();
                lp.sockets.drain_tx_stamps(&mut stamps);
                lp.tx_stamps(&mut port, stamps)
            }
            _ = tokio::time::sleep(Duration::from_millis(1)), if waiting_tx => {
                let mut stamps = Vec::new();
                lp.sockets.drain_tx_stamps(&mut stamps);
                lp.tx_stamps(&mut port, stamps)
            }
            _ = tokio::time::sleep_until(timer_at), if next_timer.is_some() => {
                let mut out = Vec::new();
                let now = Instant::now();
                let due: Vec<Timer> = lp.timers.iter().filter(|(_, at)| **at <= now).map(|(t, _)| *t).collect();
                for t in due {
                    lp.timers.remove(&t);
                    out.extend(port.handle_timer(t, realtime_ns()));
                }
                out
            }
            _ = status.tick() => {
                on_status(&port, &lp.stats);
                Vec::new()
            }
        };
        lp.apply(&mut port, actions).await;
    }
    Ok((port, lp.stats))
}
