//! The dance models, one file per paper, behind one trait the worker calls.
//!
//! CONTRACT (lead owns this folder): the worker builds a [`GenerateRequest`], calls
//! [`DanceModel::generate`] on a blocking thread, and gets a [`Motion`] back. Models report
//! progress through [`Progress`], which also carries cancellation.
use crate::audio::DecodedAudio;
use crate::motion::{KeyPose, Motion};
use serde::{Deserialize, Serialize};

pub mod dance_revolution;
pub mod keypose_transformer;
pub mod train;

/// A model's stable id, as used by the API (`"dance-revolution"`, `"keypose-transformer"`).
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(transparent)]
pub struct ModelId(pub String);

/// What a model can take besides the song.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Capabilities {
    pub key_poses: bool,
    pub seed_motion: bool,
    pub style: bool,
}

/// One model as `GET /v1/models` lists it.
#[derive(Clone, Debug, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ModelInfo {
    pub id: ModelId,
    pub paper: String,
    pub capabilities: Capabilities,
}

/// Everything a model needs for one dance.
pub struct GenerateRequest<'a> {
    pub audio: &'a DecodedAudio,
    /// Seeds every random draw, so the same seed gives the same dance.
    pub seed: u64,
    pub key_poses: &'a [KeyPose],
    pub seed_motion: Option<&'a Motion>,
}

/// Returned by [`Progress::report`] when the job was cancelled.
#[derive(Debug, Clone, Copy, thiserror::Error)]
#[error("cancelled")]
pub struct Cancelled;

/// Receives progress; returning `Err(Cancelled)` stops the model at this checkpoint.
pub trait Progress {
    /// `stage` is a short name ("features", "encode", "decode"); `fraction` is 0..=1 within it.
    fn report(&mut self, stage: &str, fraction: f32) -> Result<(), Cancelled>;
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
    #[error("invalid input: {0}")]
    Invalid(String),
    #[error("motion: {0}")]
    Motion(#[from] crate::motion::MotionError),
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
    ndarray::Array2::from_shape_vec((r as usize, c as usize), data).map_err(|e| ModelError::Invalid(e.to_string()))
}

/// A trained model, ready to dance.
pub trait DanceModel: Send + Sync {
    fn info(&self) -> ModelInfo;
    fn generate(&self, req: &GenerateRequest<'_>, progress: &mut dyn Progress) -> Result<Motion, ModelError>;
}

/// The models found under the models dir (`models/<id>/`), loaded once at start-up.
#[derive(Default, Clone)]
pub struct Registry {
    models: Vec<std::sync::Arc<dyn DanceModel>>,
}

impl Registry {
    /// Loads every model whose weights are present under `dir`; a model without weights is left out.
    pub fn load(dir: &std::path::Path) -> Result<Self, ModelError> {
        let mut models: Vec<std::sync::Arc<dyn DanceModel>> = Vec::new();
        let dr = dir.join(dance_revolution::ID);
        if dr.join(dance_revolution::WEIGHTS_FILE).exists() {
            models.push(std::sync::Arc::new(dance_revolution::Served::load(&dr)?));
        }
        let kp = dir.join(keypose_transformer::ID);
        if kp.join(keypose_transformer::WEIGHTS_FILE).exists() {
            models.push(std::sync::Arc::new(keypose_transformer::Served::load(&kp)?));
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
    pub fn new(weights: std::path::PathBuf, build: impl Fn(&tch::nn::Path) -> M + Send + Sync + 'static) -> Result<Self, ModelError> {
        let pool = Self { weights, build: Box::new(build), free: std::sync::Mutex::new(Vec::new()) };
        let first = pool.load()?;
        pool.free.lock().unwrap_or_else(|p| p.into_inner()).push(first);
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
        self.free.lock().unwrap_or_else(|p| p.into_inner()).push(instance);
        Ok(out)
    }
}

/// Reads a model folder's description file, or says the model is missing.
pub fn read_model_file<T: serde::de::DeserializeOwned>(dir: &std::path::Path, id: &str, name: &str) -> Result<T, ModelError> {
    let text = std::fs::read_to_string(dir.join(name)).map_err(|_| ModelError::MissingWeights(id.into(), dir.display().to_string()))?;
    serde_json::from_str(&text).map_err(|e| ModelError::Invalid(format!("{name}: {e}")))
}
