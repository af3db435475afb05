//! The crate's one error type: each names the file, the flag or the listing entry at fault.

use std::path::PathBuf;

/// What can go wrong importing footage or a bag.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// An input that cannot be used: `what` names it (a flag such as `--image-topic`, a bag's
    /// path, a listing's entry such as `frames.csv line 4`).
    #[error("{what}: {message}")]
    Input {
        /// The flag, file or entry.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A file that could not be read.
    #[error("{path}: cannot {action}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// `read`.
        action: &'static str,
        /// Why.
        source: std::io::Error,
    },
    /// An image file that could not be read.
    #[error("{path}: cannot {action} image: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// `read`.
        action: &'static str,
        /// The image library's error.
        source: image::ImageError,
    },
    /// The recording could not be written.
    #[error(transparent)]
    Record(#[from] avatarm_record::RecordError),
    /// A camera file (intrinsics, distortion, pose) that could not be used.
    #[error(transparent)]
    CameraFile(#[from] avatarm_record::CameraFileError),
    /// A robot description (`--urdf`) the core refused.
    #[error(transparent)]
    Core(#[from] avatarm_core::Error),
}

impl ImportError {
    /// An [`ImportError::Input`].
    pub fn input(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Input {
            what: what.into(),
            message: message.into(),
        }
    }
}
