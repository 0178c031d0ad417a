//! The queue's rules, written once for both SQL stores.
//!
//! [`SqlStore`] implements [`super::JobStore`] (in `sql/jobs.rs`), [`SongStore`] (in `sql/songs.rs`) and (in `sql/rigs.rs`) [`super::RigStore`] over any sqlx database that is a
//! [`Dialect`]: every statement and flow (register with its idempotency key, claim, heartbeat,
//! complete, fail, cancel, the requeue of expired leases, songs) is here, once. Both drivers bind
//! `$N` placeholders, and both schemas keep times as integer milliseconds and JSON as TEXT, so
//! the same SQL runs on each. What is left apart is what truly differs between the two
//! databases, the [`Dialect`]: how ids are stored, row locking, the backoff arithmetic and
//! notifications (`sqlite.rs`, `postgres.rs`).
//!
//! Every write runs in a transaction begun by [`SqlStore::begin`] and ended by
//! [`SqlStore::commit`], so how a write becomes durable is decided in one place. A write that
//! does not end in a successful commit closes its connection instead of returning it to the
//! pool ([`Write`]): after a failed COMMIT (a full disk) the connection may still be inside the
//! transaction, and the next write on it would become a savepoint whose release "succeeds"
//! without anything reaching the disk.
//!
//! Generic sqlx code has to spell out what it asks of the driver (an executor for its
//! connections, encodings of the Rust types it binds and reads); those bounds sit on the three
//! `impl` blocks below and are met by both SQLite and PostgreSQL.
use super::{
    Idempotency, Job, JobFiles, JobId, JobKind, NewJob, QueueError, Scope, Song, SongId, Status,
    StoreFuture, TenantId,
};
use chrono::{DateTime, TimeZone, Utc};
use sqlx::pool::PoolConnection;
use sqlx::{
    ColumnIndex, Database, Decode, Encode, Executor, IntoArguments, Pool, Row, TransactionManager,
    Type,
};
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;
use uuid::Uuid;

mod delete;
mod events;
mod jobs;
mod keys;
pub mod quota;
mod rigs;
mod songs;

/// Cap on the backoff exponent, so `1 << n` cannot overflow.
pub const MAX_BACKOFF_DOUBLINGS: i64 = 16;

/// The columns a job row is read from.
pub const JOB_COLUMNS: &str = "id, tenant_id, options, status, stage, progress, priority, attempts, max_attempts, cancel_requested, \
     error, result, created_at, started_at, finished_at";
/// The columns a song row is read from.
pub const SONG_COLUMNS: &str = "id, tenant_id, filename, format, duration_s, sample_rate, channels, sha256, size_bytes, analysis, created_at";

/// What differs between the SQL of the two stores; everything else is one statement for both.
pub trait Dialect: Database {
    /// How an id is stored: hyphenated TEXT in SQLite, UUID in PostgreSQL.
    type Id: for<'q> Encode<'q, Self>
        + for<'r> Decode<'r, Self>
        + Type<Self>
        + Send
        + Sync
        + 'static;

    /// Ends the sub-select that picks the rows a claim or the reaper updates. PostgreSQL has
    /// many writers and skips rows another transaction is taking; SQLite has one writer and
    /// needs nothing.
    const SKIP_LOCKED: &'static str;

    /// `2^min(attempts - 1, cap)` as a 64-bit integer, the retry backoff's factor.
    fn backoff_factor(cap: &str) -> String;

    /// An id as stored.
    fn id(id: Uuid) -> Self::Id;

    /// A [`Scope`] as the parameter of `($n IS NULL OR tenant_id = $n)`: its tenant's id, or
    /// NULL for every tenant's rows.
    fn scope_id(scope: Scope) -> Option<Self::Id> {
        scope.tenant().map(|t| Self::id(t.0))
    }

    /// Rows a statement changed (sqlx has no driver-independent accessor).
    fn rows_affected(done: &Self::QueryResult) -> u64;

    /// A stored id back to a UUID.
    fn uuid(id: Self::Id) -> Result<Uuid, uuid::Error>;

    /// Wakes `wake` whenever a job becomes claimable in another process, until `shutdown`
    /// ([`super::JobStore::watch`]).
    fn watch(
        pool: &Pool<Self>,
        wake: Arc<Notify>,
        shutdown: CancellationToken,
    ) -> StoreFuture<'_, ()>;
}

/// The jobs and songs of one SQL database: [`super::SqliteStore`] or [`super::PgStore`].
#[derive(Debug)]
pub struct SqlStore<D: Database> {
    pool: Pool<D>,
}

impl<D: Database> Clone for SqlStore<D> {
    fn clone(&self) -> Self {
        Self {
            pool: self.pool.clone(),
        }
    }
}

impl<D: Database> SqlStore<D> {
    /// A store over a pool whose migrations have run.
    pub(super) fn from_pool(pool: Pool<D>) -> Self {
        Self { pool }
    }

