//! Avatarm: manipulate real objects through a robot arm that is hidden from view.
//!
//! This crate is the application; its rooms (docs/architecture.md shows them and the data flow):
//!
//! - [`cli`]: the `avatarm` command line: one module per command, each a clap `Args` struct
//!   with its own `run()`, and a dispatch. `main.rs` only calls [`cli::main`].
//! - [`app`]: the app's base assembled from the plugins ([`app::build_app`],
//!   [`AvatarmPlugins`]), the app's one system-set enum ([`AvatarmSystems`]), and the
//!   background sources. The front ends build on it: [`preview::build_app`],
//!   [`replay::build_app`], [`net::video::build_app`].
//! - [`preview`]: the desktop preview (panel, keys, status line, live scores, the camera
//!   switch) and the XR view.
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
pub mod bench;
pub mod cli;
pub mod error;
pub mod import;
pub mod log;
pub mod net;
pub mod preview;
pub mod progress;
pub mod replay;
pub mod score;
pub mod session;
pub mod teleop;

pub use app::{AppBase, AppTwin, AvatarmPlugins, AvatarmSystems, Runner, SceneResource};
pub use avatarm_scene as scene;
pub use error::AppError;
