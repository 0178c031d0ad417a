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

/// Songs of one file name from several folders (the dataset's `audio.mp3`) are told apart by
/// their folder's name: `DANCE_C_8_audio.mp3`. Others keep their file name.
pub(super) fn name_apart(songs: &mut [Song], paths: &[PathBuf]) {
    let names: Vec<String> = songs.iter().map(|s| s.name.clone()).collect();
    for (song, path) in songs.iter_mut().zip(paths) {
        let shared = names.iter().filter(|n| **n == song.name).count() > 1;
        if let Some(folder) = path.parent().and_then(|d| d.file_name()).filter(|_| shared) {
            song.name = format!("{}_{}", folder.to_string_lossy(), song.name);
        }
    }
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
/// The audio files of a folder, sorted by name; a file given itself is that one song.
pub(super) fn songs_in(dir: &Path) -> Result<Vec<PathBuf>, EvalError> {
    if dir.is_file() {
        return Ok(vec![dir.to_path_buf()]);
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn song(name: &str) -> Song {
        Song {
            name: name.into(),
            audio: DecodedAudio {
                format: audio::AudioFormat::Wav,
                sample_rate: 22050,
                channels: 1,
                duration_s: 0.0,
                samples: Vec::new(),
            },
            beats: Vec::new(),
        }
    }

    #[test]
    fn songs_of_one_file_name_are_named_by_their_folder() {
        let mut songs = vec![song("audio.mp3"), song("audio.mp3"), song("vibe_ace.ogg")];
        let paths = [
            "data/DANCE_C_8/audio.mp3",
            "data/DANCE_W_3/audio.mp3",
            "audio/vibe_ace.ogg",
        ]
        .map(PathBuf::from);
        name_apart(&mut songs, &paths);
        let names: Vec<&str> = songs.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            ["DANCE_C_8_audio.mp3", "DANCE_W_3_audio.mp3", "vibe_ace.ogg"]
        );
    }

    #[test]
    fn a_file_given_itself_is_one_song() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml");
        assert_eq!(songs_in(&file).unwrap(), vec![file]);
    }
}
