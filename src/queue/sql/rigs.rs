//! The rig statements of [`SqlStore`], for both stores (the rules in one place, as the queue's).
//!
//! A rig's last use is `COALESCE(last_used_at, created_at)` (migration
//! `20261207000000_rig_use.sql`); its expiry runs inside the store's one expiry transaction
//! (`sql/delete.rs`), through [`SqlStore::expire_rigs`].
use super::quota::Adds;
use super::{corrupt, now_ms, to_time, Dialect, SqlStore, StoreFuture};
use crate::motion::retarget::uploaded::SkeletonJson;
use crate::motion::retarget::TargetSkeleton;
use crate::queue::{
    KeyLimits, QueueError, Removed, RigFilter, RigId, RigStore, Scope, TenantId, UploadedRig,
};
use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Row, Type};

/// The columns a rig row is read from.
const RIG_COLUMNS: &str =
    "id, tenant_id, filename, format, units, sha256, size_bytes, skeleton, created_at";

/// A unit enum's stored text: its serde name (`bvh`, `cm`).
fn stored_name<T: serde::Serialize>(what: &str, value: &T) -> Result<String, QueueError> {
    match serde_json::to_value(value).map_err(|e| corrupt(what, e))? {
        serde_json::Value::String(s) => Ok(s),
        other => Err(corrupt(what, other)),
    }
}

fn from_stored<T: serde::de::DeserializeOwned>(what: &str, text: String) -> Result<T, QueueError> {
    serde_json::from_value(serde_json::Value::String(text)).map_err(|e| corrupt(what, e))
}

impl<D> SqlStore<D>
where
    D: Dialect,
    for<'q> i64: Decode<'q, D> + Type<D>,
    for<'q> String: Decode<'q, D> + Type<D>,
    &'static str: ColumnIndex<D::Row>,
{
    fn rig_from_row(row: &D::Row) -> Result<UploadedRig, QueueError> {
        let skeleton: String = row.try_get("skeleton")?;
        let skeleton: SkeletonJson =
            serde_json::from_str(&skeleton).map_err(|e| corrupt("rig skeleton", e))?;
        Ok(UploadedRig {
            id: RigId(D::uuid(row.try_get("id")?).map_err(|e| corrupt("rig id", e))?),
            tenant: TenantId(
                D::uuid(row.try_get("tenant_id")?).map_err(|e| corrupt("rig tenant", e))?,
            ),
            filename: row.try_get("filename")?,
            format: from_stored("rig format", row.try_get("format")?)?,
            units: from_stored("rig units", row.try_get("units")?)?,
            sha256: row.try_get("sha256")?,
            size_bytes: row
                .try_get::<i64, _>("size_bytes")?
                .try_into()
                .map_err(|e| corrupt("size_bytes", e))?,
            skeleton: TargetSkeleton::try_from(skeleton).map_err(|e| corrupt("rig skeleton", e))?,
            created_at: to_time(row.try_get("created_at")?)?,
        })
    }
}

impl<D> SqlStore<D>
where
    D: Dialect,
    for<'c> &'c mut D::Connection: Executor<'c, Database = D>,
    for<'q> D::Arguments<'q>: IntoArguments<'q, D>,
    for<'q> i64: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> String: Decode<'q, D> + Type<D>,
    &'static str: ColumnIndex<D::Row>,
{
    /// Removes up to `limit` rigs last used before `cutoff` (epoch ms) inside the caller's
    /// transaction ([`crate::queue::SongStore::expire`]); returns them, whose files are the
    /// caller's to remove.
    pub(super) async fn expire_rigs(
        conn: &mut D::Connection,
        cutoff: i64,
        limit: i64,
    ) -> Result<Vec<UploadedRig>, QueueError> {
        let sql = format!(
            "DELETE FROM rigs WHERE id IN (SELECT id FROM rigs WHERE COALESCE(last_used_at, created_at) < $1 \
             ORDER BY id LIMIT $2) RETURNING {RIG_COLUMNS}"
        );
        let rows = sqlx::query(&sql)
            .bind(cutoff)
            .bind(limit)
            .fetch_all(conn)
            .await?;
        rows.iter().map(Self::rig_from_row).collect()
    }
}

