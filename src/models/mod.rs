//! The dance models, one file per paper, behind one trait the worker calls.
//!
//! CONTRACT (lead owns this folder): the worker builds a [`GenerateRequest`], calls
//! [`DanceModel::generate`] on a blocking thread, and gets a [`Motion`] back. Models report
//! progress through [`Progress`], which also carries cancellation.
use crate::audio::{Analysis, SongAudio};
use crate::motion::{KeyPose, Motion};
use crate::stage::Stage;
use serde::{Deserialize, Serialize};

pub mod beat_graph;
pub mod beat_time;
pub mod clip_choice;
pub mod dance_revolution;
pub mod dancenet;
pub mod encoded;
pub mod folder;
pub mod keypose_transformer;
pub mod layers;
pub mod motion_style;
pub mod opening_check;
pub mod step_clock;
pub mod stretch;
pub mod train;
pub mod tsmt;

/// One row per served model: its id (the folder name under the models dir) and how to load it.
/// Adding a model is one row here, one `pub mod` above and one trainer under [`train`].
pub const MODELS: &[Entry] = &[
    // First: `GET /v1/models` lists it first and the page dances it by default, as the model
    // whose served dances score closest to real ones (docs/evaluation.md).
    Entry {
        id: beat_graph::ID,
        load: |dir| Ok(std::sync::Arc::new(beat_graph::Served::load(dir)?)),
    },
    Entry {
        id: dance_revolution::ID,
        load: |dir| Ok(std::sync::Arc::new(dance_revolution::Served::load(dir)?)),
    },
    Entry {
        id: dancenet::ID,
        load: |dir| Ok(std::sync::Arc::new(dancenet::Served::load(dir)?)),
    },
    Entry {
        id: keypose_transformer::ID,
        load: |dir| Ok(std::sync::Arc::new(keypose_transformer::Served::load(dir)?)),
    },
    Entry {
        id: tsmt::ID,
        load: |dir| Ok(std::sync::Arc::new(tsmt::Served::load(dir)?)),
    },
];

/// A row of [`MODELS`].
pub struct Entry {
    /// The API id and the folder name.
    pub id: &'static str,
    /// Loads the model from its folder (`models/<id>/`).
    pub load: fn(&std::path::Path) -> Result<std::sync::Arc<dyn DanceModel>, ModelError>,
}

/// A model's stable id, as used by the API (`"dance-revolution"`, `"keypose-transformer"`).
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(transparent)]
pub struct ModelId(pub String);

/// What a model can take besides the song.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Capabilities {
    pub key_poses: bool,
    pub seed_motion: bool,
    /// Takes a [`DanceStyle`] (and predicts one from the song when none is given).
    pub style: bool,
    /// Samples, and takes a `temperature` that scales its randomness.
    #[serde(default)]
    pub temperature: bool,
    /// Samples from discrete choices, and takes a `top_k` that restricts them.
    #[serde(default)]
    pub top_k: bool,
}

/// The four ballroom styles of the training data (dance-with-melody's folder letters C, R, T, W).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum DanceStyle {
    ChaCha,
    Rumba,
    Tango,
    Waltz,
}

impl DanceStyle {
    /// Every style, in index order.
    pub const ALL: [DanceStyle; 4] = [
        DanceStyle::ChaCha,
        DanceStyle::Rumba,
        DanceStyle::Tango,
        DanceStyle::Waltz,
    ];

    /// The style of a dataset dance folder's letter (`DANCE_W_1` → waltz).
    pub fn from_letter(c: char) -> Option<Self> {
        match c.to_ascii_uppercase() {
            'C' => Some(Self::ChaCha),
            'R' => Some(Self::Rumba),
            'T' => Some(Self::Tango),
            'W' => Some(Self::Waltz),
            _ => None,
        }
    }

