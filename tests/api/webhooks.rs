//! Webhooks against a receiver the test runs: one signed delivery per finished job, the signature
//! verified by the Standard Webhooks reference library (PyPI `standardwebhooks`, run by
//! `tests/webhooks/verify.py`, installed in `.venv-webhooks` by `scripts/setup.sh --test`), retries
//! after a 500, each attempt logged; a loopback URL refused at submission without configuration.
use crate::common_models::models_dir;
use crate::helpers::{expect_problem, short_song, spawn_app_with};
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode as AxumStatus};
use axum::routing::post;
use axum::Router;
use choreo::config::Secret;
use choreo::queue::JobId;
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::path::Path;
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// 32 bytes, in Standard Webhooks' form.
const SECRET: &str = "whsec_c2VjcmV0LWtleS1vZi10aGUtd2ViaG9vay10ZXN0cyE=";

/// What the receiver got: the path, the three signature headers and the raw body.
#[derive(Clone, Debug)]
struct Delivery {
    path: String,
    headers: Value,
    body: String,
}

#[derive(Clone, Default)]
struct Receiver {
    got: Arc<Mutex<Vec<Delivery>>>,
    /// How many more times `/flaky` answers 500.
    failures_left: Arc<Mutex<u32>>,
}

async fn receive(
    State(receiver): State<Receiver>,
    uri: axum::http::Uri,
    headers: HeaderMap,
    body: String,
) -> AxumStatus {
    let header = |name: &str| {
        headers
            .get(name)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .to_string()
    };
    receiver.got.lock().expect("lock").push(Delivery {
        path: uri.path().to_string(),
        headers: json!({
            "webhook-id": header("webhook-id"),
            "webhook-timestamp": header("webhook-timestamp"),
            "webhook-signature": header("webhook-signature"),
        }),
        body,
    });
    if uri.path() == "/flaky" {
        let mut left = receiver.failures_left.lock().expect("lock");
        if *left > 0 {
            *left -= 1;
            return AxumStatus::INTERNAL_SERVER_ERROR;
        }
    }
    AxumStatus::NO_CONTENT
}

/// Starts the receiver on 127.0.0.1:0; `/flaky` answers 500 `failures` times first.
async fn start_receiver(failures: u32) -> (Receiver, std::net::SocketAddr) {
    let receiver = Receiver {
        failures_left: Arc::new(Mutex::new(failures)),
        ..Receiver::default()
    };
    let app = Router::new()
        .route("/ok", post(receive))
        .route("/flaky", post(receive))
        .with_state(receiver.clone());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind receiver");
    let addr = listener.local_addr().expect("addr");
    tokio::spawn(async move { axum::serve(listener, app).await });
    (receiver, addr)
}

/// Runs the reference library over `deliveries`; returns the payloads it verified.
fn verify_with_reference_library(deliveries: &[Delivery]) -> Option<Vec<Value>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = root.join(".venv-webhooks/bin/python");
    if !python.is_file() {
        if std::env::var("CI").as_deref() == Ok("true") {
            panic!("{} is missing: run `scripts/setup.sh --test` (or `make test`) to install standardwebhooks (CI=true)", python.display());
        }
        eprintln!(
            "NOTICE: not verifying webhook signatures: {} not found (run scripts/setup.sh --test)",
            python.display()
        );
        return None;
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("deliveries.json");
    let list: Vec<Value> = deliveries
        .iter()
        .map(|d| json!({"headers": d.headers, "body": d.body}))
        .collect();
    std::fs::write(&file, serde_json::to_vec(&list).expect("json")).expect("write");
    let out = std::process::Command::new(&python)
        .arg(root.join("tests/webhooks/verify.py"))
        .arg(SECRET)
        .arg(&file)
        .output()
        .expect("run verify.py");
    assert!(
        out.status.success(),
        "the reference library refused a delivery: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(
        String::from_utf8(out.stdout)
            .expect("utf-8")
            .lines()
            .map(|l| serde_json::from_str(l).expect("payload json"))
            .collect(),
    )
}

