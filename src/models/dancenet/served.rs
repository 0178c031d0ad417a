//! DanceNet as served: the song's control signals, its style (asked for, or the classifier's
//! choice), the music code of the whole song, then the decoder sampled frame by frame from a real
//! seed clip (or the request's seed motion), and the rotations turned back into joint positions
//! on the model's rig.
use std::path::Path;

use ndarray::{concatenate, s, Array2, Axis};
use rand::rngs::StdRng;
use rand::SeedableRng;
use tch::{Kind, Tensor};

use super::style::ServedStyle;
use super::{DanceNet, ModelFile, Sampling, ID};
use crate::models::beat_time;
use crate::models::encoded::EncoderMemo;
use crate::models::folder::{self, SeedClips, SEED_CLIPS_FILE};
use crate::models::stretch::MusicLayout;
use crate::models::{
    smooth_columns, to_tensor, Cancelled, Capabilities, DanceModel, GenerateRequest, Generated,
    InstancePool, ModelError, ModelId, ModelInfo, Progress, StyleChoice,
};
use crate::motion::repr::RootStart;
use crate::motion::rig::Rig;
use crate::motion::rotations;
use crate::stage::Stage;

/// A trained DanceNet, ready to serve.
pub struct Served {
    file: ModelFile,
    rig: Rig,
    clips: SeedClips,
    style: Option<ServedStyle>,
    pool: InstancePool<DanceNet>,
    /// The song's code, kept for the next seeds ([`crate::models::encoded`]).
    encoded: EncoderMemo,
}

/// What one generation made, before it becomes joint positions.
pub struct Generation {
    /// Rotation features `[T, D]` (de-normalised). The contacts the decoder also predicts are
    /// dropped: the served foot planting finds contacts from foot height.
    pub features: Array2<f32>,
    pub start: RootStart,
    pub style: StyleChoice,
    /// What the opening check chose, where it ran.
    pub opening: Option<crate::models::opening_check::OpeningChosen>,
}

