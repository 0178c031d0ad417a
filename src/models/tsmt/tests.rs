//! Unit tests of the TSMT network: causality, the chunked audio stream, the cached steps,
//! sampling and the loss.
use super::sampling::{reach_m, Draw};
use super::*;
use crate::models::smooth_columns;
use ndarray::s;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use tch::nn::OptimizerConfig;

fn model(seed: i64) -> (nn::VarStore, Tsmt) {
    model_with(seed, false)
}

/// A tiny network (5 coordinates, 12 bins), with the step clock where `step_clock`.
fn model_with(seed: i64, step_clock: bool) -> (nn::VarStore, Tsmt) {
    tch::manual_seed(seed);
    let vs = nn::VarStore::new(Device::Cpu);
    let m = Tsmt::new(
        &vs.root(),
        Config {
            coords: 5,
            n_bins: 12,
            music_dim: 3,
            step_clock,
            ..Config::tiny()
        },
    );
    (vs, m)
}

fn tokens(b: i64, n: i64) -> Tensor {
    Tensor::randint(12, [b, n, 5], (Kind::Int64, Device::Cpu))
}

#[test]
fn bins_round_trip_within_half_a_bin() {
    let x = Array2::from_shape_fn((400, 2), |(t, c)| ((t as f32) * 0.01 + c as f32).sin());
    let b = Bins::fit([&x], 300).unwrap();
    let back = b.values(&b.tokens(&x));
    for c in 0..2 {
        let width = (b.hi[c] - b.lo[c]) / 300.0;
        let err = (&back.column(c) - &x.column(c))
            .mapv(f32::abs)
            .fold(0f32, |a, &v| a.max(v));
        assert!(
            err <= 0.5 * width + 1e-6,
            "column {c}: error {err}, bin {width}"
        );
    }
    assert_eq!(b.index(0, -100.0), 0);
    assert_eq!(b.index(0, 100.0), 299);
}

#[test]
fn dequantising_removes_bin_jitter_and_keeps_the_opening() {
    // A slow ramp drawn one bin off at random every frame, after 5 given frames.
    let mut rng = StdRng::seed_from_u64(1);
    let clean = Array2::from_shape_fn((200, 1), |(t, _)| t as f32 * 0.004);
    let mut x = clean.mapv(|v| v)
        + Array2::from_shape_fn((200, 1), |_| 0.004 * rng.gen_range(-1..=1) as f32);
    let given = x.slice(s![..5, ..]).to_owned();
    let accel = |a: &Array2<f32>| {
        (6..194)
            .map(|t| (a[[t + 1, 0]] - 2.0 * a[[t, 0]] + a[[t - 1, 0]]).abs())
            .fold(0f32, f32::max)
    };
    let before = accel(&x);
    smooth_columns(&mut x, 5, 1.5);
    assert_eq!(x.slice(s![..5, ..]), given);
    let after = accel(&x);
    assert!(
        after < 0.25 * before,
        "second difference {before} -> {after}"
    );
    // The ramp itself is kept (away from the ends).
    let off = (20..180)
        .map(|t| (x[[t, 0]] - clean[[t, 0]]).abs())
        .fold(0f32, f32::max);
    assert!(off < 0.004, "smoothing moved the ramp by {off}");
}

#[test]
fn logits_do_not_see_the_future_pose() {
    let (_vs, m) = model(0);
    let x = tokens(1, 11);
    let music = Tensor::randn([1, 11, 3], (Kind::Float, Device::Cpu));
    let a = m.forward(&x, &music, None, 0, false);
    assert_eq!(a.size(), vec![1, 10, 5, 12]);
    // Changing pose frame 6 may change logits of frames 7.. (index 6..), never frames ≤ 6.
    let x2 = x.copy();
    let _ = x2.narrow(1, 6, 1).fill_(3);
    let b = m.forward(&x2, &music, None, 0, false);
    let early = (a.narrow(1, 0, 6) - b.narrow(1, 0, 6))
        .abs()
        .max()
        .double_value(&[]);
    assert!(early < 1e-6, "frames ≤ 6 moved by {early}");
}

