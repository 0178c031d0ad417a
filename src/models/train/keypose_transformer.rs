//! `choreo train keypose-transformer`: the key-pose weighted reconstruction loss (ω(t), §3.4),
//! key poses sampled from the ground truth at random counts and frames, the seed motion taken as
//! each window's first `T′` frames, Adam, on the train split of dance-with-melody. After training
//! it measures the key-pose consistency error on the test split (whole dances, overlapping
//! windows, the served code path) and writes it to `eval.json` for the model card.
use std::path::Path;

use ndarray::{s, Array2};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use tch::nn;
use tch::{Device, Kind, Tensor};

use super::{
    batch_tensor, load_sequences, window_starts, write_atomic, CommonOptions, Data, EpochLog,
    EpochResult, Sequence, Tempo, TrainError, Trainer,
};
use crate::models::folder;
use crate::models::keypose_transformer::scaffold::{BankMeta, ClipInfo, PoseBank, POSE_BANK_FILE};
use crate::models::keypose_transformer::served::RootHeight;
use crate::models::keypose_transformer::{
    generate_features, local_position_embedding, loss_weights, to_local, Config, KeySampling,
    KeyposeTransformer, LocalKey, ModelFile, Serving, WindowInput, ID,
};
use crate::models::to_tensor;
use crate::motion::dataset::Dataset;
use crate::motion::repr::{self, POSE_DIM};
use crate::motion::{KeyPose, NUM_JOINTS};

/// Options of one training run; the model card gives the runs (and flags) behind the committed weights.
#[derive(Clone, Debug)]
pub struct Options {
    pub common: CommonOptions,
    pub epochs: usize,
    pub batch: usize,
    /// Stride between training window starts, in frames.
    pub stride: usize,
    pub lr: f64,
    /// `λ`: weight of the key-pose terms in ω(t).
    pub lambda: f64,
    /// `σ`: width of each key-pose term in ω(t), frames.
    pub sigma: f64,
    /// Weight of the L1 on frame differences (velocities) beside the pose term: the pose term alone
    /// lets a regression average fast motion away.
    pub velocity_weight: f64,
    /// Frames between the scaffold poses the served model draws (0: none); see the scaffold module.
    pub scaffold_spacing: usize,
    /// Clips of the served pose bank, and their length in frames.
    pub bank_clips: usize,
    pub bank_frames: usize,
    /// Key poses per training window are drawn uniformly from 0..=max_keys.
    pub max_keys: usize,
    /// Key poses per test dance in the consistency evaluation.
    pub eval_keys: usize,
    pub seed: u64,
    /// Do not train: re-run the test-split evaluation of the model already in `--out` and rewrite
    /// its `eval.json`.
    pub eval_only: bool,
    /// Do not train: redraw the pose bank (the same clips for the same `--seed`, `--bank-clips` and
    /// `--bank-frames`) with each clip's source and beats, into `--out`.
    pub bank_only: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            common: CommonOptions::default(),
            epochs: 200,
            batch: 32,
            stride: 10,
            lr: 5e-4,
            lambda: 3.0,
            sigma: 3.0,
            velocity_weight: 5.0,
            scaffold_spacing: 25,
            bank_clips: 32,
            bank_frames: 200,
            max_keys: 6,
            eval_keys: 4,
            seed: 2023,
            eval_only: false,
            bank_only: false,
        }
    }
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
    centres
        .iter()
        .filter(|&&c| c >= half && c + half <= n)
        .map(|&c| c - half..c + half)
        .collect()
}

/// The centres midway between consecutive joins (and between the seed's end and the first join,
/// and the last join and the end).
fn mid_window_centres(joins: &[usize], first: usize, n: usize) -> Vec<usize> {
    let mut bounds = vec![first];
    bounds.extend_from_slice(joins);
    bounds.push(n);
    bounds
        .windows(2)
        .filter(|p| p[1] > p[0] + 2 * SEGMENT_HALF)
        .map(|p| (p[0] + p[1]) / 2)
        .collect()
}

/// Sums of `S_cv` over the segments of a motion, and their count.
fn segment_scv(
    positions: ndarray::ArrayView3<'_, f32>,
    segs: &[std::ops::Range<usize>],
    fps: f64,
) -> (f64, usize) {
    let sum = segs
        .iter()
        .map(|r| {
            crate::metrics::kinematics::smoothness_cv(positions.slice(s![r.clone(), .., ..]), fps)
        })
        .sum();
    (sum, segs.len())
}

