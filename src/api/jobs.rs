//! `/v1/jobs`: submit, read, list, cancel, and the result files.
use super::auth::Caller;
use super::extract::{optional_integer, ApiJson, ApiQuery};
use super::paging::PageRequest;
use super::problem::{ApiError, Problem};
use super::AppState;
use crate::models::{DanceStyle, ModelId};
use crate::motion::input::{KeyPoseInput, SeedMotionInput};
use crate::motion::{validate, KeyPose, MOTION_FPS};
use crate::queue::files::RESULT_FILES;
use crate::queue::{
    GenerateOptions, Idempotency, JobFilter, JobId, JobKind, NewJob, QueueError, Registered,
    SeedMotion, SongId, Status,
};
use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, HeaderName, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::str::FromStr;

/// The header that makes a submission safe to retry.
pub const IDEMPOTENCY_KEY: HeaderName = HeaderName::from_static("idempotency-key");
/// Set on a response that replays an earlier submission.
pub const IDEMPOTENT_REPLAYED: HeaderName = HeaderName::from_static("idempotent-replayed");
/// Priority bounds a client may ask for.
const PRIORITY_RANGE: std::ops::RangeInclusive<i64> = -100..=100;
/// Sampling temperatures a job may ask for.
const TEMPERATURE_RANGE: std::ops::RangeInclusive<f64> = 0.05..=5.0;
/// Most key poses one job takes; each costs validation here and a constraint in the model.
pub const MAX_KEY_POSES: usize = 128;
/// Most seed-motion frames one job takes (41 s at 25 fps); models use only its last frames.
pub const MAX_SEED_FRAMES: usize = 1024;

/// A request for a dance.
#[derive(Debug, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateJob {
    pub song_id: SongId,
    /// A model id from `GET /v1/models`.
    pub model: String,
    /// Seeds every random draw; the same seed gives the same dance. Random when absent.
    #[serde(default, deserialize_with = "optional_integer")]
    pub seed: Option<u64>,
    /// Poses the dance must pass through (models with the `key_poses` capability). Each is 26
    /// joints in motion.json's `joint_names` order (any frame of a choreo result: `positions[t]`),
    /// 23 in the dataset's order (`joint_set: "dataset"`, relative to the body centre), or a frame
    /// of a BVH (`bvh: {text, frame}`, e.g. a job's motion.bvh). Its `time_s` must land on a frame
    /// of the dance: `round(time_s × 25) < ⌊duration_s × 25⌋`.
    #[serde(default)]
    #[schema(max_items = 128)]
    pub key_poses: Vec<KeyPoseInput>,
    /// A motion to continue from (models with the `seed_motion` capability): `fps` and `positions`
    /// in either joint set (a slice of motion.json's `positions` works as it is), or `bvh` text.
    #[serde(default)]
    pub seed_motion: Option<SeedMotionInput>,
    /// Keep the dancer on the floor (a foot touches it at least once in any two seconds) and hold
    /// the supporting foot in place so feet do not skate, by moving the whole body (the pose and
    /// key poses are kept). Default true; false returns the model's motion as it came.
    #[serde(default)]
    pub plant_feet: Option<bool>,
    /// The ballroom style to dance (models with the `style` capability). Default: the model's
    /// style classifier picks one from the song; the report says which, and whether it was picked.
    #[serde(default)]
    pub style: Option<DanceStyle>,
    /// Scales the randomness of a sampling model (the `temperature` capability): 1 is as trained,
    /// lower is more conservative. 0.05..=5.
    #[serde(default)]
    #[schema(minimum = 0.05, maximum = 5.0)]
    pub temperature: Option<f64>,
    /// Sample only among the k likeliest choices (the `top_k` capability). 1..=300.
    #[serde(default, deserialize_with = "optional_integer")]
    #[schema(minimum = 1, maximum = 300)]
    pub top_k: Option<u32>,
    /// Higher runs first; -100..=100, default 0.
    #[serde(default, deserialize_with = "optional_integer")]
    #[schema(minimum = -100, maximum = 100)]
    pub priority: Option<i64>,
    /// POSTed the job (as `GET /v1/jobs/{id}` returns it) when it ends, signed per Standard
    /// Webhooks with the server's `webhook_secret`. http(s) only; a host that resolves to a
    /// loopback, private, link-local or otherwise non-global address is refused (422
    /// `webhook-url-refused`) unless the server lists its `host:port` in `webhook_allowed_hosts`.
    #[serde(default)]
    #[schema(max_length = 2048)]
    pub webhook_url: Option<String>,
}

