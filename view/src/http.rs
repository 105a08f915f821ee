//! The browser live view, served by the rig node with tokio alone (a few routes of HTTP/1.1 GET
//! do not need a web framework).
//!
//! Routes: `/` a self-contained page (no external assets) with the stream and the status line;
//! `/frame.png` the latest frame; `/status.json` its status; `/stream` every new frame as a
//! `multipart/x-mixed-replace` stream of PNG parts, which Chrome and Firefox both render in an
//! `<img>` (the way IP cameras stream MJPEG). Each response closes its connection.
//!
//! Bounds: every connection passes the gate at accept ([`crate::gate`]: a total and a
//! per-address cap, the request deadline); only a connection whose request head is read takes
//! one of [`MAX_CLIENTS`] serving slots (more get 503). Request heads of at most 8 KiB (431),
//! 10 s to take any one write; anything else the server cannot answer gets 400, 404 or 405.
//! With a token configured, a request without it gets 401 and one with a wrong one 403.

use super::access::{Verdict, ViewAccess};
use super::error::ViewError;
use super::gate::{ConnCounts, Gate, Refusal};
use super::hub::{SnapshotReceiver, ViewHub, ViewSnapshot};
use super::request::{head_end, parse_head, Method, MAX_HEAD_BYTES, TOKEN_COOKIE};
use super::Shutdown;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;
use tokio::task::JoinHandle;

/// Connections served at once (a stream holds one for as long as the page is open).
pub const MAX_CLIENTS: usize = 8;
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);
const BOUNDARY: &str = "starcframe";

const INDEX_HTML: &str = include_str!("index.html");

/// A running browser view: its address and its connection counts.
#[derive(Clone)]
pub struct HttpServer {
    addr: SocketAddr,
    gate: Arc<Gate>,
}

impl HttpServer {
    /// Binds `bind` and serves the live view until `shutdown` fires, under `access` (the
    /// connection caps, and the token, which a bind beyond loopback must have). Returns the
    /// server (port 0 picks a free one) and its task.
    pub async fn start(
        bind: SocketAddr,
        hub: ViewHub,
        access: &ViewAccess,
        shutdown: Shutdown,
    ) -> Result<(Self, JoinHandle<()>), ViewError> {
        access.check_bind("http_bind", bind)?;
        let listener =
            TcpListener::bind(bind).await.map_err(|e| ViewError::io(format!("binding the live view on {bind}"), e))?;
        let addr = listener.local_addr().map_err(|e| ViewError::io("reading the live view's address", e))?;
        tracing::info!("live view on http://{addr}/{}", if access.token.is_some() { " (token required)" } else { "" });
        let gate = Gate::new(access.limits);
        let server =
            Server { hub, access: access.clone(), gate: gate.clone(), slots: Arc::new(Semaphore::new(MAX_CLIENTS)) };
        let task = tokio::spawn(accept_loop(listener, Arc::new(server), shutdown));
        Ok((Self { addr, gate }, task))
    }

    /// The address actually bound.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Connections accepted, refused, cut and held so far.
    pub fn connections(&self) -> ConnCounts {
        self.gate.counts()
    }
}

/// Binds `bind` and serves the live view until `shutdown` fires, with the default caps and no
/// token (so only on loopback). Returns the address actually bound (port 0 picks a free one)
/// and the server's task.
pub async fn serve_http(
    bind: SocketAddr,
    hub: ViewHub,
    shutdown: Shutdown,
) -> Result<(SocketAddr, JoinHandle<()>), ViewError> {
    let (server, task) = HttpServer::start(bind, hub, &ViewAccess::default(), shutdown).await?;
    Ok((server.local_addr(), task))
}

struct Server {
    hub: ViewHub,
    access: ViewAccess,
    gate: Arc<Gate>,
    /// Serving slots, taken once a request is read.
    slots: Arc<Semaphore>,
}

