//! `choreo train keypose-transformer`: the key-pose weighted reconstruction loss (ω(t), §3.4),
//! key poses sampled from the ground truth at random counts and frames, the seed motion taken as
//! each window's first `T′` frames, Adam, on the train split of dance-with-melody. After training
//! it measures the key-pose consistency error on the test split (whole dances, overlapping
//! windows, the served code path) and writes it to `eval.json` for the model card.
use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::{s, Array2};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use tch::nn::{self, OptimizerConfig};
use tch::{Device, Kind, Tensor};

use super::{append_log, batch_tensor, fit_normalizers, load_sequences, window_starts, write_atomic, EpochLog, Sequence, TrainError};
use crate::models::keypose_transformer::scaffold::{PoseBank, POSE_BANK_FILE};
use crate::models::keypose_transformer::served::RootHeight;
use crate::models::to_tensor;
use crate::models::keypose_transformer::{
    generate_features, local_position_embedding, loss_weights, to_local, Config, KeyposeTransformer, LocalKey, ModelFile, TrainingRecord,
    WindowInput, MODEL_FILE, WEIGHTS_FILE,
};
use crate::motion::dataset::Dataset;
use crate::motion::repr::{self, POSE_DIM};
use crate::motion::{KeyPose, NUM_JOINTS};

/// Options of one training run; the model card gives the runs (and flags) behind the committed weights.
#[derive(Clone, Debug, clap::Args)]
pub struct Options {
    /// The dance-with-melody folder.
    #[arg(long, default_value = "../shared/data/dance-with-melody")]
    pub data: PathBuf,
    /// Where model.json, weights.safetensors, train_log.jsonl and eval.json go.
    #[arg(long, default_value = "models/keypose-transformer")]
    pub out: PathBuf,
    #[arg(long, default_value_t = 200)]
    pub epochs: usize,
    #[arg(long, default_value_t = 32)]
    pub batch: usize,
    /// Stride between training window starts, in frames.
    #[arg(long, default_value_t = 10)]
    pub stride: usize,
    #[arg(long, default_value_t = 5e-4)]
    pub lr: f64,
    /// `λ`: weight of the key-pose terms in ω(t).
    #[arg(long, default_value_t = 3.0)]
    pub lambda: f64,
    /// `σ`: width of each key-pose term in ω(t), frames.
    #[arg(long, default_value_t = 3.0)]
    pub sigma: f64,
    /// Weight of the L1 on frame differences (velocities) beside the pose term: the pose term alone
    /// lets a regression average fast motion away.
    #[arg(long, default_value_t = 5.0)]
    pub velocity_weight: f64,
    /// Frames between the scaffold poses the served model draws (0: none); see the scaffold module.
    #[arg(long, default_value_t = 25)]
    pub scaffold_spacing: usize,
    /// Clips of the served pose bank, and their length in frames.
    #[arg(long, default_value_t = 32)]
    pub bank_clips: usize,
    #[arg(long, default_value_t = 200)]
    pub bank_frames: usize,
    /// Key poses per training window are drawn uniformly from 0..=max_keys.
    #[arg(long, default_value_t = 6)]
    pub max_keys: usize,
    /// Key poses per test dance in the consistency evaluation.
    #[arg(long, default_value_t = 4)]
    pub eval_keys: usize,
    #[arg(long, default_value_t = 2023)]
    pub seed: u64,
    /// libtorch intra-op threads.
    #[arg(long, default_value_t = 1)]
    pub threads: i32,
    /// Stop after this many minutes even if epochs remain (the weights are saved either way).
    #[arg(long)]
    pub max_minutes: Option<f64>,
    /// Start from these weights (same configuration) instead of a random initialisation.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Use the tiny test configuration (for smoke runs, never for committed weights).
    #[arg(long)]
    pub tiny: bool,
    /// Do not train: re-run the test-split evaluation of the model already in `--out` and rewrite
    /// its `eval.json`.
    #[arg(long)]
    pub eval_only: bool,
}

