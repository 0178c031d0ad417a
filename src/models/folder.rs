//! The one model-folder format every model uses (`models/<id>/`): `model.json` says what the
//! weights expect (configuration, train-split normalisation, frame rate) and how they were trained;
//! `weights.safetensors` holds the network; `train_log.jsonl` one line per epoch; `README.md` is
//! the model card. A model adds its own fields to `model.json` through the `X` parameters, and may
//! keep real seed clips beside the weights ([`SeedClips`]).
use std::path::Path;

use ndarray::{s, Array2, Array3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use tch::Tensor;

use super::{InstancePool, ModelError};
use crate::motion::dataset::NormStats;

/// The folder's description file.
pub const MODEL_FILE: &str = "model.json";
/// The folder's weights (safetensors).
pub const WEIGHTS_FILE: &str = "weights.safetensors";
/// Real seed clips (`[clips, frames, width]` feature rows), for models that start from one.
pub const SEED_CLIPS_FILE: &str = "seed_clips.safetensors";
/// One JSON line per training epoch.
pub const TRAIN_LOG_FILE: &str = "train_log.jsonl";

/// How the committed weights were trained; `X` holds the model's own schedule values.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrainingRecord<X> {
    pub epochs: usize,
    pub lr: f64,
    pub batch: usize,
    pub seed: u64,
    pub final_train_loss: f64,
    pub minutes: f64,
    #[serde(flatten)]
    pub extra: X,
}

/// `model.json`: configuration `C`, normalisation, frame rate, training record (`T` its own
/// fields) and the model's own top-level fields `X`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModelFile<C, T, X> {
    pub config: C,
    pub music_norm: NormStats,
    pub pose_norm: NormStats,
    pub fps: f64,
    pub training: TrainingRecord<T>,
    #[serde(flatten)]
    pub extra: X,
}

/// No fields of a model's own.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Nothing {}

/// Reads `dir/model.json`, or says the model is missing.
pub fn read<F: DeserializeOwned>(dir: &Path, id: &str) -> Result<F, ModelError> {
    let text = std::fs::read_to_string(dir.join(MODEL_FILE))
        .map_err(|_| ModelError::MissingWeights(id.into(), dir.display().to_string()))?;
    serde_json::from_str(&text)
        .map_err(|e| ModelError::BadModelFile(format!("{id}/{MODEL_FILE}: {e}")))
}

/// Reads `model.json` and loads the weights into a pool of networks built by `build`.
pub fn load<F, M>(
    dir: &Path,
    id: &str,
    build: impl Fn(&tch::nn::Path, &F) -> M + Send + Sync + 'static,
) -> Result<(F, InstancePool<M>), ModelError>
where
    F: DeserializeOwned + Clone + Send + Sync + 'static,
    M: Send,
{
    let file: F = read(dir, id)?;
    let for_build = file.clone();
    let pool = InstancePool::new(dir.join(WEIGHTS_FILE), move |p| build(p, &for_build))?;
    Ok((file, pool))
}

/// Real clips of the train split in a model's own feature rows, one drawn by a job's seed when
/// the request brings no seed motion: a dance started from one fixed pose would begin every song
/// the same way.
#[derive(Clone, Debug)]
pub struct SeedClips {
    /// `[clips, frames, width]`.
    pub clips: Array3<f32>,
}

impl SeedClips {
    /// `count` clips of `frames` frames at seeded starts over `seqs` (each a dance's features).
    pub fn draw(
        seqs: &[&Array2<f32>],
        count: usize,
        frames: usize,
        seed: u64,
    ) -> Result<Self, ModelError> {
        let usable: Vec<&&Array2<f32>> = seqs.iter().filter(|s| s.nrows() > frames + 50).collect();
        if usable.is_empty() || count == 0 {
            return Err(ModelError::Input(format!(
                "no dance longer than {frames} frames for seed clips"
            )));
        }
        let mut rng = StdRng::seed_from_u64(seed);
        let width = usable[0].ncols();
        let mut clips = Array3::<f32>::zeros((count, frames, width));
        for k in 0..count {
            let s = usable[k % usable.len()];
            let start = rng.gen_range(25..s.nrows() - frames - 25);
            clips
                .slice_mut(s![k, .., ..])
                .assign(&s.slice(s![start..start + frames, ..]));
        }
        Ok(Self { clips })
    }

