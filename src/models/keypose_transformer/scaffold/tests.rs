use super::*;

fn bank() -> PoseBank {
    // Clip c, frame f: every coordinate c·100 + f, so a pose tells where it came from.
    PoseBank::new(Array3::from_shape_fn((3, 40, 73), |(c, f, _)| {
        (c * 100 + f) as f32
    }))
    .unwrap()
}

#[test]
fn same_seed_same_scaffold_and_other_seeds_differ() {
    let b = bank();
    let a = b.scaffold(1, 200, 5, 10, &[]);
    let a2 = b.scaffold(1, 200, 5, 10, &[]);
    assert_eq!(a.poses, a2.poses);
    assert_eq!(a.seed, a2.seed);
    let others: Vec<_> = (2..6)
        .map(|s| b.scaffold(s, 200, 5, 10, &[]).seed)
        .collect();
    assert!(others.iter().any(|o| *o != a.seed));
    // Poses every 10 frames after the seed, following the clip's own timing.
    let frames: Vec<usize> = a.poses.iter().map(|p| p.0).collect();
    assert_eq!(frames, (14..200).step_by(10).collect::<Vec<_>>());
    let v0 = a.seed[[4, 0]];
    assert_eq!(a.poses[0].1[0], v0 + 10.0);
}

#[test]
fn a_dance_starts_on_a_lively_stretch() {
    // Clip 0 stands still; clip 1 stands still for its first 100 frames, then travels at 1 m/s.
    let mut clips = Array3::<f32>::zeros((2, 300, FEATURE_DIM));
    clips.slice_mut(s![1, 100.., repr::ROOT_VZ]).fill(0.04);
    let b = PoseBank::new(clips).unwrap();
    assert_eq!(b.pace(0, 0, 125), 0.0);
    assert!((b.pace(1, 100, 125) - 1.0).abs() < 1e-4);
    for seed in 0..20 {
        // Where it starts, the next 125 frames move at the slowest real dance's pace at least.
        let (clip, start) = b.scaffold(seed, 125, 25, 12, &[]).start;
        assert!(
            clip == 1 && b.pace(1, start, 125) >= LIVELY_M_S,
            "seed {seed} starts at {clip}/{start}"
        );
    }
    // With nothing lively the first draw is taken as it is.
    let still = PoseBank::new(Array3::zeros((2, 300, FEATURE_DIM))).unwrap();
    assert_eq!(still.scaffold(3, 125, 25, 12, &[]).seed.nrows(), 25);
    // The threshold is the slowest real train dance the metrics measure.
    let real = crate::metrics::reference::ReferenceStats::builtin()
        .unwrap()
        .physical
        .mean_speed_range_m_s[0];
    assert!((real - LIVELY_M_S).abs() < 0.005, "{real}");
}

#[test]
fn scaffold_keeps_away_from_user_keys_and_can_be_off() {
    let b = bank();
    let key = LocalKey {
        frame: 50,
        local: vec![0.0; POSE_DIM],
        yaw: 0.0,
    };
    let a = b.scaffold(3, 200, 5, 10, std::slice::from_ref(&key));
    assert!(a.poses.iter().all(|(f, _)| f.abs_diff(50) >= 10));
    assert!(b.scaffold(3, 200, 5, 0, &[]).poses.is_empty());
}

/// A bank of `periods.len()` clips of 200 frames, clip c's frame f holding c·1000 + f in every
/// coordinate, its beats every `periods[c]` frames from frame 3.
fn beat_bank(periods: &[f64]) -> PoseBank {
    let clips = Array3::from_shape_fn((periods.len(), 200, 73), |(c, f, _)| (c * 1000 + f) as f32);
    let infos = periods
        .iter()
        .enumerate()
        .map(|(c, &p)| ClipInfo {
            dance: format!("DANCE_C_{c}"),
            start: 0,
            style: crate::motion::dataset::Style::ChaCha,
            beats: (0..)
                .map(|k| 3.0 + p * k as f64)
                .take_while(|b| *b <= 199.0)
                .collect(),
            bar: 4,
            energy: 1.0,
        })
        .collect();
    PoseBank::new(clips)
        .unwrap()
        .with_meta(BankMeta {
            made_by: "test".into(),
            fps: 25.0,
            clips: infos,
        })
        .unwrap()
}