impl<D> RigStore for SqlStore<D>
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
    fn add_rig_within(&self, rig: UploadedRig, limits: KeyLimits) -> StoreFuture<'_, UploadedRig> {
        Box::pin(async move {
            let skeleton = serde_json::to_string(&SkeletonJson::from(&rig.skeleton))
                .map_err(|e| corrupt("rig skeleton", e))?;
            let mut tx = self.begin().await?;
            let adds = Adds {
                bytes: rig.size_bytes,
                ..Adds::default()
            };
            Self::admit(&mut tx, rig.tenant, &limits, adds).await?;
            let sql = format!(
                "INSERT INTO rigs (id, filename, format, units, sha256, size_bytes, skeleton, created_at, tenant_id) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) RETURNING {RIG_COLUMNS}"
            );
            let row = sqlx::query(&sql)
                .bind(D::id(rig.id.0))
                .bind(&rig.filename)
                .bind(stored_name("rig format", &rig.format)?)
                .bind(stored_name("rig units", &rig.units)?)
                .bind(&rig.sha256)
                .bind(i64::try_from(rig.size_bytes).map_err(|e| corrupt("size_bytes", e))?)
                .bind(skeleton)
                .bind(now_ms())
                .bind(D::id(rig.tenant.0))
                .fetch_one(&mut *tx)
                .await?;
            let stored = Self::rig_from_row(&row)?;
            Self::commit(tx).await?;
            Ok(stored)
        })
    }

    fn rig(&self, scope: Scope, id: RigId) -> StoreFuture<'_, UploadedRig> {
        Box::pin(async move {
            let sql = format!(
                "SELECT {RIG_COLUMNS} FROM rigs WHERE id = $1 AND ($2 IS NULL OR tenant_id = $2)"
            );
            match sqlx::query(&sql)
                .bind(D::id(id.0))
                .bind(D::scope_id(scope))
                .fetch_optional(&self.pool)
                .await?
            {
                Some(row) => Self::rig_from_row(&row),
                None => Err(QueueError::RigNotFound(id)),
            }
        })
    }

    fn rigs(&self, scope: Scope, filter: RigFilter) -> StoreFuture<'_, Vec<UploadedRig>> {
        Box::pin(async move {
            // Ids are UUID v7, so their order is the upload order in both stores.
            let sql = format!(
                "SELECT {RIG_COLUMNS} FROM rigs WHERE ($1 IS NULL OR id < $1) \
                 AND ($2 IS NULL OR tenant_id = $2) ORDER BY id DESC LIMIT $3"
            );
            let rows = sqlx::query(&sql)
                .bind(filter.before.map(|id| D::id(id.0)))
                .bind(D::scope_id(scope))
                .bind(i64::from(filter.limit))
                .fetch_all(&self.pool)
                .await?;
            rows.iter().map(Self::rig_from_row).collect()
        })
    }

    fn delete_rig(&self, scope: Scope, id: RigId) -> StoreFuture<'_, Removed> {
        Box::pin(async move {
            let sql = format!(
                "DELETE FROM rigs WHERE id = $1 AND ($2 IS NULL OR tenant_id = $2) RETURNING {RIG_COLUMNS}"
            );
            let mut tx = self.begin().await?;
            let row = sqlx::query(&sql)
                .bind(D::id(id.0))
                .bind(D::scope_id(scope))
                .fetch_optional(&mut *tx)
                .await?;
            let Some(row) = row else {
                // Another tenant's rig reads as missing, and stays.
                Self::rollback(tx).await?;
                return Err(QueueError::RigNotFound(id));
            };
            let rig = Self::rig_from_row(&row)?;
            Self::commit(tx).await?;
            Ok(Removed {
                rigs: vec![rig],
                ..Removed::default()
            })
        })
    }

    fn touch_rig(&self, id: RigId) -> StoreFuture<'_, ()> {
        Box::pin(self.record_use("rigs", id.0))
    }
}
