//! UDP sockets set up the way a LiDAR host needs them.

use crate::error::{LivoxError, Result};
use socket2::{Domain, Protocol, Socket, Type};
use std::net::SocketAddrV4;

/// Binds a non-blocking UDP socket for tokio. `reuse` lets several programs listen for
/// broadcasts on one port; the large receive buffer rides out scheduling hiccups at 3.4 MB/s.
pub fn bind_udp(addr: SocketAddrV4, reuse: bool, broadcast: bool) -> Result<tokio::net::UdpSocket> {
    let ctx = |what: &str| format!("{what} UDP {addr}");
    let socket =
        Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).map_err(|e| LivoxError::io(ctx("create"), e))?;
    if reuse {
        socket.set_reuse_address(true).map_err(|e| LivoxError::io(ctx("SO_REUSEADDR on"), e))?;
    }
    if broadcast {
        socket.set_broadcast(true).map_err(|e| LivoxError::io(ctx("SO_BROADCAST on"), e))?;
    }
    // Best effort: the kernel caps it at net.core.rmem_max.
    let _ = socket.set_recv_buffer_size(8 << 20);
    socket.set_nonblocking(true).map_err(|e| LivoxError::io(ctx("set non-blocking"), e))?;
    socket.bind(&addr.into()).map_err(|e| LivoxError::io(ctx("bind"), e))?;
    tokio::net::UdpSocket::from_std(socket.into()).map_err(|e| LivoxError::io(ctx("register"), e))
}

/// The IPv4 address and port a bound socket got (port 0 binds pick one).
pub fn local_v4(socket: &tokio::net::UdpSocket) -> Result<SocketAddrV4> {
    match socket.local_addr().map_err(|e| LivoxError::io("local address", e))? {
        std::net::SocketAddr::V4(a) => Ok(a),
        std::net::SocketAddr::V6(a) => Err(LivoxError::io(
            "local address",
            std::io::Error::new(std::io::ErrorKind::Unsupported, format!("IPv6 address {a}")),
        )),
    }
}
