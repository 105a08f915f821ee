//! `LinkNode`: one end of the link on a zenoh session. It publishes what the caller gives it,
//! hands the peer's messages to the caller through a bounded queue, and runs its own heartbeats,
//! clock probes and (robot side) map queryable in tasks it owns.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use starc_pipeline::link::{
    decode, encode, kind_name, map_tile_id, ClockOffset, LinkHealth, LinkMessage, LinkState, OffsetEstimate, Role,
};
use starc_time::Stamp;
use tokio::sync::{mpsc, watch};
use tokio::task::{JoinHandle, JoinSet};
use tokio::time::MissedTickBehavior;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::sample::Sample;
use zenoh::Session;

use crate::acl::{self, Refusal};
use crate::keys::{map_key, message_key, sender_wildcard};
use crate::queue::BoundedQueue;
use crate::stats::{LatencySummary, LatencyWindow};
use crate::{LinkConfig, LinkError};

type TileKey = (i32, i32, i32);

/// Host realtime clock, nanoseconds (the clock every stamp on the link is in).
pub fn host_now_ns() -> u64 {
    Stamp::host_now().ns
}

/// One message from the peer.
#[derive(Clone, Debug, PartialEq)]
pub struct Received {
    pub msg: LinkMessage,
    /// When it arrived, local host clock.
    pub recv_host_ns: u64,
    /// Arrival minus the sender's `sent_host_ns` moved onto the local clock by the current offset
    /// estimate (heartbeats and detections; None for other kinds or before the first estimate).
    pub latency_ns: Option<i64>,
    /// Arrival minus `sent_host_ns` as stamped, no offset applied: the latency itself when both
    /// hosts are synchronised (PTP, NTP) or are one host.
    pub raw_latency_ns: Option<i64>,
    /// Came as an answer to a map fetch rather than as a publication.
    pub fetched: bool,
}

/// Where the link stands, for the caller's status line and logs.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkReport {
    pub state: LinkState,
    /// Since the peer's last heartbeat (None before the first).
    pub silent_ms: Option<u64>,
    pub stalls: u64,
    pub drops: u64,
    pub resumptions: u64,
    pub heartbeats: u64,
    /// Peer clock minus ours.
    pub clock: Option<OffsetEstimate>,
    /// Heartbeat transport latency (offset-corrected).
    pub heartbeat_latency: Option<LatencySummary>,
    /// Detections transport latency: `sent_host_ns` to arrival (offset-corrected).
    pub detections_latency: Option<LatencySummary>,
    /// Detections age on arrival: the scan's last packet reaching the robot to the message
    /// reaching us (robot host clock onto ours by the offset estimate). The scan's own stamp is
    /// on the robot LiDAR's clock (PTP or free-running), which no host clock can be compared with.
    pub detections_age: Option<LatencySummary>,
    /// Messages from the peer handed to the caller, refused as damaged, dropped on a full queue
    /// (the oldest go first).
    pub received: u64,
    pub decode_errors: u64,
    pub queue_drops: u64,
    /// Bytes waiting in the queue for the caller now (at most `queue_bytes`).
    pub queue_bytes: usize,
    /// Messages that decoded but were not taken, by reason.
    pub refused: Refused,
    /// Map fetches started (rig) and tiles they brought.
    pub map_fetches: u64,
    pub map_tiles_fetched: u64,
    /// Distinct map tiles: held for publishing (robot) or seen (rig); and what the peer's last
    /// heartbeat said it holds.
    pub map_tiles: usize,
    pub peer_map_tiles: u32,
}

/// Messages from the peer that decoded but were not taken (each also logged at debug level).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Refused {
    /// A kind the peer's role never sends (the robot takes only heartbeats and clock messages
    /// from a rig), or a heartbeat naming another role.
    pub kind: u64,
    /// Arrived on a key that is not its kind's (or a fetched tile not on its own key).
    pub key: u64,
    /// Rig: map tiles beyond `max_tiles` or `max_map_bytes`, or with a version more than
    /// `max_tile_version_lead` ahead of the newest taken.
    pub tiles: u64,
}

