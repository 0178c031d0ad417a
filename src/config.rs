//! Layered configuration: `config.toml`, then `CHOREO_*` environment, then CLI flags.
//!
//! Every setting is documented in the repository's `config.toml`. The names `bind`,
//! `data_dir` (`--bind`, `--data-dir`, `CHOREO_BIND`, `CHOREO_DATA_DIR`) are fixed because tools
//! outside the project rely on them.
use figment::providers::{Env, Format, Serialized, Toml};
use figment::Figment;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// The ranges a tenant's limits are held to wherever they are set (the config, `choreo keys
/// create`): a rate of 1e-19 per second would make the limiter's next arrival overflow time.
pub const RATE_LIMIT_RPS: RangeInclusive<f64> = 0.01..=100_000.0;
/// Jobs queued or running per tenant.
pub const MAX_QUEUED_JOBS: RangeInclusive<u64> = 1..=1_000_000;
/// Bytes stored per tenant: 1 KiB to 1 PiB.
pub const STORAGE_QUOTA_BYTES: RangeInclusive<u64> = 1024..=(1 << 50);
/// Event streams one key may hold open at once.
pub const MAX_EVENT_STREAMS_PER_KEY: RangeInclusive<usize> = 1..=10_000;
/// The longest an event stream may stay open, in seconds.
pub const EVENT_STREAM_MAX_S: RangeInclusive<f64> = 1.0..=86_400.0;
/// Days of retention: up to a century.
pub const RETENTION_DAYS: RangeInclusive<f64> = 0.0..=36_500.0;

/// `value` if it lies in `range`, else why not, for a flag or setting called `name`.
pub fn in_range<T: PartialOrd + fmt::Display>(
    name: &str,
    value: T,
    range: &RangeInclusive<T>,
) -> Result<T, String> {
    if range.contains(&value) {
        Ok(value)
    } else {
        Err(format!(
            "{name} is {value}; it must be from {} to {}",
            range.start(),
            range.end()
        ))
    }
}

/// The default config file, read from the working directory when present.
pub const DEFAULT_CONFIG_FILE: &str = "config.toml";
/// Prefix of every environment override (`CHOREO_BIND`, `CHOREO_DATA_DIR`, ...).
pub const ENV_PREFIX: &str = "CHOREO_";
/// The settings, by name; only these are read from `CHOREO_*`, so other tools' variables that
/// share the prefix do not break start-up.
pub const SETTINGS: &[&str] = &[
    "bind",
    "data_dir",
    "models_dir",
    "workers",
    "max_upload_bytes",
    "max_duration_s",
    "audio_timeout_s",
    "max_job_body_bytes",
    "cors_origins",
    "auth_token",
    "log_format",
    "log_level",
    "lease_s",
    "heartbeat_s",
    "max_attempts",
    "retry_backoff_s",
    "poll_s",
    "database_url",
    "artifacts_url",
    "s3_endpoint",
    "s3_region",
    "max_connections",
    "fd_reserve",
    "header_timeout_s",
    "body_timeout_s",
    "write_timeout_s",
    "max_part_header_bytes",
    "db_timeout_s",
    "sweep_grace_s",
    "rate_limit_rps",
    "max_queued_jobs",
    "storage_quota_bytes",
    "retention_days",
    "max_event_streams_per_key",
    "event_stream_max_s",
    "webhook_secret",
    "webhook_allowed_hosts",
    "webhook_retry_s",
    "webhook_backoff_s",
];

/// Errors from loading or checking the configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("configuration: {0}")]
    Load(#[from] Box<figment::Error>),
    #[error("configuration: {field}: {message}")]
    Invalid {
        field: &'static str,
        message: String,
    },
}

impl ConfigError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            ConfigError::Load(_) => "config-load",
            ConfigError::Invalid { .. } => "config-invalid",
        }
    }
}

/// A secret that never prints: `Debug` and `Display` show `[redacted]`.
#[derive(Clone, Deserialize, PartialEq, Eq)]
#[serde(transparent)]
pub struct Secret(String);

impl Secret {
    /// Wraps a secret value.
    pub fn new(value: impl Into<String>) -> Self {
        Self(value.into())
    }
    /// The secret itself; call only where it is compared or sent.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[redacted]")
    }
}

