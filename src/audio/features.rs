//! One named feature set per model, time-major `[n_frames, dim]`, at any motion frame rate.
//!
//! # Alignment
//! A feature set at `fps` is computed at sample rate `sr = fps · hop` with a centred STFT, so
//! STFT frame j is centred on sample `j · hop`, i.e. time `j / fps` exactly. `hop` is 512
//! (librosa's default) doubled until `sr ≥ 12 kHz`, so that the 7-octave CQT from C1 fits
//! below Nyquist: 15 fps → hop 1024, 15 360 Hz; 25 fps → 512, 12 800 Hz; 30 → 512, 15 360 Hz;
//! 60 → 512, 30 720 Hz. `fps · hop` must be a whole number of Hz.
//!
//! Row i of a set built with `start_s` is the music at time `start_s + i / fps` (the dataset's
//! motion frame i is danced at `(start_position + i) / 25` s, so pass `start_position / 25`).
//! When `start_s · fps` is whole the rows are a slice of the whole-song features (beat
//! tracking and the tempogram see the whole song); otherwise the song is cut at
//! `round(start_s · sr)` samples first. Rows past the end of the song are computed from
//! silence appended to the song, so every set has exactly `n_frames` rows.
use std::borrow::Cow;
use std::ops::Range;

use ndarray::{s, Array2, ArrayViewMut1};

use super::chroma::{chroma_cqt, chroma_stft};
use super::dsp::{self, delta, mfcc_from_db, power_to_db_inplace, power_to_db_ref_max_inplace};
use super::onset::{hpss_signal, onset_strength, onset_strength_from_db, Aggregate};
use super::rhythm::{beat_track_frames, downbeats, tempo, tempogram};
use super::{resample, AudioError, DecodedAudio, N_FFT, N_MELS};

/// Tempogram window (frames) of the DanceRevolution set (librosa's default `win_length`).
pub const TEMPOGRAM_BINS: usize = 384;
/// Lowest analysis rate for feature sets (the CQT needs ≥ 4.2 kHz below Nyquist).
pub const MIN_FEATURE_SR: f64 = 12_000.0;

/// Columns of the DanceRevolution set, 438-d.
pub mod dance_revolution_cols {
    use std::ops::Range;
    /// MFCC 0..20 (mel dB re max).
    pub const MFCC: Range<usize> = 0..20;
    /// ΔMFCC (width 3, as the paper's code).
    pub const DMFCC: Range<usize> = 20..40;
    /// CQT chroma of the harmonic part, C first.
    pub const CHROMA: Range<usize> = 40..52;
    /// Autocorrelation tempogram of the onset envelope, 384 lags.
    pub const TEMPOGRAM: Range<usize> = 52..436;
    /// Onset strength of the percussive part (median over mel bands).
    pub const ONSET: usize = 436;
    /// Beat one-hot.
    pub const BEAT: usize = 437;
    /// Width of the set.
    pub const DIM: usize = 438;
    /// The beat clock ([`crate::audio::clock`]) after the paper's columns, when a model's
    /// configuration asks for it ([`super::dance_revolution_clock_at`]).
    pub const CLOCK: Range<usize> = 438..443;
    /// Width of the set with the clock.
    pub const DIM_WITH_CLOCK: usize = 443;
}

/// Width of the DanceNet set.
pub const DANCENET_DIM: usize = 15;
/// The DanceNet set's beat one-hot column (the downbeat's follows it).
pub const DANCENET_BEAT: usize = 1;
/// Width of the key-pose transformer set.
pub const KEYPOSE_DIM: usize = 15;
/// Width of the TSMT set.
pub const TSMT_DIM: usize = 27;
/// TSMT's ΔMFCC columns (after MFCC 13).
pub const TSMT_DMFCC: Range<usize> = 13..26;
/// The beat one-hot's column in TSMT's features (after MFCC 13 and its Δ).
pub const TSMT_BEAT: usize = 26;

/// The feature layouts the models use, by name: what a song's feature cache is keyed by
/// (`crate::song_cache`). A change to a layout's columns or recipe must bump
/// `song_cache::VERSION`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FeatureSet {
    /// [`dance_revolution_at`], 438-d.
    DanceRevolution,
    /// [`dance_revolution_clock_at`], 443-d.
    DanceRevolutionClock,
    /// [`dancenet`], 15-d.
    DanceNet,
    /// [`keypose`], 15-d.
    Keypose,
    /// [`tsmt`], 27-d.
    Tsmt,
}

