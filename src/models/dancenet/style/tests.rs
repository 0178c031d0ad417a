use super::*;
use tch::nn::OptimizerConfig;
use tch::Device;

fn model(seed: i64) -> (nn::VarStore, StyleClassifier) {
    tch::manual_seed(seed);
    let vs = nn::VarStore::new(Device::Cpu);
    let m = StyleClassifier::new(&vs.root(), &StyleConfig::tiny());
    (vs, m)
}

fn x(b: i64, t: i64) -> Tensor {
    Tensor::randn([b, t, 15], (Kind::Float, Device::Cpu))
}

#[test]
fn shapes_and_the_shortest_input() {
    let (_vs, m) = model(0);
    assert_eq!(m.forward(&x(3, 50), false).size(), vec![3, 4]);
    let c = StyleConfig::tiny();
    // kernel 2, pool 2, three layers: 8 → 7 → 4 → 3 → 2 → 1 → 1.
    assert_eq!(c.min_frames(), 8);
    assert_eq!(c.steps(750), Some(93));
    assert_eq!(m.forward(&x(1, 8), false).size(), vec![1, 4]);
    assert_eq!(
        StyleConfig {
            pool: 1,
            ..c.clone()
        }
        .min_frames(),
        4
    );
    let vs = nn::VarStore::new(Device::Cpu);
    let last = StyleClassifier::new(
        &vs.root(),
        &StyleConfig {
            readout: Readout::Last,
            ..c
        },
    );
    assert_eq!(last.forward(&x(2, 20), false).size(), vec![2, 4]);
}

#[test]
fn windows_cover_the_sequence_to_its_end() {
    assert_eq!(windows(100, 40, 20), vec![0..40, 20..60, 40..80, 60..100]);
    assert_eq!(
        windows(105, 40, 20),
        vec![0..40, 20..60, 40..80, 60..100, 65..105]
    );
    assert_eq!(windows(30, 40, 20), vec![0..30]);
    assert!(windows(0, 40, 20).is_empty());
}

#[test]
fn same_seed_same_network_other_seed_other_network() {
    let input = x(2, 30);
    let (_a, a) = model(7);
    let (_b, b) = model(7);
    let (_c, c) = model(8);
    let (ya, yb, yc) = (
        a.forward(&input, false),
        b.forward(&input, false),
        c.forward(&input, false),
    );
    assert_eq!((&ya - &yb).abs().max().double_value(&[]), 0.0);
    assert!((&ya - &yc).abs().max().double_value(&[]) > 1e-4);
}

#[test]
fn loss_falls_on_a_few_batches() {
    let (vs, m) = model(4);
    let mut opt = nn::Adam::default().build(&vs, 1e-2).unwrap();
    // Four styles told apart by a per-class offset of the first feature.
    let y = Tensor::from_slice(&[0i64, 1, 2, 3, 0, 1, 2, 3]);
    let shift: Vec<f32> = (0..8)
        .flat_map(|i| (0..40 * 15).map(move |k| if k % 15 == 0 { (i % 4) as f32 } else { 0.0 }))
        .collect();
    let input = x(8, 40) * 0.5 + Tensor::from_slice(&shift).view([8, 40, 15]);
    let first = m.loss(&input, &y, true).double_value(&[]);
    for _ in 0..60 {
        opt.backward_step(&m.loss(&input, &y, true));
    }
    let last = m.loss(&input, &y, true).double_value(&[]);
    assert!(last < 0.5 * first, "loss {first} -> {last}");
}

