//! A live Foxglove view: a Foxglove WebSocket server (`foxglove.websocket.v1`) that advertises
//! our ROS 2 topics (`cdr` messages, `ros2msg` schemas from `starc_pipeline::record::schema`,
//! the same as in our MCAP recordings) and forwards each published message to the clients
//! subscribed to its channel. Open it in Foxglove with "Foxglove WebSocket", `ws://<rig>:8765`.
//!
//! Each client has a bounded queue; when a slow client's queue is full its messages are dropped
//! (counted), so [`FoxgloveServer::publish`] never waits on the network.
//!
//! Every connection passes the gate at accept ([`crate::gate`]) and must finish its WebSocket
//! upgrade within the request deadline; only an upgrade that offers the token (if one is
//! configured: `ws://rig:8765/?token=...`) and our subprotocol takes one of [`MAX_CLIENTS`]
//! slots. Refusals are HTTP: 401 without the token, 403 with a wrong one, 400 without the
//! subprotocol, 503 with every slot taken.

use super::access::{Verdict, ViewAccess};
use super::error::ViewError;
use super::foxglove_proto::{self as proto, ChannelInfo, ClientOp};
use super::gate::{ConnCounts, Gate, Ticket};
use super::request::offered_token;
use super::Shutdown;
use futures_util::{SinkExt, StreamExt};
use starc_pipeline::record::{msgs::RosMessage, schema, Topic};
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, OwnedSemaphorePermit, Semaphore};
use tokio::task::JoinHandle;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::Message;

/// Clients served at once.
pub const MAX_CLIENTS: usize = 16;
/// Messages queued per client before new ones are dropped for it.
pub const CLIENT_QUEUE: usize = 32;
/// Largest message a client may send us (subscribe lists are small).
const MAX_CLIENT_MESSAGE_BYTES: usize = 256 * 1024;
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// A topic to advertise and the ROS 2 type it carries (`pkg/msg/Type`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChannelSpec {
    pub topic: String,
    pub type_name: String,
}

impl ChannelSpec {
    pub fn new(topic: impl Into<String>, type_name: impl Into<String>) -> Self {
        Self { topic: topic.into(), type_name: type_name.into() }
    }

    /// A topic of our recordings, with its type.
    pub fn recorded(topic: Topic) -> Self {
        Self::new(topic.name(), topic.type_name())
    }

    /// Every topic our recordings use (what `starc fpv` and `starc sim` can publish).
    pub fn all_recorded() -> Vec<Self> {
        Topic::ALL.iter().map(|t| Self::recorded(*t)).collect()
    }
}

/// What one publish did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Delivery {
    /// Clients the message was queued for.
    pub queued: usize,
    /// Subscribed clients whose queue was full (the message was dropped for them).
    pub dropped: usize,
}

struct ClientSlot {
    /// channel id -> the client's subscription id.
    subscriptions: HashMap<u32, u32>,
    tx: mpsc::Sender<Message>,
}

struct Shared {
    channels: Vec<ChannelInfo>,
    by_topic: HashMap<String, u32>,
    clients: Mutex<HashMap<u64, ClientSlot>>,
    next_client: AtomicU64,
    dropped: AtomicU64,
    session_id: String,
    access: ViewAccess,
    gate: Arc<Gate>,
    /// Client slots, taken during the upgrade once the request is read and accepted.
    slots: Arc<Semaphore>,
}

/// Cheap to clone; publish from any thread.
#[derive(Clone)]
pub struct FoxgloveServer {
    shared: Arc<Shared>,
    addr: SocketAddr,
}

impl FoxgloveServer {
    /// Binds `bind` and serves until `shutdown` fires, with the default caps and no token (so
    /// only on loopback). Every channel's type must be one `starc_pipeline::record::schema`
    /// knows, and topics must be unique.
    pub async fn start(
        bind: SocketAddr,
        channels: &[ChannelSpec],
        shutdown: Shutdown,
    ) -> Result<(Self, JoinHandle<()>), ViewError> {
        Self::start_with(bind, channels, &ViewAccess::default(), shutdown).await
    }

