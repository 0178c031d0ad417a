//! `/v1/jobs`: lifecycle, listing with cursors, cancellation, results, submission checks.
//!
//! No generation model is trained in a fresh clone, so the lifecycle is exercised with the
//! analyze jobs every upload queues; submission is exercised up to the model check.
use crate::helpers::{expect_problem, short_song, song, spawn_app, spawn_app_with};
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::collections::HashSet;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_analyze_job_goes_from_queued_to_succeeded() {
    let app = spawn_app().await;
    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("id");
    let job = app.analyze_job_of(song_id).await;
    let id = job["id"].as_str().expect("job id").to_string();
    assert_eq!(job["kind"], "analyze");
    assert!(
        ["queued", "running", "succeeded"].contains(&job["status"].as_str().unwrap_or("")),
        "{job}"
    );
    assert_eq!(job["links"]["self"], format!("/v1/jobs/{id}"));
    assert_eq!(job["links"]["song"], format!("/v1/songs/{song_id}"));

    let done = app.wait_job(&id).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["stage"], "done");
    assert_eq!(done["progress"], 1.0);
    assert_eq!(done["attempts"], 1);
    assert!(done["error"].is_null());
    // As instants, not strings: RFC 3339 drops a zero fraction ("…:03Z" is before "…:03.001Z").
    let at = |field: &str| {
        chrono::DateTime::parse_from_rfc3339(done[field].as_str().expect(field))
            .unwrap_or_else(|e| panic!("{field}: {e}"))
    };
    let (created, started, finished) = (at("created_at"), at("started_at"), at("finished_at"));
    assert!(created <= started && started <= finished, "{done}");

    // Analyze jobs write no files: their result is on the song.
    let file = app.get(&format!("/v1/jobs/{id}/motion.bvh")).await;
    expect_problem(file, StatusCode::NOT_FOUND, "result-not-found").await;
    let unknown_file = app
        .get(&format!("/v1/jobs/{id}/..%2F..%2Fchoreo.sqlite"))
        .await;
    expect_problem(unknown_file, StatusCode::NOT_FOUND, "result-not-found").await;
    let missing = app
        .get("/v1/jobs/01234567-89ab-7def-8123-456789abcdef")
        .await;
    expect_problem(missing, StatusCode::NOT_FOUND, "job-not-found").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn jobs_page_newest_first_with_a_cursor_and_filter() {
    let app = spawn_app().await;
    let names = [
        "trumpet_loop_90bpm.ogg",
        "hungarian_dance_5.ogg",
        "vibe_ace.ogg",
        "sugar_plum_fairy.ogg",
        "lets_go_fishin.ogg",
    ];
    for name in names {
        app.upload_ok(&song(name)).await;
    }
    let mut seen = Vec::new();
    let mut cursor: Option<String> = None;
    let mut pages = 0;
    loop {
        let path = match &cursor {
            Some(c) => format!("/v1/jobs?limit=2&cursor={c}"),
            None => "/v1/jobs?limit=2".to_string(),
        };
        let page: Value = app.get(&path).await.json().await.expect("page");
        let items = page["items"].as_array().expect("items");
        assert!(items.len() <= 2);
        seen.extend(
            items
                .iter()
                .map(|j| j["id"].as_str().expect("id").to_string()),
        );
        pages += 1;
        match page["next_cursor"].as_str() {
            Some(next) => cursor = Some(next.to_string()),
            None => break,
        }
    }
    assert_eq!(pages, 3);
    assert_eq!(seen.len(), 5);
    assert_eq!(seen.iter().collect::<HashSet<_>>().len(), 5, "no job twice");
    let mut newest_first = seen.clone();
    newest_first.sort_by(|a, b| b.cmp(a));
    assert_eq!(seen, newest_first, "v7 ids sort by creation time");

    for id in &seen {
        app.wait_job(id).await;
    }
    let succeeded: Value = app
        .get("/v1/jobs?status=succeeded&limit=100")
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(
        succeeded["items"].as_array().map(Vec::len),
        Some(5),
        "{succeeded}"
    );
    let queued: Value = app
        .get("/v1/jobs?status=queued")
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(queued["items"].as_array().map(Vec::len), Some(0));
    let by_model: Value = app
        .get("/v1/jobs?model=dance-revolution")
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(
        by_model["items"].as_array().map(Vec::len),
        Some(0),
        "analyze jobs have no model"
    );

    let body = expect_problem(
        app.get("/v1/jobs?status=bogus").await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid-field",
    )
    .await;
    assert_eq!(body["field"], "status");
    let body = expect_problem(
        app.get("/v1/jobs?limit=0").await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid-field",
    )
    .await;
    assert_eq!(body["field"], "limit");
    let body = expect_problem(
        app.get("/v1/jobs?cursor=xyz").await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid-field",
    )
    .await;
    assert_eq!(body["field"], "cursor");
    expect_problem(
        app.get("/v1/jobs?colour=blue").await,
        StatusCode::BAD_REQUEST,
        "invalid-query",
    )
    .await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_queued_job_is_cancelled_at_once_and_a_finished_one_is_deleted() {
    // One worker and four long songs ahead of it keep the last job queued.
    let app = spawn_app_with(|c| c.workers = 1).await;
    for name in [
        "lets_go_fishin.ogg",
        "sugar_plum_fairy.ogg",
        "vibe_ace.ogg",
        "hungarian_dance_5.ogg",
    ] {
        app.upload_ok(&song(name)).await;
    }
    let last = app.upload_ok(&short_song()).await;
    let job = app.analyze_job_of(last["id"].as_str().expect("id")).await;
    let id = job["id"].as_str().expect("job id").to_string();
    assert_eq!(job["status"], "queued", "{job}");

    let response = app.delete(&format!("/v1/jobs/{id}")).await;
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let cancelled: Value = response.json().await.expect("json");
    assert_eq!(cancelled["status"], "cancelled", "{cancelled}");
    assert_eq!(cancelled["cancel_requested"], true);
    assert!(cancelled["finished_at"].is_string());

    // Every other job still runs to the end; the cancelled one never starts.
    let page: Value = app
        .get("/v1/jobs?limit=100")
        .await
        .json()
        .await
        .expect("page");
    let others: Vec<String> = page["items"]
        .as_array()
        .expect("items")
        .iter()
        .map(|j| j["id"].as_str().expect("id").to_string())
        .filter(|other| *other != id)
        .collect();
    let mut finished = None;
    for other in &others {
        let done = app.wait_job(other).await;
        assert_eq!(done["status"], "succeeded", "{done}");
        finished = Some(other.clone());
    }
    let job = app.job(&id).await;
    assert_eq!(job["status"], "cancelled");
    assert!(job["started_at"].is_null(), "{job}");
    let song: Value = app
        .get(&format!("/v1/songs/{}", last["id"].as_str().expect("id")))
        .await
        .json()
        .await
        .expect("json");
    assert_eq!(song["analysis_status"], "cancelled");

    // A finished job (the cancelled one too) is deleted by DELETE: 204, then it is no more.
    let finished = finished.expect("a finished job");
    for gone in [&finished, &id] {
        assert_eq!(
            app.delete(&format!("/v1/jobs/{gone}")).await.status(),
            StatusCode::NO_CONTENT
        );
        expect_problem(
            app.get(&format!("/v1/jobs/{gone}")).await,
            StatusCode::NOT_FOUND,
            "job-not-found",
        )
        .await;
    }
    expect_problem(
        app.delete("/v1/jobs/01234567-89ab-7def-8123-456789abcdef")
            .await,
        StatusCode::NOT_FOUND,
        "job-not-found",
    )
    .await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_for_an_unknown_model_lists_the_available_ones() {
    let app = spawn_app().await;
    let song = app.upload_ok(&short_song()).await;
    let request = json!({"song_id": song["id"], "model": "no-such-model", "seed": 7});
    let body = expect_problem(
        app.post_job(&request, None).await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "unknown-model",
    )
    .await;
    assert_eq!(body["field"], "model");
    assert_eq!(
        body["available_models"],
        json!([]),
        "a fresh server has no trained model"
    );
    assert!(
        body["detail"]
            .as_str()
            .is_some_and(|d| d.contains("no-such-model")),
        "{body}"
    );

    let request =
        json!({"song_id": "01234567-89ab-7def-8123-456789abcdef", "model": "no-such-model"});
    // An id that names no song is a 404, as on GET /v1/songs/{id}.
    expect_problem(
        app.post_job(&request, None).await,
        StatusCode::NOT_FOUND,
        "song-not-found",
    )
    .await;

    let request = json!({"song_id": song["id"], "model": "x"});
    for key in ["", "has space", &"k".repeat(256)] {
        let response = app.post_job(&request, Some(key)).await;
        expect_problem(response, StatusCode::BAD_REQUEST, "invalid-idempotency-key").await;
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dance_job_runs_to_its_files_and_honours_idempotency() {
    // The committed dance-revolution weights: a real model, run on CPU.
    let app = spawn_app_with(|c| c.models_dir = crate::common_models::models_dir()).await;
    let listed: Value = app.get("/v1/models").await.json().await.expect("json");
    assert!(
        listed
            .as_array()
            .expect("array")
            .iter()
            .any(|m| m["id"] == "dance-revolution"),
        "{listed}"
    );
    let song = app.upload_ok(&short_song()).await;
    let request = json!({"song_id": song["id"], "model": "dance-revolution", "seed": 7});

    let first = app.post_job(&request, Some("dance-1")).await;
    assert_eq!(first.status(), StatusCode::ACCEPTED);
    assert!(first.headers().get("idempotent-replayed").is_none());
    let job: Value = first.json().await.expect("json");
    let id = job["id"].as_str().expect("id").to_string();
    assert_eq!(
        (
            job["kind"].as_str(),
            job["model"].as_str(),
            job["seed"].as_u64()
        ),
        (Some("generate"), Some("dance-revolution"), Some(7))
    );
    assert_eq!(
        job["links"]["motion_bvh"],
        format!("/v1/jobs/{id}/motion.bvh")
    );

    let again = app.post_job(&request, Some("dance-1")).await;
    assert_eq!(again.status(), StatusCode::ACCEPTED);
    assert_eq!(
        again
            .headers()
            .get("idempotent-replayed")
            .and_then(|v| v.to_str().ok()),
        Some("true")
    );
    let again: Value = again.json().await.expect("json");
    assert_eq!(
        again["id"],
        id.as_str(),
        "the same key and body give the same job"
    );
    let other = json!({"song_id": song["id"], "model": "dance-revolution", "seed": 8});
    expect_problem(
        app.post_job(&other, Some("dance-1")).await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "idempotency-key-reused",
    )
    .await;

    // Until it succeeds, results answer 409 with the job's status.
    let early = app.get(&format!("/v1/jobs/{id}/motion.bvh")).await;
    if early.status() != StatusCode::OK {
        let body = expect_problem(early, StatusCode::CONFLICT, "job-not-finished").await;
        assert!(
            ["queued", "running"].contains(&body["job_status"].as_str().unwrap_or("")),
            "{body}"
        );
    }

    let done = app.wait_job(&id).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let bvh = app
        .get(&format!("/v1/jobs/{id}/motion.bvh"))
        .await
        .text()
        .await
        .expect("bvh");
    assert!(
        bvh.starts_with("HIERARCHY"),
        "{}",
        &bvh[..bvh.len().min(80)]
    );
    let motion: Value = app
        .get(&format!("/v1/jobs/{id}/motion.json"))
        .await
        .json()
        .await
        .expect("motion json");
    assert!(motion.is_object());
    let report: Value = app
        .get(&format!("/v1/jobs/{id}/report.json"))
        .await
        .json()
        .await
        .expect("report json");
    assert!(report.is_object());
    let glb = app
        .get(&format!("/v1/jobs/{id}/motion.glb"))
        .await
        .bytes()
        .await
        .expect("glb");
    assert_eq!(&glb[..4], b"glTF");
    let jobs: Value = app
        .get("/v1/jobs?model=dance-revolution")
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(
        jobs["items"].as_array().map(Vec::len),
        Some(1),
        "one job despite the retry"
    );
    app.stop().await;
}
