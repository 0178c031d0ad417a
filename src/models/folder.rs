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

use super::clip_choice::{self, BankMeta};
use super::{InstancePool, ModelError};
use crate::motion::dataset::NormStats;

/// The folder's description file.
pub const MODEL_FILE: &str = "model.json";
/// The folder's weights (safetensors).
pub const WEIGHTS_FILE: &str = "weights.safetensors";
/// Real seed clips (`[clips, frames, width]` feature rows), for models that start from one.
pub const SEED_CLIPS_FILE: &str = "seed_clips.safetensors";
/// Where each seed clip came from and what its song did under it (a [`BankMeta`]), beside
/// [`SEED_CLIPS_FILE`]; with it the song chooses among the clips ([`SeedClips::chosen`]).
pub const SEED_CLIPS_META_FILE: &str = "seed_clips.json";
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
/// the same way. With their [`BankMeta`] the song chooses which clips the seed draws among
/// ([`Self::chosen`]).
#[derive(Clone, Debug)]
pub struct SeedClips {
    /// `[clips, frames, width]`.
    pub clips: Array3<f32>,
    /// Each clip's source and its song's beats ([`SEED_CLIPS_META_FILE`]), when kept.
    pub meta: Option<BankMeta>,
}

impl SeedClips {
    /// `count` clips of `frames` frames at seeded starts over `seqs` (each a dance's features).
    pub fn draw(
        seqs: &[&Array2<f32>],
        count: usize,
        frames: usize,
        seed: u64,
    ) -> Result<Self, ModelError> {
        Ok(Self::draw_with_sources(seqs, count, frames, seed)?.0)
    }

    /// [`Self::draw`], and where each clip came from: `(index into seqs, first frame)`.
    pub fn draw_with_sources(
        seqs: &[&Array2<f32>],
        count: usize,
        frames: usize,
        seed: u64,
    ) -> Result<(Self, Vec<(usize, usize)>), ModelError> {
        let usable: Vec<usize> = (0..seqs.len())
            .filter(|&i| seqs[i].nrows() > frames + 50)
            .collect();
        if usable.is_empty() || count == 0 {
            return Err(ModelError::Input(format!(
                "no dance longer than {frames} frames for seed clips"
            )));
        }
        let mut rng = StdRng::seed_from_u64(seed);
        let width = seqs[usable[0]].ncols();
        let mut clips = Array3::<f32>::zeros((count, frames, width));
        let mut sources = Vec::with_capacity(count);
        for k in 0..count {
            let i = usable[k % usable.len()];
            let s = seqs[i];
            let start = rng.gen_range(25..s.nrows() - frames - 25);
            clips
                .slice_mut(s![k, .., ..])
                .assign(&s.slice(s![start..start + frames, ..]));
            sources.push((i, start));
        }
        Ok((Self { clips, meta: None }, sources))
    }

    /// The clips with each one's source and beats (checked against the clips).
    pub fn with_meta(mut self, meta: BankMeta) -> Result<Self, ModelError> {
        let (k, l, _) = self.clips.dim();
        self.meta = Some(meta.checked(k, l, SEED_CLIPS_META_FILE)?);
        Ok(self)
    }

