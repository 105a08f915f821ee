//! `LinkConfig`: where the link listens and connects, its timings, and its security (TLS and
//! access control, from a zenoh config file and/or explicit `[tls]` paths).

use std::path::{Path, PathBuf};

use serde::Deserialize;
use starc_pipeline::link::HealthConfig;

use crate::LinkError;

/// How this node joins the zenoh network.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Talks directly to the other end (the usual robot <-> rig case).
    #[default]
    Peer,
    /// Goes through a router (`connect` names it).
    Client,
    /// Routes for others.
    Router,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Peer => "peer",
            Mode::Client => "client",
            Mode::Router => "router",
        }
    }
}

/// TLS with a private CA: the listener shows `cert`/`key`, the connector checks them against
/// `root_ca`; with `mutual`, the listener also asks the connector for its own `cert`/`key`.
/// Use `tls/<host>:<port>` endpoints. Paths relative to the config file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsConfig {
    /// PEM of the CA that signed the other end's certificate.
    pub root_ca: PathBuf,
    /// This node's PEM certificate and key (needed to listen, or to connect with `mutual`).
    #[serde(default)]
    pub cert: Option<PathBuf>,
    #[serde(default)]
    pub key: Option<PathBuf>,
    /// Mutual TLS: listeners refuse connectors without a certificate from `root_ca`. With `cert`
    /// and `key`, zenoh also grants each role's keys by the other end's certificate name
    /// (`acl::zenoh_access_control`).
    #[serde(default)]
    pub mutual: bool,
    /// Check that the listener's certificate names the host or IP connected to.
    #[serde(default = "yes")]
    pub verify_name: bool,
}

fn yes() -> bool {
    true
}

impl TlsConfig {
    /// zenoh's TLS settings (key, JSON value) for these files: the certificate and key serve
    /// both listening and connecting.
    pub(crate) fn zenoh_settings(&self) -> Vec<(&'static str, String)> {
        let path = |p: &Path| json(&p.to_string_lossy());
        let mut out = vec![("transport/link/tls/root_ca_certificate", path(&self.root_ca))];
        if let (Some(c), Some(k)) = (&self.cert, &self.key) {
            out.extend([
                ("transport/link/tls/listen_certificate", path(c)),
                ("transport/link/tls/listen_private_key", path(k)),
                ("transport/link/tls/connect_certificate", path(c)),
                ("transport/link/tls/connect_private_key", path(k)),
            ]);
        }
        out.push(("transport/link/tls/enable_mtls", self.mutual.to_string()));
        out.push(("transport/link/tls/verify_name_on_connect", self.verify_name.to_string()));
        out
    }
}

