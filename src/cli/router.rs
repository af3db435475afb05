//! `avatarm router`: a Zenoh router between the sites, fanning the video out to observers.

use clap::Args;

use crate::AppError;

/// The arguments of `avatarm router`.
#[derive(Args, Debug)]
pub struct RouterArgs {
    /// Where to listen.
    #[arg(long, value_name = "ENDPOINT", default_value = "tcp/0.0.0.0:7448")]
    listen: Vec<String>,
    /// Robot sites or other routers to connect to (on a trusted network, --insecure-lan;
    /// with a dictionary the robot site connects to the router instead).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// Stop after this many seconds (default: until killed).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    #[command(flatten)]
    net: crate::net::NetArgs,
}

impl RouterArgs {
    /// Runs `avatarm router`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            listen,
            connect,
            duration,
            net,
        } = self;
        crate::log::init_log();
        let config = net.config(avatarm_net::Role::Router, listen, connect)?;
        crate::net::router(&config, duration)
    }
}
