//! The crate error, wrapping each module's error.
//!
//! Each module owns one `thiserror` enum; this one wraps them with `#[from]` so the CLI and the
//! service can carry any of them. HTTP mapping lives in `api::problem`, where every variant gets
//! a stable `code` and a status.
use crate::audio::AudioError;
use crate::config::ConfigError;
use crate::models::ModelError;
use crate::queue::QueueError;
use crate::worker::WorkerError;

/// Any error choreo can raise.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Queue(#[from] QueueError),
    #[error(transparent)]
    Audio(#[from] AudioError),
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Worker(#[from] WorkerError),
    #[error("i/o: {0}")]
    Io(#[from] std::io::Error),
}

impl Error {
    /// Stable kebab-case name of the failure, for logs and problem bodies.
    pub fn code(&self) -> &'static str {
        match self {
            Error::Config(_) => "config",
            Error::Queue(e) => e.code(),
            Error::Audio(_) => "audio",
            Error::Model(_) => "model",
            Error::Worker(e) => e.code(),
            Error::Io(_) => "io",
        }
    }

    /// Whether trying again later may succeed.
    pub fn is_retryable(&self) -> bool {
        match self {
            Error::Config(_) => false,
            Error::Queue(e) => e.is_retryable(),
            // A song that failed to decode once fails again.
            Error::Audio(_) => false,
            Error::Model(_) => false,
            Error::Worker(e) => e.is_retryable(),
            Error::Io(_) => true,
        }
    }
}

/// The crate result.
pub type Result<T, E = Error> = std::result::Result<T, E>;
