//! The durable job queue: the job model, the `JobStore` trait and its SQLite store.
//!
//! A job is domain data the API queries (status, stage, progress, options, results), so it is a
//! row in our own `jobs` table rather than an opaque message in a queue library. The verbs are
//! [`JobStore::register`], [`JobStore::claim`], [`JobStore::heartbeat`], [`JobStore::complete`],
//! [`JobStore::fail`] and [`JobStore::cancel`]; [`JobStore::requeue_expired`] returns the jobs of
//! dead workers to the queue. Every status change is appended to `job_events` by a trigger, so
//! the history of a job cannot drift from its row.
//!
//! Handlers and workers see only the traits. Two stores keep the same contract (the tests in
//! `tests/queue.rs` run against both): [`SqliteStore`], one file beside one process, and
//! [`PgStore`], one database shared by API and worker processes on many hosts (`FOR UPDATE SKIP
//! LOCKED`, `LISTEN/NOTIFY`). Both are one [`sql::SqlStore`]: the rules are written once in
//! `sql.rs`, and `sqlite.rs` and `postgres.rs` hold only their dialect (`sql::Dialect`) and how
//! they connect. [`open`] picks one from the configured database URL.
use crate::audio::{Analysis, AudioFormat};
use crate::models::ModelId;
use crate::motion::KeyPose;
use chrono::{DateTime, Utc};
use futures::future::BoxFuture;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio_util::sync::CancellationToken;
use uuid::Uuid;

pub mod events;
pub mod files;
pub mod keys;
pub mod postgres;
pub mod rigs;
pub mod sql;
pub mod sqlite;
pub mod view;

pub use events::EventStore;
pub use files::DataDir;
pub use keys::{ApiKey, KeyLimits, NewKey, TenantStore, Usage};
pub use postgres::PgStore;
pub use rigs::{RigFilter, RigStore, UploadedRig};
pub use sqlite::SqliteStore;

/// Errors from the job, song and rig store.
#[derive(Debug, thiserror::Error)]
pub enum QueueError {
    #[error("database: {0}")]
    Database(#[from] sqlx::Error),
    #[error("database migration: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    #[error("stored row is corrupt: {0}")]
    Corrupt(String),
    #[error("song {0} not found")]
    SongNotFound(SongId),
    #[error("job {0} not found")]
    JobNotFound(JobId),
    #[error("rig {0} not found")]
    RigNotFound(RigId),
    #[error("the Idempotency-Key was already used for a different request (job {0})")]
    IdempotencyConflict(JobId),
    #[error("API key {0} not found")]
    KeyNotFound(KeyId),
    #[error("the tenant has {limit} jobs queued or running, its most")]
    QueueFull { limit: u64 },
    #[error("the tenant stores {used} bytes; {size} more would pass its {quota} byte quota")]
    QuotaExceeded { used: u64, size: u64, quota: u64 },
    #[error("the tenant stores {used} bytes of songs, rigs and results, at or past its {quota} byte quota: no room for results")]
    QuotaFull { used: u64, quota: u64 },
}

impl QueueError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            QueueError::Database(_) => "database",
            QueueError::Migrate(_) => "database-migration",
            QueueError::Corrupt(_) => "corrupt-row",
            QueueError::SongNotFound(_) => "song-not-found",
            QueueError::JobNotFound(_) => "job-not-found",
            QueueError::RigNotFound(_) => "rig-not-found",
            QueueError::IdempotencyConflict(_) => "idempotency-key-reused",
            QueueError::KeyNotFound(_) => "key-not-found",
            QueueError::QueueFull { .. } => "too-many-queued-jobs",
            QueueError::QuotaExceeded { .. } | QueueError::QuotaFull { .. } => {
                "storage-quota-exceeded"
            }
        }
    }

    /// Whether trying again later may succeed.
    pub fn is_retryable(&self) -> bool {
        match self {
            QueueError::Database(_) => true,
            QueueError::Migrate(_) => false,
            QueueError::Corrupt(_) => false,
            QueueError::SongNotFound(_) => false,
            QueueError::JobNotFound(_) => false,
            QueueError::RigNotFound(_) => false,
            QueueError::IdempotencyConflict(_) => false,
            QueueError::KeyNotFound(_) => false,
            // A job refused for its results is not tried again: the tenant must make room and
            // submit anew (it was told so at submission while already at its quota).
            QueueError::QueueFull { .. }
            | QueueError::QuotaExceeded { .. }
            | QueueError::QuotaFull { .. } => false,
        }
    }
}

