//! The S3 artifact store against a local S3-compatible server (moto, from PyPI, installed by
//! `scripts/setup.sh --test` into `.venv-moto`): an API process and a worker process with
//! separate data dirs, as on two hosts, share PostgreSQL and a bucket. The worker fetches the
//! song from the bucket, publishes the dance's files there, and the API serves them from it.
use crate::common_models::models_dir;
use crate::helpers::{listening_base, short_song, spawn_process as spawn, upload_to};
use crate::postgres::Postgres;
use object_store::ObjectStoreExt;
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub(crate) const BUCKET: &str = "choreo-test";
pub(crate) const PREFIX: &str = "run";

/// A moto S3 server on a free loopback port, killed on drop.
pub(crate) struct Moto {
    child: Child,
    pub(crate) endpoint: String,
}

impl Moto {
    pub(crate) fn start() -> Self {
        let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv-moto/bin/moto_server");
        assert!(
            bin.is_file(),
            "{} is missing: run `bash scripts/setup.sh --test` (it installs moto[server] there) (CI={})",
            bin.display(),
            std::env::var("CI").unwrap_or_default()
        );
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .expect("free port")
            .local_addr()
            .expect("addr")
            .port();
        let child = Command::new(bin)
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn moto_server");
        Self {
            child,
            endpoint: format!("http://127.0.0.1:{port}"),
        }
    }

    /// Makes the test bucket once moto answers (it accepts unsigned requests), within 60 s.
    pub(crate) async fn make_bucket(&self, client: &reqwest::Client) {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            match client
                .put(format!("{}/{BUCKET}", self.endpoint))
                .send()
                .await
            {
                Ok(r) if r.status().is_success() => break,
                other => assert!(
                    Instant::now() < deadline,
                    "moto_server did not come up in 60 s: {other:?}"
                ),
            }
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
}

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `choreo <args>` on its own data dir, with the shared database and bucket.
pub(crate) fn choreo(
    args: &[&str],
    data_dir: &Path,
    database_url: &str,
    endpoint: &str,
) -> tokio::process::Command {
    let mut c = tokio::process::Command::new(env!("CARGO_BIN_EXE_choreo"));
    c.args(args)
        .arg("--data-dir")
        .arg(data_dir)
        .arg("--models-dir")
        .arg(models_dir())
        .env("CHOREO_DATABASE_URL", database_url)
        .env("CHOREO_ARTIFACTS_URL", format!("s3://{BUCKET}/{PREFIX}"))
        .env("CHOREO_S3_ENDPOINT", endpoint)
        .env("AWS_ACCESS_KEY_ID", "test")
        .env("AWS_SECRET_ACCESS_KEY", "test")
        .env("CHOREO_POLL_S", "0.2")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .kill_on_drop(true);
    c
}

/// Every file under `dir`, relative to it.
pub(crate) fn files_under(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if let Ok(rel) = path.strip_prefix(dir) {
                out.push(rel.display().to_string());
            }
        }
    }
    out
}

