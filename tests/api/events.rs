//! `GET /v1/jobs/{id}/events`: a real job's server-sent events, read by a small SSE client over
//! real HTTP. Every stage in order, a dropped connection resumed with `Last-Event-ID` getting
//! exactly the lines it missed, `done` as `GET /v1/jobs/{id}` says, the stream closed when the
//! server stops; on SQLite in process, and on PostgreSQL with an API-only process and a worker
//! process apart.
use crate::common_models::models_dir;
use crate::helpers::{
    expect_problem, listening_base, short_song, spawn_app_with, spawn_process as spawn,
    test_config, upload_to, TestApp,
};
use crate::postgres::Postgres;
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::path::Path;
use std::process::Stdio;
use std::time::Duration;

/// Longest a test waits for one event (a whole dance-revolution job takes a few seconds).
const EVENT_WAIT: Duration = Duration::from_secs(120);

/// One server-sent event.
#[derive(Clone, Debug, PartialEq)]
struct Sse {
    id: Option<String>,
    event: String,
    data: Value,
}

/// A minimal SSE client (the text/event-stream framing, comments skipped) over reqwest.
struct SseClient {
    response: reqwest::Response,
    buffer: String,
}

impl SseClient {
    async fn open(client: &reqwest::Client, url: &str, last_event_id: Option<&str>) -> Self {
        let mut request = client.get(url).header("accept", "text/event-stream");
        if let Some(id) = last_event_id {
            request = request.header("last-event-id", id);
        }
        let response = request.send().await.expect("GET events");
        assert_eq!(response.status(), StatusCode::OK);
        let content_type = response
            .headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("");
        assert!(
            content_type.starts_with("text/event-stream"),
            "{content_type}"
        );
        Self {
            response,
            buffer: String::new(),
        }
    }

    /// The next event, or `None` when the server closed the stream.
    async fn next(&mut self) -> Option<Sse> {
        loop {
            if let Some(end) = self.buffer.find("\n\n") {
                let block: String = self.buffer.drain(..end + 2).collect();
                let (mut id, mut event, mut data) = (None, "message".to_string(), String::new());
                for line in block.lines() {
                    if line.starts_with(':') {
                        continue;
                    }
                    let (field, value) = line.split_once(':').unwrap_or((line, ""));
                    let value = value.strip_prefix(' ').unwrap_or(value);
                    match field {
                        "id" => id = Some(value.to_string()),
                        "event" => event = value.to_string(),
                        "data" => data.push_str(value),
                        _ => {}
                    }
                }
                if data.is_empty() {
                    continue; // a comment-only block (keep-alive)
                }
                let data = serde_json::from_str(&data).expect("event data is JSON");
                return Some(Sse { id, event, data });
            }
            let chunk = tokio::time::timeout(EVENT_WAIT, self.response.chunk())
                .await
                .expect("an event within the wait")
                .expect("read the stream")?;
            self.buffer
                .push_str(std::str::from_utf8(&chunk).expect("UTF-8 stream"));
        }
    }

    /// Every event up to and including `done`; asserts the stream then closes.
    async fn until_done(&mut self) -> Vec<Sse> {
        let mut events = Vec::new();
        loop {
            let event = self.next().await.expect("the stream ends only after done");
            let done = event.event == "done";
            events.push(event);
            if done {
                assert_eq!(self.next().await, None, "the stream closes after done");
                return events;
            }
        }
    }
}

fn ids(events: &[Sse]) -> Vec<i64> {
    events
        .iter()
        .filter(|e| e.event != "done")
        .map(|e| e.id.as_deref().expect("id").parse().expect("numeric id"))
        .collect()
}

