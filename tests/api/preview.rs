//! `GET /v1/jobs/{id}/preview.png`: a real generate job's contact sheet, decoded and looked at.
use crate::helpers::{expect_problem, short_song, spawn_app_with};
use choreo::report::preview::{HEIGHT, WIDTH};
use reqwest::StatusCode;
use serde_json::{json, Value};
use std::collections::HashSet;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_generate_job_serves_its_contact_sheet_as_png() {
    let models = crate::common_models::models_dir();
    // One worker: the second job waits behind the first, so it can be cancelled while queued.
    let app = spawn_app_with(|c| {
        c.models_dir = models;
        c.workers = 1;
    })
    .await;
    let song = app.upload_ok(&short_song()).await;
    let request = json!({"song_id": song["id"], "model": "dance-revolution", "seed": 5});
    let first: Value = app
        .post_job(&request, None)
        .await
        .json()
        .await
        .expect("job");
    let id = first["id"].as_str().expect("id").to_string();
    assert_eq!(
        first["links"]["preview"],
        format!("/v1/jobs/{id}/preview.png")
    );
    let second: Value = app.post_job(&json!({"song_id": song["id"], "model": "dance-revolution", "seed": 6, "priority": -100}), None).await.json().await.expect("job");
    let second = second["id"].as_str().expect("id").to_string();
    assert_eq!(
        app.delete(&format!("/v1/jobs/{second}")).await.status(),
        StatusCode::ACCEPTED
    );
    assert_eq!(app.wait_job(&second).await["status"], "cancelled");
    // A job that did not succeed has no picture: 409 with its status, as for every result.
    let body = expect_problem(
        app.get(&format!("/v1/jobs/{second}/preview.png")).await,
        StatusCode::CONFLICT,
        "job-not-finished",
    )
    .await;
    assert_eq!(body["job_status"], "cancelled", "{body}");

    let done = app.wait_job(&id).await;
    assert_eq!(done["status"], "succeeded", "{done}");
    let response = app.get(&format!("/v1/jobs/{id}/preview.png")).await;
    assert_eq!(response.status(), StatusCode::OK);
    assert_eq!(
        response
            .headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok()),
        Some("image/png")
    );
    let bytes = response.bytes().await.expect("png bytes");

    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes.to_vec()))
        .read_info()
        .expect("a PNG header");
    let mut pixels = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut pixels).expect("PNG pixels");
    assert_eq!((info.width, info.height), (WIDTH, HEIGHT));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    let pixels = &pixels[..info.buffer_size()];
    let rgb: Vec<[u8; 3]> = pixels.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let inked = rgb.iter().filter(|p| **p != [255, 255, 255]).count() as f64 / rgb.len() as f64;
    let colours: HashSet<[u8; 3]> = rgb.iter().copied().collect();
    eprintln!(
        "preview.png: {} bytes, {:.1} % inked, {} colours",
        bytes.len(),
        inked * 100.0,
        colours.len()
    );
    assert!(
        inked > 0.05 && inked < 0.6,
        "a drawing, neither blank nor filled: {:.1} % of pixels inked",
        inked * 100.0
    );
    assert!(
        colours.len() > 20,
        "figures, plots and text in several colours: {} colours",
        colours.len()
    );

    // An analyze job draws nothing.
    let analyze = app
        .analyze_job_of(song["id"].as_str().expect("song id"))
        .await;
    let analyze = analyze["id"].as_str().expect("id");
    expect_problem(
        app.get(&format!("/v1/jobs/{analyze}/preview.png")).await,
        StatusCode::NOT_FOUND,
        "result-not-found",
    )
    .await;
    app.stop().await;
}
