//! The two UDP sockets of a PTP port, bound to one interface and joined to 224.0.1.129.

use super::iface::Interface;
use super::timestamping::{self, KernelStamps, TimestampMode};
use crate::error::{PtpError, Result};
use crate::message::{EVENT_PORT, GENERAL_PORT, PTP_PRIMARY_MULTICAST};
use socket2::{Domain, Protocol, Socket, Type};
use std::io;
use std::net::{Ipv4Addr, SocketAddrV4};
use std::os::fd::AsRawFd;
use tokio::io::unix::AsyncFd;
use tokio::io::Interest;

/// Where the sockets listen and send (the standard ports and group unless a test moves them).
#[derive(Clone, Debug)]
pub struct TransportConfig {
    pub iface: String,
    pub want: TimestampMode,
    pub event_port: u16,
    pub general_port: u16,
    pub group: Ipv4Addr,
}

impl TransportConfig {
    pub fn on(iface: &str) -> Self {
        Self {
            iface: iface.to_string(),
            want: TimestampMode::Software,
            event_port: EVENT_PORT,
            general_port: GENERAL_PORT,
            group: PTP_PRIMARY_MULTICAST,
        }
    }
}

fn multicast_socket(iface: &Interface, port: u16, group: Ipv4Addr) -> Result<Socket> {
    let ctx = |what: &str| format!("{what} UDP port {port} on {}", iface.name);
    let s = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).map_err(|e| PtpError::io(ctx("create"), e))?;
    s.set_reuse_address(true).map_err(|e| PtpError::io(ctx("SO_REUSEADDR on"), e))?;
    s.bind_device(Some(iface.name.as_bytes())).map_err(|e| PtpError::io(ctx("SO_BINDTODEVICE"), e))?;
    s.set_multicast_if_v4(&iface.ipv4).map_err(|e| PtpError::io(ctx("IP_MULTICAST_IF"), e))?;
    s.set_multicast_loop_v4(false).map_err(|e| PtpError::io(ctx("IP_MULTICAST_LOOP off"), e))?;
    s.set_multicast_ttl_v4(1).map_err(|e| PtpError::io(ctx("IP_MULTICAST_TTL"), e))?;
    s.join_multicast_v4(&group, &iface.ipv4).map_err(|e| PtpError::io(ctx(&format!("join {group}")), e))?;
    s.set_nonblocking(true).map_err(|e| PtpError::io(ctx("set non-blocking"), e))?;
    s.bind(&SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, port).into()).map_err(|e| PtpError::io(ctx("bind"), e))?;
    Ok(s)
}

/// The event socket (time-stamped) and the general socket.
pub struct PtpSockets {
    pub iface: Interface,
    pub mode: TimestampMode,
    event: AsyncFd<Socket>,
    general: AsyncFd<Socket>,
    event_dest: SocketAddrV4,
    general_dest: SocketAddrV4,
    /// OPT_ID of the next packet sent on the event socket.
    next_tx_id: u32,
}

