//! `choreo train tsmt`: cross-entropy over the discretised poses of every step of a window in
//! parallel (paper §3.3), Adam, on the train split of dance-with-melody. Writes the bins (fitted
//! on the train split) into `model.json` and a few real seed clips beside the weights.
use ndarray::{s, Array2, ArrayView2};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use tch::{Device, Tensor};

use super::augment::Augment;
use super::{
    batch_tensor, window_starts, CommonOptions, Data, EpochLog, EpochResult, Sequence, Tempo,
    TrainError,
};
use super::{Trainer, Windows};
use crate::models::folder::{SeedClips, SEED_CLIPS_FILE};
use crate::models::stretch::MusicLayout;
use crate::models::tsmt::{
    Bins, Config, ModelFile, Sampling, Schedule, Serving, StallGuard, Tsmt, ID, MAX_POSITION,
};
use crate::motion::repr;

mod free;
mod free_run;
mod lock;
mod self_condition;
mod warp;

use free::FREE_CONTEXT;
use self_condition::{runs_mask, self_conditioned};

/// Options of one training run (the card gives the run behind the committed weights).
#[derive(Clone, Debug)]
pub struct Options {
    pub common: CommonOptions,
    pub epochs: usize,
    pub batch: usize,
    /// Stride between window starts, in frames (the window is the configuration's context).
    pub stride: usize,
    pub lr: f64,
    /// Standard deviation, in bins, of Gaussian noise added to the pose stream's input tokens
    /// (the targets stay clean), so that the model learns to come back from its own draws.
    pub input_noise_bins: f64,
    /// Default sampling temperature written into `model.json`.
    pub temperature: f64,
    /// Default top-k written into `model.json` (0: every bin).
    pub top_k: usize,
    /// Share of each window's predicted frames scored per step (drawn afresh every batch):
    /// the 300-bin read-out is most of a step's cost, so scoring a quarter of the frames gives
    /// about three times the steps for the same minutes.
    pub loss_frames: f64,
    /// Windows whose last second's mean root-relative joint speed is below this (m/s) are not
    /// trained on (the dancer comes to a stand, mostly a dance's closing hold). 0 keeps all (the
    /// served weights; 0.15 was tried, see the model card).
    pub min_window_speed: f64,
    /// De-quantisation σ (frames) written into `model.json` (see `tsmt::Serving`).
    pub smooth_frames: f64,
    /// De-quantisation σ (frames) of the height column (see `tsmt::Serving`).
    pub smooth_height_frames: f64,
    /// The stall guard's reach (m) written into `model.json` (0: no guard; `tsmt::StallGuard`,
    /// over 2 s, temperature × 1.5).
    pub stall_reach: f64,
    /// The stall guard's reopen reach (m) written into `model.json` (0: never;
    /// `tsmt::StallGuard::reopen_reach_m`).
    pub reopen_reach: f64,
    /// The step clock's gain as served, written into `model.json` (`tsmt::Serving::clock_gain`);
    /// training hears the clock at 1.
    pub clock_gain: f64,
    /// The served clock's step rate, written into `model.json` (`tsmt::Serving::clock_step_hz`;
    /// none: the metre's fraction).
    pub clock_step_hz: Option<f64>,
    /// The served clock's band once a bar, written into `model.json`
    /// (`tsmt::Serving::clock_bar_hz`).
    pub clock_bar_hz: Option<Vec<f64>>,
    pub seed: u64,
    /// Train in beat time (`models::beat_time`): every dance re-timed to the split's median
    /// tempo (after the bins are fitted on the dances as danced); the model then serves so.
    pub beat_time: bool,
    /// Windows at tempo factors in `[min_tempo, max_tempo]` and mirrored (`train::augment`):
    /// one figure heard at many tempi. The bins stay those fitted on the dances as danced.
    pub min_tempo: f64,
    pub max_tempo: f64,
    pub mirror: bool,
    /// Self-conditioning (against the freeze): share of each window's input frames replaced
    /// by the model's own draws, in runs of `self_run` frames between runs of the dance, as
    /// Zhou et al.'s auto-conditioned LSTM (ICLR 2018) does against motion that freezes on long
    /// generation; made parallel for a transformer as in Duckworth et al. (2019): `self_passes`
    /// teacher-forced passes without gradient, each drawing every frame from the last pass's
    /// mixed input. 0: off (the served weights).
    pub self_condition: f64,
    pub self_run: usize,
    pub self_passes: usize,
    /// The step clock (`tsmt::Config::step_clock`): each window's clock is the real dancer's own
    /// step over the [`lock::CLOCK_CONTEXT`] frames up to its end.
    pub step_clock: bool,
    /// Weight of the lock term (`train::tsmt::lock`; with `step_clock`). 0: off.
    pub lock_weight: f64,
    /// Warped histories (`train::tsmt::warp`; with `step_clock`): each window's first
    /// [`HISTORY_FRAMES`] frames replayed at a pace drawn log-uniformly in `[1/R, R]`, and only
    /// the frames after them scored. 0 (or 1): off.
    pub history_warp: f64,
    /// The lock term raises the score itself rather than its shortfall against the real
    /// continuation's (`train::tsmt::lock::term`).
    pub lock_uncapped: bool,
    /// Free runs (`tsmt::free_run`, `free::runs`; with `step_clock`): the first
    /// `free_runs` windows of each batch are also danced by the network from
    /// [`FREE_CONTEXT`] real frames on, `free_frames` frames as served; their lock term
    /// weighs `free_weight`, their body term (`free::Body`) `free_body`. 0: off.
    pub free_runs: usize,
    pub free_frames: usize,
    pub free_weight: f64,
    pub free_body: f64,
    /// The body term's pace ceiling, a multiple of the real continuation's (0: none).
    pub free_pace_max: f64,
    /// Do not train: redraw the seed clips (the same clips for the same `seed`) with each one's
    /// source and its song's beats (`seed_clips.json`) into the output folder.
    pub clips_only: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            common: CommonOptions::default(),
            epochs: 200,
            batch: 32,
            stride: 20,
            lr: 1e-3,
            input_noise_bins: 2.0,
            temperature: 1.0,
            top_k: 20,
            loss_frames: 0.25,
            min_window_speed: 0.0,
            smooth_frames: 1.0,
            smooth_height_frames: 4.0,
            stall_reach: 0.22,
            reopen_reach: 0.1,
            clock_gain: 1.0,
            clock_step_hz: None,
            clock_bar_hz: None,
            seed: 2020,
            beat_time: false,
            min_tempo: 1.0,
            max_tempo: 1.0,
            mirror: false,
            self_condition: 0.0,
            self_run: 10,
            self_passes: 2,
            step_clock: false,
            lock_weight: 0.0,
            history_warp: 0.0,
            lock_uncapped: false,
            free_runs: 0,
            free_frames: 160,
            free_weight: 1.0,
            free_body: 0.0,
            free_pace_max: free::FASTEST,
            clips_only: false,
        }
    }
}

