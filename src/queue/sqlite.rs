//! The SQLite store: WAL mode, `synchronous=NORMAL`, one atomic `UPDATE … RETURNING` per claim.
//!
//! SQLite has a single writer, so a claim that selects and updates in one statement cannot hand
//! the same job to two workers. Every write transaction starts with its write, so a waiting
//! writer is handled by the busy timeout and never surfaces as `SQLITE_BUSY`.
use super::sql::{corrupt, ms, now_ms, opt_time, to_time, JOB_COLUMNS, MAX_BACKOFF_DOUBLINGS, SONG_COLUMNS};
use super::{
    Beat, Idempotency, Job, JobFiles, JobFilter, JobId, JobKind, JobStore, LeasePolicy, NewJob, Outcome, QueueError,
    Registered, Requeued, Song, SongId, SongStore, Status, StoreFuture,
};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteRow, SqliteSynchronous};
use sqlx::{Row, SqlitePool};
use std::path::Path;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;

/// How long a writer waits for the lock before SQLite gives up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(30);
/// Connections in the pool; SQLite serialises writers anyway, readers run in parallel in WAL.
const MAX_CONNECTIONS: u32 = 8;

/// The jobs and songs of one SQLite file.
#[derive(Clone, Debug)]
pub struct SqliteStore {
    pool: SqlitePool,
}

