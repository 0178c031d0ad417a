//! The checked-in `openapi/openapi.json` must equal the spec the code generates.
//!
//! After changing the API, regenerate it with
//! `UPDATE_OPENAPI=1 cargo test --release --test api openapi` and commit the file.
use crate::helpers::spawn_app;
use reqwest::StatusCode;
use serde_json::Value;
use std::path::Path;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_checked_in_spec_matches_the_code() {
    let generated = choreo::api::openapi::spec_json().expect("spec serialises");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(choreo::api::openapi::SPEC_PATH);
    if std::env::var("UPDATE_OPENAPI").is_ok_and(|v| v == "1") {
        std::fs::write(&path, &generated).expect("write spec");
    }
    let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        checked_in == generated,
        "{} is out of date with the code; run `UPDATE_OPENAPI=1 cargo test --release --test api openapi` and commit it",
        path.display()
    );

    // The server serves the same document, and the docs page.
    let app = spawn_app().await;
    let served: Value = app.get("/openapi.json").await.json().await.expect("json");
    let expected: Value = serde_json::from_str(&generated).expect("json");
    assert_eq!(served, expected);
    for route in [
        "/v1/songs",
        "/v1/jobs",
        "/v1/jobs/{id}",
        "/v1/jobs/{id}/{file}",
        "/v1/models",
        "/metrics",
    ] {
        assert!(served["paths"].get(route).is_some(), "spec lacks {route}");
    }
    let docs = app.get("/docs/").await;
    assert_eq!(docs.status(), StatusCode::OK);
    assert!(
        docs.text().await.expect("html").contains("swagger"),
        "an interactive docs page"
    );
    app.stop().await;
}
