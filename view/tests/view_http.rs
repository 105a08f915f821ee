//! The browser live view (view/src/http.rs) against real clients: curl for the page, the frame,
//! the status and a 404; Python's http.client reading parts of the multipart stream
//! (tests/peers/http_stream.py); raw sockets for malformed and oversized requests, the client
//! limit, and a viewer that never reads.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use serde_json::Value;
use starc_pipeline::ar::ArFrame;
use starc_view::{serve_http, ConnLimits, HttpServer, ViewAccess, ViewHub, ViewStatus};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const CURL: &str = "/usr/bin/curl";

/// The workspace root, where .venv and tests/peers live.
fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// A frame whose every pixel says where it is and which frame it belongs to.
fn frame(w: u32, h: u32, seq: u64) -> ArFrame {
    let mut rgb = Vec::with_capacity((w * h * 3) as usize);
    for y in 0..h {
        for x in 0..w {
            rgb.extend_from_slice(&[(x * 7) as u8, (y * 11) as u8, seq as u8]);
        }
    }
    ArFrame { width: w, height: h, rgb }
}

fn status(seq: u64) -> ViewStatus {
    ViewStatus {
        aligned: true,
        detection_age_ms: Some(80.5),
        link: "OK".into(),
        people: 2,
        frame_seq: seq,
        stamp_ns: 1_763_719_200_000_000_000 + seq,
    }
}

fn decode_png(bytes: &[u8]) -> ArFrame {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    ArFrame { width: info.width, height: info.height, rgb: buf }
}

struct Server {
    rt: tokio::runtime::Runtime,
    hub: ViewHub,
    addr: SocketAddr,
    _stop: tokio::sync::watch::Sender<bool>,
    http: Option<HttpServer>,
}

fn start() -> Server {
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let hub = ViewHub::new();
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let (addr, _task) = rt.block_on(serve_http("127.0.0.1:0".parse().unwrap(), hub.clone(), shutdown)).unwrap();
    Server { rt, hub, addr, _stop: stop, http: None }
}

/// A server whose per-address cap is above its serving slots, so that viewers all on 127.0.0.1
/// meet the slots first.
fn start_wide_open() -> Server {
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let hub = ViewHub::new();
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let access =
        ViewAccess { limits: ConnLimits { max_per_address: 64, ..ConnLimits::default() }, ..ViewAccess::default() };
    let (http, _task) =
        rt.block_on(HttpServer::start("127.0.0.1:0".parse().unwrap(), hub.clone(), &access, shutdown)).unwrap();
    Server { rt, hub, addr: http.local_addr(), _stop: stop, http: Some(http) }
}

/// curl's body (to `out` if given) and "<code> <content type>".
fn curl(url: &str, out: Option<&Path>) -> (Vec<u8>, String) {
    let mut cmd = Command::new(CURL);
    cmd.args(["-sS", "--max-time", "5", "-w", "\n%{http_code} %{content_type}"]);
    if let Some(p) = out {
        cmd.arg("-o").arg(p);
    }
    let o = cmd.arg(url).output().expect("running /usr/bin/curl");
    assert!(o.status.success(), "curl {url}: {}", String::from_utf8_lossy(&o.stderr));
    let text = o.stdout;
    let split = text.iter().rposition(|&b| b == b'\n').unwrap();
    (text[..split].to_vec(), String::from_utf8_lossy(&text[split + 1..]).into_owned())
}

/// Sends raw bytes and reads the whole response (the server closes after each).
fn raw(addr: SocketAddr, request: &[u8]) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    s.write_all(request).unwrap();
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

#[test]
fn page_frame_status_and_errors() {
    let server = start();
    let base = format!("http://{}", server.addr);
    // Before the first frame.
    let (body, meta) = curl(&format!("{base}/frame.png"), None);
    assert!(meta.starts_with("503"), "{meta} {body:?}");
    let (body, meta) = curl(&format!("{base}/status.json"), None);
    assert_eq!(meta, "200 application/json");
    assert_eq!(serde_json::from_slice::<Value>(&body).unwrap(), serde_json::json!({"frame": null}));

    let published = frame(64, 48, 5);
    server.hub.publish(&published, status(5)).unwrap();

    let (page, meta) = curl(&format!("{base}/"), None);
    assert_eq!(meta, "200 text/html; charset=utf-8");
    let page = String::from_utf8(page).unwrap();
    assert!(page.contains("src=\"/stream\"") && page.contains("/status.json"));
    // Self-contained: nothing loaded from elsewhere.
    assert!(!page.contains("http://") && !page.contains("https://") && !page.contains("//cdn"));

    let dir = tempfile::tempdir().unwrap();
    let png_path = dir.path().join("frame.png");
    let (_, meta) = curl(&format!("{base}/frame.png?t=1"), Some(&png_path));
    assert_eq!(meta, "200 image/png");
    assert_eq!(decode_png(&std::fs::read(&png_path).unwrap()), published);

    let (body, meta) = curl(&format!("{base}/status.json"), None);
    assert_eq!(meta, "200 application/json");
    let s: ViewStatus = serde_json::from_slice(&body).unwrap();
    assert_eq!(s, status(5));

    let (_, meta) = curl(&format!("{base}/nope"), None);
    assert!(meta.starts_with("404"), "{meta}");

    assert!(raw(server.addr, b"BLAH\r\n\r\n").starts_with("HTTP/1.1 400 "));
    assert!(raw(server.addr, b"GET / HTTP/1.1\r\nno colon here\r\n\r\n").starts_with("HTTP/1.1 400 "));
    assert!(raw(server.addr, b"GET /../etc/passwd\x01 HTTP/1.1\r\n\r\n").starts_with("HTTP/1.1 400 "));
    assert!(raw(server.addr, b"POST / HTTP/1.1\r\nContent-Length: 0\r\n\r\n").starts_with("HTTP/1.1 405 "));
    let mut huge = b"GET / HTTP/1.1\r\n".to_vec();
    huge.extend(std::iter::repeat_n(b'a', 20_000));
    assert!(raw(server.addr, &huge).starts_with("HTTP/1.1 431 "));
    // A client that hangs up mid-request gets nothing, and the server carries on.
    assert_eq!(raw(server.addr, b"GET / HT"), "");
    let head = raw(server.addr, b"HEAD /frame.png HTTP/1.0\r\n\r\n");
    assert!(head.starts_with("HTTP/1.1 200 ") && head.ends_with("\r\n\r\n"), "{head}");
    let (_, meta) = curl(&format!("{base}/status.json"), None);
    assert!(meta.starts_with("200"));
}

