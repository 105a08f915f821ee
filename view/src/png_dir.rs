//! PNG files of the frames, for the record and for viewers that just watch a directory.

use super::error::ViewError;
use super::hub::{SnapshotReceiver, ViewSnapshot};
use super::Shutdown;
use std::path::{Path, PathBuf};
use tokio::task::JoinHandle;

/// Writes `ar_<frame_seq>.png` for frames whose `frame_seq` is a multiple of `every`.
pub struct PngDir {
    dir: PathBuf,
    every: u32,
}

impl PngDir {
    /// Creates `dir` if needed.
    pub fn create(dir: &Path, every: u32) -> Result<Self, ViewError> {
        if every == 0 {
            return Err(ViewError::Config("png_every must be at least 1".into()));
        }
        std::fs::create_dir_all(dir).map_err(|e| ViewError::io(format!("creating {}", dir.display()), e))?;
        Ok(Self { dir: dir.to_path_buf(), every })
    }

    /// Writes the snapshot's PNG if its turn has come; returns the file written. The file
    /// appears whole (written under a temporary name, then renamed).
    pub fn write(&mut self, snapshot: &ViewSnapshot) -> Result<Option<PathBuf>, ViewError> {
        if !snapshot.status.frame_seq.is_multiple_of(u64::from(self.every)) {
            return Ok(None);
        }
        let path = self.dir.join(format!("ar_{:08}.png", snapshot.status.frame_seq));
        let tmp = self.dir.join(format!(".ar_{:08}.png.tmp", snapshot.status.frame_seq));
        std::fs::write(&tmp, snapshot.png()?).map_err(|e| ViewError::io(format!("writing {}", tmp.display()), e))?;
        std::fs::rename(&tmp, &path).map_err(|e| ViewError::io(format!("renaming to {}", path.display()), e))?;
        Ok(Some(path))
    }
}

/// Writes frames from `frames` until shutdown (blocking file I/O off the async threads).
pub fn follow(writer: PngDir, frames: SnapshotReceiver, shutdown: Shutdown) -> JoinHandle<()> {
    super::hub::follow_blocking("PNG frames", writer, |w, s| w.write(s).map(|_| ()), frames, shutdown)
}
