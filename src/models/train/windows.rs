//! Training windows re-timed: windows drawn at a tempo factor and mirrored ([`Windows`]), and
//! whole dances re-timed to a reference tempo ([`Data::retime`], beat time).
use tch::Tensor;

use super::{augment, normalize_all, Data, TrainError};
use crate::models::beat_time::{self, BeatTime, BeatTimeConfig};
use crate::models::stretch;

impl Data {
    /// The beat-time reference of the train split: the median of its songs' folded tempi
    /// ([`beat_time::reference_bpm`]).
    pub fn reference_tempo(&self) -> Result<BeatTimeConfig, TrainError> {
        let hz: Vec<f64> = self.train_raw.iter().filter_map(|s| s.beat_hz).collect();
        let bpm = beat_time::reference_bpm(&hz).ok_or_else(|| {
            TrainError::InvalidOption("beat time: no train song has a tempo".into())
        })?;
        tracing::info!(bpm, songs = hz.len(), "beat time: reference tempo");
        Ok(BeatTimeConfig {
            bpm,
            max_factor: None,
        })
    }

    /// Re-times every dance of both splits, whole, to `config.bpm` ([`crate::models::beat_time`]:
    /// each song's tempo folded by octaves, the music's frames resampled as `layout` says, the
    /// motion with them) and normalises with the statistics already fitted, so a network
    /// continued from served weights reads its inputs on the same scale. Returns the reference.
    pub fn retime(&mut self, layout: &stretch::MusicLayout) -> Result<BeatTimeConfig, TrainError> {
        let config = self.reference_tempo()?;
        for s in self.train_raw.iter_mut().chain(self.test_raw.iter_mut()) {
            let Some(hz) = s.beat_hz else { continue };
            let f = beat_time::folded_factor(config.bpm, hz);
            let len = BeatTime::with_factor(f, s.poses.nrows()).net_frames;
            s.music = stretch::stretch_music(s.music.view(), 0, len, f, layout);
            s.poses = stretch::stretch_poses(s.poses.view(), 0, len, f);
            // The dance now beats at the reference tempo.
            s.beat_hz = Some(hz * f);
        }
        self.train = normalize_all(&self.train_raw, &self.music_norm, &self.pose_norm)?;
        self.test = normalize_all(&self.test_raw, &self.music_norm, &self.pose_norm)?;
        tracing::info!(
            bpm = config.bpm,
            "beat time: every dance re-timed to the reference tempo"
        );
        Ok(config)
    }
}

/// Training windows drawn from the raw train split, varied by [`augment::Augment`] and
/// normalised with the split's statistics.
pub struct Windows<'a> {
    data: &'a Data,
    layout: stretch::MusicLayout,
    augment: augment::Augment,
    partner: Vec<usize>,
    /// Each train dance re-timed to this reference tempo before the drawn factor
    /// ([`crate::models::beat_time`]); `None`: danced at its own tempo.
    beat_time: Option<BeatTimeConfig>,
}

impl<'a> Windows<'a> {
    pub fn new(data: &'a Data, layout: stretch::MusicLayout, augment: augment::Augment) -> Self {
        Self {
            data,
            layout,
            augment,
            partner: augment::mirror_joints(),
            beat_time: None,
        }
    }

    /// Windows in beat time: every train dance played at `config.bpm` (times the drawn factor).
    pub fn in_beat_time(mut self, config: BeatTimeConfig) -> Self {
        self.beat_time = Some(config);
        self
    }

    /// The tempo factor that re-times train dance `i` to the reference (1 outside beat time).
    fn dance_factor(&self, i: usize) -> f64 {
        match (self.beat_time, self.data.train_raw[i].beat_hz) {
            (Some(cfg), Some(hz)) => beat_time::folded_factor(cfg.bpm, hz),
            _ => 1.0,
        }
    }

    /// Source frames a window of `len` frames may span (the fastest drawn factor, re-timed).
    pub fn source_len(&self, len: usize) -> usize {
        let most = self
            .beat_time
            .map_or(1.0, |c| beat_time::max_factor(c.bpm).max(1.0));
        ((len.saturating_sub(1)) as f64 * most * self.augment.max_tempo.max(1.0)).ceil() as usize
            + 1
    }

    /// One window of `len` frames from frame `f0` of train dance `i`, at a drawn tempo and
    /// mirroring: its music and pose rows as the split holds them (not normalised). The start
    /// must leave [`Windows::source_len`] frames.
    pub fn raw_window(
        &self,
        i: usize,
        f0: usize,
        len: usize,
        rng: &mut impl rand::Rng,
    ) -> Result<(ndarray::Array2<f32>, ndarray::Array2<f32>), TrainError> {
        let seq = &self.data.train_raw[i];
        let (f, mirror) = self.augment.draw(rng);
        let f = f * self.dance_factor(i);
        let m = stretch::stretch_music(seq.music.view(), f0, len, f, &self.layout);
        let mut p = stretch::stretch_poses(seq.poses.view(), f0, len, f);
        if mirror {
            if p.ncols() != crate::motion::repr::FEATURE_DIM {
                return Err(TrainError::InvalidOption(format!(
                    "mirroring needs the {}-column pose rows, not {}",
                    crate::motion::repr::FEATURE_DIM,
                    p.ncols()
                )));
            }
            augment::mirror_poses(&mut p, &self.partner);
        }
        Ok((m, p))
    }

    /// `[b, len, ·]` normalised music and poses of the windows starting at `starts` (sequence,
    /// frame) of the raw train split, each at its own drawn tempo and mirroring
    /// ([`Windows::raw_window`]).
    pub fn train_batch(
        &self,
        starts: &[(usize, usize)],
        len: usize,
        rng: &mut impl rand::Rng,
    ) -> Result<(Tensor, Tensor), TrainError> {
        let (mut music, mut poses) = (
            Vec::with_capacity(starts.len()),
            Vec::with_capacity(starts.len()),
        );
        for &(i, f0) in starts {
            let (m, p) = self.raw_window(i, f0, len, rng)?;
            music.push(crate::models::to_tensor(
                &self.data.music_norm.normalize(&m)?,
            ));
            poses.push(crate::models::to_tensor(
                &self.data.pose_norm.normalize(&p)?,
            ));
        }
        Ok((Tensor::stack(&music, 0), Tensor::stack(&poses, 0)))
    }
}