impl fmt::Display for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[redacted]")
    }
}

/// How log lines are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// Human-readable lines.
    #[default]
    Pretty,
    /// One JSON object per line, for log collectors.
    Json,
}

/// The job and song database a [`Config`] names.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Database {
    /// One SQLite file, for one process (the default: `<data_dir>/choreo.sqlite`).
    Sqlite(PathBuf),
    /// A PostgreSQL database shared by API and worker processes; the URL may hold a password.
    Postgres(Secret),
}

/// The whole service configuration.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Address the HTTP server listens on; port 0 picks a free port.
    pub bind: String,
    /// Where the database, songs and results live.
    pub data_dir: PathBuf,
    /// Where trained models live (`<models_dir>/<model id>/`).
    pub models_dir: PathBuf,
    /// Worker count; 0 means one per CPU core.
    pub workers: usize,
    /// Largest accepted upload, in bytes.
    pub max_upload_bytes: u64,
    /// Longest accepted song, in seconds.
    pub max_duration_s: f64,
    /// Wall-clock budget of one decode, and of one analysis, in seconds; past it the work is
    /// abandoned with an error and its thread stops.
    pub audio_timeout_s: f64,
    /// Largest accepted `POST /v1/jobs` body, in bytes.
    pub max_job_body_bytes: u64,
    /// Origins allowed by CORS; `["*"]` allows any, `[]` none.
    pub cors_origins: Vec<String>,
    /// When set, every `/v1` route needs `Authorization: Bearer <token>`.
    pub auth_token: Option<Secret>,
    /// `pretty` or `json`.
    pub log_format: LogFormat,
    /// Tracing filter when `RUST_LOG` is unset.
    pub log_level: String,
    /// How long a claimed job's lease lasts without a heartbeat, in seconds.
    pub lease_s: f64,
    /// How often a running job heartbeats, in seconds.
    pub heartbeat_s: f64,
    /// Attempts before a job whose lease keeps expiring is failed.
    pub max_attempts: u32,
    /// First retry delay in seconds; doubles each attempt.
    pub retry_backoff_s: f64,
    /// How often idle workers look for new jobs, in seconds.
    pub poll_s: f64,
    /// `sqlite://PATH` or `postgres://user:password@host:port/db`; unset means
    /// `sqlite://<data_dir>/choreo.sqlite`. Never printed.
    pub database_url: Option<Secret>,
    /// Where songs and results are kept: unset or `local` (the data dir), or
    /// `s3://bucket[/prefix]` (credentials from the `AWS_*` environment).
    pub artifacts_url: Option<String>,
    /// The S3-compatible server's URL when not AWS (MinIO, moto, ...); `http://` is allowed.
    pub s3_endpoint: Option<String>,
    /// The bucket's region.
    pub s3_region: String,
    /// Most HTTP connections open at once; further ones get `503 too-many-connections` and are
    /// closed. Lowered at start-up to the open-file limit less `fd_reserve`.
    pub max_connections: usize,
    /// File handles kept free of sockets for workers, the database and result files.
    pub fd_reserve: u64,
    /// Time a client has to send a request's head, counted from the connection's opening or the
    /// previous response (so it is also the keep-alive idle timeout), in seconds.
    pub header_timeout_s: f64,
    /// Longest pause between two pieces of a request body, in seconds (`408 body-timeout`).
    pub body_timeout_s: f64,
    /// Longest a response write may wait on a client that does not read, in seconds; then the
    /// connection is closed.
    pub write_timeout_s: f64,
    /// Largest header block of one multipart part (field name and file name included), in bytes.
    pub max_part_header_bytes: usize,
    /// How long a database call may wait for a connection, and `/readyz` for the database's
    /// answer, in seconds.
    pub db_timeout_s: f64,
    /// Crash leftovers (temp files, files without a database row) older than this are removed at
    /// start-up, in seconds.
    pub sweep_grace_s: f64,
    /// Requests per second each tenant (API key, or the open service / `auth_token`) may make
    /// to `/v1`, with a burst of one second's worth; past it `429` with `Retry-After`. Unset:
    /// no limit. A key's own `--rate-limit-rps` overrides it.
    pub rate_limit_rps: Option<f64>,
    /// Most jobs a tenant may have queued or running; past it `POST /v1/jobs` answers `429
    /// too-many-queued-jobs`. Unset: no limit. A key's own `--max-queued-jobs` overrides it.
    pub max_queued_jobs: Option<u64>,
    /// Most bytes of songs, rigs and results a tenant may store; an upload past it answers `413
    /// storage-quota-exceeded`. Unset: no limit. A key's own `--storage-quota-bytes` overrides it.
    pub storage_quota_bytes: Option<u64>,
    /// Songs and results are removed this many days (fractions allowed) after their last use;
    /// unset keeps them until deleted.
    pub retention_days: Option<f64>,
    /// Event streams (`GET /v1/jobs/{id}/events`) one key may hold open at once, per API
    /// process; past it `429 too-many-event-streams` and the connection is closed.
    pub max_event_streams_per_key: usize,
    /// The longest an event stream stays open, in seconds; then it ends and the client resumes
    /// with `Last-Event-ID`, so a stream on a job that never ends does not hold a slot for good.
    pub event_stream_max_s: f64,
    /// The key webhooks are signed with, in Standard Webhooks' form `whsec_<base64 of 24 to 64
    /// random bytes>` (`CHOREO_WEBHOOK_SECRET`). Unset: a job with a `webhook_url` is refused
    /// (422 `webhooks-not-configured`), since the receiver could not check what it gets. Every
    /// process (API and workers) needs the same one. Never printed.
    pub webhook_secret: Option<Secret>,
    /// `host:port` pairs webhooks may reach although they resolve to a loopback, private or
    /// other non-global address (`CHOREO_WEBHOOK_ALLOWED_HOSTS=hooks.internal:443,127.0.0.1:9000`).
    #[serde(deserialize_with = "comma_list")]
    pub webhook_allowed_hosts: Vec<String>,
    /// How long after a job ends its webhook is retried, in seconds.
    pub webhook_retry_s: f64,
    /// Pause before a webhook's first retry, in seconds; doubles each retry (at most an hour).
    pub webhook_backoff_s: f64,
}

