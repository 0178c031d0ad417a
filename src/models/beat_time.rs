//! Beat time: a network that runs on a clock of beats, not of seconds.
//!
//! Every network here learned one step rate per style, because the data's tempi cluster by style
//! (every waltz near 87 BPM, every cha-cha 115–127) and no figure was ever danced at two tempi.
//! Teaching the networks tempo through the input (a beat clock, time-stretched windows) did not
//! move their step rate (dance-revolution's card, runs 1–3). Beat time removes tempo from what a
//! network must learn instead: the song is heard at one reference tempo — its feature frames
//! resampled in time, which is what a tempo change does to onset, chroma and MFCC frames
//! ([`crate::models::stretch::stretch_music`]) — the network makes its motion on that
//! clock, and the motion is played back at the song's own tempo. A step the network makes every
//! k of its frames is then the same fraction of a beat on any song, so the network's own motion
//! follows the tempo. Training on dances re-timed the same way (`choreo train … --beat-time
//! true`: [`crate::models::train::Data::retime`], [`crate::models::train::Windows::in_beat_time`])
//! would make that fraction the data's own; the fine-tunes tried so far made the motion less
//! regular (the model cards), so the served weights were trained in seconds and run in beat time.
//!
//! It is one uniform change of time base per song, not an alignment: where the song's beats
//! drift, [`crate::motion::beat_align`] is still the stage that follows them.
use ndarray::{Array2, ArrayView2};
use serde::{Deserialize, Serialize};

use super::stretch::{stretch_music, MusicLayout};
use super::ModelError;
use crate::motion::input::lerp_frames;
use crate::motion::Motion;

/// `model.json`'s `"beat_time"`: the tempo the network hears every song at.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct BeatTimeConfig {
    /// Reference tempo (beats per minute): the median tempo of the train split's songs as the
    /// service's own beat tracker hears them, so the train dances move least when re-timed.
    pub bpm: f64,
    /// The largest factor a served song is heard at (absent: the fold's own, `bpm / 60`). 1 means
    /// a song that folds below the reference is danced at the network's own pace, never slowed
    /// ([`serving_factor`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_factor: Option<f64>,
}

/// The clock a job's network ran on, as `report.json` says it (`beat_time`; models in beat
/// time only).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct BeatTimeUsed {
    /// The tempo the network hears every song at (`model.json`'s `beat_time.bpm`).
    pub reference_bpm: f64,
    /// The factor this song was heard at: network frame `j` is song frame `j · factor` (above 1
    /// the song was heard faster than it is, below 1 slower; 1 as it is: the song's folded tempo
    /// is the reference's, or under it where the model's `max_factor` keeps it from being slowed).
    pub factor: f64,
}

/// The tempo window (BPM) a song's tracked tempo is folded into by octaves: `[FOLD_LO_BPM,
/// FOLD_HI_BPM)`. Trackers count many songs in double time: ours reads 8 of the train split's
/// 15 waltzes at 174 BPM, not 87, and the shared trumpet loop (90 BPM) at 185. Folded, such a
/// song is heard at its own tempo and a train dance is re-timed like the others of its style; a
/// dancer, too, dances a song that fast in half time. The window holds every tempo of the data
/// (waltz 87, rumba 87–96, cha-cha 115–130), so the network hears the data's songs as they are.
///
/// It is wider than an octave (2.5×): between 60 and 75 BPM, and between 120 and 150, both
/// octaves are tempi songs have, and there the tracker's reading is kept. With an octave window
/// from 75, a song heard at 74 BPM (the test waltzes at 0.85×) was doubled to 148 and its dance
/// played back 1.7 times as fast as the network made it (dance-revolution: arms 0.96–1.0 m/s
/// there, 0.71–0.74 on the same songs at 1.2×), while one at 76 BPM was danced as made. The
/// tracker does not count slow songs in half time the way it counts fast ones in double time
/// (its prior centres on 120 BPM), so a slow reading is taken as it is.
///
/// The price: a song near 150 BPM and its 0.85× or 1.2× copy can fold to opposite ends (the
/// shared songs at 153 and 130 BPM do), and the faster copy is then danced in half time.
pub const FOLD_LO_BPM: f64 = 60.0;

