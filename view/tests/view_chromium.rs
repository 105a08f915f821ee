//! The browser page in headless Chromium (Debian's `chromium`, installed by scripts/test.sh): the
//! page shows the published frame, then, once other frames are published while it stays open,
//! the newest (the stream keeps updating the image, not only its first part), and its status
//! line, read from /status.json by the page's script, says what the rig's status says, in green.
//!
//! tests/peers/chromium_view.py drives Chromium over the DevTools protocol (PyPI websockets):
//! it shoots the page, tells the test, which switches what it publishes, and shoots again. Both
//! screenshots are taken after a set time, whatever the machine's load, which `--screenshot`
//! does not allow (it shoots at the load event, the first frame). Chromium reaches nothing but loopback: every other
//! host goes to a proxy at a closed loopback port, host names do not resolve, its background
//! services (updates, sync, metrics) are off; it runs in a process group of its own with a
//! throwaway profile, and the group is killed at the end, so no browser process outlives it.
//!
//! `BROWSER_SHOT=path.png` keeps the screenshot (docs/img/view_browser.png is one);
//! `BROWSER_FRAME=frame.png` publishes that PNG (an AR frame of a run) instead of the test's
//! two-colour frames and only takes the screenshot.

#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::{peer_python, root};
use starc_pipeline::ar::ArFrame;
use starc_view::{serve_http, ViewHub, ViewStatus};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const WIDTH: u32 = 320;
const HEIGHT: u32 = 240;
/// How long the page is open before each screenshot (seconds).
const WAIT_S: f64 = 2.0;
const FIRST: [u8; 3] = [150, 20, 150];
const SECOND: [u8; 3] = [20, 150, 150];

fn solid(colour: [u8; 3]) -> ArFrame {
    ArFrame::filled(WIDTH, HEIGHT, colour)
}

fn status(aligned: bool, seq: u64) -> ViewStatus {
    ViewStatus {
        aligned,
        detection_age_ms: Some(300.0),
        link: "OK".into(),
        people: 2,
        frame_seq: seq,
        stamp_ns: 1_763_719_200_000_000_000 + seq,
    }
}

