//! TSMT as served: the song's features, the opening (the request's seed motion or a real clip),
//! the audio stream over the whole song, then the poses sampled frame by frame and rebuilt into
//! joint positions.
use std::ops::Range;
use std::path::Path;

use ndarray::{s, Array2};
use serde::{Deserialize, Serialize};

use super::opening::{
    frozen_from, holds_from, PoseReader, FREEZE_FRAMES, OPENING_CHECK_FRAMES, OPENING_HOLD_FRAMES,
    REACH_STRIDE,
};
use super::sampling::Draw;
use super::{Bins, Config, Sampling, StallGuard, Tsmt, ID};
use crate::models::beat_time;
use crate::models::encoded::EncoderMemo;
use crate::models::folder::{self, SeedClips, SEED_CLIPS_FILE};
use crate::models::step_clock;
use crate::models::stretch::MusicLayout;
use crate::models::{
    smooth_columns, to_tensor, Cancelled, Capabilities, DanceModel, GenerateRequest, Generated,
    InstancePool, ModelError, ModelId, ModelInfo, Progress,
};
use crate::motion::repr::{self, RootStart, FEATURE_DIM};
use crate::stage::Stage;

/// The run behind the committed weights, beside the common record.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Schedule {
    pub window: usize,
    pub stride: usize,
    /// Standard deviation (bins) of the noise added to the pose stream's input tokens.
    pub input_noise_bins: f64,
    /// Share of each window's frames scored per step (1: all; see `train::tsmt::Options`).
    #[serde(default = "one")]
    pub loss_frames: f64,
    /// Windows whose last second was slower than this (m/s, root-relative joints) were left out
    /// (0: none).
    #[serde(default)]
    pub min_window_speed: f64,
    /// Share of input frames replaced by the model's own draws, their run length and passes
    /// (`train::tsmt::Options::self_condition`; 0: off).
    #[serde(default)]
    pub self_condition: f64,
    #[serde(default)]
    pub self_run: usize,
    #[serde(default)]
    pub self_passes: usize,
    /// Weight of the step clock's lock term (`train::tsmt::Options::lock_weight`; 0: off).
    #[serde(default)]
    pub lock_weight: f64,
    /// Warped histories' pace range (`train::tsmt::Options::history_warp`; 0: off).
    #[serde(default)]
    pub history_warp: f64,
    /// Free runs per batch, their frames and their term's weight
    /// (`train::tsmt::Options::free_runs`; 0: off).
    #[serde(default)]
    pub free_runs: usize,
    #[serde(default)]
    pub free_frames: usize,
    #[serde(default)]
    pub free_weight: f64,
    /// Weight of the free runs' body term (`train::tsmt::Options::free_body`; 0: off).
    #[serde(default)]
    pub free_body: f64,
    /// The body term's pace ceiling (`train::tsmt::Options::free_pace_max`; 0: none).
    #[serde(default)]
    pub free_pace_max: f64,
    pub steps: usize,
}

fn one() -> f64 {
    1.0
}

