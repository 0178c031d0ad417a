//! `GET /v1/models`.
use crate::helpers::spawn_app;
use reqwest::StatusCode;
use serde_json::{json, Value};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lists_the_models_found_under_the_models_dir() {
    let app = spawn_app().await;
    let response = app.get("/v1/models").await;
    assert_eq!(response.status(), StatusCode::OK);
    let models: Value = response.json().await.expect("json");
    assert_eq!(models, json!([]), "the test models dir is empty");
    app.stop().await;
}