impl Options {
    /// The sampling written into `model.json`, which training's own draws use too.
    fn sampling(&self) -> Sampling {
        Sampling {
            temperature: self.temperature,
            top_k: self.top_k,
        }
    }
}

/// Frames of a window's history that `history_warp` replays at another pace (1.6 s at 25 fps:
/// half the served window, so the frames scored after it still see 40 frames of it).
const HISTORY_FRAMES: usize = 40;

/// Seed clips kept in the folder, and their length in frames.
const SEED_CLIPS: usize = 32;
const SEED_CLIP_FRAMES: usize = 50;

/// The seed clips ([`SEED_CLIPS`] of [`SEED_CLIP_FRAMES`] frames at `opts.seed`'s starts over
/// the train dances as danced) with each clip's source and its song under it
/// ([`crate::models::clip_choice::ClipInfo`]): every source dance's song is analysed
/// (`audio::analyze`) and its beats put on the clip's frames; the energy is the mean onset
/// strength (`audio::features::keypose`'s column, as the pose bank's) of the music under the clip.
fn seed_clips(data: &Data, opts: &Options) -> Result<SeedClips, TrainError> {
    use crate::models::clip_choice::{BankMeta, ClipInfo};
    let (clips, sources) = SeedClips::draw_with_sources(
        &data.train_raw.iter().map(|s| &s.poses).collect::<Vec<_>>(),
        SEED_CLIPS,
        SEED_CLIP_FRAMES,
        opts.seed,
    )?;
    let ds = crate::motion::dataset::Dataset::open(&opts.common.data)?;
    let mut infos = Vec::with_capacity(sources.len());
    for (k, &(i, start)) in sources.iter().enumerate() {
        let dance = ds.load(&data.train_raw[i].id)?;
        let audio = crate::audio::decode_path(&dance.audio_path)?;
        let analysis = crate::audio::analyze(&audio)?;
        let fps = dance.motion.fps;
        let first = dance.song_time_s(start);
        let onset = crate::audio::features::keypose(&audio, fps, first, SEED_CLIP_FRAMES)?;
        let energy = onset
            .column(crate::audio::features::KEYPOSE_DIM - 1)
            .iter()
            .map(|v| f64::from(*v))
            .sum::<f64>()
            / SEED_CLIP_FRAMES as f64;
        let info = ClipInfo::of_song(
            data.train_raw[i].id.clone(),
            start,
            dance.style,
            &analysis,
            first,
            fps,
            SEED_CLIP_FRAMES,
            energy,
        );
        tracing::info!(clip = k, dance = %dance.id, start, beats = info.beats.len(), bar = info.bar, energy, "seed clip");
        infos.push(info);
    }
    let meta = BankMeta {
        made_by: format!(
            "choreo train tsmt --clips-only --seed {}: {SEED_CLIPS} clips of {SEED_CLIP_FRAMES} frames at seeded starts, one per train dance in order (the clips training writes for the same seed); beats from audio::analyze of each dance's whole song, put on the clip's frames with Dance::song_time_s; energy = mean onset strength (audio::features::keypose column 14) of the music under the clip",
            opts.seed
        ),
        fps: crate::motion::MOTION_FPS,
        clips: infos,
    };
    Ok(clips.with_meta(meta)?)
}

