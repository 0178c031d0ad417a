//! The `choreo` binary as a newcomer meets it: `generate`'s help shows its defaults, its errors
//! name the file and the models folder (and the nearest model id) without a library's log lines,
//! `keys create` warns when it closes an open service, and `doctor` reports the keys.
use crate::helpers::{short_song, spawn_app};
use reqwest::StatusCode;
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output};

/// Runs the binary with `args`, without inherited log settings; stderr as it would reach a pipe.
fn choreo(args: &[&str], data_dir: Option<&Path>) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_choreo"));
    command
        .args(args)
        .env_remove("RUST_LOG")
        .env_remove("NO_COLOR")
        .env_remove("CHOREO_LOG_FORMAT")
        .env_remove("CHOREO_DATABASE_URL")
        .env_remove("CHOREO_AUTH_TOKEN");
    if let Some(dir) = data_dir {
        command.env("CHOREO_DATA_DIR", dir);
    }
    command.output().expect("run choreo")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn generate_s_help_shows_the_defaults() {
    let out = choreo(&["generate", "--help"], None);
    assert!(out.status.success());
    let help = text(&out.stdout);
    let line = |flag: &str| {
        help.lines()
            .find(|l| l.trim_start().starts_with(flag))
            .unwrap_or_else(|| panic!("no {flag} in\n{help}"))
            .to_string()
    };
    assert!(
        line("--model <MODEL>").ends_with("[default: beat-graph]"),
        "{help}"
    );
    assert!(
        line("--models-dir").ends_with("[default: models]"),
        "{help}"
    );
    assert!(line("--seed").ends_with("[default: 0]"), "{help}");
    let usage = help
        .lines()
        .find(|l| l.starts_with("Usage:"))
        .expect("usage");
    assert!(
        !usage.contains("--model"),
        "--model is not required: {usage}"
    );
}

#[test]
fn generate_s_errors_name_the_file_the_folder_and_the_nearest_model() {
    let models = crate::common_models::models_dir();
    let models_arg = models.to_str().expect("utf-8 path");
    let scratch = tempfile::tempdir().expect("tempdir");
    let out_dir = scratch.path().join("out");
    let out_arg = out_dir.to_str().expect("utf-8 path");
    let song = short_song();

    let misspelt = choreo(
        &[
            "generate",
            song.to_str().expect("utf-8 path"),
            "--model",
            "dance-revolutoin",
            "--models-dir",
            models_arg,
            "--out",
            out_arg,
        ],
        None,
    );
    assert!(!misspelt.status.success());
    let stderr = text(&misspelt.stderr);
    assert!(
        stderr.contains(&format!(
            "model dance-revolutoin is not available in {models_arg}, which holds"
        )),
        "{stderr}"
    );
    for id in crate::common_models::SERVED {
        assert!(stderr.contains(id), "{id} not named: {stderr}");
    }
    assert!(
        stderr.contains("did you mean dance-revolution?"),
        "{stderr}"
    );

    let missing = scratch.path().join("no-such-song.ogg");
    let gone = choreo(
        &[
            "generate",
            missing.to_str().expect("utf-8 path"),
            "--out",
            out_arg,
        ],
        None,
    );
    assert!(!gone.status.success());
    let stderr = text(&gone.stderr);
    assert!(
        stderr.contains(&format!("cannot read the song {}", missing.display())),
        "{stderr}"
    );
    assert!(stderr.contains("No such file or directory"), "{stderr}");

    // A text file: choreo says it is not audio, naming it; symphonia's own ERROR line (coloured
    // on a terminal) stays out.
    let notes = scratch.path().join("notes.txt");
    std::fs::write(&notes, "hi\n").expect("write");
    let not_audio = choreo(
        &[
            "generate",
            notes.to_str().expect("utf-8 path"),
            "--models-dir",
            models_arg,
            "--out",
            out_arg,
        ],
        None,
    );
    assert!(!not_audio.status.success());
    let stderr = text(&not_audio.stderr);
    assert!(
        stderr.contains(&format!("choreo generate {}", notes.display())),
        "{stderr}"
    );
    assert!(stderr.contains("not audio"), "{stderr}");
    assert!(
        !stderr.contains("symphonia"),
        "a library's log line: {stderr}"
    );
    assert!(
        !stderr.contains('\u{1b}'),
        "colour codes on a pipe: {stderr:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_first_key_warns_that_it_closes_the_open_service_and_doctor_counts_keys() {
    let app = spawn_app().await;
    let data = app.data_dir.path().to_path_buf();
    let no_models = data.join("no-models");
    let doctor_auth = || {
        let out = choreo(
            &["doctor", "--models-dir", no_models.to_str().expect("utf-8")],
            Some(&data),
        );
        assert!(out.status.success(), "{}", text(&out.stderr));
        let stdout = text(&out.stdout);
        stdout
            .lines()
            .find_map(|l| l.strip_prefix("auth "))
            .unwrap_or_else(|| panic!("no auth line: {stdout}"))
            .trim()
            .to_string()
    };
    assert_eq!(
        doctor_auth(),
        "off: the service is open (no API keys, no auth_token)"
    );
    let song = app.upload_ok(&short_song()).await;
    let song_path = format!("/v1/songs/{}", song["id"].as_str().expect("id"));

    let create = |args: &[&str]| {
        let mut all = vec!["keys", "create"];
        all.extend_from_slice(args);
        let out = choreo(&all, Some(&data));
        assert!(out.status.success(), "{}", text(&out.stderr));
        let made: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
        (made, text(&out.stderr))
    };
    let (_, warned) = create(&["--name", "first"]);
    assert!(
        warned.contains("warning: this service was open"),
        "{warned}"
    );
    assert!(
        warned.contains("--admin"),
        "says how to reach the open tenant's rows: {warned}"
    );
    let (admin, second) = create(&["--name", "ops", "--admin"]);
    assert_eq!(second, "", "only the first key closes the service");

    // What the warning says: anonymous requests are refused, an operator's key reads the song
    // made without a key.
    tokio::time::sleep(choreo::api::tenancy::KEY_CACHE + std::time::Duration::from_millis(200))
        .await;
    assert_eq!(app.get(&song_path).await.status(), StatusCode::UNAUTHORIZED);
    let read = app
        .client
        .get(app.url(&song_path))
        .bearer_auth(admin["secret"].as_str().expect("secret"))
        .send()
        .await
        .expect("GET");
    assert_eq!(read.status(), StatusCode::OK);

    assert_eq!(
        doctor_auth(),
        "on: an API key required on /v1 (API keys: 2 active, 0 revoked)"
    );
    app.stop().await;
}
