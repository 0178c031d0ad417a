//! Real clips of the train split in a model's own feature rows, which a sampled model continues
//! from when the request brings no seed motion (DanceNet, TSMT): a dance started from one fixed
//! pose would begin every song the same way.
//!
//! A clip was first drawn by the job's seed alone ([`SeedClips::pick`]), and the opening of a
//! dance is its context's continuation: DanceNet with seed 1 danced the 5-s trumpet loop and the
//! first 5 s of another song 0.015 m apart (root-relative; two real dances are 0.34 m apart).
//! Clips kept with their sources (`seed_clips.json`: the train dance, its style and its song's
//! tempo) are chosen by the song too ([`SeedClips::pick_for`]): among the clips of the style
//! danced, those whose song's tempo is nearest the new song's (as keypose-transformer's pose bank
//! ranks its clips, at ½, 1 or 2 of their own pace), and among those the draw of the seed and
//! the song together, so one seed dances different openings to different songs and two seeds
//! different openings to one song.
use std::path::{Path, PathBuf};

use ndarray::{s, Array2, Array3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use super::{DanceStyle, ModelError};
use crate::audio::Analysis;

/// Real seed clips (`[clips, frames, width]` feature rows), for models that start from one.
pub const SEED_CLIPS_FILE: &str = "seed_clips.safetensors";
/// Where each seed clip came from ([`SeedClipsMeta`]), beside [`SEED_CLIPS_FILE`].
pub const SEED_CLIPS_META_FILE: &str = "seed_clips.json";

/// Clips whose tempo is within this (|log₂| of the pace) of the best are all good candidates.
const PACE_MARGIN: f64 = 0.15;
/// Good candidates the seed and song choose among, at least (when that many clips match).
const MIN_CANDIDATES: usize = 4;

/// One clip's source.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeedClipSource {
    /// Train dance id (`DANCE_W_3`).
    pub dance: String,
    /// The clip's first row in that dance's feature rows.
    pub start: usize,
    pub style: DanceStyle,
    /// The tempo of the dance's whole song (`audio::analyze`).
    pub tempo_bpm: f64,
}

/// `seed_clips.json`: how the clips were drawn and each one's source, in the clips' order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeedClipsMeta {
    pub made_by: String,
    pub clips: Vec<SeedClipSource>,
}

/// What the clip choice hears of a song.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SongCue {
    /// The style danced (the request's, or the model's classifier's); none: any clip's.
    pub style: Option<DanceStyle>,
    pub tempo_bpm: f64,
    /// A number that differs between songs ([`SongCue::of`]), mixed into the seed's draw.
    pub fingerprint: u64,
}

impl SongCue {
    /// The cue of a song from its analysis. The fingerprint is FNV-1a over the beat times in
    /// milliseconds: the same decoded song always gives the same one, and two songs share it only
    /// if every beat falls on the same millisecond. (Hand-written because std's hasher may change
    /// between Rust releases, and a served dance must not.)
    pub fn of(analysis: &Analysis, style: Option<DanceStyle>) -> Self {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for t in &analysis.beat_times {
            for b in ((t * 1000.0).round() as i64).to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        }
        Self {
            style,
            tempo_bpm: analysis.tempo_bpm,
            fingerprint: h,
        }
    }
}

/// Real clips a job's seed (and song) draws from.
#[derive(Clone, Debug)]
pub struct SeedClips {
    /// `[clips, frames, width]`.
    pub clips: Array3<f32>,
    /// `(sequence, first row)` of each clip as [`Self::draw`] took it; empty when loaded.
    pub drawn: Vec<(usize, usize)>,
    /// Each clip's source, when the folder keeps [`SEED_CLIPS_META_FILE`].
    pub meta: Option<SeedClipsMeta>,
}

impl SeedClips {
    /// `count` clips of `frames` frames at seeded starts over `seqs` (each a dance's features).
    pub fn draw(
        seqs: &[&Array2<f32>],
        count: usize,
        frames: usize,
        seed: u64,
    ) -> Result<Self, ModelError> {
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
        let mut drawn = Vec::with_capacity(count);
        for k in 0..count {
            let i = usable[k % usable.len()];
            let s = seqs[i];
            let start = rng.gen_range(25..s.nrows() - frames - 25);
            clips
                .slice_mut(s![k, .., ..])
                .assign(&s.slice(s![start..start + frames, ..]));
            drawn.push((i, start));
        }
        Ok(Self {
            clips,
            drawn,
            meta: None,
        })
    }

    /// The clips with their sources; refused unless there is one source per clip.
    pub fn with_meta(mut self, meta: SeedClipsMeta) -> Result<Self, ModelError> {
        if meta.clips.len() != self.clips.dim().0 {
            return Err(ModelError::BadModelFile(format!(
                "{SEED_CLIPS_META_FILE}: {} sources for {} clips",
                meta.clips.len(),
                self.clips.dim().0
            )));
        }
        self.meta = Some(meta);
        Ok(self)
    }

