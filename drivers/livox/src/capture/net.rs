//! Link layer to IPv4 to UDP, and back (for the pcap writer).
//!
//! Decoding never fails the capture: a frame that is not a complete, unfragmented UDP/IPv4 datagram
//! is skipped with a [`Skip`] reason the reader counts.

use std::net::{Ipv4Addr, SocketAddrV4};

/// LINKTYPE_NULL: BSD loopback, 4-byte address family in the capturing host's byte order.
pub const LINKTYPE_NULL: u16 = 0;
pub const LINKTYPE_ETHERNET: u16 = 1;
/// LINKTYPE_RAW: a raw IPv4 or IPv6 packet.
pub const LINKTYPE_RAW: u16 = 101;
/// LINKTYPE_LOOP: OpenBSD loopback, address family in network byte order.
pub const LINKTYPE_LOOP: u16 = 108;
/// LINKTYPE_LINUX_SLL: Linux "cooked" capture, version 1 (16-byte header).
pub const LINKTYPE_LINUX_SLL: u16 = 113;
/// LINKTYPE_IPV4: a raw IPv4 packet.
pub const LINKTYPE_IPV4: u16 = 228;
/// LINKTYPE_LINUX_SLL2: Linux "cooked" capture, version 2 (20-byte header).
pub const LINKTYPE_LINUX_SLL2: u16 = 276;

pub const ETHERTYPE_IPV4: u16 = 0x0800;
pub const ETHERTYPE_VLAN: u16 = 0x8100;
pub const ETHERTYPE_QINQ: u16 = 0x88A8;
/// Pre-standard double tagging, still seen on some switches.
pub const ETHERTYPE_QINQ_OLD: u16 = 0x9100;
pub const IPPROTO_UDP: u8 = 17;
pub const ETHERNET_HEADER_LEN: usize = 14;
pub const IPV4_HEADER_LEN: usize = 20;
pub const UDP_HEADER_LEN: usize = 8;
/// Largest UDP payload in one IPv4 datagram.
pub const MAX_UDP_PAYLOAD: usize = 65_535 - IPV4_HEADER_LEN - UDP_HEADER_LEN;

/// Whether a link type is one [`decode_link`] understands.
pub fn is_supported_link(link_type: u16) -> bool {
    matches!(
        link_type,
        LINKTYPE_NULL
            | LINKTYPE_ETHERNET
            | LINKTYPE_RAW
            | LINKTYPE_LOOP
            | LINKTYPE_LINUX_SLL
            | LINKTYPE_IPV4
            | LINKTYPE_LINUX_SLL2
    )
}

/// Why a frame yields no datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Skip {
    /// Not UDP over IPv4.
    NotUdp,
    /// An IPv4 fragment (more-fragments set or non-zero offset).
    Fragment,
    /// Headers promise more bytes than the frame holds.
    Short,
    /// Inconsistent header fields (IHL below 5, UDP length below 8 or beyond the IP packet).
    Malformed,
    UnsupportedLink,
}

/// A UDP datagram found in a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Udp<'a> {
    pub src: SocketAddrV4,
    pub dst: SocketAddrV4,
    pub payload: &'a [u8],
}

#[inline]
fn be16(b: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_be_bytes([*b.get(i)?, *b.get(i + 1)?]))
}

/// Finds the UDP datagram in one captured frame.
pub fn decode_link(link_type: u16, frame: &[u8]) -> Result<Udp<'_>, Skip> {
    match link_type {
        LINKTYPE_ETHERNET => {
            let ethertype = be16(frame, 12).ok_or(Skip::Short)?;
            after_ethertype(ethertype, frame.get(ETHERNET_HEADER_LEN..).ok_or(Skip::Short)?)
        }
        LINKTYPE_LINUX_SLL => {
            let protocol = be16(frame, 14).ok_or(Skip::Short)?;
            after_ethertype(protocol, frame.get(16..).ok_or(Skip::Short)?)
        }
        LINKTYPE_LINUX_SLL2 => {
            let protocol = be16(frame, 0).ok_or(Skip::Short)?;
            after_ethertype(protocol, frame.get(20..).ok_or(Skip::Short)?)
        }
        LINKTYPE_RAW | LINKTYPE_IPV4 => ipv4(frame),
        LINKTYPE_NULL | LINKTYPE_LOOP => {
            let family = frame.get(..4).ok_or(Skip::Short)?;
            // AF_INET is 2 on every system; NULL stores it in the writer's byte order.
            let le = u32::from_le_bytes([family[0], family[1], family[2], family[3]]);
            let be = u32::from_be_bytes([family[0], family[1], family[2], family[3]]);
            let inet = if link_type == LINKTYPE_LOOP { be == 2 } else { le == 2 || be == 2 };
            if inet {
                ipv4(frame.get(4..).ok_or(Skip::Short)?)
            } else {
                Err(Skip::NotUdp)
            }
        }
        _ => Err(Skip::UnsupportedLink),
    }
}