/// Publishes at 20 Hz until `stop`: the first colour, not aligned, until `switched`, then the
/// second, aligned (or `fixed` throughout, aligned).
fn publish_until(hub: ViewHub, stop: Arc<AtomicBool>, switched: Arc<AtomicBool>, fixed: Option<ArFrame>) {
    let start = Instant::now();
    let mut seq = 0;
    while !stop.load(Ordering::Relaxed) && start.elapsed() < Duration::from_secs(120) {
        seq += 1;
        let second = switched.load(Ordering::Relaxed);
        let frame = fixed.clone().unwrap_or_else(|| solid(if second { SECOND } else { FIRST }));
        hub.publish(&frame, status(second || fixed.is_some(), seq)).unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// tests/peers/chromium_view.py on `url` in a window of `width` x `height`: a first screenshot
/// `wait_s` after the page opened, then `switch` is set, then the final screenshot `wait_s`
/// later (the first beside it, `.first` before the suffix) and the page's status line (text,
/// class).
fn chromium_view(
    url: &str,
    shot: &Path,
    wait_s: f64,
    (width, height): (u32, u32),
    switch: &AtomicBool,
) -> (String, String) {
    let mut child = Command::new(peer_python())
        .arg(root().join("tests/peers/chromium_view.py"))
        .args([url, &shot.display().to_string(), &wait_s.to_string(), &width.to_string(), &height.to_string()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("running the peers' python");
    let mut stdin = child.stdin.take().unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut last = String::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        if line.contains("\"phase\"") {
            switch.store(true, Ordering::Relaxed);
            writeln!(stdin, "go").unwrap();
        } else {
            last = line;
        }
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "chromium_view.py: {}\n{last}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(last.trim()).unwrap();
    (v["status"].as_str().unwrap().to_string(), v["class"].as_str().unwrap().to_string())
}

fn decode_png(bytes: &[u8]) -> ArFrame {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    let rgb = match info.color_type {
        png::ColorType::Rgb => buf,
        png::ColorType::Rgba => buf.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect(),
        other => panic!("screenshot colour type {other:?}"),
    };
    ArFrame { width: info.width, height: info.height, rgb }
}

fn count_near(img: &ArFrame, colour: [u8; 3]) -> usize {
    img.rgb.chunks_exact(3).filter(|p| p.iter().zip(colour).all(|(a, b)| a.abs_diff(b) <= 6)).count()
}

struct Server {
    _rt: tokio::runtime::Runtime,
    url: String,
    _stop: tokio::sync::watch::Sender<bool>,
    publishing: Arc<AtomicBool>,
    switched: Arc<AtomicBool>,
    publisher: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Server {
    fn drop(&mut self) {
        self.publishing.store(true, Ordering::Relaxed);
        if let Some(p) = self.publisher.take() {
            let _ = p.join();
        }
    }
}

fn serve(fixed: Option<ArFrame>) -> Server {
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let hub = ViewHub::new();
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let (addr, _task) = rt.block_on(serve_http("127.0.0.1:0".parse().unwrap(), hub.clone(), shutdown)).unwrap();
    let (publishing, switched) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
    let (flag, switch) = (publishing.clone(), switched.clone());
    let publisher = std::thread::spawn(move || publish_until(hub, flag, switch, fixed));
    let url = format!("http://{addr}/");
    Server { _rt: rt, url, _stop: stop, publishing, switched, publisher: Some(publisher) }
}

#[test]
fn the_page_shows_the_newest_frame_and_the_status_in_headless_chromium() {
    let fixed = std::env::var_os("BROWSER_FRAME").map(|p| decode_png(&std::fs::read(p).unwrap()));
    let only_shot = fixed.is_some();
    let server = serve(fixed);
    let dir = tempfile::tempdir().unwrap();
    let shot = dir.path().join("shot.png");

    // The page opens on the first frames, is shot, then the second frames are published and it
    // is shot again. A run's frame is shot at a size for the docs; the test's in a small window.
    let window = if only_shot { (680, 540) } else { (480, 320) };
    let (line, class) = chromium_view(&server.url, &shot, WAIT_S, window, &server.switched);
    let bytes = std::fs::read(&shot).unwrap();
    if let Some(keep) = std::env::var_os("BROWSER_SHOT") {
        std::fs::write(PathBuf::from(keep), &bytes).unwrap();
    }
    if only_shot {
        return;
    }
    let frame_px = (WIDTH * HEIGHT) as usize;
    // First the first frames, the status line red.
    let first_shot = decode_png(&std::fs::read(dir.path().join("shot.first.png")).unwrap());
    assert_eq!((first_shot.width, first_shot.height), (480, 320));
    let (first, second) = (count_near(&first_shot, FIRST), count_near(&first_shot, SECOND));
    assert!(first > frame_px * 8 / 10 && second == 0, "first shot: {first} / {second} pixels of {frame_px}");
    let img = decode_png(&bytes);
    assert_eq!((img.width, img.height), (480, 320));
    // Then the whole frame in the second colour: the stream replaced the first frames with the
    // newest (the page did not stop at its first part).
    let (first, second) = (count_near(&img, FIRST), count_near(&img, SECOND));
    assert!(second > frame_px * 8 / 10, "newest frame: {second} pixels of {frame_px} (first colour {first})");
    assert!(first < frame_px / 100, "an old frame is still shown: {first} pixels");

    // The status line, written by the page's script from /status.json, green.
    assert_eq!(class, "ok", "status line {line:?}");
    assert!(line.starts_with("ALIGNED | people 2 | detection 0.3 s | link OK | frame "), "status line: {line:?}");
}