macro_rules! typed_id {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, utoipa::ToSchema)]
        #[serde(transparent)]
        #[schema(value_type = String, format = Uuid)]
        pub struct $name(pub Uuid);

        impl $name {
            /// A fresh, time-ordered (v7) id.
            pub fn new() -> Self {
                Self(Uuid::now_v7())
            }
        }

        impl Default for $name {
            fn default() -> Self {
                Self::new()
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                self.0.hyphenated().fmt(f)
            }
        }

        impl FromStr for $name {
            type Err = uuid::Error;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                Uuid::parse_str(s).map(Self)
            }
        }
    };
}

typed_id!(
    /// A job's id: a UUID v7, so ids sort by creation time.
    JobId
);
typed_id!(
    /// A song's id: a UUID v7; the stored file is named by it, never by the upload's name.
    SongId
);
typed_id!(
    /// An uploaded rig's id: a UUID v7, naming its stored file as a song's id does.
    RigId
);
typed_id!(
    /// Whose a song, job or rig is: the API key that made it ([`TenantId::OPEN`] without keys).
    TenantId
);

typed_id!(
    /// An API key's id (`choreo keys create`); not secret, it is part of the key's secret.
    KeyId
);

impl TenantId {
    /// The tenant of an open service and of the single `auth_token`; every row stored before
    /// keys existed belongs to it.
    pub const OPEN: TenantId = TenantId(Uuid::nil());
}

/// Whose rows a read or a change may touch. Every API request is one tenant's; workers, sweeps
/// and operators' tools see all. A row outside the scope is "not found", never "forbidden", so
/// a tenant cannot learn that another's id exists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope {
    Tenant(TenantId),
    All,
}

impl Scope {
    /// The one tenant the scope is limited to; none for [`Scope::All`].
    pub fn tenant(self) -> Option<TenantId> {
        match self {
            Scope::Tenant(tenant) => Some(tenant),
            Scope::All => None,
        }
    }
}

/// Where a job is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl Status {
    /// Every status, in life order.
    pub const ALL: [Status; 5] = [
        Status::Queued,
        Status::Running,
        Status::Succeeded,
        Status::Failed,
        Status::Cancelled,
    ];

    /// The lowercase name stored in the database and shown by the API.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Queued => "queued",
            Status::Running => "running",
            Status::Succeeded => "succeeded",
            Status::Failed => "failed",
            Status::Cancelled => "cancelled",
        }
    }

    /// Whether the job will never change again.
    pub fn is_terminal(self) -> bool {
        match self {
            Status::Queued | Status::Running => false,
            Status::Succeeded | Status::Failed | Status::Cancelled => true,
        }
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A status name that is not one of [`Status::ALL`].
#[derive(Debug, thiserror::Error)]
#[error("unknown status {0:?}; use one of queued, running, succeeded, failed, cancelled")]
pub struct UnknownStatus(pub String);

impl FromStr for Status {
    type Err = UnknownStatus;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Status::ALL
            .into_iter()
            .find(|status| status.as_str() == s)
            .ok_or_else(|| UnknownStatus(s.to_string()))
    }
}

/// A motion a dance should continue from, as a job stores it: the canonical form the API makes of
/// what was sent (`motion::input::seed_motion`), world joint positions in metres, y up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeedMotion {
    /// Frames per second of `positions` (the motion rate, 25).
    pub fps: f64,
    /// `T × 23 × [x, y, z]`, in the dataset's joint order (`motion::skeleton::JOINT_NAMES`).
    pub positions: Vec<Vec<[f64; 3]>>,
}

/// The options of a generate job, as submitted.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GenerateOptions {
    pub song_id: SongId,
    pub model: ModelId,
    /// Seeds every random draw of the model.
    pub seed: u64,
    #[serde(default)]
    pub key_poses: Vec<KeyPose>,
    #[serde(default)]
    pub seed_motion: Option<SeedMotion>,
    /// Plant the feet of the model's motion (`motion::feet`); jobs stored before the option
    /// existed read as true, what they would get now.
    #[serde(default = "planted")]
    pub plant_feet: bool,
    /// The style asked for (models that dance one); none lets the model choose from the song.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub style: Option<crate::models::DanceStyle>,
    /// Sampling temperature (sampling models); none is the model's default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature: Option<f64>,
    /// Keep the k likeliest choices when sampling (models over discrete choices).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub top_k: Option<u32>,
    /// Where the finished job is POSTed (`webhooks`); the outbox trigger reads it from here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub webhook_url: Option<String>,
}

