//! The library's one error type. Every variant's message names what a person must fix.

use std::path::PathBuf;

/// Everything the library can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scene file (or a file it references) is malformed or breaks the contract of
    /// docs/SCENE_FORMAT.md. `key` is the TOML key path (`shapes[2].vertices`) or `line N`.
    #[error("{file}: {key}: {message}")]
    Scene { file: PathBuf, key: String, message: String },
    /// A command-line value or combination of options that cannot be honoured.
    #[error("{0}")]
    Usage(String),
    /// No usable GPU adapter, or the chosen one lacks what the scene needs.
    #[error("{0}")]
    Adapter(String),
    /// The scene does not fit the device's limits (buffer or binding sizes).
    #[error("{0}")]
    Limits(String),
    /// The GPU failed during the run (device lost, out of memory, validation).
    #[error("GPU failure: {0}")]
    Gpu(String),
    /// An input named by the user (the scene, a checkpoint, an image to compare) cannot be
    /// read: missing, unreadable, or not a regular file (a folder, a FIFO, a device).
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// An image could not be encoded or decoded.
    #[error("{path}: {message}")]
    Image { path: PathBuf, message: String },
}

impl Error {
    /// Shorthand for a scene error.
    pub fn scene(file: impl Into<PathBuf>, key: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Scene { file: file.into(), key: key.into(), message: message.into() }
    }

    /// Whether this error is the user's to fix before any work starts (exit status 2).
    pub fn is_usage(&self) -> bool {
        matches!(self, Error::Scene { .. } | Error::Usage(_) | Error::Limits(_) | Error::Input { .. })
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
