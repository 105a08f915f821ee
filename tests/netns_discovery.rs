//! Discovery by real broadcast, between two network namespaces joined by a veth pair: the mock
//! Avia in one broadcasts to 255.255.255.255:55000 as a real Avia does, and `starc devices` and
//! `starc livox monitor` in the other find it, handshake, and receive its points and IMU.
//!
//! Broadcasts and non-loopback addresses exist only inside namespaces this test creates and
//! removes. It needs root (CI runs as root); elsewhere it says it skipped.

use std::process::{Command, Output, Stdio};
use std::time::Duration;

#[path = "support/netns.rs"]
mod netns;
use netns::{ip, veth_pair, Namespaces};

fn setup(tag: &str) -> Result<Namespaces, String> {
    let (dev, host) = (format!("starc-dev-{tag}"), format!("starc-host-{tag}"));
    let (va, vb) = (format!("sva{tag}"), format!("svb{tag}"));
    let ns = veth_pair(&dev, &host, &va, &vb, "192.168.1.110/24", "192.168.1.50/24")?;
    // Limited broadcast leaves by the default route, as on a real LiDAR network.
    ip(&["-n", &dev, "route", "add", "default", "dev", &va])?;
    Ok(ns)
}

fn starc_in(ns: &str, args: &[&str]) -> Command {
    let mut c = Command::new("ip");
    c.args(["netns", "exec", ns, env!("CARGO_BIN_EXE_starc")]).args(args);
    c
}

fn output_of(mut c: Command) -> Output {
    c.stdout(Stdio::piped()).stderr(Stdio::piped()).output().unwrap_or_else(|e| panic!("running starc: {e}"))
}

#[test]
fn avia_found_by_broadcast_streams_to_the_host() {
    let tag = format!("{}", std::process::id() % 100_000);
    let mut ns = match setup(&tag) {
        Ok(ns) => ns,
        Err(e) => {
            eprintln!("skipped: cannot create network namespaces here ({e})");
            return;
        }
    };
    let (dev, host) = (ns.names[0].clone(), ns.names[1].clone());
    let mock = starc_in(
        &dev,
        &[
            "mock",
            "avia",
            "--ip",
            "192.168.1.110",
            "--code",
            "NETNSAVIA000001",
            "--broadcast-to",
            "255.255.255.255:55000",
            "--duration",
            "12",
        ],
    )
    .stdout(Stdio::null())
    .stderr(Stdio::null())
    .spawn();
    ns.children.push(mock.unwrap_or_else(|e| panic!("spawning the mock: {e}")));
    std::thread::sleep(Duration::from_millis(300));

    let listed = output_of(starc_in(&host, &["devices", "--host-ip", "192.168.1.50", "--seconds", "2.5", "--json"]));
    let text = String::from_utf8_lossy(&listed.stdout);
    assert!(listed.status.success(), "starc devices failed: {}", String::from_utf8_lossy(&listed.stderr));
    let devices: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}: {text}"));
    let first = &devices[0];
    assert_eq!(first["broadcast_code"], "NETNSAVIA000001", "{text}");
    assert_eq!(first["ip"], "192.168.1.110");
    assert_eq!(first["device_type"], "Avia");
    assert!(first["firmware"].is_string(), "{text}");
    assert!(first["status"].is_string(), "{text}");

    let monitor = output_of(starc_in(&host, &["livox", "monitor", "--host-ip", "192.168.1.50", "--seconds", "3.2"]));
    let text = String::from_utf8_lossy(&monitor.stdout);
    assert!(monitor.status.success(), "monitor failed: {}", String::from_utf8_lossy(&monitor.stderr));
    // The last full second: about 240,000 returns/s and 200 IMU packets/s.
    let last = text.lines().rfind(|l| l.contains("NETNSAVIA000001")).unwrap_or_default().to_string();
    let field = |name: &str| -> f64 {
        let after = last.split(name).nth(1).unwrap_or_default();
        after.split_whitespace().next().unwrap_or_default().parse().unwrap_or(-1.0)
    };
    let points = field("points/s");
    let imu = field("imu");
    assert!((200_000.0..=280_000.0).contains(&points), "points/s {points} in: {text}");
    assert!((170.0..=230.0).contains(&imu), "imu Hz {imu} in: {text}");
}