impl FeatureSet {
    /// Stable kebab-case name, with the set's width (part of a cache key).
    pub const fn name(self) -> &'static str {
        match self {
            FeatureSet::DanceRevolution => "dance-revolution-438",
            FeatureSet::DanceRevolutionClock => "dance-revolution-clock-443",
            FeatureSet::DanceNet => "dancenet-15",
            FeatureSet::Keypose => "keypose-15",
            FeatureSet::Tsmt => "tsmt-27",
        }
    }

    /// The set of `audio`, row i at time `start_s + i / fps`, `n_frames` rows.
    pub fn compute(
        self,
        audio: &DecodedAudio,
        fps: f64,
        start_s: f64,
        n_frames: usize,
    ) -> Result<Array2<f32>, AudioError> {
        match self {
            FeatureSet::DanceRevolution => dance_revolution_at(audio, fps, start_s, n_frames),
            FeatureSet::DanceRevolutionClock => {
                dance_revolution_clock_at(audio, fps, start_s, n_frames)
            }
            FeatureSet::DanceNet => dancenet(audio, fps, start_s, n_frames),
            FeatureSet::Keypose => keypose(audio, fps, start_s, n_frames),
            FeatureSet::Tsmt => tsmt(audio, fps, start_s, n_frames),
        }
    }
}

/// The sample grid of a feature set: `sr = fps · hop`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameGrid {
    pub fps: f64,
    pub hop: usize,
    pub sr: u32,
}

impl FrameGrid {
    /// The grid for a motion frame rate (see the module doc).
    pub fn for_fps(fps: f64) -> Result<Self, AudioError> {
        if !(fps.is_finite() && (1.0..=240.0).contains(&fps)) {
            return Err(AudioError::InvalidParameter(format!(
                "fps {fps} is outside 1..=240"
            )));
        }
        let mut hop = super::HOP_LENGTH;
        while fps * (hop as f64) < MIN_FEATURE_SR {
            hop *= 2;
        }
        let sr = fps * hop as f64;
        if (sr - sr.round()).abs() > 1e-6 {
            return Err(AudioError::InvalidParameter(format!(
                "fps {fps} × hop {hop} = {sr} Hz is not a whole sample rate"
            )));
        }
        Ok(Self {
            fps,
            hop,
            sr: sr.round() as u32,
        })
    }
}

/// The song on a grid, cut and padded so that frames `rows` are the ones asked for.
struct Prepared<'a> {
    y: Cow<'a, [f32]>,
    grid: FrameGrid,
    rows: Range<usize>,
}

fn prepare(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<Prepared<'_>, AudioError> {
    let grid = FrameGrid::for_fps(fps)?;
    if !(start_s.is_finite() && start_s >= 0.0) {
        return Err(AudioError::InvalidParameter(format!(
            "start_s {start_s} must be ≥ 0"
        )));
    }
    if n_frames == 0 {
        return Err(AudioError::InvalidParameter("n_frames must be ≥ 1".into()));
    }
    if audio.samples.is_empty() {
        return Err(AudioError::Empty);
    }
    if audio.samples.iter().any(|v| !v.is_finite()) {
        return Err(AudioError::NonFinite);
    }
    let mut y: Cow<[f32]> = if audio.sample_rate == grid.sr {
        Cow::Borrowed(&audio.samples)
    } else {
        Cow::Owned(resample(&audio.samples, audio.sample_rate, grid.sr)?)
    };
    let frames_f = start_s * fps;
    let r0 = if (frames_f - frames_f.round()).abs() < 1e-6 {
        frames_f.round() as usize
    } else {
        let cut = ((start_s * grid.sr as f64).round() as usize).min(y.len());
        y = Cow::Owned(y[cut..].to_vec());
        0
    };
    let rows = r0..r0 + n_frames;
    // Frames = 1 + len / hop; append silence until the last asked-for row exists.
    let need = (rows.end - 1) * grid.hop;
    if y.len() < need.max(1) {
        let mut v = y.into_owned();
        v.resize(need.max(1), 0.0);
        y = Cow::Owned(v);
    }
    Ok(Prepared { y, grid, rows })
}

/// Copies `src[rows, ..]` into `dst[.., cols]`.
fn put(dst: &mut Array2<f32>, cols: Range<usize>, src: &Array2<f32>, rows: &Range<usize>) {
    let avail = src.nrows().min(rows.end).saturating_sub(rows.start);
    if avail > 0 {
        dst.slice_mut(s![..avail, cols.clone()])
            .assign(&src.slice(s![rows.start..rows.start + avail, ..]));
    }
}

