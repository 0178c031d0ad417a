//! `Range` on every download (RFC 9110 §14): a song's audio, a job's files and the dances
//! computed on request, so a player can seek and a broken download can resume.
//!
//! One byte range is answered `206 Partial Content` with `Content-Range`; a range that selects
//! no byte (it starts past the end) is `416 range-not-satisfiable` with
//! `Content-Range: bytes */<length>`. No `Range`, a malformed one, another unit, several ranges
//! (choreo does not build `multipart/byteranges` bodies) or an `If-Range` (choreo sends no
//! validator it could match) get the whole file, `200`, as §14.2 allows a server to answer.
//! Every download says `Accept-Ranges: bytes`. The header is parsed and checked against the
//! length by `http-range-header`, the parser tower-http's `ServeFile` uses: ServeFile itself
//! serves only local files, and results may stream from a bucket.
use super::problem::ApiError;
use axum::body::{Body, Bytes};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use futures::{Stream, StreamExt as _};
use http_range_header::RangeUnsatisfiableError;
use std::ops::RangeInclusive;

/// The part of a download a request asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Span {
    /// The whole file (`200`).
    Whole,
    /// These bytes, first and last included (`206`).
    Part(RangeInclusive<u64>),
}

impl Span {
    /// The span the request's `Range` (and `If-Range`) select of a `len`-byte file.
    pub fn of(request: &HeaderMap, len: u64) -> Result<Span, ApiError> {
        if request.contains_key(header::IF_RANGE) {
            return Ok(Span::Whole);
        }
        let Some(value) = request.get(header::RANGE).and_then(|v| v.to_str().ok()) else {
            return Ok(Span::Whole);
        };
        let Ok(parsed) = http_range_header::parse_range_header(value) else {
            // Malformed, or not in bytes: a server may ignore a Range it does not understand.
            return Ok(Span::Whole);
        };
        match parsed.validate(len) {
            Ok(ranges) => Ok(match ranges.as_slice() {
                [one] => Span::Part(one.clone()),
                // Several ranges, or none (an empty file): the whole file.
                _ => Span::Whole,
            }),
            Err(RangeUnsatisfiableError::Unsatisfiable) => Err(ApiError::RangeNotSatisfiable {
                range: value.to_string(),
                len,
            }),
            // Overlapping ranges and the like: refusing is allowed, the whole file is kinder.
            Err(_) => Ok(Span::Whole),
        }
    }

    /// How many bytes the answer carries.
    fn count(&self, len: u64) -> u64 {
        match self {
            Span::Whole => len,
            Span::Part(r) => r.end() - r.start() + 1,
        }
    }
}

/// The answer for `span` of a `len`-byte file whose body (already cut to the span) is `body`:
/// `206` with `Content-Range`, or `200`; `Accept-Ranges` and `Content-Length` either way, plus
/// `headers` (the content type, a file name).
pub fn respond(
    span: &Span,
    len: u64,
    body: Body,
    headers: impl IntoIterator<Item = (header::HeaderName, HeaderValue)>,
) -> Response {
    let mut response = body.into_response();
    let out = response.headers_mut();
    out.extend(headers);
    out.insert(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"));
    out.insert(header::CONTENT_LENGTH, HeaderValue::from(span.count(len)));
    if let Span::Part(r) = span {
        *response.status_mut() = StatusCode::PARTIAL_CONTENT;
        if let Ok(value) = HeaderValue::from_str(&format!("bytes {}-{}/{len}", r.start(), r.end()))
        {
            response.headers_mut().insert(header::CONTENT_RANGE, value);
        }
    }
    response
}

/// In-memory bytes (a dance computed on request), answered for the request's `Range`.
pub fn bytes(
    request: &HeaderMap,
    bytes: Vec<u8>,
    headers: impl IntoIterator<Item = (header::HeaderName, HeaderValue)>,
) -> Result<Response, ApiError> {
    let len = bytes.len() as u64;
    let span = Span::of(request, len)?;
    let body = match &span {
        Span::Whole => Body::from(bytes),
        // Within 0..len: `validate` clamps the end and refuses a start past it.
        Span::Part(r) => Body::from(bytes[*r.start() as usize..=*r.end() as usize].to_vec()),
    };
    Ok(respond(&span, len, body, headers))
}

/// The bytes of `range` out of a stream of the whole file: chunks before it are read and
/// dropped (results are a few MB; songs, the large files, are seeked instead), the stream is
/// left once past it.
pub fn slice<S>(
    body: S,
    range: RangeInclusive<u64>,
) -> impl Stream<Item = Result<Bytes, std::io::Error>> + Send
where
    S: Stream<Item = Result<Bytes, std::io::Error>> + Send,
{
    let (start, end) = (*range.start(), range.end() + 1);
    body.scan(0u64, move |at, chunk| {
        if *at >= end {
            return std::future::ready(None);
        }
        let cut = chunk.map(|bytes| {
            let from = *at;
            let to = from + bytes.len() as u64;
            *at = to;
            let lo = start.clamp(from, to) - from;
            let hi = end.clamp(from, to) - from;
            bytes.slice(lo as usize..hi as usize)
        });
        std::future::ready(Some(cut))
    })
    .filter(|chunk| std::future::ready(!matches!(chunk, Ok(b) if b.is_empty())))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asking(range: &str) -> HeaderMap {
        let mut headers = HeaderMap::new();
        headers.insert(header::RANGE, HeaderValue::from_str(range).expect("ascii"));
        headers
    }

    #[test]
    fn one_range_is_a_part_and_the_rest_the_whole_file() {
        let span = |range: &str| Span::of(&asking(range), 1000).ok();
        assert_eq!(span("bytes=100-199"), Some(Span::Part(100..=199)));
        assert_eq!(span("bytes=-50"), Some(Span::Part(950..=999)));
        assert_eq!(span("bytes=990-2000"), Some(Span::Part(990..=999)));
        assert_eq!(span("bytes=0-1,5-6"), Some(Span::Whole));
        assert_eq!(span("items=0-1"), Some(Span::Whole));
        assert_eq!(span("bytes=oops"), Some(Span::Whole));
        assert!(matches!(
            Span::of(&asking("bytes=1000-"), 1000),
            Err(ApiError::RangeNotSatisfiable { len: 1000, .. })
        ));
        let mut conditional = asking("bytes=0-1");
        conditional.insert(header::IF_RANGE, HeaderValue::from_static("\"x\""));
        assert_eq!(Span::of(&conditional, 1000).ok(), Some(Span::Whole));
    }

    #[tokio::test]
    async fn a_slice_of_a_chunked_stream_is_the_slice_of_its_bytes() {
        let whole: Vec<u8> = (0..=255).collect();
        for (chunk, range) in [(7, 10..=99u64), (64, 0..=255), (1, 255..=255), (100, 3..=3)] {
            let chunks: Vec<Result<Bytes, std::io::Error>> = whole
                .chunks(chunk)
                .map(|c| Ok(Bytes::copy_from_slice(c)))
                .collect();
            let got: Vec<u8> = slice(futures::stream::iter(chunks), range.clone())
                .map(|c| c.expect("ok").to_vec())
                .concat()
                .await;
            let want = &whole[*range.start() as usize..=*range.end() as usize];
            assert_eq!(got, want, "chunks of {chunk}, {range:?}");
        }
    }
}
