//! `choreo train dancenet`: the mixture negative log-likelihood of every next frame of a window
//! plus λ times the foot-contact cross-entropy (paper §3.4), teacher-forced with Gaussian noise on
//! the decoder's input frames, Adam, on the train split of dance-with-melody. Fits the rig every
//! dance is expressed on (train split), and writes it, the normalisation and a few real seed
//! clips beside the weights.
use ndarray::{concatenate, Array2, ArrayView2, Axis};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use tch::{Device, Kind, Tensor};

use super::augment::Augment;
use super::{
    batch_tensor, window_starts, CommonOptions, EpochLog, EpochResult, Sequence, TrainError,
    Trainer,
};
use crate::metrics::physical::seed_distance_m;
use crate::models::dancenet::{Config, DanceNet, ModelFile, Sampling, Schedule, Serving, ID};
use crate::models::folder::{SeedClips, SEED_CLIPS_FILE};
use crate::models::stretch::{stretch_music, stretch_rotation_rows, MusicLayout};
use crate::models::to_tensor;
use crate::models::DanceStyle;
use crate::motion::dataset::{Dance, Dataset, NormStats};
use crate::motion::rig::Rig;
use crate::motion::rotations;

mod free_run;
mod lock;
mod phase;

/// Options of one training run (the card gives the run behind the committed weights).
#[derive(Clone, Debug)]
pub struct Options {
    pub common: CommonOptions,
    pub epochs: usize,
    pub batch: usize,
    /// Training window, frames (the context encoder's 8 s).
    pub window: usize,
    /// Stride between window starts, frames.
    pub stride: usize,
    pub lr: f64,
    /// λ, the weight of the foot-contact loss.
    pub lambda_foot: f64,
    /// σ_in: standard deviation of the Gaussian noise on the decoder's input frames (normalised
    /// units; the targets stay clean), so it learns to come back from its own samples.
    pub input_noise: f64,
    /// Correlation from frame to frame of that noise (AR(1)); 0 is independent per frame. Noise
    /// independent per frame taught the decoder to undo a frame-to-frame zig-zag, and on its own
    /// (smooth) samples it then made one: its means alternated direction on 57 % of frames.
    pub input_coherence: f64,
    /// Standard deviation of a constant offset added to each window's input frames (normalised
    /// units; per window and dimension): a history that has drifted off the real dances, which
    /// the decoder must learn to come back from since the targets stay clean. Sampling drifts:
    /// every draw adds its own error to what the decoder reads next.
    pub input_offset: f64,
    /// Standard deviation per frame of a random walk added to the input frames (normalised
    /// units): drift that grows within the window.
    pub input_walk: f64,
    /// Frames of each window that are context only (default: the receptive field, so every
    /// scored frame sees real history, never zero padding).
    pub warmup: Option<usize>,
    /// Windows of the rarer styles repeat `(waltz frames / style frames)^p` times (at most 4), so
    /// the style input is learned from more than waltz; 0 trains on the data as it is.
    pub style_balance: f64,
    /// Mixture components (the paper: 1).
    pub mixtures: Option<i64>,
    /// Leading frame columns whose mixture means are absolute rather than relative to the current
    /// frame (default: all; 4 makes only the root's absolute, see `dancenet::Config::absolute_dims`).
    pub absolute_dims: Option<i64>,
    /// Default sampling temperature written into `model.json` (served: 0.8; see the model card).
    pub temperature: f64,
    /// Default coherence ρ of the sampling draws written into `model.json` (`dancenet::Sampling`).
    pub coherence: f64,
    /// σ (frames) of the served smoothing written into `model.json` (`dancenet::Serving`).
    pub smooth_frames: f64,
    pub seed: u64,
    /// Weight of the rhythm term: `rollout_windows` windows of each batch are danced on
    /// by the decoder alone after their first `warmup` real frames, drawing as served (σ ×
    /// `temperature`, draws of coherence `coherence`, reparameterised so the gradient reaches each
    /// draw's mean and σ), and the magnitude spectra of that motion's velocities are held to the real
    /// continuation's (`train::spectral`). Teacher forcing alone never scores the decoder's own
    /// stepping, which is where it loses the beat. 0: the paper's losses only.
    pub spectral_weight: f64,
    /// Weight of the lock term ([`lock`]): the same free-running windows, scored
    /// by how much of the toes' speed swings at the style's fraction of the song's beats. 0: off.
    pub lock_weight: f64,
    /// Windows of each batch danced on freely for the rhythm and lock terms.
    pub rollout_windows: usize,
    /// Windows drawn at tempo factors in `[min_tempo, max_tempo]` (log-uniform): music and dance
    /// resampled together (`train::augment`), so one figure is seen at many tempi.
    pub min_tempo: f64,
    pub max_tempo: f64,
    /// Share of training windows whose style input is zeroed, so the decoder learns what the
    /// style implies from the music code too (0: every window has its style).
    pub style_dropout: f64,
    /// [`Config::music_direct`]: the control signals join the music code in every gated layer
    /// (with `--init` from weights without them, their columns start at zero).
    pub music_direct: bool,
    /// [`Config::step_clock`]: a phase turning once per step of the song's beats joins every
    /// gated layer's conditioning; in training, at the real dancer's own fraction and zero
    /// ([`phase`]); with `--init` from weights without it, its columns start at zero.
    pub step_clock: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            common: CommonOptions::default(),
            epochs: 50,
            batch: 32,
            window: 200,
            stride: 20,
            lr: 1e-3,
            lambda_foot: 0.5,
            input_noise: 0.1,
            input_coherence: 0.9,
            input_offset: 0.1,
            input_walk: 0.01,
            warmup: None,
            style_balance: 0.5,
            mixtures: None,
            absolute_dims: None,
            temperature: 0.8,
            coherence: 0.95,
            smooth_frames: 2.0,
            seed: 2020,
            spectral_weight: 0.0,
            lock_weight: 0.0,
            rollout_windows: 8,
            min_tempo: 1.0,
            max_tempo: 1.0,
            style_dropout: 0.0,
            music_direct: false,
            step_clock: false,
        }
    }
}

