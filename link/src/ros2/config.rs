//! `[ros2]` in robot.toml and fpv.toml: the optional bridge to a ROS 2 system on rmw_zenoh.
//!
//! The bridge is a zenoh *client* of the ROS 2 system's router (`ros2 run rmw_zenoh_cpp
//! rmw_zenohd`, tcp/…:7447 by default): it connects out and listens on nothing. Plain tcp to a
//! router off this host is refused unless `insecure = true` (anyone on that network could read
//! the map, the people and the images); `/cmd_vel` is taken only over mutual TLS, and zenoh's
//! access control then takes puts from the router's certificate name on that one key alone.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::names::Distro;
use crate::config::{is_loopback, json, json_list};
use crate::{LinkError, TlsConfig};

/// rmw_zenoh's router listens here by default.
pub const DEFAULT_ROUTER: &str = "tcp/127.0.0.1:7447";

#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Config {
    /// Off unless set: nothing is published and no connection is made.
    #[serde(default)]
    pub enabled: bool,
    /// `ROS_DOMAIN_ID`: the first segment of every key (0-232).
    #[serde(default)]
    pub domain_id: u32,
    /// Put before every topic (`/starc` gives `/starc/robot/points`); empty: none.
    #[serde(default)]
    pub namespace: String,
    /// The ROS 2 router's endpoints (`tcp/HOST:7447`, or `tls/HOST:PORT` with `[ros2.tls]`).
    #[serde(default = "default_connect")]
    pub connect: Vec<String>,
    /// Jazzy (type hashes in keys) or Humble (`TypeHashNotSupported`).
    #[serde(default)]
    pub distro: Distro,
    /// Allow plain tcp to a router that is not on this host.
    #[serde(default)]
    pub insecure: bool,
    #[serde(default)]
    pub tls: Option<TlsConfig>,
    /// Robot only: take `geometry_msgs/Twist` on `/cmd_vel` and drive the base with it, through
    /// the base's limits and watchdog. Needs mutual TLS and `cmd_vel_from`.
    #[serde(default)]
    pub cmd_vel: bool,
    /// The certificate common names of the routers `/cmd_vel` may come through.
    #[serde(default)]
    pub cmd_vel_from: Vec<String>,
    /// With `cmd_vel`: the base driver's config (config/base.toml: its bus, limits, watchdog).
    /// The node then drives the base; `starc base drive` must not run beside it.
    #[serde(default)]
    pub base_config: Option<PathBuf>,
    /// With `cmd_vel`: `/cmd_vel` silent this long and the base is told to stop (it ramps down
    /// at its deceleration limits). Under the base's own watchdog (200 ms), twice the gaps of a
    /// 20 Hz publisher (Nav2's controller, teleop_twist_joy).
    #[serde(default = "default_cmd_vel_timeout_ms")]
    pub cmd_vel_timeout_ms: u64,
    /// Messages waiting for the bridge; past this the oldest kinds are dropped and counted, so a
    /// slow router never holds up a scan.
    #[serde(default = "default_queue")]
    pub queue: usize,
    /// Publish every n-th AR frame on `/fpv/ar_image/compressed` (rig); 0: none.
    #[serde(default = "one")]
    pub image_every: u64,
}

fn default_connect() -> Vec<String> {
    vec![DEFAULT_ROUTER.into()]
}

fn default_cmd_vel_timeout_ms() -> u64 {
    100
}

fn default_queue() -> usize {
    256
}

fn one() -> u64 {
    1
}

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            enabled: false,
            domain_id: 0,
            namespace: String::new(),
            connect: default_connect(),
            distro: Distro::Jazzy,
            insecure: false,
            tls: None,
            cmd_vel: false,
            cmd_vel_from: Vec::new(),
            base_config: None,
            cmd_vel_timeout_ms: default_cmd_vel_timeout_ms(),
            queue: default_queue(),
            image_every: 1,
        }
    }
}