/// The link's configuration (`config/link.toml` documents every field).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkConfig {
    #[serde(default)]
    pub mode: Mode,
    /// zenoh endpoints to listen on, e.g. `tcp/192.168.1.10:7447`. Empty: listen nowhere (zenoh's
    /// own default, every interface, is never used).
    #[serde(default)]
    pub listen: Vec<String>,
    /// zenoh endpoints to connect to (retried in the background until they answer).
    #[serde(default)]
    pub connect: Vec<String>,
    /// zenoh's UDP multicast scouting (224.0.0.224:7446). Off: peers meet only through the
    /// endpoints above, so the link never talks to strangers on the WiFi.
    #[serde(default)]
    pub multicast_scouting: bool,
    /// First key segment of every key.
    #[serde(default = "default_prefix")]
    pub key_prefix: String,
    /// Heartbeat period.
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u64,
    /// No heartbeat for this long: Stale (overlays greyed).
    #[serde(default = "default_stale_after_ms")]
    pub stale_after_ms: u64,
    /// No heartbeat for this long: Lost.
    #[serde(default = "default_lost_after_ms")]
    pub lost_after_ms: u64,
    /// Clock probe period.
    #[serde(default = "default_clock_probe_ms")]
    pub clock_probe_ms: u64,
    /// Probes the offset filter keeps (the least-delay one wins).
    #[serde(default = "default_clock_window")]
    pub clock_window: usize,
    /// Longest wait between two attempts to reach a `connect` endpoint that is down.
    #[serde(default = "default_reconnect_ms")]
    pub reconnect_ms: u64,
    /// How long the rig waits for the robot's map after asking for it.
    #[serde(default = "default_map_fetch_timeout_ms")]
    pub map_fetch_timeout_ms: u64,
    /// Received messages held for the caller; when full, the oldest are dropped and counted.
    #[serde(default = "default_queue")]
    pub queue: usize,
    /// The same queue's bound in bytes (encoded frames): a caller that never reads, or a peer
    /// that floods, holds at most this much (a message larger than it alone is dropped).
    #[serde(default = "default_queue_bytes")]
    pub queue_bytes: usize,
    /// Rig: most distinct map tiles taken; a new tile beyond it is refused and counted.
    #[serde(default = "default_max_tiles")]
    pub max_tiles: usize,
    /// Rig: most bytes of map tiles held (the newest frame of each tile, encoded).
    #[serde(default = "default_max_map_bytes")]
    pub max_map_bytes: usize,
    /// Rig: a tile whose version is more than this ahead of the newest version taken so far (of
    /// any tile; 0 before the first) is refused. The robot's tile versions are its map's
    /// generations, one per `map_period_ms` that changed anything, so this is how many map
    /// periods a rig may miss (late join, link down) and still take the robot's tiles; it also
    /// caps how far a bad version can hold a tile: the robot's own versions pass it after at
    /// most this many periods (docs/link.md).
    #[serde(default = "default_max_tile_version_lead")]
    pub max_tile_version_lead: u32,
    /// Allow plain `tcp/` endpoints on non-loopback addresses (and TLS listeners without
    /// `mutual`): anyone on that network can then read the map and people and inject messages.
    /// Loopback (127.0.0.0/8, ::1, localhost) is always allowed.
    #[serde(default)]
    pub insecure: bool,
    /// A zenoh JSON5 config file to start from: its `transport/link/tls` and `access_control`
    /// sections (and anything else) apply; the fields above are written over it. An
    /// `access_control` it enables replaces the built-in policy by certificate name.
    #[serde(default)]
    pub zenoh_config: Option<PathBuf>,
    #[serde(default)]
    pub tls: Option<TlsConfig>,
}

fn default_prefix() -> String {
    "starc".into()
}
fn default_heartbeat_ms() -> u64 {
    100
}
fn default_stale_after_ms() -> u64 {
    500
}
fn default_lost_after_ms() -> u64 {
    2000
}
fn default_clock_probe_ms() -> u64 {
    500
}
fn default_clock_window() -> usize {
    32
}
fn default_reconnect_ms() -> u64 {
    500
}
fn default_map_fetch_timeout_ms() -> u64 {
    5000
}
fn default_queue() -> usize {
    1024
}
fn default_queue_bytes() -> usize {
    64 << 20
}
fn default_max_tiles() -> usize {
    100_000
}
fn default_max_map_bytes() -> usize {
    512 << 20
}
fn default_max_tile_version_lead() -> u32 {
    100_000
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            mode: Mode::Peer,
            listen: Vec::new(),
            connect: Vec::new(),
            multicast_scouting: false,
            key_prefix: default_prefix(),
            heartbeat_ms: default_heartbeat_ms(),
            stale_after_ms: default_stale_after_ms(),
            lost_after_ms: default_lost_after_ms(),
            clock_probe_ms: default_clock_probe_ms(),
            clock_window: default_clock_window(),
            reconnect_ms: default_reconnect_ms(),
            map_fetch_timeout_ms: default_map_fetch_timeout_ms(),
            queue: default_queue(),
            queue_bytes: default_queue_bytes(),
            max_tiles: default_max_tiles(),
            max_map_bytes: default_max_map_bytes(),
            max_tile_version_lead: default_max_tile_version_lead(),
            insecure: false,
            zenoh_config: None,
            tls: None,
        }
    }
}