/// What the node's tasks share with the zenoh callbacks.
struct Shared {
    health: LinkHealth,
    clock: ClockOffset,
    /// Our recent probes (seq, t1), to match replies.
    probes: VecDeque<(u32, u64)>,
    heartbeat_latency: LatencyWindow,
    detections_latency: LatencyWindow,
    detections_age: LatencyWindow,
    received: u64,
    decode_errors: u64,
    refused: Refused,
    map_fetches: u64,
    map_tiles_fetched: u64,
    peer_map_tiles: u32,
    /// Rig: tiles taken (key -> newest version, its frame's bytes), their bytes together, and
    /// the newest version of any tile (the robot's map generation as far as we know).
    tiles_seen: HashMap<TileKey, (u32, usize)>,
    tile_bytes: usize,
    newest_tile_version: u32,
    /// Robot: newest tile of each key, as encoded link frames, for the map queryable.
    tiles_held: BTreeMap<TileKey, (u32, Vec<u8>)>,
    fetch_in_flight: bool,
    last_fetch_ns: u64,
}

impl Shared {
    fn map_tiles(&self, role: Role) -> usize {
        match role {
            Role::Robot => self.tiles_held.len(),
            Role::Rig => self.tiles_seen.len(),
        }
    }
}

fn lock(shared: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    // A panic elsewhere while holding the lock leaves counters at worst half-updated: keep going.
    shared.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Work the zenoh callbacks hand to the node's task (callbacks must not block).
enum Control {
    ReplyProbe { seq: u32, t1_ns: u64, t2_ns: u64 },
    FetchMap,
}

/// Everything a callback needs.
#[derive(Clone)]
struct Inbox {
    role: Role,
    cfg: Arc<LinkConfig>,
    shared: Arc<Mutex<Shared>>,
    to_caller: Arc<BoundedQueue<Received>>,
    control: mpsc::Sender<Control>,
}

fn signed_diff(a: u64, b: u64) -> i64 {
    i64::try_from(i128::from(a) - i128::from(b)).unwrap_or(if a > b { i64::MAX } else { i64::MIN })
}

impl Inbox {
    /// A message from the peer on `key`: decoded, checked against what the peer's role sends
    /// and the key it came on, then handled here (heartbeats, clock) or queued for the caller.
    fn on_bytes(&self, key: &str, bytes: &[u8], fetched: bool) {
        let recv_host_ns = host_now_ns();
        let msg = match decode(bytes) {
            Ok(m) => m,
            Err(e) => {
                lock(&self.shared).decode_errors += 1;
                tracing::debug!("link: refused a message on {key}: {e}");
                return;
            }
        };
        let peer = self.role.peer();
        if let Err(why) = acl::check(&self.cfg.key_prefix, peer, key, &msg, fetched) {
            let mut s = lock(&self.shared);
            match why {
                Refusal::Kind => s.refused.kind += 1,
                Refusal::Key => s.refused.key += 1,
            }
            tracing::debug!("link: refused a {} on {key} from the {}: {why:?}", kind_name(&msg), peer.name());
            return;
        }
        let mut s = lock(&self.shared);
        let latency = |s: &Shared, sent: u64| {
            let raw = signed_diff(recv_host_ns, sent);
            let corrected = s.clock.peer_to_local(sent).map(|local| signed_diff(recv_host_ns, local));
            (corrected, raw)
        };
        let (mut latency_ns, mut raw_latency_ns) = (None, None);
        match &msg {
            LinkMessage::Heartbeat { sent_host_ns, map_tiles, .. } => {
                // acl::check took only a heartbeat naming the peer's role.
                let was = s.health.state();
                if s.health.on_heartbeat(recv_host_ns).is_some() {
                    tracing::info!("link: {} up (was {was})", self.role.peer().name());
                    if was == LinkState::Lost {
                        // The peer may have restarted on a stepped clock: measure afresh.
                        s.clock.reset();
                        s.probes.clear();
                    }
                    if self.role == Role::Rig {
                        self.request_fetch(&mut s, recv_host_ns, true);
                    }
                }
                let (c, _) = latency(&s, *sent_host_ns);
                if let Some(c) = c {
                    s.heartbeat_latency.record(c);
                }
                s.peer_map_tiles = *map_tiles;
                if self.role == Role::Rig && (*map_tiles as usize) > s.tiles_seen.len() {
                    // The robot holds tiles we never saw (joined late, or they went while stale).
                    self.request_fetch(&mut s, recv_host_ns, false);
                }
                return;
            }
            LinkMessage::ClockProbe { seq, t1_ns } => {
                let _ = self.control.try_send(Control::ReplyProbe { seq: *seq, t1_ns: *t1_ns, t2_ns: recv_host_ns });
                return;
            }
            LinkMessage::ClockReply { seq, t1_ns, t2_ns, t3_ns } => {
                let ours = s.probes.iter().any(|&(q, t1)| q == *seq && t1 == *t1_ns);
                if ours {
                    s.probes.retain(|&(q, _)| q != *seq);
                    if let Err(e) = s.clock.add(*t1_ns, *t2_ns, *t3_ns, recv_host_ns) {
                        tracing::debug!("link: clock reply refused: {e}");
                    }
                }
                return;
            }
            LinkMessage::Detections { scan_last_packet_host_ns, sent_host_ns, .. } => {
                let (c, raw) = latency(&s, *sent_host_ns);
                (latency_ns, raw_latency_ns) = (c, Some(raw));
                if let Some(c) = c {
                    s.detections_latency.record(c);
                }
                if let (Some(c), _) = latency(&s, *scan_last_packet_host_ns) {
                    s.detections_age.record(c);
                }
            }
            LinkMessage::MapTile { bytes: tile } => {
                if self.role == Role::Rig {
                    if let Err(why) = self.take_tile(&mut s, tile, bytes.len()) {
                        s.refused.tiles += 1;
                        tracing::debug!("link: map tile refused: {why}");
                        return;
                    }
                }
                if fetched {
                    s.map_tiles_fetched += 1;
                }
            }
            LinkMessage::RobotPose { .. } => {}
        }
        let r = Received { msg, recv_host_ns, latency_ns, raw_latency_ns, fetched };
        if self.to_caller.push(r, bytes.len()).queued {
            s.received += 1;
        }
    }

    /// Rig: whether a tile may be taken, and its bookkeeping if so. Bounds: `max_tiles`
    /// distinct tiles, `max_map_bytes` of them, and a version at most `max_tile_version_lead`
    /// ahead of the newest taken (the robot numbers its map's generations 1, 2, ...; one far
    /// ahead would hide every real update of its tile, `TileMap::apply` keeping the highest).
    /// An older or equal version changes nothing here and is passed on (the caller's
    /// `TileMap` ignores it).
    fn take_tile(&self, s: &mut Shared, tile: &[u8], frame_bytes: usize) -> Result<(), String> {
        let Some((key, version)) = map_tile_id(tile) else { return Err("too short for a tile header".into()) };
        let limit = u64::from(s.newest_tile_version) + u64::from(self.cfg.max_tile_version_lead);
        if u64::from(version) > limit {
            return Err(format!(
                "tile {key:?} version {version} is more than {} ahead of the newest taken ({})",
                self.cfg.max_tile_version_lead, s.newest_tile_version
            ));
        }
        let held = s.tiles_seen.get(&key).copied();
        if held.is_some_and(|(v, _)| v >= version) {
            return Ok(());
        }
        if held.is_none() && s.tiles_seen.len() >= self.cfg.max_tiles {
            return Err(format!("tile {key:?} beyond max_tiles {}", self.cfg.max_tiles));
        }
        let bytes = s.tile_bytes - held.map_or(0, |(_, b)| b) + frame_bytes;
        if bytes > self.cfg.max_map_bytes {
            return Err(format!("tile {key:?} would hold {bytes} B of tiles, beyond max_map_bytes"));
        }
        s.tiles_seen.insert(key, (version, frame_bytes));
        s.tile_bytes = bytes;
        s.newest_tile_version = s.newest_tile_version.max(version);
        Ok(())
    }

    /// Asks the task for a map fetch unless one runs, or (when not forced) one started lately.
    fn request_fetch(&self, s: &mut Shared, now_ns: u64, force: bool) {
        let recent = now_ns.saturating_sub(s.last_fetch_ns) < self.cfg.map_fetch_timeout_ms.saturating_mul(1_000_000);
        if s.fetch_in_flight || (!force && recent) {
            return;
        }
        if self.control.try_send(Control::FetchMap).is_ok() {
            s.fetch_in_flight = true;
            s.last_fetch_ns = now_ns;
        }
    }
}

/// QoS per kind: heartbeats and clock probes jump every queue and go out alone (express: their
/// timing is the point); people and poses go next, batched, and are dropped rather than queued
/// when the link chokes (a newer one follows); map tiles wait their turn but are never dropped.
fn qos(msg: &LinkMessage) -> (CongestionControl, Priority, bool) {
    match msg {
        LinkMessage::Heartbeat { .. } | LinkMessage::ClockProbe { .. } | LinkMessage::ClockReply { .. } => {
            (CongestionControl::Drop, Priority::RealTime, true)
        }
        LinkMessage::RobotPose { .. } | LinkMessage::Detections { .. } => {
            (CongestionControl::Drop, Priority::InteractiveHigh, false)
        }
        LinkMessage::MapTile { .. } => (CongestionControl::Block, Priority::DataLow, false),
    }
}

async fn put(session: &Session, prefix: &str, role: Role, msg: &LinkMessage) -> Result<(), LinkError> {
    let bytes = encode(msg)?;
    let (cc, prio, express) = qos(msg);
    session
        .put(message_key(prefix, role, msg), bytes)
        .congestion_control(cc)
        .priority(prio)
        .express(express)
        .await
        .map_err(|e| LinkError::zenoh("put", e))
}

/// One end of the link.
pub struct LinkNode {
    role: Role,
    cfg: Arc<LinkConfig>,
    session: Session,
    shared: Arc<Mutex<Shared>>,
    inbox: Inbox,
    from_peer: Arc<BoundedQueue<Received>>,
    stop: watch::Sender<bool>,
    tasks: Vec<JoinHandle<()>>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl LinkNode {
    /// Opens the zenoh session (listening and connecting as configured; endpoints that do not
    /// answer yet are retried in the background), subscribes to the peer's messages and starts
    /// heartbeats and clock probes; the robot also answers map queries.
    pub async fn open(cfg: &LinkConfig, role: Role) -> Result<LinkNode, LinkError> {
        let zcfg = cfg.zenoh()?;
        let session = zenoh::open(zcfg).await.map_err(|e| LinkError::zenoh("open", e))?;
        let cfg = Arc::new(cfg.clone());
        let health = LinkHealth::new(cfg.health())?;
        let shared = Arc::new(Mutex::new(Shared {
            health,
            clock: ClockOffset::new(cfg.clock_window),
            probes: VecDeque::new(),
            heartbeat_latency: LatencyWindow::default(),
            detections_latency: LatencyWindow::default(),
            detections_age: LatencyWindow::default(),
            received: 0,
            decode_errors: 0,
            refused: Refused::default(),
            map_fetches: 0,
            map_tiles_fetched: 0,
            peer_map_tiles: 0,
            tiles_seen: HashMap::new(),
            tile_bytes: 0,
            newest_tile_version: 0,
            tiles_held: BTreeMap::new(),
            fetch_in_flight: false,
            last_fetch_ns: 0,
        }));
        let from_peer = Arc::new(BoundedQueue::new(cfg.queue, cfg.queue_bytes));
        let (control_tx, control_rx) = mpsc::channel(64);
        let inbox =
            Inbox { role, cfg: cfg.clone(), shared: shared.clone(), to_caller: from_peer.clone(), control: control_tx };
        let sub_inbox = inbox.clone();
        let subscriber = session
            .declare_subscriber(sender_wildcard(&cfg.key_prefix, role.peer()))
            .callback(move |sample: Sample| {
                sub_inbox.on_bytes(sample.key_expr().as_str(), &sample.payload().to_bytes(), false)
            })
            .await
            .map_err(|e| LinkError::zenoh("declare subscriber", e))?;
        let (stop, stop_rx) = watch::channel(false);
        let mut tasks = Vec::new();
        if role == Role::Robot {
            let queryable = session
                .declare_queryable(format!("{}/**", map_key(&cfg.key_prefix)))
                .await
                .map_err(|e| LinkError::zenoh("declare map queryable", e))?;
            tasks.push(tokio::spawn(serve_map(queryable, cfg.key_prefix.clone(), shared.clone(), stop_rx.clone())));
        }
        tasks.push(tokio::spawn(run_timers(session.clone(), role, inbox.clone(), control_rx, stop_rx)));
        Ok(LinkNode { role, cfg, session, shared, inbox, from_peer, stop, tasks, _subscriber: subscriber })
    }

    pub fn role(&self) -> Role {
        self.role
    }

    /// Publishes one message on `<prefix>/<role>/<kind>`. A map tile sent by the robot is also
    /// kept (newest version per tile) to answer the map queries of rigs that join late.
    /// Map tiles may wait when the link is congested; everything else is dropped instead.
    pub async fn publish(&self, msg: &LinkMessage) -> Result<(), LinkError> {
        if let (Role::Robot, LinkMessage::MapTile { bytes }) = (self.role, msg) {
            let frame = encode(msg)?;
            if let Some((key, version)) = map_tile_id(bytes) {
                let mut s = lock(&self.shared);
                let newer = s.tiles_held.get(&key).is_none_or(|(v, _)| *v <= version);
                if newer {
                    s.tiles_held.insert(key, (version, frame));
                }
            }
        }
        put(&self.session, &self.cfg.key_prefix, self.role, msg).await
    }

    /// The next message from the peer (the oldest still held); None once the node is closed.
    pub async fn recv(&mut self) -> Option<Received> {
        self.from_peer.pop().await
    }

    /// A message from the peer if one is waiting.
    pub fn try_recv(&mut self) -> Option<Received> {
        self.from_peer.try_pop()
    }

    /// Asks the robot for its whole map now (rig side; the node also does so by itself when the
    /// link comes up and when the robot holds tiles this node has not seen). The tiles arrive
    /// through [`recv`](Self::recv) with `fetched` set.
    pub fn request_map(&self) {
        let mut s = lock(&self.shared);
        self.inbox.request_fetch(&mut s, host_now_ns(), true);
    }

    /// A stamp of the peer's host clock on ours, once the offset is estimated.
    pub fn peer_to_local_ns(&self, peer_ns: u64) -> Option<u64> {
        lock(&self.shared).clock.peer_to_local(peer_ns)
    }

    /// The link's state now, with its counters, clock offset and latency figures.
    pub fn health(&self) -> LinkReport {
        let now = host_now_ns();
        let mut s = lock(&self.shared);
        s.health.tick(now);
        LinkReport {
            state: s.health.state(),
            silent_ms: s.health.silent_ms(now),
            stalls: s.health.stalls(),
            drops: s.health.drops(),
            resumptions: s.health.resumptions(),
            heartbeats: s.health.heartbeats(),
            clock: s.clock.estimate(),
            heartbeat_latency: s.heartbeat_latency.summary(),
            detections_latency: s.detections_latency.summary(),
            detections_age: s.detections_age.summary(),
            received: s.received,
            decode_errors: s.decode_errors,
            queue_drops: self.from_peer.dropped(),
            queue_bytes: self.from_peer.bytes(),
            refused: s.refused,
            map_fetches: s.map_fetches,
            map_tiles_fetched: s.map_tiles_fetched,
            map_tiles: s.map_tiles(self.role),
            peer_map_tiles: s.peer_map_tiles,
        }
    }

    /// Stops the node's tasks and closes the zenoh session (its listeners and connections).
    pub async fn close(mut self) -> Result<(), LinkError> {
        let _ = self.stop.send(true);
        self.from_peer.close();
        for t in self.tasks.drain(..) {
            // Each task checks the stop flag at least every heartbeat; abort covers a stuck one.
            let abort = t.abort_handle();
            if tokio::time::timeout(Duration::from_secs(2), t).await.is_err() {
                abort.abort();
            }
        }
        self.session.close().await.map_err(|e| LinkError::zenoh("close", e))
    }
}

impl Drop for LinkNode {
    fn drop(&mut self) {
        let _ = self.stop.send(true);
        for t in &self.tasks {
            t.abort();
        }
    }
}

/// Heartbeats, clock probes and the work the callbacks hand over (probe replies, map fetches).
async fn run_timers(
    session: Session,
    role: Role,
    inbox: Inbox,
    mut control: mpsc::Receiver<Control>,
    mut stop: watch::Receiver<bool>,
) {
    let cfg = inbox.cfg.clone();
    let prefix = cfg.key_prefix.clone();
    let mut heartbeat = tokio::time::interval(Duration::from_millis(cfg.heartbeat_ms));
    heartbeat.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut probe = tokio::time::interval(Duration::from_millis(cfg.clock_probe_ms));
    probe.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut fetches = JoinSet::new();
    let (mut heartbeat_seq, mut probe_seq) = (0u32, 0u32);
    loop {
        tokio::select! {
            _ = stop.changed() => break,
            _ = heartbeat.tick() => {
                let now = host_now_ns();
                let map_tiles = {
                    let mut s = lock(&inbox.shared);
                    if let Some(state) = s.health.tick(now) {
                        tracing::info!("link: {} {state}", role.peer().name());
                    }
                    s.map_tiles(role)
                };
                let msg = LinkMessage::Heartbeat {
                    role,
                    seq: heartbeat_seq,
                    sent_host_ns: host_now_ns(),
                    map_tiles: u32::try_from(map_tiles).unwrap_or(u32::MAX),
                };
                heartbeat_seq = heartbeat_seq.wrapping_add(1);
                if let Err(e) = put(&session, &prefix, role, &msg).await {
                    tracing::debug!("link: heartbeat not sent: {e}");
                }
            }
            _ = probe.tick() => {
                let t1_ns = host_now_ns();
                {
                    let mut s = lock(&inbox.shared);
                    if s.probes.len() >= 8 {
                        s.probes.pop_front();
                    }
                    s.probes.push_back((probe_seq, t1_ns));
                }
                let msg = LinkMessage::ClockProbe { seq: probe_seq, t1_ns };
                probe_seq = probe_seq.wrapping_add(1);
                if let Err(e) = put(&session, &prefix, role, &msg).await {
                    tracing::debug!("link: clock probe not sent: {e}");
                }
            }
            Some(c) = control.recv() => match c {
                Control::ReplyProbe { seq, t1_ns, t2_ns } => {
                    let msg = LinkMessage::ClockReply { seq, t1_ns, t2_ns, t3_ns: host_now_ns() };
                    if let Err(e) = put(&session, &prefix, role, &msg).await {
                        tracing::debug!("link: clock reply not sent: {e}");
                    }
                }
                Control::FetchMap => {
                    lock(&inbox.shared).map_fetches += 1;
                    fetches.spawn(fetch_map(session.clone(), inbox.clone()));
                }
            },
            Some(_) = fetches.join_next(), if !fetches.is_empty() => {}
        }
    }
    fetches.abort_all();
}

/// Rig: asks the robot's map queryable for every tile and hands them to the caller.
async fn fetch_map(session: Session, inbox: Inbox) {
    let timeout = Duration::from_millis(inbox.cfg.map_fetch_timeout_ms);
    let replies = session
        .get(format!("{}/**", map_key(&inbox.cfg.key_prefix)))
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(timeout)
        .await;
    match replies {
        Ok(replies) => {
            let mut tiles = 0usize;
            // Bounded: the query ends at its timeout at the latest.
            while let Ok(reply) = replies.recv_async().await {
                if let Ok(sample) = reply.result() {
                    inbox.on_bytes(sample.key_expr().as_str(), &sample.payload().to_bytes(), true);
                    tiles += 1;
                }
            }
            tracing::info!("link: map fetch brought {tiles} tiles");
        }
        Err(e) => tracing::warn!("link: map fetch failed: {e}"),
    }
    lock(&inbox.shared).fetch_in_flight = false;
}

/// Robot: answers each map query with every tile held, one reply per tile.
async fn serve_map(
    queryable: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    prefix: String,
    shared: Arc<Mutex<Shared>>,
    mut stop: watch::Receiver<bool>,
) {
    loop {
        let query = tokio::select! {
            _ = stop.changed() => break,
            q = queryable.recv_async() => match q {
                Ok(q) => q,
                Err(_) => break,
            },
        };
        let tiles: Vec<(TileKey, Vec<u8>)> =
            lock(&shared).tiles_held.iter().map(|(k, (_, frame))| (*k, frame.clone())).collect();
        for ((x, y, z), frame) in tiles {
            let key = format!("{}/{x}/{y}/{z}", map_key(&prefix));
            if let Err(e) = query.reply(key, frame).await {
                tracing::debug!("link: map reply failed: {e}");
                break;
            }
        }
    }
}