/// Key-pose consistency on the test split, written to `eval.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct KeyPoseEval {
    pub dances: usize,
    pub keys_per_dance: usize,
    /// Mean per-joint error at key frames of the network alone (before the exact pass), cm.
    pub network_error_cm: f64,
    /// The same after the served pass-through blend, measured on the exported world motion, cm.
    pub served_error_cm: f64,
    /// Mean per-joint error of the whole generated dance against the real one (root-relative), cm.
    pub dance_error_cm: f64,
    /// Mean per-joint error with no key poses (seed only), for comparison, cm.
    pub dance_error_no_keys_cm: f64,
    /// Smoothness `S_cv` of the whole dances (lower is smoother): the real test dances, the network's
    /// output alone, and the served output (after the exact key-pose pass).
    #[serde(default)]
    pub scv_real: f64,
    #[serde(default)]
    pub scv_network: f64,
    #[serde(default)]
    pub scv_served: f64,
    /// Mean `S_cv` of the served output on 1-s segments centred on the frames where one window's
    /// output takes over from the previous one's, and on 1-s segments midway between joins.
    #[serde(default)]
    pub scv_at_joins: f64,
    #[serde(default)]
    pub scv_within_windows: f64,
    /// The same two segment sets measured on the real dances (which have no joins), for scale.
    #[serde(default)]
    pub scv_real_at_joins: f64,
    #[serde(default)]
    pub scv_real_within_windows: f64,
}

/// Half the length of the segments `S_cv` is compared on at and between window joins (0.5 s).
const SEGMENT_HALF: usize = 12;

/// Segments of `2·half` frames centred on `centres`, those that fit in `n` frames.
fn segments(centres: &[usize], half: usize, n: usize) -> Vec<std::ops::Range<usize>> {
    centres.iter().filter(|&&c| c >= half && c + half <= n).map(|&c| c - half..c + half).collect()
}

/// The centres midway between consecutive joins (and between the seed's end and the first join,
/// and the last join and the end).
fn mid_window_centres(joins: &[usize], first: usize, n: usize) -> Vec<usize> {
    let mut bounds = vec![first];
    bounds.extend_from_slice(joins);
    bounds.push(n);
    bounds.windows(2).filter(|p| p[1] > p[0] + 2 * SEGMENT_HALF).map(|p| (p[0] + p[1]) / 2).collect()
}

/// Sums of `S_cv` over the segments of a motion, and their count.
fn segment_scv(positions: ndarray::ArrayView3<'_, f32>, segs: &[std::ops::Range<usize>], fps: f64) -> (f64, usize) {
    let sum = segs.iter().map(|r| crate::metrics::kinematics::smoothness_cv(positions.slice(s![r.clone(), .., ..]), fps)).sum();
    (sum, segs.len())
}

