//! Captures: pcap, pcapng and .lvx.
