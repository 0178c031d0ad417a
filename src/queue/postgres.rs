//! The PostgreSQL store: many API and worker processes on many hosts share one queue.
//!
//! The twin of `sqlite.rs`, statement for statement, so both keep one contract (the tests in
//! `tests/queue.rs` run against each). Where SQLite has one writer, PostgreSQL has many: a claim
//! selects its row `FOR UPDATE SKIP LOCKED` inside the same `UPDATE … RETURNING`, so concurrent
//! claims take different jobs without waiting on each other. A trigger appends every status
//! change to `job_events` and, when a job becomes queued, sends `NOTIFY choreo_jobs`, which
//! [`JobStore::watch`] turns into a wake-up of this process's idle workers.
use super::sql::{corrupt, ms, now_ms, opt_time, to_time, JOB_COLUMNS, MAX_BACKOFF_DOUBLINGS, SONG_COLUMNS};
use super::{
    Beat, Idempotency, Job, JobFiles, JobFilter, JobId, JobKind, JobStore, LeasePolicy, NewJob, Outcome, QueueError,
    Registered, Requeued, Song, SongId, SongStore, Status, StoreFuture,
};
use crate::config::Secret;
use sqlx::postgres::{PgConnectOptions, PgListener, PgPoolOptions, PgRow};
use sqlx::{PgPool, Row};
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;
use uuid::Uuid;

/// The channel the job trigger notifies (see `migrations/postgres/`).
pub const CHANNEL: &str = "choreo_jobs";
/// How long a query waits for a pooled connection.
const ACQUIRE_TIMEOUT: Duration = Duration::from_secs(30);
/// Connections per process: workers hold none while a job runs, so a few serve many.
const MAX_CONNECTIONS: u32 = 8;
/// Pause before listening again after the notification connection failed.
const RELISTEN_AFTER: Duration = Duration::from_secs(1);

/// The jobs and songs of one PostgreSQL database.
#[derive(Clone, Debug)]
pub struct PgStore {
    pool: PgPool,
}

