//! Two network namespaces joined by a veth pair, removed (with every child process started in
//! them) when dropped, even when a test fails. Shared by the tests that need a real network.

use std::process::{Child, Command};

pub struct Namespaces {
    pub names: Vec<String>,
    pub children: Vec<Child>,
}

impl Drop for Namespaces {
    fn drop(&mut self) {
        for c in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
        for n in &self.names {
            let _ = Command::new("ip").args(["netns", "del", n]).status();
        }
    }
}

pub fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip").args(args).output().map_err(|e| format!("ip {args:?}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("ip {args:?}: {}", String::from_utf8_lossy(&out.stderr)))
    }
}

/// Namespaces `a` and `b`, joined by veth `va` (in `a`, address `addr_a`) and `vb` (in `b`,
/// `addr_b`), both up with their loopback.
pub fn veth_pair(a: &str, b: &str, va: &str, vb: &str, addr_a: &str, addr_b: &str) -> Result<Namespaces, String> {
    ip(&["netns", "add", a])?;
    let mut ns = Namespaces { names: vec![a.to_string()], children: Vec::new() };
    ip(&["netns", "add", b])?;
    ns.names.push(b.to_string());
    ip(&["link", "add", va, "netns", a, "type", "veth", "peer", "name", vb, "netns", b])?;
    for (n, v, addr) in [(a, va, addr_a), (b, vb, addr_b)] {
        ip(&["-n", n, "link", "set", "lo", "up"])?;
        ip(&["-n", n, "addr", "add", addr, "dev", v])?;
        ip(&["-n", n, "link", "set", v, "up"])?;
    }
    Ok(ns)
}
