//! The event-log and webhook-outbox statements of [`SqlStore`], for both stores.
use super::{corrupt, ms, now_ms, to_time, Dialect, SqlStore, StoreFuture};
use crate::queue::events::{Change, EventStore, JobEvent, WebhookAttempt, WebhookDue, WebhookNext};
use crate::queue::{JobId, QueueError, Status, TenantId};
use sqlx::{ColumnIndex, Decode, Encode, Executor, IntoArguments, Row, Type};
use std::str::FromStr;
use std::time::Duration;

impl<D> SqlStore<D>
where
    D: Dialect,
    for<'q> i64: Decode<'q, D> + Type<D>,
    for<'q> f64: Decode<'q, D> + Type<D>,
    for<'q> String: Decode<'q, D> + Type<D>,
    for<'q> Option<String>: Decode<'q, D>,
    &'static str: ColumnIndex<D::Row>,
{
    fn job_id_from(row: &D::Row) -> Result<JobId, QueueError> {
        Ok(JobId(
            D::uuid(row.try_get("job_id")?).map_err(|e| corrupt("job id", e))?,
        ))
    }

    /// A `job_events` row, or `None` for a line this build does not stream (an unknown kind,
    /// stage or status, e.g. an audit line another version wrote).
    fn event_from_row(row: &D::Row) -> Result<Option<JobEvent>, QueueError> {
        let kind: String = row.try_get("kind")?;
        let attempt: i64 = row.try_get("attempt")?;
        let change = match kind.as_str() {
            "progress" => {
                let Some(stage) = crate::stage::Stage::from_stored(
                    row.try_get::<Option<String>, _>("stage")?.as_deref(),
                ) else {
                    return Ok(None);
                };
                let progress: Option<f64> = row.try_get("progress")?;
                Change::Progress {
                    stage,
                    progress: progress.unwrap_or(0.0),
                }
            }
            "status" => {
                let to: Option<String> = row.try_get("to_status")?;
                let Some(Ok(to)) = to.as_deref().map(Status::from_str) else {
                    return Ok(None);
                };
                let from: Option<String> = row.try_get("from_status")?;
                Change::Status {
                    from: from.as_deref().and_then(|s| Status::from_str(s).ok()),
                    to,
                    attempt: u32::try_from(attempt).map_err(|e| corrupt("attempt", e))?,
                    error: row.try_get("error")?,
                }
            }
            _ => return Ok(None),
        };
        Ok(Some(JobEvent {
            seq: row.try_get("seq")?,
            job_id: Self::job_id_from(row)?,
            at: to_time(row.try_get("at")?)?,
            change,
        }))
    }

    fn attempt_from_row(row: &D::Row) -> Result<WebhookAttempt, QueueError> {
        let attempt: i64 = row.try_get("attempt")?;
        let status: Option<i64> = row.try_get("status_code")?;
        Ok(WebhookAttempt {
            job_id: Self::job_id_from(row)?,
            attempt: u32::try_from(attempt).map_err(|e| corrupt("attempt", e))?,
            status_code: status
                .map(u16::try_from)
                .transpose()
                .map_err(|e| corrupt("status_code", e))?,
            error: row.try_get("error")?,
            at: to_time(row.try_get("at")?)?,
        })
    }
}

