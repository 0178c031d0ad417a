//! beat-graph on real songs and real key poses: on the beat, seamless at its joins, recombining
//! rather than replaying, and following its controls.
use super::*;
use choreo::metrics::plausibility::{angular_velocities, joint_angles};
use choreo::metrics::reference::ReferenceStats;
use choreo::models::beat_graph::{self, Composition};
use choreo::motion::repr;

const ID: &str = "beat-graph";

fn served() -> beat_graph::Served {
    beat_graph::Served::load(&common_models::models_dir().join(ID)).expect("beat-graph loads")
}

/// The first `seconds` of shared song `name`.
fn song_head(name: &str, seconds: f64) -> DecodedAudio {
    let mut a = audio::decode_path(&shared_song_path(name)).expect("decodes");
    let keep = ((seconds * a.sample_rate as f64) as usize).min(a.samples.len());
    a.samples.truncate(keep);
    a.duration_s = keep as f64 / a.sample_rate as f64;
    a
}

fn composed(song: &DecodedAudio, req: GenerateRequest<'_>) -> (Motion, Composition) {
    let g = model(ID).generate(&req, &mut Quiet).expect("composes");
    let c = g.composition.expect("a composition");
    assert_eq!(
        g.motion.num_frames(),
        song_frames(song.duration_s, MOTION_FPS)
    );
    (g.motion, c)
}

/// Share of frames `frames` whose every joint angle (`velocity`: angular velocity) lies within
/// the real train dances' limits.
fn share_within(motion: &Motion, frames: &[usize], velocity: bool) -> f64 {
    let limits = ReferenceStats::builtin().expect("reference").angle_limits;
    let angles = joint_angles(motion.positions.view(), &limits.triples);
    let (series, bounds) = if velocity {
        (
            angular_velocities(&angles, motion.fps),
            &limits.velocity_deg_s,
        )
    } else {
        (angles, &limits.angle_deg)
    };
    let inside = frames
        .iter()
        .filter(|&&f| f < series.len())
        .filter(|&&f| {
            series[f]
                .iter()
                .zip(bounds)
                .all(|(v, [lo, hi])| v >= lo && v <= hi)
        })
        .count();
    inside as f64 / frames.len().max(1) as f64
}

/// The longest stretch (s) of `motion` that follows one dance of `library` in order: each frame's
/// nearest library pose (root-relative, facing aligned: the model's own features) within 5 cm
/// RMS, and the next frame's 0–3 frames further on in the same dance.
fn longest_copy_s(motion: &Motion, library: &beat_graph::library::Library) -> f64 {
    let root = choreo::motion::skeleton::body_centre_track(motion.positions.view());
    let (x, _) = repr::to_features(motion.positions.view(), root.view()).expect("features");
    let pose = |m: &ndarray::Array2<f32>| {
        let rows = m.nrows() as i64;
        let v: Vec<f32> = m
            .rows()
            .into_iter()
            .flat_map(|r| r.iter().take(repr::POSE_DIM).copied().collect::<Vec<_>>())
            .collect();
        tch::Tensor::from_slice(&v).view([rows, repr::POSE_DIM as i64])
    };
    let lib = pose(&library.frames);
    let lib_sq = lib
        .pow_tensor_scalar(2)
        .sum_dim_intlist(1, false, tch::Kind::Float);
    let mut nearest: Vec<(usize, f32)> = Vec::new();
    for chunk in x.axis_chunks_iter(ndarray::Axis(0), 256) {
        let q = pose(&chunk.to_owned());
        let d = q
            .pow_tensor_scalar(2)
            .sum_dim_intlist(1, true, tch::Kind::Float)
            + lib_sq.unsqueeze(0)
            - q.matmul(&lib.transpose(0, 1)) * 2.0;
        let (min, arg) = d.min_dim(1, false);
        let min = Vec::<f32>::try_from(min).expect("min");
        let arg = Vec::<i64>::try_from(arg).expect("arg");
        nearest.extend(arg.into_iter().map(|a| a as usize).zip(min));
    }
    let dance_of = |row: usize| library.dance_first.partition_point(|&f| f <= row) - 1;
    let within = |d2: f32| (d2.max(0.0) / NUM_JOINTS as f32).sqrt() < 0.05;
    let (mut best, mut run) = (0usize, 0usize);
    for t in 0..nearest.len() {
        let (row, d2) = nearest[t];
        let follows = t > 0 && {
            let (prev, pd2) = nearest[t - 1];
            within(pd2) && dance_of(prev) == dance_of(row) && row >= prev && row <= prev + 3
        };
        run = if !within(d2) {
            0
        } else if follows {
            run + 1
        } else {
            1
        };
        best = best.max(run);
    }
    best as f64 / motion.fps
}

