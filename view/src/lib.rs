//! `starc-view`: the rig's live views of the responder's AR frame (docs/view.md): a browser page
//! served over HTTP, a Foxglove WebSocket server, a Linux framebuffer for a small display, and a
//! directory of PNG files. The network views bind to loopback by default ([`DEFAULT_HTTP_BIND`],
//! [`DEFAULT_FOXGLOVE_BIND`]); serving them beyond this machine takes an explicit address.
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

pub mod error;
pub mod foxglove;
pub mod foxglove_proto;
pub mod framebuffer;
pub mod http;
pub mod hub;
pub mod png_dir;
pub mod request;

pub use error::ViewError;
pub use foxglove::{ChannelSpec, Delivery, FoxgloveServer};
pub use framebuffer::{FbGeometry, Framebuffer, PixelFormat};
pub use http::serve_http;
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
}

/// The browser view's address when one is wanted but none given.
pub const DEFAULT_HTTP_BIND: &str = "127.0.0.1:8080";
/// Foxglove's default port for a WebSocket data source.
pub const DEFAULT_FOXGLOVE_BIND: &str = "127.0.0.1:8765";

impl Default for ViewConfig {
    fn default() -> Self {
        Self { http_bind: None, framebuffer: None, foxglove_bind: None, png_dir: None, png_every: 10 }
    }
}

impl ViewConfig {
    /// Parses a `[view]` table (or a file holding only its keys) and checks it.
    pub fn from_toml(text: &str) -> Result<Self, ViewError> {
        let config: Self = toml::from_str(text).map_err(|e| ViewError::Config(e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    pub fn validate(&self) -> Result<(), ViewError> {
        if self.png_every == 0 {
            return Err(ViewError::Config("png_every must be at least 1".into()));
        }
        Ok(())
    }
}

/// The outputs [`start_views`] started.
pub struct RunningViews {
    /// The browser view's bound address.
    pub http: Option<SocketAddr>,
    /// Publish ROS 2 messages here for Foxglove (channels: [`ChannelSpec::all_recorded`]).
    pub foxglove: Option<FoxgloveServer>,
    /// Every task started; they end after shutdown.
    pub tasks: Vec<JoinHandle<()>>,
}

/// Starts every output `config` enables, all following `hub`. Fails (starting nothing further)
/// on the first output that cannot start: a bind in use, a missing framebuffer, a bad dir.
pub async fn start_views(config: &ViewConfig, hub: ViewHub, shutdown: Shutdown) -> Result<RunningViews, ViewError> {
    config.validate()?;
    let mut views = RunningViews { http: None, foxglove: None, tasks: Vec::new() };
    if let Some(device) = &config.framebuffer {
        let fb = Framebuffer::open(device)?;
        views.tasks.push(framebuffer::follow(fb, hub.subscribe(), shutdown.clone()));
    }
    if let Some(dir) = &config.png_dir {
        let writer = png_dir::PngDir::create(dir, config.png_every)?;
        views.tasks.push(png_dir::follow(writer, hub.subscribe(), shutdown.clone()));
    }
    if let Some(bind) = config.http_bind {
        let (addr, task) = serve_http(bind, hub.clone(), shutdown.clone()).await?;
        views.http = Some(addr);
        views.tasks.push(task);
    }
    if let Some(bind) = config.foxglove_bind {
        let (server, task) = FoxgloveServer::start(bind, &ChannelSpec::all_recorded(), shutdown.clone()).await?;
        views.foxglove = Some(server);
        views.tasks.push(task);
    }
    Ok(views)
}
