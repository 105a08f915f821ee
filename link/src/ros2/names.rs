//! rmw_zenoh's names (its design document, docs/design.md, "Topic and Service name mapping to
//! Zenoh key expressions" and "Graph Cache"): where a topic's samples go, and the liveliness
//! tokens that make a node and its publishers and subscriptions visible to `ros2 node list`,
//! `ros2 topic list` and every rmw_zenoh graph cache.
//!
//! - data: `<domain>/<fully qualified topic, no leading slash>/<DDS type name>/<type hash>`;
//! - node: `@ros2_lv/<domain>/<zenoh id>/<node id>/<node id>/NN/<enclave>/<namespace>/<node>`;
//! - publisher (`MP`) or subscription (`MS`): the node's fields with the entity's id, then the
//!   topic, type, hash and QoS.
//!
//! In a token every `/` of a name becomes `%`, and an empty name is `%`.

use std::fmt;

/// Which ROS 2 distribution's form the keys take.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Distro {
    /// Type hashes (RIHS01) in keys and tokens.
    #[default]
    Jazzy,
    /// Humble's rmw_zenoh has no type hashes: `TypeHashNotSupported` in their place.
    Humble,
}

/// `pkg/msg/Type` -> `pkg::msg::dds_::Type_`, the DDS-mangled name rmw_zenoh keys use.
pub fn dds_type_name(type_name: &str) -> String {
    match type_name.rsplit_once('/') {
        Some((pkg, ty)) => format!("{}::dds_::{ty}_", pkg.replace('/', "::")),
        None => format!("{type_name}_"),
    }
}

/// A name in a token: `/` -> `%`, empty -> `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// `namespace` + `/` + `topic`: the fully qualified name, with one leading slash.
pub fn qualified(namespace: &str, topic: &str) -> String {
    let ns = namespace.trim_matches('/');
    let topic = topic.trim_start_matches('/');
    if ns.is_empty() {
        format!("/{topic}")
    } else {
        format!("/{ns}/{topic}")
    }
}

/// The key expression a topic's samples are put on.
pub fn topic_key(domain: u32, qualified_topic: &str, type_name: &str, hash: &str) -> String {
    format!("{domain}/{}/{}/{hash}", qualified_topic.trim_start_matches('/'), dds_type_name(type_name))
}

/// A ROS 2 QoS profile as rmw_zenoh writes it in tokens: `reliability:durability:history,depth:
/// deadline:lifespan:liveliness`, each empty where it is the default (reliable, volatile, keep
/// last, infinite).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Qos {
    pub best_effort: bool,
    pub transient_local: bool,
    pub depth: u32,
}

impl Qos {
    /// Reliable, volatile, keep last 10: rclcpp's default.
    pub const DEFAULT: Self = Self { best_effort: false, transient_local: false, depth: 10 };
}

impl fmt::Display for Qos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let reliability = if self.best_effort { "2" } else { "" };
        let durability = if self.transient_local { "1" } else { "" };
        write!(f, "{reliability}:{durability}:,{}:,:,:,,", self.depth)
    }
}

/// What a liveliness token announces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EntityKind {
    Publisher,
    Subscription,
}

impl EntityKind {
    fn code(self) -> &'static str {
        match self {
            Self::Publisher => "MP",
            Self::Subscription => "MS",
        }
    }
}

/// The node a set of tokens belongs to.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeName {
    pub domain: u32,
    /// The zenoh session's id, as zenoh prints it.
    pub zid: String,
    pub node_id: u32,
    pub namespace: String,
    pub name: String,
}

impl NodeName {
    fn prefix(&self, entity_id: u32, kind: &str) -> String {
        let ns = format!("/{}", self.namespace.trim_matches('/'));
        let ns = if ns == "/" { "%".to_string() } else { mangle(&ns) };
        format!("@ros2_lv/{}/{}/{}/{entity_id}/{kind}/%/{ns}/{}", self.domain, self.zid, self.node_id, self.name)
    }

    /// The node's own token.
    pub fn node_token(&self) -> String {
        self.prefix(self.node_id, "NN")
    }

    /// A publisher's or subscription's token.
    pub fn entity_token(
        &self,
        entity_id: u32,
        kind: EntityKind,
        qualified_topic: &str,
        type_name: &str,
        hash: &str,
        qos: Qos,
    ) -> String {
        format!(
            "{}/{}/{}/{hash}/{qos}",
            self.prefix(entity_id, kind.code()),
            mangle(qualified_topic),
            dds_type_name(type_name)
        )
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const STRING_HASH: &str = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";

    /// The examples of rmw_zenoh's design document: a `listener` subscribed to `/chatter`.
    #[test]
    fn keys_and_tokens_match_the_design_documents_examples() {
        assert_eq!(dds_type_name("std_msgs/msg/String"), "std_msgs::msg::dds_::String_");
        assert_eq!(
            topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH),
            format!("0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
        );
        let node = NodeName {
            domain: 0,
            zid: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
            node_id: 0,
            namespace: String::new(),
            name: "listener".into(),
        };
        assert_eq!(node.node_token(), "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener");
        assert_eq!(
            node.entity_token(
                10,
                EntityKind::Subscription,
                "/chatter",
                "std_msgs/msg/String",
                STRING_HASH,
                Qos::DEFAULT
            ),
            format!(
                "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/\
                 std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,"
            )
        );
    }

    #[test]
    fn namespaces_and_qos_are_written_as_rmw_zenoh_writes_them() {
        assert_eq!(qualified("", "robot/points"), "/robot/points");
        assert_eq!(qualified("/starc/", "/tf"), "/starc/tf");
        assert_eq!(mangle("/starc/tf"), "%starc%tf");
        let node = NodeName { domain: 3, zid: "1".into(), node_id: 0, namespace: "/starc".into(), name: "n".into() };
        assert_eq!(node.node_token(), "@ros2_lv/3/1/0/0/NN/%/%starc/n");
        assert_eq!(Qos { best_effort: true, transient_local: false, depth: 5 }.to_string(), "2::,5:,:,:,,");
        assert_eq!(Qos { best_effort: false, transient_local: true, depth: 1 }.to_string(), ":1:,1:,:,:,,");
    }
}
