//! The API key and usage statements of [`SqlStore`], for both stores.
use super::quota::Adds;
use super::{corrupt, now_ms, opt_time, to_time, Dialect, SqlStore, StoreFuture};
use crate::queue::keys::{ApiKey, KeyLimits, NewKey, TenantStore, Usage};
use crate::queue::{JobId, KeyId, QueueError, TenantId};
use chrono::{DateTime, Utc};
use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Row, Type};

/// The columns a key row is read from.
const KEY_COLUMNS: &str =
    "id, tenant_id, name, secret_sha256, admin, rate_limit_rps, max_queued_jobs, \
     storage_quota_bytes, created_at, last_used_at, revoked_at";

fn to_i64(what: &str, n: Option<u64>) -> Result<Option<i64>, QueueError> {
    n.map(|n| i64::try_from(n).map_err(|e| corrupt(what, e)))
        .transpose()
}

fn to_u64(what: &str, n: Option<i64>) -> Result<Option<u64>, QueueError> {
    n.map(|n| u64::try_from(n).map_err(|e| corrupt(what, e)))
        .transpose()
}

impl<D> SqlStore<D>
where
    D: Dialect,
    for<'q> i64: Decode<'q, D> + Type<D>,
    for<'q> f64: Decode<'q, D> + Type<D>,
    for<'q> bool: Decode<'q, D> + Type<D>,
    for<'q> String: Decode<'q, D> + Type<D>,
    &'static str: ColumnIndex<D::Row>,
{
    fn key_from_row(row: &D::Row) -> Result<ApiKey, QueueError> {
        Ok(ApiKey {
            id: KeyId(D::uuid(row.try_get("id")?).map_err(|e| corrupt("key id", e))?),
            tenant: TenantId(
                D::uuid(row.try_get("tenant_id")?).map_err(|e| corrupt("key tenant", e))?,
            ),
            name: row.try_get("name")?,
            admin: row.try_get("admin")?,
            limits: KeyLimits {
                rate_limit_rps: row.try_get("rate_limit_rps")?,
                max_queued_jobs: to_u64("max_queued_jobs", row.try_get("max_queued_jobs")?)?,
                storage_quota_bytes: to_u64(
                    "storage_quota_bytes",
                    row.try_get("storage_quota_bytes")?,
                )?,
            },
            secret_sha256: row.try_get("secret_sha256")?,
            created_at: to_time(row.try_get("created_at")?)?,
            last_used_at: opt_time(row.try_get("last_used_at")?)?,
            revoked_at: opt_time(row.try_get("revoked_at")?)?,
        })
    }
}

impl<D> TenantStore for SqlStore<D>
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
    for<'q> Option<f64>: Encode<'q, D>,
    &'static str: ColumnIndex<D::Row>,
{
    fn add_key(&self, key: NewKey) -> StoreFuture<'_, ApiKey> {
        Box::pin(async move {
            let sql = format!(
                "INSERT INTO api_keys (id, tenant_id, name, secret_sha256, admin, rate_limit_rps, max_queued_jobs, \
                 storage_quota_bytes, created_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) RETURNING {KEY_COLUMNS}"
            );
            let mut tx = self.begin().await?;
            let row = sqlx::query(&sql)
                .bind(D::id(key.id.0))
                .bind(D::id(key.tenant.0))
                .bind(key.name.as_str())
                .bind(key.secret_sha256.as_str())
                .bind(key.admin)
                .bind(key.limits.rate_limit_rps)
                .bind(to_i64("max_queued_jobs", key.limits.max_queued_jobs)?)
                .bind(to_i64(
                    "storage_quota_bytes",
                    key.limits.storage_quota_bytes,
                )?)
                .bind(now_ms())
                .fetch_one(&mut *tx)
                .await?;
            let stored = Self::key_from_row(&row)?;
            Self::commit(tx).await?;
            Ok(stored)
        })
    }

    fn keys(&self) -> StoreFuture<'_, Vec<ApiKey>> {
        Box::pin(async move {
            let sql = format!("SELECT {KEY_COLUMNS} FROM api_keys ORDER BY created_at, id");
            let rows = sqlx::query(&sql).fetch_all(&self.pool).await?;
            rows.iter().map(Self::key_from_row).collect()
        })
    }

    fn key(&self, id: KeyId) -> StoreFuture<'_, ApiKey> {
        Box::pin(async move {
            let sql = format!("SELECT {KEY_COLUMNS} FROM api_keys WHERE id = $1");
            match sqlx::query(&sql)
                .bind(D::id(id.0))
                .fetch_optional(&self.pool)
                .await?
            {
                Some(row) => Self::key_from_row(&row),
                None => Err(QueueError::KeyNotFound(id)),
            }
        })
    }

    fn any_key(&self) -> StoreFuture<'_, bool> {
        Box::pin(async move {
            let row = sqlx::query("SELECT 1 FROM api_keys LIMIT 1")
                .fetch_optional(&self.pool)
                .await?;
            Ok(row.is_some())
        })
    }

    fn revoke_key(&self, id: KeyId) -> StoreFuture<'_, ApiKey> {
        Box::pin(async move {
            let sql = format!(
                "UPDATE api_keys SET revoked_at = COALESCE(revoked_at, $1) WHERE id = $2 RETURNING {KEY_COLUMNS}"
            );
            let mut tx = self.begin().await?;
            let row = sqlx::query(&sql)
                .bind(now_ms())
                .bind(D::id(id.0))
                .fetch_optional(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            match row {
                Some(row) => Self::key_from_row(&row),
                None => Err(QueueError::KeyNotFound(id)),
            }
        })
    }

    fn touch_key(&self, id: KeyId, at: DateTime<Utc>) -> StoreFuture<'_, ()> {
        Box::pin(async move {
            let mut tx = self.begin().await?;
            sqlx::query("UPDATE api_keys SET last_used_at = $1 WHERE id = $2")
                .bind(at.timestamp_millis())
                .bind(D::id(id.0))
                .execute(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            Ok(())
        })
    }

    fn usage(&self, tenant: TenantId) -> StoreFuture<'_, Usage> {
        Box::pin(async move {
            let mut conn = self.pool.acquire().await?;
            Self::usage_on(&mut conn, tenant).await
        })
    }

    fn record_result_bytes(&self, job: JobId, bytes: u64) -> StoreFuture<'_, ()> {
        Box::pin(async move {
            let row = sqlx::query("SELECT tenant_id, storage_quota_bytes FROM jobs WHERE id = $1")
                .bind(D::id(job.0))
                .fetch_optional(&self.pool)
                .await?;
            let Some(row) = row else {
                // Deleted while it ran: nothing to count.
                return Ok(());
            };
            let tenant = Self::tenant_from_row(&row)?;
            let quota = to_u64("storage quota", row.try_get("storage_quota_bytes")?)?;
            let mut tx = self.begin().await?;
            let limits = KeyLimits {
                storage_quota_bytes: quota,
                ..KeyLimits::default()
            };
            let adds = Adds {
                results: true,
                ..Adds::default()
            };
            Self::admit(&mut tx, tenant, &limits, adds).await?;
            sqlx::query("UPDATE jobs SET result_bytes = $1 WHERE id = $2")
                .bind(i64::try_from(bytes).map_err(|e| corrupt("result bytes", e))?)
                .bind(D::id(job.0))
                .execute(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            Ok(())
        })
    }
}
