//! Bad clients and a failing log sink, each against a real `choreo serve` process:
//! stalled connections under a lowered open-file limit, stalled readers of a large result, a
//! closed stderr; and a failing store (`store`: a full disk, a stopped database). Every loop is
//! bounded in count and time; all traffic stays on 127.0.0.1.
use crate::helpers::{short_song, song};
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

mod store;

/// Where a served process's stderr goes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Stderr {
    /// A file in the process's temp dir, read by [`Serve::log`].
    File,
    /// A pipe whose reading end is closed before the server starts: every write fails.
    Closed,
}

struct Options<'a> {
    env: &'a [(&'a str, &'a str)],
    /// RLIMIT_NOFILE (soft and hard) of the child.
    open_files: Option<u64>,
    stderr: Stderr,
    models: bool,
    /// The data dir (default: one in the process's temp dir).
    data_dir: Option<PathBuf>,
}

impl Default for Options<'_> {
    fn default() -> Self {
        Self {
            env: &[],
            open_files: None,
            stderr: Stderr::File,
            models: false,
            data_dir: None,
        }
    }
}

/// A `choreo serve` child on port 0 with its own data dir, killed when dropped.
struct Serve {
    child: Child,
    addr: String,
    dir: tempfile::TempDir,
}

impl Serve {
    fn start(options: Options<'_>) -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let models = if options.models {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("models")
        } else {
            dir.path().join("no-models")
        };
        // CHOREO_BIN runs another build (e.g. main's, to measure the behaviour before a fix).
        let bin = std::env::var("CHOREO_BIN")
            .unwrap_or_else(|_| env!("CARGO_BIN_EXE_choreo").to_string());
        let mut command = Command::new(bin);
        command
            .args([
                "serve",
                "--bind",
                "127.0.0.1:0",
                "--workers",
                "2",
                "--data-dir",
            ])
            .arg(
                options
                    .data_dir
                    .clone()
                    .unwrap_or_else(|| dir.path().join("data")),
            )
            .arg("--models-dir")
            .arg(models)
            .envs(options.env.iter().copied())
            .env("CHOREO_LOG_LEVEL", "info")
            .env_remove("RUST_LOG")
            .current_dir(dir.path())
            .stdout(Stdio::piped());
        match options.stderr {
            Stderr::File => {
                command.stderr(
                    std::fs::File::create(dir.path().join("stderr.log")).expect("log file"),
                );
            }
            Stderr::Closed => {
                command.stderr(Stdio::piped());
            }
        }
        if let Some(limit) = options.open_files {
            // SAFETY: setrlimit is async-signal-safe and touches only the child being started.
            unsafe {
                command.pre_exec(move || {
                    let rlimit = libc::rlimit {
                        rlim_cur: limit,
                        rlim_max: limit,
                    };
                    if libc::setrlimit(libc::RLIMIT_NOFILE, &rlimit) == 0 {
                        Ok(())
                    } else {
                        Err(std::io::Error::last_os_error())
                    }
                });
            }
        }
        let mut child = command.spawn().expect("start choreo serve");
        // Closed before the server writes anything: it starts with a dead stderr.
        drop(child.stderr.take());
        let stdout = child.stdout.take().expect("stdout");
        let mut line = String::new();
        BufReader::new(stdout)
            .read_line(&mut line)
            .expect("read the listening line");
        let addr = line
            .trim()
            .strip_prefix("choreo listening on http://")
            .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
            .to_string();
        Self { child, addr, dir }
    }

    fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addr, path)
    }

    /// A field of /proc/<pid>/status, in kB.
    fn status_kb(&self, field: &str) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id()))
            .expect("proc status");
        status
            .lines()
            .find_map(|l| {
                l.strip_prefix(field)?
                    .trim_start_matches(':')
                    .trim()
                    .strip_suffix("kB")?
                    .trim()
                    .parse()
                    .ok()
            })
            .unwrap_or_else(|| panic!("no {field} in /proc status"))
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("stderr.log")).unwrap_or_default()
    }

    fn assert_alive(&mut self) {
        assert!(
            self.child.try_wait().expect("try_wait").is_none(),
            "choreo serve exited; log:\n{}",
            self.log()
        );
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn client() -> reqwest::Client {
    // No pooled connections: each request must win its own connection, as a new client's would.
    reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .timeout(Duration::from_secs(30))
        .build()
        .expect("client")
}

async fn upload(client: &reqwest::Client, serve: &Serve, path: &Path) -> Value {
    let form = reqwest::multipart::Form::new().part(
        "file",
        reqwest::multipart::Part::bytes(std::fs::read(path).expect("read song"))
            .file_name("song.ogg"),
    );
    let response = client
        .post(serve.url("/v1/songs"))
        .multipart(form)
        .send()
        .await
        .expect("upload");
    let status = response.status();
    let body: Value = response.json().await.expect("song json");
    assert!(
        status == StatusCode::CREATED || status == StatusCode::OK,
        "{status}: {body}"
    );
    body
}

/// Waits until every job is terminal (bounded) and returns them.
async fn settle(client: &reqwest::Client, serve: &Serve, limit: Duration) -> Vec<Value> {
    let deadline = Instant::now() + limit;
    loop {
        let page: Value = client
            .get(serve.url("/v1/jobs?limit=100"))
            .send()
            .await
            .expect("GET jobs")
            .json()
            .await
            .expect("jobs json");
        let jobs = page["items"].as_array().expect("items").clone();
        if jobs.iter().all(|j| {
            ["succeeded", "failed", "cancelled"].contains(&j["status"].as_str().unwrap_or(""))
        }) {
            return jobs;
        }
        assert!(
            Instant::now() < deadline,
            "jobs unfinished after {limit:?}: {jobs:?}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

async fn metric(client: &reqwest::Client, serve: &Serve, name: &str) -> f64 {
    let text = client
        .get(serve.url("/metrics"))
        .send()
        .await
        .expect("GET /metrics")
        .text()
        .await
        .expect("metrics text");
    text.lines()
        .filter(|l| l.starts_with(name))
        .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .sum()
}

/// Raises this test process's own open-file limit so it can hold `n` sockets.
fn allow_open_files(n: u64) {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit read and write only the struct we own.
    unsafe {
        assert_eq!(libc::getrlimit(libc::RLIMIT_NOFILE, &mut limit), 0);
        if limit.rlim_cur < n {
            limit.rlim_cur = n.min(limit.rlim_max.max(n));
            limit.rlim_max = limit.rlim_max.max(n);
            assert_eq!(
                libc::setrlimit(libc::RLIMIT_NOFILE, &limit),
                0,
                "raise RLIMIT_NOFILE to {n}: {}",
                std::io::Error::last_os_error()
            );
        }
    }
}

/// Reads until the server closes the connection (EOF or reset), within `limit`; what was read.
async fn read_until_closed(stream: &mut TcpStream, limit: Duration) -> Option<Vec<u8>> {
    let mut seen = Vec::new();
    let mut buf = vec![0u8; 64 * 1024];
    let read = async {
        loop {
            match stream.read(&mut buf).await {
                Ok(0) | Err(_) => return,
                Ok(n) if seen.len() < 4096 => seen.extend_from_slice(&buf[..n]),
                Ok(_) => {}
            }
        }
    };
    tokio::time::timeout(limit, read).await.ok().map(|()| seen)
}

/// Long enough that all 1,000 connections are open before the first is timed out, even on a busy
/// 2-core CI runner (4.1 s to open them there): otherwise the earliest close before the cap is
/// reached and no connection is ever past it.
const HEADER_TIMEOUT_S: u64 = 10;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_thousand_stalled_connections_leave_health_and_jobs_working() {
    allow_open_files(4096);
    let header_timeout = HEADER_TIMEOUT_S.to_string();
    let mut serve = Serve::start(Options {
        env: &[
            ("CHOREO_HEADER_TIMEOUT_S", &header_timeout),
            ("CHOREO_RETRY_BACKOFF_S", "0.2"),
        ],
        open_files: Some(1024),
        ..Options::default()
    });
    let client = client();
    // Jobs that need file handles while the sockets are stalled: five analyses queued first.
    let names = [
        "lets_go_fishin.ogg",
        "sugar_plum_fairy.ogg",
        "vibe_ace.ogg",
        "hungarian_dance_5.ogg",
    ];
    for path in names.iter().map(|n| song(n)).chain([short_song()]) {
        upload(&client, &serve, &path).await;
    }

    // 1,000 connections that each send 30 bytes of a request head and stop.
    let opened = Instant::now();
    let mut stalled = Vec::with_capacity(1000);
    for _ in 0..1000 {
        let mut stream = TcpStream::connect(&serve.addr).await.expect("connect");
        let _ = stream.write_all(b"POST /v1/songs HTTP/1.1\r\nHost:").await;
        stalled.push(stream);
    }
    let opening_s = opened.elapsed().as_secs_f64();
    eprintln!("opened 1000 stalled connections in {opening_s:.2} s");
    assert!(
        opening_s < HEADER_TIMEOUT_S as f64,
        "opening took {opening_s:.1} s, past the {HEADER_TIMEOUT_S} s header timeout: the test measures nothing"
    );

    // While they hold every slot, a new client gets an answer at once (a 503 past the cap), not a hang.
    let during = Instant::now();
    let answer = client
        .get(serve.url("/healthz"))
        .timeout(Duration::from_secs(5))
        .send()
        .await;
    let during_s = during.elapsed().as_secs_f64();
    match &answer {
        Ok(r) => assert!(
            r.status() == StatusCode::OK || r.status() == StatusCode::SERVICE_UNAVAILABLE,
            "{r:?}"
        ),
        // A refused connection may be reset under its 503; what matters is that it did not hang.
        Err(e) => assert!(!e.is_timeout(), "/healthz hung during the stall: {e}"),
    }
    eprintln!(
        "/healthz during the stall: {:?} in {during_s:.2} s",
        answer.as_ref().map(|r| r.status())
    );

    // The server closes every stalled connection by the header timeout; past-the-cap ones got a 503.
    let mut refused = 0;
    for stream in &mut stalled {
        let seen = read_until_closed(stream, Duration::from_secs(HEADER_TIMEOUT_S + 10)).await;
        let seen = seen.unwrap_or_else(|| {
            panic!(
                "a stalled connection was still open {} s after opening",
                opened.elapsed().as_secs()
            )
        });
        if seen.starts_with(b"HTTP/1.1 503") {
            assert!(String::from_utf8_lossy(&seen).contains("too-many-connections"));
            refused += 1;
        }
    }
    let closed_after = opened.elapsed().as_secs_f64();
    eprintln!("all 1000 closed by the server {closed_after:.2} s after opening; {refused} answered 503 too-many-connections");
    assert!(
        refused > 0 && refused < 1000,
        "some connections past the cap were refused with a 503: {refused}"
    );
    assert!(
        closed_after < (HEADER_TIMEOUT_S + 8) as f64,
        "stalled connections closed within the header timeout: {closed_after:.1} s"
    );

    let health = Instant::now();
    let response = client
        .get(serve.url("/healthz"))
        .send()
        .await
        .expect("/healthz after the stall");
    assert_eq!(response.status(), StatusCode::OK);
    eprintln!(
        "/healthz after the stall: 200 in {:.3} s",
        health.elapsed().as_secs_f64()
    );

    // Every job queued before the stall ran to success: sockets did not starve the workers' files.
    let jobs = settle(&client, &serve, Duration::from_secs(120)).await;
    assert_eq!(jobs.len(), 5);
    for job in &jobs {
        assert_eq!(job["status"], "succeeded", "{job}");
    }
    // And a real job after it.
    let fresh = upload(&client, &serve, &crate::helpers::fixture("wav")).await;
    assert!(fresh["id"].is_string());
    for job in settle(&client, &serve, Duration::from_secs(60)).await {
        assert_eq!(job["status"], "succeeded", "{job}");
    }
    assert!(metric(&client, &serve, "choreo_connections_refused_total").await >= refused as f64);
    serve.assert_alive();
    let log = serve.log();
    assert!(
        !log.contains("Too many open files"),
        "the server ran out of file handles:\n{log}"
    );
}

/// A song of about six minutes (the five shared songs joined), made once per build.
fn long_song() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("audio-fixtures");
    let out = dir.join("joined-6min.ogg");
    if out.is_file() {
        return out;
    }
    std::fs::create_dir_all(&dir).expect("fixture dir");
    let names = [
        "lets_go_fishin.ogg",
        "sugar_plum_fairy.ogg",
        "vibe_ace.ogg",
        "hungarian_dance_5.ogg",
    ];
    let list = dir.join("joined.txt");
    let lines: String = names
        .iter()
        .chain(names.iter())
        .map(|n| format!("file '{}'\n", song(n).display()))
        .collect();
    std::fs::write(&list, lines).expect("concat list");
    let partial = dir.join(format!("partial-{}-joined.ogg", std::process::id()));
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-f", "concat", "-safe", "0", "-i"])
        .arg(&list)
        .args(["-t", "360", "-ac", "1", "-c:a", "libvorbis", "-q:a", "0"])
        .arg(&partial)
        .status()
        .expect("ffmpeg is needed to make test fixtures: run `scripts/setup.sh --test` (or `make test`)");
    assert!(status.success(), "ffmpeg failed to join the songs");
    std::fs::rename(&partial, &out).expect("fixture rename");
    out
}

/// Bound on resident memory growth with 60 stalled readers of a large result (each holds one
/// 64 KiB chunk and hyper's buffers; before streaming, each held the whole file).
const STALLED_READERS_BUDGET_KB: u64 = 64 * 1024;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sixty_stalled_readers_of_a_large_result_hold_bounded_memory() {
    let mut serve = Serve::start(Options {
        env: &[("CHOREO_WRITE_TIMEOUT_S", "5")],
        models: true,
        ..Options::default()
    });
    let client = client();
    let song = upload(&client, &serve, &long_song()).await;
    let response = client
        .post(serve.url("/v1/jobs"))
        .json(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": 1}))
        .send()
        .await
        .expect("POST /v1/jobs");
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let job: Value = response.json().await.expect("job");
    let id = job["id"].as_str().expect("id").to_string();
    for job in settle(&client, &serve, Duration::from_secs(300)).await {
        assert_eq!(job["status"], "succeeded", "{job}");
    }
    let path = format!("/v1/jobs/{id}/motion.json");
    let whole = client
        .get(serve.url(&path))
        .send()
        .await
        .expect("GET motion.json");
    assert_eq!(whole.status(), StatusCode::OK);
    let size = whole.bytes().await.expect("body").len();
    assert!(size > 10_000_000, "a large result: {size} bytes");

    tokio::time::sleep(Duration::from_millis(500)).await;
    let idle_kb = serve.status_kb("VmRSS");
    let mut readers = Vec::new();
    for _ in 0..60 {
        let mut stream = TcpStream::connect(&serve.addr).await.expect("connect");
        stream
            .write_all(format!("GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").as_bytes())
            .await
            .expect("request");
        let mut head = [0u8; 1024];
        let n = stream.read(&mut head).await.expect("head");
        assert!(
            head[..n].starts_with(b"HTTP/1.1 200"),
            "{}",
            String::from_utf8_lossy(&head[..n])
        );
        readers.push(stream);
    }
    // The server writes until the sockets' buffers are full, then waits on the readers.
    tokio::time::sleep(Duration::from_secs(2)).await;
    let stalled_kb = serve.status_kb("VmRSS");
    let growth_kb = stalled_kb.saturating_sub(idle_kb);
    eprintln!(
        "motion.json {:.1} MB; VmRSS idle {} MB, with 60 stalled readers {} MB (+{} MB)",
        size as f64 / 1e6,
        idle_kb / 1024,
        stalled_kb / 1024,
        growth_kb / 1024
    );
    assert!(
        growth_kb < STALLED_READERS_BUDGET_KB,
        "60 stalled readers grew resident memory by {growth_kb} kB"
    );

    // The write timeout (5 s) ends each stalled response; the reader then sees the close.
    let started = Instant::now();
    for stream in &mut readers {
        assert!(
            read_until_closed(stream, Duration::from_secs(30))
                .await
                .is_some(),
            "a stalled reader was never cut off"
        );
    }
    eprintln!(
        "stalled readers cut off and drained in {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let health = client
        .get(serve.url("/healthz"))
        .send()
        .await
        .expect("healthz");
    assert_eq!(health.status(), StatusCode::OK);
    serve.assert_alive();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_closed_stderr_neither_stops_jobs_nor_fools_readyz() {
    let mut serve = Serve::start(Options {
        stderr: Stderr::Closed,
        models: true,
        ..Options::default()
    });
    let client = client();
    let song = upload(&client, &serve, &short_song()).await;
    let response = client
        .post(serve.url("/v1/jobs"))
        .json(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": 2}))
        .send()
        .await
        .expect("POST /v1/jobs");
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let jobs = settle(&client, &serve, Duration::from_secs(120)).await;
    assert_eq!(jobs.len(), 2, "{jobs:?}");
    for job in &jobs {
        assert_eq!(job["status"], "succeeded", "{job}");
    }
    let ready = client
        .get(serve.url("/readyz"))
        .send()
        .await
        .expect("readyz");
    assert_eq!(
        ready.status(),
        StatusCode::OK,
        "workers are alive and the database answers"
    );
    // Log lines were written, failed, and were dropped and counted rather than panicking.
    let dropped = metric(&client, &serve, "choreo_log_write_errors_total").await;
    assert!(
        dropped > 0.0,
        "the failed log writes were counted: {dropped}"
    );
    assert_eq!(
        metric(&client, &serve, "choreo_worker_restarts_total").await,
        0.0,
        "no worker died"
    );
    eprintln!("{dropped} log lines dropped; both jobs succeeded; /readyz 200");
    serve.assert_alive();
}
