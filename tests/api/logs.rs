//! The service's log when stderr is a file or a pipe: plain lines without colour codes, JSON
//! lines with `CHOREO_LOG_FORMAT=json`, and no library's lines (symphonia logs an ERROR of its
//! own for a file that is not audio, which the 415 already says).
use crate::helpers::{listening_base, short_song, spawn_process, upload_to};
use reqwest::multipart::{Form, Part};
use reqwest::StatusCode;
use serde_json::Value;
use std::path::Path;
use std::process::Stdio;

/// Runs `choreo serve` with its stderr written to `log` and `env` set (and no `RUST_LOG`,
/// `NO_COLOR` or log setting inherited), uploads a song and a text file, and stops it; returns
/// what it logged.
async fn log_of_a_short_run(data: &Path, env: &[(&str, &str)]) -> String {
    let log = data.join("serve.log");
    let mut command = tokio::process::Command::new(env!("CARGO_BIN_EXE_choreo"));
    command
        .args([
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--workers",
            "1",
            "--data-dir",
        ])
        .arg(data)
        .arg("--models-dir")
        .arg(data.join("no-models"))
        .env_remove("RUST_LOG")
        .env_remove("NO_COLOR")
        .env_remove("CHOREO_LOG_FORMAT")
        .env_remove("CHOREO_LOG_LEVEL")
        .envs(env.iter().copied())
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(&log).expect("log file"))
        .kill_on_drop(true);
    let (mut child, line) = spawn_process(command).await;
    let base = listening_base(&line);
    let client = reqwest::Client::new();
    upload_to(
        &client,
        &base,
        std::fs::read(short_song()).expect("song"),
        "song.ogg",
    )
    .await;
    let form = Form::new().part(
        "file",
        Part::bytes(b"not a song, just words".to_vec()).file_name("notes.txt"),
    );
    let refused = client
        .post(format!("{base}/v1/songs"))
        .multipart(form)
        .send()
        .await
        .expect("upload");
    assert_eq!(refused.status(), StatusCode::UNSUPPORTED_MEDIA_TYPE);
    child.kill().await.expect("stop choreo serve");
    std::fs::read_to_string(&log).expect("log")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_log_written_to_a_file_is_plain_text() {
    let data = tempfile::tempdir().expect("tempdir");
    let log = log_of_a_short_run(data.path(), &[]).await;
    assert!(log.contains("listening"), "{log}");
    assert!(
        !log.contains('\u{1b}'),
        "colour codes in a log file:\n{log:?}"
    );
    assert!(
        !log.contains("symphonia"),
        "a library's line in the log:\n{log}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn choreo_log_format_json_writes_one_json_object_a_line() {
    let data = tempfile::tempdir().expect("tempdir");
    let log = log_of_a_short_run(data.path(), &[("CHOREO_LOG_FORMAT", "json")]).await;
    let lines: Vec<Value> = log
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l:?}")))
        .collect();
    assert!(lines.iter().any(|l| l["message"] == "listening"), "{log}");
    for line in &lines {
        assert!(
            line["level"].is_string() && line["timestamp"].is_string(),
            "{line}"
        );
    }
    assert!(
        !log.contains('\u{1b}') && !log.contains("symphonia"),
        "{log}"
    );
}
