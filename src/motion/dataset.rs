//! The dance-with-melody dataset: 43 real motion-capture dances with their music.
//!
//! Layout (`../shared/data/dance-with-melody`): one folder per dance (`DANCE_<style>_<n>`) with
//! `audio.mp3`, `config.json` (`start_position`, `end_position` in 25 fps frames of the song),
//! `skeletons.npy` (`[T, 23, 3]` cm, relative to the body centre) and `center.npy` (`[T, 3]` cm,
//! world); plus `split.json` (train/test ids). Motion frame i is danced to song time
//! `(start_position + i) / 25` s. We load positions in metres: `center + skeletons`, / 100.
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use ndarray::{Array2, Array3, Axis};
use serde::{Deserialize, Serialize};

use super::{Motion, MotionError, MOTION_FPS, NUM_JOINTS};

/// Where the dataset sits relative to the repository root.
pub const DEFAULT_ROOT: &str = "../shared/data/dance-with-melody";
/// Centimetres per metre: the dataset stores centimetres.
const CM_PER_M: f32 = 100.0;

/// Ballroom style of a dance, from the letter in its folder name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Style {
    /// C: cha-cha.
    ChaCha,
    /// R: rumba.
    Rumba,
    /// T: tango.
    Tango,
    /// W: waltz.
    Waltz,
}

impl Style {
    /// Every style, in a fixed order (the index is the style's class id).
    pub const ALL: [Style; 4] = [Style::ChaCha, Style::Rumba, Style::Tango, Style::Waltz];

    /// The style of a dance id such as `DANCE_W_3`.
    pub fn from_dance_id(id: &str) -> Option<Style> {
        let letter = id.strip_prefix("DANCE_")?.split('_').next()?;
        match letter {
            "C" => Some(Style::ChaCha),
            "R" => Some(Style::Rumba),
            "T" => Some(Style::Tango),
            "W" => Some(Style::Waltz),
            _ => None,
        }
    }

    /// Class index in [`Style::ALL`].
    pub fn index(self) -> usize {
        match self {
            Style::ChaCha => 0,
            Style::Rumba => 1,
            Style::Tango => 2,
            Style::Waltz => 3,
        }
    }

    /// Kebab-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Style::ChaCha => "cha-cha",
            Style::Rumba => "rumba",
            Style::Tango => "tango",
            Style::Waltz => "waltz",
        }
    }
}

impl fmt::Display for Style {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Style {
    type Err = MotionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Style::ALL
            .into_iter()
            .find(|st| st.as_str() == s)
            .ok_or_else(|| MotionError::Invalid(format!("unknown style {s:?}")))
    }
}

/// Fold `k` of `n` (`k` in `1..=n`) of a leave-dances-out check on the train split: each
/// style's dances, in split order, go to fold i mod n, and a style with one train dance (the
/// tango) is never left out, so what is trained on keeps every style.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fold {
    pub k: usize,
    pub n: usize,
}

/// A `--hold-out` that is not `K/N` with 1 ≤ K ≤ N, N ≥ 2.
#[derive(Debug, thiserror::Error)]
#[error("--hold-out {0:?}: expected K/N with 1 ≤ K ≤ N, N ≥ 2")]
pub struct FoldError(pub String);

impl Fold {
    /// Parses `K/N`.
    pub fn parse(s: &str) -> Result<Self, FoldError> {
        let bad = || FoldError(s.to_string());
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (k, n): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if n < 2 || k == 0 || k > n {
            return Err(bad());
        }
        Ok(Self { k, n })
    }

    /// Whether each dance (in split order, given by its style's class index) is held out.
    pub fn holds(&self, styles: &[usize]) -> Vec<bool> {
        let mut total = [0usize; Style::ALL.len()];
        for &s in styles {
            total[s] += 1;
        }
        let mut seen = [0usize; Style::ALL.len()];
        styles
            .iter()
            .map(|&s| {
                seen[s] += 1;
                total[s] > 1 && (seen[s] - 1) % self.n == self.k - 1
            })
            .collect()
    }

    /// Whether each dance id (in split order) is held out; an id of no style never is.
    pub fn holds_ids(&self, ids: &[String]) -> Vec<bool> {
        let styles: Vec<Option<usize>> = ids
            .iter()
            .map(|id| Style::from_dance_id(id).map(Style::index))
            .collect();
        let known: Vec<usize> = styles.iter().flatten().copied().collect();
        let mut held = self.holds(&known).into_iter();
        styles
            .iter()
            .map(|s| s.is_some() && held.next().unwrap_or(false))
            .collect()
    }
}

