//! The song statements of [`SqlStore`], for both stores: an upload with its analyze job in one
//! transaction (held to the tenant's limits, `super::quota`), the reads, deletion and expiry.
use super::quota::Adds;
use super::{corrupt, format_name, now_ms, Dialect, SqlStore, JOB_COLUMNS, SONG_COLUMNS};
use crate::queue::{
    Job, KeyLimits, NewJob, QueueError, Removed, Scope, Song, SongFilter, SongId, SongStore,
    StoreFuture, TenantId,
};
use chrono::{DateTime, Utc};
use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Type};

impl<D> SongStore for SqlStore<D>
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
    fn add_song_within(
        &self,
        song: Song,
        analyze: NewJob,
        limits: KeyLimits,
    ) -> StoreFuture<'_, (Song, bool)> {
        Box::pin(async move {
            let now = now_ms();
            // Bytes the tenant already has cost nothing: such an upload is answered with its song.
            let known = sqlx::query("SELECT 1 FROM songs WHERE tenant_id = $1 AND sha256 = $2")
                .bind(D::id(song.tenant.0))
                .bind(&song.sha256)
                .fetch_optional(&self.pool)
                .await?
                .is_some();
            let mut tx = self.begin().await?;
            if !known {
                let adds = Adds {
                    jobs: 1,
                    bytes: song.size_bytes,
                    results: false,
                };
                Self::admit(&mut tx, song.tenant, &limits, adds).await?;
            }
            let sql = format!(
                "INSERT INTO songs (id, filename, format, duration_s, sample_rate, channels, sha256, size_bytes, created_at, \
                 tenant_id) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10) \
                 ON CONFLICT (tenant_id, sha256) DO NOTHING RETURNING {SONG_COLUMNS}"
            );
            let inserted = sqlx::query(&sql)
                .bind(D::id(song.id.0))
                .bind(&song.filename)
                .bind(format_name(&song)?)
                .bind(song.duration_s)
                .bind(i64::from(song.sample_rate))
                .bind(i64::from(song.channels))
                .bind(&song.sha256)
                .bind(i64::try_from(song.size_bytes).map_err(|e| corrupt("size_bytes", e))?)
                .bind(now)
                .bind(D::id(song.tenant.0))
                .fetch_optional(&mut *tx)
                .await?;
            let Some(row) = inserted else {
                // The conflicting row is committed (SQLite has one writer; PostgreSQL's ON
                // CONFLICT waits for the other transaction), so a fresh read in this one sees it.
                let sql = format!(
                    "SELECT {SONG_COLUMNS} FROM songs WHERE tenant_id = $1 AND sha256 = $2"
                );
                let row = sqlx::query(&sql)
                    .bind(D::id(song.tenant.0))
                    .bind(&song.sha256)
                    .fetch_one(&mut *tx)
                    .await?;
                let existing = Self::song_from_row(&row)?;
                Self::commit(tx).await?;
                return Ok((existing, false));
            };
            let stored = Self::song_from_row(&row)?;
            if Self::insert_job(&mut tx, &analyze, now, None)
                .await?
                .is_none()
            {
                return Err(QueueError::Corrupt(
                    "analyze job insert returned nothing".into(),
                ));
            }
            Self::commit(tx).await?;
            Ok((stored, true))
        })
    }

    fn song(&self, scope: Scope, id: SongId) -> StoreFuture<'_, Song> {
        Box::pin(async move {
            let sql = format!(
                "SELECT {SONG_COLUMNS} FROM songs WHERE id = $1 AND ($2 IS NULL OR tenant_id = $2)"
            );
            let tenant = D::scope_id(scope);
            match sqlx::query(&sql)
                .bind(D::id(id.0))
                .bind(tenant)
                .fetch_optional(&self.pool)
                .await?
            {
                Some(row) => Self::song_from_row(&row),
                None => Err(QueueError::SongNotFound(id)),
            }
        })
    }

    fn songs(&self, scope: Scope, filter: SongFilter) -> StoreFuture<'_, Vec<Song>> {
        Box::pin(async move {
            // Ids are UUID v7, so their order is the upload order in both stores.
            let sql = format!(
                "SELECT {SONG_COLUMNS} FROM songs WHERE ($1 IS NULL OR id < $1) \
                 AND ($2 IS NULL OR tenant_id = $2) ORDER BY id DESC LIMIT $3"
            );
            let rows = sqlx::query(&sql)
                .bind(filter.before.map(|id| D::id(id.0)))
                .bind(D::scope_id(scope))
                .bind(i64::from(filter.limit))
                .fetch_all(&self.pool)
                .await?;
            rows.iter().map(Self::song_from_row).collect()
        })
    }

    fn song_by_sha256<'a>(
        &'a self,
        tenant: TenantId,
        sha256: &'a str,
    ) -> StoreFuture<'a, Option<Song>> {
        Box::pin(async move {
            let sql =
                format!("SELECT {SONG_COLUMNS} FROM songs WHERE tenant_id = $1 AND sha256 = $2");
            let row = sqlx::query(&sql)
                .bind(D::id(tenant.0))
                .bind(sha256)
                .fetch_optional(&self.pool)
                .await?;
            row.as_ref().map(Self::song_from_row).transpose()
        })
    }

    fn analyze_job(&self, song: SongId) -> StoreFuture<'_, Option<Job>> {
        Box::pin(async move {
            let sql = format!("SELECT {JOB_COLUMNS} FROM jobs WHERE song_id = $1 AND kind = 'analyze' ORDER BY id DESC LIMIT 1");
            let row = sqlx::query(&sql)
                .bind(D::id(song.0))
                .fetch_optional(&self.pool)
                .await?;
            row.as_ref().map(Self::job_from_row).transpose()
        })
    }

    // Deletion and retention: `sql/delete.rs`.
    fn delete_song<'a>(
        &'a self,
        scope: Scope,
        id: SongId,
        reason: &'a str,
    ) -> StoreFuture<'a, Removed> {
        Box::pin(self.delete_song_and_jobs(scope, id, reason))
    }

    fn touch_song(&self, id: SongId) -> StoreFuture<'_, ()> {
        Box::pin(self.record_use("songs", id.0))
    }

    fn add_song_cache_bytes(&self, id: SongId, bytes: u64) -> StoreFuture<'_, bool> {
        Box::pin(async move {
            let bytes = i64::try_from(bytes).map_err(|e| corrupt("song cache bytes", e))?;
            let mut tx = self.begin().await?;
            let row = sqlx::query(
                "UPDATE songs SET cache_bytes = cache_bytes + $1 WHERE id = $2 RETURNING cache_bytes",
            )
            .bind(bytes)
            .bind(D::id(id.0))
            .fetch_optional(&mut *tx)
            .await?;
            Self::commit(tx).await?;
            Ok(row.is_some())
        })
    }

    fn expire<'a>(
        &'a self,
        cutoff: DateTime<Utc>,
        limit: u32,
        reason: &'a str,
    ) -> StoreFuture<'a, Removed> {
        Box::pin(self.expire_unused(cutoff, limit, reason))
    }
}
