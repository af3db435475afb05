//! One ROS 2 node on either middleware a lab runs ([`Rmw`]): DDS through `ros2-client`
//! (RustDDS; ROS 2's DDS conventions: topics `rt/<name>`, types `<pkg>::msg::dds_::<Type>_`),
//! or rmw_zenoh through `hiroz` (the Zenoh team's pure-Rust ROS 2: key expressions
//! `<domain>/<name>/<type>/<REP-2016 hash>`, liveliness tokens for the ROS graph, rmw_zenoh's
//! attachments). The link, the camera, its calibration and the publisher use this node and
//! do not know which middleware carries them.

use std::future::Future;
use std::pin::Pin;

use crate::settings::{Rmw, Ros2Transport};

/// The QoS a topic is used with, in ROS 2's terms, mapped onto each middleware's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Qos {
    /// Reliable (else best effort).
    pub reliable: bool,
    /// Transient local (a late subscriber gets the publisher's last `depth`), else volatile.
    pub transient_local: bool,
    /// Keep last `depth`; 0 is taken as 1 on both middlewares (hiroz would read it as its
    /// default of 10, RustDDS would keep none).
    pub depth: usize,
}

impl Qos {
    /// Best effort, volatile: a subscription that matches reliable and best-effort
    /// publishers alike (a sensor's, a joint_state_broadcaster's).
    pub const fn best_effort(depth: usize) -> Self {
        Self {
            reliable: false,
            transient_local: false,
            depth,
        }
    }

    /// Reliable, volatile: what a controller's command topic and ROS 2's default profile use.
    pub const fn reliable(depth: usize) -> Self {
        Self {
            reliable: true,
            transient_local: false,
            depth,
        }
    }

    /// Reliable, transient local: tf2's static listener (`/tf_static`).
    pub const fn latched(depth: usize) -> Self {
        Self {
            reliable: true,
            transient_local: true,
            depth,
        }
    }

    fn dds(self) -> ros2_client::QosProfile {
        use ros2_client::qos::{Durability, History, WhenFull};
        let mut q = ros2_client::QosProfile::subscription_default().history(History::KeepLast {
            depth: self.depth.max(1),
        });
        if self.reliable {
            q = q.reliability_reliable(WhenFull::DEFAULT);
        }
        if self.transient_local {
            q = q.durability(Durability::TransientLocal);
        }
        q
    }

    fn zenoh(self) -> hiroz::qos::QosProfile {
        use hiroz::qos::{QosDurability, QosHistory, QosProfile, QosReliability};
        QosProfile {
            reliability: if self.reliable {
                QosReliability::Reliable
            } else {
                QosReliability::BestEffort
            },
            durability: if self.transient_local {
                QosDurability::TransientLocal
            } else {
                QosDurability::Volatile
            },
            history: QosHistory::from_depth(self.depth.max(1)),
            ..QosProfile::default()
        }
    }
}

/// A ROS 2 message either middleware carries: its CDR by serde (fields in the message
/// definition's order), its names, and (for rmw_zenoh) its REP-2016 type hash, taken from
/// `hiroz-msgs`' type generated from the same definition ([`ros2_message!`]).
pub trait Ros2Message:
    ros2_client::Message
    + hiroz::msg::ZMessage<Serdes = hiroz::msg::SerdeCdrSerdes<Self>>
    + hiroz::WithTypeInfo
    + std::fmt::Debug
    + Send
    + Sync
    + 'static
{
    /// The package (`sensor_msgs`).
    const PACKAGE: &'static str;
    /// The type's name in it (`JointState`).
    const NAME: &'static str;
}

/// Declares `$ty` (a serde struct laid out as the message) as the ROS 2 message
/// `$package/msg/$name`, its rmw_zenoh type name and hash those of `hiroz-msgs`' `$generated`.
macro_rules! ros2_message {
    ($ty:ty, $package:literal, $name:literal, $generated:ty) => {
        impl ros2_client::Message for $ty {}
        impl hiroz::msg::ZMessage for $ty {
            type Serdes = hiroz::msg::SerdeCdrSerdes<$ty>;
        }
        impl hiroz::MessageTypeInfo for $ty {
            fn type_name() -> &'static str {
                <$generated as hiroz::MessageTypeInfo>::type_name()
            }
            fn type_hash() -> hiroz::TypeHash {
                <$generated as hiroz::MessageTypeInfo>::type_hash()
            }
        }
        impl hiroz::WithTypeInfo for $ty {}
        impl $crate::ros2::node::Ros2Message for $ty {
            const PACKAGE: &'static str = $package;
            const NAME: &'static str = $name;
        }
    };
}
pub(crate) use ros2_message;

