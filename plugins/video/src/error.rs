//! The crate's one error type.

use std::path::PathBuf;

/// What can go wrong with a video source: a recorded session that cannot be read, a frame that
/// does not fit its size, format or clock.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// The timestamps file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line of the timestamps file is wrong.
    #[error("{path}:{line}: {message}")]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The folder has no frames listed.
    #[error("{path}: no frames listed")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// A frame whose bytes do not fit its size or format, or whose timestamps are not finite.
    #[error("{what}: {message}")]
    BadFrame {
        /// Which frame (`video frame 12`, `YUYV frame 640x480`).
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A compressed frame that does not decode.
    #[error("{what}: {source}")]
    Decode {
        /// Which frame.
        what: String,
        /// The decoder's error.
        source: image::ImageError,
    },
}