/// The window's top (BPM), see [`FOLD_LO_BPM`]: a song at or above it is halved until under it.
pub const FOLD_HI_BPM: f64 = 150.0;

/// The tempo (BPM) of `beat_hz` folded by octaves into `[FOLD_LO_BPM, FOLD_HI_BPM)`.
pub fn folded_bpm(beat_hz: f64) -> Option<f64> {
    let mut bpm = beat_hz * 60.0;
    if !(bpm.is_finite() && bpm > 0.0) {
        return None;
    }
    while bpm >= FOLD_HI_BPM {
        bpm /= 2.0;
    }
    while bpm < FOLD_LO_BPM {
        bpm *= 2.0;
    }
    Some(bpm)
}

/// The factor that plays a song of `beat_hz` beats per second (folded, [`folded_bpm`]) at `bpm`.
pub fn folded_factor(bpm: f64, beat_hz: f64) -> f64 {
    folded_bpm(beat_hz).map_or(1.0, |song| bpm / song)
}

/// The factor a served song is heard at: [`folded_factor`], at most `config.max_factor`. The data
/// has no dance slower than 87 BPM (its waltzes), so a song that folds below the reference is
/// heard slower than any the network learned from and its motion is played back slowed: a network
/// whose motion is barely above the verdict's 0.5-m/s floor in seconds (dance-revolution, 0.51–0.59)
/// then falls below it (0.44 m/s on the shared 153-BPM song folded to 77), so its model.json caps
/// the factor at 1.
pub fn serving_factor(config: BeatTimeConfig, beat_hz: f64) -> f64 {
    let f = folded_factor(config.bpm, beat_hz);
    config.max_factor.map_or(f, |m| f.min(m))
}

/// The largest factor [`folded_factor`] gives for a reference of `bpm`.
pub fn max_factor(bpm: f64) -> f64 {
    bpm / FOLD_LO_BPM
}

/// The reference tempo of a train split: the median of its songs' folded tempi (BPM).
pub fn reference_bpm(beat_hz: &[f64]) -> Option<f64> {
    let mut bpm: Vec<f64> = beat_hz.iter().filter_map(|&h| folded_bpm(h)).collect();
    if bpm.is_empty() {
        return None;
    }
    bpm.sort_by(f64::total_cmp);
    Some(bpm[bpm.len() / 2])
}

/// The time base of one dance: song frames ↔ network frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BeatTime {
    /// Tempo factor: network frame `j` is song frame `j · factor` (> 1: the song is slower than
    /// the reference, and is heard faster).
    pub factor: f64,
    /// Frames of the dance the user gets.
    pub song_frames: usize,
    /// Frames the network makes.
    pub net_frames: usize,
}

impl BeatTime {
    /// The identity: the network runs in seconds.
    pub fn seconds(song_frames: usize) -> Self {
        Self {
            factor: 1.0,
            song_frames,
            net_frames: song_frames,
        }
    }

    /// The time base that plays a song of `beat_times_s` (the analysis's) at `config.bpm`.
    /// Without a config, or without a tempo to read (fewer than 4 beats), the identity.
    pub fn plan(
        config: Option<BeatTimeConfig>,
        beat_times_s: &[f64],
        duration_s: f64,
        song_frames: usize,
    ) -> Self {
        let Some(cfg) = config else {
            return Self::seconds(song_frames);
        };
        let Some(beat_hz) = crate::metrics::musicality::beat_rate_hz(beat_times_s, duration_s)
        else {
            return Self::seconds(song_frames);
        };
        Self::with_factor(serving_factor(cfg, beat_hz), song_frames)
    }

