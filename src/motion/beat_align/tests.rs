use super::plan::*;
use super::rhythm::*;
use super::*;
use crate::metrics::musicality::{tempo_lock, TEMPO_FRACTIONS};
use crate::motion::skeleton::ANKLES;
use crate::motion::NUM_JOINTS;
use ndarray::Axis;

const FPS: f64 = 25.0;

/// A dance whose ankles travel with speed `1 + 0.8 cos(2π f t)` (so the step rate is `f`), the
/// rest of the body still; the ankles swing up and down too, so no two frames are equal.
fn periodic(seconds: f64, f: f64) -> Motion {
    let frames = (seconds * FPS) as usize;
    let mut p = Array3::<f32>::zeros((frames, NUM_JOINTS, 3));
    for t in 0..frames {
        let s = t as f64 / FPS;
        let x = s + 0.8 * (std::f64::consts::TAU * f * s).sin() / (std::f64::consts::TAU * f);
        for (side, &j) in ANKLES.iter().enumerate() {
            p[[t, j, 0]] = x as f32;
            p[[t, j, 1]] =
                (0.1 + 0.05 * (std::f64::consts::TAU * f * s + side as f64).cos()) as f32;
            p[[t, j, 2]] = side as f32 * 0.3;
        }
    }
    Motion {
        fps: FPS,
        positions: p,
    }
}

/// Beats every `period` s from `first` to past `seconds`.
fn beats(seconds: f64, period: f64, first: f64) -> Vec<f64> {
    (0..)
        .map(|i| first + i as f64 * period)
        .take_while(|&t| t < seconds + period)
        .collect()
}

#[test]
fn the_grid_fractions_and_the_checks_padding_are_the_metrics() {
    assert_eq!(GRID_FRACTIONS, TEMPO_FRACTIONS);
    assert_eq!(CHECK_ZERO_PAD, crate::metrics::musicality::ZERO_PAD);
}

#[test]
fn a_periodic_motion_off_the_grid_becomes_locked() {
    // 120 bpm; steps at 0.93 Hz, 7 % off half the beat rate: not locked as it comes.
    let (motion, beats) = (periodic(60.0, 0.93), beats(60.0, 0.5, 0.21));
    let before = tempo_lock(motion.positions.view(), FPS, &beats).expect("measured");
    assert!(!before.locked, "{before:?}");
    let (aligned, summary) = align(&motion, &beats, &[]);
    assert!(summary.applied, "{summary:?}");
    assert_eq!(summary.grid_fraction, 0.5);
    let after = tempo_lock(aligned.positions.view(), FPS, &beats).expect("measured");
    assert!(
        after.locked && (after.fraction - 0.5).abs() < 1e-9,
        "{after:?} {summary:?}"
    );
    assert!(summary.locked_share > 0.6, "{summary:?}");
    // Tempo changes: the same dance to a song 15 % faster locks too.
    let faster = beats_for(60.0, 0.5 / 1.15);
    let (aligned, summary) = align(&motion, &faster, &[]);
    let after = tempo_lock(aligned.positions.view(), FPS, &faster).expect("measured");
    assert!(after.locked, "{after:?} {summary:?}");
}

#[test]
fn a_rhythm_only_the_planted_dance_shows_is_the_one_locked() {
    // Steps at 0.93 Hz under a wide sway (sideways, in z) that the stage after it removes,
    // as planting removes a slow drift of a network's feet. The sway's speed peaks twice a
    // cycle, at 0.28 Hz: at 180 bpm out of every grid's reach (1/6 of the beat is 0.5 Hz).
    let beats = beats_for(60.0, 1.0 / 3.0);
    let mut motion = periodic(60.0, 0.93);
    for t in 0..motion.num_frames() {
        let s = t as f64 / FPS;
        for &j in &ANKLES {
            motion.positions[[t, j, 2]] += 3.0 * (std::f64::consts::TAU * 0.14 * s).sin() as f32;
        }
    }
    let unsway = |mut m: Motion| {
        for t in 0..m.num_frames() {
            for (side, &j) in ANKLES.iter().enumerate() {
                m.positions[[t, j, 2]] = side as f32 * 0.3;
            }
        }
        m
    };
    let (_, network_only) = align(&motion, &beats, &[]);
    assert!(!network_only.applied, "{network_only:?}");
    let (served, summary) = align_served(
        motion.clone(),
        &beats,
        &[],
        Some(unsway),
        None::<fn(&Motion) -> Option<Motion>>,
    );
    assert!(summary.applied, "{summary:?}");
    assert_eq!(summary.rhythm_from, RhythmFrom::Planted);
    assert!(summary.steps_on_beat, "{summary:?}");
    let after = tempo_lock(served.positions.view(), FPS, &beats).expect("measured");
    assert!(after.locked, "{after:?} {summary:?}");
    // What is served went through the stage after it: no sway left.
    assert!(served.positions.iter().all(|v| v.is_finite()));
    assert!((0..served.num_frames()).all(|t| served.positions[[t, ANKLES[0], 2]] == 0.0));
}

