//! The HTTP server loop: a cap on open connections, and a timeout on every way a client can stall.
//!
//! `axum::serve` takes no timeouts, so connections are served here with hyper's HTTP/1 builder:
//!
//! - hyper's `header_read_timeout`: a client has `header_timeout_s` to send a request head,
//!   counted from the connection's opening and, on a keep-alive connection, from the previous
//!   response (hyper restarts the timer at each message), so it is the idle timeout as well;
//! - a write timeout on the socket (`tokio-io-timeout`): a response that cannot be written for
//!   `write_timeout_s` (the client stopped reading) ends the connection;
//! - the request body's timeout is a tower-http layer in [`super::router`];
//! - a semaphore caps open connections at [`connection_cap`]: `max_connections`, lowered to the
//!   open-file limit less `fd_reserve`, so sockets never take the file handles workers need. A
//!   connection past the cap gets a `503 too-many-connections` problem and is closed; when even
//!   the few slots for those answers are taken it is closed at once;
//! - except a health probe: a connection past the cap whose first bytes are `GET /healthz` or
//!   `GET /readyz` (peeked, not read) is served anyway, one request, from the slots kept for
//!   refusals, so a load balancer is told the truth about a busy server rather than a 503 that
//!   would take it out of rotation.
use super::problem::ApiError;
use axum::Router;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;
use tokio_io_timeout::TimeoutStream;
use tokio_util::sync::CancellationToken;

/// Connections past the cap that are still answered with a 503 (each holds a handle for up to
/// [`REFUSAL_LINGER`]); past these, a connection is closed without an answer.
const REFUSALS: usize = 32;
/// How long a refused connection is kept open so the client can read its 503 before the close.
const REFUSAL_LINGER: Duration = Duration::from_secs(1);
/// Longest request head, and the read buffer of a connection: bounds memory per connection.
const MAX_HEAD_BYTES: usize = 64 * 1024;
/// How long the server waits for in-flight requests when it stops.
const DRAIN: Duration = Duration::from_secs(10);
/// After an accept error (out of file handles), wait this long before accepting again.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);
/// How long a connection past the cap may take to show whether it is a health probe.
const PROBE_PEEK: Duration = Duration::from_millis(200);
/// The request lines served past the connection cap.
const HEALTH_PROBES: [&[u8]; 2] = [b"GET /healthz ", b"GET /readyz "];

/// The limits one server loop applies.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    pub max_connections: usize,
    pub header_timeout: Duration,
    pub write_timeout: Duration,
}

impl Limits {
    /// The limits of `config`, with the connection cap fitted to the open-file limit.
    pub fn new(config: &crate::config::Config) -> Self {
        Self {
            max_connections: connection_cap(
                config.max_connections,
                config.fd_reserve,
                open_file_limit(),
            ),
            header_timeout: Duration::from_secs_f64(config.header_timeout_s),
            write_timeout: Duration::from_secs_f64(config.write_timeout_s),
        }
    }
}

/// The open-file limit, raised first to the hard limit (as Go's runtime does): the default soft
/// limit of 1,024 is a relic that the hard limit usually far exceeds.
pub fn open_file_limit() -> u64 {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes into the struct we own.
    if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit) } != 0 {
        return u64::MAX;
    }
    if limit.rlim_cur < limit.rlim_max {
        let raised = libc::rlimit {
            rlim_cur: limit.rlim_max,
            rlim_max: limit.rlim_max,
        };
        // SAFETY: setrlimit only reads the struct.
        if unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &raised) } == 0 {
            limit = raised;
        }
    }
    if limit.rlim_cur == libc::RLIM_INFINITY {
        u64::MAX
    } else {
        limit.rlim_cur
    }
}

/// `max_connections`, lowered so that `reserve` file handles of `open_files` stay free.
pub fn connection_cap(max_connections: usize, reserve: u64, open_files: u64) -> usize {
    let room = open_files
        .saturating_sub(reserve)
        .saturating_sub(REFUSALS as u64)
        .max(1);
    max_connections.min(usize::try_from(room).unwrap_or(usize::MAX))
}

