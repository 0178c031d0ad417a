//! An upload's multipart body, read with multer, with every part's header block capped.
//!
//! multer keeps a part's header block in memory until the blank line that ends it, bounded only
//! by the whole body's limit, so one 60 MB part header cost 60 MB per connection.
//! [`PartHeaderGuard`] watches the body on its way into multer: it finds each boundary, counts
//! the bytes from there to the end of that part's header block (and the preamble before the
//! first boundary), and fails the body as soon as one passes `max_part_header_bytes`. The parts'
//! data passes through untouched; field and file names live in the header block, so they are
//! capped too.
use super::problem::ApiError;
use axum::body::Body;
use axum::http::{header, HeaderMap};
use bytes::Bytes;
use futures::{Stream, StreamExt};
use std::pin::Pin;
use std::task::{Context, Poll};

type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// A boundary longer than this is refused (RFC 2046 allows 70 characters).
const MAX_BOUNDARY_BYTES: usize = 200;

/// A part's header block (or the preamble) ran past the limit.
#[derive(Debug, thiserror::Error)]
#[error("a multipart part's headers are longer than {limit} bytes")]
pub struct PartHeaderTooLarge {
    pub limit: usize,
}

/// KMP prefix table of `pattern`.
fn prefix_table(pattern: &[u8]) -> Vec<usize> {
    let mut table = vec![0; pattern.len()];
    let mut k = 0;
    for i in 1..pattern.len() {
        while k > 0 && pattern[i] != pattern[k] {
            k = table[k - 1];
        }
        if pattern[i] == pattern[k] {
            k += 1;
        }
        table[i] = k;
    }
    table
}

/// One KMP step: how much of `pattern` is matched after `byte`, given `matched` before it.
fn advance(pattern: &[u8], table: &[usize], mut matched: usize, byte: u8) -> usize {
    while matched > 0 && (matched == pattern.len() || pattern[matched] != byte) {
        matched = table[matched - 1];
    }
    if pattern[matched] == byte {
        matched + 1
    } else {
        0
    }
}

const BLANK_LINE: &[u8] = b"\r\n\r\n";

/// Counts header bytes of a multipart body as it streams (see the module doc).
#[derive(Debug)]
struct Scanner {
    /// `\r\n--boundary`: what starts every part.
    delimiter: Vec<u8>,
    delimiter_table: Vec<usize>,
    blank_table: Vec<usize>,
    matched: usize,
    /// Bytes of the header block being read, while one is.
    headers: Option<usize>,
    blank: usize,
    /// Bytes before the first boundary, until it is found.
    preamble: Option<usize>,
    limit: usize,
}

impl Scanner {
    fn new(boundary: &str, limit: usize) -> Self {
        let delimiter = [b"\r\n--".as_slice(), boundary.as_bytes()].concat();
        Self {
            delimiter_table: prefix_table(&delimiter),
            delimiter,
            blank_table: prefix_table(BLANK_LINE),
            // The body may open with `--boundary`, without the line break before it.
            matched: 2,
            headers: None,
            blank: 0,
            preamble: Some(0),
            limit,
        }
    }

    /// Scans `chunk`; false when a header block or the preamble is past the limit.
    fn scan(&mut self, chunk: &[u8]) -> bool {
        let mut i = 0;
        while i < chunk.len() {
            if let Some(n) = self.headers.as_mut() {
                *n += 1;
                self.blank = advance(BLANK_LINE, &self.blank_table, self.blank, chunk[i]);
                if self.blank == BLANK_LINE.len() {
                    self.headers = None;
                    self.matched = 0;
                } else if *n > self.limit {
                    return false;
                }
                i += 1;
                continue;
            }
            if self.matched == 0 {
                // Part data: jump to the next possible delimiter start.
                match chunk[i..].iter().position(|&b| b == b'\r') {
                    Some(skip) => {
                        self.count_preamble(skip);
                        i += skip;
                    }
                    None => return self.count_preamble(chunk.len() - i),
                }
            }
            self.matched = advance(
                &self.delimiter,
                &self.delimiter_table,
                self.matched,
                chunk[i],
            );
            if !self.count_preamble(1) {
                return false;
            }
            if self.matched == self.delimiter.len() {
                self.preamble = None;
                self.headers = Some(0);
                self.blank = 0;
            }
            i += 1;
        }
        true
    }

    fn count_preamble(&mut self, bytes: usize) -> bool {
        match self.preamble.as_mut() {
            Some(n) => {
                *n += bytes;
                *n <= self.limit + self.delimiter.len()
            }
            None => true,
        }
    }
}

/// A body stream that fails once a part header passes the limit.
pub struct PartHeaderGuard<S> {
    inner: S,
    scanner: Scanner,
    failed: bool,
}