/// Trains and writes the model folder; returns the per-epoch log.
pub fn train(opts: &Options) -> Result<Vec<EpochLog>, TrainError> {
    tch::set_num_threads(opts.threads);
    tch::manual_seed(opts.seed as i64);
    if opts.eval_only {
        let eval = evaluate_folder(&opts.out, &opts.data, opts.eval_keys, opts.seed)?;
        tracing::info!(?eval, "key-pose consistency on the test split");
        write_atomic(&opts.out.join("eval.json"), serde_json::to_string_pretty(&eval)?.as_bytes())?;
        return Ok(Vec::new());
    }
    let started = Instant::now();
    let ds = Dataset::open(&opts.data)?;
    let features: super::FeatureFn = crate::audio::features::keypose;
    let mut train_raw = load_sequences(&ds, ds.train_ids(), features)?;
    let mut test_raw = load_sequences(&ds, ds.test_ids(), features)?;
    for seq in train_raw.iter_mut().chain(test_raw.iter_mut()) {
        to_clearance(&mut seq.poses);
    }
    let (music_norm, pose_norm) = fit_normalizers(&train_raw)?;
    let norm = |seqs: &[Sequence]| -> Result<Vec<Sequence>, TrainError> {
        seqs.iter()
            .map(|s| Ok(Sequence { music: music_norm.normalize(&s.music)?, poses: pose_norm.normalize(&s.poses)?, id: s.id.clone() }))
            .collect()
    };
    let (train, test) = (norm(&train_raw)?, norm(&test_raw)?);
    tracing::info!(seconds = started.elapsed().as_secs_f64(), "data ready");

    let base = if opts.tiny { Config::tiny(0, 0, 0) } else { Config::cpu() };
    let config = Config { music_dim: music_norm.dim() as i64, pose_dim: pose_norm.dim() as i64, key_dim: POSE_DIM as i64, lambda: opts.lambda, sigma: opts.sigma, ..base };
    let mut vs = nn::VarStore::new(Device::Cpu);
    let model = KeyposeTransformer::new(&vs.root(), config.clone());
    if let Some(init) = &opts.init {
        vs.load(init)?;
        tracing::info!(from = %init.display(), "initialised from earlier weights");
    }
    let mut opt = nn::Adam::default().build(&vs, opts.lr)?;
    std::fs::create_dir_all(&opts.out).map_err(|source| TrainError::Io { path: opts.out.clone(), source })?;
    let log_path = opts.out.join("train_log.jsonl");
    let _ = std::fs::remove_file(&log_path);

    let len = config.window as usize;
    let mut logs = Vec::new();
    let mut steps = 0usize;
    let record = |epochs: usize, steps: usize, logs: &[EpochLog]| TrainingRecord {
        epochs,
        steps,
        lr: opts.lr,
        batch: opts.batch,
        max_keys: opts.max_keys,
        seed: opts.seed,
        final_train_loss: logs.last().map(|l| l.train_loss).unwrap_or(f64::NAN),
        minutes: started.elapsed().as_secs_f64() / 60.0,
        velocity_weight: opts.velocity_weight,
    };
    let model_file = |training: TrainingRecord| ModelFile {
        config: config.clone(),
        music_norm: music_norm.clone(),
        pose_norm: pose_norm.clone(),
        fps: crate::motion::MOTION_FPS,
        training,
        root_height: RootHeight::FootClearance,
        scaffold_spacing: opts.scaffold_spacing,
    };
    pose_bank(&train_raw, opts.bank_clips, opts.bank_frames, opts.seed)?
        .save(&opts.out.join(POSE_BANK_FILE))
        .map_err(|e| TrainError::Motion(crate::motion::MotionError::Invalid(e.to_string())))?;
    for epoch in 0..opts.epochs {
        let t0 = Instant::now();
        let starts = window_starts(&train, len, opts.stride, opts.seed + epoch as u64);
        if starts.is_empty() {
            return Err(TrainError::NoWindows(len));
        }
        let mut rng = StdRng::seed_from_u64(opts.seed ^ (epoch as u64).wrapping_mul(0x9E37_79B9));
        let (mut total, mut batches) = (0.0, 0);
        let mut out_of_time = false;
        for chunk in starts.chunks(opts.batch) {
            let loss = window_loss(&model, &config, &train, chunk, opts.max_keys, opts.velocity_weight, &mut rng, true);
            opt.backward_step_clip(&loss, 1.0);
            total += loss.double_value(&[]);
            batches += 1;
            steps += 1;
            out_of_time = opts.max_minutes.is_some_and(|m| started.elapsed().as_secs_f64() > m * 60.0);
            if out_of_time {
                break;
            }
        }
        let test_loss = tch::no_grad(|| {
            let mut rng = StdRng::seed_from_u64(7);
            let starts = window_starts(&test, len, len, 0);
            let losses: Vec<f64> = starts.chunks(opts.batch).map(|c| window_loss(&model, &config, &test, c, opts.max_keys, opts.velocity_weight, &mut rng, false).double_value(&[])).collect();
            (!losses.is_empty()).then(|| losses.iter().sum::<f64>() / losses.len() as f64)
        });
        let line = EpochLog { epoch, train_loss: total / batches.max(1) as f64, test_loss, note: format!("steps={steps} λ={} σ={}", opts.lambda, opts.sigma), seconds: t0.elapsed().as_secs_f64() };
        tracing::info!(epoch, train_loss = line.train_loss, test_loss = ?line.test_loss, steps, seconds = line.seconds, "epoch");
        append_log(&log_path, &line)?;
        logs.push(line);
        if epoch % 2 == 1 || epoch + 1 == opts.epochs || out_of_time {
            save(&vs, &opts.out, &model_file(record(epoch + 1, steps, &logs)))?;
        }
        if out_of_time {
            tracing::warn!(epoch, "stopping: --max-minutes reached");
            break;
        }
    }
    let file = model_file(record(logs.len(), steps, &logs));
    save(&vs, &opts.out, &file)?;
    let eval = evaluate(&model, &file, &ds, &test_raw, opts.eval_keys, opts.seed)?;
    tracing::info!(?eval, "key-pose consistency on the test split");
    write_atomic(&opts.out.join("eval.json"), serde_json::to_string_pretty(&eval)?.as_bytes())?;
    Ok(logs)
}