#[test]
fn chunked_audio_equals_one_pass() {
    let (_vs, m) = model(1);
    let music = Tensor::randn([1, 70, 3], (Kind::Float, Device::Cpu));
    let whole = m.audio.forward(&music, 0, false);
    let chunked = m
        .audio
        .forward_chunked(&music, m.config.a_kernel, 0, 9, |_| true)
        .unwrap();
    let d = (whole - chunked).abs().max().double_value(&[]);
    assert!(d < 1e-5, "chunked audio differs by {d}");
}

#[test]
fn cached_steps_equal_the_training_pass() {
    let (_vs, m) = model(2);
    let x = tokens(1, 9);
    let music = Tensor::randn([1, 9, 3], (Kind::Float, Device::Cpu));
    let logits = m.forward(&x, &music, None, 0, false); // [1, 8, 5, 12]
    let av = m
        .audio
        .forward(&music, 0, false)
        .squeeze_dim(0)
        .apply(&m.w_a);
    let mut caches = m.pose.stack.new_caches();
    for t in 0..8 {
        let wx = m.step(&x.get(0).get(t), None, t, &mut caches);
        let l = m.logits(&(wx + av.get(t + 1)));
        let d = (l - logits.get(0).get(t)).abs().max().double_value(&[]);
        assert!(d < 1e-4, "step {t} differs by {d}");
    }
}

#[test]
fn same_seed_same_dance_other_seed_other_dance() {
    let (_vs, m) = model(3);
    let music = Tensor::randn([1, 40, 3], (Kind::Float, Device::Cpu));
    let av = m.audio_logit_vectors(&music, None, |_| true).unwrap();
    let prefix = Array2::from_shape_fn((20, 5), |(t, c)| ((t + c) % 12) as i64);
    let s = Sampling::default();
    let a = m.sample(&prefix, &av, None, s, 7, |_| true).unwrap();
    let b = m.sample(&prefix, &av, None, s, 7, |_| true).unwrap();
    let c = m.sample(&prefix, &av, None, s, 8, |_| true).unwrap();
    assert_eq!(a.dim(), (40, 5));
    assert_eq!(a, b);
    assert_ne!(a, c);
    // top_k = 1 is greedy: the same whatever the seed.
    let g = Sampling {
        temperature: 1.0,
        top_k: 1,
    };
    assert_eq!(
        m.sample(&prefix, &av, None, g, 1, |_| true).unwrap(),
        m.sample(&prefix, &av, None, g, 2, |_| true).unwrap()
    );
}

/// The opening check stops a draw at a hold and the kept one goes on later: stopped anywhere and
/// gone on with, with a guard that acts, a draw is the one run's, frame for frame.
#[test]
fn a_draw_stopped_and_gone_on_with_is_the_one_runs() {
    let (_vs, m) = model(3);
    let music = Tensor::randn([1, 60, 3], (Kind::Float, Device::Cpu));
    let av = m.audio_logit_vectors(&music, None, |_| true).unwrap();
    let prefix = Array2::from_shape_fn((20, 5), |(t, c)| ((t + c) % 12) as i64);
    let s = Sampling::default();
    // A reach every draw stays under: the guard boosts each frame once it has seen its window
    // (from the fifth on), so what it remembers must carry over the stops.
    let guard = StallGuard {
        min_reach_m: 10.0,
        window_frames: 4,
        boost: 3.0,
        reopen_reach_m: 0.0,
    };
    let widths = vec![0.05f32; 5];
    let guard = Some((&guard, widths.as_slice()));
    let one = m
        .sample_guarded(&prefix, &av, None, s, guard, 7, |_| true)
        .unwrap();
    let unguarded = m.sample(&prefix, &av, None, s, 7, |_| true).unwrap();
    assert_ne!(one, unguarded, "the guard acts");
    let mut calls = Vec::new();
    let mut d = Draw::new(&m, &prefix, av.shallow_clone(), None, s, guard, 7);
    for end in [1, 13, 13, 40, 60] {
        d.run_to(end, |done| {
            calls.push(done);
            true
        })
        .unwrap();
        assert_eq!(d.done(), end);
        assert_eq!(d.tokens(), one.slice(ndarray::s![..end, ..]));
    }
    assert_eq!(d.into_tokens(), one);
    // Told at the start of each stretch where it begins.
    assert_eq!(calls, vec![0, 1, 13, 13, 40]);
}

