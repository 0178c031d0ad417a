//! `GET /v1/jobs/{id}/events`: a job's status, stage and progress as server-sent events.
//!
//! The stream is read from `job_events` (written by triggers on the job row, see
//! `queue::events`), never from this process's memory, so it works the same in an API-only
//! process whose workers run elsewhere, and each event's `id` is the line's `seq`: a client that
//! reconnects with `Last-Event-ID` gets exactly the lines after it. New lines are found by
//! polling the store every [`POLL`]: one indexed query per open stream, on both stores (a LISTEN
//! connection per stream would take a pooled PostgreSQL connection for its whole life).
//!
//! Events, in `seq` order: `status` (`from`, `to`, `attempt`, `error`), `progress` (`stage`,
//! `progress`), then one `done` carrying the job as `GET /v1/jobs/{id}` returns it once the job is
//! terminal (at once when it already is), after which the server closes the stream. A comment
//! line (`: keep-alive`) every [`KEEP_ALIVE`] keeps proxies from closing an idle stream. The
//! stream ends when the server stops, and after `event_stream_max_s` (so a stream on a job that
//! never ends cannot hold its slot for good); the client reconnects with `Last-Event-ID`. A key
//! holds at most `max_event_streams_per_key` streams at once in one API process; past it, `429
//! too-many-event-streams` and the connection closes.
use super::auth::Caller;
use super::jobs::{parse_job_id, JobView};
use super::problem::{ApiError, Problem};
use super::tenancy::StreamSlot;
use super::AppState;
use crate::queue::events::{Change, JobEvent};
use crate::queue::{JobId, QueueError, Scope, Status};
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use chrono::{DateTime, Utc};
use futures::Stream;
use serde::Serialize;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// How often an open stream looks for new lines.
pub const POLL: Duration = Duration::from_millis(250);
/// How often an idle stream sends a comment line.
pub const KEEP_ALIVE: Duration = Duration::from_secs(15);
/// Most lines read per poll; a longer backlog is read over several polls without waiting.
const BATCH: u32 = 200;
/// The SSE resume header.
pub const LAST_EVENT_ID: HeaderName = HeaderName::from_static("last-event-id");

/// `event: status`.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct StatusEvent {
    /// The `job_events` sequence number, also the event's `id`.
    pub seq: i64,
    pub job_id: JobId,
    /// None when the job was registered.
    pub from: Option<Status>,
    pub to: Status,
    pub attempt: u32,
    pub error: Option<String>,
    pub at: DateTime<Utc>,
}

/// `event: progress`: a stage entered, or progress past another 5 % step.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ProgressEvent {
    pub seq: i64,
    pub job_id: JobId,
    pub stage: crate::stage::Stage,
    /// 0..=1, of the whole job.
    pub progress: f64,
    pub at: DateTime<Utc>,
}

fn sse_event(event: &JobEvent) -> Event {
    let (name, data) = match &event.change {
        Change::Status {
            from,
            to,
            attempt,
            error,
        } => (
            "status",
            serde_json::to_string(&StatusEvent {
                seq: event.seq,
                job_id: event.job_id,
                from: *from,
                to: *to,
                attempt: *attempt,
                error: error.clone(),
                at: event.at,
            }),
        ),
        Change::Progress { stage, progress } => (
            "progress",
            serde_json::to_string(&ProgressEvent {
                seq: event.seq,
                job_id: event.job_id,
                stage: *stage,
                progress: *progress,
                at: event.at,
            }),
        ),
    };
    // Serialising these plain structs cannot fail; an empty object is what a client would see.
    Event::default()
        .id(event.seq.to_string())
        .event(name)
        .data(data.unwrap_or_else(|_| "{}".into()))
}

/// Where a stream is.
struct Cursor {
    state: AppState,
    scope: Scope,
    id: JobId,
    /// The last `seq` sent.
    last: i64,
    /// Events read but not yet sent.
    queue: VecDeque<Event>,
    /// The job was terminal when last looked at: once the lines are read, `done` follows.
    ending: bool,
    /// `done` was sent, or the stream must end.
    over: bool,
    /// Polls in a row that found nothing new.
    idle: u32,
    shutdown: CancellationToken,
    /// When the stream ends even if the job has not (`event_stream_max_s`): the client resumes
    /// with `Last-Event-ID`, and the slot it held is free meanwhile.
    ends_at: tokio::time::Instant,
    /// The tenant's slot for this stream, given back when the stream is dropped.
    _slot: StreamSlot,
}