/// No stage after it, and no judge.
const UNFINISHED: Option<fn(Motion) -> Motion> = None;

#[test]
fn a_warp_whose_served_dance_is_off_the_beat_gives_way_to_the_next() {
    // Steps 4.5 % fast for half the beat rate, the body travelling: warps onto 1/2 and 2/3
    // of the beat rate, and paces, all step on the beat.
    let beats = beats(60.0, 0.5, 0.21);
    let mut motion = periodic(60.0, 1.045);
    for t in 0..motion.num_frames() {
        for j in (0..NUM_JOINTS).filter(|j| !ANKLES.contains(j)) {
            motion.positions[[t, j, 0]] = (t as f64 / FPS) as f32;
        }
    }
    let no_judge = None::<fn(&Motion) -> Option<Motion>>;
    let (first, s) = align_served(motion.clone(), &beats, &[], UNFINISHED, no_judge);
    assert!(s.applied && s.steps_on_beat, "{s:?}");
    // Served, the first choice stands still (no step rate at all); the next is served.
    let still = Motion {
        fps: FPS,
        positions: Array3::zeros(motion.positions.dim()),
    };
    let judge = |m: &Motion| {
        Some(if m.positions == first.positions {
            still.clone()
        } else {
            m.clone()
        })
    };
    let (next, s) = align_served(motion.clone(), &beats, &[], UNFINISHED, Some(judge));
    assert!(s.applied && s.steps_on_beat, "{s:?}");
    assert_ne!(next.positions, first.positions);
    let after = tempo_lock(next.positions.view(), FPS, &beats).expect("measured");
    assert!(after.locked, "{after:?} {s:?}");
    // Served, none steps on the beat: the first choice still, and the summary says so.
    let (kept, s) = align_served(motion, &beats, &[], UNFINISHED, Some(|_: &Motion| None));
    assert!(s.applied && !s.steps_on_beat, "{s:?}");
    assert_eq!(kept.positions, first.positions);
}

#[test]
fn a_dance_on_the_beat_as_it_came_is_served_as_it_came_where_no_warp_is() {
    // Steps at exactly half the beat rate: on the beat as it comes.
    let (motion, beats) = (periodic(60.0, 1.0), beats(60.0, 0.5, 0.21));
    // Served, every warp of it is off the beat (here: anything but the dance as it came).
    let judge = |m: &Motion| (m.positions == motion.positions).then(|| m.clone());
    let (served, s) = align_served(motion.clone(), &beats, &[], UNFINISHED, Some(judge));
    assert_eq!(served.positions, motion.positions);
    assert!(!s.applied && s.steps_on_beat, "{s:?}");
    assert!(
        s.skipped
            .as_deref()
            .is_some_and(|w| w.contains("as it came")),
        "{s:?}"
    );
    assert_eq!(s.grid_fraction, 0.5);
    assert!((s.step_hz - 1.0).abs() < 0.01, "{s:?}");
    assert_eq!((s.slope_min, s.slope_max, s.pace), (1.0, 1.0, 1.0));
}

fn beats_for(seconds: f64, period: f64) -> Vec<f64> {
    beats(seconds, period, 0.1)
}

#[test]
fn a_grid_below_the_step_band_is_not_chosen() {
    // 87 bpm: every 6 beats is 0.24 Hz, under the metric's 0.25 Hz floor. Steps at 0.25 Hz
    // would need almost no warp onto it, and are left alone (every 4 beats is out of reach);
    // steps at 0.33 Hz go to every 4 beats (0.36 Hz).
    let beats = beats(90.0, 60.0 / 87.0, 0.2);
    let (_, s) = align(&periodic(90.0, 0.25), &beats, &[]);
    assert!(!s.applied, "{s:?}");
    let motion = periodic(90.0, 0.33);
    let (aligned, s) = align(&motion, &beats, &[]);
    assert!(s.applied && s.grid_fraction == 0.25, "{s:?}");
    let after = tempo_lock(aligned.positions.view(), FPS, &beats).expect("measured");
    assert!(after.locked, "{after:?} {s:?}");
}