/// Replaces a dance's root heights by its lowest foot's clearance above the dance's own floor.
fn to_clearance(poses: &mut Array2<f32>) {
    let floor = repr::floor_of_features(poses.view());
    repr::height_to_clearance(poses, floor);
}

/// `clips` clips of `frames` frames from the train dances (features as the model predicts them,
/// denormalised), at seeded starts spread over the dances in proportion to their length.
fn pose_bank(train: &[Sequence], clips: usize, frames: usize, seed: u64) -> Result<PoseBank, TrainError> {
    let mut rng = StdRng::seed_from_u64(seed ^ 0xBA_4C);
    let long: Vec<&Sequence> = train.iter().filter(|s| s.poses.nrows() >= frames).collect();
    let total: usize = long.iter().map(|s| s.poses.nrows() - frames + 1).sum();
    if long.is_empty() || clips == 0 {
        return Err(TrainError::NoWindows(frames));
    }
    let width = long[0].poses.ncols();
    let mut bank = ndarray::Array3::<f32>::zeros((clips, frames, width));
    for c in 0..clips {
        // Stratified over the concatenated start positions, jittered within each stratum.
        let mut at = (c * total) / clips + rng.gen_range(0..(total / clips).max(1));
        for seq in &long {
            let n = seq.poses.nrows() - frames + 1;
            if at < n {
                bank.slice_mut(s![c, .., ..]).assign(&seq.poses.slice(s![at..at + frames, ..]));
                break;
            }
            at -= n;
        }
    }
    PoseBank::new(bank).map_err(|e| TrainError::Motion(crate::motion::MotionError::Invalid(e.to_string())))
}

/// Draws 0..=max_keys distinct key frames in `[T′, T)` (the seed already fixes the first frames).
fn sample_keys(rng: &mut StdRng, c: &Config, max_keys: usize) -> Vec<i64> {
    let count = rng.gen_range(0..=max_keys);
    let mut frames: Vec<i64> = (c.seed_len..c.window).collect();
    frames.shuffle(rng);
    frames.truncate(count);
    frames.sort_unstable();
    frames
}

/// Weighted L1 between one batch's predictions and the ground truth, with ω(t) from the sampled
/// key frames (§3.4).
#[allow(clippy::too_many_arguments)]
fn window_loss(model: &KeyposeTransformer, c: &Config, seqs: &[Sequence], starts: &[(usize, usize)], max_keys: usize, velocity_weight: f64, rng: &mut StdRng, train: bool) -> Tensor {
    let len = c.window as usize;
    let music = batch_tensor(seqs, starts, len, |s| &s.music, Device::Cpu);
    let poses = batch_tensor(seqs, starts, len, |s| &s.poses, Device::Cpu); // [b, T, pose]
    let b = starts.len() as i64;
    let (t, d, kd) = (c.window, c.d, c.key_dim);
    let mut mask = vec![0f32; (b * t) as usize];
    let mut local = Vec::with_capacity((b * t * d) as usize);
    let mut weights = Vec::with_capacity((b * t) as usize);
    for i in 0..b as usize {
        let keys = sample_keys(rng, c, max_keys);
        for &k in &keys {
            mask[i * t as usize + k as usize] = 1.0;
        }
        local.extend(local_position_embedding(t, &keys, d));
        weights.extend(loss_weights(t, &keys, c.lambda, c.sigma));
    }
    let key_mask = Tensor::from_slice(&mask).view([b, t]);
    let x = WindowInput {
        keys: poses.narrow(2, 0, kd) * key_mask.unsqueeze(-1),
        key_mask,
        seed: poses.narrow(1, 0, c.seed_len),
        music,
        local_pos: Tensor::from_slice(&local).view([b, t, d]),
    };
    let w = Tensor::from_slice(&weights).view([b, t, 1]);
    let pred = model.forward(&x, train);
    let err = (&pred - &poses).abs() * &w;
    let pose_term = err.sum(Kind::Float) / (w.sum(Kind::Float) * c.pose_dim as f64);
    // Frame differences after the seed: [b, T − T′ − 1, pose].
    let (from, len) = (c.seed_len, c.window - c.seed_len);
    let (p, y) = (pred.narrow(1, from - 1, len + 1), poses.narrow(1, from - 1, len + 1));
    let vel = (p.diff(1, 1, None::<Tensor>, None::<Tensor>) - y.diff(1, 1, None::<Tensor>, None::<Tensor>)).abs().mean(Kind::Float);
    pose_term + vel * velocity_weight
}