// A job's wire form lives with the queue: the webhook body is the same view, and the
// webhooks sit below the API.
pub use crate::queue::view::{JobView, Links};

/// A page of jobs.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct JobPage {
    pub items: Vec<JobView>,
    /// Pass as `cursor` for the next page; absent on the last page.
    pub next_cursor: Option<String>,
}

/// Filters and page of `GET /v1/jobs`.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// queued, running, succeeded, failed or cancelled.
    #[param(value_type = Option<Status>)]
    pub status: Option<String>,
    /// A model id.
    pub model: Option<String>,
    /// 1..=100, default 20.
    #[param(minimum = 1, maximum = 100, default = 20)]
    pub limit: Option<u32>,
    /// `next_cursor` of the previous page (a job id).
    #[param(format = Uuid)]
    pub cursor: Option<String>,
}

fn invalid(field: &str, message: impl Into<String>) -> ApiError {
    ApiError::InvalidField {
        field: field.into(),
        message: message.into(),
    }
}

/// A refused key pose or seed motion: a number that is not finite has its own code.
fn motion_input(field: &str, e: crate::motion::validate::InputError) -> ApiError {
    match e {
        crate::motion::validate::InputError::NonFinite { .. } => ApiError::MotionNotFinite {
            field: field.into(),
            message: e.to_string(),
        },
        e => invalid(field, e.to_string()),
    }
}

/// The request's key poses and seed motion made canonical and validated by the motion module
/// (`motion::input`), the rules the models apply: 422 here rather than a failed job later.
/// BVH parsing and resampling are CPU work, so they run off the async threads.
async fn motion_inputs(
    key_poses: Vec<KeyPoseInput>,
    seed_motion: Option<SeedMotionInput>,
    duration_s: f64,
) -> Result<(Vec<KeyPose>, Option<SeedMotion>), ApiError> {
    if key_poses.is_empty() && seed_motion.is_none() {
        return Ok((Vec::new(), None));
    }
    tokio::task::spawn_blocking(move || {
        let frames = validate::song_frames(duration_s, MOTION_FPS);
        let keys = crate::motion::input::key_poses(&key_poses, frames, MOTION_FPS)
            .map_err(|e| motion_input("key_poses", e))?;
        let seed = seed_motion
            .map(|s| crate::motion::input::seed_motion(&s))
            .transpose()
            .map_err(|e| motion_input("seed_motion", e))?
            .map(|m| SeedMotion {
                fps: m.fps,
                positions: m
                    .positions
                    .outer_iter()
                    .map(|f| {
                        f.outer_iter()
                            .map(|p| [0, 1, 2].map(|c| f64::from(p[c])))
                            .collect()
                    })
                    .collect(),
            });
        Ok((keys, seed))
    })
    .await
    .map_err(|e| ApiError::Internal(format!("checking motion inputs: {e}")))?
}

/// Refuses inputs whose size alone would cost memory or time, before anything else reads them.
fn check_sizes(request: &CreateJob) -> Result<(), ApiError> {
    if request.key_poses.len() > MAX_KEY_POSES {
        return Err(invalid(
            "key_poses",
            format!(
                "at most {MAX_KEY_POSES} key poses, got {}",
                request.key_poses.len()
            ),
        ));
    }
    if let Some(positions) = request
        .seed_motion
        .as_ref()
        .and_then(|s| s.positions.as_ref())
    {
        if positions.len() > MAX_SEED_FRAMES {
            return Err(invalid(
                "seed_motion.positions",
                format!("at most {MAX_SEED_FRAMES} frames, got {}", positions.len()),
            ));
        }
    }
    Ok(())
}

fn idempotency(headers: &HeaderMap, request: &CreateJob) -> Result<Option<Idempotency>, ApiError> {
    let Some(value) = headers.get(&IDEMPOTENCY_KEY) else {
        return Ok(None);
    };
    let key = value
        .to_str()
        .map_err(|_| ApiError::InvalidIdempotencyKey)?;
    if key.is_empty() || key.len() > 255 || !key.bytes().all(|b| b.is_ascii_graphic()) {
        return Err(ApiError::InvalidIdempotencyKey);
    }
    let canonical = serde_json::to_vec(request).map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(Some(Idempotency {
        key: key.to_string(),
        request_hash: hex::encode(Sha256::digest(&canonical)),
    }))
}

