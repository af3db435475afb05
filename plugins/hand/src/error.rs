//! The crate's one error type.

use std::path::PathBuf;

/// What can go wrong with a hand source.
#[derive(Debug, thiserror::Error)]
pub enum HandError {
    /// A recording could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The recording.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A recording holds a line or a frame that cannot be used; the cause names the line and
    /// the joint.
    #[error("{path}: {source}")]
    Recording {
        /// The recording.
        path: PathBuf,
        /// What the parser found.
        source: Box<avatarm_core::Error>,
    },
    /// A tracker recording (a Leap JSON recording) that cannot be used; the message names the
    /// frame, the hand and the finger.
    #[error("{path}: {message}")]
    BadRecording {
        /// The recording.
        path: PathBuf,
        /// What is wrong, and where.
        message: String,
    },
    /// A recording with no hand frame in it.
    #[error("{path}: no hand frames")]
    Empty {
        /// The recording.
        path: PathBuf,
    },
    /// A tracker's frame that cannot be used (a non-finite number, a zero-length bone or
    /// orientation); names the tracker and the joint or bone.
    #[error("{tracker} {what}: {message}")]
    BadTrackerFrame {
        /// `OpenXR hand` or `Leap`.
        tracker: &'static str,
        /// The joint or bone.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A converted frame the core refused.
    #[error(transparent)]
    Frame(Box<avatarm_core::Error>),
    /// A device source could not start.
    #[error("{source_name}: {message}")]
    Device {
        /// The source.
        source_name: &'static str,
        /// Why.
        message: String,
    },
}

impl From<avatarm_core::Error> for HandError {
    fn from(e: avatarm_core::Error) -> Self {
        Self::Frame(Box::new(e))
    }
}
