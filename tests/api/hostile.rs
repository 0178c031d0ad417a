//! Hostile uploads and oversized job requests, against a real `choreo serve` process
//! where memory, CPU and signals are what is measured, and the in-process service otherwise.
use crate::helpers::{expect_problem, spawn_app, spawn_app_with};
use crate::hostile_files as files;
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Budget of peak resident memory above idle for any upload within the limits.
const MEMORY_BUDGET_KB: u64 = 300 * 1024;

/// A `choreo serve` child process on port 0 with its own data dir.
pub(crate) struct Serve {
    child: Child,
    pub(crate) url: String,
    _dir: tempfile::TempDir,
}

impl Serve {
    /// Starts the release binary with `env` (`CHOREO_*` settings) and waits for its address.
    pub(crate) fn start(env: &[(&str, &str)]) -> Self {
        Self::start_with(env, None)
    }

    /// [`Serve::start`] serving the models in `models` (none: no model).
    pub(crate) fn start_with(env: &[(&str, &str)], models: Option<&std::path::Path>) -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let models = models.map_or_else(|| dir.path().join("no-models"), |m| m.to_path_buf());
        let mut child = Command::new(env!("CARGO_BIN_EXE_choreo"))
            .args(["serve", "--bind", "127.0.0.1:0", "--workers", "1"])
            .arg("--data-dir")
            .arg(dir.path().join("data"))
            .arg("--models-dir")
            .arg(models)
            .envs(env.iter().copied())
            .env("CHOREO_LOG_LEVEL", "warn")
            .current_dir(dir.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start choreo serve");
        let stdout = child.stdout.take().expect("stdout");
        let mut line = String::new();
        BufReader::new(stdout)
            .read_line(&mut line)
            .expect("read the listening line");
        let url = crate::helpers::listening_base(&line);
        Self {
            child,
            url,
            _dir: dir,
        }
    }

    pub(crate) fn pid(&self) -> u32 {
        self.child.id()
    }