impl Served {
    /// Loads `dir/model.json`, the weights, the seed clips and (when present) the style classifier.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let (file, pool) = folder::load(dir, ID, |p, f: &ModelFile| {
            DanceNet::new(p, f.config.clone())
        })?;
        let rig = Rig::from_offsets(&file.extra.rig)?;
        let width = (file.config.pose_dim + file.config.contacts) as usize;
        if rotations::Layout::of(&rig).dim() != file.config.pose_dim as usize {
            return Err(ModelError::BadModelFile(format!(
                "{ID}: the rig's features are not {} wide",
                file.config.pose_dim
            )));
        }
        let clips = SeedClips::load(&dir.join(SEED_CLIPS_FILE), width)?;
        let style = if dir.join(super::style::STYLE_FILE).exists() {
            Some(ServedStyle::load(dir)?)
        } else {
            None
        };
        Ok(Self {
            file,
            rig,
            clips,
            style,
            pool,
            encoded: EncoderMemo::default(),
        })
    }

    /// The model's description file.
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// The style to dance: the request's, or the classifier's most likely one for the song.
    fn style_of(
        &self,
        req: &GenerateRequest<'_>,
        features: &Array2<f32>,
    ) -> Result<StyleChoice, ModelError> {
        if let Some(style) = req.style {
            return Ok(StyleChoice {
                style,
                predicted: false,
                probabilities: vec![],
            });
        }
        let classifier = self.style.as_ref().ok_or_else(|| {
            ModelError::MissingWeights(
                format!("{ID} style classifier"),
                super::style::STYLE_FILE.into(),
            )
        })?;
        let p = classifier.predict(features)?;
        Ok(StyleChoice {
            style: super::style::most_probable(&p),
            predicted: true,
            probabilities: p.to_vec(),
        })
    }

    /// Sampled rows (normalised features and contacts) as de-normalised rotation features, the
    /// contacts dropped, smoothed over time from row `from` on (the rows before it, a seed
    /// motion, stay as they came). σ of 2 frames (0.08 s, served) keeps 60 % of a 2-Hz movement
    /// and removes what is faster than 5 Hz; σ is a time in the song, so on the network's clock
    /// it is σ / factor frames.
    fn features_of(
        &self,
        rows: &Array2<f32>,
        from: usize,
        clock: &beat_time::BeatTime,
    ) -> Result<Array2<f32>, ModelError> {
        let d = self.file.config.pose_dim as usize;
        let mut features = self
            .file
            .pose_norm
            .denormalize(&rows.slice(s![.., ..d]).to_owned())?;
        smooth_columns(
            &mut features,
            from,
            self.file.extra.smooth_frames / clock.factor,
        );
        Ok(features)
    }

    /// Sampled rows as joint positions on the model's rig, on the network's clock, for the
    /// [`crate::models::opening_check::OpeningCheck`].
    fn motion_of(
        &self,
        rows: &Array2<f32>,
        clock: &beat_time::BeatTime,
    ) -> Result<crate::motion::Motion, ModelError> {
        let features = self.features_of(rows, 0, clock)?;
        Ok(rotations::decode(
            &self.rig,
            features.view(),
            RootStart::default(),
            self.file.fps,
        )?)
    }

    /// Generates `clock.net_frames` frames of rotation features for `req` on the network's clock.
    /// The context is the request's seed motion (which then opens the dance), else a real clip
    /// drawn by the seed (context only).
    pub fn generate_features(
        &self,
        req: &GenerateRequest<'_>,
        clock: &beat_time::BeatTime,
        progress: &mut dyn Progress,
    ) -> Result<Generation, ModelError> {
        let n = clock.net_frames;
        let fps = self.file.fps;
        let sampling = Sampling {
            temperature: req
                .temperature
                .unwrap_or(self.file.extra.sampling.temperature),
            ..self.file.extra.sampling
        };
        progress.report(Stage::Features, 0.0)?;
        let song = req.audio.features(
            crate::audio::features::FeatureSet::DanceNet,
            fps,
            0.0,
            clock.song_frames,
        )?;
        progress.report(Stage::Features, 1.0)?;
        // The style is the song's as it sounds; the network hears it on its own clock.
        let style = self.style_of(req, &song)?;
        let feats = clock.music(song.view(), &MusicLayout::dancenet());
        let music = to_tensor(&self.file.music_norm.normalize(&feats)?).unsqueeze(0);
        // The context (normalised features and contacts) and how many of its frames open the dance.
        let rf = self.file.config.receptive_field() as usize;
        let seed_motion = req.seed_motion.map(|m| clock.seed_motion(m));
        let (context, opening, start) = match seed_motion.as_ref() {
            Some(m) if m.num_frames() > 0 => {
                let keep = m.num_frames().min(n);
                let enc = rotations::encode(&self.rig, m.positions.slice(s![..keep, .., ..]), fps)?;
                let feats = self.file.pose_norm.normalize(&enc.features)?;
                let rows = concatenate(Axis(1), &[feats.view(), enc.contacts.view()])
                    .map_err(|e| ModelError::Shape(e.to_string()))?;
                (rows, keep, enc.start)
            }
            _ => (self.clips.pick(req.seed), 0, RootStart::default()),
        };
        let m = context.nrows();
        let rf_tail = m.min(rf + 1);
        let check = match opening {
            0 => self.file.extra.opening_check,
            _ => None,
        };
        let mut opened = None;
        let out = self.pool.with(|model| {
            tch::no_grad(|| -> Result<Option<Array2<f32>>, ModelError> {
                let mut cancelled = false;
                let Some(code) = self.encoded.get_or_encode(&[&music], || {
                    model.encoder.encode_song(&music, |f| {
                        cancelled = progress.report(Stage::Encode, f).is_err();
                        !cancelled
                    })
                }) else {
                    return Ok(None);
                };
                // The step clock of the song's beats (on the network's clock) at the style's
                // fraction.
                let steps = model.config.step_clock.then(|| {
                    let beats: Vec<bool> = feats
                        .column(crate::audio::features::DANCENET_BEAT)
                        .iter()
                        .map(|&v| v > 0.5)
                        .collect();
                    to_tensor(&super::step_clock::of_song(&beats, style.style, fps))
                });
                let code = model.with_clock(code, steps.as_ref());
                let draw = Draw {
                    model,
                    code: &code,
                    tail: rf_tail,
                    n,
                    opening,
                    warm: self.file.extra.warm_up_frames,
                    style: style.style.index(),
                    sampling,
                };
                // Which draw dances (`models::opening_check`): the seed's own, unless its
                // opening shuffles or flails and another of the check's draws does not.
                let mut seed = req.seed;
                if let Some(check) = check {
                    let window = check.window(clock);
                    let frames = window.net_frames.min(n);
                    let chosen =
                        check.choose(ID, req.seed, &window, |s| -> Result<_, ModelError> {
                            let ctx = self.clips.pick(s);
                            match draw.dance(&ctx, s, Some(frames), &mut |_| true) {
                                Some(rows) => Ok(Some(self.motion_of(&rows, clock)?)),
                                None => Ok(None),
                            }
                        })?;
                    let Some((chosen, seen)) = chosen else {
                        return Ok(None);
                    };
                    seed = chosen;
                    opened = Some(seen);
                }
                // The context already drawn is the seed's own (or the seed motion); another
                // draw brings its own clip.
                let redrawn = (seed != req.seed).then(|| self.clips.pick(seed));
                let ctx = redrawn.as_ref().unwrap_or(&context);
                let total = (n - opening).max(1);
                Ok(draw.dance(ctx, seed, None, &mut |done| {
                    progress
                        .report(Stage::Generate, done as f32 / total as f32)
                        .is_ok()
                }))
            })
        })??;
        let Some(sampled) = out else {
            return Err(Cancelled.into());
        };
        let rows = if opening > 0 {
            concatenate(Axis(0), &[context.view(), sampled.view()])
                .map_err(|e| ModelError::Shape(e.to_string()))?
        } else {
            sampled
        };
        let features = self.features_of(&rows, opening, clock)?;
        Ok(Generation {
            features,
            start,
            style,
            opening: opened,
        })
    }
}