#[test]
fn the_stream_delivers_new_frames_as_png_parts() {
    let server = start();
    server.hub.publish(&frame(32, 24, 0), status(0)).unwrap();
    let python = root().join(".venv/bin/python");
    assert!(python.exists(), ".venv/bin/python missing: run .ci/run's install step");
    let mut child = Command::new(python)
        .arg(root().join("tests/peers/http_stream.py"))
        .args(["127.0.0.1", &server.addr.port().to_string(), "/stream", "3"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Publish until the reader has its parts; it joins whenever it starts.
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut seq = 0;
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the stream reader did not finish");
        }
        seq += 1;
        server.hub.publish(&frame(32, 24, seq), status(seq)).unwrap();
        std::thread::sleep(Duration::from_millis(30));
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["status"], 200);
    assert_eq!(v["content_type"], "multipart/x-mixed-replace; boundary=starcframe");
    let parts = v["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 3);
    let mut last = None;
    for p in parts {
        assert_eq!(p["content_type"], "image/png");
        let hex = p["body"].as_str().unwrap();
        let bytes: Vec<u8> =
            (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect();
        let f = decode_png(&bytes);
        let seq = u64::from(f.rgb[2]);
        assert_eq!(f, frame(32, 24, seq), "each part is one published frame, whole");
        assert!(last.is_none_or(|l| seq > l), "parts come newest-after-older: {last:?} then {seq}");
        last = Some(seq);
    }
}

#[test]
fn viewers_are_bounded_and_a_stalled_one_holds_up_nobody() {
    let server = start_wide_open();
    server.hub.publish(&frame(32, 24, 0), status(0)).unwrap();
    let mut streams = Vec::new();
    for _ in 0..starc_view::http::MAX_CLIENTS {
        let mut s = TcpStream::connect(server.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        s.write_all(b"GET /stream HTTP/1.1\r\n\r\n").unwrap();
        let mut first = [0u8; 12];
        s.read_exact(&mut first).unwrap();
        assert_eq!(&first, b"HTTP/1.1 200");
        streams.push(s);
    }
    let refused = raw(server.addr, b"GET / HTTP/1.1\r\n\r\n");
    assert!(refused.starts_with("HTTP/1.1 503 ") && refused.ends_with("too many viewers\n"), "one viewer too many");
    // Refused for want of a serving slot, after its request was read; not at accept.
    let c = server.http.as_ref().unwrap().connections();
    assert_eq!((c.busy, c.refused_full, c.refused_per_address), (1, 0, 0), "{c:?}");

    // All but one viewer leave; the one left never reads again. Big noisy frames fill its
    // socket while the renderer goes on publishing.
    let stalled = streams.pop().unwrap();
    drop(streams);
    let mut noise = frame(640, 480, 0);
    let mut x = 0x1234_5678u32;
    for b in &mut noise.rgb {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        *b = x as u8;
    }
    let mut slowest = Duration::ZERO;
    for seq in 1..=40 {
        let t0 = Instant::now();
        server.hub.publish(&noise, status(seq)).unwrap();
        slowest = slowest.max(t0.elapsed());
    }
    // Encoding dominates; the bound only says no publish waited on the stalled socket (10 s).
    assert!(slowest < Duration::from_secs(2), "a publish took {slowest:?}");
    // The departed viewers' slots come back (their tasks notice on their next write).
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let r = raw(server.addr, b"GET /status.json HTTP/1.1\r\n\r\n");
        if r.starts_with("HTTP/1.1 200 ") {
            let body = r.split("\r\n\r\n").nth(1).unwrap();
            assert_eq!(serde_json::from_str::<ViewStatus>(body).unwrap().frame_seq, 40);
            break;
        }
        assert!(Instant::now() < deadline, "slots were not freed: {r}");
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(stalled);
    server.rt.shutdown_timeout(Duration::from_secs(1));
}
