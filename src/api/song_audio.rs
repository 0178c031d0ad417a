//! `GET /v1/songs/{id}/audio`: a song's bytes as uploaded, whole or in part (`Range`).
use super::auth::Caller;
use super::problem::{ApiError, Problem};
use super::ranges;
use super::songs::record_use;
use super::AppState;
use crate::artifacts::Artifact;
use crate::audio::AudioFormat;
use crate::queue::SongId;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, HeaderValue};
use std::str::FromStr;

/// The MIME type an uploaded song is served with, from the format its decode found.
fn audio_mime(format: AudioFormat) -> &'static str {
    match format {
        AudioFormat::Mp3 => "audio/mpeg",
        AudioFormat::Wav => "audio/wav",
        AudioFormat::Flac => "audio/flac",
        AudioFormat::Ogg => "audio/ogg",
        AudioFormat::M4a => "audio/mp4",
    }
}

/// The bytes of an uploaded song.
// For the OpenAPI document only: a bare `Vec<u8>` would read there as an array of integers.
#[derive(utoipa::ToSchema)]
#[schema(value_type = String, format = Binary)]
pub struct AudioBytes(pub Vec<u8>);

/// The song's audio, byte for byte as it was uploaded.
///
/// For clients that play the song beside its dance (the page at `/` does): the content type
/// follows the format found by decoding (`format` on the song). A `Range` of one byte range is
/// answered `206` with those bytes, so a player can seek.
#[utoipa::path(
    get,
    path = "/v1/songs/{id}/audio",
    operation_id = "getSongAudio",
    tag = "songs",
    params(
        ("id" = String, Path, description = "Song id"),
        ("Range" = Option<String>, Header, description = "One byte range, e.g. `bytes=0-1023` or `bytes=-500` (the last 500 bytes); without it, or with several, the whole file"),
    ),
    responses(
        (status = 200, description = "The uploaded file", content(
            (inline(AudioBytes) = "audio/mpeg"),
            (inline(AudioBytes) = "audio/wav"),
            (inline(AudioBytes) = "audio/flac"),
            (inline(AudioBytes) = "audio/ogg"),
            (inline(AudioBytes) = "audio/mp4"),
        )),
        (status = 206, description = "The bytes the Range asked for; `Content-Range` says which", content(
            (inline(AudioBytes) = "audio/mpeg"),
            (inline(AudioBytes) = "audio/wav"),
            (inline(AudioBytes) = "audio/flac"),
            (inline(AudioBytes) = "audio/ogg"),
            (inline(AudioBytes) = "audio/mp4"),
        )),
        (status = 404, description = "No such song", body = Problem, content_type = "application/problem+json"),
        (status = 416, description = "The Range selects no byte of the file (`range-not-satisfiable`); `Content-Range: bytes */<length>`", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = []))
)]
pub async fn audio(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    request: HeaderMap,
) -> Result<axum::response::Response, ApiError> {
    use tokio::io::{AsyncReadExt as _, AsyncSeekExt as _};
    let id = SongId::from_str(&id)
        .map_err(|_| ApiError::SongNotFound(format!("{id:?} (not a song id)")))?;
    let song = state.store.song(caller.scope(), id).await?;
    // Through the artifact store: with a bucket, another API host may have taken the upload; it
    // is cached in this host's data dir, then streamed from there.
    let path = state
        .artifacts
        .fetch(Artifact::Song(song.id, song.format))
        .await
        .map_err(|e| ApiError::artifact(&format!("fetching song {}", song.id), &e))?;
    let opening = format!("opening song {}", song.id);
    let mut file = tokio::fs::File::open(&path)
        .await
        .map_err(|e| ApiError::storage(&opening, &e))?;
    let len = file
        .metadata()
        .await
        .map_err(|e| ApiError::storage(&opening, &e))?
        .len();
    let span = ranges::Span::of(&request, len)?;
    record_use(&state, song.id).await;
    // A song may be up to max_upload_bytes: a part is seeked to, not read up to.
    let part = match &span {
        ranges::Span::Whole => len,
        ranges::Span::Part(r) => {
            file.seek(std::io::SeekFrom::Start(*r.start()))
                .await
                .map_err(|e| ApiError::storage(&opening, &e))?;
            r.end() - r.start() + 1
        }
    };
    // Streamed with backpressure.
    let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::with_capacity(
        file.take(part),
        crate::artifacts::STREAM_CHUNK_BYTES,
    ));
    let headers = [(
        header::CONTENT_TYPE,
        HeaderValue::from_static(audio_mime(song.format)),
    )];
    Ok(ranges::respond(&span, len, body, headers))
}