    /// The style of a dataset dance id (`DANCE_R_4`).
    pub fn of_dance_id(id: &str) -> Option<Self> {
        id.strip_prefix("DANCE_")
            .and_then(|r| r.chars().next())
            .and_then(Self::from_letter)
    }

    /// Position in [`Self::ALL`] (a one-hot's index).
    pub fn index(self) -> usize {
        self as usize
    }

    /// The name the API uses.
    pub fn name(self) -> &'static str {
        match self {
            Self::ChaCha => "cha-cha",
            Self::Rumba => "rumba",
            Self::Tango => "tango",
            Self::Waltz => "waltz",
        }
    }

    /// Parses the API name.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|d| d.name() == s)
    }

    /// The API names, comma-separated, for error messages.
    pub fn names() -> String {
        Self::ALL.map(|d| d.name()).join(", ")
    }
}

/// The style a dance was made in, as the job result and report state it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct StyleChoice {
    pub style: DanceStyle,
    /// True when the model's style classifier chose it from the song (no style was asked for).
    pub predicted: bool,
    /// The classifier's probabilities per style, in [`DanceStyle::ALL`] order, when it ran.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub probabilities: Vec<f32>,
}

/// What a model returns: the motion and what it chose on the user's behalf.
pub struct Generated {
    pub motion: Motion,
    pub style: Option<StyleChoice>,
    /// The clock the network ran on, for a model in beat time ([`beat_time`]).
    pub beat_time: Option<beat_time::BeatTimeUsed>,
    /// What the model's opening check chose, for a model that has one ([`opening_check`]).
    pub opening: Option<opening_check::OpeningChosen>,
    /// What a composed dance was made of, for a model that composes ([`beat_graph`]).
    pub composition: Option<beat_graph::Composition>,
}

impl Generated {
    /// The same, with the clock it ran on.
    pub fn with_beat_time(self, beat_time: Option<beat_time::BeatTimeUsed>) -> Self {
        Self { beat_time, ..self }
    }

    /// The same, with what its opening check chose.
    pub fn with_opening(self, opening: Option<opening_check::OpeningChosen>) -> Self {
        Self { opening, ..self }
    }
}

impl From<Motion> for Generated {
    fn from(motion: Motion) -> Self {
        Self {
            motion,
            style: None,
            beat_time: None,
            opening: None,
            composition: None,
        }
    }
}

/// One model as `GET /v1/models` lists it.
#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ModelInfo {
    pub id: ModelId,
    pub paper: String,
    pub capabilities: Capabilities,
    /// Present when the network runs in beat time: it hears every song at this reference tempo
    /// (its feature frames resampled in time), makes its motion on that clock, and the motion is
    /// played back at the song's own tempo, so its steps keep the same fraction of the beat on
    /// any song (the model card says how it was trained).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beat_time: Option<beat_time::BeatTimeConfig>,
}

/// Everything a model needs for one dance.
pub struct GenerateRequest<'a> {
    /// The song: a decoded one, or a job's, whose features and beats are computed once per song.
    pub audio: &'a dyn SongAudio,
    /// Seeds every random draw, so the same seed gives the same dance.
    pub seed: u64,
    pub key_poses: &'a [KeyPose],
    pub seed_motion: Option<&'a Motion>,
    /// The style to dance, for models whose [`Capabilities::style`] is set (else their own choice).
    pub style: Option<DanceStyle>,
    /// Scales a sampling model's randomness (1 = as trained), when [`Capabilities::temperature`].
    pub temperature: Option<f64>,
    /// Keeps the `k` likeliest choices when sampling, when [`Capabilities::top_k`].
    pub top_k: Option<u32>,
    /// The song's beats, when the caller has analysed it already (jobs and `choreo generate` do,
    /// before the model, for the beat-align stage and the report): a model that listens to the
    /// beats uses these rather than analysing the song a second time, unbudgeted.
    pub analysis: Option<&'a Analysis>,
}

