//! `POST /v1/songs`, `GET /v1/songs`, `GET /v1/songs/{id}` and `DELETE /v1/songs/{id}`; the
//! song's audio is served by [`super::song_audio`].
//!
//! An upload streams to a temp file inside the data dir while its size is checked and its
//! sha256 computed; it is decoded with symphonia (the format comes from decoding, never the
//! name), renamed into place under its id, and an analyze job is queued in the same transaction
//! that records the song.
use super::auth::Caller;
use super::extract::ApiQuery;
use super::multipart::{self, Form};
use super::paging::PageRequest;
use super::problem::{ApiError, Problem};
use super::AppState;
use crate::artifacts::Artifact;
use crate::audio::{self, Analysis, AudioError, AudioFormat, Budget, DecodeOptions, Keep};
use crate::queue::{JobKind, NewJob, Song, SongFilter, SongId, Status};
use axum::extract::{Path, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::Json;
use axum::RequestExt;
use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::str::FromStr;
use std::time::Duration;
use tokio::io::AsyncWriteExt;

/// How much shorter than its header declares a decoded file may be before it counts as cut
/// short (encoder delay and padding account for a few tens of milliseconds).
const TRUNCATION_TOLERANCE_S: f64 = 0.5;
/// Longest accepted upload file name, in bytes.
const MAX_FILENAME_BYTES: usize = 255;

/// A song and, once its analyze job is done, its analysis.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct SongView {
    pub id: SongId,
    /// The upload's file name, for display.
    pub filename: String,
    /// Found by decoding.
    pub format: AudioFormat,
    pub duration_s: f64,
    /// Native sample rate, Hz.
    pub sample_rate: u32,
    pub channels: u16,
    pub sha256: String,
    pub size_bytes: u64,
    pub created_at: DateTime<Utc>,
    /// Status of the song's analyze job.
    pub analysis_status: Option<Status>,
    /// Why the analysis failed, if it did.
    pub analysis_error: Option<String>,
    /// Tempo, beats and downbeats (seconds), once the analyze job has succeeded.
    pub analysis: Option<Analysis>,
}

/// A page of songs.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct SongPage {
    pub items: Vec<SongView>,
    /// Pass as `cursor` for the next page; absent on the last page.
    pub next_cursor: Option<String>,
}

/// The page of `GET /v1/songs`.
#[derive(Debug, Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct SongListQuery {
    /// 1..=100, default 20.
    #[param(minimum = 1, maximum = 100, default = 20)]
    pub limit: Option<u32>,
    /// `next_cursor` of the previous page (a song id).
    #[param(format = Uuid)]
    pub cursor: Option<String>,
}

/// The multipart form of an upload: one field, `file` (any other is refused with 400).
#[derive(utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[allow(dead_code)]
pub struct UploadForm {
    /// The song: mp3, wav, flac, ogg/vorbis or m4a/aac.
    #[schema(value_type = String, format = Binary, min_length = 1)]
    file: Vec<u8>,
}

async fn view(state: &AppState, song: Song) -> Result<SongView, ApiError> {
    let job = state.store.analyze_job(song.id).await?;
    Ok(SongView {
        id: song.id,
        filename: song.filename,
        format: song.format,
        duration_s: song.duration_s,
        sample_rate: song.sample_rate,
        channels: song.channels,
        sha256: song.sha256,
        size_bytes: song.size_bytes,
        created_at: song.created_at,
        analysis_status: job.as_ref().map(|j| j.status),
        analysis_error: job.and_then(|j| j.error),
        analysis: song.analysis,
    })
}

/// Accepts a plain file name; anything that could name a path is refused.
fn check_filename(name: Option<&str>) -> Result<String, ApiError> {
    let Some(name) = name else {
        return Ok("upload".into());
    };
    let bad = name.is_empty()
        || name.len() > MAX_FILENAME_BYTES
        || name == "."
        || name == ".."
        || name.contains(['/', '\\'])
        || name.contains("..")
        || name.chars().any(char::is_control);
    if bad {
        Err(ApiError::InvalidFilename(name.chars().take(80).collect()))
    } else {
        Ok(name.to_string())
    }
}

