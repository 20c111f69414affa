//! ROS 2 recordings in MCAP (docs/recordings.md): profile `ros2`, messages in CDR with the 4-byte
//! encapsulation header, schemas `ros2msg` named `pkg/msg/Type` with the full definition text.
//!
//! - [`BagWriter`] writes one `.mcap` file, or a rosbag2 folder (`metadata.yaml` + `<name>_0.mcap`) as
//!   `ros2 bag record` does; chunked, zstd, with message/chunk indexes and the summary. [`BagWriter::flush`]
//!   closes the chunk in progress: a writer killed after it loses nothing written before it.
//! - [`Recording`] reads any ROS 2 MCAP file (zstd, lz4 or plain chunks) or rosbag2 folder whoever wrote
//!   it, streamed a chunk at a time (memory bounded whatever the file's size), every chunk's CRC checked
//!   before its messages are given out; a damaged chunk is skipped with a warning that counts what it
//!   held, every intact one is read; a file without its end (a killed writer) is recovered up to its last
//!   complete chunk, with a warning, not an error.
//! - [`cdr`] encodes and decodes the message types of `softcontact-msgs`.
//!
//! Pure: files in, files out; no sockets, threads or clocks (times are given by the caller).

mod any;
pub mod cdr;
mod metadata;
mod read;
mod write;

pub use any::AnyMessage;
pub use metadata::Qos;
pub use read::{BagMessage, Messages, RECORD_LIMIT, Recording, Topic};
pub use write::{BagWriter, WriteStats};

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// (The error is in the message, not a source as well: `{:#}` would print it twice.)
    #[error("{path}: {error}")]
    Io { path: PathBuf, error: std::io::Error },
    #[error("{0}: not a regular file (a recording is an .mcap file or a rosbag2 folder)")]
    NotAFile(PathBuf),
    #[error("{0}: the file is empty")]
    Empty(PathBuf),
    #[error("{path}: truncated with nothing to recover ({reason})")]
    Truncated { path: PathBuf, reason: String },
    #[error("{0}: not an MCAP file (no MCAP magic at its start)")]
    NotMcap(PathBuf),
    #[error("{0}: not a recording: neither an .mcap file nor a rosbag2 folder with .mcap files")]
    NotRecording(PathBuf),
    #[error("{path}: {message}")]
    Metadata { path: PathBuf, message: String },
    #[error("{path}: MCAP: {source}")]
    Mcap { path: PathBuf, source: mcap::McapError },
    #[error("MCAP writer: {0}")]
    Write(#[from] mcap::McapError),
    #[error("topic {topic}: recorded as {found}, read as {expected}")]
    WrongType { topic: String, found: String, expected: String },
    #[error("topic {topic}: message encoding `{encoding}`, not ROS 2 CDR")]
    NotCdr { topic: String, encoding: String },
    #[error("topic {topic} ({type_name}): {message}")]
    Cdr { topic: String, type_name: String, message: String },
    #[error("topic {0} was not added to the recording")]
    UnknownTopic(String),
    #[error("{0}")]
    Invalid(String),
}

pub type Result<T, E = BagError> = std::result::Result<T, E>;

/// Normalises a ROS 2 type name to `pkg/msg/Type` (ROS 1-style `pkg/Type` is accepted on reading).
pub fn type_path(name: &str) -> String {
    match name.split('/').collect::<Vec<_>>()[..] {
        [package, ty] => format!("{package}/msg/{ty}"),
        _ => name.to_string(),
    }
}