    /// [`Self::plan`] for a request of `song_frames` frames (its analysis, or the song analysed
    /// here when the caller brought none and a config asks for beat time).
    pub fn for_request(
        config: Option<BeatTimeConfig>,
        req: &super::GenerateRequest<'_>,
        song_frames: usize,
    ) -> Result<Self, ModelError> {
        Ok(match config {
            Some(_) => Self::plan(
                config,
                &req.analysis_or_analyze()?.beat_times,
                req.audio.duration_s(),
                song_frames,
            ),
            None => Self::seconds(song_frames),
        })
    }

    /// The time base at a given factor.
    pub fn with_factor(factor: f64, song_frames: usize) -> Self {
        let net_frames = if song_frames == 0 {
            0
        } else {
            ((song_frames - 1) as f64 / factor + 1e-9).floor() as usize + 1
        };
        Self {
            factor,
            song_frames,
            net_frames,
        }
    }

    /// What `report.json` says of this clock for a model whose `model.json` has `config`; none
    /// for a model in seconds.
    pub fn used(&self, config: Option<BeatTimeConfig>) -> Option<BeatTimeUsed> {
        config.map(|c| BeatTimeUsed {
            reference_bpm: c.bpm,
            factor: self.factor,
        })
    }

    /// True when the network runs in seconds (nothing to resample).
    pub fn is_identity(&self) -> bool {
        (self.factor - 1.0).abs() < 1e-12
    }

    /// The song's feature rows (`song_frames` of them) as the network hears them.
    pub fn music(&self, song: ArrayView2<'_, f32>, layout: &MusicLayout) -> Array2<f32> {
        if self.is_identity() {
            return song.to_owned();
        }
        stretch_music(song, 0, self.net_frames, self.factor, layout)
    }

    /// Frames a seed motion of `seed_frames` song frames takes on the network's clock.
    ///
    /// It spans the whole seed, its last network frame at or past the seed's last frame (held
    /// there): played back, every song frame the seed covers then lies between two kept seed
    /// frames. Rounded down, the seed's last song frame fell between the last kept frame and the
    /// network's first drawn one, and a given seed motion no longer opened the dance as given.
    pub fn seed_frames(&self, seed_frames: usize) -> usize {
        if self.is_identity() {
            return seed_frames;
        }
        (seed_frames.saturating_sub(1) as f64 / self.factor - 1e-9).ceil() as usize + 1
    }

    /// A seed motion on the network's clock ([`Self::seed_frames`] frames).
    pub fn seed_motion(&self, m: &Motion) -> Motion {
        if self.is_identity() {
            return m.clone();
        }
        let n = self.seed_frames(m.num_frames());
        Motion {
            fps: m.fps,
            positions: lerp_frames(m.positions.view(), (0..n).map(|t| t as f64 * self.factor)),
        }
    }