/// An upload streamed to disk.
pub(super) struct Received {
    pub(super) file: tempfile::NamedTempFile,
    pub(super) filename: String,
    pub(super) size: u64,
    pub(super) sha256: String,
}

pub(super) async fn receive(
    state: &AppState,
    mut field: multer::Field<'static>,
) -> Result<Received, ApiError> {
    let filename = check_filename(field.file_name())?;
    let limit = state.config.max_upload_bytes;
    let tmp = state
        .data
        .temp_file()
        .map_err(|e| ApiError::storage("creating the upload's temp file", &e))?;
    let std_file = tmp
        .as_file()
        .try_clone()
        .map_err(|e| ApiError::storage("opening the upload's temp file", &e))?;
    let mut out = tokio::fs::File::from_std(std_file);
    let mut hasher = Sha256::new();
    let mut size: u64 = 0;
    loop {
        let chunk = match field.chunk().await {
            Ok(Some(chunk)) => chunk,
            Ok(None) => break,
            Err(e) => return Err(multipart::error(&e, &state.config)),
        };
        size += chunk.len() as u64;
        if size > limit {
            return Err(ApiError::FileTooLarge { limit });
        }
        hasher.update(&chunk);
        out.write_all(&chunk)
            .await
            .map_err(|e| ApiError::storage("writing the upload", &e))?;
    }
    out.flush()
        .await
        .map_err(|e| ApiError::storage("writing the upload", &e))?;
    out.sync_all()
        .await
        .map_err(|e| ApiError::storage("writing the upload", &e))?;
    if size == 0 {
        return Err(ApiError::EmptyFile);
    }
    Ok(Received {
        file: tmp,
        filename,
        size,
        sha256: hex::encode(hasher.finalize()),
    })
}

/// Reads the form to its end: the one `file` field streamed to disk, or `None` if there was none.
///
/// When the form is refused part-way (too large, a wrong field), the rest of the body is read and
/// dropped, within [`DRAIN_LIMIT_BYTES`] and [`DRAIN_TIMEOUT`], so the client gets the error
/// response on a connection it can keep using. A client still sending when the server answers
/// and closes would otherwise see a broken pipe instead of the answer.
async fn read_form(state: &AppState, request: Request) -> Result<Option<Received>, UploadError> {
    let (parts, body) = request.with_limited_body().into_parts();
    let mut multipart = multipart::form(&parts.headers, body, state.config.max_part_header_bytes)
        .map_err(UploadError::before_body_end)?;
    match read_fields(state, &mut multipart).await {
        Ok(received) => Ok(received),
        Err(error) => {
            let drained = drain(&mut multipart).await;
            Err(UploadError {
                error,
                body_unread: !drained,
            })
        }
    }
}

async fn read_fields(state: &AppState, multipart: &mut Form) -> Result<Option<Received>, ApiError> {
    let mut received = None;
    loop {
        let field = match multipart.next_field().await {
            Ok(Some(field)) => field,
            Ok(None) => return Ok(received),
            Err(e) => return Err(multipart::error(&e, &state.config)),
        };
        match field.name() {
            Some("file") if received.is_none() => received = Some(receive(state, field).await?),
            Some("file") => return Err(ApiError::UnexpectedField("file (a second one)".into())),
            Some(other) => return Err(ApiError::UnexpectedField(other.chars().take(80).collect())),
            None => return Err(ApiError::UnexpectedField("(unnamed)".into())),
        }
    }
}