impl<S, E> Stream for PartHeaderGuard<S>
where
    S: Stream<Item = Result<Bytes, E>> + Unpin,
    E: Into<BoxError>,
{
    type Item = Result<Bytes, BoxError>;

    fn poll_next(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Self::Item>> {
        if self.failed {
            return Poll::Ready(None);
        }
        match self.inner.poll_next_unpin(cx) {
            Poll::Ready(Some(Ok(chunk))) => {
                if self.scanner.scan(&chunk) {
                    Poll::Ready(Some(Ok(chunk)))
                } else {
                    self.failed = true;
                    Poll::Ready(Some(Err(Box::new(PartHeaderTooLarge {
                        limit: self.scanner.limit,
                    }))))
                }
            }
            Poll::Ready(Some(Err(e))) => Poll::Ready(Some(Err(e.into()))),
            Poll::Ready(None) => Poll::Ready(None),
            Poll::Pending => Poll::Pending,
        }
    }
}

/// An upload's form.
pub type Form = multer::Multipart<'static>;

/// Opens `body` (already limited in size) as a multipart form whose part headers are capped at
/// `limit` bytes.
pub fn form(headers: &HeaderMap, body: Body, limit: usize) -> Result<Form, ApiError> {
    let content_type = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    let boundary = multer::parse_boundary(content_type)
        .map_err(|e| ApiError::InvalidMultipart(e.to_string()))?;
    if boundary.is_empty() || boundary.len() > MAX_BOUNDARY_BYTES {
        return Err(ApiError::InvalidMultipart(format!(
            "the boundary must be 1 to {MAX_BOUNDARY_BYTES} characters"
        )));
    }
    let guard = PartHeaderGuard {
        inner: body.into_data_stream(),
        scanner: Scanner::new(&boundary, limit),
        failed: false,
    };
    Ok(multer::Multipart::new(guard, boundary))
}

/// Whether `T` is `error` or anywhere in its chain of sources.
pub fn caused_by<T: std::error::Error + 'static>(
    error: &(dyn std::error::Error + 'static),
) -> bool {
    let mut current = Some(error);
    while let Some(e) = current {
        if e.is::<T>() {
            return true;
        }
        current = e.source();
    }
    false
}

/// The API error for a failed read of a form.
pub fn error(e: &multer::Error, config: &crate::config::Config) -> ApiError {
    if let multer::Error::StreamReadFailed(source) = e {
        let source: &(dyn std::error::Error + 'static) = source.as_ref();
        if caused_by::<PartHeaderTooLarge>(source) {
            return ApiError::PartHeaderTooLarge {
                limit: config.max_part_header_bytes,
            };
        }
        if caused_by::<http_body_util::LengthLimitError>(source) {
            return ApiError::FileTooLarge {
                limit: config.max_upload_bytes,
            };
        }
        if caused_by::<tower_http::timeout::TimeoutError>(source) {
            return ApiError::BodyTimeout {
                seconds: config.body_timeout_s,
            };
        }
    }
    ApiError::InvalidMultipart(e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan_in_pieces(body: &[u8], limit: usize, piece: usize) -> bool {
        let mut scanner = Scanner::new("XyZ", limit);
        body.chunks(piece).all(|c| scanner.scan(c))
    }

    #[test]
    fn part_headers_past_the_limit_are_caught_across_chunk_edges() {
        let data = vec![b'\r'; 5000];
        let mut ok =
            b"--XyZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.ogg\"\r\n\r\n"
                .to_vec();
        ok.extend_from_slice(&data);
        ok.extend_from_slice(b"\r\n--XyZ--\r\n");
        let long_name = "n".repeat(300);
        let bad = format!(
            "--XyZ\r\nContent-Disposition: form-data; name=\"{long_name}\"\r\n\r\nx\r\n--XyZ--\r\n"
        );
        let mut second_bad = ok[..ok.len() - 4].to_vec();
        second_bad.extend_from_slice(
            format!("\r\nX-Pad: {long_name}\r\n\r\nx\r\n--XyZ--\r\n").as_bytes(),
        );
        for piece in [1, 2, 3, 7, 64, 100_000] {
            assert!(scan_in_pieces(&ok, 256, piece), "piece {piece}");
            assert!(!scan_in_pieces(bad.as_bytes(), 256, piece), "piece {piece}");
            assert!(!scan_in_pieces(&second_bad, 256, piece), "piece {piece}");
            // A long preamble before the first boundary is refused too.
            let preamble = [vec![b'p'; 1000], ok.clone()].concat();
            assert!(!scan_in_pieces(&preamble, 256, piece), "piece {piece}");
        }
    }
}
