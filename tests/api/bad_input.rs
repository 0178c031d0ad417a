//! Bad input: each answered with a clear 4xx problem while the server keeps serving.
use crate::helpers::{expect_problem, fixture, short_song, spawn_app, spawn_app_with, TestApp};
use reqwest::multipart::{Form, Part};
use reqwest::StatusCode;
use serde_json::json;

async fn still_serving(app: &TestApp) {
    assert_eq!(app.get("/healthz").await.status(), StatusCode::OK);
}

fn no_file_escaped(app: &TestApp) {
    let parent = app.data_dir.path().parent().expect("parent");
    for name in ["passwd", "evil.ogg", "x.ogg"] {
        assert!(
            !parent.join(name).exists(),
            "{name} was written outside the data dir"
        );
    }
    let songs = std::fs::read_dir(app.data_dir.path().join("songs"))
        .expect("songs")
        .count();
    assert_eq!(songs, 0, "no rejected upload is stored");
    let tmp = std::fs::read_dir(app.data_dir.path().join("tmp"))
        .expect("tmp")
        .count();
    assert_eq!(tmp, 0, "rejected uploads leave no temp files");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_uploads_get_a_clear_4xx() {
    let app = spawn_app().await;

    expect_problem(
        app.upload_bytes("empty.mp3", Vec::new()).await,
        StatusCode::BAD_REQUEST,
        "empty-file",
    )
    .await;
    still_serving(&app).await;

    let random: Vec<u8> = (0..64 * 1024u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    expect_problem(
        app.upload_bytes("song.mp3", random).await,
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "audio-undecodable",
    )
    .await;
    still_serving(&app).await;

    let mp3 = std::fs::read(fixture("mp3")).expect("mp3");
    let truncated = mp3[..mp3.len() / 2].to_vec();
    let body = expect_problem(
        app.upload_bytes("cut.mp3", truncated).await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "audio-truncated",
    )
    .await;
    assert_eq!(body["field"], "file");
    still_serving(&app).await;

    let wrong_field = Form::new().part(
        "song",
        Part::bytes(std::fs::read(short_song()).expect("ogg")).file_name("a.ogg"),
    );
    let body = expect_problem(
        app.upload_form(wrong_field).await,
        StatusCode::BAD_REQUEST,
        "unexpected-multipart-field",
    )
    .await;
    assert!(
        body["detail"]
            .as_str()
            .is_some_and(|d| d.contains("`song`") && d.contains("`file`")),
        "{body}"
    );
    // A form with no part at all is not even valid multipart.
    expect_problem(
        app.upload_form(Form::new()).await,
        StatusCode::BAD_REQUEST,
        "invalid-multipart",
    )
    .await;
    let not_multipart = app
        .client
        .post(app.url("/v1/songs"))
        .header("content-type", "application/json")
        .body("{}")
        .send()
        .await
        .expect("POST");
    expect_problem(not_multipart, StatusCode::BAD_REQUEST, "invalid-multipart").await;
    still_serving(&app).await;

    let ogg = std::fs::read(short_song()).expect("ogg");
    for name in [
        "../../passwd",
        "..\\..\\evil.ogg",
        "songs/../../x.ogg",
        "..",
        "a/b.ogg",
        "/etc/passwd",
    ] {
        let body = expect_problem(
            app.upload_bytes(name, ogg.clone()).await,
            StatusCode::BAD_REQUEST,
            "invalid-filename",
        )
        .await;
        assert_eq!(body["field"], "file");
    }
    still_serving(&app).await;
    no_file_escaped(&app);

    let unknown = app
        .get("/v1/songs/01234567-89ab-7def-8123-456789abcdef")
        .await;
    expect_problem(unknown, StatusCode::NOT_FOUND, "song-not-found").await;
    still_serving(&app).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_over_the_limits_are_refused() {
    let app = spawn_app_with(|c| {
        c.max_upload_bytes = 100_000;
        c.max_duration_s = 3.0;
    })
    .await;
    let big = std::fs::read(fixture("wav")).expect("wav");
    assert!(big.len() > 100_000);
    let too_big = app.upload_bytes("big.wav", big).await;
    // The server reads and drops the rest of a refused body (up to 16 MiB more), so the answer
    // arrives whole and the keep-alive connection stays usable: the next GET goes out on it.
    // (Answering at once and closing once made that GET, or the upload itself, fail.)
    assert_eq!(
        too_big
            .headers()
            .get("connection")
            .and_then(|v| v.to_str().ok()),
        None
    );
    expect_problem(too_big, StatusCode::PAYLOAD_TOO_LARGE, "file-too-large").await;
    still_serving(&app).await;
    // 67 kB but 5.3 s long.
    expect_problem(
        app.upload(&short_song()).await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "song-too-long",
    )
    .await;
    still_serving(&app).await;
    no_file_escaped(&app);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_job_requests_name_the_field() {
    let app = spawn_app().await;
    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("id").to_string();

    let malformed = app
        .post_job_raw(
            format!("{{\"song_id\": \"{song_id}\","),
            "application/json",
            None,
        )
        .await;
    expect_problem(malformed, StatusCode::BAD_REQUEST, "malformed-json").await;

    let unknown = app
        .post_job(
            &json!({"song_id": song_id, "model": "m", "tempo": 120}),
            None,
        )
        .await;
    let body = expect_problem(unknown, StatusCode::UNPROCESSABLE_ENTITY, "unknown-field").await;
    assert_eq!(body["field"], "tempo");
    let nested = json!({"song_id": song_id, "model": "m", "seed_motion": {"fps": 25, "positions": [], "speed": 2}});
    let body = expect_problem(
        app.post_job(&nested, None).await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "unknown-field",
    )
    .await;
    assert_eq!(body["field"], "seed_motion.speed");

    // JSON has no NaN: the literal is malformed, and a string where a number goes names the field.
    let nan = app
        .post_job_raw(
            format!("{{\"song_id\": \"{song_id}\", \"model\": \"m\", \"seed\": NaN}}"),
            "application/json",
            None,
        )
        .await;
    expect_problem(nan, StatusCode::BAD_REQUEST, "malformed-json").await;
    let nan = app
        .post_job(
            &json!({"song_id": song_id, "model": "m", "seed": "NaN"}),
            None,
        )
        .await;
    let body = expect_problem(nan, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    assert_eq!(body["field"], "seed");
    let nan = app
        .post_job(&json!({"song_id": song_id, "model": "m", "key_poses": [{"time_s": "NaN", "joints": []}]}), None)
        .await;
    let body = expect_problem(nan, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    assert_eq!(body["field"], "key_poses[0].time_s");
    let huge = app
        .post_job_raw(
            format!("{{\"song_id\": \"{song_id}\", \"model\": \"m\", \"seed\": 1e999}}"),
            "application/json",
            None,
        )
        .await;
    assert!(huge.status().is_client_error(), "{}", huge.status());

    let missing = app.post_job(&json!({"model": "m"}), None).await;
    let body = expect_problem(missing, StatusCode::UNPROCESSABLE_ENTITY, "missing-field").await;
    assert_eq!(body["field"], "song_id");
    let bad_id = app
        .post_job(&json!({"song_id": "../../etc", "model": "m"}), None)
        .await;
    let body = expect_problem(bad_id, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    assert_eq!(body["field"], "song_id");
    let negative = app
        .post_job(&json!({"song_id": song_id, "model": "m", "seed": -1}), None)
        .await;
    let body = expect_problem(negative, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    assert_eq!(body["field"], "seed");

    let not_json = app
        .post_job_raw("song_id=1", "application/x-www-form-urlencoded", None)
        .await;
    expect_problem(not_json, StatusCode::UNSUPPORTED_MEDIA_TYPE, "not-json").await;
    // Job options a model does not take, or values outside their range, name the field.
    let bogus_style = app
        .post_job(
            &json!({"song_id": song_id, "model": "dance-revolution", "style": "polka"}),
            None,
        )
        .await;
    let body = expect_problem(
        bogus_style,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid-field",
    )
    .await;
    assert_eq!(body["field"], "style");
    for style in ["waltz", "rumba", "cha-cha", "tango"] {
        assert!(
            body["detail"].as_str().is_some_and(|d| d.contains(style)),
            "{body}"
        );
    }
    let unknown_song = app
        .post_job(
            &json!({"song_id": "01234567-89ab-7def-8123-456789abcdef", "model": "m"}),
            None,
        )
        .await;
    let body = expect_problem(unknown_song, StatusCode::NOT_FOUND, "song-not-found").await;
    assert!(
        body["detail"]
            .as_str()
            .is_some_and(|d| d.contains("01234567-89ab-7def-8123-456789abcdef")),
        "{body}"
    );
    still_serving(&app).await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn job_options_a_model_does_not_take_are_refused() {
    let app = spawn_app_with(|c| {
        c.models_dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models")
    })
    .await;
    let song = app.upload_ok(&short_song()).await;
    let song_id = song["id"].as_str().expect("id").to_string();
    let not_taken = app
        .post_job(
            &json!({"song_id": song_id, "model": "dance-revolution", "style": "waltz"}),
            None,
        )
        .await;
    let body = expect_problem(not_taken, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    assert_eq!(body["field"], "style");
    let not_sampled = app
        .post_job(
            &json!({"song_id": song_id, "model": "dance-revolution", "temperature": 0.5}),
            None,
        )
        .await;
    let body = expect_problem(
        not_sampled,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid-field",
    )
    .await;
    assert_eq!(body["field"], "temperature");
    let no_top_k = app
        .post_job(
            &json!({"song_id": song_id, "model": "keypose-transformer", "top_k": 5}),
            None,
        )
        .await;
    let body = expect_problem(no_top_k, StatusCode::UNPROCESSABLE_ENTITY, "invalid-field").await;
    assert_eq!(body["field"], "top_k");
    still_serving(&app).await;
    app.stop().await;
}
