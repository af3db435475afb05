//! Two sites over Zenoh (`docs/network.md`): `avatarm serve` at the robot ([`serve`]), `avatarm
//! join` at the operator or an observer ([`join`]), `avatarm router` between them, and the
//! command-line settings they share ([`NetArgs`]).
//!
//! - [`serve`]: the robot site's control loop and report.
//! - [`join`]: the operator's hand, physics twin and targets; the observer.
//! - [`video`]: the robot site's erased video, coded and published.
//! - [`site_camera`]: where the robot site's camera comes from (simulated, a webcam, a
//!   recording played live, a ROS 2 driver's topic); [`driver_calibration`]: a ROS 2
//!   camera's size, K, lens and pose from its driver (`CameraInfo`, `/tf`).
//! - [`window`]: the operator's or observer's window (`join --window`).

#[cfg(feature = "ros")]
pub mod driver_calibration;
pub mod join;
pub mod ros2_out;
pub mod serve;
pub mod site_camera;
pub mod video;
pub mod window;

use std::path::PathBuf;

use avatarm_net::{Credentials, Keys, NetConfig, Role, TlsFiles};
use avatarm_scene::Scene;

use crate::AppError;

/// Network settings on the command line (serve, join, router).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct NetArgs {
    /// The session's name: keys are avatarm/SITE/... (letters, digits, '-', '_').
    #[arg(long, value_name = "SITE", default_value = "desk")]
    pub site: String,
    /// serve (listening) and router: a dictionary of user:password lines, who may connect;
    /// join and serve --connect: a file whose first line is this side's user:password.
    #[arg(long, value_name = "FILE")]
    pub credentials: Option<PathBuf>,
    /// serve/router: a user (in the dictionary) allowed to command the robot (repeatable;
    /// default: the dictionary's first user).
    #[arg(long = "operator", value_name = "USER")]
    pub operators: Vec<String>,
    /// router: a user (in its dictionary) that a robot site logs in as when it connects
    /// (`serve --connect`); only such users may publish the robot's joint states, status and
    /// video through the router (repeatable).
    #[arg(long = "robot-site", value_name = "USER")]
    pub robot_sites: Vec<String>,
    /// QUIC: the certificate authority's certificate (PEM), to check the other side.
    #[arg(long = "tls-ca", value_name = "FILE")]
    pub tls_ca: Option<PathBuf>,
    /// QUIC: this side's certificate (PEM; a quic/ listener needs it).
    #[arg(long = "tls-cert", value_name = "FILE")]
    pub tls_cert: Option<PathBuf>,
    /// QUIC: this side's private key (PEM).
    #[arg(long = "tls-key", value_name = "FILE")]
    pub tls_key: Option<PathBuf>,
    /// serve/router: listen without authentication (a trusted LAN or a test).
    #[arg(long = "insecure-lan")]
    pub insecure_lan: bool,
}

impl NetArgs {
    /// The network configuration for `role`, listening on `listen` or connecting to
    /// `connect`. Errors name the flag.
    pub fn config(
        &self,
        role: Role,
        listen: Vec<String>,
        connect: Vec<String>,
    ) -> Result<NetConfig, AppError> {
        let keys = Keys::new(&self.site)?;
        let listens = !listen.is_empty();
        let (credentials, dictionary, operators) = match (&self.credentials, listens) {
            (Some(path), true) => {
                let first = Credentials::from_file(path)?;
                // A router's operators are named (its first user may be a robot site).
                let operators = if self.operators.is_empty() && role != Role::Router {
                    vec![first.user]
                } else {
                    self.operators.clone()
                };
                (None, Some(path.clone()), operators)
            }
            (Some(path), false) => (Some(Credentials::from_file(path)?), None, Vec::new()),
            (None, _) => (None, None, Vec::new()),
        };
        let tls = (self.tls_ca.is_some() || self.tls_cert.is_some() || self.tls_key.is_some())
            .then(|| TlsFiles {
                root_ca: self.tls_ca.clone(),
                certificate: self.tls_cert.clone(),
                private_key: self.tls_key.clone(),
            });
        let config = NetConfig {
            role,
            keys,
            listen,
            connect,
            credentials,
            dictionary,
            operators,
            robot_sites: self.robot_sites.clone(),
            tls,
            insecure_lan: self.insecure_lan,
        };
        config.validate()?;
        Ok(config)
    }
}

/// The robot site's video coding from the command line: `codec` (`jpeg` or `h264`), JPEG
/// quality (1-100), H.264 bit rate (Mbit/s) and keyframe interval (s), at the camera's `fps`.
/// Errors name the flag.
pub fn encoder_settings(
    codec: &str,
    jpeg_quality: u8,
    bitrate_mbit_s: f64,
    keyframe_interval_s: f64,
    fps: f64,
) -> Result<avatarm_net::codec::EncoderSettings, AppError> {
    let codec = avatarm_net::msg::Codec::from_name(codec)
        .ok_or_else(|| AppError::flag("--codec", format!("'{codec}' must be jpeg or h264")))?;
    if !(bitrate_mbit_s.is_finite() && (0.01..=200.0).contains(&bitrate_mbit_s)) {
        return Err(AppError::flag(
            "--bitrate",
            format!("{bitrate_mbit_s} Mbit/s must be 0.01..=200"),
        ));
    }
    let settings = avatarm_net::codec::EncoderSettings {
        codec,
        jpeg_quality,
        jpeg_encoder: avatarm_net::codec::JpegEncoder::default(),
        bitrate_bps: (bitrate_mbit_s * 1e6).round() as u32,
        fps: fps.clamp(1.0, 240.0) as f32,
        keyframe_interval_s,
    };
    settings.validate()?;
    Ok(settings)
}

/// The scene's fingerprint: its file's text, hashed (both sites must run the same scene).
pub fn scene_fingerprint(scene: &Scene) -> Result<String, AppError> {
    let text = std::fs::read(&scene.path).map_err(|source| AppError::Io {
        path: scene.path.clone(),
        action: "read",
        source,
    })?;
    Ok(avatarm_net::msg::fingerprint(&text))
}

/// `avatarm router`: a Zenoh router until `duration_s` passes (or the process is killed).
pub fn router(config: &NetConfig, duration_s: Option<f64>) -> Result<(), AppError> {
    let session = avatarm_net::Router::open(config)?;
    bevy::log::info!(
        "router on {:?}, connected to {:?}",
        config.listen,
        config.connect
    );
    let started = std::time::Instant::now();
    while duration_s.is_none_or(|d| started.elapsed().as_secs_f64() < d) {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    drop(session);
    Ok(())
}
