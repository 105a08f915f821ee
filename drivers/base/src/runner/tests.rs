//! The loop against a fake bus: a receive flood must not starve the watchdog, a transport that
//! stops taking frames latches a fault instead of hanging the loop, and a loop torn down by a
//! panic or a runtime shutdown still sends the halt frames.

use super::*;
use crate::c620::{CurrentCommand, Feedback};
use crate::safety::DriveMode;
use starc_can::RxFrame;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// The controller tests' base, with a short send time-out.
fn config() -> String {
    format!("send_timeout_ms = 30\n{}", crate::controller::tests::CONFIG)
}

/// What the fake bus saw and how it misbehaves; shared with the test.
#[derive(Default)]
struct Wire {
    sent: Mutex<Vec<CanFrame>>,
    /// Frames sent after [`Wire::panic_now`] was set.
    sent_after_panic: AtomicUsize,
    /// Receive returns at once, every time (a flooded bus), instead of one frame per ms.
    flood: bool,
    /// Sends block forever once this many frames went out.
    stall_after: Option<usize>,
    /// The next receive panics.
    panic_now: AtomicBool,
}

struct FakeBus {
    wire: Arc<Wire>,
    next_esc: u8,
}

impl FakeBus {
    fn new(wire: &Arc<Wire>) -> Self {
        Self { wire: wire.clone(), next_esc: 1 }
    }

    fn sent(wire: &Wire) -> Vec<CanFrame> {
        wire.sent.lock().map(|s| s.clone()).unwrap_or_default()
    }
}

impl CanBus for FakeBus {
    async fn send(&mut self, frame: &CanFrame) -> starc_can::Result<()> {
        let count = self.wire.sent.lock().map(|s| s.len()).unwrap_or(0);
        if self.wire.stall_after.is_some_and(|n| count >= n) {
            std::future::pending::<()>().await;
        }
        if let Ok(mut s) = self.wire.sent.lock() {
            s.push(*frame);
        }
        if self.wire.panic_now.load(Ordering::SeqCst) {
            self.wire.sent_after_panic.fetch_add(1, Ordering::SeqCst);
        }
        Ok(())
    }

