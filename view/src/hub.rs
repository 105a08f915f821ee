//! The latest AR frame, shared by every live view.
//!
//! The renderer calls [`ViewHub::publish`] once per frame; the frame is stored with its status in
//! a `tokio::sync::watch` slot. Viewers read the newest snapshot when they are ready for one: a
//! slow browser or display skips frames and never holds up the renderer (publishing is a slot
//! swap, never a wait on a viewer). The PNG is encoded once per frame by the first viewer that
//! asks for it, so the renderer pays nothing for frames nobody watches.

use super::error::ViewError;
use serde::{Deserialize, Serialize};
use starc_pipeline::ar::ArFrame;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use tokio::sync::watch;

/// What the status line of every view shows, and `/status.json` serves.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ViewStatus {
    /// Whether the responder is aligned to the robot's map (people are drawn only then).
    pub aligned: bool,
    /// Age of the newest detection at render time, if there is one.
    pub detection_age_ms: Option<f64>,
    /// Link state to the robot as the node shows it ("OK", "LOST 2.1 S").
    pub link: String,
    /// People drawn in this frame.
    pub people: usize,
    /// The renderer's frame counter.
    pub frame_seq: u64,
    /// When the frame was rendered (ns on the node's clock, PTP on the rig).
    pub stamp_ns: u64,
}

/// One published frame: the raw image (for the framebuffer), its PNG on demand (for the
/// browser, PNG files and Foxglove) and its status.
#[derive(Debug)]
pub struct ViewSnapshot {
    pub frame: ArFrame,
    pub status: ViewStatus,
    png: OnceLock<Arc<[u8]>>,
}

impl ViewSnapshot {
    fn new(frame: ArFrame, status: ViewStatus) -> Self {
        Self { frame, status, png: OnceLock::new() }
    }

    /// The frame as PNG, encoded by the first caller (the frame was checked at publish, so an
    /// error here is the encoder's own).
    pub fn png(&self) -> Result<Arc<[u8]>, ViewError> {
        if let Some(png) = self.png.get() {
            return Ok(png.clone());
        }
        let png: Arc<[u8]> = self.frame.to_png()?.into();
        // Two viewers may race to encode the same frame; either result is the same bytes.
        Ok(self.png.get_or_init(|| png).clone())
    }
}

/// The slot viewers watch: `None` until the first frame.
pub type SnapshotReceiver = watch::Receiver<Option<Arc<ViewSnapshot>>>;

/// Cheap to clone; every clone publishes into (and watches) the same slot.
#[derive(Clone)]
pub struct ViewHub {
    tx: Arc<watch::Sender<Option<Arc<ViewSnapshot>>>>,
    published: Arc<AtomicU64>,
}

impl Default for ViewHub {
    fn default() -> Self {
        Self::new()
    }
}

impl ViewHub {
    pub fn new() -> Self {
        let (tx, _) = watch::channel(None);
        Self { tx: Arc::new(tx), published: Arc::new(AtomicU64::new(0)) }
    }

    /// Makes `frame` (with `status`) the latest snapshot. A frame whose buffer does not match
    /// its size is refused, so viewers can index it without checks failing.
    pub fn publish(&self, frame: &ArFrame, status: ViewStatus) -> Result<Arc<ViewSnapshot>, ViewError> {
        check_frame(frame)?;
        let snapshot = Arc::new(ViewSnapshot::new(frame.clone(), status));
        // send_replace stores the value even while nobody watches: a viewer that connects
        // later still gets the latest frame.
        self.tx.send_replace(Some(snapshot.clone()));
        self.published.fetch_add(1, Ordering::Relaxed);
        Ok(snapshot)
    }

    /// The newest snapshot, if any frame was published.
    pub fn latest(&self) -> Option<Arc<ViewSnapshot>> {
        self.tx.borrow().clone()
    }

    /// A receiver that wakes on every publish (coalescing frames the viewer was too slow for).
    pub fn subscribe(&self) -> SnapshotReceiver {
        self.tx.subscribe()
    }

    /// Frames published so far.
    pub fn published(&self) -> u64 {
        self.published.load(Ordering::Relaxed)
    }
}

/// `width * height * 3 == rgb.len()`, without overflow.
pub fn check_frame(frame: &ArFrame) -> Result<(), ViewError> {
    let expected = (frame.width as usize).checked_mul(frame.height as usize).and_then(|n| n.checked_mul(3));
    match expected {
        Some(n) if n == frame.rgb.len() && n > 0 => Ok(()),
        _ => Err(ViewError::BadFrame {
            width: frame.width,
            height: frame.height,
            bytes: frame.rgb.len(),
            expected: expected.unwrap_or(usize::MAX),
        }),
    }
}

/// Hands each new snapshot to a blocking sink (a display device, a disk) off the async threads
/// until shutdown; frames that arrive while it writes are skipped. One warning per run of
/// failures, not one per frame (a full disk would otherwise log at frame rate).
pub fn follow_blocking<S, W>(
    what: &'static str,
    sink: S,
    write: W,
    mut frames: SnapshotReceiver,
    mut shutdown: super::Shutdown,
) -> tokio::task::JoinHandle<()>
where
    S: Send + 'static,
    W: Fn(&mut S, &ViewSnapshot) -> Result<(), ViewError> + Copy + Send + 'static,
{
    tokio::spawn(async move {
        let mut sink = Some(sink);
        let mut failing = false;
        loop {
            tokio::select! {
                _ = super::wait_shutdown(&mut shutdown) => return,
                changed = frames.changed() => if changed.is_err() { return },
            }
            let Some(snapshot) = frames.borrow_and_update().clone() else { continue };
            let Some(mut s) = sink.take() else { return };
            let Ok((s, result)) = tokio::task::spawn_blocking(move || {
                let r = write(&mut s, &snapshot);
                (s, r)
            })
            .await
            else {
                return;
            };
            sink = Some(s);
            match result {
                Err(e) if !failing => {
                    tracing::warn!("{what}: {e}");
                    failing = true;
                }
                Ok(()) => failing = false,
                Err(_) => {}
            }
        }
    })
}