/// A song of `n` frames with beats every `period` frames from frame `first`, four a bar.
fn song(period: f64, first: f64, n: usize) -> SongCues {
    let beats: Vec<f64> = (0..)
        .map(|k| (first + period * k as f64) / 25.0)
        .take_while(|t| *t * 25.0 < n as f64)
        .collect();
    let down: Vec<f64> = beats.iter().step_by(4).copied().collect();
    SongCues::new(&beats, &down, &vec![1.0; n], 25.0, n, 12.0)
}

#[test]
fn retimed_clips_put_their_beats_on_the_songs_beats() {
    let b = beat_bank(&[12.0; 6]);
    // Song beats every 10 frames from frame 4: clips of 12-frame beats play 1.2 times as fast.
    let cues = song(10.0, 4.0, 400);
    for seed in 0..6 {
        let sc = b.scaffold_to(seed, &cues, 400, 25, &[]).unwrap();
        assert!(sc.poses.len() > 30);
        let mut last: Option<(usize, f32)> = None;
        for (frame, pose) in &sc.poses {
            // On a song beat, and the clip's pose on one of its own beats.
            assert_eq!((frame - 4) % 10, 0, "seed {seed}: pose at {frame}");
            let (clip, at) = ((pose[0] / 1000.0).floor() as usize, pose[0] % 1000.0);
            assert!(
                ((at - 3.0) / 12.0 - ((at - 3.0) / 12.0).round()).abs() < 1e-3,
                "seed {seed}: clip frame {at}"
            );
            // Within a clip the clip's time only moves forward, one clip beat per song beat.
            if let Some((c, a)) = last.filter(|l| l.0 == clip) {
                assert!(
                    (at - a - 12.0).abs() < 1e-3,
                    "seed {seed}: {a} → {at} in clip {c}"
                );
            }
            last = Some((clip, at));
        }
        // The seed rows are the first clip played at the song's pace: 1.2 clip frames a frame.
        let steps: Vec<f32> = sc
            .seed
            .column(0)
            .windows(2)
            .into_iter()
            .map(|w| w[1] - w[0])
            .collect();
        assert!(steps.iter().all(|d| (d - 1.2).abs() < 1e-3), "{steps:?}");
    }
}

#[test]
fn the_scaffold_turns_as_its_clips_turn_at_the_songs_pace() {
    // Each clip turns at its own constant rate, 0.01·(c + 1) rad a frame, and beats every 12
    // frames; the song beats every 10, so the clips play 1.2 times as fast and turn so.
    let mut b = beat_bank(&[12.0; 6]);
    for c in 0..6 {
        b.clips
            .slice_mut(s![c, .., repr::YAW_VEL])
            .fill(0.01 * (c + 1) as f32);
    }
    let sc = b
        .scaffold_to(2, &song(10.0, 4.0, 400), 400, 25, &[])
        .unwrap();
    assert_eq!(sc.facing.len(), 400);
    for (t, v) in sc.facing.iter().enumerate() {
        let c = v / (0.01 * 1.2);
        assert!(
            (c - c.round()).abs() < 1e-3 && (1.0..=6.0).contains(&c.round()),
            "frame {t}: {v}"
        );
    }
    // The first stretch turns as the clip the dance opens with.
    let first = 0.012 * (sc.start.0 + 1) as f32;
    assert!(
        (sc.facing[0] - first).abs() < 1e-5,
        "{} vs {first}",
        sc.facing[0]
    );
    // The legacy scaffold, without beats, gives no turning of its own.
    assert!(bank().scaffold(1, 200, 5, 10, &[]).facing.is_empty());
}

#[test]
fn the_song_chooses_the_clips_and_the_seed_chooses_among_them() {
    // Clips 0–4 beat every 10 frames, clips 5–9 every 16.
    let b = beat_bank(&[10.0, 10.0, 10.0, 10.0, 10.0, 16.0, 16.0, 16.0, 16.0, 16.0]);
    let (fast, slow) = (song(10.0, 0.0, 300), song(16.0, 0.0, 300));
    let clips = |sc: &Scaffold| -> Vec<usize> {
        sc.poses
            .iter()
            .map(|p| (p.1[0] / 1000.0).floor() as usize)
            .chain([sc.start.0])
            .collect()
    };
    let mut starts = std::collections::BTreeSet::new();
    for seed in 0..8 {
        let (a, z) = (
            b.scaffold_to(seed, &fast, 300, 25, &[]).unwrap(),
            b.scaffold_to(seed, &slow, 300, 25, &[]).unwrap(),
        );
        assert!(
            clips(&a).iter().all(|&c| c < 5),
            "seed {seed}: {:?}",
            clips(&a)
        );
        assert!(
            clips(&z).iter().all(|&c| c >= 5),
            "seed {seed}: {:?}",
            clips(&z)
        );
        assert_ne!(a.poses, z.poses);
        starts.insert(a.start.0);
    }
    assert!(
        starts.len() >= 2,
        "the seed draws among the good clips: {starts:?}"
    );
    // Same seed, same song: the same scaffold.
    assert_eq!(
        b.scaffold_to(3, &fast, 300, 25, &[]).unwrap().poses,
        b.scaffold_to(3, &fast, 300, 25, &[]).unwrap().poses
    );
}