    /// [`FoxgloveServer::start`] under `access`: the connection caps, and the token, which a
    /// bind beyond loopback must have.
    pub async fn start_with(
        bind: SocketAddr,
        channels: &[ChannelSpec],
        access: &ViewAccess,
        shutdown: Shutdown,
    ) -> Result<(Self, JoinHandle<()>), ViewError> {
        access.check_bind("foxglove_bind", bind)?;
        let mut infos = Vec::with_capacity(channels.len());
        let mut by_topic = HashMap::new();
        for (i, c) in channels.iter().enumerate() {
            let id = u32::try_from(i + 1).map_err(|_| ViewError::Config("too many channels".into()))?;
            let text = schema::definition(&c.type_name).ok_or_else(|| ViewError::Channel {
                topic: c.topic.clone(),
                reason: format!("no ros2msg schema for {}", c.type_name),
            })?;
            if by_topic.insert(c.topic.clone(), id).is_some() {
                return Err(ViewError::Channel { topic: c.topic.clone(), reason: "advertised twice".into() });
            }
            infos.push(ChannelInfo {
                id,
                topic: c.topic.clone(),
                encoding: "cdr".into(),
                schema_name: c.type_name.clone(),
                schema: text,
                schema_encoding: "ros2msg".into(),
            });
        }
        let listener = TcpListener::bind(bind)
            .await
            .map_err(|e| ViewError::io(format!("binding the Foxglove server on {bind}"), e))?;
        let addr = listener.local_addr().map_err(|e| ViewError::io("reading the Foxglove server's address", e))?;
        let session_id = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_millis().to_string())
            .unwrap_or_default();
        let shared = Arc::new(Shared {
            channels: infos,
            by_topic,
            clients: Mutex::new(HashMap::new()),
            next_client: AtomicU64::new(1),
            dropped: AtomicU64::new(0),
            session_id,
            access: access.clone(),
            gate: Gate::new(access.limits),
            slots: Arc::new(Semaphore::new(MAX_CLIENTS)),
        });
        tracing::info!("Foxglove WebSocket server on ws://{addr}");
        let task = tokio::spawn(accept_loop(listener, shared.clone(), shutdown));
        Ok((Self { shared, addr }, task))
    }

    /// The address actually bound.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.shared.clients.lock().map(|c| c.len()).unwrap_or(0)
    }

    /// Whether any client is subscribed to `topic` now (so a costly message need not be built).
    pub fn subscribed(&self, topic: &str) -> bool {
        let Some(channel) = self.shared.by_topic.get(topic) else { return false };
        self.shared.clients.lock().map(|c| c.values().any(|s| s.subscriptions.contains_key(channel))).unwrap_or(false)
    }

    /// Connections accepted, refused, cut and held so far.
    pub fn connections(&self) -> ConnCounts {
        self.shared.gate.counts()
    }

    /// Messages dropped for slow clients so far.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Sends a CDR payload (encapsulation header included, as `RosMessage::to_cdr` makes it) on
    /// `topic` to every client subscribed to it, stamped `log_ns`. Never waits.
    pub fn publish(&self, topic: &str, log_ns: u64, cdr: &[u8]) -> Result<Delivery, ViewError> {
        let channel = *self
            .shared
            .by_topic
            .get(topic)
            .ok_or_else(|| ViewError::Channel { topic: topic.into(), reason: "not advertised".into() })?;
        let mut delivery = Delivery::default();
        let Ok(clients) = self.shared.clients.lock() else { return Ok(delivery) };
        for slot in clients.values() {
            let Some(&subscription) = slot.subscriptions.get(&channel) else { continue };
            let frame = Message::Binary(proto::message_data(subscription, log_ns, cdr).into());
            match slot.tx.try_send(frame) {
                Ok(()) => delivery.queued += 1,
                Err(mpsc::error::TrySendError::Full(_)) => delivery.dropped += 1,
                // The client is leaving; its task removes the slot.
                Err(mpsc::error::TrySendError::Closed(_)) => {}
            }
        }
        self.shared.dropped.fetch_add(delivery.dropped as u64, Ordering::Relaxed);
        Ok(delivery)
    }

    /// Encodes and publishes a typed message.
    pub fn publish_msg<T: RosMessage>(&self, topic: &str, log_ns: u64, msg: &T) -> Result<Delivery, ViewError> {
        self.publish(topic, log_ns, &msg.to_cdr())
    }
}