/// Trains and writes the model folder; returns the per-epoch log.
pub fn train(opts: &Options) -> Result<Vec<EpochLog>, TrainError> {
    let out = opts.common.out_dir(ID);
    if opts.eval_only {
        tch::set_num_threads(opts.common.threads);
        let eval = evaluate_folder(&out, &opts.common.data, opts.eval_keys, opts.seed)?;
        tracing::info!(?eval, "key-pose consistency on the test split");
        write_atomic(
            &out.join("eval.json"),
            serde_json::to_string_pretty(&eval)?.as_bytes(),
        )?;
        return Ok(Vec::new());
    }
    if opts.bank_only {
        let ds = Dataset::open(&opts.common.data)?;
        let mut train = load_sequences(
            &ds,
            ds.train_ids(),
            crate::audio::features::keypose,
            Tempo::Skipped,
        )?;
        train.iter_mut().for_each(|s| to_clearance(&mut s.poses));
        std::fs::create_dir_all(&out).map_err(|source| TrainError::Io {
            path: out.clone(),
            source,
        })?;
        let bank = pose_bank(&ds, &train, opts)?;
        bank.save(&out.join(POSE_BANK_FILE))?;
        tracing::info!(clips = opts.bank_clips, out = %out.display(), "pose bank redrawn");
        return Ok(Vec::new());
    }
    let data = Data::load(
        &opts.common.data,
        crate::audio::features::keypose,
        Tempo::Skipped,
        |seq| {
            to_clearance(&mut seq.poses);
            Ok(())
        },
    )?;
    let base = if opts.common.tiny {
        Config::tiny(0, 0, 0)
    } else {
        Config::cpu()
    };
    let config = Config {
        music_dim: data.music_norm.dim() as i64,
        pose_dim: data.pose_norm.dim() as i64,
        key_dim: POSE_DIM as i64,
        lambda: opts.lambda,
        sigma: opts.sigma,
        ..base
    };
    let (mut trainer, model) = Trainer::new(&opts.common, ID, opts.lr, opts.seed, |p| {
        KeyposeTransformer::new(p, config.clone())
    })?;
    let (train, test) = (&data.train, &data.test);
    let len = config.window as usize;
    let steps = std::cell::Cell::new(0usize);
    let model_file = |t: &Trainer| ModelFile {
        config: config.clone(),
        music_norm: data.music_norm.clone(),
        pose_norm: data.pose_norm.clone(),
        fps: crate::motion::MOTION_FPS,
        training: t.record(
            opts.lr,
            opts.batch,
            opts.seed,
            KeySampling {
                steps: steps.get(),
                max_keys: opts.max_keys,
                velocity_weight: opts.velocity_weight,
            },
        ),
        extra: Serving {
            root_height: RootHeight::FootClearance,
            scaffold_spacing: opts.scaffold_spacing,
            scaffold_facing: true,
        },
    };
    pose_bank(&data.dataset, &data.train_raw, opts)?
        .save(&trainer.out.join(POSE_BANK_FILE))
        .map_err(|e| TrainError::Motion(crate::motion::MotionError::Invalid(e.to_string())))?;
    trainer.run(
        0..opts.epochs,
        2,
        |epoch, opt, deadline| {
            let starts = window_starts(train, len, opts.stride, opts.seed + epoch as u64);
            if starts.is_empty() {
                return Err(TrainError::NoWindows(len));
            }
            let mut rng =
                StdRng::seed_from_u64(opts.seed ^ (epoch as u64).wrapping_mul(0x9E37_79B9));
            let (mut total, mut batches) = (0.0, 0);
            for chunk in starts.chunks(opts.batch) {
                let loss = window_loss(
                    &model,
                    &config,
                    train,
                    chunk,
                    opts.max_keys,
                    opts.velocity_weight,
                    &mut rng,
                    true,
                );
                opt.backward_step_clip(&loss, 1.0);
                total += loss.double_value(&[]);
                batches += 1;
                steps.set(steps.get() + 1);
                if deadline.expired() {
                    break;
                }
            }
            let test_loss = tch::no_grad(|| {
                let mut rng = StdRng::seed_from_u64(7);
                let starts = window_starts(test, len, len, 0);
                let losses: Vec<f64> = starts
                    .chunks(opts.batch)
                    .map(|c| {
                        window_loss(
                            &model,
                            &config,
                            test,
                            c,
                            opts.max_keys,
                            opts.velocity_weight,
                            &mut rng,
                            false,
                        )
                        .double_value(&[])
                    })
                    .collect();
                (!losses.is_empty()).then(|| losses.iter().sum::<f64>() / losses.len() as f64)
            });
            Ok(EpochResult {
                train_loss: total / batches.max(1) as f64,
                test_loss,
                note: format!("steps={} λ={} σ={}", steps.get(), opts.lambda, opts.sigma),
            })
        },
        model_file,
    )?;
    let file = model_file(&trainer);
    trainer.save(&file)?;
    let eval = evaluate(
        &model,
        &file,
        &data.dataset,
        &data.test_raw,
        opts.eval_keys,
        opts.seed,
    )?;
    tracing::info!(?eval, "key-pose consistency on the test split");
    write_atomic(
        &trainer.out.join("eval.json"),
        serde_json::to_string_pretty(&eval)?.as_bytes(),
    )?;
    Ok(trainer.logs)
}

