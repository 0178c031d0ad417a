//! The small limits, in process: request ids, the Bearer scheme, multipart part
//! headers, stalled bodies and the start-up sweep of crash leftovers.
use crate::helpers::{expect_problem, spawn_app_with};
use reqwest::StatusCode;
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

#[tokio::test]
async fn an_oversized_request_id_is_replaced_and_a_fair_one_echoed() {
    let app = spawn_app_with(|_| {}).await;
    let fair = "client-id-42";
    let response = app
        .client
        .get(app.url("/healthz"))
        .header("x-request-id", fair)
        .send()
        .await
        .expect("GET");
    assert_eq!(response.headers()["x-request-id"], fair);
    let huge = "x".repeat(60 * 1024);
    let response = app
        .client
        .get(app.url("/healthz"))
        .header("x-request-id", &huge)
        .send()
        .await
        .expect("GET");
    assert_eq!(response.status(), StatusCode::OK);
    let echoed = response.headers()["x-request-id"]
        .to_str()
        .expect("ascii")
        .to_string();
    assert!(
        echoed.len() <= 128 && echoed != huge,
        "replaced by a fresh id: {} chars",
        echoed.len()
    );
    app.stop().await;
}

#[tokio::test]
async fn the_bearer_scheme_is_case_insensitive() {
    let app = spawn_app_with(|c| c.auth_token = Some(choreo::config::Secret::new("s3cret"))).await;
    for scheme in ["Bearer", "bearer", "BEARER"] {
        let response = app
            .client
            .get(app.url("/v1/models"))
            .header("authorization", format!("{scheme} s3cret"))
            .send()
            .await
            .expect("GET");
        assert_eq!(response.status(), StatusCode::OK, "{scheme}");
    }
    let response = app
        .client
        .get(app.url("/v1/models"))
        .header("authorization", "bearer wrong")
        .send()
        .await
        .expect("GET");
    expect_problem(response, StatusCode::UNAUTHORIZED, "unauthorized").await;
    app.stop().await;
}

#[tokio::test]
async fn a_long_part_header_is_refused_before_it_is_buffered() {
    let app = spawn_app_with(|_| {}).await;
    let boundary = "b0und4ry";
    let mut body = format!("--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.ogg\"\r\nX-Pad: ").into_bytes();
    body.extend(std::iter::repeat_n(b'a', 1024 * 1024));
    body.extend_from_slice(format!("\r\n\r\nxyz\r\n--{boundary}--\r\n").as_bytes());
    let response = app
        .client
        .post(app.url("/v1/songs"))
        .header(
            "content-type",
            format!("multipart/form-data; boundary={boundary}"),
        )
        .body(body)
        .send()
        .await
        .expect("POST");
    let problem = expect_problem(
        response,
        StatusCode::from_u16(431).expect("431"),
        "part-header-too-large",
    )
    .await;
    assert!(
        problem["detail"].as_str().expect("detail").contains("8192"),
        "{problem}"
    );
    app.stop().await;
}

#[tokio::test]
async fn a_stalled_body_gets_408() {
    let app = spawn_app_with(|c| c.body_timeout_s = 1.0).await;
    let mut stream = tokio::net::TcpStream::connect(app.addr)
        .await
        .expect("connect");
    let head = "POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n{\"song_id\":";
    stream.write_all(head.as_bytes()).await.expect("write");
    let started = Instant::now();
    let mut answer = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(10), stream.read_to_end(&mut answer))
        .await
        .expect("answered within 10 s");
    let answer = String::from_utf8_lossy(&answer);
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert!(answer.contains("body-timeout"), "{answer}");
    assert!(
        started.elapsed() < Duration::from_secs(5),
        "{:?}",
        started.elapsed()
    );
    app.stop().await;
}

#[tokio::test]
async fn crash_leftovers_are_swept_at_start() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    let orphan_song = data
        .join("songs")
        .join(format!("{}.ogg", uuid::Uuid::now_v7()));
    let orphan_job = data.join("jobs").join(uuid::Uuid::now_v7().to_string());
    for d in [data.join("songs"), orphan_job.clone()] {
        std::fs::create_dir_all(d).expect("mkdir");
    }
    std::fs::write(&orphan_song, b"not a row").expect("write");
    std::fs::write(orphan_job.join(".partial-abc"), b"cut off").expect("write");
    let unrelated = data.join("songs").join("README");
    std::fs::write(&unrelated, b"not ours to judge").expect("write");
    let app = spawn_app_with(|c| {
        c.data_dir = data.clone();
        c.sweep_grace_s = 0.0;
    })
    .await;
    let deadline = Instant::now() + Duration::from_secs(10);
    while orphan_song.exists() || orphan_job.exists() {
        assert!(Instant::now() < deadline, "leftovers not swept within 10 s");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(
        unrelated.exists(),
        "files not named by an id are left alone"
    );
    // A song uploaded after the sweep stays.
    let song = app.upload_ok(&crate::helpers::short_song()).await;
    assert!(song["id"].is_string());
    app.stop().await;
}
