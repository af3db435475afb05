//! `avatarm relay`: the seeded impairment relay (delay, jitter, loss, a bandwidth cap)
//! between two sites, where `tc netem` is not available.

use clap::Args;

use crate::AppError;

/// The arguments of `avatarm relay`.
#[derive(Args, Debug)]
pub struct RelayArgs {
    /// tcp or udp.
    #[arg(long, value_parser = ["tcp", "udp"], default_value = "tcp")]
    transport: String,
    /// Where the traffic goes (HOST:PORT).
    #[arg(long, value_name = "HOST:PORT")]
    to: std::net::SocketAddr,
    /// One-way delay each direction (ms).
    #[arg(long = "delay-ms", default_value_t = 0.0)]
    delay_ms: f64,
    /// Extra delay uniform in 0..JITTER (ms).
    #[arg(long = "jitter-ms", default_value_t = 0.0)]
    jitter_ms: f64,
    /// Datagrams dropped (%, UDP).
    #[arg(long = "loss", default_value_t = 0.0)]
    loss_pct: f64,
    /// Bandwidth cap each direction (Mbit/s).
    #[arg(long = "mbit-s")]
    mbit_s: Option<f64>,
    /// Seed of the loss and jitter.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// TCP: what each direction holds at most (KiB, at least 64): delayed, queued behind
    /// the cap or held through a cut; when full the sender is pushed back.
    #[arg(long = "queue-kib", default_value_t = 4096)]
    queue_kib: usize,
    /// Stop after this many seconds (default: until killed).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
}

impl RelayArgs {
    /// Runs `avatarm relay`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            transport,
            to,
            delay_ms,
            jitter_ms,
            loss_pct,
            mbit_s,
            seed,
            queue_kib,
            duration,
        } = self;
        use avatarm_net::impair::{Impairment, Relay};
        let queue_bytes = queue_kib.checked_mul(1024).ok_or_else(|| {
            AppError::flag("--queue-kib", format!("{queue_kib} KiB is too large"))
        })?;
        let impairment = Impairment {
            delay_s: delay_ms / 1e3,
            jitter_s: jitter_ms / 1e3,
            loss: loss_pct / 100.0,
            bandwidth_bps: mbit_s.map(|m| m * 1e6),
            seed,
            queue_bytes,
        };
        impairment
            .validate()
            .map_err(|e| AppError::flag("avatarm relay", e.to_string()))?;
        let relay = if transport == "udp" {
            Relay::udp(to, impairment)
        } else {
            Relay::tcp(to, impairment)
        }
        .map_err(|e| AppError::flag("avatarm relay", e.to_string()))?;
        println!("{transport}/{} -> {to}", relay.local_addr());
        let started = std::time::Instant::now();
        while duration.is_none_or(|d| started.elapsed().as_secs_f64() < d) {
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        Ok(())
    }
}
