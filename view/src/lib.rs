//! `starc-view`: the rig's live views of the responder's AR frame (docs/view.md): a browser page
//! served over HTTP, a Foxglove WebSocket server, a Linux framebuffer for a small display, and a
//! directory of PNG files. The network views bind to loopback by default ([`DEFAULT_HTTP_BIND`],
//! [`DEFAULT_FOXGLOVE_BIND`]); serving them beyond this machine takes an explicit address and a
//! token ([`access`]), and every connection passes caps at accept ([`gate`]).
//!
//! The renderer publishes each frame once into a [`ViewHub`]; every output follows the hub on
//! its own task and skips frames it is too slow for, so no viewer can slow the renderer.
//!
//! ```text
//! let hub = ViewHub::new();
//! let (stop, shutdown) = tokio::sync::watch::channel(false);
//! let views = start_views(&config.view, hub.clone(), shutdown).await?;
//! hub.publish(&frame, status)?;                      // per rendered frame
//! views.foxglove.as_ref().map(|f| f.publish_msg(topic, stamp_ns, &msg));
//! stop.send(true).ok();                              // everything stops
//! ```

pub mod access;
pub mod error;
pub mod foxglove;
pub mod foxglove_proto;
pub mod framebuffer;
pub mod gate;
pub mod http;
pub mod hub;
pub mod png_dir;
pub mod request;

pub use access::{ViewAccess, ViewToken};
pub use error::ViewError;
pub use foxglove::{ChannelSpec, Delivery, FoxgloveServer};
pub use framebuffer::{FbGeometry, Framebuffer, PixelFormat};
pub use gate::{ConnCounts, ConnLimits};
pub use http::{serve_http, HttpServer};
pub use hub::{ViewHub, ViewSnapshot, ViewStatus};

use serde::{Deserialize, Serialize};
use std::net::SocketAddr;
use std::path::PathBuf;
use tokio::sync::watch;
use tokio::task::JoinHandle;

/// Stops the servers and followers: send `true` on the matching sender (dropping the sender
/// stops them too).
pub type Shutdown = watch::Receiver<bool>;

/// Resolves once shutdown is requested or its sender is gone.
pub async fn wait_shutdown(shutdown: &mut Shutdown) {
    // wait_for errs only when the sender is dropped, which also means stop.
    let _ = shutdown.wait_for(|stop| *stop).await;
}

/// The next connection on `listener`, or `None` once `shutdown` says stop. A failed accept (out
/// of file descriptors and the like) is logged as `server`'s and retried after a pause, so the
/// loop never spins.
pub(crate) async fn next_connection(
    listener: &tokio::net::TcpListener,
    shutdown: &mut Shutdown,
    server: &str,
) -> Option<(tokio::net::TcpStream, std::net::SocketAddr)> {
    loop {
        let accepted = tokio::select! {
            _ = wait_shutdown(shutdown) => return None,
            a = listener.accept() => a,
        };
        match accepted {
            Ok(a) => return Some(a),
            Err(e) => {
                tracing::warn!("{server}: accept failed: {e}");
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        }
    }
}

/// `[view]` in fpv.toml. Every output is off unless configured, except that `png_every`
/// only matters with `png_dir`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViewConfig {
    /// The browser view, e.g. "127.0.0.1:8080" (this machine only; "0.0.0.0:8080" serves it
    /// on every interface, the rig's WiFi included). Default: off.
    pub http_bind: Option<SocketAddr>,
    /// A framebuffer device, e.g. "/dev/fb0"; geometry from /sys/class/graphics. Default: off.
    pub framebuffer: Option<PathBuf>,
    /// The Foxglove WebSocket server, e.g. "127.0.0.1:8765". Default: off.
    pub foxglove_bind: Option<SocketAddr>,
    /// Write PNG files of the frames here. Default: off.
    pub png_dir: Option<PathBuf>,
    /// With `png_dir`: write frames whose `frame_seq` is a multiple of this (1 = every frame
    /// the writer keeps up with). Default 10.
    pub png_every: u32,
    /// The shared secret viewers must present (`?token=`, `Authorization: Bearer`, or the
    /// cookie the page sets) to the browser view and Foxglove. Required when either binds
    /// beyond loopback; when set, required on loopback too. Default: none.
    pub token: Option<ViewToken>,
    /// Connections each network view holds at once, counted from accept: those still sending
    /// their request and those served. When full, the oldest still without a request is closed
    /// for the new one. Default 64.
    pub max_connections: usize,
    /// Of those, from one source address. Default 8.
    pub max_connections_per_address: usize,
    /// A connection that has not sent its whole request (HTTP head, WebSocket upgrade) this
    /// long after accept is closed. Default 3000.
    pub request_timeout_ms: u64,
}

/// The browser view's address when one is wanted but none given.
pub const DEFAULT_HTTP_BIND: &str = "127.0.0.1:8080";
/// Foxglove's default port for a WebSocket data source.
pub const DEFAULT_FOXGLOVE_BIND: &str = "127.0.0.1:8765";