    /// Writes the clips as safetensors.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        write_clips(&self.clips, path)
    }

    /// Reads clips written by [`Self::save`], `width` numbers a frame.
    pub fn load(path: &Path, width: usize) -> Result<Self, ModelError> {
        let clips = read_clips(path)?;
        let (k, f, d) = clips.dim();
        if d != width || k == 0 || f == 0 {
            return Err(ModelError::BadModelFile(format!(
                "{}: clips are {k}×{f}×{d}",
                path.display()
            )));
        }
        Ok(Self { clips })
    }

    /// The clip a job's seed picks.
    pub fn pick(&self, seed: u64) -> Array2<f32> {
        let k = StdRng::seed_from_u64(seed ^ 0x5EED_C11F).gen_range(0..self.clips.dim().0);
        self.clips.slice(s![k, .., ..]).to_owned()
    }
}

/// The tensor name of a clips file ([`SeedClips`], keypose-transformer's pose bank).
const CLIPS: &str = "clips";

/// Writes `[clips, frames, width]` real clips as safetensors.
pub fn write_clips(clips: &Array3<f32>, path: &Path) -> Result<(), ModelError> {
    let (k, f, d) = clips.dim();
    let data: Vec<f32> = clips.iter().copied().collect();
    let t = Tensor::from_slice(&data).view([k as i64, f as i64, d as i64]);
    Tensor::write_safetensors(&[(CLIPS, t)], path)?;
    Ok(())
}

/// Reads clips written by [`write_clips`], any shape.
pub fn read_clips(path: &Path) -> Result<Array3<f32>, ModelError> {
    let named = Tensor::read_safetensors(path)?;
    let t = named
        .into_iter()
        .find(|(n, _)| n == CLIPS)
        .map(|(_, t)| t)
        .ok_or_else(|| {
            ModelError::BadModelFile(format!("{}: no `{CLIPS}` tensor", path.display()))
        })?;
    let (k, f, d) = t.size3()?;
    let data = Vec::<f32>::try_from(t.to_kind(tch::Kind::Float).contiguous().view([-1]))?;
    Array3::from_shape_vec((k as usize, f as usize, d as usize), data)
        .map_err(|e| ModelError::BadModelFile(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    struct Own {
        steps: usize,
        #[serde(default)]
        weight: f64,
    }

    #[test]
    fn own_fields_are_flat_and_older_files_read() {
        let norm = NormStats {
            mean: vec![0.0],
            std: vec![1.0],
        };
        let f = ModelFile {
            config: 3u8,
            music_norm: norm.clone(),
            pose_norm: norm,
            fps: 25.0,
            training: TrainingRecord {
                epochs: 2,
                lr: 1e-3,
                batch: 4,
                seed: 9,
                final_train_loss: 0.5,
                minutes: 1.0,
                extra: Own {
                    steps: 7,
                    weight: 2.0,
                },
            },
            extra: Own {
                steps: 1,
                weight: 0.0,
            },
        };
        let v = serde_json::to_value(&f).unwrap();
        assert_eq!(v["training"]["steps"], 7);
        assert_eq!(v["steps"], 1);
        // A file written before a field existed reads with its default.
        let mut old = v.clone();
        old["training"].as_object_mut().unwrap().remove("weight");
        let back: ModelFile<u8, Own, Own> = serde_json::from_value(old).unwrap();
        assert_eq!(
            back.training.extra,
            Own {
                steps: 7,
                weight: 0.0
            }
        );
    }
}