impl PtpSockets {
    /// Opens both sockets; asks for hardware stamps when wanted and falls back to software
    /// stamps, with a log line saying why, when the NIC cannot.
    pub fn open(cfg: &TransportConfig) -> Result<Self> {
        let iface = Interface::lookup(&cfg.iface)?;
        let event = multicast_socket(&iface, cfg.event_port, cfg.group)?;
        let general = multicast_socket(&iface, cfg.general_port, cfg.group)?;
        let fd = event.as_raw_fd();
        let mut mode = cfg.want;
        if mode == TimestampMode::Hardware {
            let hw = timestamping::enable_hardware_stamping(fd, &iface.name)
                .and_then(|()| timestamping::enable_so_timestamping(fd, TimestampMode::Hardware));
            if let Err(e) = hw {
                tracing::warn!(
                    "{}: hardware timestamps unavailable ({e}); falling back to software timestamps",
                    iface.name
                );
                mode = TimestampMode::Software;
            }
        }
        if mode == TimestampMode::Software {
            timestamping::enable_so_timestamping(fd, mode)
                .map_err(|e| PtpError::io(format!("software timestamps on {}", iface.name), e))?;
        }
        tracing::info!("{}: {} timestamps, {} on {}", iface.name, mode.name(), iface.ipv4, cfg.group);
        let register = |s: Socket, what: &str| {
            // SAFETY: the Socket owns its descriptor and keeps it open, unchanged, until the
            // AsyncFd (which owns the Socket) is dropped.
            unsafe { AsyncFd::register_with_interest(s, Interest::READABLE) }
                .map_err(|e| PtpError::io(format!("register {what}"), e.into_parts().1))
        };
        Ok(Self {
            event: register(event, "event socket")?,
            general: register(general, "general socket")?,
            event_dest: SocketAddrV4::new(cfg.group, cfg.event_port),
            general_dest: SocketAddrV4::new(cfg.group, cfg.general_port),
            next_tx_id: 0,
            iface,
            mode,
        })
    }

    async fn send(fd: &AsyncFd<Socket>, data: &[u8], to: SocketAddrV4) -> io::Result<()> {
        loop {
            match fd.get_ref().send_to(data, &to.into()) {
                Ok(_) => return Ok(()),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    let mut guard = fd.writable().await?;
                    guard.clear_ready();
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Sends on the event port; returns the OPT_ID its transmit stamp will carry.
    pub async fn send_event(&mut self, data: &[u8]) -> io::Result<u32> {
        Self::send(&self.event, data, self.event_dest).await?;
        let id = self.next_tx_id;
        self.next_tx_id = self.next_tx_id.wrapping_add(1);
        Ok(id)
    }

    pub async fn send_general(&self, data: &[u8]) -> io::Result<()> {
        Self::send(&self.general, data, self.general_dest).await
    }

    /// The next event datagram and its kernel receive stamps.
    pub async fn recv_event(&self, buf: &mut [u8]) -> io::Result<(usize, KernelStamps)> {
        loop {
            let mut guard = self.event.readable().await?;
            match guard.try_io(|fd| timestamping::recv_stamped(fd.get_ref().as_raw_fd(), buf)) {
                Ok(r) => return r,
                Err(_would_block) => continue,
            }
        }
    }

    /// The next general datagram.
    pub async fn recv_general(&self, buf: &mut [u8]) -> io::Result<usize> {
        loop {
            let mut guard = self.general.readable().await?;
            match guard.try_io(|fd| fd.get_ref().recv(as_uninit(buf))) {
                Ok(r) => return r,
                Err(_would_block) => continue,
            }
        }
    }

    /// Waits until the error queue has something (or a poll interval passed).
    pub async fn tx_stamp_ready(&self) -> io::Result<()> {
        let mut guard = self.event.ready(Interest::ERROR).await?;
        guard.clear_ready_matching(tokio::io::Ready::ERROR);
        Ok(())
    }

    /// Drains transmit stamps from the error queue without blocking.
    pub fn drain_tx_stamps(&self, out: &mut Vec<(u32, KernelStamps)>) {
        let fd = self.event.get_ref().as_raw_fd();
        for _ in 0..64 {
            match timestamping::recv_tx_stamp(fd) {
                Ok(Some(s)) => out.push(s),
                Ok(None) => {}
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                Err(e) => {
                    tracing::debug!("error queue: {e}");
                    break;
                }
            }
        }
    }
}

/// socket2's recv takes `&mut [MaybeUninit<u8>]`; an initialised buffer is a valid one.
fn as_uninit(buf: &mut [u8]) -> &mut [std::mem::MaybeUninit<u8>] {
    // SAFETY: u8 and MaybeUninit<u8> have the same layout, and recv only writes bytes.
    unsafe { &mut *(buf as *mut [u8] as *mut [std::mem::MaybeUninit<u8>]) }
}
