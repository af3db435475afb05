//! Avatarm's scene files, parsed and validated, without Bevy.
//!
//! A scene (TOML, documented in `docs/scene-format.md`) says which robot the camera sees, where
//! the camera is and how it behaves, what else is in the room, what the robot does over time,
//! how the robot is erased, and which teleoperation task is measured. Paths inside a scene are
//! relative to the scene file. [`Scene::load`] parses and checks every value when the scene
//! loads: a scene that loads can run, and every error names the file and the field.
//!
//! - [`spec`]: the file as written, one struct per table ([`spec::SceneFile`]).
//! - [`mod@load`]: the loaded scene ([`Scene`]): robot model, cameras, props, timeline, task.
//! - [`prop`]: the room's objects ([`prop::Prop`], [`prop::PropShape`]) and the bottle's
//!   proportions.
//! - [`task`]: the paper's pouring task as data ([`task::PouringTask`]) and its real side
//!   ([`task::TrialSetup`]).
//! - [`chess`]: the paper's chess scene as data (`[chess]`: board, pieces, moves;
//!   [`chess::ChessSetup`]).
//! - [`hand`]: which hand teleoperates the task ([`hand::HandChoice`]).
//! - [`finite`]: the check that every number in the file is finite.
//! - [`error`]: the crate's error type ([`SceneError`]).

pub mod chess;
pub mod error;
pub mod finite;
pub mod hand;
pub mod load;
pub mod prop;
pub mod spec;
pub mod task;

pub use error::SceneError;
pub use load::{HeadRig, SINGLE_CAMERA, Scene};
pub use spec::TwinSpec;

/// The types most users of scenes need.
pub mod prelude {
    pub use crate::error::SceneError;
    pub use crate::hand::HandChoice;
    pub use crate::load::Scene;
    pub use crate::prop::{Prop, PropShape};
    pub use crate::spec::{BackgroundSpec, SceneFile, TwinSpec};
    pub use crate::task::{PouringTask, TrialSetup};
}
