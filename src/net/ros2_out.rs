//! What a session publishes on ROS 2 (`--ros2-publish`, feature `ros`; docs/robot-ros2.md):
//! the publisher ([`Ros2Sink`]) on the scene's ROS 2 domain, and the messages the robot site
//! and the session recorder hand it. Without the feature no sink can be made (the flag says
//! so), and these functions cannot be called.

use avatarm_record::LogLevel;
use avatarm_scene::Scene;

use crate::AppError;

/// The session's ROS 2 publisher (cheap to clone: a queue's sender).
#[cfg(feature = "ros")]
pub type Ros2Sink = avatarm_ros::ros2::publish::Ros2Publisher;
/// The session's ROS 2 publisher: none can be made without the feature `ros`.
#[cfg(not(feature = "ros"))]
pub type Ros2Sink = NoRos2;

/// No ROS 2 in this build: a type with no value (cloned like the real sink, never made).
#[cfg(not(feature = "ros"))]
#[derive(Debug, Clone)]
pub enum NoRos2 {}

/// The publisher under `/avatarm` on `scene`'s ROS 2 domain and middleware
/// ([`crate::net::site_camera::ros2_transport`]). Errors name `--ros2-publish` (or
/// `ROS_DOMAIN_ID`, `RMW_IMPLEMENTATION`).
#[cfg(feature = "ros")]
pub fn ros2_publisher(scene: &Scene) -> Result<Ros2Sink, AppError> {
    avatarm_ros::ros2::publish::Ros2Publisher::start(
        crate::net::site_camera::ros2_transport(scene)?,
        "avatarm_out",
        "/avatarm",
        "camera_optical",
    )
    .map_err(|e| AppError::flag("--ros2-publish", format!("cannot start its thread: {e}")))
}

/// Without the feature `ros` there is no ROS 2.
#[cfg(not(feature = "ros"))]
pub fn ros2_publisher(_: &Scene) -> Result<Ros2Sink, AppError> {
    Err(AppError::flag(
        "--ros2-publish",
        "this avatarm was built without the ros feature; rebuild with `cargo build --features ros`",
    ))
}

/// The system clock now (ns since the Unix epoch).
pub fn unix_now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// The robot site's clock mapped onto the system clock (ns since the Unix epoch) by one offset
/// taken once, so that every message of a frame (its erased image, its mask) carries the same
/// stamp, as ROS's exact-time synchronisers need.
#[derive(Debug, Clone, Copy)]
pub struct SiteToUnix {
    /// The system clock minus the site's (s).
    unix_minus_site_s: f64,
}

impl SiteToUnix {
    /// The offset now.
    pub fn now(clock: &avatarm_net::SiteClock) -> Self {
        Self {
            unix_minus_site_s: unix_now_ns() as f64 * 1e-9 - clock.now_s(),
        }
    }

    /// `site_s` (the site's clock, s) on the system clock (ns; 0 where it would be before the
    /// epoch or is not finite).
    pub fn stamp_ns(&self, site_s: f64) -> u64 {
        let unix_s = site_s + self.unix_minus_site_s;
        if unix_s.is_finite() && unix_s > 0.0 {
            (unix_s * 1e9) as u64
        } else {
            0
        }
    }
}

/// `LEVEL source: message`, a safety event's line on `/avatarm/safety`.
pub fn safety_line(level: LogLevel, source: &str, message: &str) -> String {
    let level = match level {
        LogLevel::Info => "INFO",
        LogLevel::Warning => "WARN",
        LogLevel::Error => "ERROR",
    };
    format!("{level} {source}: {message}")
}

/// A joint velocity command (`names` in the velocities' order, rad/s or m/s) at `stamp_ns`;
/// whether it was handed over (a full queue drops it).
#[cfg(feature = "ros")]
pub fn publish_command(
    sink: &Ros2Sink,
    stamp_ns: u64,
    names: &[String],
    velocities: &[f64],
) -> bool {
    sink.publish(avatarm_ros::ros2::publish::Outgoing::Command {
        stamp_ns,
        names: names.to_vec(),
        velocities: velocities.to_vec(),
    })
}

/// A safety event at `stamp_ns`; whether it was handed over.
#[cfg(feature = "ros")]
pub fn publish_safety(
    sink: &Ros2Sink,
    stamp_ns: u64,
    level: LogLevel,
    source: &str,
    message: &str,
) -> bool {
    sink.publish(avatarm_ros::ros2::publish::Outgoing::Safety {
        stamp_ns,
        text: safety_line(level, source, message),
    })
}

/// An erased frame (JPEG) captured at `stamp_ns`; whether it was handed over.
#[cfg(feature = "ros")]
pub fn publish_erased(sink: &Ros2Sink, stamp_ns: u64, jpeg: Vec<u8>) -> bool {
    sink.publish(avatarm_ros::ros2::publish::Outgoing::Erased { stamp_ns, jpeg })
}

/// A mask (PNG, 255 = robot) of the frame captured at `stamp_ns`; whether it was handed over.
#[cfg(feature = "ros")]
pub fn publish_mask(sink: &Ros2Sink, stamp_ns: u64, png: Vec<u8>) -> bool {
    sink.publish(avatarm_ros::ros2::publish::Outgoing::Mask { stamp_ns, png })
}

/// Messages the sink dropped (its queue full).
#[cfg(feature = "ros")]
pub fn dropped(sink: &Ros2Sink) -> u64 {
    sink.dropped()
}

#[cfg(not(feature = "ros"))]
mod without_ros {
    //! The same calls without the feature: no sink exists, so none is ever made.
    use super::{LogLevel, Ros2Sink};

    /// See the feature's version.
    pub fn publish_command(sink: &Ros2Sink, _: u64, _: &[String], _: &[f64]) -> bool {
        match *sink {}
    }

    /// See the feature's version.
    pub fn publish_safety(sink: &Ros2Sink, _: u64, _: LogLevel, _: &str, _: &str) -> bool {
        match *sink {}
    }

    /// See the feature's version.
    pub fn publish_erased(sink: &Ros2Sink, _: u64, _: Vec<u8>) -> bool {
        match *sink {}
    }

    /// See the feature's version.
    pub fn publish_mask(sink: &Ros2Sink, _: u64, _: Vec<u8>) -> bool {
        match *sink {}
    }

    /// See the feature's version.
    pub fn dropped(sink: &Ros2Sink) -> u64 {
        match *sink {}
    }
}
#[cfg(not(feature = "ros"))]
pub use without_ros::{dropped, publish_command, publish_erased, publish_mask, publish_safety};
