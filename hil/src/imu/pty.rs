//! A pseudo-terminal pair for a mock serial device: the mock holds the master side, a host
//! program opens the slave (`/dev/pts/N`, or a symlink to it) as if it were `/dev/ttyUSB0`.

use crate::error::{HilError, Result};
use std::path::{Path, PathBuf};
use tokio_serial::{SerialPort, SerialStream};

/// A pty's slave side and link; [`Pty::open`] also hands out the master. The slave stays open here so that the master never sees a hang-up while
/// no host program has the port open (bytes written meanwhile wait in the tty's buffer).
pub struct Pty {
    _slave: SerialStream,
    tty: PathBuf,
    link: Option<PathBuf>,
}

fn io(context: impl Into<String>, e: impl std::fmt::Display) -> HilError {
    HilError::Io { context: context.into(), source: std::io::Error::other(e.to_string()) }
}

impl Pty {
    /// Opens a raw (no echo, no line editing) pty pair and returns it with its master side; with `link`, a symlink at that path
    /// points to the slave (an existing symlink there is replaced; any other file is an error).
    /// Must be called inside a tokio runtime.
    pub fn open(link: Option<&Path>) -> Result<(Self, SerialStream)> {
        // The slave is opened without TIOCEXCL or flock: a host program may open it exclusively
        // (tokio-serial does by default). Its `set_exclusive(false)` would take a shared flock
        // and lock such a host out.
        let (master, slave) = SerialStream::pair().map_err(|e| io("opening a pty pair", e))?;
        let tty = PathBuf::from(slave.name().ok_or_else(|| io("pty slave", "no name"))?);
        let link = match link {
            Some(path) => {
                if std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) {
                    std::fs::remove_file(path)
                        .map_err(|e| io(format!("removing the old link {}", path.display()), e))?;
                }
                std::os::unix::fs::symlink(&tty, path)
                    .map_err(|e| io(format!("linking {} to {}", path.display(), tty.display()), e))?;
                Some(path.to_path_buf())
            }
            None => None,
        };
        Ok((Self { _slave: slave, tty, link }, master))
    }

    /// The slave's device path.
    pub fn tty(&self) -> &Path {
        &self.tty
    }

    /// Where host programs open the port: the link if any, else the slave's path.
    pub fn port(&self) -> &Path {
        self.link.as_deref().unwrap_or(&self.tty)
    }
}

impl Drop for Pty {
    fn drop(&mut self) {
        if let Some(link) = &self.link {
            // Only our own link: it must still point at our slave.
            if std::fs::read_link(link).is_ok_and(|t| t == self.tty) {
                let _ = std::fs::remove_file(link);
            }
        }
    }
}