fn planted() -> bool {
    true
}

/// What a job does; each kind carries its own options.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum JobKind {
    /// Tempo, beats and downbeats of a newly uploaded song.
    Analyze { song_id: SongId },
    /// A dance for a song from a model.
    Generate(GenerateOptions),
}

impl JobKind {
    /// The kind's name, as stored and labelled in metrics.
    pub fn name(&self) -> &'static str {
        match self {
            JobKind::Analyze { .. } => "analyze",
            JobKind::Generate(_) => "generate",
        }
    }

    /// The song the job works on.
    pub fn song_id(&self) -> SongId {
        match self {
            JobKind::Analyze { song_id } => *song_id,
            JobKind::Generate(options) => options.song_id,
        }
    }

    /// The model a generate job uses.
    pub fn model(&self) -> Option<&ModelId> {
        match self {
            JobKind::Analyze { .. } => None,
            JobKind::Generate(options) => Some(&options.model),
        }
    }
}

/// The files a succeeded generate job wrote, relative to its result dir, and what the model chose
/// on the user's behalf.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JobFiles {
    pub files: Vec<String>,
    /// The style danced (models that dance one): asked for, or predicted from the song.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub style: Option<crate::models::StyleChoice>,
    /// Bytes the job added to its song's cache (`crate::song_cache`), for the worker to count
    /// in the tenant's storage after the job's results; not stored.
    #[serde(skip)]
    pub song_cache_bytes: u64,
}

/// What a job produced when it succeeded.
#[derive(Clone, Debug)]
pub enum Outcome {
    /// An analyze job's result, stored on its song.
    Analysis(Analysis),
    /// A generate job's result files.
    Files(JobFiles),
}

/// One job, as stored.
#[derive(Clone, Debug)]
pub struct Job {
    pub id: JobId,
    pub tenant: TenantId,
    pub kind: JobKind,
    pub status: Status,
    /// What the job is doing now; a stored name this build does not know reads as none.
    pub stage: Option<crate::stage::Stage>,
    /// 0..=1 within the whole job.
    pub progress: f64,
    pub priority: i64,
    pub attempts: u32,
    pub max_attempts: u32,
    pub cancel_requested: bool,
    /// The last error, kept across retries.
    pub error: Option<String>,
    pub files: JobFiles,
    pub created_at: DateTime<Utc>,
    pub started_at: Option<DateTime<Utc>>,
    pub finished_at: Option<DateTime<Utc>>,
}

/// A job to be registered.
#[derive(Clone, Debug)]
pub struct NewJob {
    /// Whose job it is; the song it works on must be the same tenant's.
    pub tenant: TenantId,
    pub kind: JobKind,
    pub priority: i64,
    pub max_attempts: u32,
    /// The client's `Idempotency-Key` and a hash of its request.
    pub idempotency: Option<Idempotency>,
}

/// An `Idempotency-Key` with the hash of the request it was first used for.
#[derive(Clone, Debug)]
pub struct Idempotency {
    pub key: String,
    pub request_hash: String,
}

/// Whether [`JobStore::register`] made a new job or found the one an idempotency key named.
#[derive(Clone, Debug)]
pub enum Registered {
    Created(Job),
    Existing(Job),
}

impl Registered {
    /// The job, new or existing.
    pub fn job(&self) -> &Job {
        match self {
            Registered::Created(job) | Registered::Existing(job) => job,
        }
    }
}

/// What a heartbeat learned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Beat {
    /// Still ours; `cancel_requested` tells the worker to stop at its next checkpoint.
    Held { cancel_requested: bool },
    /// The lease expired and the job went back to the queue (or elsewhere); stop working on it.
    Lost,
}

/// The filter and page of `GET /v1/jobs`.
#[derive(Clone, Debug, Default)]
pub struct JobFilter {
    pub status: Option<Status>,
    pub model: Option<String>,
    /// Return jobs older than this one (the cursor).
    pub before: Option<JobId>,
    pub limit: u32,
}

/// What [`JobStore::requeue_expired`] did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Requeued {
    pub requeued: Vec<JobId>,
    pub failed: Vec<JobId>,
    pub cancelled: Vec<JobId>,
}

/// How long a lease lasts and how retries back off.
#[derive(Clone, Copy, Debug)]
pub struct LeasePolicy {
    pub lease: Duration,
    /// First retry delay; doubles each attempt.
    pub backoff: Duration,
}