async fn wait_for(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while !done() {
        assert!(Instant::now() < deadline, "{what} within 120 s");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_finished_job_is_delivered_once_signed_and_retried_after_a_500() {
    let (receiver, addr) = start_receiver(2).await;
    let app = spawn_app_with(|c| {
        c.models_dir = models_dir();
        c.webhook_secret = Some(Secret::new(SECRET));
        c.webhook_allowed_hosts = vec![addr.to_string()];
        c.webhook_backoff_s = 0.2;
        c.webhook_retry_s = 60.0;
    })
    .await;
    let song = app.upload_ok(&short_song()).await;
    let submit = |hook: String, seed: u64| {
        let body = json!({"song_id": song["id"], "model": "dance-revolution", "seed": seed, "webhook_url": hook});
        let app = &app;
        async move {
            let response = app.post_job(&body, None).await;
            assert_eq!(response.status(), StatusCode::ACCEPTED);
            let job: Value = response.json().await.expect("job");
            assert_eq!(job["webhook_url"], body["webhook_url"]);
            job["id"].as_str().expect("id").to_string()
        }
    };
    let ok = submit(format!("http://{addr}/ok"), 1).await;
    let flaky = submit(format!("http://{addr}/flaky"), 2).await;
    // A third job cancelled before it runs: cancelled is an end too.
    let cancelled = submit(format!("http://{addr}/ok"), 3).await;
    let cancel = app.delete(&format!("/v1/jobs/{cancelled}")).await;
    assert!(cancel.status().is_success(), "{}", cancel.status());
    for id in [&ok, &flaky, &cancelled] {
        app.wait_job(id).await;
    }
    // /ok: one delivery per job; /flaky: 500, 500, then accepted.
    wait_for("every delivery", || {
        receiver.got.lock().expect("lock").len() >= 5
    })
    .await;
    // Nothing more comes: each job's delivery ended.
    tokio::time::sleep(Duration::from_secs(2)).await;
    let got = receiver.got.lock().expect("lock").clone();
    let to = |path: &str, id: &str| -> Vec<Delivery> {
        got.iter()
            .filter(|d| d.path == path && d.headers["webhook-id"] == id)
            .cloned()
            .collect()
    };
    assert_eq!(got.len(), 5, "{got:#?}");
    let ok_got = to("/ok", &ok);
    let cancelled_got = to("/ok", &cancelled);
    let flaky_got = to("/flaky", &flaky);
    assert_eq!(
        (ok_got.len(), cancelled_got.len(), flaky_got.len()),
        (1, 1, 3)
    );
    // The body is the job as GET /v1/jobs/{id} returns it.
    for (deliveries, id, statuses) in [
        (&ok_got, &ok, &["succeeded"][..]),
        // Cancelled while queued, or (rarely) already running and finished before a checkpoint.
        (&cancelled_got, &cancelled, &["cancelled", "succeeded"][..]),
        (&flaky_got, &flaky, &["succeeded"][..]),
    ] {
        let job = app.job(id).await;
        assert!(
            statuses.contains(&job["status"].as_str().unwrap_or("")),
            "{job}"
        );
        for d in deliveries {
            let body: Value = serde_json::from_str(&d.body).expect("json body");
            assert_eq!(body, job);
            assert!(d.headers["webhook-signature"]
                .as_str()
                .is_some_and(|s| s.starts_with("v1,")));
        }
    }
    if let Some(payloads) = verify_with_reference_library(&got) {
        assert_eq!(payloads.len(), got.len());
    }

    // Each attempt is logged: the retries with the 500s, then the 204.
    let store = app.server.as_ref().expect("server").state().store.clone();
    let attempts = store
        .webhook_attempts(JobId::from_str(&flaky).expect("id"))
        .await
        .expect("attempts");
    let codes: Vec<(u32, Option<u16>)> = attempts
        .iter()
        .map(|a| (a.attempt, a.status_code))
        .collect();
    assert_eq!(codes, vec![(1, Some(500)), (2, Some(500)), (3, Some(204))]);
    assert!(attempts[0].error.is_some() && attempts[2].error.is_none());
    assert!(
        attempts[1].at - attempts[0].at >= chrono::Duration::milliseconds(200),
        "backed off: {attempts:?}"
    );
    let ok_attempts = store
        .webhook_attempts(JobId::from_str(&ok).expect("id"))
        .await
        .expect("attempts");
    assert_eq!(ok_attempts.len(), 1);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_webhook_to_loopback_is_refused_at_submission_unless_allowed() {
    let app = spawn_app_with(|c| {
        c.models_dir = models_dir();
        c.webhook_secret = Some(Secret::new(SECRET));
    })
    .await;
    let song = app.upload_ok(&short_song()).await;
    let job =
        |url: &str| json!({"song_id": song["id"], "model": "dance-revolution", "webhook_url": url});
    for url in [
        "http://127.0.0.1:9/hook",
        "http://localhost:9/hook",
        "http://[::1]:9/hook",
        "http://169.254.169.254/latest/meta-data/",
        "http://10.0.0.1/hook",
        "ftp://example.com/hook",
    ] {
        let problem = expect_problem(
            app.post_job(&job(url), None).await,
            StatusCode::UNPROCESSABLE_ENTITY,
            "webhook-url-refused",
        )
        .await;
        assert_eq!(problem["field"], "webhook_url", "{url}: {problem}");
    }
    let problem = expect_problem(
        app.post_job(&job("http://127.0.0.1:9/hook"), None).await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "webhook-url-refused",
    )
    .await;
    let detail = problem["detail"].as_str().expect("detail");
    assert!(
        detail.contains("loopback") && detail.contains("127.0.0.1:9"),
        "says why and what to allow: {detail}"
    );
    app.stop().await;

    // Without a webhook_secret nothing could be signed: refused too.
    let app = spawn_app_with(|c| c.models_dir = models_dir()).await;
    let song = app.upload_ok(&short_song()).await;
    expect_problem(
        app.post_job(
            &json!({"song_id": song["id"], "model": "dance-revolution", "webhook_url": "https://example.com/hook"}),
            None,
        )
        .await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "webhooks-not-configured",
    )
    .await;
    app.stop().await;
}

fn webhook_config(c: &mut choreo::config::Config, receiver: std::net::SocketAddr, retry_s: f64) {
    c.models_dir = models_dir();
    c.webhook_secret = Some(Secret::new(SECRET));
    c.webhook_allowed_hosts = vec![receiver.to_string()];
    c.webhook_backoff_s = 0.2;
    c.webhook_retry_s = retry_s;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pending_delivery_survives_a_restart_and_retries_end_after_webhook_retry_s() {
    // /flaky answers 500 until the test says otherwise.
    let (receiver, addr) = start_receiver(u32::MAX).await;
    let app = spawn_app_with(|c| webhook_config(c, addr, 60.0)).await;
    let song = app.upload_ok(&short_song()).await;
    let hook = format!("http://{addr}/flaky");
    let body =
        json!({"song_id": song["id"], "model": "dance-revolution", "seed": 4, "webhook_url": hook});
    let response = app.post_job(&body, None).await;
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let id = response.json::<Value>().await.expect("job")["id"]
        .as_str()
        .expect("id")
        .to_string();
    app.wait_job(&id).await;
    wait_for("two failed attempts", || {
        receiver.got.lock().expect("lock").len() >= 2
    })
    .await;

    // Stop the server with the delivery pending, let the receiver recover, start again.
    let crate::helpers::TestApp {
        server, data_dir, ..
    } = app;
    server.expect("server").stop().await;
    let failed = receiver.got.lock().expect("lock").len();
    *receiver.failures_left.lock().expect("lock") = 0;
    let mut config = crate::helpers::test_config(data_dir.path());
    webhook_config(&mut config, addr, 60.0);
    let server = choreo::api::Server::start(config).await.expect("restart");
    wait_for("the delivery after the restart", || {
        receiver.got.lock().expect("lock").len() > failed
    })
    .await;
    tokio::time::sleep(Duration::from_secs(1)).await;
    let got = receiver.got.lock().expect("lock").clone();
    assert_eq!(
        got.len(),
        failed + 1,
        "delivered once after the restart, then no more"
    );
    assert!(got.iter().all(|d| d.headers["webhook-id"] == id.as_str()));
    let attempts = server
        .state()
        .store
        .webhook_attempts(JobId::from_str(&id).expect("id"))
        .await
        .expect("attempts");
    let numbers: Vec<u32> = attempts.iter().map(|a| a.attempt).collect();
    let expected: Vec<u32> = (1..=numbers.len() as u32).collect();
    assert_eq!(
        numbers, expected,
        "every attempt logged, in order: {attempts:?}"
    );
    assert_eq!(attempts.last().and_then(|a| a.status_code), Some(204));
    assert!(attempts[..attempts.len() - 1]
        .iter()
        .all(|a| a.status_code == Some(500) || a.error.is_some()));
    server.stop().await;

    // A receiver that never recovers is given up `webhook_retry_s` after the job ended.
    let (receiver, addr) = start_receiver(u32::MAX).await;
    let app = spawn_app_with(|c| webhook_config(c, addr, 1.0)).await;
    let song = app.upload_ok(&short_song()).await;
    let body = json!({"song_id": song["id"], "model": "dance-revolution", "seed": 5, "webhook_url": format!("http://{addr}/flaky")});
    let response = app.post_job(&body, None).await;
    let id = response.json::<Value>().await.expect("job")["id"]
        .as_str()
        .expect("id")
        .to_string();
    app.wait_job(&id).await;
    wait_for("a first attempt", || {
        !receiver.got.lock().expect("lock").is_empty()
    })
    .await;
    // Attempts at ~0, +0.2 s, +0.6 s; the next would be past the second.
    tokio::time::sleep(Duration::from_secs(3)).await;
    let given_up = receiver.got.lock().expect("lock").len();
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert_eq!(
        receiver.got.lock().expect("lock").len(),
        given_up,
        "no attempt after giving up"
    );
    assert!((1..=4).contains(&given_up), "{given_up} attempts in 1 s");
    app.stop().await;
}