/// Whether `s` is `host:port` (an IPv6 host in brackets), as `webhook_allowed_hosts` lists them.
fn is_host_port(s: &str) -> bool {
    let Some((host, port)) = s.rsplit_once(':') else {
        return false;
    };
    let host_ok = match host.strip_prefix('[').and_then(|h| h.strip_suffix(']')) {
        Some(v6) => v6.parse::<std::net::Ipv6Addr>().is_ok(),
        None => {
            !host.is_empty()
                && host
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'.' || b == b'_')
        }
    };
    host_ok && port.parse::<u16>().is_ok()
}

/// A list given as TOML array or as one comma-separated string (an environment variable).
fn comma_list<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<String>, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum List {
        One(String),
        Many(Vec<String>),
    }
    let items = match List::deserialize(d)? {
        List::One(s) => s.split(',').map(str::to_string).collect(),
        List::Many(v) => v,
    };
    Ok(items
        .into_iter()
        .map(|s| s.trim().to_ascii_lowercase())
        .filter(|s| !s.is_empty())
        .collect())
}

impl Default for Config {
    fn default() -> Self {
        Self {
            bind: "127.0.0.1:8080".into(),
            data_dir: PathBuf::from("data"),
            models_dir: PathBuf::from("models"),
            workers: 0,
            max_upload_bytes: 50 * 1024 * 1024,
            max_duration_s: 15.0 * 60.0,
            audio_timeout_s: 60.0,
            max_job_body_bytes: 2 * 1024 * 1024,
            cors_origins: Vec::new(),
            auth_token: None,
            log_format: LogFormat::Pretty,
            log_level: "info".into(),
            lease_s: 30.0,
            heartbeat_s: 1.0,
            max_attempts: 3,
            retry_backoff_s: 1.0,
            poll_s: 0.5,
            database_url: None,
            artifacts_url: None,
            s3_endpoint: None,
            s3_region: "us-east-1".into(),
            max_connections: 1024,
            fd_reserve: 256,
            header_timeout_s: 10.0,
            body_timeout_s: 15.0,
            write_timeout_s: 30.0,
            max_part_header_bytes: 8 * 1024,
            db_timeout_s: 3.0,
            sweep_grace_s: 3600.0,
            rate_limit_rps: None,
            max_queued_jobs: None,
            storage_quota_bytes: None,
            retention_days: None,
            max_event_streams_per_key: 16,
            event_stream_max_s: 300.0,
            webhook_secret: None,
            webhook_allowed_hosts: Vec::new(),
            webhook_retry_s: 24.0 * 3600.0,
            webhook_backoff_s: 5.0,
        }
    }
}