/// Checks a whole job's events: statuses queued → running → succeeded, stages entered in the
/// pipeline's order (each once), progress never backwards, ids increasing, `done` = the job.
fn assert_whole_history(events: &[Sse], job: &Value) -> Vec<String> {
    let ids = ids(events);
    assert!(ids.windows(2).all(|w| w[0] < w[1]), "ids increase: {ids:?}");
    let statuses: Vec<(Value, Value)> = events
        .iter()
        .filter(|e| e.event == "status")
        .map(|e| (e.data["from"].clone(), e.data["to"].clone()))
        .collect();
    assert_eq!(
        statuses,
        vec![
            (Value::Null, json!("queued")),
            (json!("queued"), json!("running")),
            (json!("running"), json!("succeeded")),
        ],
        "{events:#?}"
    );
    let mut stages: Vec<String> = Vec::new();
    let mut progress = 0.0;
    for e in events.iter().filter(|e| e.event == "progress") {
        assert_eq!(e.data["job_id"], job["id"]);
        let stage = e.data["stage"].as_str().expect("stage").to_string();
        let p = e.data["progress"].as_f64().expect("progress");
        assert!(
            (0.0..=1.0).contains(&p) && p >= progress,
            "{p} after {progress}"
        );
        progress = p;
        if stages.last() != Some(&stage) {
            stages.push(stage);
        }
    }
    let order: Vec<&str> = choreo::stage::Stage::ALL
        .iter()
        .map(|s| s.as_str())
        .collect();
    let places: Vec<usize> = stages
        .iter()
        .map(|s| order.iter().position(|o| o == s).expect("a known stage"))
        .collect();
    assert!(
        places.windows(2).all(|w| w[0] < w[1]),
        "stages in the pipeline's order, each once: {stages:?}"
    );
    let done = events.last().expect("events");
    assert_eq!(done.event, "done");
    assert_eq!(
        &done.data, job,
        "done carries the job as GET /v1/jobs/{{id}} does"
    );
    stages
}

/// The stages a dance-revolution job on the short song walks through, as the worker reports
/// them, which its events must show each of. (Its frame loop reports `generate` every 250 frames,
/// and the 5.3 s song has 132; the worker's render reports `export`, then `report`.)
const DANCE_REVOLUTION_STAGES: [&str; 7] = [
    "decode-audio",
    "analyze",
    "features",
    "encode",
    "beat-align",
    "export",
    "report",
];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_sse_client_sees_every_stage_in_order_and_resumes_after_a_drop_without_loss() {
    let app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let song = app.upload_ok(&short_song()).await;
    let response = app
        .post_job(
            &json!({"song_id": song["id"], "model": "dance-revolution", "seed": 3}),
            None,
        )
        .await;
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let id = response.json::<Value>().await.expect("job")["id"]
        .as_str()
        .expect("id")
        .to_string();
    let url = app.url(&format!("/v1/jobs/{id}/events"));

    // Read up to the first stage, then drop the connection while the job runs on.
    let mut first = SseClient::open(&app.client, &url, None).await;
    let mut before = Vec::new();
    loop {
        let event = first.next().await.expect("an event before done");
        assert_ne!(event.event, "done", "dropped before the job ends");
        let stage = event.event == "progress";
        before.push(event);
        if stage {
            break;
        }
    }
    drop(first);
    let last = before.last().and_then(|e| e.id.clone()).expect("an id");
    let mut resumed = SseClient::open(&app.client, &url, Some(&last)).await;
    let after = resumed.until_done().await;

    // The whole history, replayed to a new client after the job ended.
    let mut replay = SseClient::open(&app.client, &url, None).await;
    let whole = replay.until_done().await;
    let job = app.job(&id).await;
    assert_eq!(job["status"], "succeeded");
    let stages = assert_whole_history(&whole, &job);
    assert_eq!(stages, DANCE_REVOLUTION_STAGES, "every stage, in order");

    // Before the drop and after the resume is the whole history: nothing lost, nothing twice.
    let mut joined = before.clone();
    joined.extend(after.iter().cloned());
    assert_eq!(ids(&joined), ids(&whole));
    assert_eq!(joined, whole);

    // Resuming after the last line gets only `done`; an unknown job is a 404 problem.
    let last_line = ids(&whole).last().copied().expect("lines").to_string();
    let mut tail = SseClient::open(&app.client, &url, Some(&last_line)).await;
    let only_done = tail.until_done().await;
    assert_eq!(only_done.len(), 1);
    assert_eq!(only_done[0].event, "done");
    let unknown = app
        .get("/v1/jobs/0190e7a4-0000-7000-8000-000000000000/events")
        .await;
    expect_problem(unknown, StatusCode::NOT_FOUND, "job-not-found").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_open_stream_ends_when_the_server_stops() {
    choreo::telemetry::init_tracing(choreo::config::LogFormat::Pretty, "warn");
    let data_dir = tempfile::tempdir().expect("tempdir");
    let config = test_config(data_dir.path());
    // No workers: the song's analyze job stays queued, so its stream has no end of its own.
    let server = choreo::api::Server::start_api_only(config)
        .await
        .expect("starts");
    let app = TestApp {
        addr: server.addr(),
        client: reqwest::Client::new(),
        data_dir,
        server: Some(server),
        token: None,
    };
    let song = app.upload_ok(&short_song()).await;
    let job = app.analyze_job_of(song["id"].as_str().expect("id")).await;
    let url = app.url(&format!(
        "/v1/jobs/{}/events",
        job["id"].as_str().expect("id")
    ));
    let mut stream = SseClient::open(&app.client, &url, None).await;
    let first = stream.next().await.expect("the registration line");
    assert_eq!(
        (first.event.as_str(), &first.data["to"]),
        ("status", &json!("queued"))
    );
    let stopping = tokio::spawn(app.stop());
    let end = tokio::time::timeout(Duration::from_secs(10), stream.next())
        .await
        .expect("the stream ends within 10 s of the stop");
    assert_eq!(end, None);
    tokio::time::timeout(Duration::from_secs(10), stopping)
        .await
        .expect("the server stops with a stream open")
        .expect("stop");
}

/// A stream on a job that is deleted (here with its song, while it waits in the queue) ends:
/// the deletion's audit line is no event, so without this the client would wait forever.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_open_stream_ends_when_its_job_is_deleted() {
    let data_dir = tempfile::tempdir().expect("tempdir");
    let config = test_config(data_dir.path());
    // No workers: the song's analyze job stays queued until the song goes.
    let server = choreo::api::Server::start_api_only(config)
        .await
        .expect("starts");
    let app = TestApp {
        addr: server.addr(),
        client: reqwest::Client::new(),
        data_dir,
        server: Some(server),
        token: None,
    };
    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("id");
    let job = app.analyze_job_of(song_id).await;
    let url = app.url(&format!(
        "/v1/jobs/{}/events",
        job["id"].as_str().expect("id")
    ));
    let mut stream = SseClient::open(&app.client, &url, None).await;
    let first = stream.next().await.expect("the registration line");
    assert_eq!(first.event, "status");
    assert_eq!(
        app.delete(&format!("/v1/songs/{song_id}")).await.status(),
        StatusCode::NO_CONTENT
    );
    let end = tokio::time::timeout(Duration::from_secs(10), stream.next())
        .await
        .expect("the stream ends within 10 s of the deletion");
    assert_eq!(end, None);
    app.stop().await;
}