/// Seed clips kept in the folder, and their length in frames (past the receptive field).
const SEED_CLIPS: usize = 32;

/// One dance in DanceNet's terms.
struct Prepared {
    id: String,
    style: DanceStyle,
    music: Array2<f32>,
    /// Rotation features then contacts, `[T, D + 4]`.
    frames: Array2<f32>,
}

/// `dances` as rotation features on `rig` with their control signals, and the mean per-joint
/// distance (m, root-relative, frame-weighted) between the dances and their rigid features decoded
/// back: the error the representation itself brings.
fn prepare(dances: &[Dance], rig: &Rig) -> Result<(Vec<Prepared>, f64), TrainError> {
    let mut out = Vec::new();
    let (mut err_sum, mut err_n) = (0.0f64, 0usize);
    for dance in dances {
        let id = &dance.id;
        let style = DanceStyle::of_dance_id(id).ok_or_else(|| {
            TrainError::Motion(crate::motion::MotionError::UnknownDance { id: id.clone() })
        })?;
        let audio = crate::audio::decode_path(&dance.audio_path)?;
        let t = dance.motion.num_frames();
        let music =
            crate::audio::features::dancenet(&audio, dance.motion.fps, dance.song_time_s(0), t)?;
        let enc = rotations::encode(rig, dance.motion.positions.view(), dance.motion.fps)?;
        let back = rotations::decode(rig, enc.features.view(), enc.start, dance.motion.fps)?;
        let n = t * crate::motion::NUM_JOINTS;
        err_sum += seed_distance_m(&dance.motion, &back) * n as f64;
        err_n += n;
        let frames = concatenate(Axis(1), &[enc.features.view(), enc.contacts.view()])
            .map_err(|e| TrainError::Model(crate::models::ModelError::Shape(e.to_string())))?;
        tracing::info!(dance = %id, frames = t, "loaded");
        out.push(Prepared {
            id: id.clone(),
            style,
            music,
            frames,
        });
    }
    Ok((out, err_sum / err_n.max(1) as f64))
}