/// Submit a dance.
///
/// Returns 202 with the queued job. With an `Idempotency-Key`, the same key and body return
/// the same job (with `Idempotent-Replayed: true`); the same key with another body is a 422.
/// Key poses and seed motion are checked here by the rules the model applies, so a job queued
/// with them is one the model serves; any frame of a result (motion.json or motion.bvh) can be
/// sent back as either.
#[utoipa::path(
    post,
    path = "/v1/jobs",
    operation_id = "createJob",
    tag = "jobs",
    request_body = CreateJob,
    params(("Idempotency-Key" = Option<String>, Header, description = "Makes retries safe: one job per key. 1 to 255 visible ASCII characters",
        min_length = 1, max_length = 255, pattern = "^[!-~]+$")),
    responses(
        (status = 202, description = "Job queued (or replayed)", body = JobView),
        (status = 400, description = "Malformed JSON, or a malformed Idempotency-Key", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "The song does not exist", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is over max_job_body_bytes (code body-too-large), or the key already stores its storage_quota_bytes so the job's results have no room (code storage-quota-exceeded: delete songs, rigs or results)", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 408, description = "The body stalled for more than body_timeout_s", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A field is invalid (e.g. a key pose whose time has no frame of the dance, or joints that fit neither joint set, a number in a key pose or seed motion that is not finite: `motion-not-finite`, or a webhook_url refused: `webhook-url-refused`, `webhooks-not-configured`), the model is unknown, or the key was reused", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The database is unreachable; nothing was queued, send it again shortly", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The server is out of storage; nothing was queued", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn create(
    State(state): State<AppState>,
    caller: Caller,
    headers: HeaderMap,
    ApiJson(mut request): ApiJson<CreateJob>,
) -> Result<Response, ApiError> {
    check_sizes(&request)?;
    let idempotency = idempotency(&headers, &request)?;
    let song = match state.store.song(caller.scope(), request.song_id).await {
        Ok(song) => song,
        // 404, as for any id that names nothing: the request itself is well formed.
        Err(QueueError::SongNotFound(id)) => return Err(ApiError::SongNotFound(id.to_string())),
        Err(e) => return Err(e.into()),
    };
    let model_id = ModelId(request.model.clone());
    let Some(model) = state.registry.get(&model_id) else {
        let available = state.registry.list().into_iter().map(|m| m.id.0).collect();
        return Err(ApiError::UnknownModel {
            model: request.model,
            available,
        });
    };
    let capabilities = model.info().capabilities;
    if !request.key_poses.is_empty() && !capabilities.key_poses {
        return Err(invalid(
            "key_poses",
            format!("model `{}` does not take key poses", request.model),
        ));
    }
    if request.seed_motion.is_some() && !capabilities.seed_motion {
        return Err(invalid(
            "seed_motion",
            format!("model `{}` does not take a seed motion", request.model),
        ));
    }
    if request.style.is_some() && !capabilities.style {
        return Err(invalid(
            "style",
            format!("model `{}` does not take a style", request.model),
        ));
    }
    if let Some(t) = request.temperature {
        if !capabilities.temperature {
            return Err(invalid(
                "temperature",
                format!(
                    "model `{}` does not sample with a temperature",
                    request.model
                ),
            ));
        }
        if !TEMPERATURE_RANGE.contains(&t) {
            return Err(invalid("temperature", "must be within 0.05..=5"));
        }
    }
    if let Some(k) = request.top_k {
        if !capabilities.top_k {
            return Err(invalid(
                "top_k",
                format!("model `{}` does not take top_k", request.model),
            ));
        }
        if !(1..=300).contains(&k) {
            return Err(invalid("top_k", "must be within 1..=300"));
        }
    }
    let priority = request.priority.unwrap_or(0);
    if !PRIORITY_RANGE.contains(&priority) {
        return Err(invalid("priority", "must be within -100..=100"));
    }
    let webhook_url = match request.webhook_url.take() {
        Some(url) => Some(
            crate::webhooks::accept_url(&state.config, &url)
                .await
                .map_err(|e| match e {
                    crate::webhooks::Submission::NotConfigured => ApiError::WebhooksNotConfigured,
                    crate::webhooks::Submission::Refused(why) => {
                        ApiError::WebhookUrlRefused(why.to_string())
                    }
                })?,
        ),
        None => None,
    };
    let (key_poses, seed_motion) = motion_inputs(
        std::mem::take(&mut request.key_poses),
        request.seed_motion.take(),
        song.duration_s,
    )
    .await?;
    let seed = request.seed.unwrap_or_else(rand::random);
    let job = NewJob {
        tenant: caller.tenant,
        kind: JobKind::Generate(GenerateOptions {
            song_id: request.song_id,
            model: model_id,
            seed,
            key_poses,
            seed_motion,
            plant_feet: request.plant_feet.unwrap_or(true),
            style: request.style,
            temperature: request.temperature,
            top_k: request.top_k,
            webhook_url,
        }),
        priority,
        max_attempts: state.config.max_attempts,
        idempotency,
    };
    // The tenant's limits are checked in the transaction that inserts the job.
    let registered = state.store.register_within(job, caller.limits).await?;
    let replayed = matches!(registered, Registered::Existing(_));
    if !replayed {
        state.wake.notify_waiters();
    }
    let job = match registered {
        Registered::Created(job) | Registered::Existing(job) => job,
    };
    let mut response = (StatusCode::ACCEPTED, Json(JobView::from(job))).into_response();
    if replayed {
        response
            .headers_mut()
            .insert(IDEMPOTENT_REPLAYED, HeaderValue::from_static("true"));
    }
    Ok(response)
}

pub(super) fn parse_job_id(id: &str) -> Result<JobId, ApiError> {
    JobId::from_str(id).map_err(|_| ApiError::JobNotFound(format!("{id:?} is not a job id")))
}

/// A job's status, stage and progress.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}",
    operation_id = "getJob",
    tag = "jobs",
    params(("id" = String, Path, description = "Job id")),
    responses(
        (status = 200, description = "The job", body = JobView),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn get(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<JobView>, ApiError> {
    let job = state.store.job(caller.scope(), parse_job_id(&id)?).await?;
    Ok(Json(job.into()))
}

/// Jobs, newest first, filtered by status and model, a page at a time.
#[utoipa::path(
    get,
    path = "/v1/jobs",
    operation_id = "listJobs",
    tag = "jobs",
    params(ListQuery),
    responses(
        (status = 200, description = "A page of jobs", body = JobPage),
        (status = 400, description = "Bad query parameter", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad filter value", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn list(
    State(state): State<AppState>,
    caller: Caller,
    ApiQuery(query): ApiQuery<ListQuery>,
) -> Result<Json<JobPage>, ApiError> {
    let status = query
        .status
        .as_deref()
        .map(Status::from_str)
        .transpose()
        .map_err(|e| invalid("status", e.to_string()))?;
    let page = PageRequest::<JobId>::parse(query.limit, query.cursor.as_deref())?;
    let jobs = state
        .store
        .jobs(
            caller.scope(),
            JobFilter {
                status,
                model: query.model,
                before: page.before,
                limit: page.fetch(),
            },
        )
        .await?;
    let (jobs, next_cursor) = page.page(jobs, |j| j.id.to_string());
    Ok(Json(JobPage {
        items: jobs.into_iter().map(JobView::from).collect(),
        next_cursor,
    }))
}

/// Cancel a job that has not finished, or delete one that has.
///
/// A queued job is cancelled at once, a running one at its next progress checkpoint (202, the
/// job). A finished job (succeeded, failed or cancelled) is deleted: its result files and its row
/// (204); afterwards its id is 404, and `job_events` keeps a `deleted` line. So a second DELETE
/// of a job the first one cancelled while queued deletes it.
#[utoipa::path(
    delete,
    path = "/v1/jobs/{id}",
    operation_id = "cancelJob",
    tag = "jobs",
    params(("id" = String, Path, description = "Job id")),
    responses(
        (status = 202, description = "The job had not finished: cancelled, or cancellation requested (status running, cancel_requested true)", body = JobView),
        (status = 204, description = "The job had finished: its results and its row are deleted"),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The database or the artifact store is unreachable; nothing was deleted, send it again shortly", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn cancel_or_delete(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let id = parse_job_id(&id)?;
    let job = state.store.job(caller.scope(), id).await?;
    if !job.status.is_terminal() {
        // Finished in between, it is shown as it is: its status says so.
        let job = state.store.cancel(caller.scope(), id).await?;
        return Ok((StatusCode::ACCEPTED, Json(JobView::from(job))).into_response());
    }
    // A finished job's files never change: removed first, a failure leaves the job as it was
    // (its DELETE can be sent again) rather than files no row names.
    state
        .artifacts
        .remove_results(id)
        .await
        .map_err(|e| ApiError::artifact(&format!("deleting the results of job {id}"), &e))?;
    let reason = format!("deleted by its owner (DELETE /v1/jobs/{id})");
    state.store.delete_job(caller.scope(), id, &reason).await?;
    tracing::info!(job_id = %id, "job deleted");
    Ok(StatusCode::NO_CONTENT.into_response())
}

/// Records a download of a job's result, which restarts its retention; a failure only logs.
pub(super) async fn record_use(state: &AppState, id: JobId) {
    if let Err(e) = state.store.touch_job(id).await {
        tracing::warn!(job_id = %id, error = %e, "could not record a use of the job's results");
    }
}

fn content_type(file: &str) -> &'static str {
    match file.rsplit('.').next() {
        Some("json") => "application/json",
        Some("glb") => "model/gltf-binary",
        Some("png") => "image/png",
        _ => "text/plain; charset=utf-8",
    }
}

/// A result file of a succeeded generate job.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/{file}",
    operation_id = "getJobFile",
    tag = "jobs",
    params(
        ("id" = String, Path, description = "Job id"),
        ("file" = String, Path, description = "motion.bvh, motion.json, motion.glb, report.json or preview.png"),
        ("Range" = Option<String>, Header, description = "One byte range, e.g. `bytes=0-1023` or `bytes=-500`; without it, or with several, the whole file"),
    ),
    responses(
        (status = 200, description = "The file"),
        (status = 206, description = "The bytes the Range asked for; `Content-Range` says which"),
        (status = 404, description = "No such job or file", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job has not succeeded (yet); the body gives its status", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "The Range selects no byte of the file (`range-not-satisfiable`)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn result(
    State(state): State<AppState>,
    caller: Caller,
    Path((id, file)): Path<(String, String)>,
    request: HeaderMap,
) -> Result<Response, ApiError> {
    let Some(name) = RESULT_FILES.iter().find(|f| **f == file) else {
        return Err(ApiError::ResultNotFound(format!(
            "no result named {file:?}; jobs have {}",
            RESULT_FILES.join(", ")
        )));
    };
    let job = state.store.job(caller.scope(), parse_job_id(&id)?).await?;
    if let JobKind::Analyze { song_id } = job.kind {
        return Err(ApiError::ResultNotFound(format!(
            "analyze jobs write no files; the analysis is on /v1/songs/{song_id}"
        )));
    }
    if job.status != Status::Succeeded {
        return Err(ApiError::JobNotFinished {
            id: job.id,
            status: job.status,
        });
    }
    if !job.files.files.iter().any(|f| f == name) {
        return Err(ApiError::ResultNotFound(format!(
            "job {} did not write {name}",
            job.id
        )));
    }
    let file = state
        .artifacts
        .stream(crate::artifacts::Artifact::Result(job.id, name))
        .await
        .map_err(|e| ApiError::artifact(&format!("reading {name} of job {}", job.id), &e))?;
    let span = super::ranges::Span::of(&request, file.len)?;
    record_use(&state, job.id).await;
    // Streamed with backpressure: a client that stops reading holds one chunk, not the file.
    let body = match &span {
        super::ranges::Span::Whole => Body::from_stream(file.body),
        super::ranges::Span::Part(r) => {
            Body::from_stream(super::ranges::slice(file.body, r.clone()))
        }
    };
    let headers = [(
        header::CONTENT_TYPE,
        HeaderValue::from_static(content_type(name)),
    )];
    Ok(super::ranges::respond(&span, file.len, body, headers))
}

/// The bytes of a PNG image.
// For the OpenAPI document only: a bare `Vec<u8>` would read there as an array of integers.
#[derive(utoipa::ToSchema)]
#[schema(value_type = String, format = Binary)]
pub struct Png(pub Vec<u8>);

/// A succeeded generate job's contact sheet.
///
/// One PNG to judge the dance at a glance: stick figures at about a dozen instants (front and
/// side), drawn to one scale over the floor line (y = 0) so a floating or sinking dancer shows;
/// mean joint speed over time with the music's beats and the key-pose times marked; the lowest
/// foot's height over time against the floor; a title with model, seed, song and mean speed.
#[utoipa::path(
    get,
    path = "/v1/jobs/{id}/preview.png",
    operation_id = "getJobPreview",
    tag = "jobs",
    params(
        ("id" = String, Path, description = "Job id"),
        ("Range" = Option<String>, Header, description = "One byte range; without it, the whole file"),
    ),
    responses(
        (status = 200, description = "The contact sheet", content_type = "image/png", body = inline(Png)),
        (status = 206, description = "The bytes the Range asked for", content_type = "image/png", body = inline(Png)),
        (status = 404, description = "No such job, or a job from before previews", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The job has not succeeded (yet); the body gives its status", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "The Range selects no byte of the file (`range-not-satisfiable`)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn preview(
    state: State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    request: HeaderMap,
) -> Result<Response, ApiError> {
    result(
        state,
        caller,
        Path((id, crate::report::preview::PREVIEW_FILE.to_string())),
        request,
    )
    .await
}