/// The most bytes of a refused upload read past the point of refusal before giving up on it.
pub const DRAIN_LIMIT_BYTES: u64 = 16 * 1024 * 1024;
/// The longest a refused upload is read for.
const DRAIN_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// Reads and drops the rest of a multipart body; true when it ended within the limits.
pub(super) async fn drain(multipart: &mut Form) -> bool {
    let work = async {
        let mut budget = DRAIN_LIMIT_BYTES;
        loop {
            // multer skips what is left of an unfinished field when asked for the next one; the
            // body limit (the upload limit plus DRAIN_LIMIT_BYTES) bounds that skip.
            let mut field = match multipart.next_field().await {
                Ok(Some(field)) => field,
                Ok(None) => return true,
                Err(_) => return false,
            };
            loop {
                match field.chunk().await {
                    Ok(Some(chunk)) if (chunk.len() as u64) <= budget => {
                        budget -= chunk.len() as u64
                    }
                    Ok(Some(_)) | Err(_) => return false,
                    Ok(None) => break,
                }
            }
        }
    };
    tokio::time::timeout(DRAIN_TIMEOUT, work)
        .await
        .unwrap_or(false)
}

/// An upload's error response.
///
/// One whose body could not be read to its end says `Connection: close`: hyper drops such a
/// connection after the response, and a keep-alive client must not send its next request into it.
#[derive(Debug)]
pub struct UploadError {
    pub(super) error: ApiError,
    pub(super) body_unread: bool,
}

impl UploadError {
    pub(super) fn before_body_end(error: ApiError) -> Self {
        Self {
            error,
            body_unread: true,
        }
    }
}

impl From<ApiError> for UploadError {
    fn from(error: ApiError) -> Self {
        Self {
            error,
            body_unread: false,
        }
    }
}

impl axum::response::IntoResponse for UploadError {
    fn into_response(self) -> axum::response::Response {
        let mut response = self.error.into_response();
        if self.body_unread {
            response
                .headers_mut()
                .insert(header::CONNECTION, HeaderValue::from_static("close"));
        }
        response
    }
}