impl fmt::Display for Fold {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

/// The fixed train/test split of `split.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Split {
    pub fps: f64,
    pub train: Vec<String>,
    pub test: Vec<String>,
}

/// One dance with its music.
#[derive(Clone, Debug)]
pub struct Dance {
    /// Folder name, e.g. `DANCE_W_3`.
    pub id: String,
    pub style: Style,
    /// The whole song (`audio.mp3`).
    pub audio_path: PathBuf,
    /// Song frame (at 25 fps) of motion frame 0.
    pub start_position: u32,
    /// Song frame the config gives as the end; the frame count is authoritative.
    pub end_position: u32,
    /// World positions in metres, y up.
    pub motion: Motion,
    /// The body centre (root) per frame, metres, `[T, 3]`.
    pub center: Array2<f32>,
}

impl Dance {
    /// Song time in seconds of motion frame `frame`: `(start_position + frame) / 25`.
    pub fn song_time_s(&self, frame: usize) -> f64 {
        song_time_s(self.start_position, frame)
    }

    /// Motion frame danced at song time `t` (rounded to the nearest frame; may be out of range).
    pub fn frame_at(&self, t: f64) -> i64 {
        (t * MOTION_FPS).round() as i64 - i64::from(self.start_position)
    }

    /// Positions relative to the body centre, metres, `[T, 23, 3]` (the dataset's `skeletons`).
    pub fn root_relative(&self) -> Array3<f32> {
        let mut rel = self.motion.positions.clone();
        for (mut frame, c) in rel.outer_iter_mut().zip(self.center.outer_iter()) {
            frame -= &c.insert_axis(Axis(0));
        }
        rel
    }
}

/// Song time in seconds of motion frame `frame` of a dance starting at song frame `start_position`.
pub fn song_time_s(start_position: u32, frame: usize) -> f64 {
    (f64::from(start_position) + frame as f64) / MOTION_FPS
}

/// Start frames of training windows of `len` frames every `stride` frames within `n_frames`.
pub fn window_starts(n_frames: usize, len: usize, stride: usize) -> Vec<Range<usize>> {
    if len == 0 || stride == 0 || n_frames < len {
        return Vec::new();
    }
    (0..=n_frames - len)
        .step_by(stride)
        .map(|s| s..s + len)
        .collect()
}

/// The dataset on disk.
#[derive(Clone, Debug)]
pub struct Dataset {
    root: PathBuf,
    split: Split,
}

#[derive(Deserialize)]
struct DanceConfig {
    start_position: u32,
    end_position: u32,
}

impl Dataset {
    /// Opens the dataset at `root` (usually [`DEFAULT_ROOT`]) and reads its split.
    pub fn open(root: &Path) -> Result<Dataset, MotionError> {
        if !root.is_dir() {
            return Err(MotionError::DatasetMissing {
                path: root.to_path_buf(),
            });
        }
        let split_path = root.join("split.json");
        let split: Split = read_json(&split_path)?;
        Ok(Dataset {
            root: root.to_path_buf(),
            split,
        })
    }

    /// Opens [`DEFAULT_ROOT`], relative to the current directory (the repository root).
    pub fn open_default() -> Result<Dataset, MotionError> {
        Dataset::open(Path::new(DEFAULT_ROOT))
    }