/// Resolves (with why) when the node stops working: DDS's spinner (its discovery and graph
/// events, which must be polled beside the node's work); never for rmw_zenoh, whose session
/// runs on Zenoh's own threads.
pub(crate) type Spin = Pin<Box<dyn Future<Output = String>>>;

/// A ROS 2 node on either middleware, and the namespace its relative topic names resolve in.
pub(crate) struct Node {
    /// The node's namespace (`/`, `/robot1`).
    namespace: String,
    /// The node itself.
    inner: Inner,
}

/// A node and its context; fields drop in order, the node before its context.
enum Inner {
    /// On DDS.
    Dds {
        /// The node (boxed: it is large).
        node: Box<ros2_client::Node>,
        /// The participant.
        _context: ros2_client::Context,
    },
    /// On rmw_zenoh.
    Zenoh {
        /// The node (its liveliness token, its entities'; boxed: it is large).
        node: Box<hiroz::node::ZNode>,
        /// The session.
        _context: hiroz::context::ZContext,
    },
}

/// How long opening a Zenoh session waits for the router before it fails (and the caller
/// says so and tries again), where a router is given.
const ZENOH_CONNECT_TIMEOUT_MS: u64 = 2_000;

/// What says when a node stops ([`Spin`]) and a node `node_name` in `transport`'s namespace on
/// its middleware. Errors say which step failed; on rmw_zenoh a router given that does not
/// answer within [`ZENOH_CONNECT_TIMEOUT_MS`] is one.
///
/// The spinner comes first so that `let (spin, node) = join(..)?` drops the node before it
/// (bindings drop in reverse order): a DDS node tells its spinner to stop when dropped, and
/// ros2_client logs an ERROR ("Cannot notify spin task to stop") at every link's end when the
/// spinner has gone first.
pub(crate) fn join(transport: &Ros2Transport, node_name: &str) -> Result<(Spin, Node), String> {
    let namespace = transport.namespace.clone();
    match &transport.rmw {
        Rmw::Dds => {
            use ros2_client::{Context, ContextOptions, NodeName, NodeOptions};
            let context =
                Context::with_options(ContextOptions::new().domain_id(transport.domain_id))
                    .map_err(|e| format!("cannot join DDS: {e:?}"))?;
            let name = NodeName::new(&transport.namespace, node_name)
                .map_err(|e| format!("node name '{node_name}': {e:?}"))?;
            let mut node = context
                .new_node(name, NodeOptions::new().enable_rosout(false))
                .map_err(|e| format!("cannot create the node: {e:?}"))?;
            let spin = node
                .spinner()
                .map_err(|e| format!("cannot spin the node: {e:?}"))?
                .spin();
            let spin: Spin =
                Box::pin(async move { format!("the node's spinner stopped: {:?}", spin.await) });
            let inner = Inner::Dds {
                node: Box::new(node),
                _context: context,
            };
            Ok((spin, Node { namespace, inner }))
        }
        Rmw::Zenoh { router } => {
            use hiroz::Builder;
            // rmw_zenoh's session config (a peer, the router at tcp/localhost:7447, or
            // ZENOH_SESSION_CONFIG_URI's), the router given on top of it; a router given must
            // answer, so that a wrong address is said instead of a link that never hears.
            let mut builder = hiroz::context::ZContextBuilder::default()
                .with_domain_id(usize::from(transport.domain_id));
            if let Some(router) = router {
                builder = builder
                    .with_connect_endpoints([router.as_str()])
                    .with_json("connect/timeout_ms", ZENOH_CONNECT_TIMEOUT_MS)
                    .with_json("connect/exit_on_failure", true);
            }
            let context = builder.build().map_err(|e| {
                format!(
                    "cannot open a Zenoh session ({}): {e}",
                    transport.describe()
                )
            })?;
            // No parameters to serve (nor `/parameter_events` to publish), as the DDS node
            // has none.
            let node = context
                .create_node(node_name)
                .with_namespace(&transport.namespace)
                .without_parameters()
                .build()
                .map_err(|e| format!("cannot create the node '{node_name}': {e}"))?;
            let inner = Inner::Zenoh {
                node: Box::new(node),
                _context: context,
            };
            Ok((Box::pin(std::future::pending()), Node { namespace, inner }))
        }
    }
}

