use super::*;
use ndarray::Array2;
use rand::rngs::StdRng;
use rand::SeedableRng;
use tch::nn::OptimizerConfig;

const D: i64 = 6;

fn model(seed: i64) -> (nn::VarStore, DanceNet) {
    model_with(seed, Config::tiny(D))
}

/// A model of `config` with 3 music columns, its weights drawn from `seed`.
fn model_with(seed: i64, config: Config) -> (nn::VarStore, DanceNet) {
    tch::manual_seed(seed);
    let vs = nn::VarStore::new(Device::Cpu);
    let m = DanceNet::new(
        &vs.root(),
        Config {
            music_dim: 3,
            ..config
        },
    );
    (vs, m)
}

fn frames(b: i64, n: i64) -> Tensor {
    Tensor::randn([b, n, D + 4], (Kind::Float, Device::Cpu))
}

#[test]
fn the_decoder_does_not_see_the_future() {
    let (_vs, m) = model(0);
    let x = frames(1, 20);
    let code = Tensor::randn([1, 20, 4], (Kind::Float, Device::Cpu));
    let s = m.style_one_hot(&[2], Device::Cpu);
    let a = m.forward(&x, &code, &s);
    assert_eq!(a.mean.size(), vec![1, 19, 2, D]);
    // Changing frame 8 may change predictions from position 8 on, never before.
    let x2 = x.copy();
    let _ = x2.narrow(1, 8, 1).fill_(3.0);
    let b = m.forward(&x2, &code, &s);
    let early = (a.mean.narrow(1, 0, 8) - b.mean.narrow(1, 0, 8))
        .abs()
        .max()
        .double_value(&[]);
    assert!(early < 1e-6, "positions < 8 moved by {early}");
    let late = (a.mean.narrow(1, 8, 1) - b.mean.narrow(1, 8, 1))
        .abs()
        .max()
        .double_value(&[]);
    assert!(late > 1e-6, "position 8 did not see frame 8");
}

#[test]
fn the_receptive_field_is_one_plus_the_dilations() {
    let (_vs, m) = model(1);
    let rf = m.config.receptive_field();
    assert_eq!(rf, 8);
    let x = frames(1, 30);
    let code = Tensor::randn([1, 30, 4], (Kind::Float, Device::Cpu));
    let s = m.style_one_hot(&[0], Device::Cpu);
    let a = m.forward(&x, &code, &s);
    // Position 20 sees frames 13..=20 and not 12.
    for (f, seen) in [(12, false), (13, true)] {
        let x2 = x.copy();
        let _ = x2.narrow(1, f, 1).fill_(5.0);
        let b = m.forward(&x2, &code, &s);
        let d = (a.mean.narrow(1, 20, 1) - b.mean.narrow(1, 20, 1))
            .abs()
            .max()
            .double_value(&[]);
        assert_eq!(d > 1e-6, seen, "frame {f}: change {d}");
    }
}

#[test]
fn stepwise_sampling_follows_the_parallel_pass() {
    // With temperature 0 and one component the sample is the mean: feeding it back through the
    // teacher-forced pass must reproduce every step.
    let (_vs, m) = model_with(
        2,
        Config {
            mixtures: 1,
            ..Config::tiny(D)
        },
    );
    let prefix = Array2::from_shape_fn((10, (D + 4) as usize), |(t, c)| {
        ((t * 7 + c * 3) % 5) as f32 * 0.3 - 0.6
    });
    let n = 12;
    let code = Tensor::randn([10 + n, 4], (Kind::Float, Device::Cpu));
    let mut rng = StdRng::seed_from_u64(0);
    let out = m
        .sample(
            &prefix,
            &code.narrow(0, 1, 9 + n),
            None,
            1,
            Sampling {
                temperature: 0.0,
                coherence: 0.0,
                music_guidance: 1.0,
            },
            &mut rng,
            |_| true,
        )
        .expect("sampled");
    assert_eq!(out.nrows(), n as usize);
    let all = ndarray::concatenate(ndarray::Axis(0), &[prefix.view(), out.view()]).unwrap();
    let x = crate::models::to_tensor(&all).unsqueeze(0);
    let pass = m.forward(&x, &code.unsqueeze(0), &m.style_one_hot(&[1], Device::Cpu));
    for t in 0..n {
        let want = pass.mean.get(0).get(9 + t).get(0);
        let got = Tensor::from_slice(&out.row(t as usize).to_vec()[..D as usize]);
        let d = (want - got).abs().max().double_value(&[]);
        assert!(d < 1e-4, "step {t} differs by {d}");
    }
}

