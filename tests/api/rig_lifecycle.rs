//! `GET /v1/rigs`, `DELETE /v1/rigs/{id}` and rig retention: a tenant lists its own rigs newest
//! first a page at a time (an operator's key sees all); a deletion removes the row and the file
//! and frees the bytes from the key's storage quota, and another tenant's id is 404 like an
//! unknown one; with `retention_days`, a rig that downloads name is kept and an unused one
//! expires, file and all.
use crate::common_models::models_dir;
use crate::helpers::{expect_problem, short_song, spawn_app, spawn_app_with, TestApp};
use choreo::queue::{KeyLimits, NewKey};
use reqwest::multipart::{Form, Part};
use reqwest::{Method, Response, StatusCode};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The retention of the retention test: 4.32 s.
const FEW_SECONDS_IN_DAYS: f64 = 0.00005;

fn fixture() -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rig_unreal_cm.bvh"))
        .expect("rig fixture")
}

/// A new API key (a tenant of its own unless `admin`) in `app`'s store; returns its secret.
async fn key(app: &TestApp, name: &str, admin: bool, limits: KeyLimits) -> String {
    let (key, secret) = NewKey::mint(name, admin, limits);
    let server = app.server.as_ref().expect("the server runs");
    server.state().store.add_key(key).await.expect("add key");
    secret
}

/// `method path` as `secret`.
async fn call(app: &TestApp, method: Method, path: &str, secret: &str) -> Response {
    app.client
        .request(method, app.url(path))
        .bearer_auth(secret)
        .send()
        .await
        .expect("request")
}

/// Uploads the fixture rig as `secret`.
async fn upload(app: &TestApp, secret: &str) -> Response {
    let form = Form::new().part("file", Part::bytes(fixture()).file_name("mannequin.bvh"));
    app.client
        .post(app.url("/v1/rigs"))
        .bearer_auth(secret)
        .multipart(form)
        .send()
        .await
        .expect("POST /v1/rigs")
}

/// Uploads the fixture rig as `secret` (201 expected) and returns its document.
async fn upload_ok(app: &TestApp, secret: &str) -> Value {
    let response = upload(app, secret).await;
    let status = response.status();
    let rig: Value = response.json().await.expect("rig json");
    assert_eq!(status, StatusCode::CREATED, "{rig}");
    rig
}

/// `GET /v1/rigs{query}` as `secret` (200 expected).
async fn list(app: &TestApp, secret: &str, query: &str) -> Value {
    let response = call(app, Method::GET, &format!("/v1/rigs{query}"), secret).await;
    let status = response.status();
    let page: Value = response.json().await.expect("page json");
    assert_eq!(status, StatusCode::OK, "{page}");
    page
}

fn ids(page: &Value) -> Vec<String> {
    page["items"]
        .as_array()
        .expect("items")
        .iter()
        .map(|r| r["id"].as_str().expect("id").to_string())
        .collect()
}

fn id(rig: &Value) -> String {
    rig["id"].as_str().expect("id").to_string()
}