#[test]
fn fixed_times_start_and_end_map_to_themselves() {
    let (motion, beats) = (periodic(40.0, 1.07), beats(40.0, 0.5, 0.3));
    let keys = [7.0, 19.52, 31.0];
    let last = motion.num_frames() - 1;
    for (warp, _) in plan_from(&motion, &motion, &beats, &keys).expect("a warp") {
        assert!(warp.summary.applied, "{:?}", warp.summary);
        for f in [0, 175, 488, 775, last] {
            assert_eq!(warp.source_frames[f], f as f64, "frame {f}");
        }
    }
    let (aligned, _) = align(&motion, &beats, &keys);
    for f in [0, 175, 488, 775, last] {
        assert_eq!(
            aligned.positions.index_axis(Axis(0), f),
            motion.positions.index_axis(Axis(0), f),
            "frame {f}"
        );
    }
}

#[test]
fn the_warp_is_monotone_with_a_bounded_slope() {
    for (f, period) in [(0.93, 0.5), (1.2, 0.5), (0.55, 0.41), (1.9, 0.6)] {
        let (motion, beats) = (periodic(45.0, f), beats(45.0, period, 0.05));
        // With a key pose (pace 1) and without (the paces: the slope counts the pace's).
        for keys in [&[20.0][..], &[]] {
            // No warp within reach: the motion is served as it came (slope 1).
            let warps = plan_from(&motion, &motion, &beats, keys).unwrap_or_default();
            for (warp, _) in warps {
                for w in warp.source_frames.windows(2) {
                    let s = w[1] - w[0];
                    assert!(
                        s >= SLOPE_RANGE.0 * 0.97 && s <= SLOPE_RANGE.1 * 1.03,
                        "slope {s} ({f} Hz, {period} s): {:?}",
                        warp.summary
                    );
                }
                let s = &warp.summary;
                assert!(
                    s.slope_min >= SLOPE_RANGE.0 * 0.97 && s.slope_max <= SLOPE_RANGE.1 * 1.03,
                    "{s:?}"
                );
            }
        }
    }
}

#[test]
fn a_motion_a_little_faster_than_its_grid_is_played_slower_and_locks() {
    // 120 bpm; steps at 1.045 Hz, 4.5 % fast for half the beat rate.
    let (still, beats) = (periodic(60.0, 1.045), beats(60.0, 0.5, 0.21));
    // A dance that slow (the body still, 0.09 m/s) is not slowed further.
    assert_eq!(align(&still, &beats, &[]).1.pace, 1.0);
    // The body travelling with the ankles at 1 m/s: lively enough to be slowed a little.
    let mut motion = still.clone();
    for t in 0..motion.num_frames() {
        for j in (0..NUM_JOINTS).filter(|j| !ANKLES.contains(j)) {
            motion.positions[[t, j, 0]] = (t as f64 / FPS) as f32;
        }
    }
    let (aligned, s) = align(&motion, &beats, &[]);
    assert!(s.applied && s.pace < 1.0, "{s:?}");
    // Locked along (nearly) all of it: at pace 1, 88 % (two cycles lost in catch-ups).
    assert!(s.locked_share > 0.95, "{s:?}");
    assert!(
        (s.step_hz - 1.045).abs() < 0.02,
        "the motion's own rate: {s:?}"
    );
    let after = tempo_lock(aligned.positions.view(), FPS, &beats).expect("measured");
    assert!(
        after.locked && (after.ratio - 0.5).abs() < 0.005,
        "{after:?}"
    );
    // The dance still covers the song, and its first frame is the network's.
    assert_eq!(aligned.num_frames(), motion.num_frames());
    assert_eq!(
        aligned.positions.index_axis(Axis(0), 0),
        motion.positions.index_axis(Axis(0), 0)
    );
    // With a key pose the end is held: pace 1.
    let (_, with_key) = align(&motion, &beats, &[30.0]);
    assert_eq!(with_key.pace, 1.0, "{with_key:?}");
    // The first frame fixed, as every job fixes it, changes nothing.
    let (_, first) = align(&motion, &beats, &[0.0]);
    assert_eq!(first, s);
}