/// Music guidance: a frame's mean is the song's average music's plus g times what this frame's
/// music changes in it, on the first frame exactly; and a song whose code never changes is
/// danced as without guidance.
#[test]
fn music_guidance_amplifies_what_each_frames_music_changes() {
    let (_vs, m) = model_with(
        4,
        Config {
            mixtures: 1,
            ..Config::tiny(D)
        },
    );
    let prefix = Array2::from_shape_fn((10, (D + 4) as usize), |(t, c)| {
        ((t * 5 + c * 2) % 7) as f32 * 0.2 - 0.6
    });
    let n = 8;
    let plain = Sampling {
        temperature: 0.0,
        coherence: 0.0,
        music_guidance: 1.0,
    };
    let guided = Sampling {
        music_guidance: 3.0,
        ..plain
    };
    let sample = |code: &Tensor, average: Option<&Tensor>, s: Sampling| {
        let mut rng = StdRng::seed_from_u64(0);
        m.sample(
            &prefix,
            &code.narrow(0, 1, 9 + n),
            average,
            1,
            s,
            &mut rng,
            |_| true,
        )
        .expect("sampled")
    };
    // A song that never changes: the average is every frame's code.
    let still = Tensor::randn([1, 4], (Kind::Float, Device::Cpu)).repeat([10 + n, 1]);
    let (a, b) = (sample(&still, None, plain), sample(&still, None, guided));
    let d = (&a - &b).mapv(f32::abs).fold(0.0f32, |x, &y| x.max(y));
    assert!(d < 1e-5, "an unchanging song moved by {d}");
    // A changing song, guided against an average handed in (the whole song's, as served, where
    // the sampled span is only part of it): the first made frame's mean, from the two
    // teacher-forced passes (the tiny configuration's means are absolute, and position 9 sees
    // the prefix only).
    let code = Tensor::randn([10 + n, 4], (Kind::Float, Device::Cpu));
    let song = Tensor::randn([60, 4], (Kind::Float, Device::Cpu));
    let song_average = song.mean_dim(0, true, Kind::Float).repeat([9 + n, 1]);
    let out = sample(&code, Some(&song_average), guided);
    let all = ndarray::concatenate(ndarray::Axis(0), &[prefix.view(), out.view()]).unwrap();
    let x = crate::models::to_tensor(&all).unsqueeze(0);
    let style = m.style_one_hot(&[1], Device::Cpu);
    let average = song.mean_dim(0, true, Kind::Float).repeat([10 + n, 1]);
    let mean = |c: &Tensor| {
        m.forward(&x, &c.unsqueeze(0), &style)
            .mean
            .get(0)
            .get(9)
            .get(0)
    };
    let (with, without) = (mean(&code), mean(&average));
    let want = &without + (&with - &without) * 3.0;
    let got = Tensor::from_slice(&out.row(0).to_vec()[..D as usize]);
    let d = (want - got).abs().max().double_value(&[]);
    assert!(d < 1e-4, "the first guided frame differs by {d}");
}

#[test]
fn same_seed_same_dance_other_seed_other_dance() {
    let (_vs, m) = model(3);
    let prefix = Array2::from_shape_fn((10, (D + 4) as usize), |(t, c)| ((t + c) % 4) as f32 * 0.2);
    let code = Tensor::randn([39, 4], (Kind::Float, Device::Cpu));
    let s = Sampling::default();
    let run = |seed: u64| {
        m.sample(
            &prefix,
            &code,
            None,
            3,
            s,
            &mut StdRng::seed_from_u64(seed),
            |_| true,
        )
        .expect("sampled")
    };
    assert_eq!(run(7), run(7));
    assert_ne!(run(7), run(8));
}

#[test]
fn a_whole_song_is_encoded_in_cross_faded_windows() {
    let (_vs, m) = model(4);
    let music = Tensor::randn([1, 50, 3], (Kind::Float, Device::Cpu));
    let code = m.encoder.encode_song(&music, |_| true).expect("encoded");
    assert_eq!(code.size(), vec![50, 4]);
    // A song no longer than one window is one pass.
    let short = music.narrow(1, 0, 16);
    let one = m.encoder.forward(&short).squeeze_dim(0);
    let d = (m.encoder.encode_song(&short, |_| true).expect("encoded") - one)
        .abs()
        .max()
        .double_value(&[]);
    assert!(d < 1e-5, "{d}");
}

#[test]
fn loss_falls_on_a_few_batches() {
    let (vs, m) = model(5);
    let mut opt = nn::Adam::default().build(&vs, 3e-3).unwrap();
    let x = frames(4, 24);
    let music = Tensor::randn([4, 24, 3], (Kind::Float, Device::Cpu));
    let s = m.style_one_hot(&[0, 1, 2, 3], Device::Cpu);
    let loss = |m: &DanceNet| {
        let l = m.losses(&x, &x, &music, None, &s, 4);
        l.gmm + l.foot
    };
    let first = loss(&m).double_value(&[]);
    for _ in 0..60 {
        opt.backward_step(&loss(&m));
    }
    let last = loss(&m).double_value(&[]);
    assert!(last < first - 0.3, "loss {first} -> {last}");
}

