//! The crate's one error type: each names the file, the flag or the listing entry at fault.

use std::path::PathBuf;

/// What can go wrong importing footage or a bag.
#[derive(Debug, thiserror::Error)]
pub enum FootageError {
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
        /// `read`, `create` or `write`.
        action: &'static str,
        /// Why.
        source: std::io::Error,
    },
    /// An image file that could not be read or written.
    #[error("{path}: cannot {action} image: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// `read` or `write`.
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
    /// A robot description (`--urdf`), a lens or a fit the core refused.
    #[error(transparent)]
    Core(#[from] avatarm_core::Error),
    /// A report that could not be serialised.
    #[error("report: {0}")]
    Json(#[from] serde_json::Error),
}

impl FootageError {
    /// An [`FootageError::Input`].
    pub fn input(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Input {
            what: what.into(),
            message: message.into(),
        }
    }

    /// A [`FootageError::Io`] writing `path`.
    pub fn write(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            action: "write",
            source,
        }
    }

    /// A [`FootageError::Io`] creating the folder `path`.
    pub fn create(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            action: "create",
            source,
        }
    }

    /// A [`FootageError::Image`] writing `path`.
    pub fn write_image(path: impl Into<PathBuf>, source: image::ImageError) -> Self {
        Self::Image {
            path: path.into(),
            action: "write",
            source,
        }
    }
}