impl<D> EventStore for SqlStore<D>
where
    D: Dialect,
    for<'c> &'c mut D::Connection: Executor<'c, Database = D>,
    for<'q> D::Arguments<'q>: IntoArguments<'q, D>,
    for<'q> i64: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> f64: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> bool: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> String: Encode<'q, D> + Decode<'q, D> + Type<D>,
    for<'q> &'q str: Encode<'q, D> + Type<D>,
    for<'q> Option<String>: Encode<'q, D> + Decode<'q, D>,
    for<'q> Option<i64>: Encode<'q, D> + Decode<'q, D>,
    for<'q> Option<f64>: Decode<'q, D>,
    for<'q> Option<&'q str>: Encode<'q, D>,
    for<'q> Option<D::Id>: Encode<'q, D>,
    &'static str: ColumnIndex<D::Row>,
{
    fn job_events(&self, id: JobId, after: i64, limit: u32) -> StoreFuture<'_, Vec<JobEvent>> {
        Box::pin(async move {
            let rows = sqlx::query(
                "SELECT seq, job_id, kind, from_status, to_status, attempt, error, at, stage, progress \
                 FROM job_events WHERE job_id = $1 AND seq > $2 ORDER BY seq LIMIT $3",
            )
            .bind(D::id(id.0))
            .bind(after)
            .bind(i64::from(limit))
            .fetch_all(&self.pool)
            .await?;
            let mut events = Vec::with_capacity(rows.len());
            for row in &rows {
                if let Some(event) = Self::event_from_row(row)? {
                    events.push(event);
                }
            }
            Ok(events)
        })
    }

    fn take_webhook(&self, hold: Duration) -> StoreFuture<'_, Option<WebhookDue>> {
        Box::pin(async move {
            let now = now_ms();
            // Most polls find nothing: a read answers them, so an idle loop takes no write lock
            // (SQLite has one for the whole file, which the workers' heartbeats need).
            let due = sqlx::query(
                "SELECT job_id FROM webhooks WHERE state = 'pending' AND next_attempt_at <= $1 LIMIT 1",
            )
            .bind(now)
            .fetch_optional(&self.pool)
            .await?;
            if due.is_none() {
                return Ok(None);
            }
            // One statement picks and holds the row, so two workers never attempt it at once.
            let sql = format!(
                "UPDATE webhooks SET attempts = attempts + 1, next_attempt_at = $1 \
                 WHERE job_id = (SELECT job_id FROM webhooks WHERE state = 'pending' AND next_attempt_at <= $2 \
                                 ORDER BY next_attempt_at, job_id LIMIT 1{}) \
                 RETURNING job_id, tenant_id, url, attempts, created_at",
                D::SKIP_LOCKED
            );
            let mut tx = self.begin().await?;
            let row = sqlx::query(&sql)
                .bind(now + ms(hold))
                .bind(now)
                .fetch_optional(&mut *tx)
                .await?;
            Self::commit(tx).await?;
            let Some(row) = row else { return Ok(None) };
            let attempts: i64 = row.try_get("attempts")?;
            Ok(Some(WebhookDue {
                job_id: Self::job_id_from(&row)?,
                tenant: TenantId(
                    D::uuid(row.try_get("tenant_id")?).map_err(|e| corrupt("tenant id", e))?,
                ),
                url: row.try_get("url")?,
                attempt: u32::try_from(attempts).map_err(|e| corrupt("attempts", e))?,
                created_at: to_time(row.try_get("created_at")?)?,
            }))
        })
    }

    fn webhook_attempted(&self, attempt: WebhookAttempt, next: WebhookNext) -> StoreFuture<'_, ()> {
        Box::pin(async move {
            let at = attempt.at.timestamp_millis();
            let mut tx = self.begin().await?;
            sqlx::query(
                "INSERT INTO webhook_deliveries (job_id, attempt, status_code, error, at) \
                 VALUES ($1, $2, $3, $4, $5)",
            )
            .bind(D::id(attempt.job_id.0))
            .bind(i64::from(attempt.attempt))
            .bind(attempt.status_code.map(i64::from))
            .bind(attempt.error.clone())
            .bind(at)
            .execute(&mut *tx)
            .await?;
            let (state, next_at, finished) = match next {
                WebhookNext::Delivered => ("delivered", at, Some(at)),
                WebhookNext::RetryAt(when) => ("pending", when.timestamp_millis(), None),
                WebhookNext::GiveUp => ("failed", at, Some(at)),
            };
            sqlx::query(
                "UPDATE webhooks SET state = $1, next_attempt_at = $2, finished_at = $3 WHERE job_id = $4",
            )
            .bind(state)
            .bind(next_at)
            .bind(finished)
            .bind(D::id(attempt.job_id.0))
            .execute(&mut *tx)
            .await?;
            Self::commit(tx).await
        })
    }

    fn webhook_attempts(&self, id: JobId) -> StoreFuture<'_, Vec<WebhookAttempt>> {
        Box::pin(async move {
            let rows = sqlx::query(
                "SELECT job_id, attempt, status_code, error, at FROM webhook_deliveries \
                 WHERE job_id = $1 ORDER BY seq",
            )
            .bind(D::id(id.0))
            .fetch_all(&self.pool)
            .await?;
            rows.iter().map(Self::attempt_from_row).collect()
        })
    }
}
