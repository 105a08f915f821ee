//! The zenoh key expressions of the link: `<prefix>/<sender role>/<kind>` for published
//! messages, `<prefix>/robot/map` for the map queryable.

use starc_pipeline::link::{kind_name, LinkMessage, Role};

/// Where a message from `sender` is published.
pub fn message_key(prefix: &str, sender: Role, msg: &LinkMessage) -> String {
    format!("{prefix}/{}/{}", sender.name(), kind_name(msg))
}

/// Everything `sender` publishes.
pub fn sender_wildcard(prefix: &str, sender: Role) -> String {
    format!("{prefix}/{}/*", sender.name())
}

/// The robot's map queryable: every tile it holds, one reply each.
pub fn map_key(prefix: &str) -> String {
    format!("{prefix}/robot/map")
}