#[test]
fn reach_measures_how_far_the_pose_came_and_the_guard_only_acts_on_a_stall() {
    // Two joints, 1 cm per bin: a held pose reaches 0; a joint 30 bins away 0.15 m on the mean.
    let widths = vec![0.01f32; 6];
    let held: std::collections::VecDeque<Vec<i64>> = (0..10).map(|_| vec![5i64; 6]).collect();
    assert_eq!(reach_m(&held, &widths), 0.0);
    let mut moved = held.clone();
    moved.push_front(vec![35, 5, 5, 5, 5, 5]);
    assert!((reach_m(&moved, &widths) - 0.15).abs() < 1e-6);
    // A guard that never fires leaves the draws as they were; one that always fires changes them.
    let (_vs, m) = model(6);
    let music = Tensor::randn([1, 30, 3], (Kind::Float, Device::Cpu));
    let av = m.audio_logit_vectors(&music, None, |_| true).unwrap();
    let prefix = Array2::from_shape_fn((10, 5), |(t, c)| ((t + c) % 12) as i64);
    let s = Sampling {
        temperature: 0.3,
        top_k: 3,
    };
    let w = vec![0.01f32; 3];
    let never = StallGuard {
        min_reach_m: 0.0,
        window_frames: 5,
        boost: 10.0,
        reopen_reach_m: 0.0,
    };
    let always = StallGuard {
        min_reach_m: 1e9,
        window_frames: 5,
        boost: 10.0,
        reopen_reach_m: 0.0,
    };
    let plain = m.sample(&prefix, &av, None, s, 3, |_| true).unwrap();
    assert_eq!(
        m.sample_guarded(&prefix, &av, None, s, Some((&never, &w)), 3, |_| true)
            .unwrap(),
        plain
    );
    assert_ne!(
        m.sample_guarded(&prefix, &av, None, s, Some((&always, &w)), 3, |_| true)
            .unwrap(),
        plain
    );
}

#[test]
fn top_k_and_temperature_shape_the_draws() {
    let logits = [0.0f32, 1.0, 2.0, 3.0];
    let mut probs = [0f32; 4];
    let mut rng = StdRng::seed_from_u64(0);
    let k2 = Sampling {
        temperature: 1.0,
        top_k: 2,
    };
    assert!((0..200).all(|_| k2.draw(&logits, &mut probs, &mut rng) >= 2));
    let cold = Sampling {
        temperature: 0.05,
        top_k: 0,
    };
    assert!((0..200).all(|_| cold.draw(&logits, &mut probs, &mut rng) == 3));
    let hot = Sampling {
        temperature: 5.0,
        top_k: 0,
    };
    let zeros = (0..400)
        .filter(|_| hot.draw(&logits, &mut probs, &mut rng) == 0)
        .count();
    assert!(
        zeros > 40,
        "a hot draw picked bin 0 only {zeros} of 400 times"
    );
}

#[test]
fn loss_on_every_frame_equals_the_full_loss() {
    let (_vs, m) = model(5);
    let x = tokens(2, 9);
    let music = Tensor::randn([2, 9, 3], (Kind::Float, Device::Cpu));
    let all = Tensor::arange(8, (Kind::Int64, Device::Cpu));
    let full = m.loss(&x, &music, None, 3, false).double_value(&[]);
    let picked = m
        .loss_on_frames(&m.fused(&x, &music, None, 3, false), &x, &all)
        .double_value(&[]);
    assert!((full - picked).abs() < 1e-5, "{full} vs {picked}");
}

#[test]
fn loss_falls_on_a_few_batches() {
    let (vs, m) = model(4);
    let mut opt = nn::Adam::default().build(&vs, 3e-3).unwrap();
    let x = tokens(4, 13);
    let music = Tensor::randn([4, 13, 3], (Kind::Float, Device::Cpu));
    let first = m.loss(&x, &music, None, 0, true).double_value(&[]);
    for _ in 0..40 {
        opt.backward_step(&m.loss(&x, &music, None, 0, true));
    }
    let last = m.loss(&x, &music, None, 0, true).double_value(&[]);
    assert!(last < 0.8 * first, "loss {first} -> {last}");
}

