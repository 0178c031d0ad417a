//! TSMT as served: the song's features, the opening (the request's seed motion or a real clip),
//! the audio stream over the whole song, then the poses sampled frame by frame and rebuilt into
//! joint positions.
use std::path::Path;

use ndarray::{s, Array2};
use serde::{Deserialize, Serialize};

use super::{Bins, Config, Sampling, StallGuard, Tsmt, ID};
use crate::models::beat_time;
use crate::models::folder::{self, SeedClips, SEED_CLIPS_FILE};
use crate::models::train::augment::MusicLayout;
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
}

/// `model.json`.
pub type ModelFile = folder::ModelFile<Config, Schedule, Serving>;

/// A trained TSMT, ready to serve.
pub struct Served {
    file: ModelFile,
    clips: Option<SeedClips>,
    pool: InstancePool<Tsmt>,
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
        Ok(Self { file, clips, pool })
    }

    /// The model's description file.
    pub fn file(&self) -> &ModelFile {
        &self.file
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
        let song = crate::audio::features::tsmt(req.audio, fps, 0.0, clock.song_frames)?;
        let feats = clock.music(song.view(), &MusicLayout::tsmt());
        let music = to_tensor(&self.file.music_norm.normalize(&feats)?).unsqueeze(0);
        progress.report(Stage::Features, 1.0)?;
        // The opening: the request's seed motion (kept as the dance's first frames), or a real clip.
        let seed_motion = req.seed_motion.map(|m| clock.seed_motion(m));
        let (context, opening, start) = match seed_motion.as_ref() {
            Some(m) if m.num_frames() > 0 => {
                let keep = m.num_frames().min(n);
                let root = crate::motion::skeleton::body_centre_track(m.positions.view());
                let (mut f, start) = repr::to_features(m.positions.view(), root.view())?;
                let floor = repr::floor_of_features(f.view());
                repr::height_to_clearance(&mut f, floor);
                let f = f.slice(s![..keep, ..]).to_owned();
                (bins.tokens(&f), Some(f), start)
            }
            _ => {
                let clip = match &self.clips {
                    Some(c) => c.pick(req.seed),
                    None => {
                        return Err(ModelError::BadModelFile(format!(
                            "{ID}: no seed motion and no {SEED_CLIPS_FILE}"
                        )))
                    }
                };
                (bins.tokens(&clip), None, RootStart::default())
            }
        };
        let opened = opening.as_ref().map_or(0, |o| o.nrows());
        let out = self.pool.with(|model| {
            tch::no_grad(|| -> Result<Option<Array2<i64>>, ModelError> {
                let mut cancelled = false;
                let Some(vectors) = model.audio_logit_vectors(&music, |f| {
                    cancelled = progress.report(Stage::Encode, f).is_err();
                    !cancelled
                }) else {
                    return Ok(None);
                };
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
                Ok(
                    model.sample_guarded(&context, &rest, sampling, guard, req.seed, |done| {
                        progress
                            .report(Stage::Generate, done as f32 / total as f32)
                            .is_ok()
                    }),
                )
            })
        })??;
        let Some(tokens) = out else {
            return Err(Cancelled.into());
        };
        let mut sampled = bins.values(&tokens);
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

impl DanceModel for Served {
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
        let song_frames = crate::motion::validate::song_frames(req.audio.duration_s, self.file.fps);
        let clock = beat_time::BeatTime::for_request(self.file.extra.beat_time, req, song_frames)?;
        let n = clock.net_frames;
        let mut g = self.generate_features(req, &clock, progress)?;
        repr::clearance_to_height(&mut g.features);
        // The root height follows the lowest foot point, which hops between feet and points as
        // their coordinates are drawn; smoothing the height itself (not the clearance) keeps the
        // body from jumping with it. The opening (a request's seed motion) is kept.
        let keep = req
            .seed_motion
            .map_or(0, |m| clock.seed_frames(m.num_frames()).min(n));
        let mut h = g
            .features
            .column(repr::ROOT_Y)
            .to_owned()
            .insert_axis(ndarray::Axis(1));
        smooth_columns(
            &mut h,
            keep,
            self.file.extra.smooth_height_frames / clock.factor,
        );
        g.features.column_mut(repr::ROOT_Y).assign(&h.column(0));
        let (motion, _root) = repr::from_features(g.features.view(), g.start, self.file.fps)?;
        Ok(Generated::from(clock.back(motion))
            .with_beat_time(clock.used(self.file.extra.beat_time)))
    }
}
