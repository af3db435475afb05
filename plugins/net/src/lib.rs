//! Avatarm's two sites over Eclipse Zenoh (`avatarm serve` and `avatarm join`,
//! `docs/network.md`).
//!
//! The paper's scenario is two people in two places: the robot and the camera on Alice's desk,
//! Blair remote with her headset and tracked hand. The robot site runs the robot link, the
//! cameras, the erase pipeline and the robot's side of the motion mapping (Jacobian, limiter,
//! watchdog) next to the robot; the operator site runs the hand, the physics twin and the
//! operator's side of the mapping (contacts → grasp matrix → σ and the object's twist) and
//! sends a [`msg::TargetMsg`] every control tick.
//!
//! - [`keys`]: the key space; [`msg`]: the versioned messages and their checks;
//!   [`config`]: endpoints, authentication, TLS and access control; [`site`]: the two ends;
//!   [`codec`]: the video's codecs (JPEG, H.264) and the viewer's keyframe handling;
//!   [`impair`]: a seeded impairment relay (delay, jitter, loss, bandwidth, cuts) for tests
//!   and `avatarm bench network`, since these machines have no `netem`; [`episodes`]: refusals
//!   logged once per episode with a summary every few seconds, so a bad peer cannot flood the
//!   log.

pub mod codec;
pub mod config;
pub mod episodes;
pub mod impair;
pub mod keys;
pub mod msg;
pub mod site;

pub use config::{Credentials, NetConfig, Role, TlsFiles};
pub use keys::Keys;
pub use site::{
    ClockSample, FrameSender, HeadReceiver, OperatorInbox, OperatorSite, RESTART_JUMP_S,
    ReceivedFrame, RobotClock, RobotInbox, RobotSite, Router, SiteClock,
};

/// What can go wrong on the network; each names the message, setting or key.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    /// A setting is wrong.
    #[error("{what}: {message}")]
    Config {
        /// The setting.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A message was refused.
    #[error("{what} refused: {message}")]
    Invalid {
        /// The message.
        what: String,
        /// Why.
        message: String,
    },
    /// A peer speaks another protocol version.
    #[error("{what} refused: the peer speaks protocol {}, this build speaks {}; run the same Avatarm release at both sites", theirs.map_or("(no version)".to_string(), |v| format!("version {v}")), crate::msg::PROTOCOL_VERSION)]
    Version {
        /// The message.
        what: String,
        /// The peer's version, if it said one.
        theirs: Option<u32>,
    },
    /// Zenoh failed.
    #[error("zenoh, {what}: {message}")]
    Zenoh {
        /// What was being done.
        what: String,
        /// Zenoh's error.
        message: String,
    },
    /// No robot site answered.
    #[error(
        "no robot site answered on '{key}' within {waited_s:.1} s (is `avatarm serve` running, the endpoint right, the credentials accepted?)"
    )]
    NoRobotSite {
        /// The key asked.
        key: String,
        /// How long it waited (s).
        waited_s: f64,
    },
}