impl Ros2Config {
    /// Relative TLS paths taken from `dir` (the config file's directory).
    pub fn resolve_paths(&mut self, dir: &Path) {
        let fix = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        };
        if let Some(b) = &mut self.base_config {
            fix(b);
        }
        if let Some(t) = &mut self.tls {
            fix(&mut t.root_ca);
            if let Some(c) = &mut t.cert {
                fix(c);
            }
            if let Some(k) = &mut t.key {
                fix(k);
            }
        }
    }

    fn mutual_tls(&self) -> bool {
        self.tls.as_ref().is_some_and(|t| t.mutual && t.cert.is_some() && t.key.is_some())
    }

    pub fn validate(&self) -> Result<(), LinkError> {
        let bad = |field, reason: String| Err(LinkError::Config { field, reason });
        if self.domain_id > 232 {
            return bad("ros2.domain_id", format!("{} is past 232", self.domain_id));
        }
        let ns_ok = self.namespace.trim_matches('/').split('/').all(|s| {
            s.is_empty()
                || (s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') && !s.starts_with(char::is_numeric))
        });
        if !ns_ok || self.namespace.contains("//") {
            return bad("ros2.namespace", format!("{:?}: ROS 2 names are letters, digits and _", self.namespace));
        }
        if self.connect.is_empty() {
            return bad("ros2.connect", "the ROS 2 router's endpoint is needed".into());
        }
        if self.cmd_vel_timeout_ms == 0 {
            return bad("ros2.cmd_vel_timeout_ms", "must be > 0".into());
        }
        if self.queue == 0 {
            return bad("ros2.queue", "must be > 0".into());
        }
        for e in &self.connect {
            let ep = e
                .parse::<zenoh::config::EndPoint>()
                .map_err(|err| LinkError::Config { field: "ros2.connect", reason: format!("{e:?}: {err}") })?;
            let tls = ep.protocol().as_str() == "tls";
            if tls && self.tls.is_none() {
                return bad("ros2.tls", format!("{e:?} is tls/ but there is no [ros2.tls] table"));
            }
            if !tls && !self.insecure && !is_loopback(ep.address().as_str()) {
                return bad(
                    "ros2.connect",
                    format!(
                        "{e:?} is plain {} to another host: anyone on that network could read the map, \
                         the people and the images. Use tls/ with [ros2.tls], or set `insecure = true`",
                        ep.protocol().as_str()
                    ),
                );
            }
            if self.cmd_vel && !tls {
                return bad("ros2.cmd_vel", format!("/cmd_vel drives the base: only over tls/, not {e:?}"));
            }
        }
        if self.cmd_vel && self.base_config.is_none() {
            return bad("ros2.base_config", "/cmd_vel needs the base driver's config (base.toml)".into());
        }
        if self.cmd_vel && (!self.mutual_tls() || self.cmd_vel_from.is_empty()) {
            return bad(
                "ros2.cmd_vel",
                "/cmd_vel needs mutual TLS (`mutual = true`, `cert`, `key` in [ros2.tls]) and the router's \
                 certificate name in `cmd_vel_from`"
                    .into(),
            );
        }
        Ok(())
    }

    /// The zenoh config: a client of the router, no listening, no scouting; TLS as configured;
    /// with `/cmd_vel`, access control that takes puts from the named routers on that key only.
    pub fn zenoh(&self, cmd_vel_key: &str) -> Result<zenoh::Config, LinkError> {
        self.validate()?;
        let mut z = zenoh::Config::default();
        let mut set = |key: &'static str, value: String| {
            z.insert_json5(key, &value).map_err(|e| LinkError::Config { field: key, reason: e.to_string() })
        };
        set("mode", json("client"))?;
        set("listen/endpoints", "[]".into())?;
        set("connect/endpoints", json_list(&self.connect))?;
        set("connect/timeout_ms", "-1".into())?;
        set("connect/exit_on_failure", "false".into())?;
        set("scouting/multicast/enabled", "false".into())?;
        set("scouting/gossip/enabled", "false".into())?;
        // As on the link (config.rs): zenoh drops a sample after 1 ms without a free batch; a
        // burst (a scan, then its IMU samples) on a busy 2-core host lost some. Deeper queues for
        // data and 5 ms of patience; past that a sample is dropped, never waited for.
        set("transport/link/tx/queue/size/data", "8".into())?;
        set("transport/link/tx/queue/congestion_control/drop/wait_before_drop", "5000".into())?;
        // The link's TLS settings (the listening ones unused: the bridge listens on nothing).
        for (key, value) in self.tls.iter().flat_map(TlsConfig::zenoh_settings) {
            set(key, value)?;
        }
        if self.cmd_vel {
            set("access_control", cmd_vel_access_control(cmd_vel_key, &self.cmd_vel_from))?;
        }
        Ok(z)
    }
}

