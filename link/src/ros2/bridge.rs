//! [`Ros2Bridge`]: a ROS 2 node on rmw_zenoh, made of zenoh's own primitives. It announces itself
//! and each of its publishers and subscriptions with rmw_zenoh's liveliness tokens, puts CDR
//! payloads on rmw_zenoh's keys with rmw_zenoh's attachment, and hands the payloads of the
//! topics it subscribes to a callback.
//!
//! Blocking (zenoh's `Wait`): a node runs it on a thread of its own, never on its async
//! runtime, so a slow router never holds up a scan.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;
use zenoh::{Session, Wait};

use super::config::Ros2Config;
use super::names::{qualified, topic_key, Distro, EntityKind, NodeName, Qos};
use super::type_hash::rihs01;
use crate::LinkError;
use starc_pipeline::record::attachment::{Attachment, GID_BYTES};

/// Names a topic [`Ros2Bridge::advertise`] declared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TopicId(usize);

struct Advertised {
    publisher: Publisher<'static>,
    _token: LivelinessToken,
    gid: [u8; GID_BYTES],
    sequence: i64,
}

/// What the bridge has put, and what zenoh refused.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Ros2Counts {
    pub published: u64,
    pub put_errors: u64,
}

pub struct Ros2Bridge {
    session: Session,
    node: NodeName,
    namespace: String,
    distro: Distro,
    _node_token: LivelinessToken,
    topics: Vec<Advertised>,
    subscriptions: Vec<(Subscriber<()>, LivelinessToken)>,
    next_entity: u32,
    counts: Ros2Counts,
}

impl Ros2Bridge {
    /// Opens a session to the router `cfg` names and announces node `node_name`.
    pub fn open(cfg: &Ros2Config, node_name: &str) -> Result<Self, LinkError> {
        let cmd_vel_key =
            topic_key(cfg.domain_id, &qualified(&cfg.namespace, "cmd_vel"), TWIST, &hash(cfg.distro, TWIST)?);
        let session = zenoh::open(cfg.zenoh(&cmd_vel_key)?)
            .wait()
            .map_err(|e| LinkError::zenoh("opening the ROS 2 session", e))?;
        let node = NodeName {
            domain: cfg.domain_id,
            zid: session.zid().to_string(),
            node_id: 0,
            namespace: cfg.namespace.clone(),
            name: node_name.to_string(),
        };
        let token = session
            .liveliness()
            .declare_token(node.node_token())
            .wait()
            .map_err(|e| LinkError::zenoh("declaring the node's liveliness token", e))?;
        Ok(Self {
            session,
            node,
            namespace: cfg.namespace.clone(),
            distro: cfg.distro,
            _node_token: token,
            topics: Vec::new(),
            subscriptions: Vec::new(),
            next_entity: 1,
            counts: Ros2Counts::default(),
        })
    }

    /// The zenoh session's id, as the tokens carry it.
    pub fn zid(&self) -> String {
        self.node.zid.clone()
    }

    pub fn counts(&self) -> Ros2Counts {
        self.counts
    }

    /// The key `topic` (relative to the namespace) of `type_name` is put on.
    pub fn key(&self, topic: &str, type_name: &str) -> Result<String, LinkError> {
        Ok(topic_key(self.node.domain, &qualified(&self.namespace, topic), type_name, &hash(self.distro, type_name)?))
    }

    fn token(&mut self, kind: EntityKind, topic: &str, type_name: &str, qos: Qos) -> Result<(u32, String), LinkError> {
        let id = self.next_entity;
        self.next_entity += 1;
        let fq = qualified(&self.namespace, topic);
        Ok((id, self.node.entity_token(id, kind, &fq, type_name, &hash(self.distro, type_name)?, qos)))
    }

