//! Avatarm: manipulate real objects through a robot arm that is hidden from view.
//!
//! This crate is the application; its rooms (docs/architecture.md shows them and the data flow):
//!
//! - [`cli`]: the `avatarm` command line: the clap types, the scene overrides, dispatch, and the
//!   `avatarm robot` description check. `main.rs` only calls [`cli::main`].
//! - [`app`]: the Bevy app assembled from the plugins ([`build_app`], [`AvatarmPlugins`]), the
//!   app's one system-set enum ([`AvatarmSystems`]), and the background sources.
//! - [`preview`]: the desktop preview (panel, keys, status line, live scores) and the XR view.
//! - [`teleop`]: live teleoperation of a scene's `[task]` with any hand source.
//! - [`replay`]: headless scene replay: capture, scores, the report and the task's trials.
//! - [`score`]: the capture-and-score path shared by the replay and the live scores.
//! - [`bench`]: `avatarm bench dr`, `avatarm bench twin` and `avatarm bench control`.
//! - [`import`]: `avatarm import`: a real Leap recording to a `.hand.jsonl`, with a picture.
//! - [`progress`]: the one progress-bar style.
//! - [`error`]: the crate's error type ([`AppError`]).
//!
//! Scenes come from [`avatarm_scene`] (re-exported as [`scene`]), the maths from
//! `avatarm_core`, the ECS plugins from the `avatarm_*` plugin crates.

pub mod app;
pub mod bag;
pub mod bench;
pub mod calibrate;
pub mod cli;
pub mod error;
pub mod footage;
pub mod import;
pub mod net;
pub mod preview;
pub mod progress;
pub mod replay;
pub mod score;
pub mod session;
pub mod teleop;

pub use app::{AppTwin, AvatarmPlugins, AvatarmSystems, Mode, SceneResource, build_app};
pub use avatarm_scene as scene;
pub use error::AppError;
