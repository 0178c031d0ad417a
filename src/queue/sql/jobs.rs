//! The job statements of [`SqlStore`], for both stores: the queue's verbs (register with its
//! idempotency key, claim, heartbeat, complete, fail, cancel), the requeue of expired leases,
//! and the reads.
use super::quota::Adds;
use super::{corrupt, ms, now_ms, Dialect, SqlStore, JOB_COLUMNS, MAX_BACKOFF_DOUBLINGS};
use crate::queue::{
    Beat, Job, JobFilter, JobId, JobStore, KeyLimits, LeasePolicy, NewJob, Outcome, QueueError,
    Registered, Requeued, Scope, Status, StoreFuture,
};
use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Row, Type};
use std::str::FromStr;
use std::sync::Arc;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;

impl<D> JobStore for SqlStore<D>
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
    fn register_within(&self, job: NewJob, limits: KeyLimits) -> StoreFuture<'_, Registered> {
        Box::pin(async move {
            let song = job.kind.song_id();
            // A job works on its own tenant's song: another tenant's reads as missing.
            let exists = sqlx::query("SELECT 1 FROM songs WHERE id = $1 AND tenant_id = $2")
                .bind(D::id(song.0))
                .bind(D::id(job.tenant.0))
                .fetch_optional(&self.pool)
                .await?;
            if exists.is_none() {
                return Err(QueueError::SongNotFound(song));
            }
            // A retried request (its idempotency key taken) is answered with its job below
            // whatever the limits: only a new job is held to them.
            let taken = match &job.idempotency {
                Some(idem) => {
                    sqlx::query("SELECT 1 FROM jobs WHERE tenant_id = $1 AND idempotency_key = $2")
                        .bind(D::id(job.tenant.0))
                        .bind(&idem.key)
                        .fetch_optional(&self.pool)
                        .await?
                        .is_some()
                }
                None => false,
            };
            let mut tx = self.begin().await?;
            if !taken {
                let adds = Adds {
                    jobs: 1,
                    bytes: 0,
                    results: true,
                };
                Self::admit(&mut tx, job.tenant, &limits, adds).await?;
            }
            let created =
                Self::insert_job(&mut tx, &job, now_ms(), limits.storage_quota_bytes).await?;
            Self::commit(tx).await?;
            if let Some(created) = created {
                return Ok(Registered::Created(created));
            }
            // Only the idempotency key can conflict: the id is fresh.
            let Some(idem) = &job.idempotency else {
                return Err(QueueError::Corrupt(
                    "insert of a job without idempotency key returned nothing".into(),
                ));
            };
            let sql = format!("SELECT {JOB_COLUMNS}, request_hash FROM jobs WHERE tenant_id = $1 AND idempotency_key = $2");
            let row = sqlx::query(&sql)
                .bind(D::id(job.tenant.0))
                .bind(&idem.key)
                .fetch_one(&self.pool)
                .await?;
            let existing = Self::job_from_row(&row)?;
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
            // One statement selects and leases the job, so two workers never get the same one.
            // Fair between tenants: the tenant with the fewest jobs running goes first, then the
            // one served least recently (its latest job started earliest, or never), so one
            // tenant's 500 queued jobs wait behind another's single job rather than before it.
            // Priority orders a tenant's own jobs only: a client sets it, so across tenants it
            // would let one starve the others. (PostgreSQL: two claims at the same instant may
            // both see a tenant as idle; the next claim evens it out.)
            let sql = format!(
                "UPDATE jobs SET status = 'running', attempts = attempts + 1, lease_owner = $1, \
                 lease_expires_at = $2, heartbeat_at = $3, started_at = COALESCE(started_at, $3), \
                 stage = 'claimed', progress = 0 \
                 WHERE id = (SELECT q.id FROM jobs q WHERE q.status = 'queued' AND q.run_after <= $3 \
                             ORDER BY (SELECT COUNT(*) FROM jobs r WHERE r.tenant_id = q.tenant_id AND r.status = 'running'), \
                                      (SELECT COALESCE(MAX(s.started_at), 0) FROM jobs s WHERE s.tenant_id = q.tenant_id), \
                                      q.priority DESC, q.run_after, q.id LIMIT 1{}) \
                 RETURNING {JOB_COLUMNS}",
                D::SKIP_LOCKED
            );
            let mut tx = self.begin().await?;
            let row = sqlx::query(&sql)
                .bind(owner)
                .bind(now + ms(policy.lease))
                .bind(now)
                .fetch_optional(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            row.as_ref().map(Self::job_from_row).transpose()
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
            let mut tx = self.begin().await?;
            let row = sqlx::query(
                "UPDATE jobs SET heartbeat_at = $1, lease_expires_at = $2, stage = $3, progress = $4 \
                 WHERE id = $5 AND lease_owner = $6 AND status = 'running' RETURNING cancel_requested",
            )
            .bind(now)
            .bind(now + ms(policy.lease))
            .bind(stage)
            .bind(progress.clamp(0.0, 1.0))
            .bind(D::id(id.0))
            .bind(owner)
            .fetch_optional(&mut *tx)
            .await?;
            Self::commit(tx).await?;
            Ok(match row {
                Some(row) => Beat::Held {
                    cancel_requested: row.try_get("cancel_requested")?,
                },
                None => Beat::Lost,
            })
        })
    }

    fn complete<'a>(
        &'a self,
        id: JobId,
        owner: &'a str,
        outcome: Outcome,
    ) -> StoreFuture<'a, bool> {
        Box::pin(async move {
            let files = match &outcome {
                Outcome::Files(files) => {
                    Some(serde_json::to_string(files).map_err(|e| corrupt("job result", e))?)
                }
                Outcome::Analysis(_) => None,
            };
            let mut tx = self.begin().await?;
            let row = sqlx::query(
                "UPDATE jobs SET status = 'succeeded', stage = 'done', progress = 1, result = $1, error = NULL, \
                 finished_at = $2, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = $3 AND lease_owner = $4 AND status = 'running' RETURNING song_id",
            )
            .bind(files)
            .bind(now_ms())
            .bind(D::id(id.0))
            .bind(owner)
            .fetch_optional(&mut *tx)
            .await?;
            let Some(row) = row else {
                Self::rollback(tx).await?;
                return Ok(false);
            };
            if let Outcome::Analysis(analysis) = &outcome {
                let song_id: D::Id = row.try_get("song_id")?;
                let json = serde_json::to_string(analysis).map_err(|e| corrupt("analysis", e))?;
                sqlx::query("UPDATE songs SET analysis = $1 WHERE id = $2")
                    .bind(json)
                    .bind(song_id)
                    .execute(&mut *tx)
                    .await?;
            }
            Self::commit(tx).await?;
            Ok(true)
        })
    }

    fn fail<'a>(
        &'a self,
        id: JobId,
        owner: &'a str,
        error: &'a str,
        retry: bool,
        policy: LeasePolicy,
    ) -> StoreFuture<'a, bool> {
        Box::pin(async move {
            let now = now_ms();
            let sql = format!(
                "UPDATE jobs SET \
                   status = CASE WHEN $1 AND attempts < max_attempts AND NOT cancel_requested THEN 'queued' \
                                 WHEN cancel_requested THEN 'cancelled' ELSE 'failed' END, \
                   finished_at = CASE WHEN $1 AND attempts < max_attempts AND NOT cancel_requested THEN NULL ELSE $2 END, \
                   run_after = $2 + $3 * {}, \
                   error = $5, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = $6 AND lease_owner = $7 AND status = 'running'",
                D::backoff_factor("$4")
            );
            let mut tx = self.begin().await?;
            let done = sqlx::query(&sql)
                .bind(retry)
                .bind(now)
                .bind(ms(policy.backoff))
                .bind(MAX_BACKOFF_DOUBLINGS)
                .bind(error)
                .bind(D::id(id.0))
                .bind(owner)
                .execute(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            Ok(D::rows_affected(&done) == 1)
        })
    }

    fn finish_cancelled<'a>(&'a self, id: JobId, owner: &'a str) -> StoreFuture<'a, bool> {
        Box::pin(async move {
            let mut tx = self.begin().await?;
            let done = sqlx::query(
                "UPDATE jobs SET status = 'cancelled', finished_at = $1, lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id = $2 AND lease_owner = $3 AND status = 'running'",
            )
            .bind(now_ms())
            .bind(D::id(id.0))
            .bind(owner)
            .execute(&mut *tx)
            .await?;
            Self::commit(tx).await?;
            Ok(D::rows_affected(&done) == 1)
        })
    }

    fn cancel(&self, scope: Scope, id: JobId) -> StoreFuture<'_, Job> {
        Box::pin(async move {
            // In the SET of both databases, every column reads the row as it was before.
            let sql = format!(
                "UPDATE jobs SET \
                   status = CASE WHEN status = 'queued' THEN 'cancelled' ELSE status END, \
                   finished_at = CASE WHEN status = 'queued' THEN $1 ELSE finished_at END, \
                   cancel_requested = CASE WHEN status IN ('queued', 'running') THEN TRUE ELSE cancel_requested END \
                 WHERE id = $2 AND ($3 IS NULL OR tenant_id = $3) RETURNING {JOB_COLUMNS}"
            );
            let mut tx = self.begin().await?;
            let row = sqlx::query(&sql)
                .bind(now_ms())
                .bind(D::id(id.0))
                .bind(D::scope_id(scope))
                .fetch_optional(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            match row {
                Some(row) => Self::job_from_row(&row),
                None => Err(QueueError::JobNotFound(id)),
            }
        })
    }

    fn requeue_expired(&self, policy: LeasePolicy) -> StoreFuture<'_, Requeued> {
        Box::pin(async move {
            let now = now_ms();
            // Every worker process runs a reaper; with many writers, skipping locked rows keeps
            // two reapers (or a reaper and a late heartbeat) from waiting on each other, and the
            // row lock from counting a lease twice.
            let sql = format!(
                "UPDATE jobs SET \
                   status = CASE WHEN cancel_requested THEN 'cancelled' \
                                 WHEN attempts >= max_attempts THEN 'failed' ELSE 'queued' END, \
                   finished_at = CASE WHEN cancel_requested OR attempts >= max_attempts THEN $1 ELSE NULL END, \
                   error = 'lease expired on attempt ' || attempts || ' of ' || max_attempts || \
                           ' (the worker died or hung)' || COALESCE('; last error: ' || error, ''), \
                   run_after = $1 + $2 * {}, \
                   lease_owner = NULL, lease_expires_at = NULL \
                 WHERE id IN (SELECT id FROM jobs WHERE status = 'running' AND lease_expires_at < $1{}) \
                 RETURNING id, status",
                D::backoff_factor("$3"),
                D::SKIP_LOCKED
            );
            let mut tx = self.begin().await?;
            let rows = sqlx::query(&sql)
                .bind(now)
                .bind(ms(policy.backoff))
                .bind(MAX_BACKOFF_DOUBLINGS)
                .fetch_all(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            let mut out = Requeued::default();
            for row in rows {
                let id = JobId(D::uuid(row.try_get("id")?).map_err(|e| corrupt("job id", e))?);
                let status: String = row.try_get("status")?;
                match Status::from_str(&status).map_err(|e| corrupt("job status", e))? {
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

    fn job(&self, scope: Scope, id: JobId) -> StoreFuture<'_, Job> {
        Box::pin(async move {
            let sql = format!(
                "SELECT {JOB_COLUMNS} FROM jobs WHERE id = $1 AND ($2 IS NULL OR tenant_id = $2)"
            );
            let tenant = D::scope_id(scope);
            match sqlx::query(&sql)
                .bind(D::id(id.0))
                .bind(tenant)
                .fetch_optional(&self.pool)
                .await?
            {
                Some(row) => Self::job_from_row(&row),
                None => Err(QueueError::JobNotFound(id)),
            }
        })
    }

    fn jobs(&self, scope: Scope, filter: JobFilter) -> StoreFuture<'_, Vec<Job>> {
        Box::pin(async move {
            // Each parameter is bound with its type, so `$n IS NULL` needs no cast.
            let sql = format!(
                "SELECT {JOB_COLUMNS} FROM jobs WHERE ($1 IS NULL OR status = $1) AND ($2 IS NULL OR model = $2) \
                 AND ($3 IS NULL OR id < $3) AND ($5 IS NULL OR tenant_id = $5) ORDER BY id DESC LIMIT $4"
            );
            let rows = sqlx::query(&sql)
                .bind(filter.status.map(Status::as_str))
                .bind(filter.model)
                .bind(filter.before.map(|id| D::id(id.0)))
                .bind(i64::from(filter.limit))
                .bind(D::scope_id(scope))
                .fetch_all(&self.pool)
                .await?;
            rows.iter().map(Self::job_from_row).collect()
        })
    }

    fn counts(&self) -> StoreFuture<'_, Vec<(Status, u64)>> {
        Box::pin(async move {
            let rows = sqlx::query("SELECT status, COUNT(*) AS n FROM jobs GROUP BY status")
                .fetch_all(&self.pool)
                .await?;
            let mut counts: Vec<(Status, u64)> = Status::ALL.iter().map(|s| (*s, 0)).collect();
            for row in rows {
                let status: String = row.try_get("status")?;
                let status = Status::from_str(&status).map_err(|e| corrupt("job status", e))?;
                let n: i64 = row.try_get("n")?;
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
        D::watch(&self.pool, wake, shutdown)
    }

    // Deletion and retention: `sql/delete.rs`.
    fn delete_job<'a>(&'a self, scope: Scope, id: JobId, reason: &'a str) -> StoreFuture<'a, Job> {
        Box::pin(self.delete_finished_job(scope, id, reason))
    }

    fn touch_job(&self, id: JobId) -> StoreFuture<'_, ()> {
        Box::pin(self.record_use("jobs", id.0))
    }
}