fn put_col(mut dst: ArrayViewMut1<f32>, src: &[f32], rows: &Range<usize>) {
    for (i, r) in rows.clone().enumerate() {
        if let Some(v) = src.get(r) {
            dst[i] = *v;
        }
    }
}

fn one_hot(frames: &[usize], len: usize) -> Vec<f32> {
    let mut v = vec![0.0f32; len];
    for &f in frames {
        if f < len {
            v[f] = 1.0;
        }
    }
    v
}

fn mel_power(y: &[f32], grid: &FrameGrid) -> Array2<f32> {
    dsp::melspectrogram(y, grid.sr, N_FFT, grid.hop, N_MELS)
}

/// Beats (librosa `beat_track` on the median-aggregated onset envelope of `mel_db`).
fn beats_from_mel_db(mel_db: &Array2<f32>, grid: &FrameGrid) -> Vec<usize> {
    let env = onset_strength_from_db(mel_db, N_FFT, grid.hop, Aggregate::Median);
    beats_from_onset(&env, grid)
}

fn beats_from_onset(env: &[f32], grid: &FrameGrid) -> Vec<usize> {
    if !env.iter().any(|&v| v != 0.0) {
        return Vec::new();
    }
    let bpm = tempo(env, grid.sr, grid.hop);
    beat_track_frames(env, bpm, grid.sr as f64 / grid.hop as f64, 100.0)
}

/// DanceRevolution (Huang et al., ICLR 2021), `[n_frames, 438]`, recipe of the paper's
/// `prepro.py`/`extractor.py` with our column order (see [`dance_revolution_cols`]):
/// MFCC 20 of the mel dB (ref = max), ΔMFCC 20 (width 3), CQT chroma 12 of the harmonic
/// part (`effects.hpss`), tempogram 384 and onset 1 of the percussive part (median), beat
/// one-hot 1 (`beat_track` on that onset envelope). Frame i = time `i / fps`.
pub fn dance_revolution(
    audio: &DecodedAudio,
    fps: f64,
    n_frames: usize,
) -> Result<Array2<f32>, AudioError> {
    dance_revolution_at(audio, fps, 0.0, n_frames)
}