#[test]
fn a_whole_unseen_song_is_danced_on_its_beats_seamlessly_without_replaying() {
    let song = song_head("lets_go_fishin.ogg", 90.0);
    let analysis = audio::analyze(&song).expect("analysis");
    let mut req = GenerateRequest::plain(&song, 3);
    req.analysis = Some(&analysis);
    let (motion, composition) = composed(&song, req);
    // Recombines: no stretch of a training dance longer than 12 s, by the path and by poses.
    assert!(composition.longest_copy_s <= 12.0, "{composition:?}");
    // (One seed may lean on one dancer for a whole song: it still recombines that dancer's beats.)
    assert!(
        composition.dances_used >= 1 && composition.slots >= 150,
        "{composition:?}"
    );
    let copied = longest_copy_s(&motion, served().library());
    assert!(
        copied <= 12.0,
        "{copied} s copied in order from one training dance"
    );
    // Seamless: around every join (±3 frames) the joint angles and their velocities are as
    // real as over the whole dance, less a little.
    let fps = motion.fps;
    let near: Vec<usize> = composition
        .joins_s
        .iter()
        .flat_map(|t| {
            let f = (t * fps).round() as i64;
            (f - 3..=f + 3).filter_map(|g| usize::try_from(g).ok())
        })
        .collect();
    assert!(near.len() > 50, "{} frames near joins", near.len());
    let all: Vec<usize> = (0..motion.num_frames()).collect();
    for velocity in [false, true] {
        let (at, overall) = (
            share_within(&motion, &near, velocity),
            share_within(&motion, &all, velocity),
        );
        println!("velocity {velocity}: {at:.3} at the joins, {overall:.3} overall");
        assert!(
            at >= 0.7 && at >= overall - 0.08,
            "velocity {velocity}: {at:.3} at joins vs {overall:.3}"
        );
    }
    // No pop: served as a user downloads it, the physical verdict passes.
    let (finished, _) = choreo::motion::after_model(
        motion,
        &analysis.beat_times,
        &[],
        0,
        MotionStages::default(),
    );
    let served = choreo::motion::serve(&finished, &[], true, 0)
        .expect("served")
        .motion;
    let physical = choreo::metrics::physical::physical_series(&served, &[]).scores(1.0);
    let verdict = choreo::metrics::physical::verdict(&physical, &[], None);
    assert!(verdict.pass, "{verdict:?}");
    // On the song's beats: each unit is warped onto them, and the served dance is locked.
    let lock = choreo::metrics::musicality::tempo_lock(
        served.positions.view(),
        served.fps,
        &analysis.beat_times,
    )
    .expect("a step rate");
    assert!(lock.locked, "{lock:?}");
}

#[test]
fn seeds_and_songs_give_other_dances() {
    let (a, b) = (
        song_head("lets_go_fishin.ogg", 30.0),
        song_head("vibe_ace.ogg", 30.0),
    );
    let apart = |x: &Motion, y: &Motion| {
        let n = x.num_frames().min(y.num_frames());
        let (rx, ry) = (
            choreo::motion::skeleton::body_centre_track(x.positions.view()),
            choreo::motion::skeleton::body_centre_track(y.positions.view()),
        );
        let mut sum = 0.0f64;
        for t in 0..n {
            for j in 0..NUM_JOINTS {
                let d: f32 = (0..3)
                    .map(|k| {
                        ((x.positions[[t, j, k]] - rx[[t, k]])
                            - (y.positions[[t, j, k]] - ry[[t, k]]))
                        .powi(2)
                    })
                    .sum();
                sum += f64::from(d.sqrt());
            }
        }
        sum / (n * NUM_JOINTS) as f64
    };
    let m = model(ID);
    let one = dance(m.as_ref(), &GenerateRequest::plain(&a, 1));
    let two = dance(m.as_ref(), &GenerateRequest::plain(&a, 2));
    let other_song = dance(m.as_ref(), &GenerateRequest::plain(&b, 1));
    let (seeds, songs) = (apart(&one, &two), apart(&one, &other_song));
    assert!(
        seeds >= 0.15 && songs >= 0.15,
        "seeds {seeds:.3} m, songs {songs:.3} m apart"
    );
}