#[test]
fn too_short_too_few_beats_or_out_of_reach_is_left_alone() {
    let (out, s) = align(&periodic(1.0, 1.0), &beats(1.0, 0.1, 0.0), &[]);
    assert!(!s.applied && out.positions.dim().0 == 25, "{s:?}");
    let m = periodic(40.0, 1.0);
    let (out, s) = align(&m, &[1.0, 2.0], &[]);
    assert!(
        !s.applied && s.skipped.as_deref().is_some_and(|w| w.contains("beats")),
        "{s:?}"
    );
    assert_eq!(out.positions, m.positions);
    // Steps at 2.9 Hz against a 60-bpm song: the fastest grid (1 Hz) is out of reach.
    let m = periodic(40.0, 2.9);
    let (out, s) = align(&m, &beats(40.0, 1.0, 0.0), &[]);
    assert!(!s.applied && s.skipped.is_some(), "{s:?}");
    assert_eq!(out.positions, m.positions);
}

/// Every joint moving 1 m/s along x for `seconds`, but standing still over `still_s` (s) and
/// lifted 0.3 m (both feet up) over `up_s`.
fn walking(seconds: f64, still_s: std::ops::Range<f64>, up_s: std::ops::Range<f64>) -> Motion {
    let frames = (seconds * FPS) as usize;
    let mut p = Array3::<f32>::zeros((frames, NUM_JOINTS, 3));
    let mut x = 0.0;
    for t in 0..frames {
        let s = t as f64 / FPS;
        if !still_s.contains(&s) {
            x += 1.0 / FPS;
        }
        let up = if up_s.contains(&s) { 0.3 } else { 0.0 };
        for j in 0..NUM_JOINTS {
            p[[t, j, 0]] = x as f32;
            p[[t, j, 1]] = j as f32 * 0.1 + up;
        }
    }
    Motion {
        fps: FPS,
        positions: p,
    }
}

/// Of the candidates that step on the beat, the first that does not hold a pose for 5 s or
/// longer than the dance as it came is served; where every one does, or the dance as it came
/// held as long, the first; a 4-s hold is no reason to pass one over; one that hangs longer is
/// no alternative.
#[test]
fn a_warp_that_lengthens_a_hold_is_passed_over() {
    let candidate = |m: Motion, on_beat: bool| {
        let mut s = BeatAlignSummary::skipped("test");
        s.steps_on_beat = on_beat;
        (m, s, 0.0, None)
    };
    let no_judge = None::<&fn(&Motion) -> Option<Motion>>;
    let holds_6 = || walking(30.0, 10.0..16.0, 0.0..0.0);
    let lively = || walking(30.0, 0.0..0.0, 0.0..0.0);
    let chosen = |mut c: Vec<Candidate>, came| choose(&mut c, &[], no_judge, came);
    // A 6-s hold first, then `second` (on the beat or not).
    let after_a_hold = |second: Motion, on_beat, came| {
        chosen(
            vec![candidate(holds_6(), true), candidate(second, on_beat)],
            came,
        )
    };
    assert_eq!(after_a_hold(lively(), true, 3.0), 1);
    assert_eq!(after_a_hold(lively(), true, 6.5), 0);
    assert_eq!(after_a_hold(holds_6(), true, 3.0), 0);
    assert_eq!(after_a_hold(lively(), false, 3.0), 0);
    let holds_4 = walking(30.0, 10.0..14.0, 0.0..0.0);
    assert_eq!(
        chosen(
            vec![candidate(holds_4, true), candidate(lively(), true)],
            0.0
        ),
        0
    );
    // In place of one passed over for a hold, none that hangs longer than it or a real dancer
    // (0.72 s).
    let hangs = |s: f64| walking(30.0, 0.0..0.0, 20.0..20.0 + s);
    let three = |hang_s| {
        let c = vec![
            candidate(holds_6(), true),
            candidate(hangs(hang_s), true),
            candidate(lively(), true),
        ];
        chosen(c, 3.0)
    };
    assert_eq!(three(1.0), 2);
    assert_eq!(three(0.5), 1);
    // The measures the choice reads.
    let hung = hangs(1.0);
    assert!((hang_s(hung.positions.view(), FPS) - 1.0).abs() < 0.05);
    let held = longest_hold_s(holds_6().positions.view(), FPS);
    assert!((6.0..6.6).contains(&held), "{held}");
}
