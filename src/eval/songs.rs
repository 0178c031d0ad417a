//! The songs of `choreo eval`: each test dance's song cut to the span the dance covers, the extra
//! songs whole, and the key poses drawn from a real dance.
use std::path::{Path, PathBuf};

use rand::seq::SliceRandom;
use rand::SeedableRng;

use super::EvalError;
use crate::audio::{self, DecodedAudio};
use crate::motion::dataset::Dance;
use crate::motion::{KeyPose, MOTION_FPS};

/// A song on a dance's clock: the audio of the segment and the beats within it.
pub(super) struct Song {
    pub(super) name: String,
    pub(super) audio: DecodedAudio,
    /// Beat times in seconds from the segment start.
    pub(super) beats: Vec<f64>,
}

/// The test dance's song cut to the span the dance covers, with beats from the whole song.
pub(super) fn song_segment(d: &Dance) -> Result<Song, EvalError> {
    let full = audio::decode_path(&d.audio_path)?;
    let analysis = audio::analyze(&full)?;
    let start = d.song_time_s(0);
    let dur = d.motion.duration_s();
    let sr = full.sample_rate as f64;
    let a = ((start * sr).round() as usize).min(full.samples.len());
    let b = (((start + dur) * sr).round() as usize).min(full.samples.len());
    let audio = DecodedAudio {
        samples: full.samples[a..b].to_vec(),
        duration_s: (b - a) as f64 / sr,
        ..full
    };
    let beats = analysis
        .beat_times
        .iter()
        .map(|t| t - start)
        .filter(|t| *t >= 0.0 && *t <= dur)
        .collect();
    Ok(Song {
        name: d.id.clone(),
        audio,
        beats,
    })
}

/// An extra song, whole.
pub(super) fn whole_song(path: &Path) -> Result<Song, EvalError> {
    let audio = audio::decode_path(path)?;
    let analysis = audio::analyze(&audio)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok(Song {
        name,
        audio,
        beats: analysis.beat_times,
    })
}
/// The audio files of a folder, sorted by name.
pub(super) fn songs_in(dir: &Path) -> Result<Vec<PathBuf>, EvalError> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| EvalError::Io {
            path: dir.to_path_buf(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && audio::decode_path(p).is_ok())
        .collect();
    paths.sort();
    Ok(paths)
}

/// `n` poses of a real dance (root-relative, metres) at distinct frames after its first second,
/// drawn by `seed`, in time order.
pub(super) fn key_poses_of(d: &Dance, n: usize, seed: u64) -> Vec<KeyPose> {
    let rel = d.root_relative();
    let first = MOTION_FPS as usize;
    let mut frames: Vec<usize> = (first..d.motion.num_frames()).collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    frames.shuffle(&mut rng);
    frames.truncate(n);
    frames.sort_unstable();
    frames
        .into_iter()
        .map(|f| KeyPose {
            time_s: f as f64 / d.motion.fps,
            joints: (0..rel.dim().1)
                .map(|j| [0, 1, 2].map(|a| f64::from(rel[[f, j, a]])))
                .collect(),
        })
        .collect()
}
