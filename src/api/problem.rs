//! RFC 9457 problem+json errors: every failure has a stable `code` and says what to fix.
use crate::audio::AudioError;
use crate::motion::retarget::uploaded::RigFileError;
use crate::queue::{JobId, QueueError, Status};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

/// What `Retry-After` says on a 503 or 507, in seconds.
const RETRY_AFTER_S: &str = "5";

/// The media type of problem bodies.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// An RFC 9457 problem body.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Problem {
    /// Always `about:blank`: `code` names the problem.
    #[serde(rename = "type")]
    pub type_: String,
    /// The HTTP status phrase.
    pub title: String,
    pub status: u16,
    /// What went wrong and what to fix.
    pub detail: String,
    /// Stable kebab-case name of the problem, for clients to match on.
    pub code: String,
    /// The request field at fault, when there is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The job's status, for results asked for too early.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub job_status: Option<Status>,
    /// The models this server has, for an unknown model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub available_models: Option<Vec<String>>,
}

/// Every error the API answers with.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    #[error("the body is not valid JSON: {0}")]
    MalformedJson(String),
    #[error("send the body as JSON with `Content-Type: application/json`")]
    NotJson,
    #[error("`{field}`: {message}")]
    InvalidField { field: String, message: String },
    #[error("`{field}`: {message}")]
    MotionNotFinite { field: String, message: String },
    #[error("unknown field `{0}`; remove it")]
    UnknownField(String),
    #[error("missing field `{0}`")]
    MissingField(String),
    #[error("invalid query string: {0}")]
    InvalidQuery(String),
    #[error("the upload is not a valid multipart/form-data body: {0}")]
    InvalidMultipart(String),
    #[error("send the song as a multipart/form-data field named `file`")]
    MissingFile,
    #[error("unexpected multipart field `{0}`; send only one field, named `file`")]
    UnexpectedField(String),
    #[error("the uploaded file is empty")]
    EmptyFile,
    #[error("the file is larger than the {limit} byte limit")]
    FileTooLarge { limit: u64 },
    #[error("the body is larger than the {limit} byte limit")]
    BodyTooLarge { limit: u64 },
    #[error("the song is longer than the {limit:.0} s limit ({seconds:.1} s declared or decoded)")]
    SongTooLong { seconds: f64, limit: f64 },
    #[error("the file name {0:?} is not allowed: give a plain name without path separators, `..` or control characters")]
    InvalidFilename(String),
    #[error("{0}")]
    Audio(AudioError),
    #[error("the file is cut short: its header declares {declared_s:.1} s of audio but only {decoded_s:.1} s decode; upload the whole file")]
    Truncated { declared_s: f64, decoded_s: f64 },
    #[error("song {0} does not exist")]
    SongNotFound(String),
    #[error("{0}")]
    JobNotFound(String),
    #[error("rig {0} does not exist")]
    RigNotFound(String),
    #[error("{0}")]
    Rig(RigFileError),
    #[error("the rig file was not read within {limit_s} s (audio_timeout_s); send a smaller file")]
    RigTimedOut { limit_s: f64 },
    #[error("model `{model}` is not available; use one of the available models")]
    UnknownModel {
        model: String,
        available: Vec<String>,
    },
    #[error("job {id} is {status}; results exist once it has succeeded")]
    JobNotFinished { id: JobId, status: Status },
    #[error("{0}")]
    ResultNotFound(String),
    #[error("job {id} already {status}; it can no longer be cancelled")]
    AlreadyFinished { id: JobId, status: Status },
    #[error(
        "the Idempotency-Key was already used for a different request (job {0}); use a new key"
    )]
    IdempotencyConflict(JobId),
    #[error("the Idempotency-Key header must be 1 to 255 visible ASCII characters")]
    InvalidIdempotencyKey,
    #[error("send `Authorization: Bearer <secret>` with a valid API key's secret (or the server's token)")]
    Unauthorized,
    #[error("no route for this path; see /docs")]
    NoRoute,
    #[error("this method is not allowed on this path; see /docs")]
    MethodNotAllowed,
    #[error("the server is not ready: {0}")]
    NotReady(String),
    #[error("the request body stalled for more than {seconds} s; send it without long pauses")]
    BodyTimeout { seconds: f64 },
    #[error("a multipart part's headers (field name, file name, content type) are longer than {limit} bytes")]
    PartHeaderTooLarge { limit: usize },
    #[error("the server has {limit} connections open, its most; try again shortly")]
    TooManyConnections { limit: usize },
    #[error("the server is out of storage ({0}); nothing was stored, try again later")]
    InsufficientStorage(String),
    #[error("a service the server depends on is unavailable ({0}); try again shortly")]
    ServiceUnavailable(String),
    #[error("internal error: {0}")]
    Internal(String),
    #[error("this key made more than {rps} requests per second; wait {retry_after_s} s (Retry-After) and slow down")]
    RateLimited { rps: f64, retry_after_s: u64 },
    #[error("this key has {limit} jobs queued or running, its most; wait for some to finish (or cancel some) and submit again")]
    TooManyQueuedJobs { limit: u64 },
    #[error("this key stores {used} bytes of songs, rigs and results; {size} more would pass its {quota} byte quota: delete songs or results to make room")]
    StorageQuotaExceeded { used: u64, size: u64, quota: u64 },
    #[error("this key stores {used} bytes of songs, rigs and results, at or past its {quota} byte quota, so a job's results have no room: delete songs, rigs or results, then submit again")]
    StorageQuotaFull { used: u64, quota: u64 },
    #[error("this key has {limit} event streams open, its most; close one (or follow the job with GET /v1/jobs/{{id}}) and try again")]
    TooManyEventStreams { limit: usize },
    #[error("webhook_url is refused: {0}")]
    WebhookUrlRefused(String),
    #[error("this server has no webhook_secret (CHOREO_WEBHOOK_SECRET) to sign webhooks with; submit without webhook_url, or ask its operator to set one")]
    WebhooksNotConfigured,
    #[error("the Range {range:?} asks for no byte of this {len}-byte file; ask for bytes within 0-{last}, or send no Range for the whole file", last = .len.saturating_sub(1))]
    RangeNotSatisfiable { range: String, len: u64 },
}

