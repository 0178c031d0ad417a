//! Deletion and retention statements of [`SqlStore`], for both stores (the rules in one place,
//! as the queue's).
//!
//! Rows go first, in one transaction, and files after (by the caller): once a row is gone nothing
//! can be claimed, served or listed from it, and a file whose row is gone is garbage that the
//! data dir's sweep removes should its removal fail (`artifacts::sweep`). A running job's row
//! goes too: its worker's next heartbeat finds the lease gone (`Beat::Lost`), the job stops at
//! its next checkpoint, and every write of its outcome matches no row, so nothing it finishes is
//! recorded (its files are removed by `artifacts::retention::forget_if_deleted`).
//!
//! `job_events` keeps no foreign key to `jobs`: each removed job leaves a line there,
//! `to_status = 'deleted'` with the reason in `error`, the audit trail that outlives the row.
//!
//! The last use of a song is `COALESCE(last_used_at, created_at)`, of a job
//! `COALESCE(last_used_at, finished_at, created_at)` (migration `20261127000300_retention.sql`),
//! of a rig `COALESCE(last_used_at, created_at)` (`20261207000000_rig_use.sql`). A rig is
//! deleted in `sql/rigs.rs`; it expires here, in the same transaction as songs and jobs.
use super::{now_ms, Dialect, SqlStore, JOB_COLUMNS, SONG_COLUMNS};
use crate::queue::{Job, JobId, QueueError, Removed, Scope, Song, SongId};
use chrono::{DateTime, Utc};
use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Type};
use uuid::Uuid;