    /// [`Self::open_default`] for a unit test over the real dances: `None` (said on stderr)
    /// where `../shared` is missing, and a panic instead under `CI=true`, where it must be there.
    #[cfg(test)]
    pub(crate) fn open_for_test() -> Option<Dataset> {
        match Dataset::open_default() {
            Ok(ds) => Some(ds),
            Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => {
                panic!("../shared is needed under CI=true: {e}")
            }
            Err(e) => {
                eprintln!("skipping: {e}");
                None
            }
        }
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The fixed train/test split.
    pub fn split(&self) -> &Split {
        &self.split
    }

    /// Train dance ids.
    pub fn train_ids(&self) -> &[String] {
        &self.split.train
    }

    /// Test dance ids (report quality here; never train on them).
    pub fn test_ids(&self) -> &[String] {
        &self.split.test
    }

    /// Every dance id, train then test.
    pub fn all_ids(&self) -> Vec<String> {
        self.split
            .train
            .iter()
            .chain(&self.split.test)
            .cloned()
            .collect()
    }

    /// Loads one dance by id.
    pub fn load(&self, id: &str) -> Result<Dance, MotionError> {
        // Ids name folders: refuse anything that could leave the dataset folder.
        if id.is_empty() || id.contains(['/', '\\']) || id.starts_with('.') {
            return Err(MotionError::UnknownDance { id: id.to_string() });
        }
        let dir = self.root.join(id);
        if !dir.is_dir() {
            return Err(MotionError::UnknownDance { id: id.to_string() });
        }
        let style = Style::from_dance_id(id)
            .ok_or_else(|| MotionError::UnknownDance { id: id.to_string() })?;
        let config: DanceConfig = read_json(&dir.join("config.json"))?;
        let skel_path = dir.join("skeletons.npy");
        let center_path = dir.join("center.npy");
        let skeletons: Array3<f32> = read_npy(&skel_path)?;
        let center: Array2<f32> = read_npy(&center_path)?;
        let t = skeletons.shape()[0];
        if skeletons.shape()[1..] != [NUM_JOINTS, 3] {
            return Err(MotionError::Malformed {
                path: skel_path,
                reason: format!(
                    "shape {:?}, expected [T, {NUM_JOINTS}, 3]",
                    skeletons.shape()
                ),
            });
        }
        if center.shape() != [t, 3] {
            return Err(MotionError::Malformed {
                path: center_path,
                reason: format!("shape {:?}, expected [{t}, 3]", center.shape()),
            });
        }
        if skeletons
            .iter()
            .chain(center.iter())
            .any(|v| !v.is_finite())
        {
            return Err(MotionError::Malformed {
                path: dir,
                reason: "non-finite coordinates".into(),
            });
        }
        let center = center.mapv(|v| v / CM_PER_M);
        let mut positions = skeletons.mapv(|v| v / CM_PER_M);
        for (mut frame, c) in positions.outer_iter_mut().zip(center.outer_iter()) {
            frame += &c.insert_axis(Axis(0));
        }
        Ok(Dance {
            id: id.to_string(),
            style,
            audio_path: dir.join("audio.mp3"),
            start_position: config.start_position,
            end_position: config.end_position,
            motion: Motion {
                fps: MOTION_FPS,
                positions,
            },
            center,
        })
    }

    /// Loads every dance of a list of ids.
    pub fn load_all(&self, ids: &[String]) -> Result<Vec<Dance>, MotionError> {
        ids.iter().map(|id| self.load(id)).collect()
    }
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, MotionError> {
    let bytes = std::fs::read(path).map_err(|e| MotionError::io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| MotionError::Malformed {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

fn read_npy<D: ndarray::Dimension>(path: &Path) -> Result<ndarray::Array<f32, D>, MotionError> {
    ndarray_npy::read_npy(path).map_err(|e| match e {
        ndarray_npy::ReadNpyError::Io(io) => MotionError::io(path, io),
        other => MotionError::Malformed {
            path: path.to_path_buf(),
            reason: other.to_string(),
        },
    })
}

/// Per-feature mean and standard deviation, fitted on the train split only and stored with
/// each model so generation undoes exactly the normalisation training used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NormStats {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
}

impl NormStats {
    /// Smallest standard deviation used, so constant features do not divide by zero.
    pub const MIN_STD: f32 = 1e-4;

    /// Fits mean and std over the rows of every `[N, D]` array (all must share `D`).
    pub fn fit<'a>(
        rows: impl IntoIterator<Item = &'a Array2<f32>>,
    ) -> Result<NormStats, MotionError> {
        let mut acc: Option<(Vec<f64>, Vec<f64>)> = None;
        let mut n = 0usize;
        for a in rows {
            let d = a.ncols();
            let (s, q) = acc.get_or_insert_with(|| (vec![0.0; d], vec![0.0; d]));
            if s.len() != d {
                return Err(MotionError::Shape(format!(
                    "feature width {d} differs from {}",
                    s.len()
                )));
            }
            for row in a.outer_iter() {
                for (k, &v) in row.iter().enumerate() {
                    s[k] += f64::from(v);
                    q[k] += f64::from(v) * f64::from(v);
                }
            }
            n += a.nrows();
        }
        let Some((s, q)) = acc else {
            return Err(MotionError::Shape("no rows to fit statistics on".into()));
        };
        if n == 0 {
            return Err(MotionError::Shape("no rows to fit statistics on".into()));
        }
        let nf = n as f64;
        let mean: Vec<f32> = s.iter().map(|v| (v / nf) as f32).collect();
        let std = s
            .iter()
            .zip(q.iter())
            .map(|(s, q)| {
                let m = s / nf;
                (((q / nf) - m * m).max(0.0).sqrt() as f32).max(Self::MIN_STD)
            })
            .collect();
        Ok(NormStats { mean, std })
    }

    /// Feature width.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// `(x - mean) / std`, row by row, for `[N, D]`.
    pub fn normalize(&self, x: &Array2<f32>) -> Result<Array2<f32>, MotionError> {
        self.check(x)?;
        let mut out = x.clone();
        for mut row in out.outer_iter_mut() {
            for (k, v) in row.iter_mut().enumerate() {
                *v = (*v - self.mean[k]) / self.std[k];
            }
        }
        Ok(out)
    }

    /// `x * std + mean`, the inverse of [`NormStats::normalize`].
    pub fn denormalize(&self, x: &Array2<f32>) -> Result<Array2<f32>, MotionError> {
        self.check(x)?;
        let mut out = x.clone();
        for mut row in out.outer_iter_mut() {
            for (k, v) in row.iter_mut().enumerate() {
                *v = *v * self.std[k] + self.mean[k];
            }
        }
        Ok(out)
    }

    fn check(&self, x: &Array2<f32>) -> Result<(), MotionError> {
        if x.shape()[1] != self.dim() {
            return Err(MotionError::Shape(format!(
                "feature width {} but statistics have {}",
                x.shape()[1],
                self.dim()
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dance ids are held out by their style's turn; an id of no style and a lone style never.
    #[test]
    fn a_fold_of_dance_ids_follows_each_style_and_keeps_the_lone_tango() {
        let ids: Vec<String> = [
            "DANCE_W_1",
            "DANCE_C_1",
            "DANCE_W_2",
            "DANCE_T_1",
            "x",
            "DANCE_C_2",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let one = Fold::parse("1/2").unwrap();
        let two = Fold::parse("2/2").unwrap();
        assert_eq!(
            one.holds_ids(&ids),
            [true, true, false, false, false, false]
        );
        assert_eq!(
            two.holds_ids(&ids),
            [false, false, true, false, false, true]
        );
        assert_eq!(one.to_string(), "1/2");
        assert!(Fold::parse("2/1").is_err());
    }

    #[test]
    fn style_comes_from_the_folder_letter() {
        assert_eq!(Style::from_dance_id("DANCE_W_3"), Some(Style::Waltz));
        assert_eq!(Style::from_dance_id("DANCE_C_8"), Some(Style::ChaCha));
        assert_eq!(Style::from_dance_id("DANCE_X_1"), None);
        assert_eq!("rumba".parse::<Style>().ok(), Some(Style::Rumba));
    }

    #[test]
    fn song_time_follows_start_position() {
        assert!((song_time_s(52, 0) - 2.08).abs() < 1e-12);
        assert!((song_time_s(52, 25) - 3.08).abs() < 1e-12);
    }

    #[test]
    fn windows_cover_the_motion_without_overrun() {
        let w = window_starts(10, 4, 3);
        assert_eq!(w, vec![0..4, 3..7, 6..10]);
        assert!(window_starts(3, 4, 1).is_empty());
    }

    #[test]
    fn norm_stats_round_trip() {
        let a = ndarray::array![[1.0f32, 5.0], [3.0, 5.0]];
        let s = NormStats::fit([&a]).expect("fit");
        assert_eq!(s.mean, vec![2.0, 5.0]);
        assert!((s.std[0] - 1.0).abs() < 1e-6);
        assert_eq!(s.std[1], NormStats::MIN_STD);
        let n = s.normalize(&a).expect("normalize");
        let back = s.denormalize(&n).expect("denormalize");
        assert!(back.iter().zip(a.iter()).all(|(x, y)| (x - y).abs() < 1e-6));
    }

    #[test]
    fn missing_dataset_names_the_path() {
        let err = Dataset::open(Path::new("/nonexistent/shared/data")).unwrap_err();
        assert!(matches!(err, MotionError::DatasetMissing { .. }));
        assert!(err.to_string().contains("/nonexistent/shared/data"));
    }
}
