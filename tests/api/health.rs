//! `/healthz`, `/readyz`, `/metrics`, and what every route shares: request ids, CORS, auth.
use crate::helpers::{expect_problem, short_song, spawn_app, spawn_app_with};
use choreo::config::Secret;
use reqwest::StatusCode;
use serde_json::{json, Value};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_readiness_and_metrics() {
    let app = spawn_app().await;
    let health: Value = app.get("/healthz").await.json().await.expect("json");
    assert_eq!(health, json!({"status": "ok"}));
    let ready = app.get("/readyz").await;
    assert_eq!(ready.status(), StatusCode::OK);

    let song = app.upload_ok(&short_song()).await;
    let job = app.analyze_job_of(song["id"].as_str().expect("id")).await;
    app.wait_job(job["id"].as_str().expect("job id")).await;
    let metrics = app.get("/metrics").await;
    assert_eq!(metrics.status(), StatusCode::OK);
    let text = metrics.text().await.expect("text");
    for name in [
        "choreo_jobs{status=\"succeeded\"} 1",
        "choreo_queue_depth 0",
        "choreo_busy_workers",
        "choreo_job_duration_seconds_bucket",
        "choreo_stage_duration_seconds_bucket",
        "choreo_jobs_finished_total",
    ] {
        assert!(text.contains(name), "/metrics lacks {name}:\n{text}");
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_response_carries_a_request_id() {
    let app = spawn_app().await;
    let response = app.get("/healthz").await;
    let id = response
        .headers()
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .expect("x-request-id");
    assert_eq!(id.len(), 36, "a uuid: {id}");
    let response = app
        .client
        .get(app.url("/v1/models"))
        .header("x-request-id", "trace-me-42")
        .send()
        .await
        .expect("GET");
    assert_eq!(
        response
            .headers()
            .get("x-request-id")
            .and_then(|v| v.to_str().ok()),
        Some("trace-me-42")
    );
    let missing = app.get("/no/such/route").await;
    assert!(missing.headers().contains_key("x-request-id"));
    expect_problem(missing, StatusCode::NOT_FOUND, "not-found").await;
    let wrong_method = app
        .client
        .put(app.url("/v1/songs"))
        .send()
        .await
        .expect("PUT");
    expect_problem(
        wrong_method,
        StatusCode::METHOD_NOT_ALLOWED,
        "method-not-allowed",
    )
    .await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cors_allows_the_configured_origins_only() {
    let app = spawn_app_with(|c| c.cors_origins = vec!["http://studio.example".into()]).await;
    let preflight = |origin: &'static str| {
        app.client
            .request(reqwest::Method::OPTIONS, app.url("/v1/jobs"))
            .header("origin", origin)
            .header("access-control-request-method", "POST")
            .header(
                "access-control-request-headers",
                "content-type,idempotency-key",
            )
            .send()
    };
    let allowed = preflight("http://studio.example").await.expect("preflight");
    assert_eq!(
        allowed
            .headers()
            .get("access-control-allow-origin")
            .and_then(|v| v.to_str().ok()),
        Some("http://studio.example")
    );
    let refused = preflight("http://elsewhere.example")
        .await
        .expect("preflight");
    assert!(refused
        .headers()
        .get("access-control-allow-origin")
        .is_none());
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_configured_token_guards_every_v1_route() {
    let app = spawn_app_with(|c| c.auth_token = Some(Secret::new("s3cret-token"))).await;
    for path in [
        "/v1/models",
        "/v1/jobs",
        "/v1/songs/01234567-89ab-7def-8123-456789abcdef",
    ] {
        let bare = app.client.get(app.url(path)).send().await.expect("GET");
        assert_eq!(
            bare.headers()
                .get("www-authenticate")
                .and_then(|v| v.to_str().ok()),
            Some("Bearer")
        );
        expect_problem(bare, StatusCode::UNAUTHORIZED, "unauthorized").await;
        let wrong = app
            .client
            .get(app.url(path))
            .bearer_auth("s3cret-tokem")
            .send()
            .await
            .expect("GET");
        expect_problem(wrong, StatusCode::UNAUTHORIZED, "unauthorized").await;
    }
    let upload = app
        .client
        .post(app.url("/v1/songs"))
        .body("x")
        .send()
        .await
        .expect("POST");
    // Its body is never read, so the connection is not for reuse, and the answer says so.
    assert_eq!(
        upload
            .headers()
            .get("connection")
            .and_then(|v| v.to_str().ok()),
        Some("close")
    );
    expect_problem(upload, StatusCode::UNAUTHORIZED, "unauthorized").await;
    // The helper sends the right token.
    assert_eq!(app.get("/v1/models").await.status(), StatusCode::OK);
    // Probes and metrics stay open.
    for path in ["/healthz", "/readyz", "/metrics", "/openapi.json"] {
        let response = app.client.get(app.url(path)).send().await.expect("GET");
        assert_eq!(response.status(), StatusCode::OK, "{path}");
    }
    app.stop().await;
}