    fn meta_path(path: &Path) -> PathBuf {
        path.with_file_name(SEED_CLIPS_META_FILE)
    }

    /// Writes the clips as safetensors, and their sources (when known) beside them.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        super::folder::write_clips(&self.clips, path)?;
        if let Some(meta) = &self.meta {
            let text = serde_json::to_string_pretty(meta)
                .map_err(|e| ModelError::BadModelFile(e.to_string()))?;
            let meta_path = Self::meta_path(path);
            std::fs::write(&meta_path, text)
                .map_err(|e| ModelError::BadModelFile(format!("{}: {e}", meta_path.display())))?;
        }
        Ok(())
    }

    /// Reads clips written by [`Self::save`], `width` numbers a frame, with their sources when
    /// the folder has them.
    pub fn load(path: &Path, width: usize) -> Result<Self, ModelError> {
        let clips = super::folder::read_clips(path)?;
        let (k, f, d) = clips.dim();
        if d != width || k == 0 || f == 0 {
            return Err(ModelError::BadModelFile(format!(
                "{}: clips are {k}×{f}×{d}",
                path.display()
            )));
        }
        let loaded = Self {
            clips,
            drawn: Vec::new(),
            meta: None,
        };
        let meta_path = Self::meta_path(path);
        if !meta_path.exists() {
            return Ok(loaded);
        }
        let text = std::fs::read_to_string(&meta_path)
            .map_err(|e| ModelError::BadModelFile(format!("{}: {e}", meta_path.display())))?;
        let meta: SeedClipsMeta = serde_json::from_str(&text)
            .map_err(|e| ModelError::BadModelFile(format!("{}: {e}", meta_path.display())))?;
        loaded.with_meta(meta)
    }

    /// The clip a job's seed picks, whatever the song (clips without sources).
    pub fn pick(&self, seed: u64) -> Array2<f32> {
        let k = StdRng::seed_from_u64(seed ^ 0x5EED_C11F).gen_range(0..self.clips.dim().0);
        self.clips.slice(s![k, .., ..]).to_owned()
    }

    /// The clip a job's seed picks for the song of `cue` (module doc), and its index; the seed
    /// alone ([`Self::pick`]'s choice) when the clips have no sources.
    pub fn pick_for(&self, seed: u64, cue: &SongCue) -> (usize, Array2<f32>) {
        let k = match &self.meta {
            None => StdRng::seed_from_u64(seed ^ 0x5EED_C11F).gen_range(0..self.clips.dim().0),
            Some(meta) => {
                let good = candidates(meta, cue);
                let mut rng = StdRng::seed_from_u64(seed ^ 0x5EED_C11F ^ cue.fingerprint);
                good[rng.gen_range(0..good.len())]
            }
        };
        (k, self.clips.slice(s![k, .., ..]).to_owned())
    }
}