async fn accept_loop(listener: TcpListener, shared: Arc<Shared>, mut shutdown: Shutdown) {
    while let Some((stream, peer)) = super::next_connection(&listener, &mut shutdown, "Foxglove server").await {
        let mut ticket = match shared.gate.admit(peer.ip()) {
            Ok(t) => t,
            Err(refusal) => {
                // Closed without a word: a WebSocket client learns nothing more from a 503 here.
                tracing::debug!("Foxglove server: refusing {peer}: {refusal:?}");
                continue;
            }
        };
        let (shared, shutdown) = (shared.clone(), shutdown.clone());
        tokio::spawn(async move {
            if let Err(e) = serve_client(stream, &shared, &mut ticket, shutdown).await {
                tracing::debug!("Foxglove server: {peer}: {e}");
            }
            drop(ticket);
        });
    }
}

/// Why an upgrade was refused, for the counts.
enum Refused {
    Token,
    Busy,
}

/// Decides an upgrade request: the token first (so a stranger learns nothing else), then our
/// subprotocol, then a free slot, which it takes into `slot`.
#[allow(clippy::result_large_err)] // the signature tungstenite's callback requires
fn admit_upgrade(
    shared: &Shared,
    request: &Request,
    response: Response,
    slot: &mut Option<OwnedSemaphorePermit>,
    refused: &mut Option<Refused>,
) -> Result<Response, ErrorResponse> {
    let header = |name: &str| request.headers().get(name).and_then(|v| v.to_str().ok());
    let offered = offered_token(request.uri().query(), header("authorization"), header("cookie"));
    let denial = match shared.access.verdict(offered) {
        Verdict::Allowed => None,
        Verdict::Missing => Some((StatusCode::UNAUTHORIZED, "token required: ws://<rig>:<port>/?token=<token>\n")),
        Verdict::Wrong => Some((StatusCode::FORBIDDEN, "wrong token\n")),
    };
    if let Some((status, text)) = denial {
        *refused = Some(Refused::Token);
        return Err(refusal(status, text));
    }
    let response = select_subprotocol(request, response)?;
    match shared.slots.clone().try_acquire_owned() {
        Ok(permit) => {
            *slot = Some(permit);
            Ok(response)
        }
        Err(_) => {
            *refused = Some(Refused::Busy);
            Err(refusal(StatusCode::SERVICE_UNAVAILABLE, "too many clients\n"))
        }
    }
}

fn refusal(status: StatusCode, text: &str) -> ErrorResponse {
    let mut refusal = ErrorResponse::new(Some(text.to_string()));
    *refusal.status_mut() = status;
    refusal
}

/// Accepts only clients that offer our subprotocol, and selects it.
#[allow(clippy::result_large_err)] // the signature tungstenite's callback requires
fn select_subprotocol(request: &Request, mut response: Response) -> Result<Response, ErrorResponse> {
    let offered = request
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == proto::SUBPROTOCOL);
    if !offered {
        return Err(refusal(StatusCode::BAD_REQUEST, &format!("subprotocol {} required\n", proto::SUBPROTOCOL)));
    }
    response.headers_mut().insert("sec-websocket-protocol", HeaderValue::from_static(proto::SUBPROTOCOL));
    Ok(response)
}

