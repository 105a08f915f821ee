//! A pseudo-terminal pair for a mock serial device: the mock keeps the master, clients open the
//! slave through a stable symlink, as they would open /dev/ttyACM0.

use crate::error::{HilError, Result};
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::openpty;
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use tokio::io::unix::AsyncFd;

fn io_err(context: impl Into<String>, e: nix::Error) -> HilError {
    HilError::Io { context: context.into(), source: std::io::Error::from(e) }
}

/// The master side, non-blocking under tokio, with the slave linked at `link`.
pub struct PtyDevice {
    master: AsyncFd<File>,
    /// Held open so that the master never sees a hang-up between clients.
    _slave: OwnedFd,
    slave_path: PathBuf,
    link: PathBuf,
}

impl PtyDevice {
    /// Opens a pty pair in raw mode and points `link` (replacing a symlink there) at the slave.
    pub fn open(link: &Path) -> Result<Self> {
        let pair = openpty(None, None).map_err(|e| io_err("openpty", e))?;
        let mut t = tcgetattr(&pair.slave).map_err(|e| io_err("tcgetattr", e))?;
        cfmakeraw(&mut t);
        tcsetattr(&pair.slave, SetArg::TCSANOW, &t).map_err(|e| io_err("tcsetattr", e))?;
        let slave_path = nix::unistd::ttyname(&pair.slave).map_err(|e| io_err("ttyname", e))?;
        fcntl(pair.master.as_raw_fd(), FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).map_err(|e| io_err("O_NONBLOCK", e))?;
        let io = |context: String| move |source| HilError::Io { context, source };
        match std::fs::symlink_metadata(link) {
            Ok(m) if m.file_type().is_symlink() => {
                std::fs::remove_file(link).map_err(io(format!("removing {}", link.display())))?
            }
            Ok(_) => return Err(HilError::config("port", format!("{} exists and is not a symlink", link.display()))),
            Err(_) => {}
        }
        std::os::unix::fs::symlink(&slave_path, link).map_err(io(format!(
            "linking {} -> {}",
            link.display(),
            slave_path.display()
        )))?;
        // `AsyncFd::new` is deprecated because a type may hand out a different fd later; a
        // `File` owns its one fd for life, which is the case the replacement's safety
        // contract asks for.
        #[allow(deprecated)]
        let master = AsyncFd::new(File::from(pair.master)).map_err(io("registering the pty".into()))?;
        Ok(Self { master, _slave: pair.slave, slave_path, link: link.to_path_buf() })
    }

    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    pub fn link(&self) -> &Path {
        &self.link
    }

    /// Waits for bytes from the client.
    pub async fn read(&self, buf: &mut [u8]) -> Result<usize> {
        loop {
            let mut guard =
                self.master.readable().await.map_err(|source| HilError::Io { context: "pty".into(), source })?;
            match guard.try_io(|inner| inner.get_ref().read(buf)) {
                Ok(Ok(n)) => return Ok(n),
                // EIO: no client has the slave open right now (we hold it, so rarely seen).
                Ok(Err(e)) if e.raw_os_error() == Some(nix::libc::EIO) => {
                    tokio::time::sleep(std::time::Duration::from_millis(5)).await;
                }
                Ok(Err(e)) => return Err(HilError::Io { context: "reading the pty".into(), source: e }),
                Err(_would_block) => continue,
            }
        }
    }

    /// Writes what fits without blocking; returns the bytes that did not fit (a client that
    /// does not read loses them, as with a full USB buffer).
    pub fn write_now(&self, bytes: &[u8]) -> usize {
        let mut rest = bytes;
        while !rest.is_empty() {
            match self.master.get_ref().write(rest) {
                Ok(0) => break,
                Ok(n) => rest = rest.get(n..).unwrap_or(&[]),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(_) => break,
            }
        }
        rest.len()
    }
}

impl Drop for PtyDevice {
    fn drop(&mut self) {
        // Only our own link: a later mock may have replaced it.
        if std::fs::read_link(&self.link).is_ok_and(|target| target == self.slave_path) {
            let _ = std::fs::remove_file(&self.link);
        }
    }
}