    /// A field of /proc/<pid>/status, in kB.
    pub(crate) fn status_kb(&self, field: &str) -> u64 {
        let status =
            std::fs::read_to_string(format!("/proc/{}/status", self.pid())).expect("proc status");
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

    /// Whether the process is still running.
    pub(crate) fn alive(&mut self) -> bool {
        self.child.try_wait().expect("try_wait").is_none()
    }

    /// CPU time used so far (user + system), in clock ticks.
    fn cpu_ticks(&self) -> u64 {
        let stat =
            std::fs::read_to_string(format!("/proc/{}/stat", self.pid())).expect("proc stat");
        // Fields after the parenthesised command name; utime and stime are the 14th and 15th.
        let rest = stat.rsplit_once(')').map(|(_, r)| r).unwrap_or("");
        let fields: Vec<&str> = rest.split_whitespace().collect();
        fields[11].parse::<u64>().unwrap_or(0) + fields[12].parse::<u64>().unwrap_or(0)
    }

    fn sigterm(&self) {
        // SAFETY: kill only sends a signal to our own child.
        let rc = unsafe { libc::kill(self.pid() as libc::pid_t, libc::SIGTERM) };
        assert_eq!(rc, 0, "SIGTERM");
    }

    /// Waits for the process to end; `None` if it is still running after `limit`.
    fn wait_exit(&mut self, limit: Duration) -> Option<Duration> {
        let started = Instant::now();
        while started.elapsed() < limit {
            if self.child.try_wait().expect("try_wait").is_some() {
                return Some(started.elapsed());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

async fn upload(
    client: &reqwest::Client,
    url: &str,
    name: &str,
    bytes: Vec<u8>,
) -> reqwest::Result<reqwest::Response> {
    let form = reqwest::multipart::Form::new().part(
        "file",
        reqwest::multipart::Part::bytes(bytes).file_name(name.to_string()),
    );
    client
        .post(format!("{url}/v1/songs"))
        .multipart(form)
        .send()
        .await
}

fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .expect("client")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_uploads_get_a_quick_answer_in_bounded_memory() {
    let serve = Serve::start(&[]);
    let client = client();
    assert_eq!(
        client
            .get(format!("{}/healthz", serve.url))
            .send()
            .await
            .expect("healthz")
            .status(),
        StatusCode::OK
    );
    let idle = serve.status_kb("VmHWM");
    let cases: [(&str, Vec<u8>, StatusCode, &str); 3] = [
        (
            "hostile.m4a",
            files::the_40_byte_m4a(),
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "audio-undecodable",
        ),
        (
            "silence-384k.flac",
            files::silent_flac(384_000, 1740, true),
            StatusCode::UNPROCESSABLE_ENTITY,
            "song-too-long",
        ),
        (
            "silence-384k-undeclared.flac",
            files::silent_flac(384_000, 1740, false),
            StatusCode::UNPROCESSABLE_ENTITY,
            "song-too-long",
        ),
    ];
    for (name, bytes, status, code) in cases {
        let size = bytes.len();
        let started = Instant::now();
        let response = upload(&client, &serve.url, name, bytes)
            .await
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let took = started.elapsed();
        expect_problem(response, status, code).await;
        let peak = serve.status_kb("VmHWM");
        eprintln!(
            "{name} ({size} bytes): {status} in {took:?}; peak RSS {} MB above idle",
            peak.saturating_sub(idle) / 1024
        );
        assert!(took < Duration::from_secs(30), "{name} took {took:?}");
        assert!(
            peak.saturating_sub(idle) <= MEMORY_BUDGET_KB,
            "{name}: peak RSS {peak} kB, idle {idle} kB"
        );
    }
    // Nothing is left running: the process idles.
    let before = serve.cpu_ticks();
    tokio::time::sleep(Duration::from_secs(1)).await;
    let ticks = serve.cpu_ticks() - before;
    assert!(
        ticks < 30,
        "{ticks} CPU ticks in an idle second after the uploads"
    );
}

/// Uploads `bytes` (asserting 201) and returns the song id.
async fn upload_ok(client: &reqwest::Client, url: &str, name: &str, bytes: Vec<u8>) -> String {
    let response = upload(client, url, name, bytes).await.expect("upload");
    let status = response.status();
    let body: Value = response.json().await.expect("song json");
    assert_eq!(status, StatusCode::CREATED, "{body}");
    body["id"].as_str().expect("id").to_string()
}

/// Polls a song until its analysis is `want` (or terminal), within `limit`.
async fn wait_analysis(
    client: &reqwest::Client,
    url: &str,
    id: &str,
    want: &str,
    limit: Duration,
) -> String {
    let deadline = Instant::now() + limit;
    loop {
        let song: Value = client
            .get(format!("{url}/v1/songs/{id}"))
            .send()
            .await
            .expect("GET song")
            .json()
            .await
            .expect("json");
        let status = song["analysis_status"].as_str().unwrap_or("").to_string();
        if status == want || status == "succeeded" || status == "failed" {
            return status;
        }
        assert!(
            Instant::now() < deadline,
            "analysis still {status} after {limit:?}: {song}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_15_minute_384_khz_song_is_stored_and_analysed_in_bounded_memory() {
    // Within every limit, at the highest rate accepted: it once took 1.3 GB to upload and 1.4 GB
    // to analyse, decoded whole at 384 kHz each time.
    // A budget that a busy machine cannot run out of: memory is what is measured here.
    let serve = Serve::start(&[("CHOREO_AUDIO_TIMEOUT_S", "600")]);
    let client = client();
    let idle = serve.status_kb("VmHWM");
    let started = Instant::now();
    let id = upload_ok(
        &client,
        &serve.url,
        "long-384k.flac",
        files::silent_flac(384_000, 899, true),
    )
    .await;
    let uploaded = started.elapsed();
    let upload_peak = serve.status_kb("VmHWM").saturating_sub(idle);
    let status = wait_analysis(
        &client,
        &serve.url,
        &id,
        "succeeded",
        Duration::from_secs(240),
    )
    .await;
    assert_eq!(status, "succeeded");
    let peak = serve.status_kb("VmHWM").saturating_sub(idle);
    eprintln!(
        "899 s at 384 kHz: stored in {uploaded:?} (+{} MB), analysed after {:?} (+{} MB peak above idle)",
        upload_peak / 1024,
        started.elapsed(),
        peak / 1024
    );
    assert!(peak <= MEMORY_BUDGET_KB, "peak RSS {peak} kB above idle");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_decode_past_its_budget_is_abandoned_and_stops_burning_cpu() {
    // 1740 s of 384 kHz samples, no declared length, and limits that let the decode run.
    let serve = Serve::start(&[
        ("CHOREO_MAX_DURATION_S", "3600"),
        ("CHOREO_AUDIO_TIMEOUT_S", "0.5"),
    ]);
    let client = client();
    let started = Instant::now();
    let response = upload(
        &client,
        &serve.url,
        "slow.flac",
        files::silent_flac(384_000, 1740, false),
    )
    .await
    .expect("upload");
    let body = expect_problem(response, StatusCode::UNPROCESSABLE_ENTITY, "audio-timeout").await;
    let took = started.elapsed();
    eprintln!("abandoned after {took:?}: {}", body["detail"]);
    assert!(took < Duration::from_secs(10), "{took:?}");
    let before = serve.cpu_ticks();
    tokio::time::sleep(Duration::from_secs(1)).await;
    let ticks = serve.cpu_ticks() - before;
    assert!(
        ticks < 30,
        "the abandoned decode still runs: {ticks} CPU ticks in a second"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_stops_the_server_while_a_decode_is_in_flight() {
    let mut serve = Serve::start(&[
        ("CHOREO_MAX_DURATION_S", "3600"),
        ("CHOREO_AUDIO_TIMEOUT_S", "600"),
    ]);
    let client = client();
    let url = serve.url.clone();
    let base = serve.cpu_ticks();
    let in_flight = tokio::spawn(async move {
        upload(
            &client,
            &url,
            "slow.flac",
            files::silent_flac(384_000, 1740, false),
        )
        .await
    });
    // Wait until the decode (about 5 s of CPU) has run for 0.2 s of CPU, however busy the machine.
    let deadline = Instant::now() + Duration::from_secs(30);
    while serve.cpu_ticks() - base < 20 {
        assert!(Instant::now() < deadline, "the decode never started");
        assert!(
            !in_flight.is_finished(),
            "the upload was answered before the decode could be stopped"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    serve.sigterm();
    let exited = serve.wait_exit(Duration::from_secs(10));
    let exited = exited.unwrap_or_else(|| {
        panic!("choreo serve still runs 10 s after SIGTERM with an upload decode in flight")
    });
    eprintln!("exited {exited:?} after SIGTERM");
    // The upload got an answer (503: try again) or its connection closed; never a hang.
    match in_flight.await.expect("upload task") {
        Ok(response) => {
            let status = response.status();
            let body: Value = response.json().await.unwrap_or(Value::Null);
            assert_eq!(status, StatusCode::SERVICE_UNAVAILABLE, "{body}");
            assert_eq!(body["code"], "audio-cancelled");
        }
        Err(e) => eprintln!("upload connection ended: {e}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn job_requests_are_capped_in_size() {
    let app = spawn_app_with(|c| c.max_job_body_bytes = 64 * 1024).await;
    let song_id = "01234567-89ab-7def-8123-456789abcdef";
    // Over the body limit: refused before it is read whole, and the connection is closed.
    let big = format!(
        "{{\"song_id\": \"{song_id}\", \"model\": \"m\", \"pad\": \"{}\"}}",
        "x".repeat(100 * 1024)
    );
    let response = app.post_job_raw(big, "application/json", None).await;
    assert_eq!(
        response
            .headers()
            .get("connection")
            .and_then(|v| v.to_str().ok()),
        Some("close")
    );
    expect_problem(response, StatusCode::PAYLOAD_TOO_LARGE, "body-too-large").await;
    app.stop().await;

    let app = spawn_app().await;
    let pose = json!({"time_s": 1.0, "joints": vec![[0.0, 0.0, 0.0]; 23]});
    let poses = vec![pose; choreo::api::jobs::MAX_KEY_POSES + 1];
    let body = expect_problem(
        app.post_job(
            &json!({"song_id": song_id, "model": "m", "key_poses": poses}),
            None,
        )
        .await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid-field",
    )
    .await;
    assert_eq!(body["field"], "key_poses");
    let frames = vec![vec![[0.0, 1.0, 0.0]; 23]; choreo::api::jobs::MAX_SEED_FRAMES + 1];
    let body = expect_problem(
        app.post_job(&json!({"song_id": song_id, "model": "m", "seed_motion": {"fps": 25.0, "positions": frames}}), None).await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid-field",
    )
    .await;
    assert_eq!(body["field"], "seed_motion.positions");
    // The default limit takes the largest seed motion allowed, written with full precision.
    let frames = vec![
        vec![
            [
                0.123_456_789_012_345_67,
                1.234_567_890_123_456_7,
                -0.123_456_789_012_345_67
            ];
            23
        ];
        choreo::api::jobs::MAX_SEED_FRAMES
    ];
    let response = app.post_job(&json!({"song_id": song_id, "model": "m", "seed_motion": {"fps": 25.0, "positions": frames}}), None).await;
    // Past the size checks, it fails on the song that does not exist.
    expect_problem(response, StatusCode::NOT_FOUND, "song-not-found").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_stops_the_server_while_an_analysis_job_decodes() {
    let mut serve = Serve::start(&[]);
    let client = client();
    let id = upload_ok(
        &client,
        &serve.url,
        "long-384k.flac",
        files::silent_flac(384_000, 899, true),
    )
    .await;
    // Decoding 899 s at 384 kHz for analysis takes seconds: stop the server while it runs.
    assert_eq!(
        wait_analysis(&client, &serve.url, &id, "running", Duration::from_secs(60)).await,
        "running"
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    serve.sigterm();
    let exited = serve.wait_exit(Duration::from_secs(10));
    let exited = exited.unwrap_or_else(|| {
        panic!("choreo serve still runs 10 s after SIGTERM with an analysis in flight")
    });
    eprintln!("exited {exited:?} after SIGTERM during the analysis");
}
