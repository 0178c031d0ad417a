//! Real clips chosen by the music, shared by keypose-transformer's scaffold and
//! TSMT's opening: each clip of a model's bank keeps where it came from and what its own song
//! did under it ([`ClipInfo`]: the train dance, its style, the song's beats on the clip's frames,
//! the meter and the energy), and a song ranks the clips by how well they would dance to it —
//! the pace the clip would be played at (its own beat period against the song's, at ½, 1 or 2
//! clip beats per song beat), the meter and the energy ([`ranked`]). The seed then draws among the
//! good few ([`good`]), so two seeds still dance differently while the song decides which clips
//! are in the draw: the same seed opens two songs of different tempo or meter with different
//! clips, where a draw by the seed alone opened every song alike.
use serde::{Deserialize, Serialize};

use crate::motion::dataset::Style;

/// Good candidates the seed chooses among, at least (when the bank holds that many).
pub const MIN_CANDIDATES: usize = 4;
/// Good candidates the seed chooses among, at most.
pub const MAX_CANDIDATES: usize = 8;
/// Candidates within this score of the best are all good.
pub const SCORE_MARGIN: f64 = 0.15;
/// Score added for a clip danced in another meter than the song's.
pub const METER_PENALTY: f64 = 0.2;
/// Weight of the energy term (|ln| of the song's local energy over the clip's music's).
pub const ENERGY_WEIGHT: f64 = 0.1;

/// One bank clip's source: the train dance, its first frame there, the dance's style, and the
/// beats of the dance's song on the clip's frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipInfo {
    /// Train dance id (`DANCE_W_3`).
    pub dance: String,
    /// The dance's motion frame of the clip's frame 0.
    pub start: usize,
    pub style: Style,
    /// Beats of the song (`audio::analyze`) on the clip's frames (fractional, ascending, within it).
    pub beats: Vec<f64>,
    /// Beats per bar of the song's analysis (3 or 4).
    pub bar: usize,
    /// Mean onset strength of the music under the clip (`audio::features::keypose`'s onset column).
    pub energy: f64,
}

impl ClipInfo {
    /// Median beat period, frames; none with fewer than two beats.
    pub fn period(&self) -> Option<f64> {
        crate::models::keypose_transformer::beats::median_step(&self.beats)
    }

    /// Beats per bar of the style: a waltz has three, the other styles four. The style is the
    /// dataset's own label; the song's analysis misreads 3 of 30 waltzes as 4/4.
    pub fn meter(&self) -> usize {
        if self.style == Style::Waltz {
            3
        } else {
            4
        }
    }

    /// The clip of `frames` frames from `start` of train dance `dance` (its `style`), its first
    /// frame `first_s` seconds into the dance's song: the song's beats ([`crate::audio::analyze`])
    /// put on the clip's frames at `fps`, its bar ([`bar_of`]) and the music's `energy` under it.
    #[allow(clippy::too_many_arguments)]
    pub fn of_song(
        dance: String,
        start: usize,
        style: Style,
        analysis: &crate::audio::Analysis,
        first_s: f64,
        fps: f64,
        frames: usize,
        energy: f64,
    ) -> Self {
        let beats = analysis
            .beat_times
            .iter()
            .map(|t| (t - first_s) * fps)
            .filter(|f| *f >= 0.0 && *f <= frames.saturating_sub(1) as f64)
            .collect();
        Self {
            dance,
            start,
            style,
            beats,
            bar: bar_of(analysis),
            energy,
        }
    }
}

/// `pose_bank.json`: how the bank was made, and every clip's [`ClipInfo`] (in the bank's order).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BankMeta {
    /// The command and settings that drew the bank.
    pub made_by: String,
    pub fps: f64,
    pub clips: Vec<ClipInfo>,
}