pub(crate) async fn wait_job(client: &reqwest::Client, base: &str, id: &str) -> Value {
    let deadline = Instant::now() + Duration::from_secs(180);
    loop {
        let job: Value = client
            .get(format!("{base}/v1/jobs/{id}"))
            .send()
            .await
            .expect("GET job")
            .json()
            .await
            .expect("json");
        if ["succeeded", "failed", "cancelled"].contains(&job["status"].as_str().unwrap_or("")) {
            return job;
        }
        assert!(
            Instant::now() < deadline,
            "job {id} not finished after 180 s: {job}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn api_and_worker_on_separate_disks_share_songs_and_results_through_a_bucket() {
    let server = tokio::task::spawn_blocking(Postgres::start)
        .await
        .expect("start postgres");
    let moto = Moto::start();
    let client = reqwest::Client::new();
    moto.make_bucket(&client).await;

    let (api_dir, worker_dir) = (
        tempfile::tempdir().expect("tempdir"),
        tempfile::tempdir().expect("tempdir"),
    );
    let (_api, line) = spawn(choreo(
        &["serve", "--no-workers", "--bind", "127.0.0.1:0"],
        api_dir.path(),
        &server.url(),
        &moto.endpoint,
    ))
    .await;
    let base = listening_base(&line);
    let (_worker, line) = spawn(choreo(
        &["worker", "--workers", "1"],
        worker_dir.path(),
        &server.url(),
        &moto.endpoint,
    ))
    .await;
    assert_eq!(line, "choreo worker running 1 workers");

    let bytes = std::fs::read(short_song()).expect("song");
    let song = upload_to(&client, &base, bytes.clone(), "t.ogg").await;
    let song_id = song["id"].as_str().expect("id").to_string();
    // Read back with signed requests of our own (moto refuses anonymous reads of private objects).
    let bucket = object_store::aws::AmazonS3Builder::new()
        .with_bucket_name(BUCKET)
        .with_region("us-east-1")
        .with_endpoint(&moto.endpoint)
        .with_allow_http(true)
        .with_access_key_id("test")
        .with_secret_access_key("test")
        .build()
        .expect("bucket client");
    let key = object_store::path::Path::from(format!("{PREFIX}/songs/{song_id}.ogg"));
    let in_bucket = bucket
        .get(&key)
        .await
        .expect("the song is in the bucket")
        .bytes()
        .await
        .expect("object");
    assert_eq!(
        in_bucket.as_ref(),
        bytes.as_slice(),
        "the bucket holds the upload's bytes"
    );

    let response = client
        .post(format!("{base}/v1/jobs"))
        .json(&json!({"song_id": song_id, "model": "dance-revolution", "seed": 3}))
        .send()
        .await
        .expect("POST job");
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let job: Value = response.json().await.expect("job");
    let job_id = job["id"].as_str().expect("id").to_string();
    let done = wait_job(&client, &base, &job_id).await;
    assert_eq!(done["status"], "succeeded", "{done}");

    // The worker read the song from the bucket into its own disk; the API host never saw the
    // results on disk, so what it serves came from the bucket.
    let worker_files = files_under(worker_dir.path());
    assert!(
        worker_files.contains(&format!("songs/{song_id}.ogg")),
        "{worker_files:?}"
    );
    let api_files = files_under(api_dir.path());
    assert!(
        !api_files.iter().any(|f| f.starts_with("jobs/")),
        "{api_files:?}"
    );
    for file in [
        "motion.bvh",
        "motion.json",
        "motion.glb",
        "report.json",
        "preview.png",
    ] {
        let served = client
            .get(format!("{base}/v1/jobs/{job_id}/{file}"))
            .send()
            .await
            .expect("GET result");
        assert_eq!(served.status(), StatusCode::OK, "{file}");
        let served = served.bytes().await.expect("body");
        let on_worker = std::fs::read(worker_dir.path().join("jobs").join(&job_id).join(file))
            .expect("worker's file");
        assert_eq!(
            served.as_ref(),
            on_worker.as_slice(),
            "{file} served from the bucket is the file the worker wrote"
        );
        // A part of it, cut from the bucket's stream.
        let part = client
            .get(format!("{base}/v1/jobs/{job_id}/{file}"))
            .header("range", "bytes=100-199")
            .send()
            .await
            .expect("GET part");
        assert_eq!(part.status(), StatusCode::PARTIAL_CONTENT, "{file}");
        assert_eq!(
            part.bytes().await.expect("part").as_ref(),
            &on_worker[100..200],
            "{file}: bytes 100-199 from the bucket"
        );
        let key = object_store::path::Path::from(format!("{PREFIX}/jobs/{job_id}/{file}"));
        let stored = bucket
            .get(&key)
            .await
            .expect("the result is in the bucket")
            .bytes()
            .await
            .expect("object");
        assert_eq!(
            stored.as_ref(),
            on_worker.as_slice(),
            "{file} in the bucket"
        );
    }
    // A second API host with an empty disk serves the song's audio (fetched from the bucket).
    let second_dir = tempfile::tempdir().expect("tempdir");
    let (_second, line) = spawn(choreo(
        &["serve", "--no-workers", "--bind", "127.0.0.1:0"],
        second_dir.path(),
        &server.url(),
        &moto.endpoint,
    ))
    .await;
    let second = listening_base(&line);
    let audio = client
        .get(format!("{second}/v1/songs/{song_id}/audio"))
        .send()
        .await
        .expect("GET audio");
    assert_eq!(audio.status(), StatusCode::OK);
    assert_eq!(
        audio.bytes().await.expect("body").as_ref(),
        bytes.as_slice(),
        "the second API host serves the upload's bytes"
    );
    let tail = client
        .get(format!("{second}/v1/songs/{song_id}/audio"))
        .header("range", "bytes=-50")
        .send()
        .await
        .expect("GET audio's tail");
    assert_eq!(tail.status(), StatusCode::PARTIAL_CONTENT);
    assert_eq!(
        tail.bytes().await.expect("tail").as_ref(),
        &bytes[bytes.len() - 50..],
        "the last 50 bytes of the upload"
    );
    let second_files = files_under(second_dir.path());
    assert!(
        second_files.contains(&format!("songs/{song_id}.ogg")),
        "{second_files:?}"
    );
    // Every write went through a temp file and a rename, or a single PUT: nothing partial is left.
    for f in worker_files
        .iter()
        .chain(api_files.iter())
        .chain(second_files.iter())
    {
        assert!(
            !f.contains(".partial-") && !f.starts_with("tmp/"),
            "left behind: {f}"
        );
    }
}