/// Serves `app` on `listener` until `shutdown`, then lets in-flight requests finish (bounded).
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: Limits,
    shutdown: CancellationToken,
) -> std::io::Result<()> {
    let open = Arc::new(Semaphore::new(limits.max_connections));
    let refusals = Arc::new(Semaphore::new(REFUSALS));
    let refusal = refusal_bytes(limits.max_connections);
    let graceful = GracefulShutdown::new();
    let mut builder = http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout)
        .max_buf_size(MAX_HEAD_BYTES);
    let mut last_accept_error: Option<Instant> = None;
    loop {
        let stream = tokio::select! {
            _ = shutdown.cancelled() => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    // Out of file handles (or memory): wait, rather than spin and flood the log.
                    metrics::counter!(crate::telemetry::ACCEPT_ERRORS).increment(1);
                    if last_accept_error.is_none_or(|t| t.elapsed() > Duration::from_secs(5)) {
                        tracing::error!(error = %e, "accept failed; backing off");
                        last_accept_error = Some(Instant::now());
                    }
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                    continue;
                }
            },
        };
        let Ok(permit) = open.clone().try_acquire_owned() else {
            metrics::counter!(crate::telemetry::CONNECTIONS_REFUSED).increment(1);
            if let Ok(slot) = refusals.clone().try_acquire_owned() {
                let refusal = refusal.clone();
                let mut probe_builder = builder.clone();
                probe_builder.keep_alive(false);
                let app = app.clone();
                tokio::spawn(async move {
                    if is_health_probe(&stream).await {
                        let mut io = TimeoutStream::new(stream);
                        io.set_write_timeout(Some(limits.write_timeout));
                        let served = probe_builder.serve_connection(
                            TokioIo::new(Box::pin(io)),
                            TowerToHyperService::new(app),
                        );
                        if let Err(e) = served.await {
                            tracing::debug!(error = %e, "health probe past the cap ended with an error");
                        }
                    } else {
                        refuse(stream, &refusal).await;
                    }
                    drop(slot);
                });
            }
            continue;
        };
        let mut io = TimeoutStream::new(stream);
        io.set_write_timeout(Some(limits.write_timeout));
        let connection = builder.serve_connection(
            TokioIo::new(Box::pin(io)),
            TowerToHyperService::new(app.clone()),
        );
        let connection = graceful.watch(connection);
        tokio::spawn(async move {
            if let Err(e) = connection.await {
                tracing::debug!(error = %e, "connection ended with an error");
            }
            drop(permit);
        });
    }
    drop(listener);
    tokio::select! {
        _ = graceful.shutdown() => {}
        _ = tokio::time::sleep(DRAIN) => tracing::warn!("connections still open {} s after shutdown; closing them", DRAIN.as_secs()),
    }
    Ok(())
}

/// Whether the connection's first bytes, peeked without reading them, are a health probe's
/// request line. Waits at most [`PROBE_PEEK`] for them; a client that sent other bytes is told
/// at once.
async fn is_health_probe(stream: &TcpStream) -> bool {
    let longest = HEALTH_PROBES.iter().map(|p| p.len()).max().unwrap_or(0);
    let mut head = vec![0u8; longest];
    let deadline = tokio::time::Instant::now() + PROBE_PEEK;
    loop {
        let peeked = match tokio::time::timeout_at(deadline, stream.peek(&mut head)).await {
            Ok(Ok(n)) if n > 0 => &head[..n],
            _ => return false,
        };
        let mut could_be = false;
        for probe in HEALTH_PROBES {
            if peeked.len() >= probe.len() && peeked.starts_with(probe) {
                return true;
            }
            could_be |= probe.starts_with(peeked);
        }
        if !could_be || tokio::time::Instant::now() >= deadline {
            return false;
        }
        // Only part of a request line is in: peek again shortly (a peek returns at once while
        // the bytes it saw are still unread).
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// The whole HTTP response a connection past the cap gets.
fn refusal_bytes(limit: usize) -> Arc<[u8]> {
    let problem = ApiError::TooManyConnections { limit }.problem();
    let body = serde_json::to_vec(&problem).unwrap_or_default();
    let head = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: {}\r\ncontent-length: {}\r\nretry-after: 1\r\nconnection: close\r\n\r\n",
        super::problem::PROBLEM_JSON,
        body.len()
    );
    [head.into_bytes(), body].concat().into()
}

/// Answers `503 too-many-connections` and closes, lingering briefly so the answer is read.
async fn refuse(mut stream: TcpStream, response: &[u8]) {
    let linger = async {
        stream.write_all(response).await?;
        stream.shutdown().await?;
        // Read what the client sent, so closing does not reset the connection under the answer.
        let mut sink = [0u8; 4096];
        while stream.read(&mut sink).await? > 0 {}
        Ok::<(), std::io::Error>(())
    };
    let _ = tokio::time::timeout(REFUSAL_LINGER, linger).await;
}

#[cfg(test)]
mod tests {
    use super::connection_cap;

    #[test]
    fn the_cap_leaves_the_reserve_free() {
        assert_eq!(connection_cap(1024, 256, 1024), 1024 - 256 - 32);
        assert_eq!(connection_cap(100, 256, 1_000_000), 100);
        assert_eq!(connection_cap(100, 256, 10), 1);
    }
}
