//! Kernel timestamps: SO_TIMESTAMPING on the event socket, receive stamps from the control
//! messages of recvmsg, transmit stamps from the socket's error queue (MSG_ERRQUEUE), matched to
//! the packet by the kernel's per-socket counter (SOF_TIMESTAMPING_OPT_ID), and the SIOCSHWTSTAMP
//! request that turns on a NIC's hardware stamping.

use std::io;
use std::mem::{size_of, zeroed};
use std::os::fd::RawFd;

/// Where timestamps come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimestampMode {
    /// Taken by the kernel in the network stack (CLOCK_REALTIME): a few microseconds of jitter.
    Software,
    /// Taken by the NIC (its PTP hardware clock): tens of nanoseconds.
    Hardware,
}

impl TimestampMode {
    pub fn name(self) -> &'static str {
        match self {
            Self::Software => "software",
            Self::Hardware => "hardware",
        }
    }
}

fn check(ret: libc::c_int, what: &str) -> io::Result<()> {
    if ret < 0 {
        let e = io::Error::last_os_error();
        return Err(io::Error::new(e.kind(), format!("{what}: {e}")));
    }
    Ok(())
}

/// Turns on kernel timestamping of sent and received packets for `fd`.
pub fn enable_so_timestamping(fd: RawFd, mode: TimestampMode) -> io::Result<()> {
    let source = match mode {
        TimestampMode::Software => {
            libc::SOF_TIMESTAMPING_RX_SOFTWARE | libc::SOF_TIMESTAMPING_TX_SOFTWARE | libc::SOF_TIMESTAMPING_SOFTWARE
        }
        TimestampMode::Hardware => {
            libc::SOF_TIMESTAMPING_RX_HARDWARE
                | libc::SOF_TIMESTAMPING_TX_HARDWARE
                | libc::SOF_TIMESTAMPING_RAW_HARDWARE
        }
    };
    // OPT_ID numbers each sent packet; OPT_TSONLY returns only the stamp, not the packet.
    let flags: libc::c_uint = source | libc::SOF_TIMESTAMPING_OPT_ID | libc::SOF_TIMESTAMPING_OPT_TSONLY;
    // SAFETY: setsockopt reads `size_of::<c_uint>()` bytes from a live local.
    let ret = unsafe {
        libc::setsockopt(
            fd,
            libc::SOL_SOCKET,
            libc::SO_TIMESTAMPING,
            (&flags as *const libc::c_uint).cast(),
            size_of::<libc::c_uint>() as libc::socklen_t,
        )
    };
    check(ret, "setsockopt SO_TIMESTAMPING")
}

/// Asks the NIC behind `iface` to stamp PTPv2 UDP event packets in hardware (SIOCSHWTSTAMP).
/// Fails on NICs without a PTP hardware clock (veth, most USB adapters).
pub fn enable_hardware_stamping(fd: RawFd, iface: &str) -> io::Result<()> {
    let mut config = libc::hwtstamp_config {
        flags: 0,
        tx_type: libc::HWTSTAMP_TX_ON as libc::c_int,
        rx_filter: libc::HWTSTAMP_FILTER_PTP_V2_L4_EVENT as libc::c_int,
    };
    // SAFETY: ifreq is plain data; zeroed is a valid value.
    let mut req: libc::ifreq = unsafe { zeroed() };
    let name = iface.as_bytes();
    if name.len() >= req.ifr_name.len() {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, format!("interface name {iface} too long")));
    }
    for (dst, &src) in req.ifr_name.iter_mut().zip(name) {
        *dst = src as libc::c_char;
    }
    req.ifr_ifru.ifru_data = (&mut config as *mut libc::hwtstamp_config).cast();
    // SAFETY: SIOCSHWTSTAMP reads the ifreq and the hwtstamp_config it points to, both alive.
    let ret = unsafe { libc::ioctl(fd, libc::SIOCSHWTSTAMP as _, &mut req as *mut libc::ifreq) };
    check(ret, "ioctl SIOCSHWTSTAMP")?;
    // Drivers may upgrade the filter (e.g. to ALL); anything but NONE stamps our packets.
    if config.rx_filter == libc::HWTSTAMP_FILTER_NONE as libc::c_int {
        return Err(io::Error::new(io::ErrorKind::Unsupported, "the NIC refused to stamp received PTP packets"));
    }
    Ok(())
}

/// The stamps a control message carried.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KernelStamps {
    pub software_ns: Option<u64>,
    pub hardware_ns: Option<u64>,
}

impl KernelStamps {
    pub fn get(&self, mode: TimestampMode) -> Option<u64> {
        match mode {
            TimestampMode::Software => self.software_ns,
            TimestampMode::Hardware => self.hardware_ns,
        }
    }
}

fn timespec_ns(ts: &libc::timespec) -> Option<u64> {
    if ts.tv_sec == 0 && ts.tv_nsec == 0 {
        return None;
    }
    let s = u64::try_from(ts.tv_sec).ok()?;
    let n = u64::try_from(ts.tv_nsec).ok()?;
    s.checked_mul(1_000_000_000)?.checked_add(n)
}