/// An uploaded song, as stored.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Song {
    pub id: SongId,
    pub tenant: TenantId,
    /// The upload's own name, for display only.
    pub filename: String,
    pub format: AudioFormat,
    pub duration_s: f64,
    pub sample_rate: u32,
    pub channels: u16,
    pub sha256: String,
    pub size_bytes: u64,
    pub analysis: Option<Analysis>,
    pub created_at: DateTime<Utc>,
}

/// Rows a deletion or the retention sweep removed; their files are still to be removed.
#[derive(Clone, Debug, Default)]
pub struct Removed {
    pub songs: Vec<Song>,
    pub jobs: Vec<Job>,
    pub rigs: Vec<UploadedRig>,
}

impl Removed {
    /// Whether nothing was removed.
    pub fn is_empty(&self) -> bool {
        self.songs.is_empty() && self.jobs.is_empty() && self.rigs.is_empty()
    }
}

/// A future returned by a store.
pub type StoreFuture<'a, T> = BoxFuture<'a, Result<T, QueueError>>;

/// The job queue.
pub trait JobStore: Send + Sync {
    /// Creates a queued job, or returns the one its idempotency key already made (no limits).
    fn register(&self, job: NewJob) -> StoreFuture<'_, Registered> {
        self.register_within(job, KeyLimits::default())
    }
    /// [`JobStore::register`] within the tenant's `limits`, checked in the transaction that
    /// inserts the job: `QueueFull` past `max_queued_jobs`, `QuotaFull` when the tenant already
    /// stores its `storage_quota_bytes` (the job's results would have no room). The quota is kept
    /// on the job, and its results are held to it ([`TenantStore::record_result_bytes`]).
    fn register_within(&self, job: NewJob, limits: KeyLimits) -> StoreFuture<'_, Registered>;
    /// Atomically takes the next runnable job, leasing it to `owner`.
    fn claim<'a>(&'a self, owner: &'a str, policy: LeasePolicy) -> StoreFuture<'a, Option<Job>>;
    /// Extends `owner`'s lease and records progress.
    fn heartbeat<'a>(
        &'a self,
        id: JobId,
        owner: &'a str,
        stage: &'a str,
        progress: f64,
        policy: LeasePolicy,
    ) -> StoreFuture<'a, Beat>;
    /// Marks the job succeeded; `false` when `owner` no longer holds it (nothing changes then).
    fn complete<'a>(&'a self, id: JobId, owner: &'a str, outcome: Outcome)
        -> StoreFuture<'a, bool>;
    /// Records a failed attempt: requeued with backoff when `retry` and attempts remain,
    /// failed otherwise. `false` when `owner` no longer holds the job.
    fn fail<'a>(
        &'a self,
        id: JobId,
        owner: &'a str,
        error: &'a str,
        retry: bool,
        policy: LeasePolicy,
    ) -> StoreFuture<'a, bool>;
    /// Marks a running job cancelled after its worker stopped at a checkpoint.
    fn finish_cancelled<'a>(&'a self, id: JobId, owner: &'a str) -> StoreFuture<'a, bool>;
    /// Cancels a queued job at once, or asks a running one to stop; returns the job after.
    fn cancel(&self, scope: Scope, id: JobId) -> StoreFuture<'_, Job>;
    /// Requeues (or fails, past `max_attempts`) running jobs whose lease has expired.
    fn requeue_expired(&self, policy: LeasePolicy) -> StoreFuture<'_, Requeued>;
    /// One job.
    fn job(&self, scope: Scope, id: JobId) -> StoreFuture<'_, Job>;
    /// Jobs, newest first.
    fn jobs(&self, scope: Scope, filter: JobFilter) -> StoreFuture<'_, Vec<Job>>;
    /// Job counts by status.
    fn counts(&self) -> StoreFuture<'_, Vec<(Status, u64)>>;
    /// Whether the database answers.
    fn ping(&self) -> StoreFuture<'_, ()>;
    /// Wakes `wake` whenever a job becomes claimable in another process, until `shutdown`.
    /// A store without notifications returns at once; workers then find such jobs by polling.
    fn watch(&self, wake: Arc<Notify>, shutdown: CancellationToken) -> StoreFuture<'_, ()>;
    /// Removes a finished job's row, leaving a `deleted` line with `reason` in `job_events`;
    /// returns the job as it was, whose files are the caller's to remove. A queued or running
    /// job is not removed (cancel it first): no finished job with the id in scope is
    /// [`QueueError::JobNotFound`].
    fn delete_job<'a>(&'a self, scope: Scope, id: JobId, reason: &'a str) -> StoreFuture<'a, Job>;
    /// Records a use of the job's results (a download), which restarts its retention.
    fn touch_job(&self, id: JobId) -> StoreFuture<'_, ()>;
}