    /// Declares a publisher of `type_name` on `topic` and its liveliness token. Samples that
    /// find the router's queue full are dropped (a late scan is worth less than the next one).
    pub fn advertise(&mut self, topic: &str, type_name: &str, qos: Qos) -> Result<TopicId, LinkError> {
        let key = self.key(topic, type_name)?;
        let (entity, token_key) = self.token(EntityKind::Publisher, topic, type_name, qos)?;
        let publisher = self
            .session
            .declare_publisher(key)
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(|e| LinkError::zenoh("declaring a ROS 2 publisher", e))?;
        let token = self
            .session
            .liveliness()
            .declare_token(token_key)
            .wait()
            .map_err(|e| LinkError::zenoh("declaring a publisher's liveliness token", e))?;
        self.topics.push(Advertised { publisher, _token: token, gid: self.gid(entity), sequence: 0 });
        Ok(TopicId(self.topics.len() - 1))
    }

    /// A GID unique to this session's entity: the session id with the entity id in its last
    /// four bytes.
    fn gid(&self, entity: u32) -> [u8; GID_BYTES] {
        let mut gid = self.session.zid().to_le_bytes();
        gid[GID_BYTES - 4..].copy_from_slice(&entity.to_be_bytes());
        gid
    }

    /// Puts one CDR payload (encapsulation header included) on an advertised topic.
    pub fn put(&mut self, id: TopicId, payload: Vec<u8>, source_timestamp_ns: i64) -> Result<(), LinkError> {
        let topic = self.topics.get_mut(id.0).ok_or(LinkError::Closed)?;
        topic.sequence += 1;
        let attachment = Attachment { sequence_number: topic.sequence, source_timestamp_ns, gid: topic.gid };
        let result = topic.publisher.put(payload).attachment(attachment.encode().to_vec()).wait();
        match result {
            Ok(()) => {
                self.counts.published += 1;
                Ok(())
            }
            Err(e) => {
                self.counts.put_errors += 1;
                Err(LinkError::zenoh("putting a ROS 2 sample", e))
            }
        }
    }

    /// Subscribes to `topic` and announces the subscription; `on_payload` gets each sample's
    /// payload (on a zenoh thread: keep it short). Samples without rmw_zenoh's attachment are
    /// dropped, as rmw_zenoh drops them, and counted in the returned counter.
    pub fn subscribe(
        &mut self,
        topic: &str,
        type_name: &str,
        qos: Qos,
        on_payload: impl Fn(Vec<u8>) + Send + Sync + 'static,
    ) -> Result<Arc<AtomicU64>, LinkError> {
        let key = self.key(topic, type_name)?;
        let (_, token_key) = self.token(EntityKind::Subscription, topic, type_name, qos)?;
        let refused = Arc::new(AtomicU64::new(0));
        let counter = refused.clone();
        let subscriber = self
            .session
            .declare_subscriber(key)
            .callback(move |sample| {
                let attached = sample.attachment().is_some_and(|a| Attachment::decode(&a.to_bytes()).is_ok());
                if attached {
                    on_payload(sample.payload().to_bytes().into_owned());
                } else {
                    counter.fetch_add(1, Ordering::Relaxed);
                }
            })
            .wait()
            .map_err(|e| LinkError::zenoh("declaring a ROS 2 subscription", e))?;
        let token = self
            .session
            .liveliness()
            .declare_token(token_key)
            .wait()
            .map_err(|e| LinkError::zenoh("declaring a subscription's liveliness token", e))?;
        self.subscriptions.push((subscriber, token));
        Ok(refused)
    }

    /// Withdraws every token and closes the session.
    pub fn close(self) -> Result<(), LinkError> {
        let Self { session, topics, subscriptions, _node_token, .. } = self;
        drop((topics, subscriptions, _node_token));
        session.close().wait().map_err(|e| LinkError::zenoh("closing the ROS 2 session", e))
    }
}

const TWIST: &str = "geometry_msgs/msg/Twist";

/// The type hash as `distro` writes it in keys and tokens.
pub fn hash(distro: Distro, type_name: &str) -> Result<String, LinkError> {
    match distro {
        Distro::Jazzy => rihs01(type_name),
        Distro::Humble => Ok("TypeHashNotSupported".into()),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn humble_keys_carry_no_type_hash() {
        assert_eq!(hash(Distro::Humble, TWIST).unwrap(), "TypeHashNotSupported");
        assert_eq!(hash(Distro::Jazzy, TWIST).unwrap(), rihs01(TWIST).unwrap());
        assert!(hash(Distro::Jazzy, "geometry_msgs/msg/Nope").is_err());
    }
}
