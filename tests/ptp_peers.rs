//! PTP against the reference implementation, ptp4l (Debian `linuxptp`), in both directions,
//! between two network namespaces joined by a veth pair, with kernel software timestamps:
//!
//! (a) ptp4l is the grandmaster, `starc ptp slave` measures it;
//! (b) `starc ptp master` is the grandmaster, ptp4l is the slave and reports its offsets.
//!
//! Both namespaces share the machine's one clock, so a correct exchange shows offsets near zero
//! (PTP time is TAI, 37 s ahead of the UTC system clock: a wrong UTC offset shows as 37 s).
//! Nothing here may move that clock: our slave measures only and every ptp4l runs with
//! `--free_running 1`; the test checks the kernel's TAI offset is untouched too.
//!
//! Needs root and ptp4l; in CI (CI set) their absence fails the test, elsewhere it is skipped.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The two tests share the 2-core machine; run them one at a time so neither sees the other's load.
static SERIAL: Mutex<()> = Mutex::new(());

#[path = "support/netns.rs"]
mod netns;
use netns::{veth_pair, Namespaces};

/// Master namespace with `va` (10.79.0.1), slave namespace with `vb` (10.79.0.2).
fn setup(tag: &str) -> Result<(Namespaces, [String; 4]), String> {
    let (m, s) = (format!("starc-ptpm-{tag}"), format!("starc-ptps-{tag}"));
    let (va, vb) = (format!("pma{tag}"), format!("psb{tag}"));
    let ns = veth_pair(&m, &s, &va, &vb, "10.79.0.1/24", "10.79.0.2/24")?;
    Ok((ns, [m, va, s, vb]))
}

fn in_ci() -> bool {
    std::env::var_os("CI").is_some()
}

fn ptp4l() -> Option<String> {
    ["/usr/sbin/ptp4l", "/usr/bin/ptp4l", "/usr/local/sbin/ptp4l"]
        .iter()
        .find(|p| std::path::Path::new(p).exists())
        .map(|p| p.to_string())
}

/// Namespaces and ptp4l, or why the test cannot run (a failure in CI, a skip elsewhere).
fn prepare(name: &str) -> Option<(Namespaces, [String; 4], String)> {
    let why = match (ptp4l(), setup(&format!("{}{}", std::process::id() % 10_000, name))) {
        (Some(p), Ok((ns, names))) => return Some((ns, names, p)),
        (None, _) => "ptp4l not installed (apt-get install linuxptp; .ci/run does)".to_string(),
        (_, Err(e)) => format!("cannot create network namespaces here ({e})"),
    };
    assert!(!in_ci(), "{why}");
    eprintln!("skipped: {why}");
    None
}

/// The kernel's TAI-UTC offset (adjtimex read-only: modes = 0).
fn kernel_tai_offset() -> i32 {
    // SAFETY: timex is plain data; adjtimex with modes 0 only reads.
    let mut tx: libc::timex = unsafe { std::mem::zeroed() };
    unsafe { libc::adjtimex(&mut tx) };
    tx.tai
}

/// Spawns `ip netns exec NS program args`, collecting its stdout lines in the background.
fn spawn_collect(ns: &mut Namespaces, netns: &str, program: &str, args: &[&str]) -> Arc<Mutex<Vec<String>>> {
    let mut child = Command::new("ip")
        .args(["netns", "exec", netns, program])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("spawning {program}: {e}"));
    let lines = Arc::new(Mutex::new(Vec::new()));
    if let Some(out) = child.stdout.take() {
        let sink = Arc::clone(&lines);
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if let Ok(mut v) = sink.lock() {
                    v.push(line);
                }
            }
        });
    }
    ns.children.push(child);
    lines
}