/// Upload a song.
///
/// The same bytes uploaded again return the existing song (200). A new song (201) gets an
/// analyze job; its analysis appears on `GET /v1/songs/{id}` when that job is done.
#[utoipa::path(
    post,
    path = "/v1/songs",
    operation_id = "uploadSong",
    tag = "songs",
    request_body(content = UploadForm, content_type = "multipart/form-data"),
    responses(
        (status = 201, description = "Song stored; analysis queued", body = SongView),
        (status = 200, description = "These bytes were uploaded before", body = SongView),
        (status = 400, description = "Empty file, wrong field, bad file name or bad multipart", body = Problem, content_type = "application/problem+json"),
        (status = 408, description = "The body stalled for more than body_timeout_s", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Over the size limit (code file-too-large), or past the key's storage quota (code storage-quota-exceeded: delete songs or results to make room)", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Not audio, or not decodable", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Over the duration limit, cut short, an unsupported sample rate, or a decode past audio_timeout_s", body = Problem, content_type = "application/problem+json"),
        (status = 431, description = "A part's headers are longer than max_part_header_bytes", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The server is shutting down, or its database is unreachable; send the upload again when it is back", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The server is out of storage; nothing was stored", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn upload(
    State(state): State<AppState>,
    caller: Caller,
    request: Request,
) -> Result<(StatusCode, HeaderMap, Json<SongView>), UploadError> {
    let received = read_form(&state, request).await?;
    let received = received.ok_or(ApiError::MissingFile)?;

    if let Some(existing) = state
        .store
        .song_by_sha256(caller.tenant, &received.sha256)
        .await
        .map_err(ApiError::from)?
    {
        record_use(&state, existing.id).await;
        return Ok((
            StatusCode::OK,
            location(existing.id),
            Json(view(&state, existing).await?),
        ));
    }
    // An early refusal that saves the decode; the store's check, in the transaction that
    // inserts the song, is the one that holds against uploads racing each other.
    super::tenancy::check_storage(&state, &caller, received.size).await?;

    // Decode fully: that is the only proof the bytes are audio we can use. No samples are kept,
    // the header's length and rate are checked before decoding, and the decode stops at the
    // duration limit, the time budget or a server shutdown. Bounded in parallel as well.
    let decoded = {
        let _permit = state
            .decode_permits
            .acquire()
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))?;
        let path = received.file.path().to_path_buf();
        let (max_duration_s, timeout) = (
            state.config.max_duration_s,
            Duration::from_secs_f64(state.config.audio_timeout_s),
        );
        let shutdown = state.shutdown.clone();
        tokio::task::spawn_blocking(move || {
            let stop = || shutdown.is_cancelled();
            let budget = Budget::new(Some(timeout), Some(&stop));
            audio::decode_file(
                &path,
                &DecodeOptions {
                    keep: Keep::Nothing,
                    max_duration_s,
                    budget: &budget,
                },
            )
        })
        .await
        .map_err(|e| ApiError::Internal(format!("decoder thread: {e}")))?
        .map_err(|e| match e {
            // The configured limit is the API's own error, with the same code as ever.
            AudioError::TooLong { seconds, limit } => ApiError::SongTooLong { seconds, limit },
            other => ApiError::Audio(other),
        })?
    };
    if let Some(declared_s) = decoded.declared_s {
        if decoded.audio.duration_s + TRUNCATION_TOLERANCE_S < declared_s {
            return Err(ApiError::Truncated {
                declared_s,
                decoded_s: decoded.audio.duration_s,
            }
            .into());
        }
    }
    let decoded = decoded.audio;

    let id = SongId::new();
    let path = state.data.song_path(id, decoded.format);
    received
        .file
        .persist(&path)
        .map_err(|e| ApiError::storage("storing the song", &e.error))?;
    // Published before its analyze job exists, so any worker that claims the job finds it.
    let artifact = Artifact::Song(id, decoded.format);
    if let Err(e) = state.artifacts.publish(artifact).await {
        forget(&state, artifact).await;
        return Err(ApiError::artifact("storing the song", &e).into());
    }
    let song = Song {
        id,
        tenant: caller.tenant,
        filename: received.filename,
        format: decoded.format,
        duration_s: decoded.duration_s,
        sample_rate: decoded.sample_rate,
        channels: decoded.channels,
        sha256: received.sha256,
        size_bytes: received.size,
        analysis: None,
        created_at: Utc::now(),
    };
    let analyze = NewJob {
        tenant: caller.tenant,
        kind: JobKind::Analyze { song_id: id },
        priority: ANALYZE_PRIORITY,
        max_attempts: state.config.max_attempts,
        idempotency: None,
    };
    let (stored, created) = match state
        .store
        .add_song_within(song, analyze, caller.limits)
        .await
    {
        Ok(added) => added,
        Err(e) => {
            // No row names the file: remove it now rather than leave it to the start-up sweep.
            forget(&state, artifact).await;
            return Err(ApiError::from(e).into());
        }
    };
    if !created {
        // Another upload of the same bytes won the race; keep its file, drop ours.
        if let Err(e) = state.artifacts.remove(artifact).await {
            tracing::warn!(error = %e, "could not remove a duplicate upload");
        }
        record_use(&state, stored.id).await;
        return Ok((
            StatusCode::OK,
            location(stored.id),
            Json(view(&state, stored).await?),
        ));
    }
    state.wake.notify_waiters();
    tracing::info!(song_id = %stored.id, format = ?stored.format, duration_s = stored.duration_s, "song stored");
    Ok((
        StatusCode::CREATED,
        location(stored.id),
        Json(view(&state, stored).await?),
    ))
}

/// Removes a stored song whose row was never written.
async fn forget(state: &AppState, artifact: Artifact<'_>) {
    if let Err(e) = state.artifacts.remove(artifact).await {
        tracing::warn!(error = %e, "could not remove a song file whose row was not written; the start-up sweep will");
    }
}

/// Records a use of the song, which restarts its retention; a failure only logs.
pub(super) async fn record_use(state: &AppState, id: SongId) {
    if let Err(e) = state.store.touch_song(id).await {
        tracing::warn!(song_id = %id, error = %e, "could not record a use of the song");
    }
}

/// Analysis is quick and everything else needs it, so it runs before dances.
const ANALYZE_PRIORITY: i64 = 10;

fn location(id: SongId) -> HeaderMap {
    let mut headers = HeaderMap::new();
    if let Ok(value) = HeaderValue::from_str(&format!("/v1/songs/{id}")) {
        headers.insert(header::LOCATION, value);
    }
    headers
}

/// A song, with its analysis once done.
#[utoipa::path(
    get,
    path = "/v1/songs/{id}",
    operation_id = "getSong",
    tag = "songs",
    params(("id" = String, Path, description = "Song id")),
    responses(
        (status = 200, description = "The song", body = SongView),
        (status = 404, description = "No such song", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn get(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<SongView>, ApiError> {
    let id = SongId::from_str(&id)
        .map_err(|_| ApiError::SongNotFound(format!("{id:?} (not a song id)")))?;
    let song = state.store.song(caller.scope(), id).await?;
    Ok(Json(view(&state, song).await?))
}

/// The caller's songs, newest first, a page at a time, each as `GET /v1/songs/{id}` shows it.
#[utoipa::path(
    get,
    path = "/v1/songs",
    operation_id = "listSongs",
    tag = "songs",
    params(SongListQuery),
    responses(
        (status = 200, description = "A page of songs", body = SongPage),
        (status = 400, description = "An unknown or malformed query parameter", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A limit outside 1..=100, or a cursor that is not a next_cursor", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn list(
    State(state): State<AppState>,
    caller: Caller,
    ApiQuery(query): ApiQuery<SongListQuery>,
) -> Result<Json<SongPage>, ApiError> {
    let page = PageRequest::<SongId>::parse(query.limit, query.cursor.as_deref())?;
    let filter = SongFilter {
        before: page.before,
        limit: page.fetch(),
    };
    let songs = state.store.songs(caller.scope(), filter).await?;
    let (songs, next_cursor) = page.page(songs, |s| s.id.to_string());
    let mut items = Vec::with_capacity(songs.len());
    for song in songs {
        items.push(view(&state, song).await?);
    }
    Ok(Json(SongPage { items, next_cursor }))
}

/// Delete a song, its analysis, and every job made from it with its results.
///
/// Jobs of the song that are queued are dropped, and running ones stop at their next progress
/// checkpoint, writing nothing more. Afterwards the song's id and its jobs' ids are 404, its file
/// and its jobs' files are gone (from the data dir and the bucket), and `job_events` keeps a
/// `deleted` line for each job.
#[utoipa::path(
    delete,
    path = "/v1/songs/{id}",
    operation_id = "deleteSong",
    tag = "songs",
    params(("id" = String, Path, description = "Song id")),
    responses(
        (status = 204, description = "The song, its analysis, its jobs and their results are deleted"),
        (status = 404, description = "No such song", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The database is unreachable; nothing was deleted, send it again shortly", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn delete(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let id = SongId::from_str(&id)
        .map_err(|_| ApiError::SongNotFound(format!("{id:?} (not a song id)")))?;
    // Rows first, so nothing is claimed, served or listed from them any more; a running job's
    // worker removes what it writes after this (`artifacts::retention::forget_if_deleted`).
    let reason = format!("deleted with its song {id} (DELETE /v1/songs/{id})");
    let removed = state.store.delete_song(caller.scope(), id, &reason).await?;
    if let Err(e) =
        crate::artifacts::retention::remove_files(state.artifacts.as_ref(), &removed).await
    {
        // No row names them now: the data dir's sweep removes what is left.
        tracing::warn!(song_id = %id, error = %e, "a deleted song's files could not all be removed");
    }
    tracing::info!(song_id = %id, jobs = removed.jobs.len(), "song deleted");
    Ok(StatusCode::NO_CONTENT)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_names_that_could_name_a_path_are_refused() {
        for bad in [
            "../x.mp3",
            "..",
            "a/b.mp3",
            "a\\b.mp3",
            "x\0.mp3",
            "..\\..\\evil.wav",
            "",
        ] {
            assert!(check_filename(Some(bad)).is_err(), "{bad:?}");
        }
        assert_eq!(
            check_filename(Some("My Song (live).mp3")).ok().as_deref(),
            Some("My Song (live).mp3")
        );
        assert_eq!(check_filename(None).ok().as_deref(), Some("upload"));
    }
}