#[test]
fn evaluation_tallies_windows_and_dances() {
    let (_vs, m) = model(1);
    let d = |id: &str, style, t| Labelled {
        id: id.into(),
        style,
        features: Array2::from_shape_fn((t, 15), |(i, j)| ((i * 7 + j) % 5) as f32 - 2.0),
    };
    let e = evaluate(
        &m,
        &[
            d("DANCE_W_1", DanceStyle::Waltz, 100),
            d("DANCE_C_1", DanceStyle::ChaCha, 30),
        ],
        40,
        20,
    )
    .unwrap();
    assert_eq!((e.windows, e.dances), (5, 2));
    assert_eq!(e.window_confusion.iter().flatten().sum::<usize>(), 5);
    assert_eq!(e.window_confusion[3].iter().sum::<usize>(), 4);
    assert_eq!(e.dance_confusion.iter().flatten().sum::<usize>(), 2);
    for r in &e.per_dance {
        assert!((r.probabilities.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }
    assert!(e.window_loss > 0.0);
}

fn served(dir: &Path, window: usize, hop: usize) -> ServedStyle {
    let (vs, _m) = model(3);
    vs.save(dir.join(STYLE_WEIGHTS_FILE)).unwrap();
    let norm = NormStats {
        mean: vec![0.5; 15],
        std: vec![2.0; 15],
    };
    let training = TrainingRecord {
        epochs: 0,
        lr: 0.0,
        batch: 0,
        seed: 0,
        final_train_loss: 0.0,
        minutes: 0.0,
        extra: Schedule {
            windows_per_epoch: 0,
            sampling: String::new(),
            augmentation: String::new(),
            no_style: String::new(),
            no_style_per_batch: 0,
            steps: 0,
        },
    };
    let file = StyleFile {
        config: StyleConfig::tiny(),
        music_norm: norm,
        fps: FPS,
        window,
        hop,
        training,
        test: Evaluation::default(),
        held_out: None,
    };
    std::fs::write(dir.join(STYLE_FILE), serde_json::to_string(&file).unwrap()).unwrap();
    ServedStyle::load(dir).unwrap()
}

#[test]
fn served_probabilities_are_the_mean_over_windows() {
    let dir = tempfile::tempdir().unwrap();
    let s = served(dir.path(), 40, 20);
    let raw = Array2::from_shape_fn((100, 15), |(t, c)| ((t * 3 + c * 5) % 11) as f32 * 0.3);
    let p = s.predict(&raw).unwrap();
    assert!((p.iter().sum::<f32>() - 1.0).abs() < 1e-5, "{p:?}");
    // By hand: normalise, the four windows, their softmax averaged.
    let (mut vs, m) = model(0);
    vs.load(dir.path().join(STYLE_WEIGHTS_FILE)).unwrap();
    let norm = s.file().music_norm.normalize(&raw).unwrap();
    let by_hand = Vec::<f32>::try_from(window_probabilities(&m, &norm, 40, 20).unwrap().mean_dim(
        0,
        false,
        Kind::Float,
    ))
    .unwrap();
    for (a, b) in p.iter().zip(&by_hand) {
        assert!((a - b).abs() < 1e-6, "{p:?} vs {by_hand:?}");
    }
    // A song shorter than the window is one window; one shorter than the network's reach,
    // the wrong width, or NaN, an error.
    assert!(s.predict(&raw.slice(s![..30, ..]).to_owned()).is_ok());
    assert!(matches!(
        s.predict(&raw.slice(s![..5, ..]).to_owned()),
        Err(ModelError::Input(_))
    ));
    assert!(matches!(
        s.predict(&raw.slice(s![.., ..14]).to_owned()),
        Err(ModelError::Shape(_))
    ));
    let mut bad = raw.clone();
    bad[[3, 3]] = f32::NAN;
    assert!(matches!(s.predict(&bad), Err(ModelError::Input(_))));
}

#[test]
fn served_classifier_is_shared_across_threads() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<ServedStyle>();
    let dir = tempfile::tempdir().unwrap();
    let s = served(dir.path(), 40, 20);
    let raw = Array2::from_shape_fn((90, 15), |(t, c)| ((t + c) % 7) as f32);
    let want = s.predict(&raw).unwrap();
    std::thread::scope(|sc| {
        let handles: Vec<_> = (0..3)
            .map(|_| sc.spawn(|| s.predict(&raw).unwrap()))
            .collect();
        for h in handles {
            assert_eq!(h.join().unwrap(), want);
        }
    });
}

#[test]
fn missing_files_say_so() {
    let dir = tempfile::tempdir().unwrap();
    assert!(matches!(
        ServedStyle::load(dir.path()),
        Err(ModelError::MissingWeights(..))
    ));
}