/// Trains and writes the model folder; returns the per-epoch log.
pub fn train(opts: &Options) -> Result<Vec<EpochLog>, TrainError> {
    let clock_bar_hz = match opts.clock_bar_hz.as_deref() {
        None => None,
        Some(&[lo, hi]) if lo > 0.0 && hi > 2.0 * lo => Some([lo, hi]),
        // Under an octave wide, halving or doubling could not bring every tempo inside.
        Some(band) => {
            return Err(TrainError::InvalidOption(format!(
                "--clock-bar-hz {band:?}: want LOW,HIGH with 0 < LOW and HIGH over 2 × LOW"
            )))
        }
    };
    // The root height becomes the lowest foot's clearance over each dance's own floor.
    let tempo = if opts.beat_time {
        Tempo::Analysed
    } else {
        Tempo::Skipped
    };
    let mut data = Data::load(
        &opts.common.data,
        crate::audio::features::tsmt,
        tempo,
        |s| {
            let floor = repr::floor_of_features(s.poses.view());
            repr::height_to_clearance(&mut s.poses, floor);
            Ok(())
        },
    )?;
    if opts.clips_only {
        let out = opts.common.out_dir(ID);
        std::fs::create_dir_all(&out).map_err(|source| TrainError::Io {
            path: out.clone(),
            source,
        })?;
        seed_clips(&data, opts)?.save(&out.join(SEED_CLIPS_FILE))?;
        tracing::info!(clips = SEED_CLIPS, out = %out.display(), "seed clips redrawn");
        return Ok(Vec::new());
    }
    let base = if opts.common.tiny {
        Config::tiny()
    } else {
        Config::cpu()
    };
    let config = Config {
        music_dim: data.music_norm.dim() as i64,
        coords: data.pose_norm.dim() as i64,
        step_clock: opts.step_clock,
        ..base
    };
    if opts.lock_weight > 0.0 && !opts.step_clock {
        return Err(TrainError::InvalidOption(
            "--lock-weight needs --step-clock: the term scores the toes against the clock".into(),
        ));
    }
    let warping = opts.history_warp > 1.0;
    if warping && (!opts.step_clock || HISTORY_FRAMES + 2 > len_of(&config)) {
        return Err(TrainError::InvalidOption(format!(
            "--history-warp needs --step-clock and a window over {HISTORY_FRAMES} frames"
        )));
    }
    let free = opts.free_runs > 0;
    if free && (!opts.step_clock || FREE_CONTEXT + opts.free_frames > lock::CLOCK_CONTEXT) {
        return Err(TrainError::InvalidOption(format!(
            "--free-runs needs --step-clock and --free-frames of at most {}",
            lock::CLOCK_CONTEXT - FREE_CONTEXT
        )));
    }
    if opts.step_clock && opts.beat_time {
        return Err(TrainError::InvalidOption(
            "--step-clock with --beat-time: the clock reads the dances as danced".into(),
        ));
    }
    let bins = Bins::fit(
        data.train_raw.iter().map(|s| &s.poses),
        config.n_bins as usize,
    )?;
    let beat_time = if opts.beat_time {
        Some(data.retime(&MusicLayout::tsmt())?)
    } else {
        None
    };
    let tokens = |seqs: &[Sequence]| -> Vec<Array2<i64>> {
        seqs.iter().map(|s| bins.tokens(&s.poses)).collect()
    };
    let (train_tokens, test_tokens) = (tokens(&data.train_raw), tokens(&data.test_raw));
    let augment = Augment {
        min_tempo: opts.min_tempo,
        max_tempo: opts.max_tempo,
        mirror: opts.mirror,
    };
    // Dances already re-timed by `retime` in beat time: the windows draw only the augmentation.
    // With the step clock every window is drawn through them, with the clock's context before it.
    let windows = (augment != Augment::NONE || opts.step_clock)
        .then(|| Windows::new(&data, MusicLayout::tsmt(), augment));
    let len = len_of(&config);
    let drawn_len = if opts.step_clock {
        lock::CLOCK_CONTEXT.max(len)
    } else {
        len
    };
    let (mut trainer, model) = Trainer::new(&opts.common, ID, opts.lr, opts.seed, |p| {
        Tsmt::new(p, config.clone())
    })?;
    seed_clips(&data, opts)?.save(&trainer.out.join(SEED_CLIPS_FILE))?;
    // Windows where the dancer stands still (mostly the closing hold of a dance) are left out:
    // a held pose is an attractor for a sampled model, which once in it repeats it for minutes.
    let speeds: Vec<Vec<f32>> = data
        .train_raw
        .iter()
        .map(|s| local_speed(&s.poses, crate::motion::MOTION_FPS as f32))
        .collect();
    // Judged on the window's last second: a window that ends in a hold teaches "stay still".
    let tail = (crate::motion::MOTION_FPS as usize).min(len - 1);
    let moving = |&(i, f): &(usize, usize)| {
        speeds[i][f + len - tail..f + len].iter().sum::<f32>() / tail as f32
            >= opts.min_window_speed as f32
    };
    // An augmented window may span more source frames (the fastest tempo).
    let source_len = windows.as_ref().map_or(len, |w| w.source_len(drawn_len));
    let moving = |&(i, f): &(usize, usize)| moving(&(i, f + source_len - len));
    let all = window_starts(&data.train, source_len, opts.stride, 0).len();
    let kept = window_starts(&data.train, source_len, opts.stride, 0)
        .iter()
        .filter(|w| moving(w))
        .count();
    tracing::info!(
        all,
        kept,
        min_speed = opts.min_window_speed,
        "training windows where the dancer moves"
    );
    let mut steps = 0usize;
    let noise = Normal::new(0.0, opts.input_noise_bins.max(1e-9)).map_err(|e| {
        TrainError::Motion(crate::motion::MotionError::Invalid(format!(
            "--input-noise-bins: {e}"
        )))
    })?;
    // The test windows and, with the clock, their clocks: the same every epoch.
    let test_starts = window_starts(&data.test, len, config.window as usize, 0);
    let test_clocks: Vec<Option<Tensor>> = test_starts
        .chunks(opts.batch)
        .map(|c| opts.step_clock.then(|| test_clock(&data.test_raw, c, len)))
        .collect();
    let epochs = 0..opts.epochs;
    let (train, test) = (&data.train, &data.test);
    let file_of = |t: &Trainer, steps: usize| ModelFile {
        config: config.clone(),
        music_norm: data.music_norm.clone(),
        pose_norm: data.pose_norm.clone(),
        fps: crate::motion::MOTION_FPS,
        training: t.record(
            opts.lr,
            opts.batch,
            opts.seed,
            Schedule {
                window: config.window as usize,
                stride: opts.stride,
                input_noise_bins: opts.input_noise_bins,
                loss_frames: opts.loss_frames,
                min_window_speed: opts.min_window_speed,
                self_condition: opts.self_condition,
                self_run: opts.self_run,
                self_passes: opts.self_passes,
                lock_weight: opts.lock_weight,
                history_warp: opts.history_warp,
                free_runs: opts.free_runs,
                free_frames: if free { opts.free_frames } else { 0 },
                free_weight: if free { opts.free_weight } else { 0.0 },
                free_body: if free { opts.free_body } else { 0.0 },
                free_pace_max: if free { opts.free_pace_max } else { 0.0 },
                steps,
            },
        ),
        extra: Serving {
            bins: bins.clone(),
            sampling: opts.sampling(),
            smooth_frames: opts.smooth_frames,
            smooth_height_frames: opts.smooth_height_frames,
            stall_guard: (opts.stall_reach > 0.0).then_some(StallGuard {
                min_reach_m: opts.stall_reach as f32,
                window_frames: 50,
                boost: 1.5,
                reopen_reach_m: opts.reopen_reach as f32,
            }),
            beat_time,
            clock_gain: opts.clock_gain,
            clock_step_hz: opts.clock_step_hz,
            clock_bar_hz,
        },
    };
    let steps_cell = std::cell::Cell::new(0usize);
    trainer.run(
        epochs,
        2,
        |epoch, opt, deadline| {
            let starts: Vec<(usize, usize)> =
                window_starts(train, source_len, opts.stride, opts.seed + epoch as u64)
                    .into_iter()
                    .filter(|w| moving(w))
                    .collect();
            if starts.is_empty() {
                return Err(TrainError::NoWindows(len));
            }
            let mut rng =
                StdRng::seed_from_u64(opts.seed ^ (epoch as u64).wrapping_mul(0x9E37_79B9));
            let (mut total, mut batches) = (0.0, 0);
            let (mut lock_danced, mut lock_real, mut locked) = (0.0, 0.0, 0);
            let (mut free_danced, mut free_real, mut freed) = (0.0, 0.0, 0);
            let (mut free_pace, mut free_lift) = (0.0, 0.0);
            for chunk in starts.chunks(opts.batch) {
                let mut free_windows = Vec::new();
                let (target, music, clock) = match &windows {
                    None => (
                        token_batch(&train_tokens, chunk, len),
                        batch_tensor(train, chunk, len, |s| &s.music, Device::Cpu),
                        None,
                    ),
                    Some(w) => {
                        let (mut tokens, mut music, mut clocks) = (Vec::new(), Vec::new(), Vec::new());
                        for (j, &(i, f0)) in chunk.iter().enumerate() {
                            let (m, p) = w.raw_window(i, f0, drawn_len, &mut rng)?;
                            // The window is the drawn rows' last `len`, a free run their last
                            // `FREE_CONTEXT + free_frames`; the clock is fitted once over them all.
                            if opts.step_clock {
                                let k = lock::window_clock(p.view(), m.view(), drawn_len);
                                if j < opts.free_runs {
                                    let f = free::window(&p, &m, k.view(), opts.free_frames, &bins, &data)?;
                                    free_windows.push(f);
                                }
                                let k = k.slice(s![drawn_len - len.., ..]);
                                clocks.push(crate::models::to_tensor(&k.to_owned()));
                            }
                            let p = if warping {
                                let r = opts.history_warp.ln();
                                let r = rng.gen_range(-r..r).exp();
                                warp::warped(p.view(), len, HISTORY_FRAMES, r)
                            } else {
                                p.slice(s![drawn_len - len.., ..]).to_owned()
                            };
                            let m = m.slice(s![drawn_len - len.., ..]);
                            tokens.push(token_tensor(bins.tokens(&p).view()));
                            music.push(crate::models::to_tensor(
                                &data.music_norm.normalize(&m.to_owned())?,
                            ));
                        }
                        let clock = (!clocks.is_empty()).then(|| Tensor::stack(&clocks, 0));
                        (Tensor::stack(&tokens, 0), Tensor::stack(&music, 0), clock)
                    }
                };
                let input = if opts.input_noise_bins > 0.0 {
                    noised(&target, config.n_bins, &noise, &mut rng)
                } else {
                    target.shallow_clone()
                };
                let start = rng.gen_range(0..MAX_POSITION - len as i64);
                let own = (opts.self_condition > 0.0)
                    .then(|| runs_mask(chunk.len(), len, opts, &mut rng));
                let input = match &own {
                    Some(own) => {
                        self_conditioned(&model, &input, &music, clock.as_ref(), start, own, opts)
                    }
                    None => input,
                };
                let fused = model.fused(&input, &music, clock.as_ref(), start, true);
                // Predicted frames 1..=n are indices 0..n; with warped histories only those after
                // the history are scored (the history's own pace is not the clock's).
                let n = len - 1;
                let skip = if warping { HISTORY_FRAMES - 1 } else { 0 };
                let scored = (((n - skip) as f64 * opts.loss_frames).ceil() as usize).clamp(1, n - skip);
                let mut idx: Vec<i64> = rand::seq::index::sample(&mut rng, n - skip, scored)
                    .into_iter()
                    .map(|i| (i + skip) as i64)
                    .collect();
                idx.sort_unstable();
                let mut loss = model.loss_on_frames(&fused, &target, &Tensor::from_slice(&idx));
                if let (Some(k), true) = (&clock, opts.lock_weight > 0.0) {
                    let capped = !opts.lock_uncapped;
                    let batch = lock::Batch {
                        input: &input,
                        own: own.as_ref(),
                        target: &target,
                        clock: k,
                    };
                    let l = lock::term(&model, &fused, &batch, &bins, skip as i64, capped);
                    if let Some(l) = l {
                        loss += l.loss * opts.lock_weight;
                        lock_danced += l.danced;
                        lock_real += l.real;
                        locked += 1;
                    }
                }
                if !free_windows.is_empty() {
                    if let Some(f) = free::runs(&model, &free_windows, &mut rng, opts, &bins) {
                        loss += f.lock.loss * opts.free_weight;
                        if opts.free_body > 0.0 {
                            loss += f.body.loss * opts.free_body;
                        }
                        free_danced += f.lock.danced;
                        free_real += f.lock.real;
                        free_pace += f.body.pace;
                        free_lift += f.body.lift;
                        freed += 1;
                    }
                }
                opt.backward_step_clip(&loss, 1.0);
                total += loss.double_value(&[]);
                batches += 1;
                steps += 1;
                if deadline.expired() {
                    break;
                }
            }
            steps_cell.set(steps);
            // With the clock, the test loss also with every clock a quarter step late: how much
            // the network listens to it.
            let (test_loss, test_late) = tch::no_grad(|| {
                let (mut on, mut late) = (Vec::new(), Vec::new());
                for (i, (c, k)) in test_starts.chunks(opts.batch).zip(&test_clocks).enumerate() {
                    let t = token_batch(&test_tokens, c, len);
                    let m = batch_tensor(test, c, len, |s| &s.music, Device::Cpu);
                    let pos = (i as i64 * 997) % (MAX_POSITION - len as i64);
                    on.push(model.loss(&t, &m, k.as_ref(), pos, false).double_value(&[]));
                    if let Some(k) = &k {
                        let q = crate::models::train::step_lock::quarter_turn(k);
                        late.push(model.loss(&t, &m, Some(&q), pos, false).double_value(&[]));
                    }
                }
                let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
                (mean(&on), mean(&late))
            });
            let clock_note = match test_late {
                Some(late) => format!(
                    " test_clock_late={late:.4} lock_danced={:.3} lock_real={:.3} lock_weight={}",
                    lock_danced / locked.max(1) as f64,
                    lock_real / locked.max(1) as f64,
                    opts.lock_weight
                ),
                None => String::new(),
            };
            let free_note = if free {
                format!(
                    " free_runs={}x{} free_danced={:.3} free_real={:.3} free_weight={} free_pace={:.3} free_lift={:.4} free_body={} free_pace_max={}",
                    opts.free_runs,
                    opts.free_frames,
                    free_danced / freed.max(1) as f64,
                    free_real / freed.max(1) as f64,
                    opts.free_weight,
                    free_pace / freed.max(1) as f64,
                    free_lift / freed.max(1) as f64,
                    opts.free_body,
                    opts.free_pace_max
                )
            } else {
                String::new()
            };
            Ok(EpochResult {
                train_loss: total / batches.max(1) as f64,
                test_loss,
                note: format!(
                    "steps={steps} tempo={}..{} mirror={} self={}x{}/{}{clock_note}{free_note} history_warp={} lock_uncapped={} (cross-entropy, nats per coordinate)",
                    opts.min_tempo, opts.max_tempo, opts.mirror, opts.self_condition, opts.self_run,
                    opts.self_passes, opts.history_warp, opts.lock_uncapped
                ),
            })
        },
        |t| file_of(t, steps_cell.get()),
    )?;
    Ok(trainer.logs)
}