/// Where the rig's file is kept in the data dir.
fn stored(app: &TestApp, rig: &str) -> PathBuf {
    app.data_dir.path().join("rigs").join(format!("{rig}.bvh"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rigs_list_newest_first_a_page_at_a_time_and_only_the_callers_own() {
    let app = spawn_app().await;
    let a = key(&app, "a", false, KeyLimits::default()).await;
    let b = key(&app, "b", false, KeyLimits::default()).await;
    let ops = key(&app, "ops", true, KeyLimits::default()).await;
    let mut mine = Vec::new();
    for _ in 0..3 {
        mine.push(upload_ok(&app, &a).await);
    }
    let theirs = id(&upload_ok(&app, &b).await);
    let (oldest, middle, newest) = (id(&mine[0]), id(&mine[1]), id(&mine[2]));

    let first = list(&app, &a, "?limit=2").await;
    assert_eq!(ids(&first), vec![newest.clone(), middle.clone()]);
    assert_eq!(first["next_cursor"], json!(middle), "{first}");
    // Each item is the rig's own document.
    assert_eq!(first["items"][0], mine[2]);
    let second = list(&app, &a, &format!("?limit=2&cursor={middle}")).await;
    assert_eq!(ids(&second), vec![oldest.clone()]);
    assert_eq!(
        second["next_cursor"],
        Value::Null,
        "the last page: {second}"
    );
    let all = list(&app, &a, "").await;
    assert_eq!(
        ids(&all),
        vec![newest.clone(), middle.clone(), oldest.clone()]
    );
    assert_eq!(all["next_cursor"], Value::Null);
    assert_eq!(ids(&list(&app, &b, "").await), vec![theirs.clone()]);
    assert_eq!(
        ids(&list(&app, &ops, "").await),
        vec![theirs, newest, middle, oldest],
        "an operator's key lists every tenant's rigs"
    );

    for (query, status, code) in [
        (
            "?limit=0",
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-field",
        ),
        (
            "?limit=101",
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-field",
        ),
        (
            "?cursor=nope",
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-field",
        ),
        ("?limit=many", StatusCode::BAD_REQUEST, "invalid-query"),
        ("?status=queued", StatusCode::BAD_REQUEST, "invalid-query"),
    ] {
        let response = call(&app, Method::GET, &format!("/v1/rigs{query}"), &a).await;
        expect_problem(response, status, code).await;
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_deleted_rig_leaves_no_row_no_file_and_frees_its_bytes() {
    let size = fixture().len() as u64;
    let app = spawn_app().await;
    // Room for one rig, not two.
    let room_for_one = KeyLimits {
        storage_quota_bytes: Some(size + 100),
        ..KeyLimits::default()
    };
    let mine = key(&app, "mine", false, room_for_one).await;
    let theirs = key(&app, "theirs", false, KeyLimits::default()).await;
    let rig = id(&upload_ok(&app, &mine).await);
    let path = format!("/v1/rigs/{rig}");
    assert!(stored(&app, &rig).is_file());
    expect_problem(
        upload(&app, &mine).await,
        StatusCode::PAYLOAD_TOO_LARGE,
        "storage-quota-exceeded",
    )
    .await;

    // Another tenant's id is not found, as an unknown one is, and nothing of it is removed.
    for (path, secret) in [
        (path.clone(), &theirs),
        (
            "/v1/rigs/0191f0a0-0000-7000-8000-000000000000".to_string(),
            &mine,
        ),
        ("/v1/rigs/nope".to_string(), &mine),
    ] {
        expect_problem(
            call(&app, Method::DELETE, &path, secret).await,
            StatusCode::NOT_FOUND,
            "rig-not-found",
        )
        .await;
    }
    assert_eq!(
        call(&app, Method::GET, &path, &mine).await.status(),
        StatusCode::OK
    );
    assert!(stored(&app, &rig).is_file());

    let response = call(&app, Method::DELETE, &path, &mine).await;
    assert_eq!(response.status(), StatusCode::NO_CONTENT);
    assert!(response.bytes().await.expect("body").is_empty());
    assert!(!stored(&app, &rig).exists(), "the rig's file is gone");
    for method in [Method::GET, Method::DELETE] {
        expect_problem(
            call(&app, method, &path, &mine).await,
            StatusCode::NOT_FOUND,
            "rig-not-found",
        )
        .await;
    }
    assert_eq!(ids(&list(&app, &mine, "").await), Vec::<String>::new());
    // Its bytes no longer count: another rig fits again.
    let again = id(&upload_ok(&app, &mine).await);
    assert!(stored(&app, &again).is_file());
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rig_downloads_name_is_kept_and_an_unused_one_expires() {
    let models = models_dir();
    let app = spawn_app_with(|c| {
        c.models_dir = models;
        c.retention_days = Some(FEW_SECONDS_IN_DAYS);
        c.sweep_grace_s = 3.0;
    })
    .await;
    let keep = Duration::from_secs_f64(FEW_SECONDS_IN_DAYS * 86_400.0);
    let song = app.upload_ok(&short_song()).await;
    let job = app
        .dance(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": 4}))
        .await;
    let mut made = Vec::new();
    for name in ["used.bvh", "unused.bvh"] {
        let form = Form::new().part("file", Part::bytes(fixture()).file_name(name));
        let response = app
            .client
            .post(app.url("/v1/rigs"))
            .multipart(form)
            .send()
            .await
            .expect("POST /v1/rigs");
        assert_eq!(response.status(), StatusCode::CREATED);
        made.push(id(&response.json().await.expect("rig")));
    }
    let (used, unused) = (&made[0], &made[1]);

    // Each download that names a rig is a use: twice the retention later it is still there (and
    // so is the dance, downloaded as often), while the other has expired, its file with it.
    let until = Instant::now() + 2 * keep;
    while Instant::now() < until {
        let response = app
            .get(&format!("/v1/jobs/{job}/motion.bvh?rig={used}"))
            .await;
        assert_eq!(response.status(), StatusCode::OK, "a used rig is kept");
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    assert_eq!(
        app.get(&format!("/v1/rigs/{used}")).await.status(),
        StatusCode::OK
    );
    assert!(stored(&app, used).is_file());
    expect_problem(
        app.get(&format!("/v1/rigs/{unused}")).await,
        StatusCode::NOT_FOUND,
        "rig-not-found",
    )
    .await;
    assert!(
        file_goes(&stored(&app, unused)).await,
        "the expired rig's file is gone"
    );

    // Unused now: gone within a few retentions.
    let deadline = Instant::now() + Duration::from_secs(60);
    while app.get(&format!("/v1/rigs/{used}")).await.status() != StatusCode::NOT_FOUND {
        assert!(
            Instant::now() < deadline,
            "the rig did not expire once unused"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    assert!(
        file_goes(&stored(&app, used)).await,
        "the expired rig's file is gone"
    );
    app.stop().await;
}

/// Whether `path` is gone within a few seconds: an expiry removes the row first, then the file,
/// so a client can see the 404 a moment before the file leaves the disk.
async fn file_goes(path: &std::path::Path) -> bool {
    let deadline = Instant::now() + Duration::from_secs(10);
    while path.exists() {
        if Instant::now() > deadline {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    true
}