    /// The network's motion played back at the song's tempo: `song_frames` frames.
    pub fn back(&self, m: Motion) -> Motion {
        if self.is_identity() {
            return m;
        }
        Motion {
            fps: m.fps,
            positions: lerp_frames(
                m.positions.view(),
                (0..self.song_frames).map(|t| t as f64 / self.factor),
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    #[test]
    fn a_fast_song_is_heard_slower_and_played_back_at_its_length() {
        // Beats every 0.5 s (120 BPM) against a 100-BPM reference: factor 5/6.
        let beats: Vec<f64> = (0..60).map(|i| 0.25 + 0.5 * i as f64).collect();
        let bt = BeatTime::plan(
            Some(BeatTimeConfig {
                bpm: 100.0,
                max_factor: None,
            }),
            &beats,
            30.0,
            751,
        );
        assert!((bt.factor - 100.0 / 120.0).abs() < 1e-9, "{}", bt.factor);
        assert_eq!(bt.net_frames, 901);
        // A step every 30 network frames (1.2 s at 25 fps = 2 beats at 100 BPM) comes back every
        // 25 song frames: 1 s = 2 beats at 120 BPM.
        let mut net = Array3::<f32>::zeros((bt.net_frames, 1, 3));
        for t in 0..bt.net_frames {
            net[[t, 0, 0]] = (std::f64::consts::TAU * t as f64 / 30.0).cos() as f32;
        }
        let out = bt.back(Motion {
            fps: 25.0,
            positions: net,
        });
        assert_eq!(out.positions.shape()[0], 751);
        for k in 0..30 {
            assert!(
                (out.positions[[25 * k, 0, 0]] - 1.0).abs() < 1e-3,
                "frame {}",
                25 * k
            );
            assert!(
                out.positions[[25 * k + 12, 0, 0]] < -0.9,
                "frame {}",
                25 * k + 12
            );
        }
    }

    #[test]
    fn double_time_folds_into_the_window_and_no_config_is_seconds() {
        let beats: Vec<f64> = (0..80).map(|i| 0.3 * i as f64).collect(); // 200 BPM → 100
        let bt = BeatTime::plan(
            Some(BeatTimeConfig {
                bpm: 100.0,
                max_factor: None,
            }),
            &beats,
            24.0,
            600,
        );
        assert!((bt.factor - 1.0).abs() < 1e-9, "{}", bt.factor);
        // 130 BPM (a fast cha-cha) stays; 174 (a waltz counted in double time) is 87; a slow
        // song at 72 stays (it was doubled to 144 and danced 1.7 times as fast); 50 is 100.
        assert!((folded_factor(87.0, 130.0 / 60.0) - 87.0 / 130.0).abs() < 1e-12);
        assert!((folded_factor(87.0, 174.0 / 60.0) - 1.0).abs() < 1e-12);
        assert!((folded_factor(87.0, 72.0 / 60.0) - 87.0 / 72.0).abs() < 1e-12);
        assert!((folded_factor(87.0, 50.0 / 60.0) - 87.0 / 100.0).abs() < 1e-12);
        assert_eq!(folded_bpm(150.0 / 60.0), Some(75.0));
        assert_eq!(folded_bpm(60.0 / 60.0), Some(60.0));
        assert!((reference_bpm(&[1.45, 2.9, 2.1, 1.5, 1.45]).unwrap() - 87.0).abs() < 1e-9);
        // Capped at 1, a song slower than the reference is danced at the network's own pace.
        let capped = BeatTimeConfig {
            bpm: 87.0,
            max_factor: Some(1.0),
        };
        assert_eq!(serving_factor(capped, 80.0 / 60.0), 1.0);
        assert!((serving_factor(capped, 116.0 / 60.0) - 0.75).abs() < 1e-12);
        let free = BeatTimeConfig {
            max_factor: None,
            ..capped
        };
        assert!((serving_factor(free, 80.0 / 60.0) - 87.0 / 80.0).abs() < 1e-12);
        assert!(BeatTime::plan(None, &beats, 24.0, 600).is_identity());
        assert!(BeatTime::plan(
            Some(BeatTimeConfig {
                bpm: 100.0,
                max_factor: None
            }),
            &[1.0],
            24.0,
            600
        )
        .is_identity());
    }

    #[test]
    fn a_seed_motion_covers_its_song_frames_on_the_network_clock() {
        for factor in [0.8, 1.1, 1.16] {
            let bt = BeatTime::with_factor(factor, 500);
            let seed = Motion {
                fps: 25.0,
                positions: Array3::from_shape_fn((25, 1, 3), |(t, _, _)| t as f32),
            };
            let net = bt.seed_motion(&seed);
            assert_eq!(net.num_frames(), bt.seed_frames(25));
            let last = (net.positions.shape()[0] - 1) as f64;
            // Song frame 24 reads network time 24 / factor, which must lie within the seed.
            assert!(last >= 24.0 / factor - 1e-9, "factor {factor}: {last}");
            // Played back, the seed comes back within a quarter of a frame's motion (the last
            // network frame holds the seed's end, so the last song frame reads a blend of it).
            let back = bt.back(net);
            for t in 0..25 {
                assert!(
                    (back.positions[[t, 0, 0]] - t as f32).abs() < 0.25,
                    "{factor} {t}"
                );
            }
        }
    }
}