impl<'a> GenerateRequest<'a> {
    /// The song's analysis: the caller's ([`Self::analysis`]), else analysed here, unbudgeted.
    pub fn analysis_or_analyze(
        &self,
    ) -> Result<std::borrow::Cow<'a, Analysis>, crate::audio::AudioError> {
        match self.analysis {
            Some(a) => Ok(std::borrow::Cow::Borrowed(a)),
            None => self.audio.analysis().map(std::borrow::Cow::Owned),
        }
    }

    /// A request with only the song and the seed: no key poses, no seed motion, model defaults.
    pub fn plain(audio: &'a dyn SongAudio, seed: u64) -> Self {
        Self {
            audio,
            seed,
            key_poses: &[],
            seed_motion: None,
            style: None,
            temperature: None,
            top_k: None,
            analysis: None,
        }
    }
}

/// Returned by [`Progress::report`] when the job was cancelled.
#[derive(Debug, Clone, Copy, thiserror::Error)]
#[error("cancelled")]
pub struct Cancelled;

/// Receives progress; returning `Err(Cancelled)` stops the model at this checkpoint.
pub trait Progress {
    /// `stage` is the model's own work ([`Stage::Features`], [`Stage::Encode`], [`Stage::Generate`]);
    /// `fraction` is 0..=1 within it.
    fn report(&mut self, stage: Stage, fraction: f32) -> Result<(), Cancelled>;
}