/// Every message kind zenoh's access control names.
const EVERY_KIND: &str = "\"put\", \"delete\", \"declare_subscriber\", \"query\", \"reply\", \
                          \"declare_queryable\", \"liveliness_token\", \"declare_liveliness_subscriber\", \
                          \"liveliness_query\"";
/// The kinds that carry no data into the robot.
const NO_DATA_KINDS: &str = "\"declare_subscriber\", \"declare_queryable\", \"liveliness_token\", \
                             \"declare_liveliness_subscriber\", \"liveliness_query\"";

/// Every key: zenoh's `**` does not match a chunk that starts with `@`, as rmw_zenoh's
/// liveliness tokens (`@ros2_lv/...`) do.
const ANY: &str = "\"**\", \"@ros2_lv/**\"";

/// Access control for a bridge that takes `/cmd_vel`: to routers named in `from`, anything goes
/// out; from them only declarations, and puts on `cmd_vel_key`, come in. Everything else, and
/// every transport with another certificate name, is denied.
fn cmd_vel_access_control(cmd_vel_key: &str, from: &[String]) -> String {
    let names = from.iter().map(|n| json(n)).collect::<Vec<_>>().join(", ");
    format!(
        "{{ enabled: true, default_permission: \"deny\", rules: [\
         {{ id: \"out\", messages: [{EVERY_KIND}], flows: [\"egress\"], permission: \"allow\", key_exprs: [{ANY}] }}, \
         {{ id: \"declarations_in\", messages: [{NO_DATA_KINDS}], flows: [\"ingress\"], permission: \"allow\", \
         key_exprs: [{ANY}] }}, \
         {{ id: \"cmd_vel_in\", messages: [\"put\"], flows: [\"ingress\"], permission: \"allow\", key_exprs: [{}] }}], \
         subjects: [{{ id: \"router\", cert_common_names: [{names}] }}], \
         policies: [{{ id: \"router\", subjects: [\"router\"], rules: [\"out\", \"declarations_in\", \"cmd_vel_in\"] }}] }}",
        json(cmd_vel_key)
    )
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn tls() -> TlsConfig {
        TlsConfig {
            root_ca: "ca.pem".into(),
            cert: Some("robot.pem".into()),
            key: Some("robot.key".into()),
            mutual: true,
            verify_name: true,
        }
    }

    #[test]
    fn defaults_are_off_and_on_loopback() {
        let c: Ros2Config = toml::from_str("").unwrap();
        assert!(!c.enabled && !c.cmd_vel);
        assert_eq!(c.connect, vec![DEFAULT_ROUTER.to_string()]);
        c.validate().unwrap();
        c.zenoh("0/cmd_vel/**").unwrap();
        assert!(toml::from_str::<Ros2Config>("enabeld = true").is_err());
    }

    #[test]
    fn plain_tcp_off_host_and_cmd_vel_without_mutual_tls_are_refused() {
        let off_host = Ros2Config { connect: vec!["tcp/192.168.1.9:7447".into()], ..Ros2Config::default() };
        assert!(off_host.validate().is_err());
        Ros2Config { insecure: true, ..off_host }.validate().unwrap();
        let plain_cmd_vel = Ros2Config {
            cmd_vel: true,
            cmd_vel_from: vec!["router".into()],
            base_config: Some("base.toml".into()),
            ..Ros2Config::default()
        };
        assert!(plain_cmd_vel.validate().is_err());
        let tls_cmd_vel = Ros2Config {
            connect: vec!["tls/127.0.0.1:7447".into()],
            tls: Some(tls()),
            cmd_vel: true,
            cmd_vel_from: vec!["router".into()],
            base_config: Some("base.toml".into()),
            ..Ros2Config::default()
        };
        tls_cmd_vel.validate().unwrap();
        assert!(Ros2Config { base_config: None, ..tls_cmd_vel.clone() }.validate().is_err());
        tls_cmd_vel.zenoh("0/cmd_vel/**").unwrap();
        assert!(Ros2Config { cmd_vel_from: vec![], ..tls_cmd_vel.clone() }.validate().is_err());
        assert!(Ros2Config { domain_id: 233, ..Ros2Config::default() }.validate().is_err());
        assert!(Ros2Config { namespace: "/a b".into(), ..Ros2Config::default() }.validate().is_err());
        Ros2Config { namespace: "/starc/robot_1".into(), ..Ros2Config::default() }.validate().unwrap();
    }
}