#[test]
fn key_poses_are_reached_and_a_seed_motion_is_continued() {
    let ds = choreo::motion::dataset::Dataset::open_default().expect("the dataset (../shared)");
    let real = ds.load("DANCE_W_3").expect("a test dance");
    let rel = real.root_relative();
    let song = song_head("sugar_plum_fairy.ogg", 40.0);
    let keys: Vec<KeyPose> = [8.0, 17.5, 29.0]
        .iter()
        .map(|&t| KeyPose {
            time_s: t,
            joints: (0..NUM_JOINTS)
                .map(|j| {
                    let f = (t * MOTION_FPS) as usize;
                    [0, 1, 2].map(|k| f64::from(rel[[f, j, k]]))
                })
                .collect(),
        })
        .collect();
    let req = GenerateRequest {
        key_poses: &keys,
        ..GenerateRequest::plain(&song, 4)
    };
    let (motion, _) = composed(&song, req);
    let errs =
        choreo::metrics::kinematics::key_pose_errors_cm(motion.positions.view(), motion.fps, &keys);
    assert_eq!(errs.len(), keys.len());
    assert!(errs.iter().all(|e| *e <= 3.0), "{errs:?} cm");
    // A seed motion: its 2 s open the dance, and the dance goes on from its last pose with no
    // pop (the largest acceleration over the half second after it is a real dancer's).
    let seed = Motion {
        fps: MOTION_FPS,
        positions: real
            .motion
            .positions
            .slice(ndarray::s![100..150, .., ..])
            .to_owned(),
    };
    let req = GenerateRequest {
        seed_motion: Some(&seed),
        ..GenerateRequest::plain(&song, 4)
    };
    let (motion, _) = composed(&song, req);
    let opening = motion.positions.slice(ndarray::s![..50, .., ..]);
    let drift = (&opening - &seed.positions)
        .mapv(f32::abs)
        .fold(0.0f32, |a, &b| a.max(b));
    assert!(drift < 0.01, "the seed's frames moved {drift} m");
    let window = Motion {
        fps: MOTION_FPS,
        positions: motion
            .positions
            .slice(ndarray::s![45..63, .., ..])
            .to_owned(),
    };
    let accel = choreo::metrics::physical::physical_series(&window, &[]).scores(1.0);
    assert!(
        accel.acceleration_m_s2.max < 56.0,
        "{:?}",
        accel.acceleration_m_s2
    );
}

#[test]
fn a_style_is_danced_and_the_one_tango_is_recombined() {
    let song = song_head("vibe_ace.ogg", 60.0);
    for style in [DanceStyle::Waltz, DanceStyle::Tango] {
        let req = GenerateRequest {
            style: Some(style),
            ..GenerateRequest::plain(&song, 2)
        };
        let g = model(ID).generate(&req, &mut Quiet).expect("composes");
        let chosen = g.style.expect("a style");
        assert_eq!(chosen.style, style);
        assert!(!chosen.predicted);
        let c = g.composition.expect("composition");
        // The train split has one tango: the path recombines its beats (and takes units of the
        // other dances in four where none of its own fits) rather than replay it.
        assert!(c.longest_copy_s <= 12.0, "{style:?}: {c:?}");
    }
}

/// A song that speeds up from a rumba's tempo (95 BPM) to 148 BPM: the guessed style changes at
/// the change to the style whose tempo fits and whose steps a beat are the rumba's (a cha-cha,
/// not the one tango, whose dancer steps 0.38 a beat), so the steps speed up with the beats. A
/// steady song, or a style asked for, is one section.
#[test]
fn a_song_that_speeds_up_changes_to_a_style_of_the_same_steps_a_beat() {
    use choreo::audio::{Analysis, TempoPoint};
    use choreo::models::{DanceStyle, StyleChoice};
    let s = served();
    let beats = |from: f64, to: f64, step: f64| {
        let mut v = Vec::new();
        let mut t = from;
        while t < to {
            v.push(t);
            t += step;
        }
        v
    };
    let mut beat_times = beats(0.0, 56.0, 60.0 / 95.0);
    beat_times.extend(beats(56.0, 90.0, 60.0 / 148.0));
    let downbeat_times: Vec<f64> = beat_times.iter().copied().step_by(4).collect();
    let mut tempo_curve: Vec<TempoPoint> = (0..28)
        .map(|k| TempoPoint {
            time_s: 2.0 * k as f64,
            bpm: 95.0,
        })
        .collect();
    tempo_curve.extend((28..45).map(|k| TempoPoint {
        time_s: 2.0 * k as f64,
        bpm: 148.0,
    }));
    let changing = Analysis {
        tempo_bpm: 120.0,
        beat_times,
        downbeat_times,
        tempo_curve: tempo_curve.clone(),
    };
    let guess = |a: &Analysis| s.predict_style(60.0 / 95.0, beat_graph::served::meter_of(a));
    let sections = s.sections(&changing, &guess(&changing), 90.0);
    let styles: Vec<(f64, DanceStyle)> = sections.iter().map(|x| (x.from_s, x.style)).collect();
    assert_eq!(
        styles,
        vec![(0.0, DanceStyle::Rumba), (56.0, DanceStyle::ChaCha)],
        "{sections:?}"
    );
    let asked = StyleChoice {
        style: DanceStyle::Rumba,
        predicted: false,
        probabilities: Vec::new(),
    };
    assert_eq!(s.sections(&changing, &asked, 90.0).len(), 1);
    let steady = Analysis {
        tempo_curve: vec![
            TempoPoint {
                time_s: 0.0,
                bpm: 95.0,
            },
            TempoPoint {
                time_s: 90.0,
                bpm: 95.0,
            },
        ],
        ..changing.clone()
    };
    assert_eq!(s.sections(&steady, &guess(&steady), 90.0).len(), 1);
}