/// One draw of the decoder for a song: what [`Served::generate_features`] samples, once for the
/// dance and once per draw the [`crate::models::opening_check::OpeningCheck`] tries.
struct Draw<'a> {
    model: &'a DanceNet,
    /// The music code of every song frame, `[n, d_code]`.
    code: &'a Tensor,
    /// Context rows the decoder sees (its receptive field and one).
    tail: usize,
    /// Frames of the song (the network's clock).
    n: usize,
    /// Frames of the request's seed motion that open the dance (0: a clip is context only).
    opening: usize,
    warm: usize,
    style: usize,
    sampling: Sampling,
}

impl Draw<'_> {
    /// Samples from `context` (normalised rows) with the stream of `seed`: the rows after the
    /// seed motion's `opening` frames, or, from a clip, the warm-up and then the song's frames;
    /// the first `limit` of them when given. `None` when `on_step` stops it.
    fn dance(
        &self,
        context: &Array2<f32>,
        seed: u64,
        limit: Option<usize>,
        on_step: &mut dyn FnMut(usize) -> bool,
    ) -> Option<Array2<f32>> {
        let (tail, n, opening) = (self.tail, self.n, self.opening);
        let m = context.nrows();
        let ctx = context.slice(s![m - tail.., ..]).to_owned();
        // Conditioning rows: a seed motion is danced over the song's opening, so its frames
        // have the song's code; a context from elsewhere (a clip from another dance, or
        // the warm-up's last frames) gets the opening's first code, then the song's follow.
        let all = n - opening;
        let whole = if opening > 0 {
            self.code
                .narrow(0, (opening - tail + 1) as i64, (all + tail - 1) as i64)
        } else {
            after_context(self.code, self.code.narrow(0, 0, all as i64), tail)
        };
        let made = limit.unwrap_or(all).min(all);
        let rows = whole.narrow(0, 0, (made + tail - 1) as i64);
        // Music guidance guides against the whole dance's average even when only its first
        // `limit` frames are drawn, so the opening check judges the opening the dance dances.
        let average = whole.mean_dim(0, true, Kind::Float); // [1, d_code]
        let mut rng = StdRng::seed_from_u64(seed ^ 0xDA_2CE_2E7);
        // The warm-up (not in the paper): from a drawn clip, the network first dances
        // `warm` frames over the song's own music (from its start, cycled when the
        // song is shorter) and the dance continues from how it ended, so its opening
        // is the network's answer to this song rather than the seed's and the style's.
        // At least the context's length, so its last `tail` frames are all danced.
        let warm = match self.warm {
            0 => 0,
            w => w.max(tail),
        };
        let ctx = if opening == 0 && warm > 0 {
            let idx: Vec<i64> = (0..warm).map(|t| (t % n) as i64).collect();
            let idx = Tensor::from_slice(&idx).to_device(self.code.device());
            let warm_rows = after_context(self.code, self.code.index_select(0, &idx), tail);
            // The warm-up is guided against its own rows' average.
            let warm_average =
                self.guided_against(&warm_rows.mean_dim(0, true, Kind::Float), &warm_rows);
            let danced = self.model.sample(
                &ctx,
                &warm_rows,
                Some(&warm_average),
                self.style,
                self.sampling,
                &mut rng,
                |_| on_step(0),
            )?;
            danced.slice(s![warm - tail.., ..]).to_owned()
        } else {
            ctx
        };
        self.model.sample(
            &ctx,
            &rows,
            Some(&self.guided_against(&average, &rows)),
            self.style,
            self.sampling,
            &mut rng,
            on_step,
        )
    }
}

