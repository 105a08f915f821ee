//! Work the node can wait for without it holding up the live path: the rig's registrations
//! (tens to hundreds of milliseconds each) run on their own thread at a lower CPU priority, so
//! the LiDAR feed, the LIO and the frames go first when the cores are busy.

use tokio::sync::oneshot;

/// How much lower than the node the background thread runs (nice steps, 0-19).
const NICE_STEPS: i32 = 10;

/// Runs `work` on a new thread at lower priority; its result arrives on the receiver (closed
/// without a value if the thread could not be started or `work` panicked).
pub fn spawn_low_priority<T: Send + 'static>(
    name: &str,
    work: impl FnOnce() -> T + Send + 'static,
) -> oneshot::Receiver<T> {
    let (tx, rx) = oneshot::channel();
    let spawned = std::thread::Builder::new().name(name.into()).spawn(move || {
        lower_this_thread(NICE_STEPS);
        let _ = tx.send(work());
    });
    if let Err(e) = spawned {
        tracing::warn!("background thread {name} not started: {e}");
    }
    rx
}

/// Sets the calling thread's nice value (0-19; higher runs later when the cores are busy).
/// Threads it starts afterwards inherit it. Failing to is logged, not an error: the work still runs.
pub fn lower_this_thread(nice: i32) {
    // SAFETY: gettid and setpriority take and return plain integers and touch no memory of ours.
    // On Linux the nice value belongs to the thread (the id gettid returns), not the process.
    let rc = unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, nice)
    };
    if rc != 0 {
        tracing::debug!("could not lower the thread's priority: {}", std::io::Error::last_os_error());
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn result_arrives_and_the_thread_runs_lower() {
        let rx = spawn_low_priority("test-bg", || {
            // SAFETY: as above; getpriority only reads.
            unsafe {
                *libc::__errno_location() = 0;
                libc::getpriority(libc::PRIO_PROCESS, libc::syscall(libc::SYS_gettid) as libc::id_t)
            }
        });
        let nice = rx.await.unwrap();
        // SAFETY: as above.
        let own = unsafe { libc::getpriority(libc::PRIO_PROCESS, libc::syscall(libc::SYS_gettid) as libc::id_t) };
        assert_eq!(nice, (own + NICE_STEPS).min(19));
    }

    #[tokio::test]
    async fn a_panicking_job_closes_the_channel() {
        let rx = spawn_low_priority("test-bg-panic", || -> u32 { panic!("boom") });
        assert!(rx.await.is_err());
    }
}