/// Mean speed (m/s) of the joints relative to the root, per frame (0 for the first), from
/// feature rows: root-relative joint coordinates in the facing frame, metres.
fn local_speed(poses: &Array2<f32>, fps: f32) -> Vec<f32> {
    let joints = repr::POSE_DIM / 3;
    let rows = poses.outer_iter();
    let moved = rows.clone().zip(rows.skip(1)).map(|(a, b)| {
        let sum: f32 = (0..joints)
            .map(|j| {
                (0..3)
                    .map(|c| (b[3 * j + c] - a[3 * j + c]).powi(2))
                    .sum::<f32>()
                    .sqrt()
            })
            .sum();
        sum / joints as f32 * fps
    });
    std::iter::once(0.0).chain(moved).collect()
}

/// Frames of a training window: the pose stream's context and the frame it predicts last.
fn len_of(config: &Config) -> usize {
    config.window as usize + 1
}

/// The clocks `[b, len, WIDTH]` of test windows `starts` (sequence, frame) of the raw test
/// split, each fitted over the [`lock::CLOCK_CONTEXT`] frames up to its end (fewer at a
/// dance's start), as in training.
fn test_clock(test_raw: &[Sequence], starts: &[(usize, usize)], len: usize) -> Tensor {
    let parts: Vec<Tensor> = starts
        .iter()
        .map(|&(i, f)| {
            let end = f + len;
            let from = end.saturating_sub(lock::CLOCK_CONTEXT.max(len));
            let (p, m) = (&test_raw[i].poses, &test_raw[i].music);
            crate::models::to_tensor(&lock::window_clock(
                p.slice(s![from..end, ..]),
                m.slice(s![from..end, ..]),
                len,
            ))
        })
        .collect();
    Tensor::stack(&parts, 0)
}

/// Token windows `[b, len, coords]` (int64).
fn token_batch(tokens: &[Array2<i64>], starts: &[(usize, usize)], len: usize) -> Tensor {
    let parts: Vec<Tensor> = starts
        .iter()
        .map(|&(i, f)| token_tensor(tokens[i].slice(s![f..f + len, ..])))
        .collect();
    Tensor::stack(&parts, 0)
}

/// One token window `[len, coords]` (int64).
fn token_tensor(m: ArrayView2<'_, i64>) -> Tensor {
    let (r, c) = m.dim();
    Tensor::from_slice(&m.iter().copied().collect::<Vec<i64>>()).view([r as i64, c as i64])
}

/// `tokens` with rounded Gaussian noise on every token, clamped to the bins.
fn noised(tokens: &Tensor, n_bins: i64, noise: &Normal<f64>, rng: &mut StdRng) -> Tensor {
    let v: Vec<i64> = Vec::<i64>::try_from(tokens.flatten(0, -1))
        .expect("int64 tokens")
        .into_iter()
        .map(|b| (b + noise.sample(rng).round() as i64).clamp(0, n_bins - 1))
        .collect();
    Tensor::from_slice(&v).view(tokens.size().as_slice())
}
