//! A worker-only process (`choreo worker`): workers, reaper and wake-ups, no HTTP.
//!
//! It opens the same database and data dir an API process (`choreo serve --no-workers`) uses,
//! so API and worker processes scale apart: one API and N worker processes on one host, or on
//! many hosts sharing PostgreSQL and an S3 bucket.
use super::Context;
use crate::config::{Config, ConfigError};
use crate::models::{ModelError, Registry};
use crate::queue::{DataDir, QueueError, Requeued};
use std::sync::Arc;
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

/// Errors from starting a worker process.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    #[error("data dir {path}: {source}")]
    DataDir {
        path: String,
        source: std::io::Error,
    },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Queue(#[from] QueueError),
    #[error("loading models: {0}")]
    Models(#[from] ModelError),
    #[error(transparent)]
    Artifacts(#[from] crate::artifacts::ArtifactError),
}

impl StartError {
    /// Stable kebab-case name of the failure; a wrapped module error keeps its own code.
    pub fn code(&self) -> &'static str {
        match self {
            StartError::DataDir { .. } => "data-dir",
            StartError::Config(e) => e.code(),
            StartError::Queue(e) => e.code(),
            StartError::Models(_) => "models-load",
            StartError::Artifacts(e) => e.code(),
        }
    }
}

/// Running workers of one process.
pub struct WorkerProcess {
    shutdown: CancellationToken,
    handles: Vec<JoinHandle<()>>,
    count: usize,
}

impl WorkerProcess {
    /// Opens the store, requeues expired leases and starts `config.worker_count()` workers.
    pub async fn start(config: &Config) -> Result<Self, StartError> {
        let data = DataDir::create(&config.data_dir).map_err(|source| StartError::DataDir {
            path: config.data_dir.display().to_string(),
            source,
        })?;
        let store = crate::queue::open(
            &config.database()?,
            std::time::Duration::from_secs_f64(config.db_timeout_s),
        )
        .await?;
        let artifacts = crate::artifacts::open(config, data.clone())?;
        let registry = Arc::new(Registry::load(&config.models_dir)?);
        let data_dir = data.clone();
        let ctx: Context = super::context(store.clone(), artifacts, registry, data, config);
        let recovered = super::recover(store.as_ref(), ctx.policy).await?;
        if recovered != Requeued::default() {
            tracing::warn!(?recovered, "requeued jobs whose leases had expired");
        }
        let count = config.worker_count();
        let shutdown = CancellationToken::new();
        // The worker side's upkeep of stored data: this host's data dir, and retention.
        let sweep = crate::artifacts::sweep::spawn(
            store.clone(),
            data_dir,
            std::time::Duration::from_secs_f64(config.sweep_grace_s),
            shutdown.clone(),
        );
        let retention = crate::artifacts::retention::spawn(
            store.clone(),
            ctx.artifacts.clone(),
            config,
            shutdown.clone(),
        );
        let mut handles = super::start(ctx, count, shutdown.clone());
        handles.push(sweep);
        handles.extend(retention);
        handles.extend(crate::webhooks::spawn(store, config, shutdown.clone()));
        Ok(Self {
            shutdown,
            handles,
            count,
        })
    }

    /// How many workers run.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Stops claiming; running jobs stop at their next checkpoint and are requeued.
    pub async fn stop(self) {
        self.shutdown.cancel();
        for handle in self.handles {
            if let Err(e) = handle.await {
                tracing::error!(error = %e, "worker task failed");
            }
        }
    }
}