/// Waits for the last spawned child to exit by itself, at most `limit`.
fn wait_last(ns: &mut Namespaces, limit: Duration) {
    let deadline = Instant::now() + limit;
    if let Some(c) = ns.children.last_mut() {
        while Instant::now() < deadline {
            if matches!(c.try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

struct Figures {
    offsets: Vec<i64>,
    delays: Vec<i64>,
}

fn figures(lines: &[String]) -> Figures {
    let parsed: Vec<_> = lines.iter().filter_map(|l| starc_ptp::status::parse_offset_line(l)).collect();
    Figures {
        offsets: parsed.iter().map(|p| p.offset_ns).collect(),
        delays: parsed.iter().map(|p| p.path_delay_ns).collect(),
    }
}

/// The path delays from the first one measured on: ptp4l prints a delay of 0 on the offset lines
/// before its first delay response has come back, which the machine's load decides.
fn measured_delays(f: &Figures) -> Vec<i64> {
    f.delays.iter().copied().skip_while(|&d| d == 0).collect()
}

fn median_abs(v: &[i64]) -> i64 {
    let mut a: Vec<i64> = v.iter().map(|x| x.abs()).collect();
    a.sort_unstable();
    a.get(a.len() / 2).copied().unwrap_or(i64::MAX)
}

fn report(what: &str, f: &Figures) {
    let max = f.offsets.iter().map(|x| x.abs()).max().unwrap_or(0);
    println!(
        "{what}: {} offset lines, |offset| median {} ns, max {} ns; path delay median {} ns; offsets {:?}",
        f.offsets.len(),
        median_abs(&f.offsets),
        max,
        median_abs(&f.delays),
        f.offsets
    );
}

const PTP4L_FAST: [&str; 6] = ["-S", "-m", "-4", "-E", "--logAnnounceInterval=-2", "--announceReceiptTimeout=2"];

#[test]
fn our_slave_measures_a_ptp4l_master() {
    let _one = SERIAL.lock();
    let Some((mut ns, [m, va, s, vb], ptp4l)) = prepare("a") else { return };
    let tai_before = kernel_tai_offset();
    let uds = format!("/tmp/starc-ptp4l-{}-a", std::process::id());
    let mut args = vec!["-i", va.as_str(), "--free_running=1", "--logSyncInterval=-3"];
    args.extend(PTP4L_FAST);
    let uds_arg = format!("--uds_address={uds}");
    args.push(&uds_arg);
    let master_log = spawn_collect(&mut ns, &m, &ptp4l, &args);
    std::thread::sleep(Duration::from_millis(300));

    let starc = env!("CARGO_BIN_EXE_starc");
    let ours = spawn_collect(
        &mut ns,
        &s,
        starc,
        // --hw-timestamps: veth has no PTP clock, so this also proves the software fallback.
        &[
            "ptp",
            "slave",
            "--iface",
            &vb,
            "--free-running",
            "--hw-timestamps",
            "--delay-req-interval",
            "-3",
            "--seconds",
            "9",
        ],
    );
    wait_last(&mut ns, Duration::from_secs(15));
    let lines = ours.lock().map(|v| v.clone()).unwrap_or_default();
    let f = figures(&lines);
    report("ptp4l master -> starc slave", &f);
    let text = lines.join("\n");
    assert!(text.contains("measure-only"), "{text}");
    assert!(text.contains("(software timestamps)"), "no fallback to software stamps:\n{text}");
    assert!(f.offsets.len() >= 5, "too few offset lines:\n{text}\nptp4l:\n{:?}", master_log.lock().map(|v| v.clone()));
    assert!(median_abs(&f.offsets) < 10_000, "median |offset| too large:\n{text}");
    assert!(f.delays.iter().all(|&d| d > 0 && d < 1_000_000), "path delays not sane:\n{text}");
    let summary = lines.iter().find(|l| l.starts_with("summary:")).cloned().unwrap_or_default();
    assert!(summary.contains("clock_adjustments: 0"), "{summary}");
    assert_eq!(kernel_tai_offset(), tai_before, "the kernel's TAI offset changed");
    let _ = std::fs::remove_file(&uds);
}

#[test]
fn ptp4l_slave_follows_our_master() {
    let _one = SERIAL.lock();
    let Some((mut ns, [m, va, s, vb], ptp4l)) = prepare("b") else { return };
    let tai_before = kernel_tai_offset();
    let starc = env!("CARGO_BIN_EXE_starc");
    let ours = spawn_collect(
        &mut ns,
        &m,
        starc,
        &["ptp", "master", "--iface", &va, "--sync-interval", "-3", "--announce-interval", "-2", "--seconds", "12"],
    );
    std::thread::sleep(Duration::from_millis(300));

    let uds = format!("/tmp/starc-ptp4l-{}-b", std::process::id());
    let uds_arg = format!("--uds_address={uds}");
    // -s: slave only; --free_running 1: compute offsets, never adjust the clock. One offset line
    // per second: stats per Sync (summary_interval = sync interval), frequency per second.
    let mut args = vec![
        "-i",
        vb.as_str(),
        "-s",
        "--free_running=1",
        "--summary_interval=-3",
        "--freq_est_interval=0",
        "--logMinDelayReqInterval=-3",
        uds_arg.as_str(),
    ];
    args.extend(PTP4L_FAST);
    let theirs = spawn_collect(&mut ns, &s, &ptp4l, &args);
    std::thread::sleep(Duration::from_secs(9));
    if let Some(c) = ns.children.last_mut() {
        let _ = c.kill();
        let _ = c.wait();
    }
    std::thread::sleep(Duration::from_millis(100));
    let lines = theirs.lock().map(|v| v.clone()).unwrap_or_default();
    let f = figures(&lines);
    report("starc master -> ptp4l slave", &f);
    let text = lines.join("\n");
    assert!(!text.contains("not using PTP timescale"), "our master must announce PTP time:\n{text}");
    assert!(f.offsets.len() >= 5, "too few offset lines from ptp4l:\n{text}");
    // A wrong UTC offset would show as whole seconds; the median says how well we agree.
    assert!(f.offsets.iter().all(|o| o.abs() < 1_000_000_000), "a UTC-offset error:\n{text}");
    assert!(median_abs(&f.offsets) < 10_000, "median |offset| too large:\n{text}");
    let delays = measured_delays(&f);
    assert!(delays.len() >= 4, "too few path delays measured:\n{text}");
    assert!(delays.iter().all(|&d| d > 0 && d < 1_000_000), "path delays not sane:\n{text}");
    assert_eq!(kernel_tai_offset(), tai_before, "the kernel's TAI offset changed");
    let ours = ours.lock().map(|v| v.join("\n")).unwrap_or_default();
    assert!(ours.contains("grandmaster"), "{ours}");
    let _ = std::fs::remove_file(&uds);
}