    async fn recv(&mut self) -> starc_can::Result<BusEvent> {
        if self.wire.panic_now.load(Ordering::SeqCst) {
            panic!("the fake bus panics, as a bug in a transport or a driver would");
        }
        if self.wire.flood {
            // A real transport's reads count against tokio's budget too; that is what lets
            // the task yield at all under a flood.
            tokio::task::coop::consume_budget().await;
        } else {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        // Feedback of a standing wheel from each ESC in turn: fresh feedback, so no fault.
        let esc = self.next_esc;
        self.next_esc = esc % 3 + 1;
        let frame = Feedback { esc, angle_raw: 0, rotor_rpm: 0, current_raw: 0, temperature_c: 30 }
            .to_frame()
            .map_err(|e| starc_can::CanError::io("fake feedback", std::io::Error::other(e.to_string())))?;
        Ok(BusEvent::Frame(RxFrame { frame, host: Stamp::host_now(), device: None }))
    }

    fn stats(&self) -> BusStats {
        BusStats::default()
    }
}

fn base() -> Base {
    Base::new(BaseConfig::from_toml(&config()).unwrap_or_else(|e| panic!("{e}"))).unwrap_or_else(|e| panic!("{e}"))
}

use crate::config::BaseConfig;

fn options() -> RunnerOptions {
    RunnerOptions { status_poll: None }
}

/// Waits up to `limit` for the status to satisfy `cond`; the time it took.
async fn wait_for(handle: &BaseHandle, limit: Duration, cond: impl Fn(&BaseStatus) -> bool) -> Option<Duration> {
    let start = Instant::now();
    while start.elapsed() < limit {
        if cond(&handle.status()) {
            return Some(start.elapsed());
        }
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    None
}

fn is_zero_current(f: &CanFrame) -> bool {
    CurrentCommand::parse(f).is_ok_and(|c| c.raw == [0; 4])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_watchdog_brakes_within_its_period_while_the_bus_floods() {
    let wire = Arc::new(Wire { flood: true, ..Default::default() });
    let (handle, _events) = spawn(FakeBus::new(&wire), base(), options());
    for _ in 0..15 {
        handle.command(Twist::new(0.3, 0.0, 0.0)).await.unwrap_or_else(|e| panic!("{e}"));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let ran = wait_for(&handle, Duration::from_millis(500), |s| s.mode == DriveMode::Run).await;
    assert!(ran.is_some(), "never drove: {:?}", handle.status());
    // The last command, then nothing: the watchdog (200 ms) must brake, flood or not.
    handle.command(Twist::new(0.3, 0.0, 0.0)).await.unwrap_or_else(|e| panic!("{e}"));
    let braked = wait_for(&handle, Duration::from_secs(1), |s| s.mode == DriveMode::Brake && s.watchdog_tripped).await;
    let braked = braked.unwrap_or_else(|| panic!("no brake within 1 s: {:?}", handle.status()));
    // 200 ms, plus one control period to see it and one of scheduling slack.
    assert!(braked <= Duration::from_millis(230), "braked {braked:?} after the last command");
    let summary = handle.stop().await.unwrap_or_else(|e| panic!("{e}"));
    assert!(summary.ticks >= 30, "{summary:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_send_that_never_completes_latches_a_fault_instead_of_hanging_the_loop() {
    let wire = Arc::new(Wire { stall_after: Some(40), ..Default::default() });
    let (handle, mut events) = spawn(FakeBus::new(&wire), base(), options());
    let faulted = wait_for(&handle, Duration::from_secs(2), |s| {
        s.mode == DriveMode::Halt && s.faults.iter().any(|f| matches!(f, Fault::SendTimeout { timeout_ms: 30 }))
    })
    .await;
    assert!(faulted.is_some(), "{:?}", handle.status());
    // The loop goes on ticking (status, watchdog, operator requests) with the transport stuck.
    let stamp = handle.status().stamp;
    tokio::time::sleep(Duration::from_millis(150)).await;
    assert_ne!(handle.status().stamp, stamp, "the loop stopped ticking");
    let mut latched = 0;
    while let Ok(e) = events.try_recv() {
        latched += usize::from(matches!(e, BaseEvent::Fault { fault: Fault::SendTimeout { .. }, .. }));
    }
    assert_eq!(latched, 1, "one fault, its repeats counted");
    // Stopping does not hang either: the halt frames time out, and that is an error.
    let stopped = tokio::time::timeout(Duration::from_secs(1), handle.stop()).await;
    assert!(matches!(stopped, Ok(Err(BaseError::Io { .. }))), "{stopped:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_panic_in_the_loop_still_sends_the_halt_frames() {
    let wire = Arc::new(Wire::default());
    let (handle, _events) = spawn(FakeBus::new(&wire), base(), options());
    for _ in 0..10 {
        handle.command(Twist::new(0.5, 0.0, 0.0)).await.unwrap_or_else(|e| panic!("{e}"));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let driving = FakeBus::sent(&wire).last().is_some_and(|f| !is_zero_current(f));
    assert!(driving, "the base was not commanding current before the panic");
    wire.panic_now.store(true, Ordering::SeqCst);
    let ended = tokio::time::timeout(Duration::from_secs(1), async {
        while !handle.is_finished() {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    })
    .await;
    assert!(ended.is_ok(), "the loop did not panic");
    assert!(wire.sent_after_panic.load(Ordering::SeqCst) >= 1);
    let last = FakeBus::sent(&wire).last().copied();
    assert!(last.is_some_and(|f| is_zero_current(&f)), "last frame {last:?}");
    assert!(handle.stop().await.is_err(), "a panicked loop reports an error");
}

#[test]
fn a_runtime_shut_down_under_the_loop_still_sends_the_halt_frames() {
    let wire = Arc::new(Wire::default());
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap_or_else(|e| panic!("{e}"));
    let handle = runtime.block_on(async {
        let (handle, events) = spawn(FakeBus::new(&wire), base(), options());
        for _ in 0..10 {
            handle.command(Twist::new(0.5, 0.0, 0.0)).await.unwrap_or_else(|e| panic!("{e}"));
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        drop(events);
        handle
    });
    let driving = FakeBus::sent(&wire).last().is_some_and(|f| !is_zero_current(f));
    assert!(driving, "the base was not commanding current");
    let before = FakeBus::sent(&wire).len();
    // As when `main` returns early with an error: the runtime drops the task mid-loop.
    drop(runtime);
    let sent = FakeBus::sent(&wire);
    assert!(sent.len() > before, "nothing sent on the way down");
    assert!(sent.last().is_some_and(is_zero_current), "last frame {:?}", sent.last());
    drop(handle);
}