/// Replaces a dance's root heights by its lowest foot's clearance above the dance's own floor.
fn to_clearance(poses: &mut Array2<f32>) {
    let floor = repr::floor_of_features(poses.view());
    repr::height_to_clearance(poses, floor);
}

/// `clips` clips of `frames` frames from the train dances (features as the model predicts them,
/// denormalised), at seeded starts spread over the dances in proportion to their length: the
/// dance (index into `train`) and start frame of each.
fn bank_picks(
    train: &[Sequence],
    clips: usize,
    frames: usize,
    seed: u64,
) -> Result<Vec<(usize, usize)>, TrainError> {
    let mut rng = StdRng::seed_from_u64(seed ^ 0xBA_4C);
    let long: Vec<usize> = (0..train.len())
        .filter(|&i| train[i].poses.nrows() >= frames)
        .collect();
    let total: usize = long
        .iter()
        .map(|&i| train[i].poses.nrows() - frames + 1)
        .sum();
    if long.is_empty() || clips == 0 {
        return Err(TrainError::NoWindows(frames));
    }
    let mut picks = Vec::with_capacity(clips);
    for c in 0..clips {
        // Stratified over the concatenated start positions, jittered within each stratum.
        let mut at = (c * total) / clips + rng.gen_range(0..(total / clips).max(1));
        for &i in &long {
            let n = train[i].poses.nrows() - frames + 1;
            if at < n {
                picks.push((i, at));
                break;
            }
            at -= n;
        }
    }
    Ok(picks)
}

/// The pose bank ([`bank_picks`] with the options' seed, clip count and length) with each clip's
/// source, style and song beats: every train dance's song is analysed (`audio::analyze`) and its
/// beats put on the clip's frames; the energy is the mean onset strength of the dance's music
/// features (`train[..].music`, `audio::features::keypose`, raw) under the clip.
fn pose_bank(ds: &Dataset, train: &[Sequence], opts: &Options) -> Result<PoseBank, TrainError> {
    let (clips, frames) = (opts.bank_clips, opts.bank_frames);
    let picks = bank_picks(train, clips, frames, opts.seed)?;
    let width = train[picks[0].0].poses.ncols();
    let mut bank = ndarray::Array3::<f32>::zeros((clips, frames, width));
    let mut infos = Vec::with_capacity(clips);
    let mut analysed: std::collections::HashMap<
        usize,
        (crate::motion::dataset::Dance, crate::audio::Analysis),
    > = std::collections::HashMap::new();
    for (c, &(i, at)) in picks.iter().enumerate() {
        let seq = &train[i];
        bank.slice_mut(s![c, .., ..])
            .assign(&seq.poses.slice(s![at..at + frames, ..]));
        let (dance, analysis) = match analysed.entry(i) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(e) => {
                let dance = ds.load(&seq.id)?;
                let analysis =
                    crate::audio::analyze(&crate::audio::decode_path(&dance.audio_path)?)?;
                e.insert((dance, analysis))
            }
        };
        let fps = dance.motion.fps;
        let first = dance.song_time_s(at);
        let onset = seq
            .music
            .slice(s![at..at + frames, crate::audio::features::KEYPOSE_DIM - 1]);
        let energy = onset.iter().map(|v| f64::from(*v)).sum::<f64>() / frames as f64;
        let info = ClipInfo::of_song(
            seq.id.clone(),
            at,
            dance.style,
            analysis,
            first,
            fps,
            frames,
            energy,
        );
        tracing::info!(clip = c, dance = %seq.id, start = at, beats = info.beats.len(), tempo = analysis.tempo_bpm, bar = info.bar, energy, "bank clip");
        infos.push(info);
    }
    let meta = BankMeta {
        made_by: format!(
            "choreo train keypose-transformer --bank-only --seed {} --bank-clips {clips} --bank-frames {frames}: {clips} clips of {frames} frames from the train split at seeded starts spread over the dances in proportion to their length (the clips training writes for the same options); beats from audio::analyze of each dance's whole song, put on the clip's frames with Dance::song_time_s; energy = mean onset strength (audio::features::keypose column 14) under the clip",
            opts.seed
        ),
        fps: crate::motion::MOTION_FPS,
        clips: infos,
    };
    Ok(PoseBank::new(bank)?.with_meta(meta)?)
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
fn window_loss(
    model: &KeyposeTransformer,
    c: &Config,
    seqs: &[Sequence],
    starts: &[(usize, usize)],
    max_keys: usize,
    velocity_weight: f64,
    rng: &mut StdRng,
    train: bool,
) -> Tensor {
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
    let (p, y) = (
        pred.narrow(1, from - 1, len + 1),
        poses.narrow(1, from - 1, len + 1),
    );
    let vel = (p.diff(1, 1, None::<Tensor>, None::<Tensor>)
        - y.diff(1, 1, None::<Tensor>, None::<Tensor>))
    .abs()
    .mean(Kind::Float);
    pose_term + vel * velocity_weight
}