impl BankMeta {
    /// The description in `file` beside the clips file `path`, if there is one.
    pub fn read_beside(
        path: &std::path::Path,
        file: &str,
    ) -> Result<Option<Self>, crate::models::ModelError> {
        let meta_path = path.with_file_name(file);
        if !meta_path.exists() {
            return Ok(None);
        }
        let bad = |e: String| {
            crate::models::ModelError::BadModelFile(format!("{}: {e}", meta_path.display()))
        };
        let text = std::fs::read_to_string(&meta_path).map_err(|e| bad(e.to_string()))?;
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| bad(e.to_string()))
    }

    /// Writes the description as `file` beside the clips file `path`.
    pub fn write_beside(
        &self,
        path: &std::path::Path,
        file: &str,
    ) -> Result<(), crate::models::ModelError> {
        let bad = |e: String| crate::models::ModelError::BadModelFile(e);
        let text = serde_json::to_string_pretty(self).map_err(|e| bad(e.to_string()))?;
        std::fs::write(path.with_file_name(file), text + "\n").map_err(|e| bad(e.to_string()))
    }

    /// The description, checked against a bank of `clips` clips of `frames` frames read from
    /// `file` ([`Self::check`]).
    pub fn checked(
        self,
        clips: usize,
        frames: usize,
        file: &str,
    ) -> Result<Self, crate::models::ModelError> {
        self.check(clips, frames)
            .map_err(|e| crate::models::ModelError::BadModelFile(format!("{file}: {e}")))?;
        Ok(self)
    }

    /// Checks the description against a bank of `clips` clips of `frames` frames: one
    /// [`ClipInfo`] per clip, beats ascending within the clip, a finite energy. The error names
    /// what is wrong (the caller names the file).
    pub fn check(&self, clips: usize, frames: usize) -> Result<(), String> {
        if self.clips.len() != clips {
            return Err(format!(
                "describes {} clips, the bank holds {clips}",
                self.clips.len()
            ));
        }
        let bad = self.clips.iter().any(|c| {
            c.beats
                .iter()
                .any(|b| !b.is_finite() || *b < 0.0 || *b > frames.saturating_sub(1) as f64)
                || c.beats.windows(2).any(|p| p[1] <= p[0])
                || !c.energy.is_finite()
        });
        if bad {
            return Err("beats outside their clip, out of order, or a non-finite energy".into());
        }
        Ok(())
    }
}

/// Clips ranked by how well they suit a song whose beat period is `period` frames, with `bar`
/// beats a bar and local energy `energy` (the clips' measure; 0 or less: not known, no energy
/// term), best first: `(clip, u, score)`, `u` the clip beats per song beat it would dance at (½,
/// 1 or 2: the one that plays it nearest its own pace). The score adds the pace error
/// `|log₂ rate|`, a [`METER_PENALTY`] for another meter and the energy term. Clips with fewer
/// than two beats are left out.
pub fn ranked(clips: &[ClipInfo], period: f64, bar: usize, energy: f64) -> Vec<(usize, f64, f64)> {
    let mut out: Vec<(usize, f64, f64)> = clips
        .iter()
        .enumerate()
        .filter_map(|(c, info)| {
            let pc = info.period()?;
            // The clip plays at rate u·pc/period (clip frames per song frame).
            let (u, pace) = [0.5, 1.0, 2.0]
                .map(|u| (u, (u * pc / period).log2().abs()))
                .into_iter()
                .min_by(|a, b| a.1.total_cmp(&b.1))?;
            let meter = if info.meter() == bar {
                0.0
            } else {
                METER_PENALTY
            };
            let energy = if energy > 0.0 && info.energy > 0.0 {
                ENERGY_WEIGHT * (energy / info.energy).ln().abs()
            } else {
                0.0
            };
            Some((c, u, pace + meter + energy))
        })
        .collect();
    out.sort_by(|a, b| a.2.total_cmp(&b.2).then(a.0.cmp(&b.0)));
    out
}

/// The good candidates of a ranking: those within [`SCORE_MARGIN`] of the best, at least
/// [`MIN_CANDIDATES`] and at most [`MAX_CANDIDATES`]: `(clip, u)`.
pub fn good(ranked: &[(usize, f64, f64)]) -> Vec<(usize, f64)> {
    let Some(best) = ranked.first().map(|r| r.2) else {
        return Vec::new();
    };
    let within = ranked.iter().filter(|r| r.2 <= best + SCORE_MARGIN).count();
    ranked
        .iter()
        .take(within.clamp(MIN_CANDIDATES, MAX_CANDIDATES))
        .map(|r| (r.0, r.1))
        .collect()
}