#[test]
fn a_clip_that_holds_its_arms_is_drawn_only_where_too_few_others_suit() {
    // Eight clips suit the song alike; clip 0 holds its arms (0.3 m/s against the spine).
    let mut b = beat_bank(&[10.0; 8]);
    let used = |b: &PoseBank| -> std::collections::BTreeSet<usize> {
        (0..16)
            .flat_map(|seed| {
                let sc = b
                    .scaffold_to(seed, &song(10.0, 0.0, 600), 600, 25, &[])
                    .unwrap();
                sc.poses
                    .iter()
                    .map(|p| (p.1[0] / 1000.0).floor() as usize)
                    .chain([sc.start.0])
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    b.arms = vec![1.0; 8];
    assert!(used(&b).contains(&0), "all lively: clip 0 is drawn too");
    b.arms[0] = 0.3;
    assert!(!used(&b).contains(&0), "{:?}", used(&b));
}

#[test]
fn beat_scaffold_keeps_away_from_user_keys_and_thins_fast_beats() {
    let b = beat_bank(&[12.0; 4]);
    let key = LocalKey {
        frame: 100,
        local: vec![0.0; POSE_DIM],
        yaw: 0.0,
    };
    let sc = b
        .scaffold_to(
            1,
            &song(12.0, 0.0, 300),
            300,
            25,
            std::slice::from_ref(&key),
        )
        .unwrap();
    assert!(sc.poses.iter().all(|(f, _)| f.abs_diff(100) >= 12));
    assert!(sc.poses.iter().all(|(f, _)| *f >= 25 && *f < 300));
    // Beats every 6 frames: a pose every other beat.
    let fast = b
        .scaffold_to(1, &song(6.0, 0.0, 300), 300, 25, &[])
        .unwrap();
    assert!(
        fast.poses.windows(2).all(|p| p[1].0 - p[0].0 == 12),
        "{:?}",
        fast.poses.iter().map(|p| p.0).collect::<Vec<_>>()
    );
    // Beats every 24 frames: poses on half beats too.
    let slow = b
        .scaffold_to(1, &song(24.0, 0.0, 300), 300, 25, &[])
        .unwrap();
    assert!(slow.poses.len() > 20);
    assert!(slow.poses.windows(2).all(|p| p[1].0 - p[0].0 == 12));
    // Without the clips' beats there is no music-following scaffold.
    assert!(bank()
        .scaffold_to(1, &song(12.0, 0.0, 300), 300, 5, &[])
        .is_none());
}

#[test]
fn bank_meta_round_trips_beside_the_bank_and_is_checked() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(POSE_BANK_FILE);
    let b = beat_bank(&[12.0, 15.0]);
    b.save(&p).unwrap();
    assert!(dir.path().join(POSE_BANK_META_FILE).exists());
    assert_eq!(PoseBank::load(&p).unwrap().meta(), b.meta());
    let mut meta = b.meta().unwrap().clone();
    meta.clips[0].beats.push(250.0);
    assert!(PoseBank::new(b.clips.clone())
        .unwrap()
        .with_meta(meta.clone())
        .is_err());
    meta.clips.pop();
    assert!(PoseBank::new(b.clips.clone())
        .unwrap()
        .with_meta(meta)
        .is_err());
}

#[test]
fn bank_round_trips_through_safetensors_and_refuses_bad_shapes() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(POSE_BANK_FILE);
    let b = bank();
    b.save(&p).unwrap();
    let c = PoseBank::load(&p).unwrap();
    assert_eq!(c.clips, b.clips);
    assert!(PoseBank::new(Array3::zeros((0, 10, 73))).is_err());
    assert!(PoseBank::new(Array3::zeros((2, 10, 5))).is_err());
}
