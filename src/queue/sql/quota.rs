//! Quotas enforced where rows are written: a job, a song or a rig is admitted in the same
//! transaction that inserts it, and a job's results in the one that records their size.
//!
//! Checking usage first and inserting after, as two steps, let 50 requests released together
//! all pass `max_queued_jobs 3`. Here each admission first takes its tenant's row of
//! `tenant_admissions` (an upsert: PostgreSQL then holds that row's lock until the commit, and
//! SQLite, whose first write takes the database's one write lock, holds that), so a tenant's
//! admissions run one after another and each reads what the one before it wrote. Tenants without
//! a limit skip the lock: their writes never wait on each other.
use super::{corrupt, now_ms, Dialect, SqlStore};
use crate::queue::keys::{KeyLimits, Usage};
use crate::queue::{QueueError, TenantId};
use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Row, Type};

/// What a tenant holds now: its jobs queued or running, and the bytes of its songs (with their
/// caches), rigs and results. (PostgreSQL's SUM of a BIGINT is NUMERIC: cast back, in both.)
pub const USAGE_SQL: &str = "SELECT \
   (SELECT COUNT(*) FROM jobs WHERE tenant_id = $1 AND status IN ('queued', 'running')) AS queued_jobs, \
   CAST((SELECT COALESCE(SUM(size_bytes + cache_bytes), 0) FROM songs WHERE tenant_id = $1) \
      + (SELECT COALESCE(SUM(size_bytes), 0) FROM rigs WHERE tenant_id = $1) \
      + (SELECT COALESCE(SUM(result_bytes), 0) FROM jobs WHERE tenant_id = $1) AS BIGINT) AS stored_bytes";

/// What a write adds to its tenant's holdings.
#[derive(Clone, Copy, Debug, Default)]
pub struct Adds {
    /// Queued jobs it creates (a job; an upload with its analyze job).
    pub jobs: u64,
    /// Bytes it stores (an upload's file).
    pub bytes: u64,
    /// Whether it will store results (a job): refused while the tenant is at its quota.
    pub results: bool,
}

impl<D> SqlStore<D>
where
    D: Dialect,
    for<'c> &'c mut D::Connection: Executor<'c, Database = D>,
    for<'q> D::Arguments<'q>: IntoArguments<'q, D>,
    for<'q> i64: Encode<'q, D> + Decode<'q, D> + Type<D>,
    &'static str: ColumnIndex<D::Row>,
{
    /// What `tenant` holds, read on `conn` (inside the caller's transaction when it has one).
    pub(super) async fn usage_on(
        conn: &mut D::Connection,
        tenant: TenantId,
    ) -> Result<Usage, QueueError> {
        let row = sqlx::query(USAGE_SQL)
            .bind(D::id(tenant.0))
            .fetch_one(conn)
            .await?;
        let count = |name: &str, n: i64| u64::try_from(n).map_err(|e| corrupt(name, e));
        Ok(Usage {
            queued_jobs: count("queued jobs", row.try_get("queued_jobs")?)?,
            stored_bytes: count("stored bytes", row.try_get("stored_bytes")?)?,
        })
    }

    /// Takes `tenant`'s admission lock for the rest of the transaction on `conn`. Must be the
    /// transaction's first statement: in SQLite a write after a read could find its snapshot
    /// stale and fail instead of waiting.
    pub(super) async fn lock_tenant(
        conn: &mut D::Connection,
        tenant: TenantId,
    ) -> Result<(), QueueError> {
        sqlx::query(
            "INSERT INTO tenant_admissions (tenant_id, admitted_at) VALUES ($1, $2) \
             ON CONFLICT (tenant_id) DO UPDATE SET admitted_at = excluded.admitted_at",
        )
        .bind(D::id(tenant.0))
        .bind(now_ms())
        .execute(conn)
        .await?;
        Ok(())
    }

    /// Admits a write that `adds` to `tenant`'s holdings within `limits`, or refuses it; on
    /// `conn`, inside the write's transaction, before its first other statement.
    pub(super) async fn admit(
        conn: &mut D::Connection,
        tenant: TenantId,
        limits: &KeyLimits,
        adds: Adds,
    ) -> Result<(), QueueError> {
        let queue_limit = limits.max_queued_jobs.filter(|_| adds.jobs > 0);
        let quota = limits
            .storage_quota_bytes
            .filter(|_| adds.bytes > 0 || adds.results);
        if queue_limit.is_none() && quota.is_none() {
            return Ok(());
        }
        Self::lock_tenant(conn, tenant).await?;
        let usage = Self::usage_on(conn, tenant).await?;
        if let Some(limit) = queue_limit {
            if usage.queued_jobs.saturating_add(adds.jobs) > limit {
                return Err(QueueError::QueueFull { limit });
            }
        }
        if let Some(quota) = quota {
            if adds.bytes > 0 && usage.stored_bytes.saturating_add(adds.bytes) > quota {
                return Err(QueueError::QuotaExceeded {
                    used: usage.stored_bytes,
                    size: adds.bytes,
                    quota,
                });
            }
            if adds.results && usage.stored_bytes >= quota {
                return Err(QueueError::QuotaFull {
                    used: usage.stored_bytes,
                    quota,
                });
            }
        }
        Ok(())
    }
}