impl Cursor {
    /// Reads the lines after `last`; after the terminal status line (or when the job already was
    /// terminal), the job itself as `done`. `Err` ends the stream (the client resumes).
    async fn fill(&mut self) -> Result<(), QueueError> {
        let lines = self
            .state
            .store
            .job_events(self.id, self.last, BATCH)
            .await?;
        let full = lines.len() == BATCH as usize;
        for line in &lines {
            self.last = line.seq;
            if let Change::Status { to, .. } = line.change {
                self.ending |= to.is_terminal();
            }
            self.queue.push_back(sse_event(line));
        }
        if self.ending && !full {
            // Every line of a terminal job is in: each was written with the change it logs.
            let job = self.state.store.job(self.scope, self.id).await?;
            let data = serde_json::to_string(&JobView::from(job)).unwrap_or_else(|_| "{}".into());
            self.queue
                .push_back(Event::default().event("done").data(data));
            self.over = true;
        }
        Ok(())
    }

    async fn next(mut self) -> Option<(Result<Event, Infallible>, Self)> {
        loop {
            if let Some(event) = self.queue.pop_front() {
                return Some((Ok(event), self));
            }
            if self.over
                || self.shutdown.is_cancelled()
                || tokio::time::Instant::now() >= self.ends_at
            {
                return None;
            }
            let before = self.last;
            if let Err(e) = self.fill().await {
                tracing::warn!(job_id = %self.id, error = %e, "job event stream ended by a store error; the client resumes with Last-Event-ID");
                return None;
            }
            if self.queue.is_empty() && self.last == before {
                self.idle += 1;
                // A deleted job's audit line is no event, so a stream on it would wait forever:
                // every 8th idle poll (2 s) looks whether the job still exists.
                if self.idle.is_multiple_of(8) {
                    if let Err(QueueError::JobNotFound(_)) =
                        self.state.store.job(self.scope, self.id).await
                    {
                        return None;
                    }
                }
                tokio::select! {
                    _ = self.shutdown.cancelled() => return None,
                    _ = tokio::time::sleep_until(self.ends_at) => return None,
                    _ = tokio::time::sleep(POLL) => {}
                }
            }
        }
    }
}

/// A job's status, stage and progress as they happen (server-sent events).
///
/// `text/event-stream`. Each `status` and `progress` event has `id: <seq>`; send the last one
/// seen as `Last-Event-ID` to resume after it, missing nothing. `status` data:
/// `{seq, job_id, from, to, attempt, error, at}`; `progress` data: `{seq, job_id, stage,
/// progress, at}` (sent when the stage changes and at every 5 % of progress); `done` data: the job
/// as `GET /v1/jobs/{id}` returns it, sent once the job is terminal (at once when it already is),
/// after which the stream closes. `: keep-alive` comments every 15 s. A stream also ends after
/// `event_stream_max_s` (300 s by default): resume with `Last-Event-ID`. A key may hold
/// `max_event_streams_per_key` streams (16 by default) at once; past it, 429.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/events",
    operation_id = "getJobEvents",
    tag = "jobs",
    params(
        ("id" = String, Path, description = "Job id"),
        ("Last-Event-ID" = Option<i64>, Header, description = "The `id` of the last event received: the stream resumes after it"),
    ),
    responses(
        (status = 200, description = "The job's events, until it is terminal", content_type = "text/event-stream", body = String),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn events(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let id = parse_job_id(&id)?;
    let scope = caller.scope();
    // Taken first: a key past its streams is refused before it costs a database read.
    let slot = state
        .tenancy
        .streams
        .take(caller.tenant, state.config.max_event_streams_per_key)?;
    let ends_at =
        tokio::time::Instant::now() + Duration::from_secs_f64(state.config.event_stream_max_s);
    // 404 before any byte of the stream, and another tenant's job reads as no job.
    let job = state.store.job(scope, id).await?;
    // A malformed Last-Event-ID replays from the start, as a client without one would get: the
    // stream may repeat lines to a confused client but never skips any.
    let last = headers
        .get(LAST_EVENT_ID)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<i64>().ok())
        .unwrap_or(0)
        .max(0);
    let cursor = Cursor {
        shutdown: state.shutdown.clone(),
        state,
        scope,
        id,
        last,
        queue: VecDeque::new(),
        ending: job.status.is_terminal(),
        over: false,
        idle: 0,
        ends_at,
        _slot: slot,
    };
    let stream = futures::stream::unfold(cursor, Cursor::next);
    let mut response = sse(stream).into_response();
    // Reverse proxies (nginx) would otherwise buffer the stream.
    response.headers_mut().insert(
        HeaderName::from_static("x-accel-buffering"),
        HeaderValue::from_static("no"),
    );
    Ok(response)
}

fn sse<S>(stream: S) -> impl IntoResponse
where
    S: Stream<Item = Result<Event, Infallible>> + Send + 'static,
{
    Sse::new(stream).keep_alive(KeepAlive::new().interval(KEEP_ALIVE).text("keep-alive"))
}
