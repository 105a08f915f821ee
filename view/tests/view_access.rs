//! Who gets into the network views (view/src/gate.rs, view/src/access.rs), on loopback only:
//! 1,000 half-open connections (connect and say nothing, or send half a request) from 125
//! loopback addresses do not keep curl from the page nor a Foxglove client (PyPI `websockets`,
//! tests/peers/foxglove_client.py) from subscribing, and every one of them is closed and
//! counted; the per-address cap holds; a bind beyond loopback without a token is refused
//! before anything binds; with a token, requests without it get 401, with a wrong one 403, and
//! with it are served.
//!
//! Source addresses 127.0.1.x and 127.0.2.x are loopback (127.0.0.0/8 is routed to `lo`), so
//! nothing leaves the machine. Each test holds at most about 2,000 sockets for at most about
//! 15 s and closes them all.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;
use common::{peer_python, root};
use serde_json::Value;
use starc_pipeline::ar::ArFrame;
use starc_pipeline::record::Topic;
use starc_view::{
    start_views, ChannelSpec, ConnCounts, ConnLimits, FoxgloveServer, HttpServer, ViewAccess, ViewConfig, ViewHub,
    ViewStatus, ViewToken,
};
use std::net::SocketAddr;
use std::process::{Command, Output};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

const CURL: &str = "/usr/bin/curl";
const FLOOD: usize = 1000;
const MAX_CONNECTIONS: usize = 64;
const PER_ADDRESS: usize = 8;
const TOKEN: &str = "test-token-0123456789abcdef";

fn access(request_timeout: Duration, token: Option<&str>) -> ViewAccess {
    ViewAccess {
        limits: ConnLimits { max_connections: MAX_CONNECTIONS, max_per_address: PER_ADDRESS, request_timeout },
        token: token.map(|t| ViewToken::new(t).unwrap()),
    }
}

async fn connect_from(src: [u8; 4], to: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::from((src, 0))).unwrap();
    socket.connect(to).await.unwrap_or_else(|e| panic!("connecting from {src:?}: {e}"))
}

/// `FLOOD` connections, `PER_ADDRESS` from each of 127.0.1.1..: every other one sends `half` (a
/// request without its end), the rest send nothing.
async fn flood(to: SocketAddr, half: &[u8]) -> Vec<TcpStream> {
    let mut sockets = Vec::with_capacity(FLOOD);
    for i in 0..FLOOD {
        let mut s = connect_from([127, 0, 1, (i / PER_ADDRESS + 1) as u8], to).await;
        if i % 2 == 0 {
            // The server may already have closed it to make room; that is what is tested later.
            let _ = s.write_all(half).await;
        }
        sockets.push(s);
    }
    sockets
}

/// Whether the server closes `s` (end of stream or reset) within `within`; what it sent first.
async fn closed_within(s: &mut TcpStream, within: Duration) -> Option<String> {
    let deadline = tokio::time::Instant::now() + within;
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    loop {
        match tokio::time::timeout_at(deadline, s.read(&mut buf)).await {
            Err(_) => return None,
            Ok(Ok(0)) | Ok(Err(_)) => return Some(String::from_utf8_lossy(&got).into_owned()),
            Ok(Ok(n)) => got.extend_from_slice(&buf[..n]),
        }
    }
}

/// Every flood socket is closed by the server within `within` (from now).
async fn all_closed(mut sockets: Vec<TcpStream>, within: Duration) {
    let deadline = Instant::now() + within;
    for (i, s) in sockets.iter_mut().enumerate() {
        let left = deadline.saturating_duration_since(Instant::now());
        assert!(closed_within(s, left).await.is_some(), "flood connection {i} is still open");
    }
}

