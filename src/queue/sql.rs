//! What the SQLite and PostgreSQL job stores share: column lists, the backoff cap and the
//! conversions between stored integers (epoch milliseconds) and times.
//!
//! The row mappers stay in each store: the two drivers' row types differ, and ids are TEXT in
//! SQLite but UUID in PostgreSQL.
use super::QueueError;
use chrono::{DateTime, TimeZone, Utc};
use std::time::Duration;

/// Cap on the backoff exponent, so `1 << n` cannot overflow.
pub const MAX_BACKOFF_DOUBLINGS: i64 = 16;

/// The columns a job row is read from, in `job_from_row`'s order.
pub const JOB_COLUMNS: &str = "id, options, status, stage, progress, priority, attempts, max_attempts, cancel_requested, \
     error, result, created_at, started_at, finished_at";
/// The columns a song row is read from.
pub const SONG_COLUMNS: &str = "id, filename, format, duration_s, sample_rate, channels, sha256, size_bytes, analysis, created_at";

/// Now, in epoch milliseconds (how both stores keep times).
pub fn now_ms() -> i64 {
    Utc::now().timestamp_millis()
}

/// A stored time back to a `DateTime`.
pub fn to_time(ms: i64) -> Result<DateTime<Utc>, QueueError> {
    Utc.timestamp_millis_opt(ms).single().ok_or_else(|| QueueError::Corrupt(format!("timestamp {ms}")))
}

/// An optional stored time back to a `DateTime`.
pub fn opt_time(ms: Option<i64>) -> Result<Option<DateTime<Utc>>, QueueError> {
    ms.map(to_time).transpose()
}

/// A duration in whole milliseconds, saturating.
pub fn ms(d: Duration) -> i64 {
    i64::try_from(d.as_millis()).unwrap_or(i64::MAX)
}

/// A stored value that does not parse.
pub fn corrupt(what: &str, e: impl std::fmt::Display) -> QueueError {
    QueueError::Corrupt(format!("{what}: {e}"))
}