/// Follows 802.1Q / 802.1ad tags to the network layer.
fn after_ethertype(mut ethertype: u16, mut rest: &[u8]) -> Result<Udp<'_>, Skip> {
    while matches!(ethertype, ETHERTYPE_VLAN | ETHERTYPE_QINQ | ETHERTYPE_QINQ_OLD) {
        // Tag control information (2 bytes), then the next ethertype.
        ethertype = be16(rest, 2).ok_or(Skip::Short)?;
        rest = rest.get(4..).ok_or(Skip::Short)?;
    }
    if ethertype == ETHERTYPE_IPV4 {
        ipv4(rest)
    } else {
        Err(Skip::NotUdp)
    }
}

/// IPv4 (header length and total length checked, fragments refused) then UDP (length checked).
/// Bytes after the IPv4 total length (Ethernet padding, a frame check sequence) are ignored.
pub fn ipv4(packet: &[u8]) -> Result<Udp<'_>, Skip> {
    let Some(&first) = packet.first() else {
        return Err(Skip::Short);
    };
    if first >> 4 != 4 {
        return Err(Skip::NotUdp);
    }
    if packet.len() < IPV4_HEADER_LEN {
        return Err(Skip::Short);
    }
    let ihl = usize::from(first & 0x0f) * 4;
    if ihl < IPV4_HEADER_LEN {
        return Err(Skip::Malformed);
    }
    if packet[9] != IPPROTO_UDP {
        return Err(Skip::NotUdp);
    }
    let flags_offset = u16::from_be_bytes([packet[6], packet[7]]);
    if flags_offset & 0x3fff != 0 {
        return Err(Skip::Fragment);
    }
    let total = usize::from(u16::from_be_bytes([packet[2], packet[3]]));
    if total < ihl + UDP_HEADER_LEN {
        return Err(Skip::Malformed);
    }
    if total > packet.len() {
        return Err(Skip::Short);
    }
    let udp = packet.get(ihl..total).ok_or(Skip::Short)?;
    let udp_len = usize::from(u16::from_be_bytes([udp[4], udp[5]]));
    if udp_len < UDP_HEADER_LEN || udp_len > udp.len() {
        return Err(Skip::Malformed);
    }
    let src_ip = Ipv4Addr::new(packet[12], packet[13], packet[14], packet[15]);
    let dst_ip = Ipv4Addr::new(packet[16], packet[17], packet[18], packet[19]);
    Ok(Udp {
        src: SocketAddrV4::new(src_ip, u16::from_be_bytes([udp[0], udp[1]])),
        dst: SocketAddrV4::new(dst_ip, u16::from_be_bytes([udp[2], udp[3]])),
        payload: udp.get(UDP_HEADER_LEN..udp_len).ok_or(Skip::Short)?,
    })
}

/// The Ones' complement sum used by IPv4 and UDP checksums, folded to 16 bits.
fn ones_sum(mut sum: u32, bytes: &[u8]) -> u32 {
    let mut pairs = bytes.chunks_exact(2);
    for p in &mut pairs {
        sum += u32::from(u16::from_be_bytes([p[0], p[1]]));
    }
    if let [last] = pairs.remainder() {
        sum += u32::from(*last) << 8;
    }
    while sum > 0xffff {
        sum = (sum & 0xffff) + (sum >> 16);
    }
    sum
}

/// A MAC address for an IPv4 address: the multicast or broadcast mapping, or a locally
/// administered unicast address carrying the IP.
pub fn mac_for(ip: Ipv4Addr) -> [u8; 6] {
    let o = ip.octets();
    if ip.is_broadcast() || o[3] == 255 {
        [0xff; 6]
    } else if ip.is_multicast() {
        [0x01, 0x00, 0x5e, o[1] & 0x7f, o[2], o[3]]
    } else {
        [0x02, 0x00, o[0], o[1], o[2], o[3]]
    }
}