/// `topic` as a fully qualified name: as given where absolute (`/joint_states`), else in
/// `namespace` (`joint_states` in `/robot1`: `/robot1/joint_states`; in `/`: `/joint_states`),
/// as ROS 2 resolves names (design.ros2.org, "Topic and Service name mapping"). Errors: a
/// private name (`~/...`) or an empty one.
fn resolve(namespace: &str, topic: &str) -> Result<String, String> {
    if topic.is_empty() || topic.starts_with('~') {
        return Err(format!(
            "topic '{topic}': give an absolute name (/ns/name) or one relative to the namespace"
        ));
    }
    if topic.starts_with('/') {
        return Ok(topic.to_owned());
    }
    Ok(format!("{}/{topic}", namespace.trim_end_matches('/')))
}

/// A ROS 2 topic name for ros2-client.
fn dds_name(topic: &str) -> Result<ros2_client::Name, String> {
    ros2_client::Name::parse(topic).map_err(|e| format!("topic '{topic}': not a ROS 2 name: {e:?}"))
}

/// `topic` carrying `M` with `qos` on DDS (what a reader or a writer is made on).
fn dds_topic<M: Ros2Message>(
    node: &mut ros2_client::Node,
    topic: &str,
    qos: Qos,
) -> Result<ros2_client::dds::rustdds::Topic, String> {
    node.create_topic(
        &dds_name(topic)?,
        ros2_client::MessageTypeName::new(M::PACKAGE, M::NAME),
        &qos.dds(),
    )
    .map_err(|e| format!("{topic}: {e:?}"))
}

impl Node {
    /// Subscribes to `topic` (`M`; relative names resolve in the node's namespace) with
    /// `qos`. Errors name the topic.
    pub fn subscribe<M: Ros2Message>(
        &mut self,
        topic: &str,
        qos: Qos,
    ) -> Result<Subscription<M>, String> {
        let topic = &resolve(&self.namespace, topic)?;
        match &mut self.inner {
            Inner::Dds { node, .. } => {
                let t = dds_topic::<M>(node, topic, qos)?;
                node.create_subscription::<M>(&t, Some(qos.dds()))
                    .map(Subscription::Dds)
                    .map_err(|e| format!("{topic}: {e:?}"))
            }
            Inner::Zenoh { node, .. } => {
                use hiroz::Builder;
                node.create_sub::<M>(topic)
                    .with_qos(qos.zenoh())
                    .build()
                    .map(Subscription::Zenoh)
                    .map_err(|e| format!("{topic}: {e}"))
            }
        }
    }

    /// A publisher of `M` on `topic` (relative names resolve in the node's namespace) with
    /// `qos`. On rmw_zenoh a publisher is best effort whatever `qos` says: `hiroz` gives a
    /// reliable one Zenoh's blocking congestion control (a slow reader would stall this
    /// thread for up to a minute), which rmw_zenoh uses only for keep-all history; a
    /// best-effort one drops under congestion, as rmw_zenoh's keep-last publishers do, and
    /// Zenoh over TCP delivers it all otherwise. Errors name the topic.
    pub fn publisher<M: Ros2Message>(
        &mut self,
        topic: &str,
        qos: Qos,
    ) -> Result<Publisher<M>, String> {
        let topic = &resolve(&self.namespace, topic)?;
        match &mut self.inner {
            Inner::Dds { node, .. } => {
                let t = dds_topic::<M>(node, topic, qos)?;
                node.create_publisher::<M>(&t, Some(qos.dds()))
                    .map(|p| Publisher::Dds(Box::new(p)))
                    .map_err(|e| format!("{topic}: {e:?}"))
            }
            Inner::Zenoh { node, .. } => {
                use hiroz::Builder;
                let qos = Qos {
                    reliable: false,
                    ..qos
                };
                node.create_pub::<M>(topic)
                    .with_qos(qos.zenoh())
                    .build()
                    .map(|p| Publisher::Zenoh(Box::new(p)))
                    .map_err(|e| format!("{topic}: {e}"))
            }
        }
    }
}