/// [`dance_revolution`] with row i at time `start_s + i / fps`.
pub fn dance_revolution_at(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<Array2<f32>, AudioError> {
    dance_revolution_set(audio, fps, start_s, n_frames, false)
}

/// [`dance_revolution_at`] with the beat clock of its own beats appended (`[n_frames, 443]`,
/// [`dance_revolution_cols::CLOCK`]): bars from [`downbeats`] of the same mel spectrogram.
pub fn dance_revolution_clock_at(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<Array2<f32>, AudioError> {
    dance_revolution_set(audio, fps, start_s, n_frames, true)
}

fn dance_revolution_set(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
    clock: bool,
) -> Result<Array2<f32>, AudioError> {
    use dance_revolution_cols as c;
    let p = prepare(audio, fps, start_s, n_frames)?;
    let (g, rows) = (p.grid, p.rows.clone());
    let mut out = Array2::<f32>::zeros((n_frames, if clock { c::DIM_WITH_CLOCK } else { c::DIM }));
    let mel_for_bars = {
        let mut mel = mel_power(&p.y, &g);
        power_to_db_ref_max_inplace(&mut mel);
        let mfcc = mfcc_from_db(mel.view(), 20);
        put(&mut out, c::MFCC, &mfcc, &rows);
        put(&mut out, c::DMFCC, &delta(&mfcc, 3), &rows);
        // The downbeat finder compares bass flux and spectra, which a dB offset does not change.
        clock.then_some(mel)
    };
    let (harmonic, percussive) = hpss_signal(&p.y, N_FFT, g.hop);
    drop(p);
    let onset = onset_strength(&percussive, g.sr, N_FFT, g.hop, Aggregate::Median);
    drop(percussive);
    let chroma = chroma_cqt(&harmonic, g.sr, g.hop)?;
    drop(harmonic);
    put(&mut out, c::CHROMA, &chroma, &rows);
    let tg = tempogram(&onset, TEMPOGRAM_BINS);
    put(&mut out, c::TEMPOGRAM, &tg, &rows);
    drop(tg);
    put_col(out.column_mut(c::ONSET), &onset, &rows);
    let beats = beats_from_onset(&onset, &g);
    put_col(
        out.column_mut(c::BEAT),
        &one_hot(&beats, onset.len()),
        &rows,
    );
    if let Some(mel) = mel_for_bars {
        let bars = downbeats(&beats, &mel, g.sr);
        let clock = super::clock::beat_clock(&beats, &bars, onset.len(), g.fps);
        put(&mut out, c::CLOCK, &clock, &rows);
    }
    Ok(out)
}

/// DanceNet (Zhuang et al. 2022), `[n_frames, 15]`: onset strength 1 (librosa default, mean
/// over mel bands) | beat one-hot 1, downbeat one-hot 1 | chroma_stft 12 (C first).
pub fn dancenet(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<Array2<f32>, AudioError> {
    let (chroma, onset, beats, down, rows) = rhythm_and_chroma(audio, fps, start_s, n_frames)?;
    let mut out = Array2::<f32>::zeros((n_frames, DANCENET_DIM));
    put_col(out.column_mut(0), &onset, &rows);
    put_col(out.column_mut(DANCENET_BEAT), &beats, &rows);
    put_col(out.column_mut(DANCENET_BEAT + 1), &down, &rows);
    put(&mut out, 3..15, &chroma, &rows);
    Ok(out)
}

/// Key-pose transformer, `[n_frames, 15]`: chroma_stft 12 | beat one-hot 1, downbeat
/// one-hot 1 (the "downbeat 2" of the paper: beat and bar positions) | onset strength 1.
pub fn keypose(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<Array2<f32>, AudioError> {
    let (chroma, onset, beats, down, rows) = rhythm_and_chroma(audio, fps, start_s, n_frames)?;
    let mut out = Array2::<f32>::zeros((n_frames, KEYPOSE_DIM));
    put(&mut out, 0..12, &chroma, &rows);
    put_col(out.column_mut(12), &beats, &rows);
    put_col(out.column_mut(13), &down, &rows);
    put_col(out.column_mut(14), &onset, &rows);
    Ok(out)
}

type RhythmChroma = (Array2<f32>, Vec<f32>, Vec<f32>, Vec<f32>, Range<usize>);

fn rhythm_and_chroma(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<RhythmChroma, AudioError> {
    let p = prepare(audio, fps, start_s, n_frames)?;
    let g = p.grid;
    let mut mel = mel_power(&p.y, &g);
    power_to_db_inplace(&mut mel);
    let onset = onset_strength_from_db(&mel, N_FFT, g.hop, Aggregate::Mean);
    let beats = beats_from_mel_db(&mel, &g);
    let down = downbeats(&beats, &mel, g.sr);
    let chroma = chroma_stft(&p.y, g.sr, N_FFT, g.hop);
    let t_n = onset.len();
    Ok((
        chroma,
        onset,
        one_hot(&beats, t_n),
        one_hot(&down, t_n),
        p.rows,
    ))
}

/// TSMT, `[n_frames, 27]`: MFCC 13 (librosa defaults) | ΔMFCC 13 (width 9) | beat one-hot 1.
pub fn tsmt(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<Array2<f32>, AudioError> {
    let p = prepare(audio, fps, start_s, n_frames)?;
    let g = p.grid;
    let mut mel = mel_power(&p.y, &g);
    power_to_db_inplace(&mut mel);
    let mfcc = mfcc_from_db(mel.view(), 13);
    let beats = beats_from_mel_db(&mel, &g);
    let mut out = Array2::<f32>::zeros((n_frames, TSMT_DIM));
    put(&mut out, 0..13, &mfcc, &p.rows);
    put(&mut out, TSMT_DMFCC, &delta(&mfcc, 9), &p.rows);
    put_col(
        out.column_mut(TSMT_BEAT),
        &one_hot(&beats, mel.nrows()),
        &p.rows,
    );
    Ok(out)
}

/// Percussive onset envelope for the beat-alignment metric, `n_frames` values at `fps`:
/// librosa `onset_strength(y=effects.percussive(y), aggregate=np.median)` on the grid, the
/// same envelope as the DanceRevolution onset column.
pub fn percussive_onset(
    audio: &DecodedAudio,
    fps: f64,
    start_s: f64,
    n_frames: usize,
) -> Result<Vec<f32>, AudioError> {
    let p = prepare(audio, fps, start_s, n_frames)?;
    let g = p.grid;
    let (_, percussive) = hpss_signal(&p.y, N_FFT, g.hop);
    let env = onset_strength(&percussive, g.sr, N_FFT, g.hop, Aggregate::Median);
    Ok(p.rows.map(|r| env.get(r).copied().unwrap_or(0.0)).collect())
}
