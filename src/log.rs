//! The process's log: one filter for every command ([`LOG_FILTER`]), Bevy's log plugin with it
//! ([`log_plugin`], [`with_log`]) or, for the network commands, whose loops run before or
//! without an app, a subscriber of their own ([`init_log`]); and, built with the `trace` feature,
//! the Chrome trace of Bevy's spans (docs/latency.md, "Profile").

use bevy::app::{PluginGroup, PluginGroupBuilder};
use bevy::prelude::default;

/// The log filter of every command where `RUST_LOG` is not set: Avatarm's info, and only the
/// warnings of the libraries that log routine events at info (Zenoh's sessions, RustDDS's
/// discovery and its mio wake-ups: hundreds of lines a second while a DDS link runs).
pub const LOG_FILTER: &str =
    "info,zenoh=warn,zenoh_transport=warn,rustdds=warn,ros2_client=warn,wgpu=error,naga=warn";

/// Bevy's log plugin with [`LOG_FILTER`] and Bevy's own [`bevy::log::DEFAULT_FILTER`]; where
/// `RUST_LOG` is set, that alone (Bevy adds its directives on top of the plugin's filter: a
/// `RUST_LOG=debug` would leave Zenoh's and RustDDS's at warnings), as in the network commands'
/// [`init_log`].
pub fn log_plugin() -> bevy::log::LogPlugin {
    let filter = if std::env::var_os("RUST_LOG").is_some() {
        String::new()
    } else {
        format!("{LOG_FILTER},{}", bevy::log::DEFAULT_FILTER)
    };
    bevy::log::LogPlugin {
        filter,
        ..default()
    }
}

/// `plugins` with the app's log: Bevy's [`log_plugin`]; or, where a Chrome trace is asked for
/// ([`chrome_trace_asked`]: the `trace` feature and `AVATARM_TRACE_CHROME` set), the
/// network commands' subscriber ([`init_log`]) in its place, so that the preview's
/// and the replay's spans go to the trace as the robot site's do (docs/latency.md, "Profile").
/// Where this process has its log already (an app built before: a replay of several cameras,
/// a bench's runs), none: Bevy's plugin would say ERROR that it could not set it again.
pub fn with_log(plugins: impl PluginGroup) -> PluginGroupBuilder {
    let plugins = plugins.build();
    if chrome_trace_asked() {
        init_log();
    }
    if bevy::log::tracing::dispatcher::has_been_set() {
        plugins.disable::<bevy::log::LogPlugin>()
    } else {
        plugins.set(log_plugin())
    }
}

/// Logs to stderr for the network commands (their loops run before or without an app):
/// `RUST_LOG` when set, else [`LOG_FILTER`]. Built with the `trace`
/// feature and `AVATARM_TRACE_CHROME=FILE.json` set, Bevy's spans go to that Chrome trace too
/// (written when the command ends: [`finish_trace`]).
pub fn init_log() {
    // Once a process: a second Chrome layer on the same file would truncate the first's trace
    // (a replay of several cameras, a bench's runs, build an app each).
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(init_log_once);
}

/// [`init_log`]'s work, done once.
fn init_log_once() {
    use bevy::log::tracing_subscriber::{self, EnvFilter};
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(LOG_FILTER));
    #[cfg(feature = "trace")]
    if let Some(path) = std::env::var_os("AVATARM_TRACE_CHROME") {
        use bevy::log::tracing_subscriber::prelude::*;
        let (chrome, guard) = tracing_chrome::ChromeLayerBuilder::new()
            .file(path)
            .include_args(true)
            .build();
        let ok = tracing_subscriber::registry()
            .with(filter)
            .with(tracing_subscriber::fmt::layer().with_writer(std::io::stderr))
            .with(chrome)
            .try_init()
            .is_ok();
        if ok {
            *TRACE
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(guard);
        }
        return;
    }
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}

/// Whether [`init_log`] will write a Chrome trace: built with the `trace` feature and
/// `AVATARM_TRACE_CHROME` set.
pub fn chrome_trace_asked() -> bool {
    cfg!(feature = "trace") && std::env::var_os("AVATARM_TRACE_CHROME").is_some()
}

/// The Chrome trace's writer, flushed and closed by [`finish_trace`].
#[cfg(feature = "trace")]
static TRACE: std::sync::Mutex<Option<tracing_chrome::FlushGuard>> = std::sync::Mutex::new(None);

/// Writes out the Chrome trace [`init_log`] started, if it did (feature `trace`).
pub fn finish_trace() {
    #[cfg(feature = "trace")]
    drop(
        TRACE
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take(),
    );
}

/// [`init_log`] with only warnings and errors (a bench's progress bar owns the terminal).
pub fn init_log_quiet() {
    use bevy::log::tracing_subscriber::{self, EnvFilter};
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("error"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}