#[test]
fn coherent_draws_keep_each_frames_spread_and_move_together() {
    // One component, one dimension, mean 0, σ 1 (log σ 0), no contacts.
    let raw = [0.0f32, 0.0, 0.0];
    let stats = |rho: f64| {
        let s = Sampling {
            temperature: 2.0,
            coherence: rho,
            music_guidance: 1.0,
        };
        let mut rng = StdRng::seed_from_u64(1);
        let mut draws = Draws::new(1, &mut rng);
        let x: Vec<f32> = (0..20_000)
            .map(|_| s.draw(&raw, &[0.0], 1, 1, 0, &mut [0.0], &mut draws, &mut rng)[0])
            .collect();
        let var = x.iter().map(|v| v * v).sum::<f32>() / x.len() as f32;
        let lag1 = x.windows(2).map(|w| w[0] * w[1]).sum::<f32>() / (x.len() - 1) as f32 / var;
        (var, lag1)
    };
    let (var0, lag0) = stats(0.0);
    let (var9, lag9) = stats(0.9);
    // σ × temperature = 2 either way; only independent draws are uncorrelated.
    assert!(
        (var0 - 4.0).abs() < 0.3 && (var9 - 4.0).abs() < 0.6,
        "variances {var0} {var9}"
    );
    assert!(
        lag0.abs() < 0.05 && (lag9 - 0.9).abs() < 0.05,
        "lag-1 correlations {lag0} {lag9}"
    );
}

#[test]
fn with_music_direct_a_beat_reaches_the_decoder_on_its_own_frame() {
    let (_vs, m) = model_with(
        6,
        Config {
            music_direct: true,
            ..Config::tiny(D)
        },
    );
    assert_eq!(m.config.code_width(), 4 + 3);
    let music = Tensor::zeros([1, 40, 3], (Kind::Float, Device::Cpu));
    let code = m.encoder.forward(&music);
    assert_eq!(code.size(), vec![1, 40, 7]);
    // The signals ride along unchanged after the code, in the song encoding too.
    let song = m.encoder.encode_song(&music, |_| true).expect("encoded");
    assert_eq!(song.size(), vec![40, 7]);
    // A beat at frame 20 alone, its code held fixed: the prediction of frame 20 (position 19)
    // changes, through the signal's own columns; the ones before it do not.
    let beat = code.copy();
    let _ = beat.narrow(1, 20, 1).narrow(2, 4, 1).fill_(1.0);
    let x = frames(1, 40);
    let s = m.style_one_hot(&[0], Device::Cpu);
    let (a, b) = (m.forward(&x, &code, &s), m.forward(&x, &beat, &s));
    let moved = |t: i64| {
        (a.mean.narrow(1, t, 1) - b.mean.narrow(1, t, 1))
            .abs()
            .max()
            .double_value(&[])
    };
    assert!(
        moved(19) > 1e-6,
        "frame 20's beat did not reach its prediction"
    );
    assert!(moved(18) < 1e-9);
}

/// The step clock rides after the code in every gated layer's conditioning: a window's clock
/// turned by half a step moves the decoder's predictions, frame by frame, and a model without
/// it reads the same code as before.
#[test]
fn with_the_step_clock_the_phase_reaches_every_frame() {
    let (_vs, m) = model_with(
        6,
        Config {
            step_clock: true,
            ..Config::tiny(D)
        },
    );
    assert_eq!(m.config.code_width(), 4 + super::step_clock::WIDTH);
    let n = 40;
    let music = Tensor::zeros([1, n, 3], (Kind::Float, Device::Cpu));
    let phase: Vec<f64> = (0..n).map(|t| t as f64 * 0.3).collect();
    let half: Vec<f64> = phase.iter().map(|p| p + std::f64::consts::PI).collect();
    let clock = |p: &[f64]| crate::models::to_tensor(&super::step_clock::columns(p)).unsqueeze(0);
    let (a, b) = (
        m.code(&music, Some(&clock(&phase))),
        m.code(&music, Some(&clock(&half))),
    );
    assert_eq!(a.size(), vec![1, n, 4 + 4]);
    // Before training the clock's weights are random (from `--init` they start at zero).
    let x = frames(1, n);
    let s = m.style_one_hot(&[0], Device::Cpu);
    let (pa, pb) = (m.forward(&x, &a, &s), m.forward(&x, &b, &s));
    let moved = (pa.mean - pb.mean).abs().amax([-1, -2], false); // [1, n − 1]
    let moved: Vec<f32> = Vec::try_from(moved.view([-1])).unwrap();
    assert!(moved.iter().all(|&v| v > 1e-6), "{moved:?}");
    // No clock given: zeros after the code.
    let none = m.code(&music, None);
    assert_eq!(
        none.narrow(2, 4, 4)
            .abs()
            .sum(Kind::Float)
            .double_value(&[]),
        0.0
    );
    let (_vs, plain) = model_with(6, Config::tiny(D));
    assert_eq!(plain.code(&music, None).size(), vec![1, n, 4]);
}
