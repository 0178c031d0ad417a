//! `POST /v1/songs`, `GET /v1/songs`, `GET /v1/songs/{id}` and `GET /v1/songs/{id}/audio`.
use crate::helpers::{expect_problem, fixture, short_song, spawn_app};
use reqwest::StatusCode;
use serde_json::Value;
use sha2::{Digest, Sha256};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uploads_each_of_the_five_formats_and_analyses_them() {
    let app = spawn_app().await;
    let files = [
        ("ogg", short_song()),
        ("wav", fixture("wav")),
        ("flac", fixture("flac")),
        ("mp3", fixture("mp3")),
        ("m4a", fixture("m4a")),
    ];
    let mut ids = Vec::new();
    for (format, path) in &files {
        let bytes = std::fs::read(path).expect("read fixture");
        // The name says nothing: the format must come from decoding.
        let response = app.upload_bytes("no-extension", bytes.clone()).await;
        assert_eq!(response.status(), StatusCode::CREATED, "{format}");
        let location = response
            .headers()
            .get("location")
            .and_then(|v| v.to_str().ok())
            .map(str::to_string);
        let song: Value = response.json().await.expect("json");
        assert_eq!(song["format"], *format, "{song}");
        assert_eq!(
            location,
            Some(format!("/v1/songs/{}", song["id"].as_str().expect("id")))
        );
        let duration = song["duration_s"].as_f64().expect("duration");
        assert!(
            (duration - 5.333).abs() < 0.15,
            "{format}: duration {duration}"
        );
        assert_eq!(song["sample_rate"], 44_100, "{format}");
        assert_eq!(song["channels"], 2, "{format}");
        assert_eq!(song["size_bytes"], bytes.len() as u64);
        assert_eq!(song["sha256"], hex::encode(Sha256::digest(&bytes)));
        assert_eq!(song["filename"], "no-extension");
        let stored = app
            .data_dir
            .path()
            .join("songs")
            .join(format!("{}.{format}", song["id"].as_str().expect("id")));
        assert_eq!(std::fs::read(&stored).expect("stored under its id"), bytes);
        ids.push(song["id"].as_str().expect("id").to_string());
    }
    for id in &ids {
        let job = app.analyze_job_of(id).await;
        let job = app.wait_job(job["id"].as_str().expect("job id")).await;
        assert_eq!(job["status"], "succeeded", "{job}");
        let song: Value = app
            .get(&format!("/v1/songs/{id}"))
            .await
            .json()
            .await
            .expect("json");
        assert_eq!(song["analysis_status"], "succeeded");
        let analysis = &song["analysis"];
        let tempo = analysis["tempo_bpm"].as_f64().expect("tempo");
        assert!(tempo > 40.0 && tempo < 250.0, "{analysis}");
        let beats = analysis["beat_times"].as_array().expect("beats");
        assert!(
            beats.len() >= 4,
            "a 5 s loop at 90 bpm has beats: {analysis}"
        );
        assert!(
            beats
                .iter()
                .all(|t| t.as_f64().is_some_and(|t| (0.0..=5.4).contains(&t))),
            "{analysis}"
        );
        assert!(analysis["downbeat_times"].is_array());
    }
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_same_bytes_return_the_existing_song() {
    let app = spawn_app().await;
    let first = app.upload(&short_song()).await;
    assert_eq!(first.status(), StatusCode::CREATED);
    let first: Value = first.json().await.expect("json");
    let again = app
        .upload_bytes("renamed.ogg", std::fs::read(short_song()).expect("read"))
        .await;
    assert_eq!(again.status(), StatusCode::OK);
    let again: Value = again.json().await.expect("json");
    assert_eq!(again["id"], first["id"]);
    assert_eq!(
        again["filename"], first["filename"],
        "the first upload's name is kept"
    );
    let jobs: Value = app.get("/v1/jobs").await.json().await.expect("json");
    assert_eq!(
        jobs["items"].as_array().map(Vec::len),
        Some(1),
        "one analyze job: {jobs}"
    );
    let songs = std::fs::read_dir(app.data_dir.path().join("songs"))
        .expect("songs dir")
        .count();
    assert_eq!(songs, 1);
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_song_shows_its_analysis_status_before_the_analysis() {
    let app = spawn_app().await;
    let song = app.upload_ok(&short_song()).await;
    assert!(
        ["queued", "running", "succeeded"]
            .contains(&song["analysis_status"].as_str().unwrap_or("")),
        "{song}"
    );
    if song["analysis_status"] != "succeeded" {
        assert!(song["analysis"].is_null(), "{song}");
    }
    let missing = app
        .get("/v1/songs/01234567-89ab-7def-8123-456789abcdef")
        .await;
    expect_problem(missing, StatusCode::NOT_FOUND, "song-not-found").await;
    let garbage = app.get("/v1/songs/not-an-id").await;
    expect_problem(garbage, StatusCode::NOT_FOUND, "song-not-found").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_song_is_served_back_byte_for_byte_with_its_format_s_type() {
    let app = spawn_app().await;
    for (path, mime) in [
        (short_song(), "audio/ogg"),
        (fixture("mp3"), "audio/mpeg"),
        (fixture("m4a"), "audio/mp4"),
    ] {
        let bytes = std::fs::read(&path).expect("read song");
        let song = app.upload_ok(&path).await;
        let response = app
            .get(&format!(
                "/v1/songs/{}/audio",
                song["id"].as_str().expect("id")
            ))
            .await;
        assert_eq!(response.status(), StatusCode::OK);
        assert_eq!(
            response.headers()["content-type"],
            mime,
            "{}",
            path.display()
        );
        assert_eq!(
            response.headers()["content-length"],
            bytes.len().to_string().as_str()
        );
        assert!(
            response.bytes().await.expect("body").as_ref() == bytes.as_slice(),
            "{} comes back as uploaded",
            path.display()
        );
    }
    let unknown = app
        .get("/v1/songs/01900000-0000-7000-8000-000000000000/audio")
        .await;
    expect_problem(unknown, StatusCode::NOT_FOUND, "song-not-found").await;
    expect_problem(
        app.get("/v1/songs/not-an-id/audio").await,
        StatusCode::NOT_FOUND,
        "song-not-found",
    )
    .await;
    app.stop().await;
}

/// `GET /v1/songs`: the caller's songs, newest first, a page at a time; another key's songs are
/// not listed, and its cursor is refused as any id that is not a `next_cursor`.
async fn the_song_list_pages_newest_first_with_the_caller_s_songs_only(db: crate::tenants::Db) {
    use choreo::queue::KeyLimits;
    let app = crate::tenants::spawn(db, |_| {}).await;
    let mine = app.key("mine", KeyLimits::default()).await;
    let theirs = app.key("theirs", KeyLimits::default()).await;
    let mut uploaded = Vec::new();
    for path in [short_song(), fixture("wav"), fixture("flac")] {
        let response = app.upload(&mine, &path).await;
        assert_eq!(response.status(), StatusCode::CREATED);
        let song: Value = response.json().await.expect("song");
        uploaded.push(song["id"].as_str().expect("id").to_string());
    }
    let other: Value = app
        .upload(&theirs, &short_song())
        .await
        .json()
        .await
        .expect("song");
    let newest_first: Vec<String> = uploaded.iter().rev().cloned().collect();

    let first: Value = app
        .get("/v1/songs?limit=2", &mine)
        .await
        .json()
        .await
        .expect("page");
    let ids = |page: &Value| -> Vec<String> {
        page["items"]
            .as_array()
            .expect("items")
            .iter()
            .map(|s| s["id"].as_str().expect("id").to_string())
            .collect()
    };
    assert_eq!(ids(&first), newest_first[..2], "{first}");
    // Each item is the song as GET /v1/songs/{id} shows it.
    assert_eq!(first["items"][0]["format"], "flac", "{first}");
    assert!(first["items"][0]["analysis_status"].is_string(), "{first}");
    let cursor = first["next_cursor"].as_str().expect("a next page");
    let second: Value = app
        .get(&format!("/v1/songs?limit=2&cursor={cursor}"), &mine)
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(ids(&second), newest_first[2..], "{second}");
    assert!(
        second.get("next_cursor").is_none_or(Value::is_null),
        "{second}"
    );

    let theirs_page: Value = app
        .get("/v1/songs", &theirs)
        .await
        .json()
        .await
        .expect("page");
    assert_eq!(ids(&theirs_page), [other["id"].as_str().expect("id")]);
    for (query, field) in [("limit=0", "limit"), ("cursor=nope", "cursor")] {
        let body = expect_problem(
            app.get(&format!("/v1/songs?{query}"), &mine).await,
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid-field",
        )
        .await;
        assert_eq!(body["field"], field, "{body}");
    }
    expect_problem(
        app.get("/v1/songs?page=2", &mine).await,
        StatusCode::BAD_REQUEST,
        "invalid-query",
    )
    .await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_song_list_on_sqlite() {
    the_song_list_pages_newest_first_with_the_caller_s_songs_only(crate::tenants::Db::Sqlite).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_song_list_on_postgres() {
    the_song_list_pages_newest_first_with_the_caller_s_songs_only(crate::tenants::Db::Postgres)
        .await
}