/// Appends an Ethernet/IPv4/UDP frame carrying `payload` (checksums filled in). The caller checks
/// `payload.len() <= MAX_UDP_PAYLOAD`.
pub fn build_udp_frame(src: SocketAddrV4, dst: SocketAddrV4, ip_id: u16, payload: &[u8], out: &mut Vec<u8>) {
    let udp_len = (UDP_HEADER_LEN + payload.len()) as u16;
    let total = (IPV4_HEADER_LEN + UDP_HEADER_LEN + payload.len()) as u16;
    out.extend_from_slice(&mac_for(*dst.ip()));
    out.extend_from_slice(&mac_for(*src.ip()));
    out.extend_from_slice(&ETHERTYPE_IPV4.to_be_bytes());
    let ip_start = out.len();
    out.extend_from_slice(&[0x45, 0]);
    out.extend_from_slice(&total.to_be_bytes());
    out.extend_from_slice(&ip_id.to_be_bytes());
    out.extend_from_slice(&0x4000u16.to_be_bytes()); // don't fragment
    out.extend_from_slice(&[64, IPPROTO_UDP, 0, 0]);
    out.extend_from_slice(&src.ip().octets());
    out.extend_from_slice(&dst.ip().octets());
    let ip_sum = !(ones_sum(0, out.get(ip_start..).unwrap_or(&[])) as u16);
    if let Some(slot) = out.get_mut(ip_start + 10..ip_start + 12) {
        slot.copy_from_slice(&ip_sum.to_be_bytes());
    }
    // UDP checksum over the pseudo-header, the UDP header (checksum zero) and the payload.
    let mut pseudo = [0u8; 12];
    pseudo[..4].copy_from_slice(&src.ip().octets());
    pseudo[4..8].copy_from_slice(&dst.ip().octets());
    pseudo[9] = IPPROTO_UDP;
    pseudo[10..12].copy_from_slice(&udp_len.to_be_bytes());
    let mut header = [0u8; UDP_HEADER_LEN];
    header[..2].copy_from_slice(&src.port().to_be_bytes());
    header[2..4].copy_from_slice(&dst.port().to_be_bytes());
    header[4..6].copy_from_slice(&udp_len.to_be_bytes());
    let sum = ones_sum(ones_sum(ones_sum(0, &pseudo), &header), payload);
    let udp_sum = match !(sum as u16) {
        0 => 0xffff,
        s => s,
    };
    header[6..8].copy_from_slice(&udp_sum.to_be_bytes());
    out.extend_from_slice(&header);
    out.extend_from_slice(payload);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn addr(a: u8, port: u16) -> SocketAddrV4 {
        SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, a), port)
    }

    #[test]
    fn built_frames_decode_and_checksums_verify() {
        let mut frame = Vec::new();
        build_udp_frame(addr(1, 60001), addr(2, 56001), 7, b"hello", &mut frame);
        let udp = decode_link(LINKTYPE_ETHERNET, &frame);
        assert_eq!(udp, Ok(Udp { src: addr(1, 60001), dst: addr(2, 56001), payload: b"hello" }));
        // A correct checksum sums to 0xffff over the header (IPv4) / pseudo-header and datagram (UDP).
        assert_eq!(ones_sum(0, &frame[14..34]), 0xffff);
        let mut pseudo = frame[26..34].to_vec();
        pseudo.extend_from_slice(&[0, IPPROTO_UDP, 0, 13]);
        assert_eq!(ones_sum(ones_sum(0, &pseudo), &frame[34..]), 0xffff);
    }

    #[test]
    fn padding_is_ignored_and_short_frames_are_refused() {
        let mut frame = Vec::new();
        build_udp_frame(addr(1, 1), addr(2, 2), 0, b"x", &mut frame);
        let mut padded = frame.clone();
        padded.resize(60, 0);
        assert_eq!(decode_link(LINKTYPE_ETHERNET, &padded).map(|u| u.payload), Ok(&b"x"[..]));
        for len in 0..frame.len() {
            assert!(decode_link(LINKTYPE_ETHERNET, &frame[..len]).is_err(), "len {len}");
        }
    }

    #[test]
    fn fragments_options_and_other_protocols() {
        let mut frame = Vec::new();
        build_udp_frame(addr(1, 1), addr(2, 2), 0, b"abc", &mut frame);
        let ip = frame[14..].to_vec();
        let mut frag = ip.clone();
        frag[6] = 0x20; // more fragments
        assert_eq!(ipv4(&frag), Err(Skip::Fragment));
        let mut frag = ip.clone();
        frag[7] = 1; // offset 8
        assert_eq!(ipv4(&frag), Err(Skip::Fragment));
        let mut tcp = ip.clone();
        tcp[9] = 6;
        assert_eq!(ipv4(&tcp), Err(Skip::NotUdp));
        let mut bad = ip.clone();
        bad[0] = 0x44;
        assert_eq!(ipv4(&bad), Err(Skip::Malformed));
        // IHL 6: one 4-byte option.
        let mut opt = ip[..20].to_vec();
        opt[0] = 0x46;
        let total = (ip.len() + 4) as u16;
        opt[2..4].copy_from_slice(&total.to_be_bytes());
        opt.extend_from_slice(&[1, 1, 1, 0]);
        opt.extend_from_slice(&ip[20..]);
        assert_eq!(ipv4(&opt).map(|u| u.payload), Ok(&b"abc"[..]));
        let mut long_udp = ip.clone();
        long_udp[25] = 200;
        assert_eq!(ipv4(&long_udp), Err(Skip::Malformed));
        assert_eq!(decode_link(LINKTYPE_RAW, &[0x60; 40]), Err(Skip::NotUdp));
        assert_eq!(decode_link(999, &ip), Err(Skip::UnsupportedLink));
    }

    #[test]
    fn multicast_and_broadcast_macs() {
        assert_eq!(mac_for(Ipv4Addr::new(224, 0, 1, 129)), [1, 0, 0x5e, 0, 1, 129]);
        assert_eq!(mac_for(Ipv4Addr::BROADCAST), [0xff; 6]);
    }
}
