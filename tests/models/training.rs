//! Training on a tiny schedule: TSMT and DanceNet train a few finite epochs on windows at other
//! tempi (and mirrored), with the step clock, the lock term and free runs.
use super::*;

/// The `model.json` a training run wrote into `dir`.
fn written_model_file(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("model.json")).unwrap()).unwrap()
}

/// A tiny run's log: one epoch, finite train and test losses, and `note` in its line.
fn one_finite_epoch(logs: &[choreo::models::train::EpochLog], note: &str) {
    assert_eq!(logs.len(), 1);
    let log = &logs[0];
    assert!(
        log.train_loss.is_finite() && log.test_loss.is_some_and(f64::is_finite),
        "{log:?}"
    );
    assert!(log.note.contains(note), "{}", log.note);
}

/// `choreo train tsmt --min-tempo … --max-tempo … --mirror true --self-condition …`
/// trains on windows re-timed and mirrored from the real train split, half of each window's input
/// frames drawn by the model itself: one tiny epoch gives finite losses, `model.json` records the
/// self-conditioning, and the folder it writes is served and dances the song.
#[test]
fn tsmt_trains_on_windows_at_other_tempi_and_mirrored() {
    use choreo::models::train::tsmt;
    let out = tempfile::tempdir().unwrap();
    let opts = tsmt::Options {
        common: tiny_training(out.path()),
        epochs: 1,
        min_tempo: 0.8,
        max_tempo: 1.25,
        mirror: true,
        self_condition: 0.5,
        self_run: 4,
        ..tsmt::Options::default()
    };
    one_finite_epoch(
        &tsmt::train(&opts).expect("training runs"),
        "tempo=0.8..1.25 mirror=true self=0.5x4/2",
    );
    let file = written_model_file(out.path());
    assert_eq!(file["training"]["self_condition"], 0.5);
    assert_eq!(file["training"]["self_run"], 4);
    let served = choreo::models::tsmt::Served::load(out.path()).expect("the folder loads");
    let motion = dance(&served, &GenerateRequest::plain(song(), 1));
    assert!(motion.positions.iter().all(|v| v.is_finite()));
}

/// `choreo train tsmt --init … --step-clock --lock-weight …`: a run continued
/// from a folder without the clock gives the network the clock (its new weights from zero), fits
/// each window's clock to the real dancer's step, and scores what the network means to draw after
/// its own draws against it, and with `--free-runs` dances a few windows freely through its
/// sampler and scores those too (the lock and, with `--free-body`, the body term): the real
/// continuations are scored, the test loss is logged
/// with the clock a quarter step late too, and the folder serves with the song's clock at the
/// gain written (`--clock-gain`), which the dance hears.
#[test]
fn tsmt_continues_with_the_step_clock_the_lock_term_and_free_runs() {
    use choreo::models::train::tsmt;
    let first = tempfile::tempdir().unwrap();
    let opts = tsmt::Options {
        common: tiny_training(first.path()),
        epochs: 1,
        ..tsmt::Options::default()
    };
    tsmt::train(&opts).expect("training runs");
    let out = tempfile::tempdir().unwrap();
    let continued = tsmt::Options {
        common: choreo::models::train::CommonOptions {
            init: Some(first.path().join("weights.safetensors")),
            ..tiny_training(out.path())
        },
        epochs: 1,
        min_tempo: 0.8,
        max_tempo: 1.25,
        self_condition: 0.5,
        self_run: 4,
        step_clock: true,
        lock_weight: 1.0,
        free_runs: 2,
        free_frames: 100,
        free_body: 1.0,
        clock_gain: 3.0,
        clock_step_hz: Some(0.49),
        ..tsmt::Options::default()
    };
    let logs = tsmt::train(&continued).expect("the continued run trains");
    one_finite_epoch(&logs, "test_clock_late=");
    // The tiny network's window is 16 frames, under one step: the real score is near zero there
    // (the served window, 80 frames, scores the real dancer well above it), but it is scored.
    let real = real_lock(&logs[0].note);
    assert!(real != 0.0 && real.abs() <= 1.0, "{}", logs[0].note);
    // The free runs' 100 frames hold several steps: the real continuation scores well above
    // zero on the clock fitted to it, and the network's own run is scored too.
    let free = |key: &str| -> f64 {
        let note = &logs[0].note;
        note.split(key)
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|r| r.parse().ok())
            .unwrap_or_else(|| panic!("no {key} in {note}"))
    };
    assert!(free("free_real=") > 0.1, "{}", logs[0].note);
    assert!(free("free_danced=").abs() <= 1.0, "{}", logs[0].note);
    // The body term reads the run's pace against the real one's and its lift off the floor.
    assert!(free("free_pace=") > 0.0, "{}", logs[0].note);
    assert!(free("free_lift=") >= 0.0, "{}", logs[0].note);
    let file = written_model_file(out.path());
    assert_eq!(file["config"]["step_clock"], true);
    assert_eq!(file["training"]["lock_weight"], 1.0);
    assert_eq!(file["training"]["free_runs"], 2);
    assert_eq!(file["training"]["free_frames"], 100);
    assert_eq!(file["training"]["free_body"], 1.0);
    assert_eq!(file["clock_gain"], 3.0);
    assert_eq!(file["clock_step_hz"], 0.49);
    // A folder at the trained gain (1) and the metre's clock does not write them.
    let plain_file = written_model_file(first.path());
    assert!(plain_file.get("clock_gain").is_none() && plain_file.get("clock_step_hz").is_none());
    let served = choreo::models::tsmt::Served::load(out.path()).expect("the folder loads");
    let motion = dance(&served, &GenerateRequest::plain(song(), 1));
    assert!(motion.positions.iter().all(|v| v.is_finite()));
    // The served gain is heard: the same seed at the gain the network trained with dances
    // otherwise.
    let mut at_one = file.clone();
    at_one.as_object_mut().unwrap().remove("clock_gain");
    std::fs::write(
        out.path().join("model.json"),
        serde_json::to_string_pretty(&at_one).unwrap(),
    )
    .unwrap();
    let plain = choreo::models::tsmt::Served::load(out.path()).expect("the folder loads");
    let other = dance(&plain, &GenerateRequest::plain(song(), 1));
    assert_ne!(
        motion.positions, other.positions,
        "the clock's gain changed nothing"
    );
}

