use choreo::audio;
use choreo::metrics::musicality::Musicality;
use choreo::motion::dataset::Dataset;
use std::path::PathBuf;

#[test]
fn real_dances_step_at_a_fraction_of_the_beat_move_their_arms_and_bend_their_knees_forwards() {
    let root =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(choreo::motion::dataset::DEFAULT_ROOT);
    if !root.is_dir() {
        assert!(std::env::var("CI").as_deref() != Ok("true"), "../shared/data/dance-with-melody is missing; the musicality tests need it under CI=true");
        eprintln!("skipping: {} not found", root.display());
        return;
    }
    let data = Dataset::open(&root).expect("dataset opens");
    let (mut within_2, mut within_3, mut arms, mut knees) = (0, 0, Vec::new(), Vec::new());
    let mut postures = Vec::new();
    let ids = data.all_ids();
    for id in &ids {
        let d = data.load(id).expect("dance loads");
        let song = audio::decode_path(&d.audio_path).expect("song decodes");
        let start = d.song_time_s(0);
        let beats: Vec<f64> = audio::analyze(&song)
            .expect("analysis")
            .beat_times
            .iter()
            .map(|t| t - start)
            .collect();
        let m = Musicality::of(&d.motion, &beats);
        let lock = m.tempo_lock.expect("every real dance has a step rate");
        within_2 += usize::from(lock.distance <= 0.02);
        within_3 += usize::from(lock.locked);
        eprintln!(
            "{id}: step/beat {:.3} (nearest {:.3}, {:.1} %), arms {:.2} m/s, knees back {:.1} %",
            lock.ratio,
            lock.fraction,
            100.0 * lock.distance,
            m.arm_speed_m_s,
            100.0 * m.knee_backward_share
        );
        arms.push(m.arm_speed_m_s);
        knees.push(m.knee_backward_share);
        postures.push(
            m.posture_variety_m
                .expect("every real dance is longer than 12 s"),
        );
    }
    assert_eq!(ids.len(), 43);
    // numpy on the same beats (Hann, 16× zero-padding, beats inside the dance) gives 28 and 32.
    assert!(
        (27..=29).contains(&within_2),
        "within 2 %: {within_2} of 43"
    );
    assert!(
        (31..=33).contains(&within_3),
        "within 3 %: {within_3} of 43"
    );
    arms.sort_by(f64::total_cmp);
    let (lo, med, hi) = (arms[0], arms[21], arms[42]);
    assert!(
        (lo - 0.43).abs() < 0.01 && (med - 0.61).abs() < 0.01 && (hi - 1.44).abs() < 0.01,
        "arms {lo:.3}/{med:.3}/{hi:.3} m/s"
    );
    // The arms' posture over the song: no real dance holds one figure throughout
    // (tools/posture_variety.py, numpy, gives 0.059 / 0.127 / 0.216 m).
    postures.sort_by(f64::total_cmp);
    let (p_lo, p_med, p_hi) = (postures[0], postures[21], postures[42]);
    assert!(
        (p_lo - 0.059).abs() < 0.002
            && (p_med - 0.127).abs() < 0.002
            && (p_hi - 0.216).abs() < 0.002,
        "posture variety {p_lo:.3}/{p_med:.3}/{p_hi:.3} m"
    );
    let worst_knee = knees.iter().copied().fold(0.0, f64::max);
    assert!(
        (0.04..=0.05).contains(&worst_knee),
        "worst knee share {worst_knee}"
    );
    // The committed reference (train split only) holds what these functions give.
    let committed = choreo::metrics::reference::ReferenceStats::builtin()
        .expect("reference")
        .musicality;
    assert_eq!(committed.summary.measured, 37);
    assert!(
        committed.summary.tempo_locked <= within_3 && committed.within_2_percent <= within_2,
        "{committed:?}"
    );
    assert!(
        committed.arm_speed_range_m_s[0] >= lo - 1e-9
            && committed.arm_speed_range_m_s[1] <= hi + 1e-9,
        "{committed:?}"
    );
    assert!(
        committed.summary.knee_backward_max <= worst_knee + 1e-12,
        "{committed:?}"
    );
    let [p_min, p_max] = committed
        .posture_variety_range_m
        .expect("the committed reference measures posture variety");
    assert!(
        p_min >= p_lo - 1e-9 && p_max <= p_hi + 1e-9,
        "{committed:?}"
    );
    // The longest hold of the train split is DANCE_R_7's rumba pose (9.5 s), the longest of
    // all 43 ([`choreo::motion::hold`]).
    let hold = committed.summary.longest_hold_max_s;
    assert!(
        (hold - 9.48).abs() < 0.05 && hold <= choreo::motion::hold::HOLD_REAL_MAX_S,
        "{committed:?}"
    );
}
