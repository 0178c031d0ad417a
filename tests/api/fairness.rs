//! One client cannot lock out the others: a key's event streams are capped (429 past
//! `max_event_streams_per_key`, the connection closed) while another key is answered at once, a
//! stream ends after `event_stream_max_s` and resumes, and health probes are served past the
//! connection cap. The flood's figures are printed (`--nocapture`).
use crate::helpers::{expect_problem, short_song, spawn_app_with, TestApp};
use crate::tenants::{spawn_with, Db};
use choreo::config::Config;
use choreo::queue::KeyLimits;
use reqwest::multipart::{Form, Part};
use reqwest::StatusCode;
use serde_json::Value;
use std::time::{Duration, Instant};

/// An API-only service (no workers: jobs stay queued, and a stream on one never ends) with two
/// keys; returns it with the keys' secrets.
async fn api_only(edit: impl FnOnce(&mut Config)) -> (TestApp, String, String) {
    let app = spawn_with(Db::Sqlite, false, edit).await;
    let flood = app.key("flood", KeyLimits::default()).await;
    let other = app.key("other", KeyLimits::default()).await;
    (app.app, flood, other)
}

/// Uploads the short song as `secret`; returns the id of its analyze job, which stays queued.
async fn queued_job(app: &TestApp, secret: &str) -> String {
    let form = Form::new().part(
        "file",
        Part::bytes(std::fs::read(short_song()).expect("song")).file_name("song.ogg"),
    );
    let response = app
        .client
        .post(app.url("/v1/songs"))
        .bearer_auth(secret)
        .multipart(form)
        .send()
        .await
        .expect("upload");
    assert_eq!(response.status(), StatusCode::CREATED);
    let jobs: Value = app
        .client
        .get(app.url("/v1/jobs"))
        .bearer_auth(secret)
        .send()
        .await
        .expect("jobs")
        .json()
        .await
        .expect("jobs json");
    jobs["items"][0]["id"].as_str().expect("job id").to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_thousand_streams_of_one_key_leave_room_for_another() {
    const TRIES: usize = 1000;
    let (app, flood, other) = api_only(|_| {}).await;
    let job = queued_job(&app, &flood).await;
    let url = app.url(&format!("/v1/jobs/{job}/events"));
    // Every try on its own connection, as an attacker opening streams would.
    let attacker = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .timeout(Duration::from_secs(60))
        .build()
        .expect("client");
    let started = Instant::now();
    let tries = (0..TRIES).map(|_| {
        let (attacker, url, flood) = (attacker.clone(), url.clone(), flood.clone());
        tokio::spawn(async move { attacker.get(url).bearer_auth(flood).send().await })
    });
    let flood_task = tokio::spawn(futures::future::join_all(tries));
    // While the flood runs, the other key is served, and so is /healthz.
    let mut slowest = Duration::ZERO;
    for _ in 0..20 {
        let asked = Instant::now();
        let response = app
            .client
            .get(app.url("/v1/jobs"))
            .bearer_auth(&other)
            .send()
            .await
            .expect("the other key is answered");
        assert_eq!(response.status(), StatusCode::OK);
        let health = app
            .client
            .get(app.url("/healthz"))
            .send()
            .await
            .expect("health");
        assert_eq!(health.status(), StatusCode::OK);
        slowest = slowest.max(asked.elapsed());
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    let answers = flood_task.await.expect("flood");
    let mut streams = Vec::new();
    let (mut refused, mut closed, mut failed) = (0, 0, 0);
    for answer in answers {
        match answer.expect("task") {
            Ok(r) if r.status() == StatusCode::OK => streams.push(r),
            Ok(r) if r.status() == StatusCode::TOO_MANY_REQUESTS => {
                refused += 1;
                closed += usize::from(r.headers().get("connection").is_some_and(|v| v == "close"));
                if refused == 1 {
                    expect_problem(r, StatusCode::TOO_MANY_REQUESTS, "too-many-event-streams")
                        .await;
                }
            }
            Ok(r) => panic!("unexpected {}", r.status()),
            Err(_) => failed += 1,
        }
    }
    eprintln!(
        "{TRIES} stream requests of one key in {:?}: {} open, {refused} refused with 429 ({closed} closed), \
         {failed} failed; the other key's slowest answer meanwhile {slowest:?}",
        started.elapsed(),
        streams.len()
    );
    assert_eq!(
        streams.len(),
        16,
        "max_event_streams_per_key defaults to 16"
    );
    assert_eq!(refused + failed, TRIES - 16);
    assert_eq!(failed, 0, "every refused try was answered");
    assert_eq!(closed, refused, "each 429 closes its connection");
    assert!(slowest < Duration::from_secs(1), "{slowest:?}");
    // The other key's own streams are its own.
    let own = queued_job(&app, &other).await;
    let stream = app
        .client
        .get(app.url(&format!("/v1/jobs/{own}/events")))
        .bearer_auth(&other)
        .send()
        .await
        .expect("stream");
    assert_eq!(stream.status(), StatusCode::OK);
    // A closed stream gives its slot back: the server sees the close at its next write, the
    // keep-alive comment at the latest (15 s).
    drop(streams.pop());
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let again = attacker
            .get(&url)
            .bearer_auth(&flood)
            .send()
            .await
            .expect("again");
        if again.status() == StatusCode::OK {
            break;
        }
        assert!(Instant::now() < deadline, "the slot was not given back");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    drop(streams);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_ends_after_its_longest_life_and_resumes() {
    let (app, flood, _) = api_only(|c| c.event_stream_max_s = 1.0).await;
    let job = queued_job(&app, &flood).await;
    let started = Instant::now();
    let response = app
        .client
        .get(app.url(&format!("/v1/jobs/{job}/events")))
        .bearer_auth(&flood)
        .send()
        .await
        .expect("stream");
    assert_eq!(response.status(), StatusCode::OK);
    let body = tokio::time::timeout(Duration::from_secs(10), response.text())
        .await
        .expect("the stream ends by itself")
        .expect("body");
    let took = started.elapsed();
    eprintln!("a stream on a queued job ended after {took:?}");
    assert!(took >= Duration::from_millis(900), "{took:?}");
    assert!(!body.contains("event: done"), "{body}");
    let last = body
        .lines()
        .filter_map(|l| l.strip_prefix("id: "))
        .next_back()
        .expect("the job's first events came with ids")
        .to_string();
    let resumed = app
        .client
        .get(app.url(&format!("/v1/jobs/{job}/events")))
        .bearer_auth(&flood)
        .header("last-event-id", last)
        .send()
        .await
        .expect("resume");
    assert_eq!(resumed.status(), StatusCode::OK);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_probes_are_served_past_the_connection_cap() {
    let app = spawn_app_with(|c| c.max_connections = 4).await;
    // Stalled clients hold every connection the cap allows, and more.
    let mut stalled = Vec::new();
    for _ in 0..12 {
        stalled.push(
            tokio::net::TcpStream::connect(app.addr)
                .await
                .expect("connect"),
        );
    }
    tokio::time::sleep(Duration::from_millis(100)).await;
    let fresh = || {
        reqwest::Client::builder()
            .pool_max_idle_per_host(0)
            .timeout(Duration::from_secs(5))
            .build()
            .expect("client")
    };
    for path in ["/healthz", "/readyz"] {
        let asked = Instant::now();
        let response = fresh().get(app.url(path)).send().await.expect(path);
        eprintln!(
            "{path} past the cap ({} connections stalled): {} in {:?}",
            stalled.len(),
            response.status(),
            asked.elapsed()
        );
        assert_eq!(response.status(), StatusCode::OK, "{path}");
        assert!(asked.elapsed() < Duration::from_secs(1));
    }
    let refused = fresh()
        .get(app.url("/v1/jobs"))
        .send()
        .await
        .expect("refused");
    expect_problem(
        refused,
        StatusCode::SERVICE_UNAVAILABLE,
        "too-many-connections",
    )
    .await;
    drop(stalled);
    app.stop().await;
}