fn job_from_row(row: &PgRow) -> Result<Job, QueueError> {
    let options: String = row.try_get("options")?;
    let status: String = row.try_get("status")?;
    let result: Option<String> = row.try_get("result")?;
    Ok(Job {
        id: JobId(row.try_get::<Uuid, _>("id")?),
        kind: serde_json::from_str::<JobKind>(&options).map_err(|e| corrupt("job options", e))?,
        status: Status::from_str(&status).map_err(|e| corrupt("job status", e))?,
        stage: crate::stage::Stage::from_stored(row.try_get::<Option<String>, _>("stage")?.as_deref()),
        progress: row.try_get("progress")?,
        priority: row.try_get("priority")?,
        attempts: row.try_get::<i64, _>("attempts")?.try_into().map_err(|e| corrupt("attempts", e))?,
        max_attempts: row.try_get::<i64, _>("max_attempts")?.try_into().map_err(|e| corrupt("max_attempts", e))?,
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

fn song_from_row(row: &PgRow) -> Result<Song, QueueError> {
    let format: String = row.try_get("format")?;
    let analysis: Option<String> = row.try_get("analysis")?;
    Ok(Song {
        id: SongId(row.try_get::<Uuid, _>("id")?),
        filename: row.try_get("filename")?,
        format: serde_json::from_value(serde_json::Value::String(format)).map_err(|e| corrupt("song format", e))?,
        duration_s: row.try_get("duration_s")?,
        sample_rate: row.try_get::<i64, _>("sample_rate")?.try_into().map_err(|e| corrupt("sample_rate", e))?,
        channels: row.try_get::<i64, _>("channels")?.try_into().map_err(|e| corrupt("channels", e))?,
        sha256: row.try_get("sha256")?,
        size_bytes: row.try_get::<i64, _>("size_bytes")?.try_into().map_err(|e| corrupt("size_bytes", e))?,
        analysis: analysis.map(|json| serde_json::from_str(&json)).transpose().map_err(|e| corrupt("analysis", e))?,
        created_at: to_time(row.try_get("created_at")?)?,
    })
}

fn format_name(song: &Song) -> Result<String, QueueError> {
    match serde_json::to_value(song.format).map_err(|e| corrupt("song format", e))? {
        serde_json::Value::String(s) => Ok(s),
        other => Err(corrupt("song format", other)),
    }
}

impl PgStore {
    /// Connects to `url` (`postgres://user:password@host:port/db`, or `?host=/socket/dir`) and
    /// runs the migrations; many processes may do this at once (sqlx takes an advisory lock).
    pub async fn connect(url: &Secret) -> Result<Self, QueueError> {
        let options = PgConnectOptions::from_str(url.expose())?;
        let pool = PgPoolOptions::new()
            .max_connections(MAX_CONNECTIONS)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_with(options)
            .await?;
        sqlx::migrate!("./migrations/postgres").run(&pool).await?;
        Ok(Self { pool })
    }

    /// The pool, for tests and tools that inspect the database.
    pub fn pool(&self) -> &PgPool {
        &self.pool
    }

    async fn insert_job<'e, E>(executor: E, job: &NewJob, now: i64) -> Result<Option<Job>, QueueError>
    where
        E: sqlx::Executor<'e, Database = sqlx::Postgres>,
    {
        let options = serde_json::to_string(&job.kind).map_err(|e| corrupt("job options", e))?;
        let (key, hash) = match &job.idempotency {
            Some(Idempotency { key, request_hash }) => (Some(key.as_str()), Some(request_hash.as_str())),
            None => (None, None),
        };
        let sql = format!(
            "INSERT INTO jobs (id, kind, song_id, model, options, status, priority, max_attempts, run_after, \
             idempotency_key, request_hash, created_at) VALUES ($1, $2, $3, $4, $5, 'queued', $6, $7, $8, $9, $10, $8) \
             ON CONFLICT (idempotency_key) DO NOTHING RETURNING {JOB_COLUMNS}"
        );
        let row = sqlx::query(&sql)
            .bind(JobId::new().0)
            .bind(job.kind.name())
            .bind(job.kind.song_id().0)
            .bind(job.kind.model().map(|m| m.0.clone()))
            .bind(options)
            .bind(job.priority)
            .bind(i64::from(job.max_attempts))
            .bind(now)
            .bind(key)
            .bind(hash)
            .fetch_optional(executor)
            .await?;
        row.as_ref().map(job_from_row).transpose()
    }
}

impl JobStore for PgStore {
    fn register(&self, job: NewJob) -> StoreFuture<'_, Registered> {
        Box::pin(async move {
            let song = job.kind.song_id();
            let exists = sqlx::query("SELECT 1 FROM songs WHERE id = $1").bind(song.0).fetch_optional(&self.pool).await?;
            if exists.is_none() {
                return Err(QueueError::SongNotFound(song));
            }
            if let Some(created) = Self::insert_job(&self.pool, &job, now_ms()).await? {
                return Ok(Registered::Created(created));
            }
            // Only the idempotency key can conflict: the id is fresh.
            let Some(idem) = &job.idempotency else {
                return Err(QueueError::Corrupt("insert of a job without idempotency key returned nothing".into()));
            };
            let sql = format!("SELECT {JOB_COLUMNS}, request_hash FROM jobs WHERE idempotency_key = $1");
            let row = sqlx::query(&sql).bind(&idem.key).fetch_one(&self.pool).await?;
            let existing = job_from_row(&row)?;
            let hash: Option<String> = row.try_get("request_hash")?;
            if hash.as_deref() == Some(idem.request_hash.as_str()) {
                Ok(Registered::Existing(existing))
            } else {
                Err(QueueError::IdempotencyConflict(existing.id))
            }
        })
    }

    fn claim<'a>(&'a self, owner: &'a str, policy: LeasePolicy) -> StoreFuture<'a, Option<Job>> {
        Box::pin(async move {
            let now = now_ms();
            // SKIP LOCKED: a row another claim is taking is passed over, not waited for, so N
            // workers claiming at once get N different jobs (or none), never the same one.
            let sql = format!(
                "UPDATE jobs SET status = 'running', attempts = attempts + 1, lease_owner = $1, \
                 lease_expires_at = $2, heartbeat_at = $3, started_at = COALESCE(started_at, $3), \
                 stage = 'claimed', progress = 0 \
                 WHERE id = (SELECT id FROM jobs WHERE status = 'queued' AND run_after <= $3 \
                             ORDER BY priority DESC, run_after, id LIMIT 1 FOR UPDATE SKIP LOCKED) \
                 RETURNING {JOB_COLUMNS}"
            );
            let row = sqlx::query(&sql)
                .bind(owner)
                .bind(now + ms(policy.lease))
                .bind(now)
                .fetch_optional(&self.pool)
                .await?;
            row.as_ref().map(job_from_row).transpose()
        })
    }

    fn heartbeat<'a>(
        &'a self,
        id: JobId,
        owner: &'a str,
        stage: &'a str,
        progress: f64,
        policy: LeasePolicy,
    ) -> StoreFuture<'a, Beat> {
        Box::pin(async move {
            let now = now_ms();
            let row = sqlx::query(
                "UPDATE jobs SET heartbeat_at = $1, lease_expires_at = $2, stage = $3, progress = $4 \
                 WHERE id = $5 AND lease_owner = $6 AND status = 'running' RETURNING cancel_requested",
            )
            .bind(now)
            .bind(now + ms(policy.lease))
            .bind(stage)
            .bind(progress.clamp(0.0, 1.0))
            .bind(id.0)
            .bind(owner)
            .fetch_optional(&self.pool)
            .await?;
            Ok(match row {
                Some(row) => Beat::Held { cancel_requested: row.try_get::<bool, _>(0)? },
                None => Beat::Lost,
            })
        })
    }

    fn complete<'a>(&'a self, id: JobId, owner: &'a str, outcome: Outcome) -> StoreFuture<'a, bool> {
        Box::pin(async move {
            let files = match &outcome {
                Outcome::Files(files) => Some(serde_json::to_string(files).map_err(|e| corrupt("job result", e))?),
                Outcome::Analysis(_) => None,
            };
            let mut tx = self.pool.begin().await?;
            let row = sqlx::query(
                "UPDATE jobs SET status = 'succeeded', stage = 'done', progress = 1, result = $1, error = NULL, \
                 finished_at = $2, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = $3 AND lease_owner = $4 AND status = 'running' RETURNING song_id",
            )
            .bind(files)
            .bind(now_ms())
            .bind(id.0)
            .bind(owner)
            .fetch_optional(&mut *tx)
            .await?;
            let Some(row) = row else {
                tx.rollback().await?;
                return Ok(false);
            };
            if let Outcome::Analysis(analysis) = &outcome {
                let song_id: Uuid = row.try_get(0)?;
                let json = serde_json::to_string(analysis).map_err(|e| corrupt("analysis", e))?;
                sqlx::query("UPDATE songs SET analysis = $1 WHERE id = $2").bind(json).bind(song_id).execute(&mut *tx).await?;
            }
            tx.commit().await?;
            Ok(true)
        })
    }

    fn fail<'a>(&'a self, id: JobId, owner: &'a str, error: &'a str, retry: bool, policy: LeasePolicy) -> StoreFuture<'a, bool> {
        Box::pin(async move {
            let now = now_ms();
            let done = sqlx::query(
                "UPDATE jobs SET \
                   status = CASE WHEN $1 AND attempts < max_attempts AND NOT cancel_requested THEN 'queued' \
                                 WHEN cancel_requested THEN 'cancelled' ELSE 'failed' END, \
                   finished_at = CASE WHEN $1 AND attempts < max_attempts AND NOT cancel_requested THEN NULL ELSE $2 END, \
                   run_after = $2 + $3 * (1::BIGINT << LEAST(attempts - 1, $4)::INTEGER), \
                   error = $5, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = $6 AND lease_owner = $7 AND status = 'running'",
            )
            .bind(retry)
            .bind(now)
            .bind(ms(policy.backoff))
            .bind(MAX_BACKOFF_DOUBLINGS)
            .bind(error)
            .bind(id.0)
            .bind(owner)
            .execute(&self.pool)
            .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    fn finish_cancelled<'a>(&'a self, id: JobId, owner: &'a str) -> StoreFuture<'a, bool> {
        Box::pin(async move {
            let done = sqlx::query(
                "UPDATE jobs SET status = 'cancelled', finished_at = $1, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = $2 AND lease_owner = $3 AND status = 'running'",
            )
            .bind(now_ms())
            .bind(id.0)
            .bind(owner)
            .execute(&self.pool)
            .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    fn cancel(&self, id: JobId) -> StoreFuture<'_, Job> {
        Box::pin(async move {
            // In PostgreSQL's SET, as in SQLite's, every column reads the row as it was before.
            let sql = format!(
                "UPDATE jobs SET \
                   status = CASE WHEN status = 'queued' THEN 'cancelled' ELSE status END, \
                   finished_at = CASE WHEN status = 'queued' THEN $1 ELSE finished_at END, \
                   cancel_requested = CASE WHEN status IN ('queued', 'running') THEN TRUE ELSE cancel_requested END \
                 WHERE id = $2 RETURNING {JOB_COLUMNS}"
            );
            let row = sqlx::query(&sql).bind(now_ms()).bind(id.0).fetch_optional(&self.pool).await?;
            match row {
                Some(row) => job_from_row(&row),
                None => Err(QueueError::JobNotFound(id)),
            }
        })
    }

    fn requeue_expired(&self, policy: LeasePolicy) -> StoreFuture<'_, Requeued> {
        Box::pin(async move {
            let now = now_ms();
            // Every worker process runs a reaper; SKIP LOCKED keeps two reapers (or a reaper and
            // a late heartbeat) from waiting on each other, and the row lock from counting a
            // lease twice.
            let rows = sqlx::query(
                "UPDATE jobs SET \
                   status = CASE WHEN cancel_requested THEN 'cancelled' \
                                 WHEN attempts >= max_attempts THEN 'failed' ELSE 'queued' END, \
                   finished_at = CASE WHEN cancel_requested OR attempts >= max_attempts THEN $1 ELSE NULL END, \
                   error = 'lease expired on attempt ' || attempts || ' of ' || max_attempts || \
                           ' (the worker died or hung)' || COALESCE('; last error: ' || error, ''), \
                   run_after = $1 + $2 * (1::BIGINT << LEAST(attempts - 1, $3)::INTEGER), \
                   lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id IN (SELECT id FROM jobs WHERE status = 'running' AND lease_expires_at < $1 \
                              FOR UPDATE SKIP LOCKED) \
                 RETURNING id, status",
            )
            .bind(now)
            .bind(ms(policy.backoff))
            .bind(MAX_BACKOFF_DOUBLINGS)
            .fetch_all(&self.pool)
            .await?;
            let mut out = Requeued::default();
            for row in rows {
                let id = JobId(row.try_get::<Uuid, _>(0)?);
                match Status::from_str(row.try_get::<&str, _>(1)?).map_err(|e| corrupt("job status", e))? {
                    Status::Queued => out.requeued.push(id),
                    Status::Failed => out.failed.push(id),
                    Status::Cancelled => out.cancelled.push(id),
                    other @ (Status::Running | Status::Succeeded) => {
                        return Err(corrupt("requeue", format!("job {id} became {other}")));
                    }
                }
            }
            Ok(out)
        })
    }

    fn job(&self, id: JobId) -> StoreFuture<'_, Job> {
        Box::pin(async move {
            let sql = format!("SELECT {JOB_COLUMNS} FROM jobs WHERE id = $1");
            match sqlx::query(&sql).bind(id.0).fetch_optional(&self.pool).await? {
                Some(row) => job_from_row(&row),
                None => Err(QueueError::JobNotFound(id)),
            }
        })
    }

    fn jobs(&self, filter: JobFilter) -> StoreFuture<'_, Vec<Job>> {
        Box::pin(async move {
            let sql = format!(
                "SELECT {JOB_COLUMNS} FROM jobs WHERE ($1::TEXT IS NULL OR status = $1) AND ($2::TEXT IS NULL OR model = $2) \
                 AND ($3::UUID IS NULL OR id < $3) ORDER BY id DESC LIMIT $4"
            );
            let rows = sqlx::query(&sql)
                .bind(filter.status.map(Status::as_str))
                .bind(filter.model)
                .bind(filter.before.map(|id| id.0))
                .bind(i64::from(filter.limit))
                .fetch_all(&self.pool)
                .await?;
            rows.iter().map(job_from_row).collect()
        })
    }

    fn counts(&self) -> StoreFuture<'_, Vec<(Status, u64)>> {
        Box::pin(async move {
            let rows = sqlx::query("SELECT status, COUNT(*) FROM jobs GROUP BY status").fetch_all(&self.pool).await?;
            let mut counts: Vec<(Status, u64)> = Status::ALL.iter().map(|s| (*s, 0)).collect();
            for row in rows {
                let status = Status::from_str(row.try_get::<&str, _>(0)?).map_err(|e| corrupt("job status", e))?;
                let n: i64 = row.try_get(1)?;
                if let Some(slot) = counts.iter_mut().find(|(s, _)| *s == status) {
                    slot.1 = u64::try_from(n).unwrap_or(0);
                }
            }
            Ok(counts)
        })
    }

    fn ping(&self) -> StoreFuture<'_, ()> {
        Box::pin(async move {
            sqlx::query("SELECT 1").execute(&self.pool).await?;
            Ok(())
        })
    }

    fn watch(&self, wake: Arc<Notify>, shutdown: CancellationToken) -> StoreFuture<'_, ()> {
        Box::pin(async move {
            while !shutdown.is_cancelled() {
                let mut listener = match PgListener::connect_with(&self.pool).await {
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

impl SongStore for PgStore {
    fn add_song(&self, song: Song, analyze: NewJob) -> StoreFuture<'_, (Song, bool)> {
        Box::pin(async move {
            let now = now_ms();
            let mut tx = self.pool.begin().await?;
            let sql = format!(
                "INSERT INTO songs (id, filename, format, duration_s, sample_rate, channels, sha256, size_bytes, created_at) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) ON CONFLICT (sha256) DO NOTHING RETURNING {SONG_COLUMNS}"
            );
            let inserted = sqlx::query(&sql)
                .bind(song.id.0)
                .bind(&song.filename)
                .bind(format_name(&song)?)
                .bind(song.duration_s)
                .bind(i64::from(song.sample_rate))
                .bind(i64::from(song.channels))
                .bind(&song.sha256)
                .bind(i64::try_from(song.size_bytes).map_err(|e| corrupt("size_bytes", e))?)
                .bind(now)
                .fetch_optional(&mut *tx)
                .await?;
            let Some(row) = inserted else {
                // The conflicting row was committed by another transaction (ON CONFLICT waits
                // for it), so a fresh read in this one sees it.
                let sql = format!("SELECT {SONG_COLUMNS} FROM songs WHERE sha256 = $1");
                let row = sqlx::query(&sql).bind(&song.sha256).fetch_one(&mut *tx).await?;
                let existing = song_from_row(&row)?;
                tx.commit().await?;
                return Ok((existing, false));
            };
            let stored = song_from_row(&row)?;
            if Self::insert_job(&mut *tx, &analyze, now).await?.is_none() {
                return Err(QueueError::Corrupt("analyze job insert returned nothing".into()));
            }
            tx.commit().await?;
            Ok((stored, true))
        })
    }

    fn song(&self, id: SongId) -> StoreFuture<'_, Song> {
        Box::pin(async move {
            let sql = format!("SELECT {SONG_COLUMNS} FROM songs WHERE id = $1");
            match sqlx::query(&sql).bind(id.0).fetch_optional(&self.pool).await? {
                Some(row) => song_from_row(&row),
                None => Err(QueueError::SongNotFound(id)),
            }
        })
    }

    fn song_by_sha256<'a>(&'a self, sha256: &'a str) -> StoreFuture<'a, Option<Song>> {
        Box::pin(async move {
            let sql = format!("SELECT {SONG_COLUMNS} FROM songs WHERE sha256 = $1");
            let row = sqlx::query(&sql).bind(sha256).fetch_optional(&self.pool).await?;
            row.as_ref().map(song_from_row).transpose()
        })
    }

    fn analyze_job(&self, song: SongId) -> StoreFuture<'_, Option<Job>> {
        Box::pin(async move {
            let sql = format!("SELECT {JOB_COLUMNS} FROM jobs WHERE song_id = $1 AND kind = 'analyze' ORDER BY id DESC LIMIT 1");
            let row = sqlx::query(&sql).bind(song.0).fetch_optional(&self.pool).await?;
            row.as_ref().map(job_from_row).transpose()
        })
    }
}