/// Errors a model can raise.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    #[error("cancelled")]
    Cancelled(#[from] Cancelled),
    #[error("model {0} does not take {1}")]
    Unsupported(String, &'static str),
    #[error("weights for model {0} not found at {1}")]
    MissingWeights(String, String),
    #[error("audio: {0}")]
    Audio(#[from] crate::audio::AudioError),
    #[error("libtorch: {0}")]
    Torch(#[from] tch::TchError),
    /// A model folder's files cannot be read, or disagree with each other (a JSON that does not
    /// parse, a tensor missing or of the wrong shape, a normalisation for other features).
    #[error("model file: {0}")]
    BadModelFile(String),
    /// What the model was given it cannot use: a song too short to classify, non-finite
    /// features, training data with nothing to fit.
    #[error("invalid input: {0}")]
    Input(String),
    /// Arrays the code itself put together do not fit (a bug, not the input's fault).
    #[error("shape: {0}")]
    Shape(String),
    #[error("motion: {0}")]
    Motion(#[from] crate::motion::MotionError),
}

impl ModelError {
    /// Stable kebab-case name of the failure. The worker reports every model failure to clients
    /// as `model-failed` (see `WorkerError::code`); this finer code goes to the logs.
    pub fn code(&self) -> &'static str {
        match self {
            ModelError::Cancelled(_) => "cancelled",
            ModelError::Unsupported(..) => "model-unsupported-input",
            ModelError::MissingWeights(..) => "model-missing-weights",
            ModelError::Audio(e) => e.code(),
            ModelError::Torch(_) => "model-torch",
            ModelError::BadModelFile(_) => "model-file-invalid",
            ModelError::Input(_) => "model-input-invalid",
            ModelError::Shape(_) => "model-shape",
            ModelError::Motion(e) => e.code(),
        }
    }
}

/// `[r, c]` ndarray → tensor (a copy in standard layout).
pub fn to_tensor(m: &ndarray::Array2<f32>) -> tch::Tensor {
    let (r, c) = m.dim();
    let m = m.as_standard_layout();
    tch::Tensor::from_slice(m.as_slice().unwrap_or(&[])).view([r as i64, c as i64])
}

/// `[r, c]` tensor → ndarray.
pub fn to_array(t: &tch::Tensor) -> Result<ndarray::Array2<f32>, ModelError> {
    let (r, c) = t.size2()?;
    let data: Vec<f32> = Vec::<f32>::try_from(t.contiguous().view([-1]))?;
    ndarray::Array2::from_shape_vec((r as usize, c as usize), data)
        .map_err(|e| ModelError::Shape(e.to_string()))
}

/// Smooths every column of `[T, D]` feature rows over time (Gaussian, σ `sigma` frames, scipy's
/// `gaussian_filter1d`), leaving the first `keep` rows (a request's own seed motion) as given: a
/// sampling model's draws jitter from frame to frame in a way a dancer does not.
pub fn smooth_columns(features: &mut ndarray::Array2<f32>, keep: usize, sigma: f64) {
    if sigma <= 0.0 || features.nrows() <= keep + 1 {
        return;
    }
    for mut col in features.columns_mut() {
        let x: Vec<f64> = col.iter().skip(keep).map(|&v| f64::from(v)).collect();
        let y = crate::metrics::beats::gaussian_filter1d(&x, sigma);
        for (dst, v) in col.iter_mut().skip(keep).zip(y) {
            *dst = v as f32;
        }
    }
}

/// A trained model, ready to dance.
pub trait DanceModel: Send + Sync {
    fn info(&self) -> ModelInfo;

    /// The network's arithmetic per motion frame in its generate loop (a multiply-add counts 2),
    /// from its Config; `None` for a model without a network loop. `choreo bench generate` sets
    /// the loop's speed against one core's peak with it.
    fn frame_flops(&self) -> Option<f64> {
        None
    }
    fn generate(
        &self,
        req: &GenerateRequest<'_>,
        progress: &mut dyn Progress,
    ) -> Result<Generated, ModelError>;

    /// Refuses a request with an input this model's [`Capabilities`] do not list, as the API does
    /// before queueing; every model's `generate` starts with it, so the CLI and the eval refuse too.
    fn refuse_unsupported(&self, req: &GenerateRequest<'_>) -> Result<(), ModelError> {
        let info = self.info();
        let c = info.capabilities;
        let refused = [
            (!req.key_poses.is_empty() && !c.key_poses, "key poses"),
            (req.seed_motion.is_some() && !c.seed_motion, "a seed motion"),
            (req.style.is_some() && !c.style, "a style"),
            (req.temperature.is_some() && !c.temperature, "a temperature"),
            (req.top_k.is_some() && !c.top_k, "top_k"),
        ];
        match refused.into_iter().find(|(r, _)| *r) {
            Some((_, what)) => Err(ModelError::Unsupported(info.id.0, what)),
            None => Ok(()),
        }
    }
}

/// The models found under the models dir (`models/<id>/`), loaded once at start-up.
#[derive(Default, Clone)]
pub struct Registry {
    models: Vec<std::sync::Arc<dyn DanceModel>>,
}

impl Registry {
    /// Loads every model whose weights are present under `dir`; a model without weights is left out.
    pub fn load(dir: &std::path::Path) -> Result<Self, ModelError> {
        let mut models = Vec::new();
        for entry in MODELS {
            let folder = dir.join(entry.id);
            if folder.join(folder::WEIGHTS_FILE).exists() {
                models.push((entry.load)(&folder)?);
            }
        }
        Ok(Self { models })
    }

    /// The models available, in a stable order.
    pub fn list(&self) -> Vec<ModelInfo> {
        self.models.iter().map(|m| m.info()).collect()
    }

    /// The model with this id, if it is available.
    pub fn get(&self, id: &ModelId) -> Option<std::sync::Arc<dyn DanceModel>> {
        self.models.iter().find(|m| &m.info().id == id).cloned()
    }
}

/// Loaded copies of one network. libtorch tensors are `Send` but not `Sync`, so each concurrent
/// generation borrows a copy of its own; a copy is loaded when none is free and returned after.
pub struct InstancePool<M> {
    weights: std::path::PathBuf,
    build: Box<dyn Fn(&tch::nn::Path) -> M + Send + Sync>,
    free: std::sync::Mutex<Vec<(M, tch::nn::VarStore)>>,
}

impl<M: Send> InstancePool<M> {
    /// Loads one copy now, so a bad weights file fails at start-up rather than on the first job.
    pub fn new(
        weights: std::path::PathBuf,
        build: impl Fn(&tch::nn::Path) -> M + Send + Sync + 'static,
    ) -> Result<Self, ModelError> {
        let pool = Self {
            weights,
            build: Box::new(build),
            free: std::sync::Mutex::new(Vec::new()),
        };
        let first = pool.load()?;
        pool.free
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(first);
        Ok(pool)
    }

    fn load(&self) -> Result<(M, tch::nn::VarStore), ModelError> {
        let mut vs = tch::nn::VarStore::new(tch::Device::Cpu);
        let model = (self.build)(&vs.root());
        vs.load(&self.weights)?;
        Ok((model, vs))
    }

    /// Runs `f` on a free copy of the network.
    pub fn with<R>(&self, f: impl FnOnce(&M) -> R) -> Result<R, ModelError> {
        let pooled = self.free.lock().unwrap_or_else(|p| p.into_inner()).pop();
        let instance = match pooled {
            Some(i) => i,
            None => self.load()?,
        };
        let out = f(&instance.0);
        self.free
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(instance);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Only what `refuse_unsupported` reads: the model's capabilities.
    struct Takes(Capabilities);

    impl DanceModel for Takes {
        fn info(&self) -> ModelInfo {
            ModelInfo {
                id: ModelId("m".into()),
                paper: String::new(),
                capabilities: self.0,
                beat_time: None,
            }
        }
        fn generate(
            &self,
            _: &GenerateRequest<'_>,
            _: &mut dyn Progress,
        ) -> Result<Generated, ModelError> {
            unreachable!("refuse_unsupported only")
        }
    }

    #[test]
    fn inputs_a_model_does_not_take_are_refused_by_name() {
        let audio = crate::audio::DecodedAudio {
            format: crate::audio::AudioFormat::Wav,
            sample_rate: 22_050,
            channels: 1,
            duration_s: 0.0,
            samples: Vec::new(),
        };
        let key = [KeyPose {
            time_s: 0.0,
            joints: vec![[0.0; 3]; 23],
        }];
        let plain = GenerateRequest::plain(&audio, 0);
        let with = |f: fn(&mut GenerateRequest<'_>)| {
            let mut r = GenerateRequest::plain(&audio, 0);
            f(&mut r);
            r
        };
        let nothing = Takes(Capabilities::default());
        assert!(nothing.refuse_unsupported(&plain).is_ok());
        let refused = |m: &Takes, r: &GenerateRequest<'_>| match m.refuse_unsupported(r) {
            Err(ModelError::Unsupported(id, what)) => Some((id, what)),
            _ => None,
        };
        assert_eq!(
            refused(&nothing, &with(|r| r.style = Some(DanceStyle::ALL[0]))),
            Some(("m".into(), "a style"))
        );
        assert_eq!(
            refused(&nothing, &with(|r| r.temperature = Some(0.8))),
            Some(("m".into(), "a temperature"))
        );
        assert_eq!(
            refused(&nothing, &with(|r| r.top_k = Some(4))),
            Some(("m".into(), "top_k"))
        );
        let keyed = GenerateRequest {
            key_poses: &key,
            ..GenerateRequest::plain(&audio, 0)
        };
        assert_eq!(refused(&nothing, &keyed), Some(("m".into(), "key poses")));
        let all = Takes(Capabilities {
            key_poses: true,
            seed_motion: true,
            style: true,
            temperature: true,
            top_k: true,
        });
        let everything = GenerateRequest {
            key_poses: &key,
            style: Some(DanceStyle::ALL[0]),
            temperature: Some(0.8),
            top_k: Some(4),
            ..GenerateRequest::plain(&audio, 0)
        };
        assert!(all.refuse_unsupported(&everything).is_ok());
    }
}
