//! Why a job attempt ends: one error for every stage a worker runs, with its stable `code()`
//! and whether another attempt may succeed.
use super::standalone;
use crate::audio::AudioError;
use crate::models::{Cancelled, ModelError, ModelId};
use crate::queue::QueueError;

/// Errors that end a job attempt.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    #[error("queue: {0}")]
    Queue(#[from] QueueError),
    #[error("audio: {0}")]
    Audio(AudioError),
    #[error("model: {0}")]
    Model(ModelError),
    #[error("model {} is not available on this server", .0.0)]
    ModelUnavailable(ModelId),
    /// The command line's form of [`WorkerError::ModelUnavailable`]: the folder is the user's
    /// own, so naming it and what it holds is what helps (the service never names its paths).
    #[error("{}", standalone::not_in_folder(.model, .dir, .found))]
    ModelNotInFolder {
        model: ModelId,
        dir: std::path::PathBuf,
        /// The ids of the models the folder holds.
        found: Vec<String>,
    },
    #[error("invalid job options: {0}")]
    InvalidOptions(String),
    #[error("writing results: {0}")]
    Io(#[from] std::io::Error),
    #[error("{0}")]
    Export(String),
    #[error("motion: {0}")]
    Motion(#[from] crate::motion::MotionError),
    #[error("report: {0}")]
    Metrics(#[from] crate::metrics::MetricsError),
    #[error("cancelled")]
    Cancelled,
    #[error("the job panicked: {0}")]
    Panicked(String),
    #[error("artifact store: {0}")]
    Artifact(#[from] crate::artifacts::ArtifactError),
}

impl From<ModelError> for WorkerError {
    fn from(e: ModelError) -> Self {
        match e {
            ModelError::Cancelled(_) => WorkerError::Cancelled,
            other => WorkerError::Model(other),
        }
    }
}

impl From<AudioError> for WorkerError {
    fn from(e: AudioError) -> Self {
        match e {
            // Stopped at a checkpoint: cancelled, or the server is shutting down.
            AudioError::Cancelled => WorkerError::Cancelled,
            other => WorkerError::Audio(other),
        }
    }
}

impl From<Cancelled> for WorkerError {
    fn from(_: Cancelled) -> Self {
        WorkerError::Cancelled
    }
}

impl WorkerError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            WorkerError::Queue(e) => e.code(),
            WorkerError::Audio(e) => e.code(),
            // Stable for clients: no model failure is one a client can fix (the API refuses what a
            // model does not take before a job exists); the finer `ModelError::code` is logged.
            WorkerError::Model(_) => "model-failed",
            WorkerError::ModelUnavailable(_) => "model-unavailable",
            WorkerError::ModelNotInFolder { .. } => "model-unavailable",
            WorkerError::InvalidOptions(_) => "invalid-job-options",
            WorkerError::Io(_) => "result-io",
            WorkerError::Export(_) => "export-failed",
            WorkerError::Motion(e) => e.code(),
            WorkerError::Metrics(_) => "report-failed",
            WorkerError::Cancelled => "cancelled",
            WorkerError::Panicked(_) => "job-panicked",
            WorkerError::Artifact(e) => e.code(),
        }
    }

    /// Whether another attempt may succeed; deterministic failures are not retried.
    pub fn is_retryable(&self) -> bool {
        match self {
            WorkerError::Queue(e) => e.is_retryable(),
            WorkerError::Audio(e) => !e.is_client_error(),
            WorkerError::Model(_) => false,
            WorkerError::ModelUnavailable(_) => false,
            WorkerError::ModelNotInFolder { .. } => false,
            WorkerError::InvalidOptions(_) => false,
            WorkerError::Io(_) => true,
            WorkerError::Export(_) => false,
            WorkerError::Motion(e) => e.is_retryable(),
            WorkerError::Metrics(_) => false,
            WorkerError::Cancelled => false,
            WorkerError::Panicked(_) => false,
            WorkerError::Artifact(e) => e.is_retryable(),
        }
    }
}