impl Draw<'_> {
    /// What music guidance's second branch hears beside `rows`: the `average` code, with each
    /// row's own step clock where the model has one. The clock is the song's time, not its
    /// sound: amplified it would turn three times as hard as anything the decoder was trained on.
    fn guided_against(&self, average: &Tensor, rows: &Tensor) -> Tensor {
        if !self.model.config.step_clock {
            return average.shallow_clone();
        }
        let (n, width) = (rows.size()[0], rows.size()[1]);
        let w = super::step_clock::WIDTH;
        Tensor::cat(
            &[
                average
                    .narrow(1, 0, width - w)
                    .expand([n, width - w], false),
                rows.narrow(1, width - w, w),
            ],
            1,
        )
    }
}

/// Conditioning after a context of `tail` frames from elsewhere (a clip from another dance, or
/// the warm-up's last frames): the context's frames after its first get the song's first code,
/// then `rows` follow.
fn after_context(code: &Tensor, rows: Tensor, tail: usize) -> Tensor {
    Tensor::cat(
        &[code.narrow(0, 0, 1).repeat([(tail - 1) as i64, 1]), rows],
        0,
    )
}

impl DanceModel for Served {
    fn frame_flops(&self) -> Option<f64> {
        let branches = self.file.extra.sampling.branches() as f64;
        Some(self.file.config.frame_flops(branches))
    }

    fn info(&self) -> ModelInfo {
        ModelInfo {
            id: ModelId(ID.into()),
            paper: "Zhuang et al., Music2Dance: DanceNet for Music-driven Dance Generation, 2020 (dilated gated convolutions, mixture output, style control)".into(),
            capabilities: Capabilities { key_poses: false, seed_motion: true, style: true, temperature: true, top_k: false },
            beat_time: self.file.extra.beat_time,
        }
    }

    fn generate(
        &self,
        req: &GenerateRequest<'_>,
        progress: &mut dyn Progress,
    ) -> Result<Generated, ModelError> {
        self.refuse_unsupported(req)?;
        let n = crate::motion::validate::song_frames(req.audio.duration_s(), self.file.fps);
        let clock = beat_time::BeatTime::for_request(self.file.extra.beat_time, req, n)?;
        let g = self.generate_features(req, &clock, progress)?;
        let motion = rotations::decode(&self.rig, g.features.view(), g.start, self.file.fps)?;
        Ok(Generated {
            motion: clock.back(motion),
            style: Some(g.style),
            beat_time: clock.used(self.file.extra.beat_time),
            opening: g.opening,
            composition: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::dancenet::Config;
    use tch::{nn, Device};

    /// The opening check draws only a dance's first frames and judges them: with music guidance
    /// they must be the first frames of the whole dance, drawn against the same average.
    #[test]
    fn a_draw_of_the_first_frames_is_the_opening_of_the_whole_draw() {
        tch::manual_seed(3);
        let vs = nn::VarStore::new(Device::Cpu);
        let d = 6;
        let config = Config {
            music_dim: 3,
            ..Config::tiny(d)
        };
        let model = DanceNet::new(&vs.root(), config.clone());
        let n = 60;
        let code = Tensor::randn([n, config.d_code], (Kind::Float, Device::Cpu));
        let context = Array2::from_shape_fn((12, (d + 4) as usize), |(t, c)| {
            ((t * 3 + c) % 5) as f32 * 0.3 - 0.6
        });
        let draw = Draw {
            model: &model,
            code: &code,
            tail: config.receptive_field() as usize + 1,
            n: n as usize,
            opening: 0,
            warm: 20,
            style: 1,
            sampling: Sampling {
                temperature: 1.0,
                coherence: 0.5,
                music_guidance: 3.0,
            },
        };
        let whole = draw.dance(&context, 7, None, &mut |_| true).expect("drawn");
        let first = draw
            .dance(&context, 7, Some(25), &mut |_| true)
            .expect("drawn");
        assert_eq!(whole.nrows(), n as usize);
        assert_eq!(first, whole.slice(s![..25, ..]).to_owned());
    }
}
