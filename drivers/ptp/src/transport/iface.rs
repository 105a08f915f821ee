//! What we need to know about a network interface: index, IPv4 address, MAC.

use crate::error::{PtpError, Result};
use crate::message::ClockIdentity;
use std::ffi::{CStr, CString};
use std::net::Ipv4Addr;

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Interface {
    pub name: String,
    pub index: u32,
    pub ipv4: Ipv4Addr,
    pub mac: Option<[u8; 6]>,
}

impl Interface {
    /// Looks `name` up with getifaddrs; it must exist and carry an IPv4 address.
    pub fn lookup(name: &str) -> Result<Self> {
        let err = |reason: String| PtpError::Interface { iface: name.to_string(), reason };
        let cname = CString::new(name).map_err(|_| err("name contains NUL".into()))?;
        // SAFETY: if_nametoindex reads a NUL-terminated string.
        let index = unsafe { libc::if_nametoindex(cname.as_ptr()) };
        if index == 0 {
            return Err(err(format!("no such interface ({})", std::io::Error::last_os_error())));
        }
        let mut ipv4 = None;
        let mut mac = None;
        let mut head: *mut libc::ifaddrs = std::ptr::null_mut();
        // SAFETY: getifaddrs fills `head` with a list we free below with freeifaddrs.
        if unsafe { libc::getifaddrs(&mut head) } != 0 {
            return Err(PtpError::io("getifaddrs", std::io::Error::last_os_error()));
        }
        let mut cur = head;
        while !cur.is_null() {
            // SAFETY: `cur` is a node of the list getifaddrs returned, still alive.
            let ifa = unsafe { &*cur };
            cur = ifa.ifa_next;
            if ifa.ifa_name.is_null() || ifa.ifa_addr.is_null() {
                continue;
            }
            // SAFETY: ifa_name is a NUL-terminated string owned by the list.
            if unsafe { CStr::from_ptr(ifa.ifa_name) }.to_bytes() != name.as_bytes() {
                continue;
            }
            // SAFETY: ifa_addr is non-null; sa_family says which sockaddr it is.
            let family = unsafe { (*ifa.ifa_addr).sa_family } as i32;
            if family == libc::AF_INET && ipv4.is_none() {
                // SAFETY: AF_INET addresses are sockaddr_in.
                let sin = unsafe { &*(ifa.ifa_addr as *const libc::sockaddr_in) };
                ipv4 = Some(Ipv4Addr::from(u32::from_be(sin.sin_addr.s_addr)));
            } else if family == libc::AF_PACKET {
                // SAFETY: AF_PACKET addresses are sockaddr_ll.
                let sll = unsafe { &*(ifa.ifa_addr as *const libc::sockaddr_ll) };
                if sll.sll_halen == 6 {
                    let a = sll.sll_addr;
                    mac = Some([a[0], a[1], a[2], a[3], a[4], a[5]]);
                }
            }
        }
        // SAFETY: `head` came from getifaddrs and is freed once.
        unsafe { libc::freeifaddrs(head) };
        let ipv4 = ipv4.ok_or_else(|| err("has no IPv4 address".into()))?;
        Ok(Self { name: name.to_string(), index, ipv4, mac })
    }

    /// The clock identity ptp4l would derive: the MAC as EUI-64, or one built from the IPv4
    /// address when the interface has no MAC.
    pub fn clock_identity(&self) -> ClockIdentity {
        match self.mac {
            Some(mac) => ClockIdentity::from_mac(mac),
            None => {
                let [a, b, c, d] = self.ipv4.octets();
                ClockIdentity([0x02, 0x00, a, 0xff, 0xfe, b, c, d])
            }
        }
    }
}
