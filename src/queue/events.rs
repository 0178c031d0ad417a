//! A job's history as clients are told it (`GET /v1/jobs/{id}/events`), and the webhook outbox.
//!
//! Both are written by triggers on the job row (migration `20261127000200_events.sql`), in the
//! transaction that changes the job, so neither can drift from it nor be lost to a crash: the
//! event stream reads `job_events` by its `seq`, and the workers' delivery loop drains
//! `webhooks` and logs each attempt in `webhook_deliveries`.
use super::{JobId, Status, StoreFuture, TenantId};
use crate::stage::Stage;
use chrono::{DateTime, Utc};
use std::time::Duration;

/// One line of a job's history.
#[derive(Clone, Debug, PartialEq)]
pub struct JobEvent {
    /// The line's place in `job_events`: increasing, the SSE event id.
    pub seq: i64,
    pub job_id: JobId,
    pub at: DateTime<Utc>,
    pub change: Change,
}

/// What a line of a job's history says.
#[derive(Clone, Debug, PartialEq)]
pub enum Change {
    /// The job's status changed (`from` is none when it was registered).
    Status {
        from: Option<Status>,
        to: Status,
        attempt: u32,
        error: Option<String>,
    },
    /// A running job entered a stage, or its progress crossed a 5 % step.
    Progress { stage: Stage, progress: f64 },
}

/// A webhook delivery a worker took to attempt.
#[derive(Clone, Debug, PartialEq)]
pub struct WebhookDue {
    pub job_id: JobId,
    pub tenant: TenantId,
    pub url: String,
    /// This attempt's number, from 1.
    pub attempt: u32,
    /// When the job ended; retries stop `webhook_retry_s` after it.
    pub created_at: DateTime<Utc>,
}

/// One delivery attempt, as logged.
#[derive(Clone, Debug, PartialEq)]
pub struct WebhookAttempt {
    pub job_id: JobId,
    pub attempt: u32,
    /// The receiver's HTTP status, when it answered.
    pub status_code: Option<u16>,
    /// Why the attempt failed, when it did (no answer, a refused address, a non-2xx status).
    pub error: Option<String>,
    pub at: DateTime<Utc>,
}

/// What becomes of a delivery after an attempt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WebhookNext {
    /// The receiver answered 2xx: done.
    Delivered,
    /// Try again then.
    RetryAt(DateTime<Utc>),
    /// Past `webhook_retry_s`, or refused for good: stop.
    GiveUp,
}

/// The event log and the webhook outbox.
pub trait EventStore: Send + Sync {
    /// The job's history lines after `after` (a `seq`), oldest first, at most `limit`. Lines of a
    /// kind this build does not know are skipped.
    fn job_events(&self, id: JobId, after: i64, limit: u32) -> StoreFuture<'_, Vec<JobEvent>>;
    /// Takes the delivery due longest ago, if any, counting its attempt and holding it from other
    /// workers for `hold` (longer than one attempt can take): if this worker dies, another
    /// takes it after that.
    fn take_webhook(&self, hold: Duration) -> StoreFuture<'_, Option<WebhookDue>>;
    /// Logs an attempt and decides the delivery's fate, in one transaction.
    fn webhook_attempted(&self, attempt: WebhookAttempt, next: WebhookNext) -> StoreFuture<'_, ()>;
    /// Every attempt to deliver the job's webhook, oldest first.
    fn webhook_attempts(&self, id: JobId) -> StoreFuture<'_, Vec<WebhookAttempt>>;
}
