//! The views' config (`[view]`, config/view.toml) and `start_views` with every output that
//! needs no hardware: the browser view, Foxglove and PNG files, all following one hub and all
//! stopping on shutdown.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use starc_pipeline::ar::ArFrame;
use starc_view::{start_views, ViewConfig, ViewHub, ViewStatus};
use std::time::{Duration, Instant};

#[test]
fn the_shipped_example_loads_and_typos_are_refused() {
    let shipped = ViewConfig::from_toml(include_str!("../../config/view.toml")).unwrap();
    assert_eq!(shipped.http_bind, Some("127.0.0.1:8080".parse().unwrap()));
    assert_eq!(shipped.foxglove_bind, Some("127.0.0.1:8765".parse().unwrap()));
    assert_eq!(shipped.framebuffer, None);
    assert_eq!(shipped.png_every, 10);
    // The caps as shipped are the defaults; no token ships (loopback needs none).
    let defaults = ViewConfig::default();
    assert_eq!(shipped.token, None);
    assert_eq!(
        (shipped.max_connections, shipped.max_connections_per_address, shipped.request_timeout_ms),
        (defaults.max_connections, defaults.max_connections_per_address, defaults.request_timeout_ms)
    );
    assert_eq!(
        (defaults.max_connections, defaults.max_connections_per_address, defaults.request_timeout_ms),
        (64, 8, 3000)
    );
    assert_eq!(ViewConfig::from_toml("").unwrap(), ViewConfig::default());
    assert!(ViewConfig::from_toml("http_bnd = \"127.0.0.1:1\"").is_err());
    assert!(ViewConfig::from_toml("png_every = 0").is_err());
    assert!(ViewConfig::from_toml("http_bind = \"rig:8080\"").is_err());
    // Embedded as [view] in a bigger file, as fpv.toml will hold it.
    #[derive(serde::Deserialize)]
    struct Fpv {
        view: ViewConfig,
    }
    let fpv: Fpv = toml::from_str("[view]\npng_dir = \"out/frames\"\npng_every = 3\n").unwrap();
    assert_eq!(fpv.view.png_dir.as_deref(), Some(std::path::Path::new("out/frames")));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn start_views_runs_every_output_and_stops_them() {
    let dir = tempfile::tempdir().unwrap();
    let config = ViewConfig {
        http_bind: Some("127.0.0.1:0".parse().unwrap()),
        foxglove_bind: Some("127.0.0.1:0".parse().unwrap()),
        png_dir: Some(dir.path().join("frames")),
        png_every: 2,
        framebuffer: None,
        ..ViewConfig::default()
    };
    let hub = ViewHub::new();
    let (stop, shutdown) = tokio::sync::watch::channel(false);
    let views = start_views(&config, hub.clone(), shutdown).await.unwrap();
    let http = views.http.unwrap();
    assert_ne!(http.port(), 0);
    assert_ne!(views.foxglove.as_ref().unwrap().local_addr().port(), 0);
    assert_eq!(views.tasks.len(), 3);

    // A second start on the same ports fails cleanly.
    let (_s, shutdown2) = tokio::sync::watch::channel(false);
    let taken = ViewConfig { http_bind: Some(http), ..ViewConfig::default() };
    assert!(start_views(&taken, hub.clone(), shutdown2).await.is_err());

    // Frames 0..=6 at a pace the writer keeps up with: files for the even ones, whole PNGs.
    for seq in 0..=6u64 {
        let frame = ArFrame::filled(16, 12, [seq as u8 * 30, 0, 0]);
        hub.publish(&frame, ViewStatus { frame_seq: seq, ..ViewStatus::default() }).unwrap();
        let want = dir.path().join(format!("frames/ar_{seq:08}.png"));
        let deadline = Instant::now() + Duration::from_secs(5);
        while seq % 2 == 0 && !want.exists() {
            assert!(Instant::now() < deadline, "{} not written", want.display());
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }
    let mut names: Vec<String> = std::fs::read_dir(dir.path().join("frames"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["ar_00000000.png", "ar_00000002.png", "ar_00000004.png", "ar_00000006.png"]);
    let png = std::fs::read(dir.path().join("frames/ar_00000004.png")).unwrap();
    assert_eq!(png, *hub.latest().map(|_| ArFrame::filled(16, 12, [120, 0, 0]).to_png().unwrap()).unwrap());

    stop.send(true).unwrap();
    for task in views.tasks {
        tokio::time::timeout(Duration::from_secs(5), task).await.expect("a view did not stop").unwrap();
    }
    assert!(tokio::net::TcpStream::connect(http).await.is_err(), "the browser view still listens");
}
