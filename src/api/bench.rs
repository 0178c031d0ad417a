//! `choreo bench http`: throughput and latency of `GET /v1/jobs/{id}` on loopback while the
//! workers are busy; `choreo bench jobs` ([`jobs`]): dances a minute with 1 and 2 workers.
//!
//! It starts the real service on port 0 with a temporary data dir, uploads a song over HTTP,
//! queues analyze jobs for it until every worker has work, and then drives keep-alive HTTP/1.1
//! connections for a fixed time. The client is a few lines over a `TcpStream`, so the figures
//! measure the server, not a client library.
pub mod jobs;

use super::Server;
use crate::config::Config;
use crate::queue::{JobId, JobKind, NewJob, SongId, Status};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Errors of the bench harness.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("starting the service: {0}")]
    Start(#[from] super::StartError),
    #[error("i/o: {0}")]
    Io(#[from] std::io::Error),
    #[error("queue: {0}")]
    Queue(#[from] crate::queue::QueueError),
    #[error("bad response: {0}")]
    Protocol(String),
}

impl BenchError {
    /// Stable kebab-case name of the failure; a wrapped error keeps its own code.
    pub fn code(&self) -> &'static str {
        match self {
            BenchError::Start(e) => e.code(),
            BenchError::Io(_) => "bench-io",
            BenchError::Queue(e) => e.code(),
            BenchError::Protocol(_) => "bench-bad-response",
        }
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct HttpBench {
    /// The song uploaded to give the workers analyze jobs.
    pub song: PathBuf,
    /// How long to measure.
    pub duration: Duration,
    /// Concurrent keep-alive connections.
    pub connections: usize,
    /// Analyze jobs queued to keep the workers busy.
    pub busy_jobs: usize,
    /// The service configuration (its data dir is replaced by a temporary one).
    pub config: Config,
}

/// The figures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct HttpReport {
    pub requests: u64,
    pub errors: u64,
    pub seconds: f64,
    pub requests_per_s: f64,
    pub p50_ms: f64,
    pub p90_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
    pub connections: usize,
    pub workers: usize,
    /// Jobs running when measuring started and ended (should equal `workers`).
    pub running_at_start: u64,
    pub running_at_end: u64,
}

/// One keep-alive HTTP/1.1 connection.
struct Conn {
    stream: TcpStream,
    buf: Vec<u8>,
}

impl Conn {
    async fn open(addr: std::net::SocketAddr) -> Result<Self, BenchError> {
        let stream = TcpStream::connect(addr).await?;
        stream.set_nodelay(true)?;
        Ok(Self {
            stream,
            buf: Vec::with_capacity(16 * 1024),
        })
    }

    /// Sends one request and reads the whole response; returns its status and body.
    async fn request(&mut self, head: &[u8], body: &[u8]) -> Result<(u16, Vec<u8>), BenchError> {
        self.stream.write_all(head).await?;
        self.stream.write_all(body).await?;
        let header_end = loop {
            if let Some(pos) = self.buf.windows(4).position(|w| w == b"\r\n\r\n") {
                break pos + 4;
            }
            self.fill().await?;
        };
        let head = std::str::from_utf8(&self.buf[..header_end])
            .map_err(|e| BenchError::Protocol(e.to_string()))?;
        let status = head
            .split(' ')
            .nth(1)
            .and_then(|s| s.parse::<u16>().ok())
            .ok_or_else(|| BenchError::Protocol(format!("status line of {head:?}")))?;
        let length = head
            .lines()
            .find_map(|l| {
                let (name, value) = l.split_once(':')?;
                name.eq_ignore_ascii_case("content-length")
                    .then(|| value.trim().parse::<usize>().ok())?
            })
            .ok_or_else(|| BenchError::Protocol("no content-length".into()))?;
        while self.buf.len() < header_end + length {
            self.fill().await?;
        }
        let body = self.buf[header_end..header_end + length].to_vec();
        self.buf.drain(..header_end + length);
        Ok((status, body))
    }

    async fn fill(&mut self) -> Result<(), BenchError> {
        let mut chunk = [0u8; 8192];
        let n = self.stream.read(&mut chunk).await?;
        if n == 0 {
            return Err(BenchError::Protocol("connection closed".into()));
        }
        self.buf.extend_from_slice(&chunk[..n]);
        Ok(())
    }
}

/// POSTs `body` (of `content_type`) to `path` over `conn`; the response's body when the status is
/// `expect`, else what the server said.
async fn post(
    conn: &mut Conn,
    path: &str,
    content_type: &str,
    body: &[u8],
    expect: u16,
) -> Result<Vec<u8>, BenchError> {
    let head = format!(
        "POST {path} HTTP/1.1\r\nHost: bench\r\nContent-Type: {content_type}\r\n\
         Content-Length: {}\r\n\r\n",
        body.len()
    );
    let (status, response) = conn.request(head.as_bytes(), body).await?;
    if status != expect {
        return Err(BenchError::Protocol(format!(
            "POST {path} answered {status}: {}",
            String::from_utf8_lossy(&response)
        )));
    }
    Ok(response)
}

/// The string field `name` of a JSON response body.
fn json_field(body: &[u8], name: &str) -> Result<String, BenchError> {
    let value: serde_json::Value =
        serde_json::from_slice(body).map_err(|e| BenchError::Protocol(e.to_string()))?;
    value[name]
        .as_str()
        .map(str::to_string)
        .ok_or_else(|| BenchError::Protocol(format!("no {name} in {value}")))
}

/// Uploads a song as multipart form data over `conn`; returns its id.
async fn upload(conn: &mut Conn, bytes: &[u8]) -> Result<String, BenchError> {
    let boundary = "choreo-bench-boundary";
    let mut body = format!(
        "--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"bench\"\r\n\
         Content-Type: application/octet-stream\r\n\r\n"
    )
    .into_bytes();
    body.extend_from_slice(bytes);
    body.extend_from_slice(format!("\r\n--{boundary}--\r\n").as_bytes());
    let content_type = format!("multipart/form-data; boundary={boundary}");
    let response = post(conn, "/v1/songs", &content_type, &body, 201).await?;
    json_field(&response, "id")
}

fn percentile(sorted: &[Duration], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1].as_secs_f64() * 1e3
}

async fn running(server: &Server) -> Result<u64, BenchError> {
    let counts = server.state().store.counts().await?;
    Ok(counts
        .iter()
        .find(|(s, _)| *s == Status::Running)
        .map_or(0, |(_, n)| *n))
}

/// Runs the bench and returns its figures.
pub async fn run(bench: HttpBench) -> Result<HttpReport, BenchError> {
    let data = tempfile::tempdir()?;
    let mut config = bench.config.clone();
    config.data_dir = data.path().to_path_buf();
    config.bind = "127.0.0.1:0".into();
    let workers = config.worker_count();
    let server = Server::start(config).await?;
    let addr = server.addr();

    // Upload the song over HTTP, as a client would.
    let bytes = tokio::fs::read(&bench.song).await?;
    let mut conn = Conn::open(addr).await?;
    let song_id: SongId = upload(&mut conn, &bytes)
        .await?
        .parse()
        .map_err(|_| BenchError::Protocol("upload response's id is not a song id".into()))?;

    // Keep every worker busy: the analyze jobs queued here are real work on the real song.
    let mut target: Option<JobId> = None;
    for _ in 0..bench.busy_jobs.max(workers) {
        let job = NewJob {
            tenant: crate::queue::TenantId::OPEN,
            kind: JobKind::Analyze { song_id },
            priority: 0,
            max_attempts: 1,
            idempotency: None,
        };
        target = Some(server.state().store.register(job).await?.job().id);
    }
    server.state().wake.notify_waiters();
    let target = target.ok_or_else(|| BenchError::Protocol("no job to poll".into()))?;
    let deadline = Instant::now() + Duration::from_secs(30);
    while running(&server).await? < workers as u64 && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let running_at_start = running(&server).await?;

    let request = format!("GET /v1/jobs/{target} HTTP/1.1\r\nHost: bench\r\n\r\n").into_bytes();
    let started = Instant::now();
    let end = started + bench.duration;
    let tasks: Vec<_> = (0..bench.connections.max(1))
        .map(|_| {
            let request = request.clone();
            tokio::spawn(async move {
                let mut latencies = Vec::with_capacity(64 * 1024);
                let mut errors = 0u64;
                let mut conn = Conn::open(addr).await?;
                while Instant::now() < end {
                    let sent = Instant::now();
                    match conn.request(&request, &[]).await {
                        Ok((200, _)) => latencies.push(sent.elapsed()),
                        Ok(_) => errors += 1,
                        Err(_) => {
                            errors += 1;
                            conn = Conn::open(addr).await?;
                        }
                    }
                }
                Ok::<_, BenchError>((latencies, errors))
            })
        })
        .collect();
    let mut latencies = Vec::new();
    let mut errors = 0;
    for task in tasks {
        let (l, e) = task
            .await
            .map_err(|e| BenchError::Protocol(format!("client task: {e}")))??;
        latencies.extend(l);
        errors += e;
    }
    let seconds = started.elapsed().as_secs_f64();
    let running_at_end = running(&server).await?;
    server.stop().await;
    latencies.sort_unstable();
    Ok(HttpReport {
        requests: latencies.len() as u64,
        errors,
        seconds,
        requests_per_s: latencies.len() as f64 / seconds,
        p50_ms: percentile(&latencies, 0.50),
        p90_ms: percentile(&latencies, 0.90),
        p99_ms: percentile(&latencies, 0.99),
        max_ms: latencies.last().map_or(f64::NAN, |d| d.as_secs_f64() * 1e3),
        connections: bench.connections.max(1),
        workers,
        running_at_start,
        running_at_end,
    })
}