/// Trains and writes the model folder; returns the per-epoch log.
pub fn train(opts: &Options) -> Result<Vec<EpochLog>, TrainError> {
    // Refused before the minutes of loading: the mixture count does not depend on the data.
    let mixtures = opts.mixtures.unwrap_or(if opts.common.tiny {
        Config::tiny(0).mixtures
    } else {
        Config::cpu(0).mixtures
    });
    if (opts.spectral_weight > 0.0 || opts.lock_weight > 0.0) && mixtures != 1 {
        return Err(TrainError::InvalidOption(format!(
            "--spectral-weight and --lock-weight dance one mixture component; this run has {mixtures} (--mixtures 1)"
        )));
    }
    // A run continued from a model folder's weights keeps that folder's rig and normalisation:
    // refitted today they differ a little (the features changed since), and the first epochs of
    // every fine-tune then went to re-learning the input scale, which no control could separate
    // from what the run was for.
    let inherited: Option<ModelFile> = match opts.common.init.as_deref().and_then(|w| w.parent()) {
        Some(dir) if dir.join(crate::models::folder::MODEL_FILE).exists() => {
            let file: ModelFile = crate::models::folder::read(dir, ID)?;
            tracing::info!(from = %dir.display(), "the rig and normalisation of the --init folder");
            Some(file)
        }
        _ => None,
    };
    let augment = Augment::checked(opts.min_tempo, opts.max_tempo, false)?;
    if !(0.0..=1.0).contains(&opts.style_dropout) {
        return Err(TrainError::InvalidOption(format!(
            "--style-dropout {}: want a share in 0..=1",
            opts.style_dropout
        )));
    }
    let ds = Dataset::open(&opts.common.data)?;
    // One skeleton for every dance, fitted on the train split: rotations are relative to its
    // rest pose, which must be the same for all.
    let train_dances = ds.load_all(ds.train_ids())?;
    let all_pos = concatenate(
        Axis(0),
        &train_dances
            .iter()
            .map(|d| d.motion.positions.view())
            .collect::<Vec<_>>(),
    )
    .map_err(|e| TrainError::Model(crate::models::ModelError::Shape(e.to_string())))?;
    let all_root = concatenate(
        Axis(0),
        &train_dances
            .iter()
            .map(|d| d.center.view())
            .collect::<Vec<_>>(),
    )
    .map_err(|e| TrainError::Model(crate::models::ModelError::Shape(e.to_string())))?;
    let rig = match &inherited {
        Some(file) => Rig::from_offsets(&file.extra.rig)?,
        None => Rig::fit(all_pos.view(), all_root.view())?,
    };
    drop((all_pos, all_root));
    let (train_raw, fit_err) = prepare(&train_dances, &rig)?;
    drop(train_dances);
    let (test_raw, test_fit_err) = prepare(&ds.load_all(ds.test_ids())?, &rig)?;
    tracing::info!(
        train_cm = 100.0 * fit_err,
        test_cm = 100.0 * test_fit_err,
        "rigid representation error (mean per joint, root-relative)"
    );
    let layout = rotations::Layout::of(&rig);
    let d = layout.dim();
    let (music_norm, pose_norm) = match &inherited {
        Some(file) => (file.music_norm.clone(), file.pose_norm.clone()),
        None => (
            NormStats::fit(train_raw.iter().map(|p| &p.music))?,
            NormStats::fit(
                train_raw
                    .iter()
                    .map(|p| p.frames.slice(ndarray::s![.., ..d]).to_owned())
                    .collect::<Vec<_>>()
                    .iter(),
            )?,
        ),
    };
    if pose_norm.dim() != d {
        return Err(TrainError::InvalidOption(format!(
            "--init: its folder's pose normalisation is {} wide, the rig's features {d}",
            pose_norm.dim()
        )));
    }
    let normalise = |seqs: &[Prepared]| -> Result<Vec<Sequence>, TrainError> {
        seqs.iter()
            .map(|p| {
                Ok(Sequence {
                    id: p.id.clone(),
                    music: music_norm.normalize(&p.music)?,
                    poses: normalised_rows(p.frames.view(), &pose_norm, d)?,
                    beat_hz: None,
                })
            })
            .collect()
    };
    let (train, test) = (normalise(&train_raw)?, normalise(&test_raw)?);
    let train_style: Vec<usize> = train_raw.iter().map(|p| p.style.index()).collect();
    let test_style: Vec<usize> = test_raw.iter().map(|p| p.style.index()).collect();
    let base = if opts.common.tiny {
        Config::tiny(d as i64)
    } else {
        Config::cpu(d as i64)
    };
    let config = Config {
        music_dim: music_norm.dim() as i64,
        mixtures: opts.mixtures.unwrap_or(base.mixtures),
        absolute_dims: opts
            .absolute_dims
            .unwrap_or(base.absolute_dims)
            .clamp(0, d as i64),
        music_direct: opts.music_direct,
        step_clock: opts.step_clock,
        ..base
    };
    let warmup = opts
        .warmup
        .unwrap_or(config.receptive_field() as usize)
        .min(opts.window.saturating_sub(2));
    let (mut trainer, model) = Trainer::new(&opts.common, ID, opts.lr, opts.seed, |p| {
        DanceNet::new(p, config.clone())
    })?;
    // Seed clips: normalised rows (features and contacts), long enough to fill the receptive field.
    let clip_frames = config.receptive_field() as usize + 1;
    let clips = SeedClips::draw(
        &train.iter().map(|s| &s.poses).collect::<Vec<_>>(),
        SEED_CLIPS,
        clip_frames,
        opts.seed,
    )?;
    clips.save(&trainer.out.join(SEED_CLIPS_FILE))?;
    // How often each style's windows repeat in an epoch.
    let mut style_frames = [0usize; 4];
    for p in &train_raw {
        style_frames[p.style.index()] += p.frames.nrows();
    }
    let most = *style_frames.iter().max().unwrap_or(&1) as f64;
    let repeats: Vec<usize> = style_frames
        .iter()
        .map(|&f| {
            if f == 0 || opts.style_balance <= 0.0 {
                1
            } else {
                ((most / f as f64).powf(opts.style_balance).round() as usize).clamp(1, 4)
            }
        })
        .collect();
    tracing::info!(
        ?style_frames,
        ?repeats,
        warmup,
        receptive_field = config.receptive_field(),
        "training set-up"
    );
    let len = opts.window;
    let schedule = |steps: usize| Schedule {
        window: len,
        stride: opts.stride,
        input_noise: opts.input_noise,
        input_coherence: opts.input_coherence,
        input_offset: opts.input_offset,
        input_walk: opts.input_walk,
        lambda_foot: opts.lambda_foot,
        warmup,
        style_balance: opts.style_balance,
        steps,
        rigid_fit_error_cm: 100.0 * fit_err,
        min_tempo: opts.min_tempo,
        max_tempo: opts.max_tempo,
        style_dropout: opts.style_dropout,
        lock_weight: opts.lock_weight,
    };
    let file_of = |t: &Trainer, steps: usize| ModelFile {
        config: config.clone(),
        music_norm: music_norm.clone(),
        pose_norm: pose_norm.clone(),
        fps: crate::motion::MOTION_FPS,
        training: t.record(opts.lr, opts.batch, opts.seed, schedule(steps)),
        extra: Serving {
            rig: rig.offset_arrays(),
            sampling: Sampling {
                temperature: opts.temperature,
                coherence: opts.coherence,
                music_guidance: crate::models::dancenet::MUSIC_GUIDANCE,
            },
            smooth_frames: opts.smooth_frames,
            beat_time: None,
            warm_up_frames: crate::models::dancenet::WARM_UP_FRAMES,
            opening_check: Some(crate::models::dancenet::OPENING_CHECK),
        },
    };
    let steps = std::cell::Cell::new(0usize);
    let dev = Device::Cpu;
    let pose_std = Tensor::from_slice(&pose_norm.std);
    trainer.run(
        0..opts.epochs,
        2,
        |epoch, opt, deadline| {
            let mut starts: Vec<(usize, usize)> = Vec::new();
            for w in window_starts(&train, len, opts.stride, opts.seed + epoch as u64) {
                for _ in 0..repeats[train_style[w.0]] {
                    starts.push(w);
                }
            }
            if starts.is_empty() {
                return Err(TrainError::NoWindows(len));
            }
            use rand::seq::SliceRandom;
            // The epoch's random streams, one per use, so a run without tempi or style dropout
            // draws what it drew before they existed.
            let epoch_rng = |salt: u64| StdRng::seed_from_u64(opts.seed ^ salt ^ (epoch as u64).wrapping_mul(0x9E37_79B9));
            let mut rng = epoch_rng(0);
            starts.shuffle(&mut rng);
            let mut tempo_rng = epoch_rng(0x7E_3B0);
            let mut style_rng = epoch_rng(0x57_11E);
            let (mut total, mut gmm_sum, mut foot_sum, mut spectral_sum, mut batches) = (0.0, 0.0, 0.0, 0.0, 0usize);
            let (mut lock_own, mut lock_real, mut lock_batches) = (0.0, 0.0, 0usize);
            for chunk in starts.chunks(opts.batch) {
                let (target, music) = if augment == Augment::NONE {
                    (batch_tensor(&train, chunk, len, |s| &s.poses, dev), batch_tensor(&train, chunk, len, |s| &s.music, dev))
                } else {
                    stretched_batch(&train_raw, chunk, len, &augment, &mut tempo_rng, &pose_norm, &music_norm, d)?
                };
                let style = model.style_one_hot(&chunk.iter().map(|&(i, _)| train_style[i]).collect::<Vec<_>>(), dev);
                let style = if opts.style_dropout > 0.0 {
                    let keep: Vec<f32> = chunk.iter().map(|_| if style_rng.gen_bool(opts.style_dropout) { 0.0 } else { 1.0 }).collect();
                    style * Tensor::from_slice(&keep).view([-1, 1, 1]).to_device(dev)
                } else {
                    style
                };
                let input = if opts.input_noise > 0.0 || opts.input_offset > 0.0 || opts.input_walk > 0.0 {
                    let (b, l) = (chunk.len() as i64, len as i64);
                    let noise = ar1_noise(b, l, d as i64, opts.input_coherence, dev) * opts.input_noise
                        + Tensor::randn([b, 1, d as i64], (Kind::Float, dev)) * opts.input_offset
                        + (Tensor::randn([b, l, d as i64], (Kind::Float, dev)) * opts.input_walk).cumsum(1, Kind::Float);
                    let zeros = Tensor::zeros([chunk.len() as i64, len as i64, config.contacts], (Kind::Float, dev));
                    &target + Tensor::cat(&[noise, zeros], 2)
                } else {
                    target.shallow_clone()
                };
                let clock = config
                    .step_clock
                    .then(|| phase::window_clock(&target, &music, &pose_norm, &music_norm, &layout));
                let l = model.losses(&input, &target, &music, clock.as_ref(), &style, warmup as i64);
                let mut loss = &l.gmm + opts.lambda_foot * &l.foot;
                // The rhythm and lock terms score one free run of the same windows.
                if opts.spectral_weight > 0.0 || opts.lock_weight > 0.0 {
                    let r = (opts.rollout_windows as i64).min(chunk.len() as i64);
                    let real = target.narrow(0, 0, r);
                    let window_music = music.narrow(0, 0, r);
                    let window_clock = clock.as_ref().map(|c| c.narrow(0, 0, r));
                    let code = model.code(&window_music, window_clock.as_ref());
                    let danced = model.free_run(&real, &code, &style.narrow(0, 0, r), warmup as i64, opts.temperature, opts.coherence);
                    if opts.spectral_weight > 0.0 {
                        let continuation = real.narrow(1, warmup as i64, len as i64 - warmup as i64);
                        let spectral = super::spectral::spectral_loss(&danced, &continuation, &pose_std, crate::motion::MOTION_FPS);
                        spectral_sum += spectral.double_value(&[]);
                        loss += spectral * opts.spectral_weight;
                    }
                    let styles: Vec<DanceStyle> = chunk[..r as usize].iter().map(|&(i, _)| train_raw[i].style).collect();
                    if opts.lock_weight > 0.0 {
                        if let Some(l) = lock::term(&danced, &real, &window_music, window_clock.as_ref(), &styles, warmup as i64, &pose_norm, &music_norm, &layout) {
                            lock_own += l.danced;
                            lock_real += l.real;
                            lock_batches += 1;
                            loss += l.loss * opts.lock_weight;
                        }
                    }
                }
                opt.backward_step_clip(&loss, 1.0);
                total += loss.double_value(&[]);
                gmm_sum += l.gmm.double_value(&[]);
                foot_sum += l.foot.double_value(&[]);
                batches += 1;
                steps.set(steps.get() + 1);
                if deadline.expired() {
                    break;
                }
            }
            let test_loss = tch::no_grad(|| {
                let starts = window_starts(&test, len, len, 0);
                let losses: Vec<(f64, f64, f64)> = starts
                    .chunks(opts.batch)
                    .map(|c| {
                        let t = batch_tensor(&test, c, len, |s| &s.poses, dev);
                        let m = batch_tensor(&test, c, len, |s| &s.music, dev);
                        let s = model.style_one_hot(&c.iter().map(|&(i, _)| test_style[i]).collect::<Vec<_>>(), dev);
                        let clock = config
                            .step_clock
                            .then(|| phase::window_clock(&t, &m, &pose_norm, &music_norm, &layout));
                        let l = model.losses(&t, &t, &m, clock.as_ref(), &s, warmup as i64);
                        // How much the decoder listens to the clock: the same windows with it a
                        // quarter of a step late.
                        let late = clock.as_ref().map_or(f64::NAN, |k| {
                            model.losses(&t, &t, &m, Some(&super::step_lock::quarter_turn(k)), &s, warmup as i64).gmm.double_value(&[])
                        });
                        (l.gmm.double_value(&[]), l.foot.double_value(&[]), late)
                    })
                    .collect();
                (!losses.is_empty()).then(|| {
                    let n = losses.len() as f64;
                    (
                        losses.iter().map(|l| l.0).sum::<f64>() / n,
                        losses.iter().map(|l| l.1).sum::<f64>() / n,
                        losses.iter().map(|l| l.2).sum::<f64>() / n,
                    )
                })
            });
            let b = batches.max(1) as f64;
            Ok(EpochResult {
                train_loss: total / b,
                test_loss: test_loss.map(|(g, f, _)| g + opts.lambda_foot * f),
                note: format!(
                    "steps={} tempo={}..{} style_dropout={} gmm={:.4} foot={:.4} spectral={:.4} (weight {}) lock danced={:.4} real={:.4} (weight {}) test_gmm={} test_foot={} test_gmm_clock_late={} (nats per dimension; BCE; the clock a quarter step late; spectral L1 per bin; lock: toes' speed projected on the style's fraction of the beats, free-running windows / the real continuation)",
                    steps.get(),
                    opts.min_tempo,
                    opts.max_tempo,
                    opts.style_dropout,
                    gmm_sum / b,
                    foot_sum / b,
                    spectral_sum / b,
                    opts.spectral_weight,
                    lock_own / lock_batches.max(1) as f64,
                    lock_real / lock_batches.max(1) as f64,
                    opts.lock_weight,
                    test_loss.map_or("-".into(), |t| format!("{:.4}", t.0)),
                    test_loss.map_or("-".into(), |t| format!("{:.4}", t.1)),
                    test_loss.map_or("-".into(), |t| format!("{:.4}", t.2))
                ),
            })
        },
        |t| file_of(t, steps.get()),
    )?;
    Ok(trainer.logs)
}

