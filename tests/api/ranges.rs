//! `Range` on every download: a song's audio, a job's stored files and the dances computed on
//! request each answer one byte range with `206` and exactly those bytes, a range past the end
//! with `416`, and say `Accept-Ranges: bytes`.
use crate::helpers::{expect_problem, short_song, spawn_app, spawn_app_with, TestApp};
use reqwest::header::{
    ACCEPT_RANGES, CONTENT_LENGTH, CONTENT_RANGE, CONTENT_TYPE, IF_RANGE, RANGE,
};
use reqwest::StatusCode;
use serde_json::json;

/// GET `path` with these request headers.
async fn get(app: &TestApp, path: &str, headers: &[(&str, &str)]) -> reqwest::Response {
    let mut request = app.client.get(app.url(path));
    for (name, value) in headers {
        request = request.header(*name, *value);
    }
    request.send().await.expect("GET")
}

fn header(response: &reqwest::Response, name: reqwest::header::HeaderName) -> Option<String> {
    response
        .headers()
        .get(name)
        .and_then(|v| v.to_str().ok())
        .map(str::to_string)
}

/// Checks `path` against `whole`, its bytes: the whole file, `bytes=100-199`, `bytes=-50`, a
/// range past the end, two ranges and an `If-Range`. Returns the content type.
async fn ranges_of(app: &TestApp, path: &str) -> String {
    let full = get(app, path, &[]).await;
    assert_eq!(full.status(), StatusCode::OK, "{path}");
    assert_eq!(
        header(&full, ACCEPT_RANGES).as_deref(),
        Some("bytes"),
        "{path}"
    );
    let content_type = header(&full, CONTENT_TYPE).expect("content type");
    let whole = full.bytes().await.expect("body").to_vec();
    let len = whole.len();
    assert!(len > 200, "{path} is {len} bytes");

    for (range, first, last) in [
        ("bytes=100-199", 100, 199),
        ("bytes=-50", len - 50, len - 1),
        // An end past the file is cut to it.
        ("bytes=150-99999999", 150, len - 1),
    ] {
        let part = get(app, path, &[(RANGE.as_str(), range)]).await;
        assert_eq!(part.status(), StatusCode::PARTIAL_CONTENT, "{path} {range}");
        assert_eq!(
            header(&part, CONTENT_RANGE),
            Some(format!("bytes {first}-{last}/{len}")),
            "{path} {range}"
        );
        assert_eq!(
            header(&part, CONTENT_LENGTH),
            Some((last - first + 1).to_string()),
            "{path} {range}"
        );
        assert_eq!(header(&part, ACCEPT_RANGES).as_deref(), Some("bytes"));
        assert_eq!(
            header(&part, CONTENT_TYPE).as_deref(),
            Some(content_type.as_str())
        );
        let bytes = part.bytes().await.expect("part");
        assert!(
            bytes[..] == whole[first..=last],
            "{path} {range}: other bytes"
        );
    }

    let past = get(app, path, &[(RANGE.as_str(), &format!("bytes={len}-"))]).await;
    assert_eq!(
        header(&past, CONTENT_RANGE),
        Some(format!("bytes */{len}")),
        "{path}"
    );
    let body = expect_problem(
        past,
        StatusCode::RANGE_NOT_SATISFIABLE,
        "range-not-satisfiable",
    )
    .await;
    assert!(
        body["detail"]
            .as_str()
            .is_some_and(|d| d.contains(&format!("0-{}", len - 1))),
        "{body}"
    );

    // Not served as parts: several ranges, or a condition choreo has no validator for.
    for headers in [
        vec![(RANGE.as_str(), "bytes=0-9,20-29")],
        vec![(RANGE.as_str(), "bytes=0-9"), (IF_RANGE.as_str(), "\"x\"")],
        vec![(RANGE.as_str(), "lines=1-2")],
    ] {
        let response = get(app, path, &headers).await;
        assert_eq!(response.status(), StatusCode::OK, "{path} {headers:?}");
        assert!(
            response.bytes().await.expect("body")[..] == whole[..],
            "{path} {headers:?}"
        );
    }
    content_type
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn song_audio_answers_a_range_with_those_bytes() {
    let app = spawn_app().await;
    let song = app.upload_ok(&short_song()).await;
    let id = song["id"].as_str().expect("id");
    let path = format!("/v1/songs/{id}/audio");
    assert_eq!(ranges_of(&app, &path).await, "audio/ogg");
    // The bytes are the upload's.
    let uploaded = std::fs::read(short_song()).expect("song");
    let tail = get(&app, &path, &[(RANGE.as_str(), "bytes=-50")]).await;
    assert!(tail.bytes().await.expect("tail")[..] == uploaded[uploaded.len() - 50..]);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_job_download_answers_a_range_with_those_bytes() {
    let models = crate::common_models::models_dir();
    let app = spawn_app_with(|c| c.models_dir = models).await;
    let song = app.upload_ok(&short_song()).await;
    let id = app
        .dance(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": 3}))
        .await;
    // Stored files (streamed from the artifact store), and dances computed on request.
    for file in [
        "motion.json",
        "motion.bvh",
        "report.json",
        "preview.png",
        "motion.glb",
        "motion.bvh?rig=mixamo",
        "motion.vrma",
        "motion.smpl.npz",
    ] {
        ranges_of(&app, &format!("/v1/jobs/{id}/{file}")).await;
    }
    app.stop().await;
}