/// `model.json`'s own fields: the bins, the default sampling and the de-quantisation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Serving {
    pub bins: Bins,
    /// Used where a job gives no `temperature` / `top_k`.
    pub sampling: Sampling,
    /// σ, in frames, of the Gaussian that smooths the sampled bin centres over time before the
    /// motion is rebuilt (0: none). Each coordinate is drawn on its own, so a joint's three
    /// coordinates jitter by a bin or two from frame to frame; at 25 fps one 4-mm bin of jitter
    /// is already ~2.5 m/s² of acceleration, and the model card measures what is left.
    #[serde(default)]
    pub smooth_frames: f64,
    /// σ, in frames, of a second Gaussian over the root height once it is rebuilt from the
    /// clearance (0: none). The height is the clearance minus the lowest foot point's local
    /// height, and which point is lowest hops between feet and heel/toe as each coordinate is
    /// drawn on its own: the whole body then rises or drops by up to 0.2 m in a frame (4–6 m/s).
    #[serde(default)]
    pub smooth_height_frames: f64,
    /// The stall guard, if any ([`StallGuard`]).
    #[serde(default)]
    pub stall_guard: Option<StallGuard>,
    /// The network runs on a clock of beats at this tempo (`models::beat_time`); absent: in
    /// seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_time: Option<crate::models::beat_time::BeatTimeConfig>,
    /// The step clock's gain as served (not in the paper): the clock's columns
    /// are multiplied by it before both of its maps ([`super::StepClockIn`]). The maps are
    /// linear, so at the fusion this is the clock's learned part pushed g times as far from the
    /// clock-free one, as classifier-free guidance does. Trained at 1, the clock moves the
    /// network's own steps too little to lock them (the card); at the gain chosen on the train
    /// split they lock. 1: as trained; ignored without `config.step_clock`.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub clock_gain: f64,
    /// Where set, the served clock turns at the fraction of the song's beat (one of the training
    /// clock's, 1/6 to 2/3) whose step rate is nearest this (Hz), not at its metre's fraction
    /// (not in the paper). TSMT takes no style, and its own steps settle near
    /// the train split's pace, a waltz's 0.49 Hz (26 of its 37 dances are waltzes): it followed a clock
    /// there, and drifted off one at a cha-cha's 1 Hz (the card).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clock_step_hz: Option<f64>,
    /// Where set, the served clock turns once a bar, halved or doubled into this band of step
    /// rates (Hz; `step_clock::phase_per_bar`), before `clock_step_hz` is read: a clock that
    /// follows the song's tempo (tried: the tsmt card).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clock_bar_hz: Option<[f64; 2]>,
}

fn is_one(v: &f64) -> bool {
    *v == 1.0
}

/// `model.json`.
pub type ModelFile = folder::ModelFile<Config, Schedule, Serving>;

/// A trained TSMT, ready to serve.
pub struct Served {
    file: ModelFile,
    clips: Option<SeedClips>,
    pool: InstancePool<Tsmt>,
    /// The song's audio stream, kept for the next seeds ([`crate::models::encoded`]).
    encoded: EncoderMemo,
}

/// What one generation made: the feature rows (foot clearance as the height) and the root start.
pub struct Generation {
    pub features: Array2<f32>,
    pub start: RootStart,
}