/// Polls `counts` until `done` holds, for at most `within`.
async fn counts_until(
    counts: impl Fn() -> ConnCounts,
    done: impl Fn(&ConnCounts) -> bool,
    within: Duration,
) -> ConnCounts {
    let deadline = Instant::now() + within;
    loop {
        let c = counts();
        if done(&c) {
            return c;
        }
        assert!(Instant::now() < deadline, "counts never settled: {c:?}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// curl from 127.0.0.1: body and "<code>", plus the response headers.
async fn curl(url: String, extra: Vec<String>) -> (String, String, String) {
    tokio::task::spawn_blocking(move || {
        let headers = tempfile::NamedTempFile::new().unwrap();
        let o = Command::new(CURL)
            .args(["-sS", "--max-time", "5", "-w", "\n%{http_code}", "-D"])
            .arg(headers.path())
            .args(&extra)
            .arg(&url)
            .output()
            .expect("running /usr/bin/curl");
        assert!(o.status.success(), "curl {url}: {}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        let (body, code) = text.rsplit_once('\n').unwrap();
        (body.to_string(), code.to_string(), std::fs::read_to_string(headers.path()).unwrap())
    })
    .await
    .unwrap()
}

/// Runs the Foxglove peer to the end (killed after 30 s) and parses its last line.
async fn peer(args: Vec<String>) -> Value {
    let out: Output = tokio::task::spawn_blocking(move || {
        let mut child = Command::new(peer_python())
            .arg(root().join("tests/peers/foxglove_client.py"))
            .args(&args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(30);
        while child.try_wait().unwrap().is_none() {
            if Instant::now() > deadline {
                let _ = child.kill();
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        child.wait_with_output().unwrap()
    })
    .await
    .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "peer failed: {}\n{stdout}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(stdout.lines().last().unwrap_or_default()).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_thousand_half_open_connections_do_not_keep_a_browser_from_the_page_and_are_closed_and_counted() {
    let hub = ViewHub::new();
    hub.publish(&ArFrame::filled(16, 12, [200, 0, 0]), ViewStatus { frame_seq: 7, ..ViewStatus::default() }).unwrap();
    let (_stop, shutdown) = tokio::sync::watch::channel(false);
    let deadline = Duration::from_secs(2);
    let (server, _task) =
        HttpServer::start("127.0.0.1:0".parse().unwrap(), hub, &access(deadline, None), shutdown).await.unwrap();
    let addr = server.local_addr();
    let sockets = flood(addr, b"GET / HTTP/1.1\r\nHost: rig\r\n").await;
    // Every flood connection is counted, and the server holds no more than its cap.
    let c = counts_until(|| server.connections(), |c| c.accepted == FLOOD as u64, Duration::from_secs(5)).await;
    assert_eq!((c.held, c.pending), (MAX_CONNECTIONS as u64, MAX_CONNECTIONS as u64), "{c:?}");

    // While they hold every place, a browser gets the page and the status, promptly.
    let t0 = Instant::now();
    let (page, code, _) = curl(format!("http://{addr}/"), vec![]).await;
    assert_eq!(code, "200");
    assert!(page.contains("src=\"/stream\""));
    let (status, code, _) = curl(format!("http://{addr}/status.json"), vec![]).await;
    assert_eq!(code, "200");
    assert_eq!(serde_json::from_str::<ViewStatus>(&status).unwrap().frame_seq, 7);
    assert!(t0.elapsed() < Duration::from_secs(2), "the page took {:?}", t0.elapsed());

    // Every flood connection is closed: those evicted for newer ones at once, the rest at the
    // request deadline; each is counted as one or the other, and nothing is left held.
    all_closed(sockets, deadline + Duration::from_secs(3)).await;
    let c = counts_until(|| server.connections(), |c| c.held == 0, Duration::from_secs(2)).await;
    assert_eq!(c.evicted + c.timed_out, FLOOD as u64, "{c:?}");
    assert!(c.evicted >= (FLOOD - MAX_CONNECTIONS) as u64, "{c:?}");
    assert_eq!((c.accepted, c.refused_full, c.refused_per_address, c.busy), (FLOOD as u64 + 2, 0, 0, 0), "{c:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_thousand_half_open_connections_do_not_keep_a_foxglove_client_from_subscribing_and_are_closed_and_counted() {
    let (_stop, shutdown) = tokio::sync::watch::channel(false);
    // Long enough that the flood still holds every place when the Python client (slow to
    // import its decoders) connects.
    let deadline = Duration::from_secs(8);
    let channels = [ChannelSpec::recorded(Topic::DetectionMarkers)];
    let (server, _task) =
        FoxgloveServer::start_with("127.0.0.1:0".parse().unwrap(), &channels, &access(deadline, None), shutdown)
            .await
            .unwrap();
    let addr = server.local_addr();
    let sockets = flood(addr, b"GET / HTTP/1.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n").await;
    let flooded = Instant::now();
    let c = counts_until(|| server.connections(), |c| c.accepted == FLOOD as u64, Duration::from_secs(5)).await;
    assert_eq!((c.held, c.pending), (MAX_CONNECTIONS as u64, MAX_CONNECTIONS as u64), "{c:?}");

    // The client subscribes and receives; publish until it has its messages.
    let url = format!("ws://{addr}");
    let client = tokio::spawn(peer(vec!["receive".into(), url, "1".into(), "/detections/markers".into()]));
    let mut k = 0u64;
    while !client.is_finished() {
        let markers = starc_pipeline::record::msgs::MarkerArray::default();
        server.publish_msg(Topic::DetectionMarkers.name(), k, &markers).unwrap();
        k += 1;
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let v = client.await.unwrap();
    assert_eq!(v["server_info"]["op"], "serverInfo");
    assert_eq!(v["received"]["/detections/markers"].as_array().map(Vec::len), Some(1), "{v}");
    // It connected while the flood held every place (it took one from the oldest of them).
    assert!(flooded.elapsed() < deadline, "the client came after the flood had timed out: test too slow");
    let c = server.connections();
    assert_eq!(c.evicted, (FLOOD - MAX_CONNECTIONS + 1) as u64, "{c:?}");

    all_closed(sockets, deadline + Duration::from_secs(3)).await;
    let c = counts_until(|| server.connections(), |c| c.held == 0, Duration::from_secs(2)).await;
    assert_eq!(c.evicted + c.timed_out, FLOOD as u64, "{c:?}");
    assert_eq!((c.accepted, c.refused_full, c.refused_per_address, c.busy), (FLOOD as u64 + 1, 0, 0, 0), "{c:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_per_address_cap_refuses_at_accept_and_spares_other_addresses() {
    let hub = ViewHub::new();
    hub.publish(&ArFrame::filled(8, 6, [0, 200, 0]), ViewStatus::default()).unwrap();
    let (_stop, shutdown) = tokio::sync::watch::channel(false);
    let deadline = Duration::from_secs(5);
    let (http, _t1) = HttpServer::start("127.0.0.1:0".parse().unwrap(), hub, &access(deadline, None), shutdown.clone())
        .await
        .unwrap();
    let channels = [ChannelSpec::recorded(Topic::DetectionMarkers)];
    let (fox, _t2) =
        FoxgloveServer::start_with("127.0.0.1:0".parse().unwrap(), &channels, &access(deadline, None), shutdown)
            .await
            .unwrap();

    // Browser view: half of one address's places idle, half streaming (served connections
    // count too); the next from that address is answered 503 and closed at once.
    let mut held = Vec::new();
    for i in 0..PER_ADDRESS {
        let mut s = connect_from([127, 0, 2, 1], http.local_addr()).await;
        if i % 2 == 0 {
            s.write_all(b"GET /stream HTTP/1.1\r\n\r\n").await.unwrap();
            let mut first = [0u8; 12];
            s.read_exact(&mut first).await.unwrap();
            assert_eq!(&first, b"HTTP/1.1 200");
        }
        held.push(s);
    }
    let mut over = connect_from([127, 0, 2, 1], http.local_addr()).await;
    let t0 = Instant::now();
    let answer = closed_within(&mut over, Duration::from_secs(1)).await.expect("the one over the cap stays open");
    assert!(answer.starts_with("HTTP/1.1 503 ") && answer.contains("from your address"), "{answer}");
    assert!(t0.elapsed() < deadline / 2, "closed at accept, not at the request deadline");
    let (_, code, _) = curl(format!("http://{}/frame.png", http.local_addr()), vec![]).await;
    assert_eq!(code, "200", "another address is still served");
    let c = http.connections();
    assert_eq!((c.refused_per_address, c.refused_full), (1, 0), "{c:?}");

    // Foxglove: the same cap, the refused connection closed without a word.
    let mut fox_held = Vec::new();
    for _ in 0..PER_ADDRESS {
        fox_held.push(connect_from([127, 0, 2, 2], fox.local_addr()).await);
    }
    let mut over = connect_from([127, 0, 2, 2], fox.local_addr()).await;
    assert_eq!(closed_within(&mut over, Duration::from_secs(1)).await.as_deref(), Some(""));
    let v = peer(vec!["connect".into(), format!("ws://{}", fox.local_addr())]).await;
    assert_eq!(v["status"], 101, "another address is still served: {v}");
    let c = fox.connections();
    assert_eq!((c.refused_per_address, c.refused_full), (1, 0), "{c:?}");
    drop((held, fox_held));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bind_beyond_loopback_without_a_token_is_refused_naming_the_key() {
    // Checked before anything binds: no traffic leaves loopback.
    for (text, key) in [
        ("http_bind = \"0.0.0.0:8080\"", "http_bind"),
        ("foxglove_bind = \"[::]:8765\"", "foxglove_bind"),
        ("http_bind = \"192.168.4.1:8080\"", "http_bind"),
    ] {
        let e = ViewConfig::from_toml(text).unwrap_err().to_string();
        assert!(e.contains(key) && e.contains("`token`"), "{text}: {e}");
        let with_token = format!("{text}\ntoken = \"{TOKEN}\"");
        assert!(ViewConfig::from_toml(&with_token).unwrap().token.is_some());
    }
    // Loopback stays tokenless; a token too short or with characters a URL would mangle is refused.
    assert!(ViewConfig::from_toml("http_bind = \"127.0.0.1:8080\"\nfoxglove_bind = \"127.0.0.1:8765\"").is_ok());
    assert!(ViewConfig::from_toml("token = \"short\"").is_err());
    assert!(ViewConfig::from_toml("token = \"0123456789abcdef 0123\"").is_err());
    assert!(ViewConfig::from_toml("max_connections = 4").is_err());
    assert!(ViewConfig::from_toml("max_connections_per_address = 0").is_err());
    assert!(ViewConfig::from_toml("request_timeout_ms = 0").is_err());

    // The servers and start_views refuse it too, whoever built the config.
    let (_stop, shutdown) = tokio::sync::watch::channel(false);
    let open: SocketAddr = "0.0.0.0:0".parse().unwrap();
    let e = HttpServer::start(open, ViewHub::new(), &ViewAccess::default(), shutdown.clone()).await.err().unwrap();
    assert!(e.to_string().contains("http_bind"), "{e}");
    let e = FoxgloveServer::start(open, &ChannelSpec::all_recorded(), shutdown.clone()).await.err().unwrap();
    assert!(e.to_string().contains("foxglove_bind"), "{e}");
    let config = ViewConfig { foxglove_bind: Some(open), ..ViewConfig::default() };
    let e = start_views(&config, ViewHub::new(), shutdown).await.err().unwrap();
    assert!(e.to_string().contains("foxglove_bind") && e.to_string().contains("`token`"), "{e}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_token_requests_without_it_are_refused_and_with_it_served() {
    let hub = ViewHub::new();
    hub.publish(&ArFrame::filled(8, 6, [0, 0, 200]), ViewStatus { frame_seq: 3, ..ViewStatus::default() }).unwrap();
    let (_stop, shutdown) = tokio::sync::watch::channel(false);
    let guarded = access(Duration::from_secs(3), Some(TOKEN));
    let (http, _t1) = HttpServer::start("127.0.0.1:0".parse().unwrap(), hub, &guarded, shutdown.clone()).await.unwrap();
    let base = format!("http://{}", http.local_addr());

    let (_, code, headers) = curl(format!("{base}/"), vec![]).await;
    assert_eq!(code, "401");
    assert!(headers.to_ascii_lowercase().contains("www-authenticate: bearer"), "{headers}");
    let (_, code, _) = curl(format!("{base}/status.json?token=wrong-token-0123456789"), vec![]).await;
    assert_eq!(code, "403");
    let (_, code, _) = curl(format!("{base}/frame.png"), vec!["-H".into(), "Authorization: Bearer nope".into()]).await;
    assert_eq!(code, "403");
    let (_, code, _) = curl(format!("{base}/stream"), vec!["-I".into()]).await;
    assert_eq!(code, "401");

    // With it: the page, which sets the cookie its own requests then carry.
    let (page, code, headers) = curl(format!("{base}/?token={TOKEN}"), vec![]).await;
    assert_eq!(code, "200");
    assert!(page.contains("src=\"/stream\""));
    let cookie =
        headers.lines().find_map(|l| l.strip_prefix("Set-Cookie: ")).unwrap_or_else(|| panic!("no cookie: {headers}"));
    assert!(cookie.starts_with(&format!("starc_view_token={TOKEN};")) && cookie.contains("HttpOnly"), "{cookie}");
    let (status, code, _) =
        curl(format!("{base}/status.json"), vec!["-H".into(), format!("Cookie: starc_view_token={TOKEN}")]).await;
    assert_eq!(code, "200");
    assert_eq!(serde_json::from_str::<ViewStatus>(&status).unwrap().frame_seq, 3);
    let (_, code, _) =
        curl(format!("{base}/frame.png"), vec!["-H".into(), format!("Authorization: Bearer {TOKEN}")]).await;
    assert_eq!(code, "200");
    let mut stream = TcpStream::connect(http.local_addr()).await.unwrap();
    stream
        .write_all(format!("GET /stream HTTP/1.1\r\nCookie: starc_view_token={TOKEN}\r\n\r\n").as_bytes())
        .await
        .unwrap();
    let mut first = [0u8; 12];
    stream.read_exact(&mut first).await.unwrap();
    assert_eq!(&first, b"HTTP/1.1 200");
    drop(stream);
    assert_eq!(http.connections().unauthorized, 4);

    // Foxglove: the token in the URL.
    let channels = [ChannelSpec::recorded(Topic::DetectionMarkers)];
    let (fox, _t2) =
        FoxgloveServer::start_with("127.0.0.1:0".parse().unwrap(), &channels, &guarded, shutdown).await.unwrap();
    let url = format!("ws://{}", fox.local_addr());
    assert_eq!(peer(vec!["connect".into(), url.clone()]).await["status"], 401);
    assert_eq!(peer(vec!["connect".into(), format!("{url}/?token=wrong-token-0123456789")]).await["status"], 403);
    let v = peer(vec!["connect".into(), format!("{url}/?token={TOKEN}")]).await;
    assert_eq!((v["status"].as_u64(), v["op"].as_str()), (Some(101), Some("serverInfo")), "{v}");
    assert_eq!(fox.connections().unauthorized, 2);
}
