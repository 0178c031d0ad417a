//! `spawn_app()`: the real service on port 0 with a temporary data dir, and typed helpers.
use choreo::api::Server;
use choreo::config::Config;
use reqwest::multipart::{Form, Part};
use reqwest::{Response, StatusCode};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The five permissively licensed songs beside the repository; tests need them.
pub fn shared_audio() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/audio");
    assert!(
        dir.join("trumpet_loop_90bpm.ogg").is_file(),
        "{} is missing: the API tests upload the songs in ../shared/audio (CI={})",
        dir.display(),
        std::env::var("CI").unwrap_or_default()
    );
    dir
}

/// A shared song by file name.
pub fn song(name: &str) -> PathBuf {
    shared_audio().join(name)
}

/// The short song most tests upload (5.3 s).
pub fn short_song() -> PathBuf {
    song("trumpet_loop_90bpm.ogg")
}

static FIXTURES: Mutex<()> = Mutex::new(());

/// `short_song()` converted to `ext` (wav, flac, mp3, m4a) with ffmpeg, made once per build.
pub fn fixture(ext: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("audio-fixtures");
    let out = dir.join(format!("trumpet.{ext}"));
    let _guard = FIXTURES.lock().unwrap_or_else(|p| p.into_inner());
    if out.is_file() {
        return out;
    }
    std::fs::create_dir_all(&dir).expect("fixture dir");
    let codec: &[&str] = match ext {
        "wav" => &["-c:a", "pcm_s16le"],
        "flac" => &["-c:a", "flac"],
        "mp3" => &["-c:a", "libmp3lame", "-b:a", "128k"],
        "m4a" => &["-c:a", "aac", "-b:a", "128k"],
        other => panic!("no fixture recipe for {other}"),
    };
    let partial = dir.join(format!("partial-trumpet.{ext}"));
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-i"])
        .arg(short_song())
        .args(codec)
        .arg(&partial)
        .status()
        .expect("ffmpeg is needed to make test fixtures: run `scripts/setup.sh --test` (or `make test`)");
    assert!(status.success(), "ffmpeg failed to make {}", out.display());
    std::fs::rename(&partial, &out).expect("fixture rename");
    out
}

/// A running service and a client for it.
pub struct TestApp {
    pub addr: std::net::SocketAddr,
    pub client: reqwest::Client,
    pub data_dir: tempfile::TempDir,
    pub server: Option<Server>,
    pub token: Option<String>,
}

/// The test configuration: port 0, a temporary data dir, no models, short leases.
pub fn test_config(data_dir: &Path) -> Config {
    Config {
        bind: "127.0.0.1:0".into(),
        data_dir: data_dir.to_path_buf(),
        models_dir: data_dir.join("no-models"),
        workers: 2,
        heartbeat_s: 0.2,
        lease_s: 5.0,
        poll_s: 0.1,
        ..Config::default()
    }
}

/// Starts the service with the test configuration.
pub async fn spawn_app() -> TestApp {
    spawn_app_with(|_| {}).await
}

/// Starts the service with the test configuration changed by `edit`.
pub async fn spawn_app_with(edit: impl FnOnce(&mut Config)) -> TestApp {
    choreo::telemetry::init_tracing(choreo::config::LogFormat::Pretty, "warn");
    let data_dir = tempfile::tempdir().expect("tempdir");
    let mut config = test_config(data_dir.path());
    edit(&mut config);
    config.validate().expect("valid test config");
    let token = config.auth_token.as_ref().map(|t| t.expose().to_string());
    let server = Server::start(config).await.expect("service starts");
    TestApp {
        addr: server.addr(),
        client: reqwest::Client::builder()
            .timeout(Duration::from_secs(60))
            .build()
            .expect("client"),
        data_dir,
        server: Some(server),
        token,
    }
}

impl TestApp {
    /// The `capabilities` of model `id` as `GET /v1/models` lists them (panics when it is not listed).
    pub async fn capabilities(&self, id: &str) -> Value {
        let models: Value = self.get("/v1/models").await.json().await.expect("models");
        let listed = models
            .as_array()
            .or_else(|| models["models"].as_array())
            .expect("model list")
            .iter()
            .find(|m| m["id"] == id)
            .cloned();
        listed.unwrap_or_else(|| panic!("{id} is not listed: {models}"))["capabilities"].clone()
    }