impl Served {
    /// Loads `dir/model.json`, `dir/weights.safetensors` and `dir/seed_clips.safetensors`.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let (file, pool) =
            folder::load(dir, ID, |p, f: &ModelFile| Tsmt::new(p, f.config.clone()))?;
        let path = dir.join(SEED_CLIPS_FILE);
        let clips = if path.exists() {
            Some(SeedClips::load(&path, FEATURE_DIM)?)
        } else {
            None
        };
        Ok(Self {
            file,
            clips,
            pool,
            encoded: EncoderMemo::default(),
        })
    }

    /// The model's description file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// The real clips the dance may continue from when the job brings no seed motion (context
    /// only, not danced), the seed's draw first. With the clips' [`folder::SEED_CLIPS_META_FILE`]
    /// the song chooses the clips the seed draws among (`clip_choice`: the clip's own beat period
    /// against the song's, and the meter), each replayed at the song's pace, so the network starts
    /// from a real dance stepping at this song's tempo: the context decides how TSMT opens (the
    /// same seed and draws continued from four other clips opened the 5-s trumpet loop 0.15–0.31
    /// m away from where the seed's own clip took it), and a draw by the seed alone opened every
    /// song alike. The other good candidates follow, best first, for an opening that freezes.
    /// Without the description, or without two beats in the song, the seed alone draws one.
    fn opening_clips(
        clips: &SeedClips,
        req: &GenerateRequest<'_>,
        clock: &beat_time::BeatTime,
        fps: f64,
    ) -> Result<Vec<Array2<f32>>, ModelError> {
        if clips.meta.is_none() {
            return Ok(vec![clips.pick(req.seed)]);
        }
        let analysis = req.analysis_or_analyze()?;
        // The song's beat period on the network's clock (network frame j is song frame j·factor).
        let chosen = crate::models::clip_choice::song_pace(&analysis, fps)
            .map(|(period, bar)| clips.chosen(req.seed, period / clock.factor, bar))
            .unwrap_or_default();
        if chosen.is_empty() {
            return Ok(vec![clips.pick(req.seed)]);
        }
        Ok(chosen
            .into_iter()
            .map(|(c, rate)| {
                let clip = clips.clips.slice(s![c, .., ..]);
                let len = ((clip.nrows() - 1) as f64 / rate).floor() as usize + 1;
                crate::models::stretch::stretch_poses(clip, 0, len, rate)
            })
            .collect())
    }

    /// Reads tokens drawn on the network's `clock` as served ([`PoseReader`]).
    fn pose_reader(&self, clock: &beat_time::BeatTime) -> PoseReader<'_> {
        let x = &self.file.extra;
        PoseReader {
            bins: &x.bins,
            sigma: x.smooth_frames / clock.factor,
            sigma_height: x.smooth_height_frames / clock.factor,
            fps: self.file.fps / clock.factor,
        }
    }

    /// Generates `clock.net_frames` frames of features (clearance heights) for `audio` on the
    /// network's clock. The context is the seed motion's features (which then open the dance),
    /// else a drawn clip (context only).
    pub fn generate_features(
        &self,
        req: &GenerateRequest<'_>,
        clock: &beat_time::BeatTime,
        progress: &mut dyn Progress,
    ) -> Result<Generation, ModelError> {
        let n = clock.net_frames;
        let fps = self.file.fps;
        let bins = &self.file.extra.bins;
        let sampling = Sampling {
            temperature: req
                .temperature
                .unwrap_or(self.file.extra.sampling.temperature),
            top_k: req
                .top_k
                .map(|k| k as usize)
                .unwrap_or(self.file.extra.sampling.top_k),
        };
        progress.report(Stage::Features, 0.0)?;
        let song = req.audio.features(
            crate::audio::features::FeatureSet::Tsmt,
            fps,
            0.0,
            clock.song_frames,
        )?;
        let feats = clock.music(song.view(), &MusicLayout::tsmt());
        let music = to_tensor(&self.file.music_norm.normalize(&feats)?).unsqueeze(0);
        // The step clock's phase on every network frame (`models::step_clock`): the song's beats
        // at the fraction of its metre's steps.
        let song_phase = if self.file.config.step_clock {
            let is_beat: Vec<bool> = feats
                .column(crate::audio::features::TSMT_BEAT)
                .iter()
                .map(|&v| v > 0.5)
                .collect();
            let bar = crate::models::clip_choice::bar_of(&*req.analysis_or_analyze()?);
            // On the network's clock a frame lasts `factor` song frames.
            match (self.file.extra.clock_bar_hz, self.file.extra.clock_step_hz) {
                (Some(band), _) => {
                    step_clock::phase_per_bar(&is_beat, bar, band, fps / clock.factor)
                }
                (None, Some(hz)) => step_clock::phase_near(&is_beat, hz, fps / clock.factor),
                (None, None) => step_clock::phase_of_song(
                    &is_beat,
                    step_clock::style_of_metre(bar),
                    fps / clock.factor,
                ),
            }
        } else {
            None
        };
        // The clock of `m` context frames read before song frame `s0` and the `rows` drawn from it.
        let clock_from = |m: usize, s0: usize, rows: usize| {
            song_phase.as_ref().map(|p| {
                let span = step_clock::phase_span(p, s0 as i64 - m as i64, m + rows);
                to_tensor(&step_clock::columns(&span)) * self.file.extra.clock_gain
            })
        };
        progress.report(Stage::Features, 1.0)?;
        // The opening: the request's seed motion (kept as the dance's first frames), or a real clip.
        let seed_motion = req.seed_motion.map(|m| clock.seed_motion(m));
        let (contexts, opening, start) = match seed_motion.as_ref() {
            Some(m) if m.num_frames() > 0 => {
                let keep = m.num_frames().min(n);
                let root = crate::motion::skeleton::body_centre_track(m.positions.view());
                let (mut f, start) = repr::to_features(m.positions.view(), root.view())?;
                let floor = repr::floor_of_features(f.view());
                repr::height_to_clearance(&mut f, floor);
                let f = f.slice(s![..keep, ..]).to_owned();
                (vec![bins.tokens(&f)], Some(f), start)
            }
            _ => {
                let Some(clips) = &self.clips else {
                    return Err(ModelError::BadModelFile(format!(
                        "{ID}: no seed motion and no {SEED_CLIPS_FILE}"
                    )));
                };
                let candidates = Self::opening_clips(clips, req, clock, fps)?;
                let tokens = candidates.iter().map(|c| bins.tokens(c)).collect();
                (tokens, None, RootStart::default())
            }
        };
        let opened = opening.as_ref().map_or(0, |o| o.nrows());
        let out = self.pool.with(|model| {
            tch::no_grad(|| -> Result<Option<Array2<f32>>, ModelError> {
                let mut cancelled = false;
                let song_clock = clock_from(0, 0, n);
                let Some(z) = self.encoded.get_or_encode(&[&music], || {
                    model.encode_song(&music, |f| {
                        cancelled = progress.report(Stage::Encode, f).is_err();
                        !cancelled
                    })
                }) else {
                    return Ok(None);
                };
                let vectors = model.logit_vectors_of(&z, song_clock.as_ref());
                let rest = vectors.narrow(0, opened as i64, (n - opened) as i64);
                let total = (n - opened).max(1);
                let widths: Vec<f32> = (0..repr::POSE_DIM)
                    .map(|c| (bins.hi[c] - bins.lo[c]) / bins.n as f32)
                    .collect();
                let guard = self
                    .file
                    .extra
                    .stall_guard
                    .as_ref()
                    .map(|g| (g, widths.as_slice()));
                // `rows` frames drawn from song frame `opened + from` on after the context `c`,
                // with the clock of exactly those frames.
                let draw = |c: &Array2<i64>,
                            from: usize,
                            rows: usize,
                            guard: Option<(&StallGuard, &[f32])>,
                            on_step: &mut dyn FnMut(usize) -> bool| {
                    let k = clock_from(c.nrows(), opened + from, rows);
                    let audio = rest.narrow(0, from as i64, rows as i64);
                    model.sample_guarded(c, &audio, k.as_ref(), sampling, guard, req.seed, on_step)
                };
                // The whole song's draw after the context `c`, nothing drawn yet.
                let whole = |c: &Array2<i64>| {
                    let k = clock_from(c.nrows(), opened, n - opened);
                    Draw::new(model, c, rest.shallow_clone(), k, sampling, guard, req.seed)
                };
                let reader = self.pose_reader(clock);
                let check = self.file.extra.stall_guard.as_ref().and_then(|g| {
                    (g.reopen_reach_m > 0.0 && contexts.len() > 1)
                        .then(|| (g.reopen_reach_m, OPENING_CHECK_FRAMES.min(n - opened)))
                });
                // A clip whose opening (the song's first 20 s, or all of a shorter song) holds
                // one pose for OPENING_HOLD_FRAMES (within the reach, or under
                // OPENING_SLOW_M_S), holds its arms (OPENING_MIN_ARMS_M_S) or bends its knees
                // backwards (OPENING_MAX_KNEE_BACKWARD), or on a song no longer than the window
                // moves slower than SHORT_SONG_MIN_SPEED_M_S, is passed over for the next candidate
                // ([`Self::opening_clips`]). When every candidate's opening is passed over, the
                // first that does not freeze (FREEZE_FRAMES) is kept, else the last. Each
                // opening is drawn REACH_STRIDE frames at a time and stops at the first hold the
                // reach sees; the one kept goes on from where it stopped, so the song is drawn as
                // one run would draw it.
                let mut opened_draws: Vec<Draw> = Vec::new();
                let mut kept = 0;
                if let (Some((reach, frames)), Some(guard)) = (check, guard) {
                    let window = guard.0.window_frames;
                    let holds = |d: &Draw, hold| {
                        holds_from(&d.tokens(), window, guard.1, reach, 0, hold).is_some()
                    };
                    let mut passed = None;
                    for c in &contexts {
                        let mut d = whole(c);
                        let mut held = false;
                        while d.done() < frames && !held {
                            let next = (d.done() + REACH_STRIDE).min(frames);
                            if d.run_to(next, |_| true).is_none() {
                                return Ok(None);
                            }
                            held = holds(&d, OPENING_HOLD_FRAMES);
                        }
                        // The poses are rebuilt for the measures only where the reach passed.
                        let lively = !held && {
                            let m = reader.opening_measures(&d.tokens())?;
                            tracing::debug!(?m, "tsmt: opening measured");
                            // A song no longer than the window is all opening.
                            !m.passed_over(frames == n - opened)
                        };
                        opened_draws.push(d);
                        if lively {
                            passed = Some(opened_draws.len() - 1);
                            break;
                        }
                    }
                    kept = match passed {
                        Some(i) => i,
                        None => {
                            let mut unfrozen = None;
                            for (i, d) in opened_draws.iter_mut().enumerate() {
                                if d.run_to(frames, |_| true).is_none() {
                                    return Ok(None);
                                }
                                if !holds(d, FREEZE_FRAMES) {
                                    unfrozen = Some(i);
                                    break;
                                }
                            }
                            unfrozen.unwrap_or(contexts.len() - 1)
                        }
                    };
                }
                tracing::debug!(kept, tried = opened_draws.len(), "tsmt: opening check");
                let mut song = if opened_draws.is_empty() {
                    whole(&contexts[kept])
                } else {
                    opened_draws.swap_remove(kept)
                };
                drop(opened_draws);
                let end = song.frames();
                let ran = song.run_to(end, |done| {
                    progress
                        .report(Stage::Generate, done as f32 / total as f32)
                        .is_ok()
                });
                if ran.is_none() {
                    return Ok(None);
                }
                let mut tokens = song.into_tokens();
                // A freeze or a hold (MIDSONG_HOLD_S) later in the song is drawn again from the
                // next candidate clip ([`redrawn_span`]): a hold from a second before it to
                // REJOIN_FRAMES after it, a freeze to the end of the song. Where the new frames
                // hold there too, the next candidate is tried from the same frame. The candidates
                // are taken in turn after the kept one, round again where the opening check used
                // them up (a clip read from another frame continues otherwise), at most one fewer
                // times than there are candidates: the cost of an opening check that passed
                // every one over.
                let mut values = bins.values(&tokens);
                if let (Some((reach, checked)), Some(guard)) = (check, guard) {
                    // The opening check has seen the first `checked` frames already.
                    let mut after = checked;
                    let turns = contexts.len() - 1;
                    tracing::debug!(turns, candidates = contexts.len(), "tsmt: mid-song check");
                    for c in contexts.iter().cycle().skip(kept + 1).take(turns) {
                        let frozen =
                            frozen_from(&tokens, guard.0.window_frames, guard.1, reach, after);
                        let held = reader.midsong_hold(&values, after)?;
                        let Some(span) = redrawn_span(frozen, held.clone(), after, tokens.nrows())
                        else {
                            break;
                        };
                        tracing::debug!(?frozen, ?held, ?span, "tsmt: drawn again");
                        let Some(again) =
                            draw(c, span.start, span.len(), Some(guard), &mut |_| true)
                        else {
                            return Ok(None);
                        };
                        join(&mut values, span.clone(), bins.values(&again));
                        tokens.slice_mut(s![span.clone(), ..]).assign(&again);
                        after = span.start;
                    }
                }
                Ok(Some(values))
            })
        })??;
        let Some(mut sampled) = out else {
            return Err(Cancelled.into());
        };
        // σ is a time in the song (what the jitter of drawn bins is smoothed over before 25-fps
        // playback), so on the network's clock it is σ / factor frames.
        smooth_columns(
            &mut sampled,
            0,
            self.file.extra.smooth_frames / clock.factor,
        );
        let features = match opening {
            Some(o) => ndarray::concatenate(ndarray::Axis(0), &[o.view(), sampled.view()])
                .map_err(|e| ModelError::Shape(e.to_string()))?,
            None => sampled,
        };
        Ok(Generation { features, start })
    }
}