/// The settings CLI flags may override; `None` leaves the lower layers alone.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Overrides {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bind: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub data_dir: Option<PathBuf>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub models_dir: Option<PathBuf>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub workers: Option<usize>,
}

/// Serializable mirror of the defaults, the bottom layer of the figment.
#[derive(Serialize)]
struct Defaults {
    bind: String,
    data_dir: PathBuf,
    models_dir: PathBuf,
    workers: usize,
    max_upload_bytes: u64,
    max_duration_s: f64,
    audio_timeout_s: f64,
    max_job_body_bytes: u64,
    cors_origins: Vec<String>,
    log_format: LogFormat,
    log_level: String,
    lease_s: f64,
    heartbeat_s: f64,
    max_attempts: u32,
    retry_backoff_s: f64,
    poll_s: f64,
    s3_region: String,
    max_connections: usize,
    fd_reserve: u64,
    header_timeout_s: f64,
    body_timeout_s: f64,
    write_timeout_s: f64,
    max_part_header_bytes: usize,
    db_timeout_s: f64,
    sweep_grace_s: f64,
    max_event_streams_per_key: usize,
    event_stream_max_s: f64,
    webhook_allowed_hosts: Vec<String>,
    webhook_retry_s: f64,
    webhook_backoff_s: f64,
}

impl Defaults {
    fn new() -> Self {
        let d = Config::default();
        Self {
            bind: d.bind,
            data_dir: d.data_dir,
            models_dir: d.models_dir,
            workers: d.workers,
            max_upload_bytes: d.max_upload_bytes,
            max_duration_s: d.max_duration_s,
            audio_timeout_s: d.audio_timeout_s,
            max_job_body_bytes: d.max_job_body_bytes,
            cors_origins: d.cors_origins,
            log_format: d.log_format,
            log_level: d.log_level,
            lease_s: d.lease_s,
            heartbeat_s: d.heartbeat_s,
            max_attempts: d.max_attempts,
            retry_backoff_s: d.retry_backoff_s,
            poll_s: d.poll_s,
            s3_region: d.s3_region,
            max_connections: d.max_connections,
            fd_reserve: d.fd_reserve,
            header_timeout_s: d.header_timeout_s,
            body_timeout_s: d.body_timeout_s,
            write_timeout_s: d.write_timeout_s,
            max_part_header_bytes: d.max_part_header_bytes,
            db_timeout_s: d.db_timeout_s,
            sweep_grace_s: d.sweep_grace_s,
            max_event_streams_per_key: d.max_event_streams_per_key,
            event_stream_max_s: d.event_stream_max_s,
            webhook_allowed_hosts: d.webhook_allowed_hosts,
            webhook_retry_s: d.webhook_retry_s,
            webhook_backoff_s: d.webhook_backoff_s,
        }
    }
}

impl Config {
    /// Loads defaults, then `file` (if it exists), then `CHOREO_*`, then `overrides`.
    pub fn load(file: Option<&Path>, overrides: &Overrides) -> Result<Self, ConfigError> {
        let file = file.unwrap_or(Path::new(DEFAULT_CONFIG_FILE));
        let config: Config = Figment::from(Serialized::defaults(Defaults::new()))
            .merge(Toml::file(file))
            .merge(
                Env::prefixed(ENV_PREFIX)
                    .filter(|key| SETTINGS.contains(&key.as_str().to_ascii_lowercase().as_str())),
            )
            .merge(Serialized::defaults(overrides))
            .extract()
            .map_err(Box::new)?;
        config.validate()?;
        Ok(config)
    }