/// The step clock starts at zero (a network given it draws what it drew without it), and once
/// its weights move, the cached steps that sampling takes still compute the training pass, the
/// clock included, and the clock changes the logits.
#[test]
fn the_step_clock_starts_silent_and_the_cached_steps_hear_it() {
    let (vs, m) = model_with(7, true);
    let (_plain_vs, plain) = model(7);
    let x = tokens(1, 9);
    let music = Tensor::randn([1, 9, 3], (Kind::Float, Device::Cpu));
    let phase: Vec<f64> = (0..9).map(|t| 0.4 * t as f64).collect();
    let clock = crate::models::to_tensor(&crate::models::step_clock::columns(&phase));
    let with = m.forward(&x, &music, Some(&clock.unsqueeze(0)), 0, false);
    let without = plain.forward(&x, &music, None, 0, false);
    let d = (&with - &without).abs().max().double_value(&[]);
    assert!(d < 1e-6, "a zero clock moved the logits by {d}");
    // Weights moved: the clock is heard, by the training pass and by the cached steps alike.
    tch::no_grad(|| {
        for (name, mut v) in vs.variables() {
            if name.starts_with("step_clock.") {
                v.copy_(&Tensor::randn(v.size(), (Kind::Float, Device::Cpu)));
            }
        }
    });
    let logits = m.forward(&x, &music, Some(&clock.unsqueeze(0)), 0, false);
    let moved = (&logits - &without).abs().max().double_value(&[]);
    assert!(moved > 1e-3, "the clock changed nothing ({moved})");
    let av = m
        .audio_logit_vectors(&music, Some(&clock), |_| true)
        .unwrap();
    let mut caches = m.pose.stack.new_caches();
    for t in 0..8 {
        let wx = m.step(&x.get(0).get(t), Some(&clock.get(t)), t, &mut caches);
        let l = m.logits(&(wx + av.get(t + 1)));
        let d = (l - logits.get(0).get(t)).abs().max().double_value(&[]);
        assert!(d < 1e-4, "step {t} differs by {d}");
    }
}

/// A hold is drawn again from a second before it (not before `after`) to two seconds after it
/// (not past the song), a freeze to the end; whichever starts first, the freeze on a tie.
#[test]
fn a_hold_is_drawn_again_around_it_and_a_freeze_to_the_end() {
    use super::served::redrawn_span;
    assert_eq!(redrawn_span(None, None, 500, 2000), None);
    assert_eq!(redrawn_span(Some(900), None, 500, 2000), Some(900..2000));
    assert_eq!(
        redrawn_span(None, Some(700..900), 500, 2000),
        Some(675..950)
    );
    assert_eq!(
        redrawn_span(None, Some(510..900), 500, 2000),
        Some(500..950)
    );
    assert_eq!(
        redrawn_span(None, Some(700..1990), 500, 2000),
        Some(675..2000)
    );
    assert_eq!(
        redrawn_span(Some(800), Some(700..900), 500, 2000),
        Some(675..950)
    );
    assert_eq!(
        redrawn_span(Some(600), Some(700..900), 500, 2000),
        Some(600..2000)
    );
    assert_eq!(
        redrawn_span(Some(675), Some(700..900), 500, 2000),
        Some(675..2000)
    );
}

/// The new frames fade in over a second and back out over the last where the old dance goes
/// on, each fade smooth and one-way; where the span reaches the end they stay.
#[test]
fn a_redrawn_span_fades_in_and_back_out() {
    use super::served::join;
    let mut values = Array2::<f32>::zeros((300, 2));
    join(&mut values, 50..150, Array2::ones((100, 2)));
    let w: Vec<f32> = values.column(0).to_vec();
    assert!(w[..50].iter().all(|&v| v == 0.0) && w[150..].iter().all(|&v| v == 0.0));
    assert!(w[75..125].iter().all(|&v| v == 1.0));
    assert!(w[50] > 0.0 && w[50] < 0.01 && w[149] > 0.0 && w[149] < 0.01);
    assert!(w[50..75].windows(2).all(|p| p[0] < p[1]));
    assert!(w[125..150].windows(2).all(|p| p[0] > p[1]));
    assert_eq!(values.column(1), values.column(0));
    join(&mut values, 250..300, Array2::from_elem((50, 2), 2.0));
    assert!(values[[274, 0]] > 1.9 && values[[299, 0]] == 2.0);
}