/// Turns drawn `features`' clearance into the root's height, smoothed over `sigma` frames from
/// frame `keep` on. The root height follows the lowest foot point, which hops between feet and
/// points as their coordinates are drawn; smoothing the height itself (not the clearance) keeps
/// the body from jumping with it.
pub(super) fn heights_as_served(features: &mut Array2<f32>, keep: usize, sigma: f64) {
    repr::clearance_to_height(features);
    let mut h = features
        .column(repr::ROOT_Y)
        .to_owned()
        .insert_axis(ndarray::Axis(1));
    smooth_columns(&mut h, keep, sigma);
    features.column_mut(repr::ROOT_Y).assign(&h.column(0));
}

/// The frames drawn again after `after` for a freeze that starts at `frozen` or a `held` span
/// (whichever starts first; the freeze where they start together) in a dance of `frames` frames:
/// a freeze to the end (a frozen network stays frozen), a hold from JOIN_FRAMES before it, so
/// the join blends the new frames with the old one's last steps rather than with the hold, to
/// REJOIN_FRAMES after it, where the old dance moves again. Drawing the rest of the song again
/// for every hold cost 1.6–2.3× on a 3-minute song (the tsmt card).
pub(super) fn redrawn_span(
    frozen: Option<usize>,
    held: Option<Range<usize>>,
    after: usize,
    frames: usize,
) -> Option<Range<usize>> {
    let frozen = frozen.map(|f| f..frames);
    let held = held.map(|h| {
        h.start.saturating_sub(JOIN_FRAMES).max(after)..(h.end + REJOIN_FRAMES).min(frames)
    });
    match (frozen, held) {
        (Some(f), Some(h)) if h.start < f.start => Some(h),
        (Some(f), _) => Some(f),
        (None, h) => h,
    }
}