/// `choreo <args>` on PostgreSQL, sharing `data_dir`, with the committed models.
fn choreo(args: &[&str], data_dir: &Path, database_url: &str) -> tokio::process::Command {
    let mut c = tokio::process::Command::new(env!("CARGO_BIN_EXE_choreo"));
    c.args(args)
        .arg("--data-dir")
        .arg(data_dir)
        .arg("--models-dir")
        .arg(models_dir())
        .env("CHOREO_DATABASE_URL", database_url)
        .env("CHOREO_HEARTBEAT_S", "0.2")
        .env("CHOREO_POLL_S", "0.2")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .kill_on_drop(true);
    c
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_api_only_process_streams_the_stages_a_worker_process_runs_on_postgres() {
    let server = tokio::task::spawn_blocking(Postgres::start)
        .await
        .expect("start postgres");
    let url = server.url();
    let data = tempfile::tempdir().expect("tempdir");
    let (_api, line) = spawn(choreo(
        &["serve", "--no-workers", "--bind", "127.0.0.1:0"],
        data.path(),
        &url,
    ))
    .await;
    let base = listening_base(&line);
    let client = reqwest::Client::new();
    let bytes = std::fs::read(short_song()).expect("song");
    let song = upload_to(&client, &base, bytes, "trumpet.ogg").await;
    let job: Value = client
        .post(format!("{base}/v1/jobs"))
        .json(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": 5}))
        .send()
        .await
        .expect("submit")
        .json()
        .await
        .expect("job");
    let id = job["id"].as_str().expect("id").to_string();
    let events_url = format!("{base}/v1/jobs/{id}/events");
    // The stream is open before any worker exists: every line comes from the other process.
    let mut stream = SseClient::open(&client, &events_url, None).await;
    let first = stream.next().await.expect("registration line");
    assert_eq!(first.data["to"], "queued");
    let (_worker, line) = spawn(choreo(&["worker", "--workers", "1"], data.path(), &url)).await;
    assert_eq!(line, "choreo worker running 1 workers");
    let mut events = vec![first];
    events.extend(stream.until_done().await);
    let job: Value = client
        .get(format!("{base}/v1/jobs/{id}"))
        .send()
        .await
        .expect("job")
        .json()
        .await
        .expect("job json");
    let stages = assert_whole_history(&events, &job);
    assert_eq!(stages, DANCE_REVOLUTION_STAGES, "every stage, in order");
}