/// Beats a bar of a song's analysis: 3 where the downbeats come every three beats (median
/// steps), else 4. The banks' clips were described with this rule, so a song is heard by it too.
pub fn bar_of(analysis: &crate::audio::Analysis) -> usize {
    use crate::models::keypose_transformer::beats::{beats_a_bar, median_step};
    median_step(&analysis.beat_times)
        .map_or(4, |b| beats_a_bar(median_step(&analysis.downbeat_times), b))
}

/// A song's median beat period in frames at `fps` and its beats a bar ([`bar_of`]); none with
/// fewer than two beats.
pub fn song_pace(analysis: &crate::audio::Analysis, fps: f64) -> Option<(f64, usize)> {
    let period =
        crate::models::keypose_transformer::beats::median_step(&analysis.beat_times)? * fps;
    Some((period, bar_of(analysis)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clip of `style` whose song beat every `period` frames over a 50-frame clip.
    fn clip(style: Style, period: f64) -> ClipInfo {
        ClipInfo {
            dance: "DANCE_X_1".into(),
            start: 0,
            style,
            beats: (0..)
                .map(|k| 1.0 + k as f64 * period)
                .take_while(|b| *b <= 49.0)
                .collect(),
            bar: if style == Style::Waltz { 3 } else { 4 },
            energy: 1.0,
        }
    }

    /// A cha-cha song (123 BPM: 12.2 frames a beat, four a bar) ranks the cha-cha clip first and
    /// plays it at its own pace; a waltz (86 BPM, three a bar) ranks the waltz clips first, the one
    /// counted in double time (8.7 frames) played at two of its beats per song beat.
    #[test]
    fn a_song_ranks_the_clips_of_its_pace_and_meter_first() {
        let clips = [
            clip(Style::Waltz, 17.4),
            clip(Style::ChaCha, 12.2),
            clip(Style::Rumba, 16.3),
            clip(Style::Waltz, 8.7),
        ];
        let chacha = ranked(&clips, 12.2, 4, 0.0);
        assert_eq!((chacha[0].0, chacha[0].1), (1, 1.0));
        assert!(chacha[0].2 < 1e-9, "{chacha:?}");
        let waltz = ranked(&clips, 17.2, 3, 0.0);
        let first: Vec<usize> = waltz.iter().take(2).map(|r| r.0).collect();
        assert_eq!(first, [0, 3], "{waltz:?}");
        assert_eq!(waltz[1].1, 2.0);
        // The rumba clip has nearly the waltz's pace, but not its meter.
        assert!(waltz[2].0 == 2 && waltz[2].2 >= METER_PENALTY, "{waltz:?}");
    }

    /// The seed draws among at least [`MIN_CANDIDATES`], at most [`MAX_CANDIDATES`]: those within
    /// [`SCORE_MARGIN`] of the best.
    #[test]
    fn the_good_candidates_are_the_best_few() {
        let ranked: Vec<(usize, f64, f64)> = (0..12).map(|c| (c, 1.0, c as f64 * 0.01)).collect();
        assert_eq!(good(&ranked).len(), MAX_CANDIDATES);
        let spread: Vec<(usize, f64, f64)> = (0..12).map(|c| (c, 1.0, c as f64)).collect();
        assert_eq!(good(&spread).len(), MIN_CANDIDATES);
        assert!(good(&[]).is_empty());
    }

    /// A description is refused when it does not fit its clips.
    #[test]
    fn a_description_that_does_not_fit_its_clips_is_refused() {
        let meta = BankMeta {
            made_by: "test".into(),
            fps: 25.0,
            clips: vec![clip(Style::Waltz, 17.4)],
        };
        assert!(meta.check(1, 50).is_ok());
        assert!(meta.check(2, 50).unwrap_err().contains("describes 1 clips"));
        assert!(meta.check(1, 20).unwrap_err().contains("outside"));
    }
}