/// Key-pose consistency on whole test dances through the served path: each dance is seeded with
/// its first `T′` real frames and given `keys` real poses at random frames after the seed.
pub fn evaluate(model: &KeyposeTransformer, file: &ModelFile, ds: &Dataset, test: &[Sequence], keys: usize, seed: u64) -> Result<KeyPoseEval, TrainError> {
    let mut rng = StdRng::seed_from_u64(seed);
    let ts = file.config.seed_len as usize;
    let (mut net, mut served, mut dance, mut dance_free, mut n) = (0.0, 0.0, 0.0, 0.0, 0usize);
    let (mut scv_real, mut scv_network, mut scv_served) = (0.0, 0.0, 0.0);
    // (sum, count) of segment S_cv: served at joins, served within, real at joins, real within.
    let mut seg = [(0.0, 0usize); 4];
    for seq in test {
        let t = seq.poses.nrows();
        if t <= ts + keys {
            continue;
        }
        let d = ds.load(&seq.id)?;
        let rel = d.root_relative();
        let mut frames: Vec<usize> = (ts..t).collect();
        frames.shuffle(&mut rng);
        frames.truncate(keys);
        frames.sort_unstable();
        let key_poses: Vec<KeyPose> = frames
            .iter()
            .map(|&f| KeyPose { time_s: f as f64 / file.fps, joints: (0..NUM_JOINTS).map(|j| [0, 1, 2].map(|a| f64::from(rel[[f, j, a]]))).collect() })
            .collect();
        let local: Vec<LocalKey> = key_poses
            .iter()
            .zip(&frames)
            .map(|(k, &f)| {
                let joints = Array2::from_shape_fn((NUM_JOINTS, 3), |(j, a)| k.joints[j][a] as f32);
                let (local, yaw) = to_local(joints.view());
                LocalKey { frame: f, local, yaw }
            })
            .collect();
        let music = to_tensor(&file.music_norm.normalize(&seq.music)?);
        let (mut seed_feats, start) = repr::to_features(d.motion.positions.view(), d.center.view())?;
        to_clearance(&mut seed_feats);
        let seed_rows = seed_feats.slice(s![0..ts, ..]).to_owned();
        let gen = |keys: &[LocalKey]| {
            generate_features(model, file, &music, Some((&seed_rows, start)), true, keys, &[], |_, _| true)
                .map_err(|e| TrainError::Motion(crate::motion::MotionError::Invalid(e.to_string())))?
                .ok_or(TrainError::NoWindows(0))
        };
        let g = gen(&local)?;
        let (raw, out, start2) = (g.network, g.served, g.start);
        let free = gen(&[])?.served;
        for (k, lk) in frames.iter().zip(&local) {
            net += joint_error_cm(&raw.row(*k).to_vec(), &lk.local);
        }
        let (motion, root) = repr::from_features(out.view(), start2, file.fps)?;
        served += crate::metrics::kinematics::key_pose_error_root_cm(&motion, root.view(), &key_poses).unwrap_or(f64::NAN) * keys as f64;
        let fps = file.fps;
        let smooth = crate::metrics::kinematics::smoothness_cv;
        let (net_motion, _) = repr::from_features(raw.view(), start2, fps)?;
        scv_real += smooth(d.motion.positions.view(), fps);
        scv_network += smooth(net_motion.positions.view(), fps);
        scv_served += smooth(motion.positions.view(), fps);
        let joins = crate::models::keypose_transformer::join_frames(t, &file.config);
        let at = segments(&joins, SEGMENT_HALF, t);
        let within = segments(&mid_window_centres(&joins, ts, t), SEGMENT_HALF, t);
        for (slot, (pos, segs)) in [(&motion.positions, &at), (&motion.positions, &within), (&d.motion.positions, &at), (&d.motion.positions, &within)].into_iter().enumerate() {
            let (sum, count) = segment_scv(pos.view(), segs, fps);
            seg[slot].0 += sum;
            seg[slot].1 += count;
        }
        dance += mean_rows_error_cm(&out, &seed_feats);
        dance_free += mean_rows_error_cm(&free, &seed_feats);
        n += 1;
        tracing::info!(dance = %seq.id, frames = t, "evaluated");
    }
    let k = (n * keys).max(1) as f64;
    let per_dance = |x: f64| x / n.max(1) as f64;
    let mean = |(sum, count): (f64, usize)| if count == 0 { f64::NAN } else { sum / count as f64 };
    Ok(KeyPoseEval {
        dances: n,
        keys_per_dance: keys,
        network_error_cm: net / k,
        served_error_cm: served / k,
        dance_error_cm: per_dance(dance),
        dance_error_no_keys_cm: per_dance(dance_free),
        scv_real: per_dance(scv_real),
        scv_network: per_dance(scv_network),
        scv_served: per_dance(scv_served),
        scv_at_joins: mean(seg[0]),
        scv_within_windows: mean(seg[1]),
        scv_real_at_joins: mean(seg[2]),
        scv_real_within_windows: mean(seg[3]),
    })
}