    /// The pool, for tests and tools that inspect the database.
    pub fn pool(&self) -> &Pool<D> {
        &self.pool
    }
}

/// A write in progress: a pooled connection inside the transaction [`SqlStore::begin`] opened.
///
/// Ended by [`SqlStore::commit`] or [`SqlStore::rollback`]. If it is dropped without either
/// succeeding (an error, a failed COMMIT, a cancelled request), the connection is closed rather
/// than pooled: closing rolls back whatever the database still holds open, and no later write
/// can run inside a transaction nobody will commit.
pub(super) struct Write<D: Database> {
    conn: PoolConnection<D>,
    ended: bool,
}

impl<D: Database> std::ops::Deref for Write<D> {
    type Target = D::Connection;
    fn deref(&self) -> &D::Connection {
        &self.conn
    }
}

impl<D: Database> std::ops::DerefMut for Write<D> {
    fn deref_mut(&mut self) -> &mut D::Connection {
        &mut self.conn
    }
}

impl<D: Database> Drop for Write<D> {
    fn drop(&mut self) {
        if !self.ended {
            self.conn.close_on_drop();
        }
    }
}

/// Now, in epoch milliseconds (how both stores keep times).
pub fn now_ms() -> i64 {
    Utc::now().timestamp_millis()
}

/// A stored time back to a `DateTime`.
pub fn to_time(ms: i64) -> Result<DateTime<Utc>, QueueError> {
    Utc.timestamp_millis_opt(ms)
        .single()
        .ok_or_else(|| QueueError::Corrupt(format!("timestamp {ms}")))
}

/// An optional stored time back to a `DateTime`.
pub fn opt_time(ms: Option<i64>) -> Result<Option<DateTime<Utc>>, QueueError> {
    ms.map(to_time).transpose()
}

/// A duration in whole milliseconds, saturating.
pub fn ms(d: Duration) -> i64 {
    i64::try_from(d.as_millis()).unwrap_or(i64::MAX)
}

/// A stored value that does not parse.
pub fn corrupt(what: &str, e: impl std::fmt::Display) -> QueueError {
    QueueError::Corrupt(format!("{what}: {e}"))
}

pub(super) fn format_name(song: &Song) -> Result<String, QueueError> {
    match serde_json::to_value(song.format).map_err(|e| corrupt("song format", e))? {
        serde_json::Value::String(s) => Ok(s),
        other => Err(corrupt("song format", other)),
    }
}