async fn serve_client(
    stream: TcpStream,
    shared: &Arc<Shared>,
    ticket: &mut Ticket,
    mut shutdown: Shutdown,
) -> Result<(), String> {
    let config = WebSocketConfig::default()
        .max_message_size(Some(MAX_CLIENT_MESSAGE_BYTES))
        .max_frame_size(Some(MAX_CLIENT_MESSAGE_BYTES));
    let (mut slot, mut refused) = (None, None);
    #[allow(clippy::result_large_err)] // the signature tungstenite's callback requires
    let callback =
        |request: &Request, response: Response| admit_upgrade(shared, request, response, &mut slot, &mut refused);
    // The whole upgrade (reading the request, writing the answer) runs under the request deadline.
    let handshake = ticket
        .read_request(tokio_tungstenite::accept_hdr_async_with_config(stream, callback, Some(config)))
        .await
        .map_err(|e| format!("no upgrade request: {e:?}"))?;
    match refused {
        Some(Refused::Token) => shared.gate.count_unauthorized(),
        Some(Refused::Busy) => shared.gate.count_busy(),
        None => {}
    }
    let ws = handshake.map_err(|e| format!("handshake: {e}"))?;
    // Held for as long as the client is served.
    let Some(_slot) = slot else { return Err("upgraded without a slot".into()) };
    let (mut sink, mut source) = ws.split();
    let id = shared.next_client.fetch_add(1, Ordering::Relaxed);
    let (tx, mut rx) = mpsc::channel(CLIENT_QUEUE);
    // The client is registered before the advertise goes out, so it can subscribe at once.
    if let Ok(mut clients) = shared.clients.lock() {
        clients.insert(id, ClientSlot { subscriptions: HashMap::new(), tx });
    }
    let _unregister = Unregister { shared: shared.clone(), id };
    let hello = [proto::server_info("starc", &shared.session_id), proto::advertise(&shared.channels)];
    for text in hello {
        send(&mut sink, Message::Text(text.into())).await?;
    }
    loop {
        tokio::select! {
            _ = super::wait_shutdown(&mut shutdown) => {
                let _ = tokio::time::timeout(WRITE_TIMEOUT, sink.close()).await;
                return Ok(());
            }
            out = rx.recv() => match out {
                Some(m) => send(&mut sink, m).await?,
                None => return Ok(()),
            },
            incoming = source.next() => match incoming {
                Some(Ok(Message::Text(text))) => {
                    if let Some(reply) = handle_client_text(shared, id, text.as_str()) {
                        send(&mut sink, Message::Text(reply.into())).await?;
                    }
                }
                Some(Ok(Message::Binary(_))) => {
                    let reply = proto::status(2, "client publishing is not supported");
                    send(&mut sink, Message::Text(reply.into())).await?;
                }
                Some(Ok(Message::Close(_))) | None => {
                    // Flushes tungstenite's queued close reply; without it the client waits out
                    // its close timeout.
                    let _ = tokio::time::timeout(WRITE_TIMEOUT, sink.close()).await;
                    return Ok(());
                }
                // Pings are answered by tungstenite itself.
                Some(Ok(_)) => {}
                Some(Err(e)) => return Err(e.to_string()),
            },
        }
    }
}

type Sink = futures_util::stream::SplitSink<tokio_tungstenite::WebSocketStream<TcpStream>, Message>;

async fn send(sink: &mut Sink, message: Message) -> Result<(), String> {
    match tokio::time::timeout(WRITE_TIMEOUT, sink.send(message)).await {
        Ok(r) => r.map_err(|e| e.to_string()),
        Err(_) => Err("client stalled".into()),
    }
}

/// Applies a subscribe/unsubscribe; returns a status message to send back, if any.
fn handle_client_text(shared: &Shared, id: u64, text: &str) -> Option<String> {
    let op = match proto::parse_client(text) {
        Ok(op) => op,
        Err(e) => return Some(proto::status(2, &e)),
    };
    let Ok(mut clients) = shared.clients.lock() else { return None };
    let slot = clients.get_mut(&id)?;
    let mut problems = Vec::new();
    match op {
        ClientOp::Subscribe(subs) => {
            for s in subs {
                let known = shared.channels.iter().any(|c| c.id == s.channel_id);
                if !known {
                    problems.push(format!("no channel {}", s.channel_id));
                } else if slot.subscriptions.values().any(|&sub| sub == s.id) {
                    problems.push(format!("subscription id {} already in use", s.id));
                } else {
                    // One subscription per channel: a new one replaces the old.
                    slot.subscriptions.insert(s.channel_id, s.id);
                }
            }
        }
        ClientOp::Unsubscribe(ids) => slot.subscriptions.retain(|_, sub| !ids.contains(sub)),
        ClientOp::Unsupported(op) => problems.push(format!("operation {op} is not supported")),
    }
    (!problems.is_empty()).then(|| proto::status(1, &problems.join("; ")))
}

/// Removes a client's slot however its task ends.
struct Unregister {
    shared: Arc<Shared>,
    id: u64,
}

impl Drop for Unregister {
    fn drop(&mut self) {
        if let Ok(mut clients) = self.shared.clients.lock() {
            clients.remove(&self.id);
        }
    }
}
