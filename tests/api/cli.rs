//! The `choreo` binary as a newcomer meets it: `generate`'s help shows its defaults, and its
//! errors name the file and the models folder (and the nearest model id) without a library's
//! log lines.
use crate::helpers::short_song;
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
    assert!(line("--model <MODEL>").ends_with("[default: dance-revolution]"), "{help}");
    assert!(line("--models-dir").ends_with("[default: models]"), "{help}");
    assert!(line("--seed").ends_with("[default: 0]"), "{help}");
    let usage = help.lines().find(|l| l.starts_with("Usage:")).expect("usage");
    assert!(!usage.contains("--model"), "--model is not required: {usage}");
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
    assert!(stderr.contains("did you mean dance-revolution?"), "{stderr}");

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
    assert!(!stderr.contains("symphonia"), "a library's log line: {stderr}");
    assert!(!stderr.contains('\u{1b}'), "colour codes on a pipe: {stderr:?}");
}