    /// Checks ranges that serde cannot.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let invalid = |field, message: &str| {
            Err(ConfigError::Invalid {
                field,
                message: message.into(),
            })
        };
        if self.bind.parse::<std::net::SocketAddr>().is_err() {
            return invalid("bind", "must be an IP:port address such as 127.0.0.1:8080");
        }
        if self.max_upload_bytes == 0 {
            return invalid("max_upload_bytes", "must be positive");
        }
        if !(self.max_duration_s.is_finite() && self.max_duration_s > 0.0) {
            return invalid("max_duration_s", "must be a positive number of seconds");
        }
        if !(self.audio_timeout_s.is_finite() && self.audio_timeout_s > 0.0) {
            return invalid("audio_timeout_s", "must be a positive number of seconds");
        }
        if self.max_job_body_bytes == 0 {
            return invalid("max_job_body_bytes", "must be positive");
        }
        if !(self.lease_s.is_finite() && self.lease_s > 0.0) {
            return invalid("lease_s", "must be a positive number of seconds");
        }
        if !(self.heartbeat_s.is_finite()
            && self.heartbeat_s > 0.0
            && self.heartbeat_s < self.lease_s)
        {
            return invalid("heartbeat_s", "must be positive and shorter than lease_s");
        }
        if self.max_attempts == 0 {
            return invalid("max_attempts", "must be at least 1");
        }
        if !(self.retry_backoff_s.is_finite() && self.retry_backoff_s >= 0.0) {
            return invalid(
                "retry_backoff_s",
                "must be zero or a positive number of seconds",
            );
        }
        if !(self.poll_s.is_finite() && self.poll_s > 0.0) {
            return invalid("poll_s", "must be a positive number of seconds");
        }
        if self.max_connections == 0 {
            return invalid("max_connections", "must be at least 1");
        }
        for (field, value) in [
            ("header_timeout_s", self.header_timeout_s),
            ("body_timeout_s", self.body_timeout_s),
            ("write_timeout_s", self.write_timeout_s),
            ("db_timeout_s", self.db_timeout_s),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return invalid(field, "must be a positive number of seconds");
            }
        }
        if self.max_part_header_bytes < 256 {
            return invalid(
                "max_part_header_bytes",
                "must be at least 256 (a part's Content-Disposition needs room)",
            );
        }
        if !(self.sweep_grace_s.is_finite() && self.sweep_grace_s >= 0.0) {
            return invalid(
                "sweep_grace_s",
                "must be zero or a positive number of seconds",
            );
        }
        let unset = "; leave it unset for no limit";
        if let Some(rps) = self.rate_limit_rps {
            if let Err(e) = in_range("rate_limit_rps", rps, &RATE_LIMIT_RPS) {
                return invalid("rate_limit_rps", &format!("{e} requests per second{unset}"));
            }
        }
        if let Some(jobs) = self.max_queued_jobs {
            if let Err(e) = in_range("max_queued_jobs", jobs, &MAX_QUEUED_JOBS) {
                return invalid("max_queued_jobs", &format!("{e}{unset}"));
            }
        }
        if let Some(bytes) = self.storage_quota_bytes {
            if let Err(e) = in_range("storage_quota_bytes", bytes, &STORAGE_QUOTA_BYTES) {
                return invalid("storage_quota_bytes", &format!("{e}{unset}"));
            }
        }
        if let Err(e) = in_range(
            "max_event_streams_per_key",
            self.max_event_streams_per_key,
            &MAX_EVENT_STREAMS_PER_KEY,
        ) {
            return invalid("max_event_streams_per_key", &e);
        }
        if let Err(e) = in_range(
            "event_stream_max_s",
            self.event_stream_max_s,
            &EVENT_STREAM_MAX_S,
        ) {
            return invalid("event_stream_max_s", &format!("{e} seconds"));
        }
        if let Some(days) = self.retention_days {
            if !(days.is_finite() && days > 0.0 && RETENTION_DAYS.contains(&days))
                || self.retention().is_none()
            {
                return invalid(
                    "retention_days",
                    "must be a positive number of days (fractions allowed), at most 36500; leave it unset to keep everything",
                );
            }
        }
        self.database()?;
        if let Some(url) = &self.artifacts_url {
            if url != "local"
                && !url
                    .strip_prefix("s3://")
                    .is_some_and(|rest| !rest.is_empty() && !rest.starts_with('/'))
            {
                return invalid("artifacts_url", "must be \"local\" or s3://bucket[/prefix]");
            }
        }
        self.webhook_key()?;
        for (field, value) in [
            ("webhook_retry_s", self.webhook_retry_s),
            ("webhook_backoff_s", self.webhook_backoff_s),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return invalid(field, "must be zero or a positive number of seconds");
            }
        }
        if let Some(bad) = self.webhook_allowed_hosts.iter().find(|h| !is_host_port(h)) {
            return invalid(
                "webhook_allowed_hosts",
                &format!("{bad:?} is not host:port (e.g. hooks.internal:443, 127.0.0.1:9000, [::1]:9000)"),
            );
        }
        if let Some(token) = &self.auth_token {
            if token.expose().is_empty() {
                return invalid(
                    "auth_token",
                    "must not be empty; leave it unset to turn auth off",
                );
            }
        }
        Ok(())
    }

    /// The webhook signing key: the bytes of `webhook_secret`'s base64 after `whsec_` (Standard
    /// Webhooks' form), or `None` when unset.
    pub fn webhook_key(&self) -> Result<Option<Vec<u8>>, ConfigError> {
        use base64::Engine;
        let Some(secret) = &self.webhook_secret else {
            return Ok(None);
        };
        let invalid = |message: &str| ConfigError::Invalid {
            field: "webhook_secret",
            message: message.into(),
        };
        let encoded = secret
            .expose()
            .strip_prefix("whsec_")
            .ok_or_else(|| invalid("must be whsec_<base64>, Standard Webhooks' form"))?;
        let key = base64::engine::general_purpose::STANDARD
            .decode(encoded)
            .map_err(|_| invalid("the part after whsec_ must be base64"))?;
        if !(24..=64).contains(&key.len()) {
            return Err(invalid(
                "must hold 24 to 64 random bytes (e.g. whsec_$(openssl rand -base64 32))",
            ));
        }
        Ok(Some(key))
    }

    /// The worker count with 0 resolved to the number of cores.
    pub fn worker_count(&self) -> usize {
        if self.workers > 0 {
            self.workers
        } else {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1)
        }
    }

    /// How long songs and results are kept after their last use; none without `retention_days`.
    pub fn retention(&self) -> Option<std::time::Duration> {
        let days = self.retention_days?;
        std::time::Duration::try_from_secs_f64(days * 86_400.0)
            .ok()
            .filter(|d| !d.is_zero())
    }

    /// The SQLite database file used when `database_url` is unset.
    pub fn database_path(&self) -> PathBuf {
        self.data_dir.join("choreo.sqlite")
    }

    /// The database `database_url` names (`sqlite://`, `postgres://` or `postgresql://`).
    pub fn database(&self) -> Result<Database, ConfigError> {
        let Some(url) = &self.database_url else {
            return Ok(Database::Sqlite(self.database_path()));
        };
        let url = url.expose();
        if let Some(path) = url.strip_prefix("sqlite://") {
            // sqlx's query options (`?mode=`) are not ours to take: the store sets its own.
            if path.is_empty() || path.contains('?') {
                return Err(ConfigError::Invalid {
                    field: "database_url",
                    message: "sqlite://PATH needs a file path and no query".into(),
                });
            }
            Ok(Database::Sqlite(PathBuf::from(path)))
        } else if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            Ok(Database::Postgres(Secret::new(url)))
        } else {
            // The URL is not echoed: it may hold a password.
            Err(ConfigError::Invalid {
                field: "database_url",
                message: "must start with sqlite:// or postgres://".into(),
            })
        }
    }
}

#[cfg(test)]
// figment::Jail's closures must return figment's own (large) error type; nothing here can box it.
#[allow(clippy::result_large_err)]
mod tests;