async fn accept_loop(listener: TcpListener, server: Arc<Server>, mut shutdown: Shutdown) {
    while let Some((stream, peer)) = super::next_connection(&listener, &mut shutdown, "live view").await {
        let ticket = match server.gate.admit(peer.ip()) {
            Ok(t) => t,
            Err(refusal) => {
                let why = match refusal {
                    Refusal::Full => "too many connections\n",
                    Refusal::PerAddress => "too many connections from your address\n",
                };
                // One non-blocking write: a full server must not queue work for the clients it refuses.
                let _ = stream.try_write(&status_response(503, "Service Unavailable", why));
                continue;
            }
        };
        let (server, shutdown) = (server.clone(), shutdown.clone());
        tokio::spawn(async move {
            let mut ticket = ticket;
            if let Err(e) = serve_connection(stream, &server, &mut ticket, shutdown).await {
                tracing::debug!("live view: {peer}: {e}");
            }
            drop(ticket);
        });
    }
}

async fn serve_connection(
    mut stream: TcpStream,
    server: &Server,
    ticket: &mut super::gate::Ticket,
    shutdown: Shutdown,
) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(1024);
    // Cut by the deadline or by eviction: closed without an answer, since a client that has
    // not sent its request in time is not reading either.
    let Ok(head) = ticket.read_request(read_head(&mut stream, &mut buf)).await else { return Ok(()) };
    let parsed = match head {
        Err(e) => return Err(e),
        Ok(Err(e)) => Err(e),
        Ok(Ok(end)) => parse_head(buf.get(..end).unwrap_or_default()),
    };
    let request = match parsed {
        Ok(r) => r,
        Err(e) => {
            let (code, reason) = e.status();
            return write_all(&mut stream, &status_response(code, reason, &format!("{reason}\n"))).await;
        }
    };
    let refusal = match server.access.verdict(request.token.as_deref()) {
        Verdict::Allowed => None,
        Verdict::Missing => Some(unauthorized_response()),
        Verdict::Wrong => Some(status_response(403, "Forbidden", "wrong token\n")),
    };
    if let Some(response) = refusal {
        server.gate.count_unauthorized();
        return write_all(&mut stream, &response).await;
    }
    let Ok(_slot) = server.slots.clone().try_acquire_owned() else {
        server.gate.count_busy();
        return write_all(&mut stream, &status_response(503, "Service Unavailable", "too many viewers\n")).await;
    };
    let hub = &server.hub;
    let head_only = request.method == Method::Head;
    let response = match request.path.as_str() {
        "/" | "/index.html" => {
            let mut page = ok_response("text/html; charset=utf-8", INDEX_HTML.as_bytes(), head_only);
            if let (Some(token), Some(_)) = (&server.access.token, &request.token) {
                // The page's own requests (the stream, the status, the fallback frames) are
                // relative URLs without the token: the cookie carries it for them.
                set_cookie(&mut page, &format!("{TOKEN_COOKIE}={}", token.as_str()));
            }
            page
        }
        "/frame.png" => match hub.latest().map(|s| s.png()) {
            Some(Ok(png)) => ok_response("image/png", &png, head_only),
            Some(Err(e)) => status_response(500, "Internal Server Error", &format!("{e}\n")),
            None => status_response(503, "Service Unavailable", "no frame yet\n"),
        },
        "/status.json" => {
            let body = status_json(hub.latest().as_deref());
            ok_response("application/json", body.as_bytes(), head_only)
        }
        "/stream" => {
            if head_only {
                stream_head()
            } else {
                return stream_frames(stream, hub.subscribe(), shutdown).await;
            }
        }
        _ => status_response(404, "Not Found", "not found\n"),
    };
    write_all(&mut stream, &response).await?;
    let _ = stream.shutdown().await;
    Ok(())
}