pub(crate) fn json(s: &str) -> String {
    // A JSON string literal (endpoints and paths hold no control characters worth keeping).
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {}
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

pub(crate) fn json_list(items: &[String]) -> String {
    format!("[{}]", items.iter().map(|s| json(s)).collect::<Vec<_>>().join(","))
}

/// Whether an endpoint's address (`host:port`, `[v6]:port`) is on this host only.
pub(crate) fn is_loopback(address: &str) -> bool {
    let host = address.rsplit_once(':').map_or(address, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    match host.parse::<std::net::IpAddr>() {
        Ok(ip) => ip.is_loopback(),
        Err(_) => host.eq_ignore_ascii_case("localhost"),
    }
}

impl LinkConfig {
    pub fn from_toml(text: &str) -> Result<Self, LinkError> {
        let cfg: Self =
            toml::from_str(text).map_err(|e| LinkError::Config { field: "(toml)", reason: e.to_string() })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Reads a TOML file; relative paths in it (zenoh_config, tls) are taken from its folder.
    pub fn from_file(path: &Path) -> Result<Self, LinkError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| LinkError::ConfigFile { path: path.to_path_buf(), reason: e.to_string() })?;
        let mut cfg: Self = toml::from_str(&text)
            .map_err(|e| LinkError::ConfigFile { path: path.to_path_buf(), reason: e.to_string() })?;
        cfg.resolve_paths(path.parent().unwrap_or(Path::new(".")));
        cfg.validate().map_err(|e| LinkError::ConfigFile { path: path.to_path_buf(), reason: e.to_string() })?;
        Ok(cfg)
    }

    /// Takes the relative paths (zenoh_config, tls) from `dir`, the folder of the file they
    /// were read from.
    pub fn resolve_paths(&mut self, dir: &Path) {
        let rebase = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        };
        if let Some(z) = self.zenoh_config.as_mut() {
            rebase(z);
        }
        if let Some(t) = self.tls.as_mut() {
            rebase(&mut t.root_ca);
            for p in [t.cert.as_mut(), t.key.as_mut()].into_iter().flatten() {
                rebase(p);
            }
        }
    }

    pub fn health(&self) -> HealthConfig {
        HealthConfig { stale_after_ms: self.stale_after_ms, lost_after_ms: self.lost_after_ms }
    }

    pub fn validate(&self) -> Result<(), LinkError> {
        let bad = |field, reason: String| Err(LinkError::Config { field, reason });
        if self.heartbeat_ms == 0 || self.heartbeat_ms >= self.stale_after_ms {
            return bad(
                "heartbeat_ms",
                format!("need 0 < {} < stale_after_ms {}", self.heartbeat_ms, self.stale_after_ms),
            );
        }
        self.health().validate().map_err(|e| LinkError::Config { field: "stale_after_ms", reason: e.to_string() })?;
        if self.clock_probe_ms == 0 || self.clock_window == 0 || self.reconnect_ms == 0 || self.queue == 0 {
            return bad("clock_probe_ms", "clock_probe_ms, clock_window, reconnect_ms and queue must be > 0".into());
        }
        if self.map_fetch_timeout_ms == 0 {
            return bad("map_fetch_timeout_ms", "must be > 0".into());
        }
        for (field, value) in [
            ("queue_bytes", self.queue_bytes),
            ("max_tiles", self.max_tiles),
            ("max_map_bytes", self.max_map_bytes),
            ("max_tile_version_lead", self.max_tile_version_lead as usize),
        ] {
            if value == 0 {
                return bad(field, "must be > 0".into());
            }
        }
        let prefix_ok = !self.key_prefix.is_empty()
            && self.key_prefix.split('/').all(|s| !s.is_empty() && !s.contains(['*', '$', '?', '#']));
        if !prefix_ok {
            return bad("key_prefix", format!("{:?}: non-empty segments, no wildcards", self.key_prefix));
        }
        for (field, list) in [("listen", &self.listen), ("connect", &self.connect)] {
            for e in list {
                let ep = match e.parse::<zenoh::config::EndPoint>() {
                    Ok(ep) => ep,
                    Err(err) => return bad(field, format!("{e:?}: {err}")),
                };
                let tls = ep.protocol().as_str() == "tls";
                let loopback = is_loopback(ep.address().as_str());
                if tls && self.tls.is_none() {
                    return bad("tls", format!("{field} endpoint {e:?} is tls/ but there is no [tls] table"));
                }
                if self.insecure || loopback {
                    continue;
                }
                if !tls {
                    return bad(
                        field,
                        format!(
                            "{e:?} is plain {} on a non-loopback address: anyone on that network could read \
                             the map and people and inject messages. Use a tls/ endpoint with a [tls] table \
                             (mutual TLS; `starc link certs` makes the files), or set `insecure = true` in \
                             this [link] table to allow it",
                            ep.protocol().as_str()
                        ),
                    );
                }
                let mutual = self.tls.as_ref().is_some_and(|t| t.mutual && t.cert.is_some());
                if field == "listen" && !mutual {
                    return bad(
                        "tls.mutual",
                        format!(
                            "listening on {e:?} (not loopback) without mutual TLS lets anyone connect: set \
                             `mutual = true` with `cert` and `key` in [tls], or `insecure = true` to allow it"
                        ),
                    );
                }
            }
        }
        if let Some(t) = &self.tls {
            if t.cert.is_some() != t.key.is_some() {
                return bad("tls", "cert and key go together".into());
            }
        }
        Ok(())
    }

    /// The zenoh config: the `zenoh_config` file (or zenoh's defaults), with our mode, endpoints,
    /// scouting, reconnection and TLS written over it.
    pub fn zenoh(&self) -> Result<zenoh::Config, LinkError> {
        self.validate()?;
        let mut z = match &self.zenoh_config {
            Some(p) => zenoh::Config::from_file(p)
                .map_err(|e| LinkError::ConfigFile { path: p.clone(), reason: e.to_string() })?,
            None => zenoh::Config::default(),
        };
        // A policy of the file's own (below, with TLS).
        let own_policy = z.get_json("access_control/enabled").is_ok_and(|v| v == "true");
        let mut set = |key: &'static str, value: String| {
            z.insert_json5(key, &value).map_err(|e| LinkError::Config { field: key, reason: e.to_string() })
        };
        set("mode", json(self.mode.name()))?;
        // Always written, even empty: zenoh's default listens on every interface.
        set("listen/endpoints", json_list(&self.listen))?;
        set("connect/endpoints", json_list(&self.connect))?;
        // Never give up on a configured endpoint: a robot out of WiFi range comes back.
        set("connect/timeout_ms", "-1".into())?;
        set("connect/exit_on_failure", "false".into())?;
        set(
            "connect/retry",
            format!(
                "{{ period_init_ms: {}, period_max_ms: {}, period_increase_factor: 2 }}",
                self.reconnect_ms.min(100),
                self.reconnect_ms
            ),
        )?;
        set("scouting/multicast/enabled", self.multicast_scouting.to_string())?;
        // Gossip tells peers about addresses they learnt elsewhere; with explicit endpoints on
        // both ends it only adds a way to reach addresses we did not name.
        set("scouting/gossip/enabled", "false".into())?;
        // zenoh keeps 2 batches per priority and drops a droppable message after 1 ms without a
        // free batch: a burst of poses and detections on a busy 2-core host lost 1 in 400 on
        // loopback. Deeper queues for the two priorities we use for them, and 5 ms of patience.
        set("transport/link/tx/queue/size/real_time", "4".into())?;
        set("transport/link/tx/queue/size/interactive_high", "8".into())?;
        set("transport/link/tx/queue/congestion_control/drop/wait_before_drop", "5000".into())?;
        // zenoh reassembles a fragmented message up to 1 GiB by default: no frame of ours is
        // larger than the codec's limit, so a peer cannot make us hold more for one message.
        set("transport/link/rx/max_message_size", (starc_pipeline::link::MAX_MESSAGE_BYTES + (64 << 10)).to_string())?;
        if let Some(t) = &self.tls {
            for (key, value) in t.zenoh_settings() {
                set(key, value)?;
            }
            // With mutual TLS every transport carries the other end's certificate name, so zenoh
            // itself can tie keys to roles (acl::zenoh_access_control): a stolen rig key then
            // cannot put robot messages, nor have them routed on to another rig. Without
            // mutual TLS a connector shows no name, and plain tcp never does: no policy by name
            // can apply there. A zenoh_config file that enables its own access_control keeps
            // it untouched (its author chose; zenoh has one policy per session, and merging
            // two default permissions has no clear meaning).
            if t.mutual && t.cert.is_some() && t.key.is_some() && !own_policy {
                set("access_control", crate::acl::zenoh_access_control(&self.key_prefix))?;
            }
        }
        Ok(z)
    }
}
