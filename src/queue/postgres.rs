//! The PostgreSQL store: many API and worker processes on many hosts share one queue.
//!
//! The queue's statements are in `sql.rs`, the same for both stores, so both keep one contract
//! (the tests in `tests/queue.rs` run against each); this file holds what is PostgreSQL's own.
//! Where SQLite has one writer, PostgreSQL has many: a claim selects its row `FOR UPDATE SKIP
//! LOCKED` inside the same `UPDATE … RETURNING`, so concurrent claims take different jobs without
//! waiting on each other. A trigger appends every status change to `job_events` and, when a job
//! becomes queued, sends `NOTIFY choreo_jobs`, which [`JobStore::watch`](super::JobStore::watch)
//! turns into a wake-up of this process's idle workers.
use super::sql::{Dialect, SqlStore};
use super::{QueueError, StoreFuture};
use crate::config::Secret;
use sqlx::postgres::{PgConnectOptions, PgListener, PgPoolOptions, PgQueryResult, Postgres};
use sqlx::Pool;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;
use uuid::Uuid;

/// The channel the job trigger notifies (see `migrations/postgres/`).
pub const CHANNEL: &str = "choreo_jobs";
/// Connections per process: workers hold none while a job runs, so a few serve many.
const MAX_CONNECTIONS: u32 = 8;
/// Pause before listening again after the notification connection failed.
const RELISTEN_AFTER: Duration = Duration::from_secs(1);

/// The jobs and songs of one PostgreSQL database.
pub type PgStore = SqlStore<Postgres>;

impl Dialect for Postgres {
    type Id = Uuid;

    // A row another claim (or reaper) is taking is passed over, not waited for, so N workers
    // claiming at once get N different jobs (or none), never the same one.
    const SKIP_LOCKED: &'static str = " FOR UPDATE SKIP LOCKED";

    fn backoff_factor(cap: &str) -> String {
        format!("(1::BIGINT << LEAST(attempts - 1, {cap})::INTEGER)")
    }

    fn id(id: Uuid) -> Uuid {
        id
    }

    fn uuid(id: Uuid) -> Result<Uuid, uuid::Error> {
        Ok(id)
    }

    fn rows_affected(done: &PgQueryResult) -> u64 {
        done.rows_affected()
    }

    fn watch(
        pool: &Pool<Postgres>,
        wake: Arc<Notify>,
        shutdown: CancellationToken,
    ) -> StoreFuture<'_, ()> {
        Box::pin(async move {
            while !shutdown.is_cancelled() {
                let mut listener = match PgListener::connect_with(pool).await {
                    Ok(listener) => listener,
                    Err(e) => {
                        tracing::warn!(error = %e, "LISTEN connection failed; idle workers poll until it is back");
                        tokio::select! {
                            _ = shutdown.cancelled() => return Ok(()),
                            _ = tokio::time::sleep(RELISTEN_AFTER) => continue,
                        }
                    }
                };
                if let Err(e) = listener.listen(CHANNEL).await {
                    tracing::warn!(error = %e, "LISTEN failed; idle workers poll until it is back");
                    tokio::select! {
                        _ = shutdown.cancelled() => return Ok(()),
                        _ = tokio::time::sleep(RELISTEN_AFTER) => continue,
                    }
                }
                // Jobs queued while we were not listening are found by the workers' poll.
                wake.notify_waiters();
                loop {
                    tokio::select! {
                        _ = shutdown.cancelled() => return Ok(()),
                        received = listener.recv() => match received {
                            Ok(_) => wake.notify_waiters(),
                            Err(e) => {
                                tracing::warn!(error = %e, "LISTEN connection lost; reconnecting");
                                break;
                            }
                        },
                    }
                }
            }
            Ok(())
        })
    }
}

impl SqlStore<Postgres> {
    /// Connects to `url` (`postgres://user:password@host:port/db`, or `?host=/socket/dir`) and
    /// runs the migrations; many processes may do this at once (sqlx takes an advisory lock).
    /// A query waits at most `acquire_timeout` for a connection (the config's `db_timeout_s`):
    /// while the server is down, sqlx keeps trying to connect until then, so this is how long a
    /// request waits before it is answered `503`.
    pub async fn connect(url: &Secret, acquire_timeout: Duration) -> Result<Self, QueueError> {
        let options = PgConnectOptions::from_str(url.expose())?;
        let pool = PgPoolOptions::new()
            .max_connections(MAX_CONNECTIONS)
            .acquire_timeout(acquire_timeout)
            .connect_with(options)
            .await?;
        sqlx::migrate!("./migrations/postgres").run(&pool).await?;
        Ok(Self::from_pool(pool))
    }
}