fn unauthorized_response() -> Vec<u8> {
    let body = "token required: open /?token=<token>\n";
    format!(
        "HTTP/1.1 401 Unauthorized\r\nWWW-Authenticate: Bearer realm=\"starc-view\"\r\n\
         Content-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

/// Adds a `Set-Cookie` header to a response built by [`ok_response`] (before its blank line).
/// HttpOnly keeps it from scripts; SameSite=Strict keeps other sites' pages from using it.
fn set_cookie(response: &mut Vec<u8>, cookie: &str) {
    let header = format!("Set-Cookie: {cookie}; Path=/; HttpOnly; SameSite=Strict\r\n");
    if let Some(end) = response.windows(4).position(|w| w == b"\r\n\r\n") {
        let at = end + 2;
        response.splice(at..at, header.into_bytes());
    }
}

/// Reads until the end of the head; `Ok(Err(..))` for a head the server refuses.
async fn read_head(
    stream: &mut TcpStream,
    buf: &mut Vec<u8>,
) -> std::io::Result<Result<usize, super::request::RequestError>> {
    let mut chunk = [0u8; 1024];
    loop {
        match head_end(buf) {
            Ok(Some(end)) => return Ok(Ok(end)),
            Ok(None) => {}
            Err(e) => return Ok(Err(e)),
        }
        let n = stream.read(&mut chunk).await?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        let room = MAX_HEAD_BYTES.saturating_sub(buf.len());
        buf.extend_from_slice(chunk.get(..n.min(room)).unwrap_or_default());
    }
}

/// The status of the latest frame, or `{"frame": null}` before the first.
pub fn status_json(snapshot: Option<&ViewSnapshot>) -> String {
    match snapshot {
        Some(s) => serde_json::to_string(&s.status).unwrap_or_else(|_| "{}".into()),
        None => "{\"frame\":null}".into(),
    }
}

async fn write_all(stream: &mut TcpStream, bytes: &[u8]) -> std::io::Result<()> {
    match tokio::time::timeout(WRITE_TIMEOUT, stream.write_all(bytes)).await {
        Ok(r) => r,
        Err(_) => Err(std::io::ErrorKind::TimedOut.into()),
    }
}

fn ok_response(content_type: &str, body: &[u8], head_only: bool) -> Vec<u8> {
    let mut out = format!(
        "HTTP/1.1 200 OK\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         Connection: close\r\n\r\n",
        body.len()
    )
    .into_bytes();
    if !head_only {
        out.extend_from_slice(body);
    }
    out
}

fn status_response(code: u16, reason: &str, body: &str) -> Vec<u8> {
    format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

fn stream_head() -> Vec<u8> {
    format!(
        "HTTP/1.1 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary={BOUNDARY}\r\n\
         Cache-Control: no-store\r\nConnection: close\r\n\r\n"
    )
    .into_bytes()
}

/// Writes the latest frame, then each new one, until the viewer leaves, stalls past the write
/// timeout, or the server shuts down. Each part is followed at once by the next boundary:
/// browsers show a part only once its closing boundary arrives.
async fn stream_frames(
    mut stream: TcpStream,
    mut frames: SnapshotReceiver,
    mut shutdown: Shutdown,
) -> std::io::Result<()> {
    let mut head = stream_head();
    head.extend_from_slice(format!("--{BOUNDARY}\r\n").as_bytes());
    write_all(&mut stream, &head).await?;
    loop {
        let latest = frames.borrow_and_update().clone();
        // A frame that cannot be encoded is skipped; the next one may be fine.
        if let Some(png) = latest.and_then(|s| s.png().ok()) {
            let mut part = format!("Content-Type: image/png\r\nContent-Length: {}\r\n\r\n", png.len()).into_bytes();
            part.reserve(png.len() + BOUNDARY.len() + 8);
            part.extend_from_slice(&png);
            part.extend_from_slice(format!("\r\n--{BOUNDARY}\r\n").as_bytes());
            write_all(&mut stream, &part).await?;
        }
        tokio::select! {
            _ = super::wait_shutdown(&mut shutdown) => return Ok(()),
            changed = frames.changed() => if changed.is_err() { return Ok(()) },
        }
    }
}