    /// `http://addr{path}`.
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addr, path)
    }

    fn auth(&self, request: reqwest::RequestBuilder) -> reqwest::RequestBuilder {
        match &self.token {
            Some(token) => request.bearer_auth(token),
            None => request,
        }
    }

    /// GET with the configured token.
    pub async fn get(&self, path: &str) -> Response {
        self.auth(self.client.get(self.url(path)))
            .send()
            .await
            .expect("GET")
    }

    /// DELETE with the configured token.
    pub async fn delete(&self, path: &str) -> Response {
        self.auth(self.client.delete(self.url(path)))
            .send()
            .await
            .expect("DELETE")
    }

    /// POSTs a multipart form to `/v1/songs`.
    pub async fn upload_form(&self, form: Form) -> Response {
        self.auth(self.client.post(self.url("/v1/songs")))
            .multipart(form)
            .send()
            .await
            .expect("upload")
    }

    /// Uploads bytes as field `file` named `filename`.
    pub async fn upload_bytes(&self, filename: &str, bytes: Vec<u8>) -> Response {
        // The name goes on the wire as given (no percent-encoding), as a hostile client would send it.
        let form = Form::new()
            .percent_encode_noop()
            .part("file", Part::bytes(bytes).file_name(filename.to_string()));
        self.upload_form(form).await
    }

    /// Uploads a file under its own name.
    pub async fn upload(&self, path: &Path) -> Response {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("song")
            .to_string();
        self.upload_bytes(&name, std::fs::read(path).expect("read song"))
            .await
    }

    /// Uploads a file and returns the song JSON, asserting 201 or 200.
    pub async fn upload_ok(&self, path: &Path) -> Value {
        let response = self.upload(path).await;
        let status = response.status();
        let body: Value = response.json().await.expect("song json");
        assert!(
            status == StatusCode::CREATED || status == StatusCode::OK,
            "{status}: {body}"
        );
        body
    }

    /// POSTs raw bytes to `/v1/jobs` with a content type and optional idempotency key.
    pub async fn post_job_raw(
        &self,
        body: impl Into<reqwest::Body>,
        content_type: &str,
        key: Option<&str>,
    ) -> Response {
        let mut request = self
            .auth(self.client.post(self.url("/v1/jobs")))
            .header("content-type", content_type)
            .body(body);
        if let Some(key) = key {
            request = request.header("idempotency-key", key);
        }
        request.send().await.expect("POST /v1/jobs")
    }

    /// POSTs JSON to `/v1/jobs`.
    pub async fn post_job(&self, body: &Value, key: Option<&str>) -> Response {
        self.post_job_raw(body.to_string(), "application/json", key)
            .await
    }

    /// A job's JSON.
    pub async fn job(&self, id: &str) -> Value {
        let response = self.get(&format!("/v1/jobs/{id}")).await;
        assert_eq!(response.status(), StatusCode::OK);
        response.json().await.expect("job json")
    }

    /// Polls a job until it is terminal.
    pub async fn wait_job(&self, id: &str) -> Value {
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            let job = self.job(id).await;
            if ["succeeded", "failed", "cancelled"].contains(&job["status"].as_str().unwrap_or(""))
            {
                return job;
            }
            assert!(
                Instant::now() < deadline,
                "job {id} not finished after 120 s: {job}"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Submits a job (202 expected), waits for it and asserts it succeeded; returns its id.
    pub async fn dance(&self, body: &Value) -> String {
        let response = self.post_job(body, None).await;
        assert_eq!(response.status(), StatusCode::ACCEPTED);
        let job: Value = response.json().await.expect("job");
        let id = job["id"].as_str().expect("job id").to_string();
        let done = self.wait_job(&id).await;
        assert_eq!(done["status"], "succeeded", "{done}");
        id
    }

    /// The analyze job of a song.
    pub async fn analyze_job_of(&self, song_id: &str) -> Value {
        let page: Value = self
            .get("/v1/jobs?limit=100")
            .await
            .json()
            .await
            .expect("jobs json");
        page["items"]
            .as_array()
            .expect("items")
            .iter()
            .find(|j| j["kind"] == "analyze" && j["song_id"] == song_id)
            .cloned()
            .unwrap_or_else(|| panic!("no analyze job for song {song_id}: {page}"))
    }

    /// Stops the service gracefully.
    pub async fn stop(mut self) {
        if let Some(server) = self.server.take() {
            server.stop().await;
        }
    }
}

/// Reads a problem+json body, asserting status and code.
pub async fn expect_problem(response: Response, status: StatusCode, code: &str) -> Value {
    let got = response.status();
    let content_type = response
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let text = response.text().await.expect("problem body");
    assert_eq!(got, status, "expected {status} {code}, got: {text}");
    assert_eq!(content_type, "application/problem+json", "{text}");
    let body: Value = serde_json::from_str(&text).expect("problem json");
    assert_eq!(body["code"], code, "{body}");
    assert_eq!(body["status"], status.as_u16());
    assert!(
        body["detail"].as_str().is_some_and(|d| !d.is_empty()),
        "{body}"
    );
    body
}

/// Spawns a separately started `choreo` process (stdout piped) and returns it with its first
/// stdout line (`choreo listening on …`, `choreo worker running N workers`); the rest of its
/// stdout is drained so it never blocks on a full pipe.
pub async fn spawn_process(
    mut command: tokio::process::Command,
) -> (tokio::process::Child, String) {
    use tokio::io::AsyncBufReadExt;
    let mut child = command.spawn().expect("spawn choreo");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = tokio::io::BufReader::new(stdout).lines();
    let line = tokio::time::timeout(Duration::from_secs(60), lines.next_line())
        .await
        .expect("choreo printed its first line within 60 s")
        .expect("read stdout")
        .expect("a line");
    tokio::spawn(async move { while let Ok(Some(_)) = lines.next_line().await {} });
    (child, line)
}

/// The base URL in a `choreo serve` process's first line.
pub fn listening_base(line: &str) -> String {
    line.trim()
        .strip_prefix("choreo listening on ")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_string()
}

/// Uploads `bytes` as `name` to a separately started service at `base`: the song, which is new
/// (201 Created).
pub async fn upload_to(client: &reqwest::Client, base: &str, bytes: Vec<u8>, name: &str) -> Value {
    let form = Form::new().part("file", Part::bytes(bytes).file_name(name.to_string()));
    let response = client
        .post(format!("{base}/v1/songs"))
        .multipart(form)
        .send()
        .await
        .expect("upload");
    let status = response.status();
    let body = response.text().await.expect("upload body");
    assert_eq!(status, StatusCode::CREATED, "{body}");
    serde_json::from_str(&body).expect("song json")
}