fn job_from_row(row: &SqliteRow) -> Result<Job, QueueError> {
    let id: String = row.try_get("id")?;
    let options: String = row.try_get("options")?;
    let status: String = row.try_get("status")?;
    let result: Option<String> = row.try_get("result")?;
    Ok(Job {
        id: JobId::from_str(&id).map_err(|e| corrupt("job id", e))?,
        kind: serde_json::from_str::<JobKind>(&options).map_err(|e| corrupt("job options", e))?,
        status: Status::from_str(&status).map_err(|e| corrupt("job status", e))?,
        stage: crate::stage::Stage::from_stored(row.try_get::<Option<String>, _>("stage")?.as_deref()),
        progress: row.try_get("progress")?,
        priority: row.try_get("priority")?,
        attempts: row.try_get::<i64, _>("attempts")?.try_into().map_err(|e| corrupt("attempts", e))?,
        max_attempts: row.try_get::<i64, _>("max_attempts")?.try_into().map_err(|e| corrupt("max_attempts", e))?,
        cancel_requested: row.try_get::<i64, _>("cancel_requested")? != 0,
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

fn song_from_row(row: &SqliteRow) -> Result<Song, QueueError> {
    let id: String = row.try_get("id")?;
    let format: String = row.try_get("format")?;
    let analysis: Option<String> = row.try_get("analysis")?;
    Ok(Song {
        id: SongId::from_str(&id).map_err(|e| corrupt("song id", e))?,
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

impl SqliteStore {
    /// Opens (creating if needed) the database file and runs the migrations.
    pub async fn open(path: &Path) -> Result<Self, QueueError> {
        let options = SqliteConnectOptions::new()
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .busy_timeout(BUSY_TIMEOUT)
            .foreign_keys(true);
        let pool = SqlitePoolOptions::new()
            .max_connections(MAX_CONNECTIONS)
            .acquire_timeout(BUSY_TIMEOUT)
            .connect_with(options)
            .await?;
        sqlx::migrate!("./migrations").run(&pool).await?;
        Ok(Self { pool })
    }

    /// The pool, for tests and tools that inspect the file.
    pub fn pool(&self) -> &SqlitePool {
        &self.pool
    }

    async fn insert_job<'e, E>(executor: E, job: &NewJob, now: i64) -> Result<Option<Job>, QueueError>
    where
        E: sqlx::Executor<'e, Database = sqlx::Sqlite>,
    {
        let id = JobId::new();
        let options = serde_json::to_string(&job.kind).map_err(|e| corrupt("job options", e))?;
        let (key, hash) = match &job.idempotency {
            Some(Idempotency { key, request_hash }) => (Some(key.as_str()), Some(request_hash.as_str())),
            None => (None, None),
        };
        let sql = format!(
            "INSERT INTO jobs (id, kind, song_id, model, options, status, priority, max_attempts, run_after, \
             idempotency_key, request_hash, created_at) VALUES (?, ?, ?, ?, ?, 'queued', ?, ?, ?, ?, ?, ?) \
             ON CONFLICT (idempotency_key) DO NOTHING RETURNING {JOB_COLUMNS}"
        );
        let row = sqlx::query(&sql)
            .bind(id.to_string())
            .bind(job.kind.name())
            .bind(job.kind.song_id().to_string())
            .bind(job.kind.model().map(|m| m.0.clone()))
            .bind(options)
            .bind(job.priority)
            .bind(i64::from(job.max_attempts))
            .bind(now)
            .bind(key)
            .bind(hash)
            .bind(now)
            .fetch_optional(executor)
            .await?;
        row.as_ref().map(job_from_row).transpose()
    }
}

impl JobStore for SqliteStore {
    fn register(&self, job: NewJob) -> StoreFuture<'_, Registered> {
        Box::pin(async move {
            let song = job.kind.song_id();
            let exists = sqlx::query("SELECT 1 FROM songs WHERE id = ?").bind(song.to_string()).fetch_optional(&self.pool).await?;
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
            let sql = format!("SELECT {JOB_COLUMNS}, request_hash FROM jobs WHERE idempotency_key = ?");
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
            let sql = format!(
                "UPDATE jobs SET status = 'running', attempts = attempts + 1, lease_owner = ?1, \
                 lease_expires_at = ?2, heartbeat_at = ?3, started_at = COALESCE(started_at, ?3), \
                 stage = 'claimed', progress = 0 \
                 WHERE id = (SELECT id FROM jobs WHERE status = 'queued' AND run_after <= ?3 \
                             ORDER BY priority DESC, run_after, id LIMIT 1) \
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
                "UPDATE jobs SET heartbeat_at = ?1, lease_expires_at = ?2, stage = ?3, progress = ?4 \
                 WHERE id = ?5 AND lease_owner = ?6 AND status = 'running' RETURNING cancel_requested",
            )
            .bind(now)
            .bind(now + ms(policy.lease))
            .bind(stage)
            .bind(progress.clamp(0.0, 1.0))
            .bind(id.to_string())
            .bind(owner)
            .fetch_optional(&self.pool)
            .await?;
            Ok(match row {
                Some(row) => Beat::Held { cancel_requested: row.try_get::<i64, _>(0)? != 0 },
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
            // The first statement writes, so this transaction takes the write lock at once.
            let row = sqlx::query(
                "UPDATE jobs SET status = 'succeeded', stage = 'done', progress = 1, result = ?1, error = NULL, \
                 finished_at = ?2, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = ?3 AND lease_owner = ?4 AND status = 'running' RETURNING song_id",
            )
            .bind(files)
            .bind(now_ms())
            .bind(id.to_string())
            .bind(owner)
            .fetch_optional(&mut *tx)
            .await?;
            let Some(row) = row else {
                tx.rollback().await?;
                return Ok(false);
            };
            if let Outcome::Analysis(analysis) = &outcome {
                let song_id: String = row.try_get(0)?;
                let json = serde_json::to_string(analysis).map_err(|e| corrupt("analysis", e))?;
                sqlx::query("UPDATE songs SET analysis = ? WHERE id = ?").bind(json).bind(song_id).execute(&mut *tx).await?;
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
                   status = CASE WHEN ?1 AND attempts < max_attempts AND NOT cancel_requested THEN 'queued' \
                                 WHEN cancel_requested THEN 'cancelled' ELSE 'failed' END, \
                   finished_at = CASE WHEN ?1 AND attempts < max_attempts AND NOT cancel_requested THEN NULL ELSE ?2 END, \
                   run_after = ?2 + ?3 * (1 << MIN(attempts - 1, ?4)), \
                   error = ?5, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = ?6 AND lease_owner = ?7 AND status = 'running'",
            )
            .bind(retry)
            .bind(now)
            .bind(ms(policy.backoff))
            .bind(MAX_BACKOFF_DOUBLINGS)
            .bind(error)
            .bind(id.to_string())
            .bind(owner)
            .execute(&self.pool)
            .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    fn finish_cancelled<'a>(&'a self, id: JobId, owner: &'a str) -> StoreFuture<'a, bool> {
        Box::pin(async move {
            let done = sqlx::query(
                "UPDATE jobs SET status = 'cancelled', finished_at = ?1, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = ?2 AND lease_owner = ?3 AND status = 'running'",
            )
            .bind(now_ms())
            .bind(id.to_string())
            .bind(owner)
            .execute(&self.pool)
            .await?;
            Ok(done.rows_affected() == 1)
        })
    }

    fn cancel(&self, id: JobId) -> StoreFuture<'_, Job> {
        Box::pin(async move {
            // In SQLite's SET, every column reference reads the row as it was before the update.
            let sql = format!(
                "UPDATE jobs SET \
                   status = CASE WHEN status = 'queued' THEN 'cancelled' ELSE status END, \
                   finished_at = CASE WHEN status = 'queued' THEN ?1 ELSE finished_at END, \
                   cancel_requested = CASE WHEN status IN ('queued', 'running') THEN 1 ELSE cancel_requested END \
                 WHERE id = ?2 RETURNING {JOB_COLUMNS}"
            );
            let row = sqlx::query(&sql).bind(now_ms()).bind(id.to_string()).fetch_optional(&self.pool).await?;
            match row {
                Some(row) => job_from_row(&row),
                None => Err(QueueError::JobNotFound(id)),
            }
        })
    }

    fn requeue_expired(&self, policy: LeasePolicy) -> StoreFuture<'_, Requeued> {
        Box::pin(async move {
            let now = now_ms();
            let rows = sqlx::query(
                "UPDATE jobs SET \
                   status = CASE WHEN cancel_requested THEN 'cancelled' \
                                 WHEN attempts >= max_attempts THEN 'failed' ELSE 'queued' END, \
                   finished_at = CASE WHEN cancel_requested OR attempts >= max_attempts THEN ?1 ELSE NULL END, \
                   error = 'lease expired on attempt ' || attempts || ' of ' || max_attempts || \
                           ' (the worker died or hung)' || COALESCE('; last error: ' || error, ''), \
                   run_after = ?1 + ?2 * (1 << MIN(attempts - 1, ?3)), \
                   lease_owner = NULL, lease_expires_at = NULL \
                 WHERE status = 'running' AND lease_expires_at < ?1 RETURNING id, status",
            )
            .bind(now)
            .bind(ms(policy.backoff))
            .bind(MAX_BACKOFF_DOUBLINGS)
            .fetch_all(&self.pool)
            .await?;
            let mut out = Requeued::default();
            for row in rows {
                let id = JobId::from_str(row.try_get::<&str, _>(0)?).map_err(|e| corrupt("job id", e))?;
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
            let sql = format!("SELECT {JOB_COLUMNS} FROM jobs WHERE id = ?");
            match sqlx::query(&sql).bind(id.to_string()).fetch_optional(&self.pool).await? {
                Some(row) => job_from_row(&row),
                None => Err(QueueError::JobNotFound(id)),
            }
        })
    }

    fn jobs(&self, filter: JobFilter) -> StoreFuture<'_, Vec<Job>> {
        Box::pin(async move {
            let sql = format!(
                "SELECT {JOB_COLUMNS} FROM jobs WHERE (?1 IS NULL OR status = ?1) AND (?2 IS NULL OR model = ?2) \
                 AND (?3 IS NULL OR id < ?3) ORDER BY id DESC LIMIT ?4"
            );
            let rows = sqlx::query(&sql)
                .bind(filter.status.map(Status::as_str))
                .bind(filter.model)
                .bind(filter.before.map(|id| id.to_string()))
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

    fn watch(&self, _wake: Arc<Notify>, _shutdown: CancellationToken) -> StoreFuture<'_, ()> {
        // SQLite cannot notify another process: this process's registrations wake its workers
        // directly (`worker::Context::wake`), other processes' jobs are found by polling.
        Box::pin(async { Ok(()) })
    }
}

impl SongStore for SqliteStore {
    fn add_song(&self, song: Song, analyze: NewJob) -> StoreFuture<'_, (Song, bool)> {
        Box::pin(async move {
            let now = now_ms();
            let mut tx = self.pool.begin().await?;
            // The first statement writes, so this transaction takes the write lock at once.
            let sql = format!(
                "INSERT INTO songs (id, filename, format, duration_s, sample_rate, channels, sha256, size_bytes, created_at) \
                 VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT (sha256) DO NOTHING RETURNING {SONG_COLUMNS}"
            );
            let inserted = sqlx::query(&sql)
                .bind(song.id.to_string())
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
                let sql = format!("SELECT {SONG_COLUMNS} FROM songs WHERE sha256 = ?");
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
            let sql = format!("SELECT {SONG_COLUMNS} FROM songs WHERE id = ?");
            match sqlx::query(&sql).bind(id.to_string()).fetch_optional(&self.pool).await? {
                Some(row) => song_from_row(&row),
                None => Err(QueueError::SongNotFound(id)),
            }
        })
    }

    fn song_by_sha256<'a>(&'a self, sha256: &'a str) -> StoreFuture<'a, Option<Song>> {
        Box::pin(async move {
            let sql = format!("SELECT {SONG_COLUMNS} FROM songs WHERE sha256 = ?");
            let row = sqlx::query(&sql).bind(sha256).fetch_optional(&self.pool).await?;
            row.as_ref().map(song_from_row).transpose()
        })
    }

    fn analyze_job(&self, song: SongId) -> StoreFuture<'_, Option<Job>> {
        Box::pin(async move {
            let sql = format!("SELECT {JOB_COLUMNS} FROM jobs WHERE song_id = ? AND kind = 'analyze' ORDER BY id DESC LIMIT 1");
            let row = sqlx::query(&sql).bind(song.to_string()).fetch_optional(&self.pool).await?;
            row.as_ref().map(job_from_row).transpose()
        })
    }
}