/// Control-message buffer, aligned for cmsghdr.
#[repr(C, align(8))]
struct CmsgBuf([u8; 512]);

/// Walks the control messages of `msg`; calls `f(level, type, data)` for each.
fn for_each_cmsg(msg: &libc::msghdr, mut f: impl FnMut(libc::c_int, libc::c_int, &[u8])) {
    // SAFETY: the CMSG_* macros walk the control buffer the kernel filled, bounded by
    // msg_controllen; each data slice is bounded by its cmsg_len.
    unsafe {
        let mut cmsg = libc::CMSG_FIRSTHDR(msg);
        while !cmsg.is_null() {
            let header = &*cmsg;
            let data = libc::CMSG_DATA(cmsg);
            let header_len = data.offset_from(cmsg as *const u8) as usize;
            let len = (header.cmsg_len as usize).saturating_sub(header_len);
            f(header.cmsg_level, header.cmsg_type, std::slice::from_raw_parts(data, len));
            cmsg = libc::CMSG_NXTHDR(msg, cmsg);
        }
    }
}

fn parse_scm_timestamping(data: &[u8]) -> KernelStamps {
    let each = size_of::<libc::timespec>();
    if data.len() < 3 * each {
        return KernelStamps::default();
    }
    // SAFETY: `data` holds three timespecs (checked above); read_unaligned copes with alignment.
    let ts: [libc::timespec; 3] = unsafe { std::ptr::read_unaligned(data.as_ptr().cast()) };
    KernelStamps { software_ns: timespec_ns(&ts[0]), hardware_ns: timespec_ns(&ts[2]) }
}

/// recvmsg without blocking: the datagram's length and its receive stamps.
pub fn recv_stamped(fd: RawFd, buf: &mut [u8]) -> io::Result<(usize, KernelStamps)> {
    let mut iov = libc::iovec { iov_base: buf.as_mut_ptr().cast(), iov_len: buf.len() };
    let mut control = CmsgBuf([0; 512]);
    // SAFETY: msghdr is plain data; zeroed is valid; the pointers set below outlive the call.
    let mut msg: libc::msghdr = unsafe { zeroed() };
    msg.msg_iov = &mut iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control.0.as_mut_ptr().cast();
    msg.msg_controllen = control.0.len() as _;
    // SAFETY: recvmsg writes at most iov_len bytes to buf and msg_controllen to control.
    let n = unsafe { libc::recvmsg(fd, &mut msg, libc::MSG_DONTWAIT) };
    if n < 0 {
        return Err(io::Error::last_os_error());
    }
    let mut stamps = KernelStamps::default();
    for_each_cmsg(&msg, |level, kind, data| {
        if level == libc::SOL_SOCKET && kind == libc::SCM_TIMESTAMPING {
            stamps = parse_scm_timestamping(data);
        }
    });
    Ok((n as usize, stamps))
}

/// One transmit stamp from the error queue: the OPT_ID counter of the packet and its stamps.
pub fn recv_tx_stamp(fd: RawFd) -> io::Result<Option<(u32, KernelStamps)>> {
    let mut scratch = [0u8; 256];
    let mut iov = libc::iovec { iov_base: scratch.as_mut_ptr().cast(), iov_len: scratch.len() };
    let mut control = CmsgBuf([0; 512]);
    // SAFETY: as in recv_stamped.
    let mut msg: libc::msghdr = unsafe { zeroed() };
    msg.msg_iov = &mut iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control.0.as_mut_ptr().cast();
    msg.msg_controllen = control.0.len() as _;
    // SAFETY: as in recv_stamped.
    let n = unsafe { libc::recvmsg(fd, &mut msg, libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT) };
    if n < 0 {
        return Err(io::Error::last_os_error());
    }
    let mut stamps = KernelStamps::default();
    let mut id = None;
    for_each_cmsg(&msg, |level, kind, data| {
        if level == libc::SOL_SOCKET && kind == libc::SCM_TIMESTAMPING {
            stamps = parse_scm_timestamping(data);
        } else if level == libc::SOL_IP
            && kind == libc::IP_RECVERR
            && data.len() >= size_of::<libc::sock_extended_err>()
        {
            // SAFETY: length checked; read_unaligned copes with alignment.
            let ee: libc::sock_extended_err = unsafe { std::ptr::read_unaligned(data.as_ptr().cast()) };
            if ee.ee_errno == libc::ENOMSG as u32 && ee.ee_origin == libc::SO_EE_ORIGIN_TIMESTAMPING {
                id = Some(ee.ee_data);
            }
        }
    });
    Ok(id.map(|id| (id, stamps)))
}

/// CLOCK_REALTIME now, in ns.
pub fn realtime_ns() -> u64 {
    starc_time::Stamp::host_now().ns
}