/// A page of the song list: newest first.
#[derive(Clone, Copy, Debug)]
pub struct SongFilter {
    /// Return songs older than this one (the cursor).
    pub before: Option<SongId>,
    pub limit: u32,
}

/// The song catalogue.
pub trait SongStore: Send + Sync {
    /// Stores a new song with its analyze job in one transaction; when the same tenant has a
    /// song with the same sha256, returns it and stores nothing (`false`).
    fn add_song(&self, song: Song, analyze: NewJob) -> StoreFuture<'_, (Song, bool)> {
        self.add_song_within(song, analyze, KeyLimits::default())
    }
    /// [`SongStore::add_song`] within the tenant's `limits`, checked in the same transaction:
    /// `QuotaExceeded` when the song's bytes would pass `storage_quota_bytes`, `QueueFull` when
    /// its analyze job would pass `max_queued_jobs`. Bytes the tenant already has cost nothing.
    fn add_song_within(
        &self,
        song: Song,
        analyze: NewJob,
        limits: KeyLimits,
    ) -> StoreFuture<'_, (Song, bool)>;
    /// One song.
    fn song(&self, scope: Scope, id: SongId) -> StoreFuture<'_, Song>;
    /// The songs in scope, newest first, older than `filter.before` when set.
    fn songs(&self, scope: Scope, filter: SongFilter) -> StoreFuture<'_, Vec<Song>>;
    /// The tenant's song with these bytes, if it uploaded them before.
    fn song_by_sha256<'a>(
        &'a self,
        tenant: TenantId,
        sha256: &'a str,
    ) -> StoreFuture<'a, Option<Song>>;
    /// The latest analyze job of a song.
    fn analyze_job(&self, song: SongId) -> StoreFuture<'_, Option<Job>>;
    /// Removes a song's row (its analysis with it) and the row of every job made from it,
    /// whatever their status, in one transaction, leaving a `deleted` line with `reason` in
    /// `job_events` for each job. A running job's worker finds its lease gone at its next
    /// heartbeat and stops at its next checkpoint. Returns what was removed; its files are the
    /// caller's to remove.
    fn delete_song<'a>(
        &'a self,
        scope: Scope,
        id: SongId,
        reason: &'a str,
    ) -> StoreFuture<'a, Removed>;
    /// Records a use of the song (an upload of the same bytes, a download of its audio), which
    /// restarts its retention.
    fn touch_song(&self, id: SongId) -> StoreFuture<'_, ()>;
    /// Adds `bytes` a job stored in the song's cache (`crate::song_cache`) to the song's size in
    /// its tenant's storage. Not held to a quota: the cache saves the tenant's later jobs the
    /// work, and goes with the song. `false` when the song is gone (deleted while the job ran):
    /// then nothing is added, and what the job stored is the caller's to remove.
    fn add_song_cache_bytes(&self, id: SongId, bytes: u64) -> StoreFuture<'_, bool>;
    /// Removes, as [`SongStore::delete_song`], [`JobStore::delete_job`] and
    /// [`RigStore::delete_rig`] do, up to `limit` finished generate jobs, up to `limit` songs and
    /// up to `limit` rigs last used before `cutoff`, in one transaction. A song is removed only
    /// when no job made from it is queued, running or used since `cutoff`; a rig is used only by
    /// the downloads that name it, so its own last use decides.
    fn expire<'a>(
        &'a self,
        cutoff: DateTime<Utc>,
        limit: u32,
        reason: &'a str,
    ) -> StoreFuture<'a, Removed>;
}

/// Everything the service stores.
pub trait Store: JobStore + SongStore + RigStore + TenantStore + EventStore {}

impl<T: JobStore + SongStore + RigStore + TenantStore + EventStore> Store for T {}

/// Opens the store `database` names, running its migrations. `timeout` bounds how long a call
/// waits for a PostgreSQL connection (the config's `db_timeout_s`).
pub async fn open(
    database: &crate::config::Database,
    timeout: Duration,
) -> Result<Arc<dyn Store>, QueueError> {
    use crate::config::Database;
    Ok(match database {
        Database::Sqlite(path) => Arc::new(SqliteStore::open(path).await?),
        Database::Postgres(url) => Arc::new(PgStore::connect(url, timeout).await?),
    })
}