/// Rotation-feature rows as the network reads them: the first `d` columns (the features)
/// normalised, the contacts after them as they are.
fn normalised_rows(
    rows: ArrayView2<'_, f32>,
    pose_norm: &NormStats,
    d: usize,
) -> Result<Array2<f32>, TrainError> {
    let feats = pose_norm.normalize(&rows.slice(ndarray::s![.., ..d]).to_owned())?;
    concatenate(Axis(1), &[feats.view(), rows.slice(ndarray::s![.., d..])])
        .map_err(|e| TrainError::Model(crate::models::ModelError::Shape(e.to_string())))
}

/// A batch of windows each drawn at its own tempo factor (`augment`): the raw rows and music of
/// `dances` resampled together from each window's start, then normalised as the network reads
/// them. A window too near its dance's end for a factor plays at the fastest factor that fits.
/// Returns (poses `[b, len, D + contacts]`, music `[b, len, music]`).
#[allow(clippy::too_many_arguments)]
fn stretched_batch(
    dances: &[Prepared],
    chunk: &[(usize, usize)],
    len: usize,
    augment: &Augment,
    rng: &mut StdRng,
    pose_norm: &NormStats,
    music_norm: &NormStats,
    d: usize,
) -> Result<(Tensor, Tensor), TrainError> {
    let layout = MusicLayout::dancenet();
    let (mut poses, mut music) = (Vec::new(), Vec::new());
    for &(i, start) in chunk {
        let p = &dances[i];
        let (f, _) = augment.draw(rng);
        let room =
            (p.frames.nrows().min(p.music.nrows()) - 1 - start) as f64 / (len - 1).max(1) as f64;
        let f = f.min(room);
        let rows = stretch_rotation_rows(p.frames.view(), start, len, f);
        poses.push(to_tensor(&normalised_rows(rows.view(), pose_norm, d)?));
        music.push(to_tensor(&music_norm.normalize(&stretch_music(
            p.music.view(),
            start,
            len,
            f,
            &layout,
        ))?));
    }
    Ok((Tensor::stack(&poses, 0), Tensor::stack(&music, 0)))
}

/// Standard-normal noise `[b, l, d]` correlated along the frames as an AR(1) process with
/// coefficient `rho` (each frame's marginal stays N(0, 1)).
fn ar1_noise(b: i64, l: i64, d: i64, rho: f64, dev: Device) -> Tensor {
    let rho = rho.clamp(0.0, 0.999);
    let fresh = Tensor::randn([b, l, d], (Kind::Float, dev));
    if rho == 0.0 {
        return fresh;
    }
    let scale = (1.0 - rho * rho).sqrt();
    let mut z = fresh.select(1, 0);
    let mut frames = vec![z.shallow_clone()];
    for t in 1..l {
        z = &z * rho + fresh.select(1, t) * scale;
        frames.push(z.shallow_clone());
    }
    Tensor::stack(&frames, 1)
}