/// Key-pose consistency on whole test dances through the served path: each dance is seeded with
/// its first `T′` real frames and given `keys` real poses at random frames after the seed.
pub fn evaluate(
    model: &KeyposeTransformer,
    file: &ModelFile,
    ds: &Dataset,
    test: &[Sequence],
    keys: usize,
    seed: u64,
) -> Result<KeyPoseEval, TrainError> {
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
            .map(|&f| KeyPose {
                time_s: f as f64 / file.fps,
                joints: (0..NUM_JOINTS)
                    .map(|j| [0, 1, 2].map(|a| f64::from(rel[[f, j, a]])))
                    .collect(),
            })
            .collect();
        let local: Vec<LocalKey> = key_poses
            .iter()
            .zip(&frames)
            .map(|(k, &f)| {
                let joints = Array2::from_shape_fn((NUM_JOINTS, 3), |(j, a)| k.joints[j][a] as f32);
                let (local, yaw) = to_local(joints.view());
                LocalKey {
                    frame: f,
                    local,
                    yaw,
                }
            })
            .collect();
        let music = to_tensor(&file.music_norm.normalize(&seq.music)?);
        let (mut seed_feats, start) =
            repr::to_features(d.motion.positions.view(), d.center.view())?;
        to_clearance(&mut seed_feats);
        let seed_rows = seed_feats.slice(s![0..ts, ..]).to_owned();
        let gen = |keys: &[LocalKey]| {
            generate_features(
                model,
                file,
                &music,
                Some((&seed_rows, start)),
                true,
                keys,
                &[],
                &[],
                |_, _| true,
            )
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
        served +=
            crate::metrics::kinematics::key_pose_error_root_cm(&motion, root.view(), &key_poses)
                .unwrap_or(f64::NAN)
                * keys as f64;
        let fps = file.fps;
        let smooth = crate::metrics::kinematics::smoothness_cv;
        let (net_motion, _) = repr::from_features(raw.view(), start2, fps)?;
        scv_real += smooth(d.motion.positions.view(), fps);
        scv_network += smooth(net_motion.positions.view(), fps);
        scv_served += smooth(motion.positions.view(), fps);
        let joins = crate::models::keypose_transformer::join_frames(t, &file.config);
        let at = segments(&joins, SEGMENT_HALF, t);
        let within = segments(&mid_window_centres(&joins, ts, t), SEGMENT_HALF, t);
        for (slot, (pos, segs)) in [
            (&motion.positions, &at),
            (&motion.positions, &within),
            (&d.motion.positions, &at),
            (&d.motion.positions, &within),
        ]
        .into_iter()
        .enumerate()
        {
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
    let mean = |(sum, count): (f64, usize)| {
        if count == 0 {
            f64::NAN
        } else {
            sum / count as f64
        }
    };
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
    (0..NUM_JOINTS)
        .map(|j| {
            (0..3)
                .map(|k| f64::from(a[3 * j + k] - b[3 * j + k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .sum::<f64>()
        * 100.0
        / NUM_JOINTS as f64
}

/// Mean per-joint distance (cm) over all frames of two feature matrices' local poses.
fn mean_rows_error_cm(a: &Array2<f32>, b: &Array2<f32>) -> f64 {
    let n = a.nrows().min(b.nrows());
    (0..n)
        .map(|t| joint_error_cm(&a.row(t).to_vec(), &b.row(t).to_vec()))
        .sum::<f64>()
        / n.max(1) as f64
}

/// Re-runs the test-split evaluation for a trained folder (`model.json` + weights).
pub fn evaluate_folder(
    dir: &Path,
    data: &Path,
    keys: usize,
    seed: u64,
) -> Result<KeyPoseEval, TrainError> {
    let file: ModelFile = folder::read(dir, ID)
        .map_err(|e| TrainError::Motion(crate::motion::MotionError::Invalid(e.to_string())))?;
    let mut vs = nn::VarStore::new(Device::Cpu);
    let model = KeyposeTransformer::new(&vs.root(), file.config.clone());
    vs.load(dir.join(folder::WEIGHTS_FILE))?;
    let ds = Dataset::open(data)?;
    let test = load_sequences(
        &ds,
        ds.test_ids(),
        crate::audio::features::keypose,
        Tempo::Skipped,
    )?;
    evaluate(&model, &file, &ds, &test, keys, seed)
}