/// The statuses a job never leaves; only such jobs are removed on their own.
const FINISHED: &str = "('succeeded', 'failed', 'cancelled')";
/// A job's last use, in SQL.
const JOB_LAST_USE: &str = "COALESCE(last_used_at, finished_at, created_at)";

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
    /// The audit line of a removed job.
    async fn audit(
        conn: &mut D::Connection,
        job: &Job,
        reason: &str,
        now: i64,
    ) -> Result<(), QueueError> {
        // The job's webhook outbox row and attempt log go with it (a pending delivery of a
        // deleted job is dropped): only the audit line below stays.
        for table in ["webhooks", "webhook_deliveries"] {
            sqlx::query(&format!("DELETE FROM {table} WHERE job_id = $1"))
                .bind(D::id(job.id.0))
                .execute(&mut *conn)
                .await?;
        }
        sqlx::query(
            "INSERT INTO job_events (job_id, from_status, to_status, attempt, worker, error, at) \
             VALUES ($1, $2, 'deleted', $3, NULL, $4, $5)",
        )
        .bind(D::id(job.id.0))
        .bind(job.status.as_str())
        .bind(i64::from(job.attempts))
        .bind(reason)
        .bind(now)
        .execute(conn)
        .await?;
        Ok(())
    }

    /// Removes a song's row and its jobs' rows inside the caller's transaction; `None` (nothing
    /// removed) when no song has the id in scope. Its first statement is a write, so in SQLite
    /// the transaction holds the write lock from its start (see [`SqlStore::begin`]).
    async fn remove_song(
        conn: &mut D::Connection,
        scope: Scope,
        id: SongId,
        reason: &str,
        now: i64,
    ) -> Result<Option<(Song, Vec<Job>)>, QueueError> {
        let tenant = || D::scope_id(scope);
        // A song's jobs are its tenant's (`register` refuses another's song).
        let sql = format!(
            "DELETE FROM jobs WHERE song_id = $1 AND ($2 IS NULL OR tenant_id = $2) RETURNING {JOB_COLUMNS}"
        );
        let rows = sqlx::query(&sql)
            .bind(D::id(id.0))
            .bind(tenant())
            .fetch_all(&mut *conn)
            .await?;
        let jobs = rows
            .iter()
            .map(Self::job_from_row)
            .collect::<Result<Vec<_>, _>>()?;
        let sql = format!(
            "DELETE FROM songs WHERE id = $1 AND ($2 IS NULL OR tenant_id = $2) RETURNING {SONG_COLUMNS}"
        );
        let row = sqlx::query(&sql)
            .bind(D::id(id.0))
            .bind(tenant())
            .fetch_optional(&mut *conn)
            .await?;
        let Some(row) = row else {
            return Ok(None);
        };
        for job in &jobs {
            Self::audit(&mut *conn, job, reason, now).await?;
        }
        Ok(Some((Self::song_from_row(&row)?, jobs)))
    }

    /// [`crate::queue::JobStore::delete_job`].
    pub(super) async fn delete_finished_job(
        &self,
        scope: Scope,
        id: JobId,
        reason: &str,
    ) -> Result<Job, QueueError> {
        let now = now_ms();
        let sql = format!(
            "DELETE FROM jobs WHERE id = $1 AND ($2 IS NULL OR tenant_id = $2) AND status IN {FINISHED} \
             RETURNING {JOB_COLUMNS}"
        );
        let mut tx = self.begin().await?;
        let row = sqlx::query(&sql)
            .bind(D::id(id.0))
            .bind(D::scope_id(scope))
            .fetch_optional(&mut *tx)
            .await?;
        let Some(row) = row else {
            Self::rollback(tx).await?;
            return Err(QueueError::JobNotFound(id));
        };
        let job = Self::job_from_row(&row)?;
        Self::audit(&mut tx, &job, reason, now).await?;
        Self::commit(tx).await?;
        Ok(job)
    }

    /// [`crate::queue::SongStore::delete_song`].
    pub(super) async fn delete_song_and_jobs(
        &self,
        scope: Scope,
        id: SongId,
        reason: &str,
    ) -> Result<Removed, QueueError> {
        let mut tx = self.begin().await?;
        let Some((song, jobs)) = Self::remove_song(&mut tx, scope, id, reason, now_ms()).await?
        else {
            // No song has the id in scope; jobs of such an id are another tenant's, untouched.
            Self::rollback(tx).await?;
            return Err(QueueError::SongNotFound(id));
        };
        Self::commit(tx).await?;
        Ok(Removed {
            songs: vec![song],
            jobs,
            rigs: Vec::new(),
        })
    }

    /// [`crate::queue::JobStore::touch_job`], [`crate::queue::SongStore::touch_song`] and
    /// [`crate::queue::RigStore::touch_rig`]: `table` is `jobs`, `songs` or `rigs`, never user
    /// input.
    pub(super) async fn record_use(&self, table: &'static str, id: Uuid) -> Result<(), QueueError> {
        let sql = format!("UPDATE {table} SET last_used_at = $1 WHERE id = $2");
        let mut tx = self.begin().await?;
        sqlx::query(&sql)
            .bind(now_ms())
            .bind(D::id(id))
            .execute(&mut *tx)
            .await?;
        Self::commit(tx).await
    }

    /// [`crate::queue::SongStore::expire`].
    pub(super) async fn expire_unused(
        &self,
        cutoff: DateTime<Utc>,
        limit: u32,
        reason: &str,
    ) -> Result<Removed, QueueError> {
        let now = now_ms();
        let cutoff = cutoff.timestamp_millis();
        let limit = i64::from(limit);
        let mut tx = self.begin().await?;
        // A finished dance's results, unused since the cutoff. Analyze jobs go with their song:
        // the song's analysis status is read from them.
        let sql = format!(
            "DELETE FROM jobs WHERE id IN (SELECT id FROM jobs WHERE kind = 'generate' AND status IN {FINISHED} \
             AND {JOB_LAST_USE} < $1 ORDER BY id LIMIT $2) RETURNING {JOB_COLUMNS}"
        );
        let rows = sqlx::query(&sql)
            .bind(cutoff)
            .bind(limit)
            .fetch_all(&mut *tx)
            .await?;
        let mut jobs = rows
            .iter()
            .map(Self::job_from_row)
            .collect::<Result<Vec<_>, _>>()?;
        for job in &jobs {
            Self::audit(&mut tx, job, reason, now).await?;
        }
        // A song unused since the cutoff, none of whose jobs is waiting, running or used since.
        let sql = format!(
            "SELECT {SONG_COLUMNS} FROM songs s WHERE COALESCE(s.last_used_at, s.created_at) < $1 \
             AND NOT EXISTS (SELECT 1 FROM jobs j WHERE j.song_id = s.id AND (j.status NOT IN {FINISHED} \
             OR COALESCE(j.last_used_at, j.finished_at, j.created_at) >= $1)) ORDER BY s.id LIMIT $2"
        );
        let rows = sqlx::query(&sql)
            .bind(cutoff)
            .bind(limit)
            .fetch_all(&mut *tx)
            .await?;
        let candidates = rows
            .iter()
            .map(Self::song_from_row)
            .collect::<Result<Vec<Song>, _>>()?;
        let mut songs = Vec::with_capacity(candidates.len());
        for song in candidates {
            if let Some((song, removed)) =
                Self::remove_song(&mut tx, Scope::All, song.id, reason, now).await?
            {
                songs.push(song);
                jobs.extend(removed);
            }
        }
        // Rigs: no song or job refers to one, so its own last use decides.
        let rigs = Self::expire_rigs(&mut tx, cutoff, limit).await?;
        Self::commit(tx).await?;
        Ok(Removed { songs, jobs, rigs })
    }
}