impl Default for ViewConfig {
    fn default() -> Self {
        Self {
            http_bind: None,
            framebuffer: None,
            foxglove_bind: None,
            png_dir: None,
            png_every: 10,
            token: None,
            max_connections: gate::DEFAULT_MAX_CONNECTIONS,
            max_connections_per_address: gate::DEFAULT_MAX_PER_ADDRESS,
            request_timeout_ms: gate::DEFAULT_REQUEST_TIMEOUT_MS,
        }
    }
}

impl ViewConfig {
    /// Parses a `[view]` table (or a file holding only its keys) and checks it.
    pub fn from_toml(text: &str) -> Result<Self, ViewError> {
        let config: Self = toml::from_str(text).map_err(|e| ViewError::Config(e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// Checks the values, and that a network view bound beyond loopback has a token.
    pub fn validate(&self) -> Result<(), ViewError> {
        if self.png_every == 0 {
            return Err(ViewError::Config("png_every must be at least 1".into()));
        }
        // Room for every serving slot (Foxglove's 16) plus connections still sending requests.
        let least = foxglove::MAX_CLIENTS * 2;
        if !(least..=MAX_CONNECTIONS_CAP).contains(&self.max_connections) {
            return Err(ViewError::Config(format!(
                "max_connections = {}: must be {least} to {MAX_CONNECTIONS_CAP}",
                self.max_connections
            )));
        }
        if !(1..=self.max_connections).contains(&self.max_connections_per_address) {
            return Err(ViewError::Config(format!(
                "max_connections_per_address = {}: must be 1 to max_connections ({})",
                self.max_connections_per_address, self.max_connections
            )));
        }
        if !(REQUEST_TIMEOUT_MS_RANGE).contains(&self.request_timeout_ms) {
            return Err(ViewError::Config(format!(
                "request_timeout_ms = {}: must be {} to {}",
                self.request_timeout_ms,
                REQUEST_TIMEOUT_MS_RANGE.start(),
                REQUEST_TIMEOUT_MS_RANGE.end()
            )));
        }
        let access = self.access();
        if let Some(bind) = self.http_bind {
            access.check_bind("http_bind", bind)?;
        }
        if let Some(bind) = self.foxglove_bind {
            access.check_bind("foxglove_bind", bind)?;
        }
        Ok(())
    }

    /// What the network views enforce, from this config.
    pub fn access(&self) -> ViewAccess {
        ViewAccess {
            limits: ConnLimits {
                max_connections: self.max_connections,
                max_per_address: self.max_connections_per_address,
                request_timeout: std::time::Duration::from_millis(self.request_timeout_ms),
            },
            token: self.token.clone(),
        }
    }
}

/// The most `max_connections` may be: each is a file descriptor and a task.
pub const MAX_CONNECTIONS_CAP: usize = 4096;
/// What `request_timeout_ms` may be: long enough for a slow link, short enough that sockets
/// without a request do not pile up.
pub const REQUEST_TIMEOUT_MS_RANGE: std::ops::RangeInclusive<u64> = 100..=30_000;

/// The outputs [`start_views`] started.
pub struct RunningViews {
    /// The browser view's bound address.
    pub http: Option<SocketAddr>,
    /// The browser view itself (its connection counts).
    pub http_server: Option<HttpServer>,
    /// Publish ROS 2 messages here for Foxglove (channels: [`ChannelSpec::all_recorded`]).
    pub foxglove: Option<FoxgloveServer>,
    /// Every task started; they end after shutdown.
    pub tasks: Vec<JoinHandle<()>>,
}

/// Starts every output `config` enables, all following `hub`. Fails (starting nothing further)
/// on the first output that cannot start: a bind in use, a missing framebuffer, a bad dir.
pub async fn start_views(config: &ViewConfig, hub: ViewHub, shutdown: Shutdown) -> Result<RunningViews, ViewError> {
    config.validate()?;
    let access = config.access();
    let mut views = RunningViews { http: None, http_server: None, foxglove: None, tasks: Vec::new() };
    if let Some(device) = &config.framebuffer {
        let fb = Framebuffer::open(device)?;
        views.tasks.push(framebuffer::follow(fb, hub.subscribe(), shutdown.clone()));
    }
    if let Some(dir) = &config.png_dir {
        let writer = png_dir::PngDir::create(dir, config.png_every)?;
        views.tasks.push(png_dir::follow(writer, hub.subscribe(), shutdown.clone()));
    }
    if let Some(bind) = config.http_bind {
        let (server, task) = HttpServer::start(bind, hub.clone(), &access, shutdown.clone()).await?;
        views.http = Some(server.local_addr());
        views.http_server = Some(server);
        views.tasks.push(task);
    }
    if let Some(bind) = config.foxglove_bind {
        let channels = ChannelSpec::all_recorded();
        let (server, task) = FoxgloveServer::start_with(bind, &channels, &access, shutdown.clone()).await?;
        views.foxglove = Some(server);
        views.tasks.push(task);
    }
    Ok(views)
}