/// A subscription on either middleware.
pub(crate) enum Subscription<M: Ros2Message> {
    /// DDS.
    Dds(ros2_client::Subscription<M>),
    /// rmw_zenoh (its queue of samples, by the QoS's depth).
    Zenoh(hiroz::pubsub::ZSub<M, zenoh::sample::Sample, hiroz::msg::SerdeCdrSerdes<M>>),
}

impl<M: Ros2Message> Subscription<M> {
    /// The next message; an error is one that did not decode (or could not be read), and the
    /// subscription goes on. Cancel-safe: nothing is taken until it resolves.
    pub async fn recv(&self) -> Result<M, String> {
        match self {
            Self::Dds(s) => s
                .async_take()
                .await
                .map(|(m, _)| m)
                .map_err(|e| format!("{e:?}")),
            Self::Zenoh(s) => s.async_recv().await.map_err(|e| e.to_string()),
        }
    }
}

/// A publisher on either middleware.
pub(crate) enum Publisher<M: Ros2Message> {
    /// DDS (boxed, as the other: both are large).
    Dds(Box<ros2_client::Publisher<M>>),
    /// rmw_zenoh (each sample with rmw_zenoh's attachment: sequence number, time, GID).
    Zenoh(Box<hiroz::pubsub::ZPub<M, hiroz::msg::SerdeCdrSerdes<M>>>),
}

impl<M: Ros2Message> Publisher<M> {
    /// Publishes `message`. Errors: the writer could not take it (DDS's window full, a
    /// Zenoh session closed).
    pub async fn publish(&self, message: M) -> Result<(), String> {
        match self {
            Self::Dds(p) => p.async_publish(message).await.map_err(|e| format!("{e:?}")),
            Self::Zenoh(p) => p.async_publish(&message).await.map_err(|e| e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{Qos, Ros2Message, resolve};

    /// A depth of 0 keeps the last sample on both middlewares (hiroz alone would keep 10).
    #[test]
    fn a_depth_of_zero_keeps_one_sample_on_either_middleware() {
        use std::num::NonZeroUsize;
        let one = NonZeroUsize::new(1).expect("1");
        assert_eq!(
            Qos::reliable(0).zenoh().history,
            hiroz::qos::QosHistory::KeepLast(one)
        );
        assert_eq!(
            Qos::reliable(0).dds().history,
            ros2_client::qos::History::KeepLast { depth: 1 }
        );
        assert_eq!(
            Qos::latched(5).zenoh().history,
            hiroz::qos::QosHistory::KeepLast(NonZeroUsize::new(5).expect("5"))
        );
    }

    #[test]
    fn relative_names_resolve_in_the_namespace_and_private_ones_are_refused() {
        assert_eq!(resolve("/", "joint_states").as_deref(), Ok("/joint_states"));
        assert_eq!(
            resolve("/robot1", "fwd/commands").as_deref(),
            Ok("/robot1/fwd/commands")
        );
        assert_eq!(resolve("/robot1", "/tf").as_deref(), Ok("/tf"));
        assert!(resolve("/", "~/x").is_err());
        assert!(resolve("/", "").is_err());
    }

    /// Each message's names (DDS's `<pkg>::msg::dds_::<Name>_`) are those of the hiroz-msgs
    /// type its rmw_zenoh hash comes from: a wrong pairing would key it under another type.
    #[test]
    fn each_message_takes_its_hash_from_the_same_type() {
        fn same<M: Ros2Message>() {
            let dds = format!("{}::msg::dds_::{}_", M::PACKAGE, M::NAME);
            assert_eq!(<M as hiroz::MessageTypeInfo>::type_name(), dds);
        }
        same::<super::super::JointState>();
        same::<super::super::Float64MultiArray>();
        same::<super::super::JointTrajectory>();
        same::<super::super::camera::Image>();
        same::<super::super::camera::CompressedImage>();
        same::<super::super::calibration::CameraInfo>();
        same::<super::super::calibration::TfMessage>();
        same::<super::super::publish::StringMsg>();
    }
}