/// The clips that suit `cue`: of its style (all clips when none is), ranked by pace (the
/// |log₂| of the clip's song tempo, at ½, 1 or 2 times, over the song's), those within
/// [`PACE_MARGIN`] of the best and at least [`MIN_CANDIDATES`]. Never empty for non-empty meta.
fn candidates(meta: &SeedClipsMeta, cue: &SongCue) -> Vec<usize> {
    let of_style: Vec<usize> = (0..meta.clips.len())
        .filter(|&k| cue.style.is_none_or(|s| meta.clips[k].style == s))
        .collect();
    let pool = if of_style.is_empty() {
        (0..meta.clips.len()).collect()
    } else {
        of_style
    };
    let pace = |k: usize| -> f64 {
        let t = meta.clips[k].tempo_bpm;
        if t <= 0.0 || cue.tempo_bpm <= 0.0 {
            return 0.0;
        }
        [0.5, 1.0, 2.0]
            .iter()
            .map(|u| (u * t / cue.tempo_bpm).log2().abs())
            .fold(f64::INFINITY, f64::min)
    };
    let mut ranked: Vec<(usize, f64)> = pool.into_iter().map(|k| (k, pace(k))).collect();
    ranked.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    let best = ranked.first().map_or(0.0, |r| r.1);
    let within = ranked.iter().filter(|r| r.1 <= best + PACE_MARGIN).count();
    ranked
        .into_iter()
        .take(within.max(MIN_CANDIDATES))
        .map(|r| r.0)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clips_with(sources: &[(DanceStyle, f64)]) -> SeedClips {
        let n = sources.len();
        let clips = Array3::from_shape_fn((n, 3, 2), |(k, _, _)| k as f32);
        let meta = SeedClipsMeta {
            made_by: "test".into(),
            clips: sources
                .iter()
                .enumerate()
                .map(|(k, (style, tempo_bpm))| SeedClipSource {
                    dance: format!("D{k}"),
                    start: 0,
                    style: *style,
                    tempo_bpm: *tempo_bpm,
                })
                .collect(),
        };
        SeedClips {
            clips,
            drawn: Vec::new(),
            meta: None,
        }
        .with_meta(meta)
        .unwrap()
    }

    fn cue(style: Option<DanceStyle>, tempo_bpm: f64, fingerprint: u64) -> SongCue {
        SongCue {
            style,
            tempo_bpm,
            fingerprint,
        }
    }

    #[test]
    fn the_clip_is_of_the_style_danced_and_near_the_songs_tempo() {
        use DanceStyle::*;
        // Four waltzes near 87 BPM, a slow waltz, three cha-chas near 120 and a rumba.
        let c = clips_with(&[
            (Waltz, 86.0),
            (Waltz, 88.0),
            (Waltz, 87.0),
            (Waltz, 89.0),
            (Waltz, 60.0),
            (ChaCha, 120.0),
            (ChaCha, 124.0),
            (ChaCha, 118.0),
            (Rumba, 92.0),
        ]);
        for seed in 0..40 {
            let (k, rows) = c.pick_for(seed, &cue(Some(Waltz), 87.0, 7));
            assert!(k < 4, "seed {seed}: clip {k}");
            assert_eq!(rows[[0, 0]], k as f32);
            // A song at twice the tempo is danced at half its pace: the same waltzes.
            assert!(c.pick_for(seed, &cue(Some(Waltz), 174.0, 7)).0 < 4);
            // Fewer good clips than the minimum: the nearest others fill in.
            let (k, _) = c.pick_for(seed, &cue(Some(ChaCha), 120.0, 7));
            assert!((5..8).contains(&k), "seed {seed}: clip {k}");
        }
        // No clip of the style: any clip, still by pace (the rumba and its neighbours).
        assert!(c.pick_for(1, &cue(Some(Tango), 92.0, 7)).0 < 9);
    }

    #[test]
    fn one_seed_draws_different_clips_for_different_songs_and_the_same_for_one() {
        use DanceStyle::*;
        let c = clips_with(&[(Waltz, 87.0); 8]);
        let song = |f| cue(Some(Waltz), 87.0, f);
        assert_eq!(c.pick_for(3, &song(11)).0, c.pick_for(3, &song(11)).0);
        let by_song: std::collections::BTreeSet<usize> =
            (0..20u64).map(|f| c.pick_for(3, &song(f)).0).collect();
        assert!(by_song.len() > 3, "{by_song:?}");
        let by_seed: std::collections::BTreeSet<usize> =
            (0..20u64).map(|s| c.pick_for(s, &song(11)).0).collect();
        assert!(by_seed.len() > 3, "{by_seed:?}");
    }

    #[test]
    fn clips_without_sources_are_picked_by_the_seed_alone() {
        let c = SeedClips {
            clips: Array3::from_shape_fn((6, 2, 1), |(k, _, _)| k as f32),
            drawn: Vec::new(),
            meta: None,
        };
        for seed in 0..10 {
            let (k, rows) = c.pick_for(seed, &cue(None, 100.0, seed * 31 + 5));
            assert_eq!(rows, c.pick(seed));
            assert_eq!(rows[[0, 0]], k as f32);
        }
    }

    #[test]
    fn the_fingerprint_tells_songs_apart_and_is_stable() {
        let a = Analysis {
            tempo_bpm: 120.0,
            beat_times: vec![0.5, 1.0, 1.5, 2.0],
            downbeat_times: vec![0.5],
        };
        let mut b = a.clone();
        b.beat_times[2] = 1.51;
        assert_eq!(SongCue::of(&a, None), SongCue::of(&a.clone(), None));
        assert_ne!(
            SongCue::of(&a, None).fingerprint,
            SongCue::of(&b, None).fingerprint
        );
        // FNV-1a of these beats (as Python's struct and int arithmetic give it), fixed so a
        // served dance cannot change with a Rust release.
        assert_eq!(SongCue::of(&a, None).fingerprint, 0x7413_60ce_aaef_2205);
    }

    #[test]
    fn sources_round_trip_beside_the_clips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(SEED_CLIPS_FILE);
        let c = clips_with(&[(DanceStyle::Rumba, 90.0), (DanceStyle::Waltz, 87.0)]);
        c.save(&path).unwrap();
        let back = SeedClips::load(&path, 2).unwrap();
        assert_eq!(back.clips, c.clips);
        assert_eq!(back.meta, c.meta);
        // Clips written without sources load without them.
        let other = dir.path().join("other").join(SEED_CLIPS_FILE);
        std::fs::create_dir_all(other.parent().unwrap()).unwrap();
        SeedClips { meta: None, ..c }.save(&other).unwrap();
        assert!(SeedClips::load(&other, 2).unwrap().meta.is_none());
    }
}