    /// Writes the clips as safetensors, and their [`BankMeta`] beside them when they have one.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        write_clips(&self.clips, path)?;
        match &self.meta {
            Some(meta) => meta.write_beside(path, SEED_CLIPS_META_FILE),
            None => Ok(()),
        }
    }

    /// Reads clips written by [`Self::save`], `width` numbers a frame, with their
    /// [`SEED_CLIPS_META_FILE`] when it lies beside.
    pub fn load(path: &Path, width: usize) -> Result<Self, ModelError> {
        let clips = read_clips(path)?;
        let (k, f, d) = clips.dim();
        if d != width || k == 0 || f == 0 {
            return Err(ModelError::BadModelFile(format!(
                "{}: clips are {k}×{f}×{d}",
                path.display()
            )));
        }
        let bare = Self { clips, meta: None };
        match BankMeta::read_beside(path, SEED_CLIPS_META_FILE)? {
            Some(meta) => bare.with_meta(meta),
            None => Ok(bare),
        }
    }

    /// The clip a job's seed picks, by the seed alone.
    pub fn pick(&self, seed: u64) -> Array2<f32> {
        self.clips
            .slice(s![Self::seeded(seed, self.clips.dim().0), .., ..])
            .to_owned()
    }

    /// The clips a job's seed draws for a song whose beat period is `period` frames (on the clock
    /// the clips are played on) with `bar` beats a bar: the seed draws among the clips that suit it
    /// best ([`clip_choice::ranked`], [`clip_choice::good`]). Returns the seed's draw first, then
    /// the other good candidates best first (for a caller that passes over a clip), each with the
    /// rate (clip frames per song frame) that puts its own beats at the song's pace; empty without
    /// [`BankMeta`] or a clip of two beats.
    pub fn chosen(&self, seed: u64, period: f64, bar: usize) -> Vec<(usize, f64)> {
        let Some(meta) = self.meta.as_ref() else {
            return Vec::new();
        };
        if !(period.is_finite() && period > 0.0) {
            return Vec::new();
        }
        // No energy term: the song's would cost a second onset analysis per job.
        let mut good = clip_choice::good(&clip_choice::ranked(&meta.clips, period, bar, 0.0));
        if good.is_empty() {
            return Vec::new();
        }
        let first = good.remove(Self::seeded(seed, good.len()));
        std::iter::once(first)
            .chain(good)
            .filter_map(|(c, u)| Some((c, u * meta.clips[c].period()? / period)))
            .collect()
    }

    /// The seed's draw among `n` (the same draw [`Self::pick`] always made).
    fn seeded(seed: u64, n: usize) -> usize {
        StdRng::seed_from_u64(seed ^ 0x5EED_C11F).gen_range(0..n)
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

    /// Seed clips keep their description beside them, and with it the song chooses the clips the
    /// seed draws among: a cha-cha's pace draws the cha-cha clips, a waltz's the waltz clips, and
    /// each is replayed so that its own beats come at the song's pace. Without the description
    /// the seed alone draws, as before.
    #[test]
    fn seed_clips_chosen_by_the_song_round_trip_with_their_description() {
        use crate::models::clip_choice::ClipInfo;
        use crate::motion::dataset::Style;
        let info = |style: Style, period: f64| ClipInfo {
            dance: "DANCE_X_1".into(),
            start: 30,
            style,
            beats: vec![2.0, 2.0 + period, 2.0 + 2.0 * period],
            bar: if style == Style::Waltz { 3 } else { 4 },
            energy: 1.0,
        };
        let styles = [Style::ChaCha, Style::Waltz];
        let meta = BankMeta {
            made_by: "test".into(),
            fps: 25.0,
            clips: (0..10)
                .map(|c| {
                    let style = styles[c % 2];
                    let period = if style == Style::Waltz { 17.5 } else { 12.25 };
                    info(style, period + c as f64 * 0.25)
                })
                .collect(),
        };
        let clips = SeedClips {
            clips: Array3::from_shape_fn((10, 50, 3), |(c, f, d)| (c * 100 + f + d) as f32),
            meta: None,
        }
        .with_meta(meta.clone())
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(SEED_CLIPS_FILE);
        clips.save(&path).unwrap();
        let read = SeedClips::load(&path, 3).unwrap();
        assert_eq!(read.meta.as_ref(), Some(&meta));
        for seed in 0..20 {
            let chacha = read.chosen(seed, 12.0, 4);
            assert!(chacha.len() >= 4, "{chacha:?}");
            for &(c, rate) in &chacha {
                assert_eq!(c % 2, 0, "seed {seed}: a cha-cha song drew clip {c}");
                let own = meta.clips[c].period().unwrap();
                assert!((rate * 12.0 - own).abs() < 1e-9, "rate {rate}");
            }
            let waltz = read.chosen(seed, 17.0, 3);
            assert!(waltz.iter().all(|w| w.0 % 2 == 1), "seed {seed}: {waltz:?}");
        }
        // The seed draws which good candidate comes first.
        let firsts: std::collections::BTreeSet<usize> = (0..20)
            .map(|seed| read.chosen(seed, 12.0, 4)[0].0)
            .collect();
        assert!(firsts.len() >= 3, "{firsts:?}");
        assert!(read.chosen(1, f64::NAN, 4).is_empty());
        std::fs::remove_file(dir.path().join(SEED_CLIPS_META_FILE)).unwrap();
        let bare = SeedClips::load(&path, 3).unwrap();
        assert!(bare.meta.is_none() && bare.chosen(1, 12.0, 4).is_empty());
        assert_eq!(bare.pick(7), read.pick(7));
    }
}