impl ApiError {
    /// Stable kebab-case code.
    pub fn code(&self) -> &'static str {
        match self {
            ApiError::MalformedJson(_) => "malformed-json",
            ApiError::NotJson => "not-json",
            ApiError::InvalidField { .. } => "invalid-field",
            ApiError::MotionNotFinite { .. } => "motion-not-finite",
            ApiError::UnknownField(_) => "unknown-field",
            ApiError::MissingField(_) => "missing-field",
            ApiError::InvalidQuery(_) => "invalid-query",
            ApiError::InvalidMultipart(_) => "invalid-multipart",
            ApiError::MissingFile => "missing-file-field",
            ApiError::UnexpectedField(_) => "unexpected-multipart-field",
            ApiError::EmptyFile => "empty-file",
            ApiError::FileTooLarge { .. } => "file-too-large",
            ApiError::BodyTooLarge { .. } => "body-too-large",
            ApiError::SongTooLong { .. } => "song-too-long",
            ApiError::InvalidFilename(_) => "invalid-filename",
            ApiError::Audio(e) => e.code(),
            ApiError::Truncated { .. } => "audio-truncated",
            ApiError::SongNotFound(_) => "song-not-found",
            ApiError::RigNotFound(_) => "rig-not-found",
            ApiError::Rig(e) => e.code(),
            ApiError::JobNotFound(_) => "job-not-found",
            ApiError::UnknownModel { .. } => "unknown-model",
            ApiError::JobNotFinished { .. } => "job-not-finished",
            ApiError::ResultNotFound(_) => "result-not-found",
            ApiError::AlreadyFinished { .. } => "job-already-finished",
            ApiError::IdempotencyConflict(_) => "idempotency-key-reused",
            ApiError::InvalidIdempotencyKey => "invalid-idempotency-key",
            ApiError::Unauthorized => "unauthorized",
            ApiError::NoRoute => "not-found",
            ApiError::MethodNotAllowed => "method-not-allowed",
            ApiError::NotReady(_) => "not-ready",
            ApiError::BodyTimeout { .. } => "body-timeout",
            ApiError::PartHeaderTooLarge { .. } => "part-header-too-large",
            ApiError::TooManyConnections { .. } => "too-many-connections",
            ApiError::InsufficientStorage(_) => "insufficient-storage",
            ApiError::ServiceUnavailable(_) => "service-unavailable",
            ApiError::Internal(_) => "internal",
            ApiError::RateLimited { .. } => "rate-limited",
            ApiError::TooManyQueuedJobs { .. } => "too-many-queued-jobs",
            ApiError::StorageQuotaExceeded { .. } => "storage-quota-exceeded",
            ApiError::StorageQuotaFull { .. } => "storage-quota-exceeded",
            ApiError::TooManyEventStreams { .. } => "too-many-event-streams",
            ApiError::RigTimedOut { .. } => "rig-timed-out",
            ApiError::WebhookUrlRefused(_) => "webhook-url-refused",
            ApiError::WebhooksNotConfigured => "webhooks-not-configured",
            ApiError::RangeNotSatisfiable { .. } => "range-not-satisfiable",
        }
    }

    /// The HTTP status.
    pub fn status(&self) -> StatusCode {
        match self {
            ApiError::MalformedJson(_) => StatusCode::BAD_REQUEST,
            ApiError::NotJson => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            ApiError::InvalidField { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::MotionNotFinite { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::UnknownField(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::MissingField(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::InvalidQuery(_) => StatusCode::BAD_REQUEST,
            ApiError::InvalidMultipart(_) => StatusCode::BAD_REQUEST,
            ApiError::MissingFile => StatusCode::BAD_REQUEST,
            ApiError::UnexpectedField(_) => StatusCode::BAD_REQUEST,
            ApiError::EmptyFile => StatusCode::BAD_REQUEST,
            ApiError::FileTooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::BodyTooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::SongTooLong { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::InvalidFilename(_) => StatusCode::BAD_REQUEST,
            ApiError::Audio(AudioError::Undecodable(_)) => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            // The server is stopping; the same upload succeeds once it is back.
            ApiError::Audio(AudioError::Cancelled) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Audio(e) if e.is_client_error() => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::Audio(_) => StatusCode::INTERNAL_SERVER_ERROR,
            ApiError::Truncated { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::SongNotFound(_) => StatusCode::NOT_FOUND,
            ApiError::RigNotFound(_) => StatusCode::NOT_FOUND,
            ApiError::Rig(e) if e.is_unsupported_media() => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            ApiError::Rig(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::JobNotFound(_) => StatusCode::NOT_FOUND,
            ApiError::UnknownModel { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::JobNotFinished { .. } => StatusCode::CONFLICT,
            ApiError::ResultNotFound(_) => StatusCode::NOT_FOUND,
            ApiError::AlreadyFinished { .. } => StatusCode::CONFLICT,
            ApiError::IdempotencyConflict(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::InvalidIdempotencyKey => StatusCode::BAD_REQUEST,
            ApiError::Unauthorized => StatusCode::UNAUTHORIZED,
            ApiError::NoRoute => StatusCode::NOT_FOUND,
            ApiError::MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::NotReady(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::BodyTimeout { .. } => StatusCode::REQUEST_TIMEOUT,
            ApiError::PartHeaderTooLarge { .. } => StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
            ApiError::TooManyConnections { .. } => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::InsufficientStorage(_) => StatusCode::INSUFFICIENT_STORAGE,
            ApiError::ServiceUnavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
            ApiError::RateLimited { .. } => StatusCode::TOO_MANY_REQUESTS,
            ApiError::TooManyQueuedJobs { .. } => StatusCode::TOO_MANY_REQUESTS,
            // The upload is too large for the room the tenant has left: a smaller one may fit.
            ApiError::StorageQuotaExceeded { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            // The same quota, met at a job: its results are what would not fit.
            ApiError::StorageQuotaFull { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            // Like the queue limit, it clears by itself as the key's other streams end.
            ApiError::TooManyEventStreams { .. } => StatusCode::TOO_MANY_REQUESTS,
            ApiError::RigTimedOut { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::WebhookUrlRefused(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::WebhooksNotConfigured => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::RangeNotSatisfiable { .. } => StatusCode::RANGE_NOT_SATISFIABLE,
        }
    }

    /// The problem body.
    pub fn problem(&self) -> Problem {
        let status = self.status();
        let mut problem = Problem {
            type_: "about:blank".into(),
            title: status.canonical_reason().unwrap_or("Error").into(),
            status: status.as_u16(),
            detail: self.to_string(),
            code: self.code().into(),
            field: None,
            job_status: None,
            available_models: None,
        };
        match self {
            ApiError::InvalidField { field, .. }
            | ApiError::MotionNotFinite { field, .. }
            | ApiError::UnknownField(field)
            | ApiError::MissingField(field) => {
                problem.field = Some(field.clone());
            }
            ApiError::MissingFile
            | ApiError::EmptyFile
            | ApiError::InvalidFilename(_)
            | ApiError::Truncated { .. } => {
                problem.field = Some("file".into());
            }
            ApiError::UnknownModel { available, .. } => {
                problem.field = Some("model".into());
                problem.available_models = Some(available.clone());
                problem.detail = format!(
                    "{self}: [{}]{}",
                    available.join(", "),
                    if available.is_empty() {
                        " (no model is trained on this server yet)"
                    } else {
                        ""
                    }
                );
            }
            ApiError::Rig(e) => {
                problem.field = Some(e.field().into());
            }
            ApiError::WebhookUrlRefused(_) | ApiError::WebhooksNotConfigured => {
                problem.field = Some("webhook_url".into());
            }
            ApiError::JobNotFinished { status, .. } | ApiError::AlreadyFinished { status, .. } => {
                problem.job_status = Some(*status);
            }
            _ => {}
        }
        problem
    }
}

/// Whether an I/O error means the disk (or the quota, or the file size limit) is full.
pub fn is_out_of_space(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::StorageFull
            | std::io::ErrorKind::QuotaExceeded
            | std::io::ErrorKind::FileTooLarge
    ) || e
        .raw_os_error()
        .is_some_and(|n| n == libc::ENOSPC || n == libc::EDQUOT || n == libc::EFBIG)
}

impl ApiError {
    /// A failed write or read of the server's own storage, without the server's paths: out of
    /// space is `507 insufficient-storage`, anything else `500 internal`.
    pub fn storage(doing: &str, e: &std::io::Error) -> Self {
        if is_out_of_space(e) {
            ApiError::InsufficientStorage(format!("{doing}: no space left"))
        } else {
            // io::Error's Display can carry a path (tempfile adds one); its kind cannot.
            ApiError::Internal(format!("{doing}: {}", e.kind()))
        }
    }

    /// The API error for a failed artifact read or write (`doing` says which).
    pub fn artifact(doing: &str, e: &crate::artifacts::ArtifactError) -> Self {
        use crate::artifacts::ArtifactError;
        match e {
            ArtifactError::NotFound(key) => {
                ApiError::Internal(format!("{doing}: {key} is missing from the artifact store"))
            }
            ArtifactError::Io { source, .. } => ApiError::storage(doing, source),
            ArtifactError::Bucket { .. } => ApiError::ServiceUnavailable(format!("{doing}: {e}")),
            ArtifactError::Config(_) => ApiError::Internal(format!("{doing}: {e}")),
        }
    }

    /// The API error for a database failure: unreachable is `503`, full is `507`.
    fn database(e: &sqlx::Error) -> Option<Self> {
        match e {
            sqlx::Error::PoolTimedOut
            | sqlx::Error::PoolClosed
            | sqlx::Error::WorkerCrashed
            | sqlx::Error::Tls(_) => Some(ApiError::ServiceUnavailable(format!("database: {e}"))),
            sqlx::Error::Io(io) if is_out_of_space(io) => Some(ApiError::InsufficientStorage(
                "database: no space left".into(),
            )),
            sqlx::Error::Io(_) => Some(ApiError::ServiceUnavailable(format!("database: {e}"))),
            sqlx::Error::Database(db) => {
                let code = db.code();
                // SQLite's SQLITE_FULL (13), PostgreSQL's disk_full (53100).
                let full = matches!(code.as_deref(), Some("13") | Some("53100"))
                    || db.message().contains("disk is full");
                // PostgreSQL's connection exceptions (class 08) and a server shutting down or
                // starting (57P01-57P03): the database is unreachable for now, not broken.
                let gone = code.as_deref().is_some_and(|c| {
                    c.starts_with("08") || matches!(c, "57P01" | "57P02" | "57P03")
                });
                if full {
                    Some(ApiError::InsufficientStorage(
                        "database: no space left".into(),
                    ))
                } else if gone {
                    Some(ApiError::ServiceUnavailable(format!("database: {e}")))
                } else {
                    None
                }
            }
            _ => None,
        }
    }
}

impl From<QueueError> for ApiError {
    fn from(e: QueueError) -> Self {
        match e {
            QueueError::SongNotFound(id) => ApiError::SongNotFound(id.to_string()),
            QueueError::JobNotFound(id) => {
                ApiError::JobNotFound(format!("job {id} does not exist"))
            }
            QueueError::RigNotFound(id) => ApiError::RigNotFound(id.to_string()),
            QueueError::IdempotencyConflict(id) => ApiError::IdempotencyConflict(id),
            QueueError::QueueFull { limit } => ApiError::TooManyQueuedJobs { limit },
            QueueError::QuotaExceeded { used, size, quota } => {
                ApiError::StorageQuotaExceeded { used, size, quota }
            }
            QueueError::QuotaFull { used, quota } => ApiError::StorageQuotaFull { used, quota },
            // Keys are only looked up by `authenticate`, where a missing one is a 401.
            QueueError::KeyNotFound(_) => ApiError::Unauthorized,
            QueueError::Database(db) => ApiError::database(&db)
                .unwrap_or_else(|| ApiError::Internal(format!("database: {db}"))),
            other @ (QueueError::Migrate(_) | QueueError::Corrupt(_)) => {
                ApiError::Internal(other.to_string())
            }
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        if status.is_server_error() {
            tracing::error!(code = self.code(), error = %self, "request failed");
        }
        let mut response = (status, axum::Json(self.problem())).into_response();
        response
            .headers_mut()
            .insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
        if matches!(
            self,
            ApiError::BodyTooLarge { .. }
                | ApiError::BodyTimeout { .. }
                | ApiError::PartHeaderTooLarge { .. }
        ) {
            // The rest of the body is never read; hyper drops the connection after the answer,
            // so a keep-alive client must not send its next request into it.
            response
                .headers_mut()
                .insert(header::CONNECTION, HeaderValue::from_static("close"));
        }
        if status == StatusCode::SERVICE_UNAVAILABLE || status == StatusCode::INSUFFICIENT_STORAGE {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from_static(RETRY_AFTER_S));
        }
        match &self {
            ApiError::RateLimited { retry_after_s, .. } => {
                response
                    .headers_mut()
                    .insert(header::RETRY_AFTER, HeaderValue::from(*retry_after_s));
            }
            ApiError::TooManyQueuedJobs { .. } => {
                response
                    .headers_mut()
                    .insert(header::RETRY_AFTER, HeaderValue::from_static(RETRY_AFTER_S));
            }
            ApiError::TooManyEventStreams { .. } => {
                // Closed, so a client that tries a thousand streams does not keep a thousand
                // idle connections open (each would hold one of the server's connection slots).
                let headers = response.headers_mut();
                headers.insert(header::RETRY_AFTER, HeaderValue::from_static(RETRY_AFTER_S));
                headers.insert(header::CONNECTION, HeaderValue::from_static("close"));
            }
            _ => {}
        }
        if let ApiError::RangeNotSatisfiable { len, .. } = &self {
            // RFC 9110 §15.5.17: the current length, so the client can ask again within it.
            if let Ok(value) = HeaderValue::from_str(&format!("bytes */{len}")) {
                response.headers_mut().insert(header::CONTENT_RANGE, value);
            }
        }
        if matches!(self, ApiError::Unauthorized) {
            response
                .headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        response
    }
}