/// Writes `new` feature values over `span` of `values`, fading in from the old values over its
/// first JOIN_FRAMES (a turn of the body over a second, not a jump) and back into them over its
/// last JOIN_FRAMES where the old dance goes on after it.
pub(super) fn join(values: &mut Array2<f32>, span: Range<usize>, new: Array2<f32>) {
    let old = values.slice(s![span.clone(), ..]).to_owned();
    let rows = span.len();
    let fade = JOIN_FRAMES.min(rows);
    let goes_on = span.end < values.nrows() && rows >= 2 * JOIN_FRAMES;
    let mut part = values.slice_mut(s![span.clone(), ..]);
    part.assign(&new);
    // The new frames' weight: rising smoothly from 0 over the first JOIN_FRAMES, falling back
    // to 0 over the last where the old dance goes on.
    let smooth = |k: usize| {
        let x = (k + 1) as f32 / (JOIN_FRAMES + 1) as f32;
        x * x * (3.0 - 2.0 * x)
    };
    let weights = (0..fade).map(|k| (k, smooth(k))).chain(
        (0..JOIN_FRAMES)
            .filter(|_| goes_on)
            .map(|k| (rows - 1 - k, smooth(k))),
    );
    for (k, w) in weights {
        let mut row = part.row_mut(k);
        row *= w;
        row.scaled_add(1.0 - w, &old.row(k));
    }
}