/// Mean per-joint distance (cm) between two 69-long local pose vectors.
fn joint_error_cm(a: &[f32], b: &[f32]) -> f64 {
    (0..NUM_JOINTS).map(|j| (0..3).map(|k| f64::from(a[3 * j + k] - b[3 * j + k]).powi(2)).sum::<f64>().sqrt()).sum::<f64>() * 100.0 / NUM_JOINTS as f64
}

/// Mean per-joint distance (cm) over all frames of two feature matrices' local poses.
fn mean_rows_error_cm(a: &Array2<f32>, b: &Array2<f32>) -> f64 {
    let n = a.nrows().min(b.nrows());
    (0..n).map(|t| joint_error_cm(&a.row(t).to_vec(), &b.row(t).to_vec())).sum::<f64>() / n.max(1) as f64
}

/// Re-runs the test-split evaluation for a trained folder (`model.json` + weights).
pub fn evaluate_folder(dir: &Path, data: &Path, keys: usize, seed: u64) -> Result<KeyPoseEval, TrainError> {
    let text = std::fs::read_to_string(dir.join(MODEL_FILE)).map_err(|source| TrainError::Io { path: dir.join(MODEL_FILE), source })?;
    let file: ModelFile = serde_json::from_str(&text)?;
    let mut vs = nn::VarStore::new(Device::Cpu);
    let model = KeyposeTransformer::new(&vs.root(), file.config.clone());
    vs.load(dir.join(WEIGHTS_FILE))?;
    let ds = Dataset::open(data)?;
    let test = load_sequences(&ds, ds.test_ids(), crate::audio::features::keypose)?;
    evaluate(&model, &file, &ds, &test, keys, seed)
}

fn save(vs: &nn::VarStore, dir: &Path, file: &ModelFile) -> Result<(), TrainError> {
    let tmp = dir.join(format!("{WEIGHTS_FILE}.tmp.safetensors"));
    vs.save(&tmp)?;
    std::fs::rename(&tmp, dir.join(WEIGHTS_FILE)).map_err(|source| TrainError::Io { path: dir.to_owned(), source })?;
    write_atomic(&dir.join(MODEL_FILE), serde_json::to_string_pretty(file)?.as_bytes())
}