impl<D> SqlStore<D>
where
    D: Dialect,
    for<'c> &'c mut D::Connection: Executor<'c, Database = D>,
    for<'q> D::Arguments<'q>: IntoArguments<'q, D>,
    for<'q> i64: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> f64: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> bool: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> String: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> &'q str: Encode<'q, D> + Type<D>,
    for<'q> Option<String>: Encode<'q, D>,
    for<'q> Option<&'q str>: Encode<'q, D>,
    for<'q> Option<D::Id>: Encode<'q, D>,
    for<'q> Option<i64>: Encode<'q, D>,
    &'static str: ColumnIndex<D::Row>,
{
    /// Starts the transaction a write runs in. Every write begins here and ends in
    /// [`Self::commit`] (or is rolled back when dropped), so one place decides how writes are
    /// made durable. Each write transaction starts with its write: in SQLite it then takes the
    /// write lock at once, so a waiting writer is handled by the busy timeout.
    async fn begin(&self) -> Result<Write<D>, QueueError> {
        let conn = self.pool.acquire().await?;
        // Until BEGIN succeeds the write is not ended: a failed BEGIN closes the connection too.
        let mut write = Write { conn, ended: false };
        if D::TransactionManager::get_transaction_depth(&*write) != 0 {
            // A pooled connection is never inside a transaction (`Write` closes those); if one
            // is, BEGIN would only open a savepoint, so refuse it rather than write into it.
            return Err(QueueError::Database(sqlx::Error::Protocol(
                "pooled connection inside a transaction".into(),
            )));
        }
        D::TransactionManager::begin(&mut *write, None).await?;
        Ok(write)
    }

    /// Commits a write begun by [`Self::begin`]; callers answer only after it returns. When the
    /// COMMIT fails, the connection is closed (see [`Write`]) and the error goes to the caller.
    async fn commit(mut write: Write<D>) -> Result<(), QueueError> {
        D::TransactionManager::commit(&mut *write).await?;
        write.ended = true;
        Ok(())
    }

    /// Rolls back a write that found nothing to do; its connection goes back to the pool.
    async fn rollback(mut write: Write<D>) -> Result<(), QueueError> {
        D::TransactionManager::rollback(&mut *write).await?;
        write.ended = true;
        Ok(())
    }

    fn tenant_from_row(row: &D::Row) -> Result<TenantId, QueueError> {
        Ok(TenantId(
            D::uuid(row.try_get("tenant_id")?).map_err(|e| corrupt("tenant id", e))?,
        ))
    }

    fn job_from_row(row: &D::Row) -> Result<Job, QueueError> {
        let options: String = row.try_get("options")?;
        let status: String = row.try_get("status")?;
        let result: Option<String> = row.try_get("result")?;
        Ok(Job {
            id: JobId(D::uuid(row.try_get("id")?).map_err(|e| corrupt("job id", e))?),
            tenant: Self::tenant_from_row(row)?,
            kind: serde_json::from_str::<JobKind>(&options)
                .map_err(|e| corrupt("job options", e))?,
            status: Status::from_str(&status).map_err(|e| corrupt("job status", e))?,
            stage: crate::stage::Stage::from_stored(
                row.try_get::<Option<String>, _>("stage")?.as_deref(),
            ),
            progress: row.try_get("progress")?,
            priority: row.try_get("priority")?,
            attempts: row
                .try_get::<i64, _>("attempts")?
                .try_into()
                .map_err(|e| corrupt("attempts", e))?,
            max_attempts: row
                .try_get::<i64, _>("max_attempts")?
                .try_into()
                .map_err(|e| corrupt("max_attempts", e))?,
            cancel_requested: row.try_get("cancel_requested")?,
            error: row.try_get("error")?,
            files: match result {
                Some(json) => serde_json::from_str(&json).map_err(|e| corrupt("job result", e))?,
                None => JobFiles::default(),
            },
            created_at: to_time(row.try_get("created_at")?)?,
            started_at: opt_time(row.try_get("started_at")?)?,
            finished_at: opt_time(row.try_get("finished_at")?)?,
        })
    }

    fn song_from_row(row: &D::Row) -> Result<Song, QueueError> {
        let format: String = row.try_get("format")?;
        let analysis: Option<String> = row.try_get("analysis")?;
        Ok(Song {
            id: SongId(D::uuid(row.try_get("id")?).map_err(|e| corrupt("song id", e))?),
            tenant: Self::tenant_from_row(row)?,
            filename: row.try_get("filename")?,
            format: serde_json::from_value(serde_json::Value::String(format))
                .map_err(|e| corrupt("song format", e))?,
            duration_s: row.try_get("duration_s")?,
            sample_rate: row
                .try_get::<i64, _>("sample_rate")?
                .try_into()
                .map_err(|e| corrupt("sample_rate", e))?,
            channels: row
                .try_get::<i64, _>("channels")?
                .try_into()
                .map_err(|e| corrupt("channels", e))?,
            sha256: row.try_get("sha256")?,
            size_bytes: row
                .try_get::<i64, _>("size_bytes")?
                .try_into()
                .map_err(|e| corrupt("size_bytes", e))?,
            analysis: analysis
                .map(|json| serde_json::from_str(&json))
                .transpose()
                .map_err(|e| corrupt("analysis", e))?,
            created_at: to_time(row.try_get("created_at")?)?,
        })
    }

    /// Inserts a queued job: the one statement that creates a job. `None` when its idempotency
    /// key is already taken. `quota_bytes` is the tenant's storage quota when it was admitted,
    /// which its results are held to.
    async fn insert_job(
        conn: &mut D::Connection,
        job: &NewJob,
        now: i64,
        quota_bytes: Option<u64>,
    ) -> Result<Option<Job>, QueueError> {
        let options = serde_json::to_string(&job.kind).map_err(|e| corrupt("job options", e))?;
        let (key, hash) = match &job.idempotency {
            Some(Idempotency { key, request_hash }) => {
                (Some(key.as_str()), Some(request_hash.as_str()))
            }
            None => (None, None),
        };
        let sql = format!(
            "INSERT INTO jobs (id, kind, song_id, model, options, status, priority, max_attempts, run_after, \
             idempotency_key, request_hash, created_at, tenant_id, storage_quota_bytes) \
             VALUES ($1, $2, $3, $4, $5, 'queued', $6, $7, $8, $9, $10, $8, $11, $12) \
             ON CONFLICT (tenant_id, idempotency_key) DO NOTHING RETURNING {JOB_COLUMNS}"
        );
        let row = sqlx::query(&sql)
            .bind(D::id(JobId::new().0))
            .bind(job.kind.name())
            .bind(D::id(job.kind.song_id().0))
            .bind(job.kind.model().map(|m| m.0.clone()))
            .bind(options)
            .bind(job.priority)
            .bind(i64::from(job.max_attempts))
            .bind(now)
            .bind(key)
            .bind(hash)
            .bind(D::id(job.tenant.0))
            .bind(
                quota_bytes
                    .map(i64::try_from)
                    .transpose()
                    .map_err(|e| corrupt("storage quota", e))?,
            )
            .fetch_optional(conn)
            .await?;
        row.as_ref().map(Self::job_from_row).transpose()
    }
}
