//! The crate's error: each names the file, the topic or the message.

use std::path::PathBuf;

/// A recording that cannot be written or read: the file, and where in it.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not an MCAP file, or a damaged one.
    #[error("{path}: not a readable MCAP file: {source}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// Why.
        source: mcap::McapError,
    },
    /// One message is wrong.
    #[error("{path}: {topic}, message {index}: {message}")]
    Message {
        /// The file.
        path: PathBuf,
        /// Its topic.
        topic: String,
        /// Its index on the topic (0-based).
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// A value to write is wrong, or the file as a whole.
    #[error("{path}: {message}")]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}