/// The real continuations' lock logged in a dancenet epoch's note.
fn real_lock(note: &str) -> f64 {
    note.split("real=")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no real lock in {note}"))
}

/// DanceNet's trainer draws each window at its own tempo (`train::augment`: the rotation rows
/// and the music resampled together, the root and yaw velocities scaled), with `style_dropout`
/// leaves the style input out of a share of them, and with `lock_weight` dances a few windows on
/// its own and scores their toes' speed against the beats: a tiny epoch on the real
/// train split runs, logs all three (the real continuations' lock well above zero), records them
/// in `model.json`, and serves. A run continued from that folder (`--init`) keeps its rig and
/// normalisation.
#[test]
fn dancenet_trains_on_windows_at_other_tempi_with_the_lock_term_and_the_step_clock() {
    use choreo::models::train::dancenet;
    let out = tempfile::tempdir().unwrap();
    let opts = dancenet::Options {
        common: tiny_training(out.path()),
        epochs: 1,
        min_tempo: 0.8,
        max_tempo: 1.25,
        style_dropout: 0.5,
        mixtures: Some(1),
        lock_weight: 1.0,
        rollout_windows: 2,
        ..dancenet::Options::default()
    };
    let logs = dancenet::train(&opts).expect("training runs");
    one_finite_epoch(&logs, "tempo=0.8..1.25 style_dropout=0.5");
    let real = real_lock(&logs[0].note);
    assert!(real > 0.1 && real <= 1.0, "{}", logs[0].note);
    let file = written_model_file(out.path());
    assert_eq!(file["training"]["min_tempo"], 0.8);
    assert_eq!(file["training"]["max_tempo"], 1.25);
    assert_eq!(file["training"]["style_dropout"], 0.5);
    assert_eq!(file["training"]["lock_weight"], 1.0);
    let again = tempfile::tempdir().unwrap();
    let continued = dancenet::Options {
        common: choreo::models::train::CommonOptions {
            init: Some(out.path().join("weights.safetensors")),
            ..tiny_training(again.path())
        },
        epochs: 1,
        mixtures: Some(1),
        // Continued with the step clock: its columns are new to the weights (widened from zero).
        // The lock term then scores the danced toes on the clock's phase, whose zero is fitted
        // to the real dancer's speed: the real continuation must score well above zero.
        step_clock: true,
        lock_weight: 1.0,
        rollout_windows: 2,
        ..dancenet::Options::default()
    };
    let logs = dancenet::train(&continued).expect("the continued run trains");
    let real = real_lock(&logs[0].note);
    assert!(real > 0.1 && real <= 1.0, "{}", logs[0].note);
    assert!(
        logs[0].note.contains("test_gmm_clock_late="),
        "{}",
        logs[0].note
    );
    let second = written_model_file(again.path());
    for key in ["music_norm", "pose_norm", "rig"] {
        assert_eq!(second[key], file[key], "{key}");
    }
    assert_eq!(second["config"]["step_clock"], true);
    // The clock's folder serves: the song's beats make its clock.
    let served = choreo::models::dancenet::Served::load(again.path()).expect("the folder loads");
    // The style classifier is trained on its own (`choreo train dancenet-style`): ask for a style.
    let req = GenerateRequest {
        style: Some(DanceStyle::Waltz),
        ..GenerateRequest::plain(song(), 1)
    };
    let motion = dance(&served, &req);
    assert!(motion.positions.iter().all(|v| v.is_finite()));
}