/// A redrawn rest fades in over this many frames (1 s at 25 fps), and a redrawn hold back out.
const JOIN_FRAMES: usize = 25;

/// A hold is drawn again until this many frames after it ends (2 s at 25 fps): a second of new
/// steps where the old dance moves again, then a second's fade back into it.
const REJOIN_FRAMES: usize = 2 * JOIN_FRAMES;

impl DanceModel for Served {
    fn frame_flops(&self) -> Option<f64> {
        Some(self.file.config.frame_flops())
    }

    fn info(&self) -> ModelInfo {
        ModelInfo {
            id: ModelId(ID.into()),
            paper: "Li et al., Learning to Generate Diverse Dance Motions with Transformer, 2020 (two-stream motion transformer)".into(),
            capabilities: Capabilities { key_poses: false, seed_motion: true, style: false, temperature: true, top_k: true },
            beat_time: self.file.extra.beat_time,
        }
    }

    fn generate(
        &self,
        req: &GenerateRequest<'_>,
        progress: &mut dyn Progress,
    ) -> Result<Generated, ModelError> {
        self.refuse_unsupported(req)?;
        let song_frames =
            crate::motion::validate::song_frames(req.audio.duration_s(), self.file.fps);
        let clock = beat_time::BeatTime::for_request(self.file.extra.beat_time, req, song_frames)?;
        let n = clock.net_frames;
        let mut g = self.generate_features(req, &clock, progress)?;
        // The opening (a request's seed motion) is kept.
        let keep = req
            .seed_motion
            .map_or(0, |m| clock.seed_frames(m.num_frames()).min(n));
        heights_as_served(
            &mut g.features,
            keep,
            self.file.extra.smooth_height_frames / clock.factor,
        );
        let (motion, _root) = repr::from_features(g.features.view(), g.start, self.file.fps)?;
        Ok(Generated::from(clock.back(motion))
            .with_beat_time(clock.used(self.file.extra.beat_time)))
    }
}
