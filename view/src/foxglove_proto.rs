//! Sans-IO Foxglove WebSocket protocol (`foxglove.websocket.v1`), the part a data server
//! needs: the JSON it sends (serverInfo, advertise, status), the binary Message Data frame, and
//! the client's subscribe/unsubscribe parsed from untrusted text. Other client operations are
//! recognised and refused with a status message (we declare no capabilities).

use serde::{Deserialize, Serialize};

pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Binary opcode of a Message Data frame.
pub const OP_MESSAGE_DATA: u8 = 0x01;
/// Subscriptions in one subscribe message (Foxglove sends one per panel topic).
pub const MAX_SUBSCRIPTIONS_PER_MESSAGE: usize = 1024;

/// One advertised channel, as in the Advertise message.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct ChannelInfo {
    pub id: u32,
    pub topic: String,
    pub encoding: String,
    pub schema_name: String,
    /// For `ros2msg`, the schema is the definition text itself (not base64).
    pub schema: String,
    pub schema_encoding: String,
}

#[derive(Serialize)]
#[serde(tag = "op", rename_all = "camelCase")]
enum ServerJson<'a> {
    #[serde(rename_all = "camelCase")]
    ServerInfo {
        name: &'a str,
        capabilities: [&'a str; 0],
        session_id: &'a str,
    },
    Advertise {
        channels: &'a [ChannelInfo],
    },
    Status {
        level: u8,
        message: &'a str,
    },
}

pub fn server_info(name: &str, session_id: &str) -> String {
    to_json(&ServerJson::ServerInfo { name, capabilities: [], session_id })
}

pub fn advertise(channels: &[ChannelInfo]) -> String {
    to_json(&ServerJson::Advertise { channels })
}

/// `level`: 0 info, 1 warning, 2 error.
pub fn status(level: u8, message: &str) -> String {
    to_json(&ServerJson::Status { level, message })
}

fn to_json(v: &ServerJson<'_>) -> String {
    // Serializing these plain structs cannot fail; an empty object is a harmless fallback.
    serde_json::to_string(v).unwrap_or_else(|_| "{}".into())
}

/// A Message Data frame: opcode, subscription id (u32 LE), log time in ns (u64 LE), payload.
pub fn message_data(subscription_id: u32, log_ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(13 + payload.len());
    out.push(OP_MESSAGE_DATA);
    out.extend_from_slice(&subscription_id.to_le_bytes());
    out.extend_from_slice(&log_ns.to_le_bytes());
    out.extend_from_slice(payload);
    out
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Subscription {
    pub id: u32,
    pub channel_id: u32,
}

/// What a client asked for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ClientOp {
    Subscribe(Vec<Subscription>),
    Unsubscribe(Vec<u32>),
    /// A valid operation this server does not offer (clientPublish, parameters, services...).
    Unsupported(String),
}

#[derive(Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
enum ClientJson {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        subscription_ids: Vec<u32>,
    },
}

#[derive(Deserialize)]
struct OpOnly {
    op: String,
}

/// Parses one text message from a client. Errors are reported back to it as a status message.
pub fn parse_client(text: &str) -> Result<ClientOp, String> {
    let op: OpOnly = serde_json::from_str(text).map_err(|e| format!("not a JSON object with an op: {e}"))?;
    if op.op != "subscribe" && op.op != "unsubscribe" {
        return Ok(ClientOp::Unsupported(op.op.chars().take(64).collect()));
    }
    let parsed: ClientJson = serde_json::from_str(text).map_err(|e| format!("bad {}: {e}", op.op))?;
    match parsed {
        ClientJson::Subscribe { subscriptions } if subscriptions.len() > MAX_SUBSCRIPTIONS_PER_MESSAGE => {
            Err(format!("more than {MAX_SUBSCRIPTIONS_PER_MESSAGE} subscriptions in one message"))
        }
        ClientJson::Subscribe { subscriptions } => Ok(ClientOp::Subscribe(subscriptions)),
        ClientJson::Unsubscribe { subscription_ids } => Ok(ClientOp::Unsubscribe(subscription_ids)),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn parses_subscribe_and_unsubscribe() {
        let s = parse_client(r#"{"op":"subscribe","subscriptions":[{"id":0,"channelId":3},{"id":1,"channelId":5}]}"#);
        assert_eq!(
            s,
            Ok(ClientOp::Subscribe(vec![Subscription { id: 0, channel_id: 3 }, Subscription { id: 1, channel_id: 5 }]))
        );
        assert_eq!(
            parse_client(r#"{"op":"unsubscribe","subscriptionIds":[0,1]}"#),
            Ok(ClientOp::Unsubscribe(vec![0, 1]))
        );
        assert_eq!(
            parse_client(r#"{"op":"getParameters","parameterNames":[]}"#),
            Ok(ClientOp::Unsupported("getParameters".into()))
        );
        assert!(parse_client(r#"{"op":"subscribe","subscriptions":[{"id":-1,"channelId":3}]}"#).is_err());
        assert!(parse_client("[]").is_err());
        assert!(parse_client("").is_err());
    }

    #[test]
    fn message_data_layout() {
        let m = message_data(7, 0x0102_0304_0506_0708, b"ab");
        assert_eq!(m, [1, 7, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1, b'a', b'b']);
    }

    #[test]
    fn server_json_field_names() {
        let info: serde_json::Value = serde_json::from_str(&server_info("starc", "42")).unwrap();
        assert_eq!(info["op"], "serverInfo");
        assert_eq!(info["sessionId"], "42");
        let ch = ChannelInfo {
            id: 1,
            topic: "/t".into(),
            encoding: "cdr".into(),
            schema_name: "sensor_msgs/msg/Imu".into(),
            schema: "x".into(),
            schema_encoding: "ros2msg".into(),
        };
        let adv: serde_json::Value = serde_json::from_str(&advertise(&[ch])).unwrap();
        assert_eq!(adv["channels"][0]["schemaName"], "sensor_msgs/msg/Imu");
        assert_eq!(adv["channels"][0]["schemaEncoding"], "ros2msg");
    }
}
