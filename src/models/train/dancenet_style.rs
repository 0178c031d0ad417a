//! `choreo train dancenet-style`: DanceNet's musical style classifier on the train split's songs,
//! whole (not only the danced part: serving classifies whole songs), in 30-s windows drawn
//! class-balanced at random offsets (`models::train::classify`). Writes `style.safetensors`,
//! `style.json` (with the test split's accuracy) and `style_log.jsonl` into `models/dancenet/`.
use ndarray::{s, Array2};
use rand::rngs::StdRng;
use rand::Rng;

use super::classify::{fit, Additions, Augment, ClassifyOptions, Fold, Splits};
use super::{CommonOptions, FolderFiles, TrainError};
use crate::models::dancenet::style::{
    Labelled, StyleConfig, StyleFile, CHROMA, FOLDER, FPS, HOP_S, STYLE_FILE, STYLE_LOG_FILE,
    STYLE_WEIGHTS_FILE, WINDOW_S,
};
use crate::models::DanceStyle;
use crate::motion::dataset::Dataset;

/// Options of one training run (the card gives the run behind the committed weights).
#[derive(Clone, Debug)]
pub struct Options {
    pub common: CommonOptions,
    pub schedule: ClassifyOptions,
    /// Roll each training window's chroma by a random 0–11 semitones (a song's key says nothing
    /// of its style, and 37 songs are few enough to be told apart by their keys).
    pub transpose: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            common: CommonOptions::default(),
            schedule: ClassifyOptions::default(),
            transpose: true,
        }
    }
}

/// Rolls the chroma columns ([`CHROMA`]) of a window by a random number of semitones.
pub fn transpose(w: &mut Array2<f32>, rng: &mut StdRng) {
    let k = rng.gen_range(0..CHROMA.len());
    let chroma = w.slice(s![.., CHROMA]).to_owned();
    for (i, col) in chroma.columns().into_iter().enumerate() {
        w.column_mut(CHROMA.start + (i + k) % CHROMA.len())
            .assign(&col);
    }
}

/// The classifier's files in DanceNet's folder.
pub const FILES: FolderFiles = FolderFiles {
    weights: STYLE_WEIGHTS_FILE,
    description: STYLE_FILE,
    log: STYLE_LOG_FILE,
};

/// Every song of `ids`, whole, as raw DanceNet features at 25 fps.
pub fn songs(ds: &Dataset, ids: &[String]) -> Result<Vec<Labelled>, TrainError> {
    ids.iter()
        .map(|id| {
            let dance = ds.load(id)?;
            let audio = crate::audio::decode_path(&dance.audio_path)?;
            let n = crate::motion::validate::song_frames(audio.duration_s, FPS);
            let features = crate::audio::features::dancenet(&audio, FPS, 0.0, n)?;
            let style = DanceStyle::of_dance_id(id)
                .ok_or_else(|| crate::motion::MotionError::UnknownDance { id: id.clone() })?;
            tracing::info!(song = %id, seconds = audio.duration_s, "features");
            Ok(Labelled {
                id: id.clone(),
                style,
                features,
            })
        })
        .collect()
}

/// Trains and writes the classifier; returns a one-line summary.
pub fn train(opts: &Options) -> Result<String, TrainError> {
    let fold = opts
        .schedule
        .hold_out
        .as_deref()
        .map(Fold::parse)
        .transpose()?;
    let ds = Dataset::open(&opts.common.data)?;
    // The chroma shares one normalisation so that rolling it commutes with normalising.
    let splits = Splits::new(
        songs(&ds, ds.train_ids())?,
        songs(&ds, ds.test_ids())?,
        fold,
        &[CHROMA],
    )?;
    let config = opts.schedule.apply(if opts.common.tiny {
        StyleConfig::tiny()
    } else {
        StyleConfig::cpu()
    });
    let additions = Additions {
        augment: opts.transpose.then_some((
            transpose as Augment,
            "chroma rolled by a random 0-11 semitones per window",
        )),
        ..Default::default()
    };
    let (window, hop) = (
        (WINDOW_S * FPS).round() as usize,
        (HOP_S * FPS).round() as usize,
    );
    let (fitted, out) = fit(
        &opts.common,
        FOLDER,
        FILES,
        &opts.schedule,
        &config,
        &splits,
        window,
        hop,
        additions,
        |training, test, held_out| StyleFile {
            config: config.clone(),
            music_norm: splits.norm.clone(),
            fps: FPS,
            window,
            hop,
            training,
            test,
            held_out,
        },
    )?;
    Ok(fitted.summary(&out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn transposing_rolls_only_the_chroma() {
        let w0 = Array2::from_shape_fn((4, 15), |(t, c)| (t * 100 + c) as f32);
        let mut w = w0.clone();
        transpose(&mut w, &mut StdRng::seed_from_u64(3));
        assert_eq!(w.slice(s![.., ..3]), w0.slice(s![.., ..3]));
        let k = (0..12)
            .find(|&k| w[[0, 3 + k]] == w0[[0, 3]])
            .expect("C moved somewhere");
        for i in 0..12 {
            assert_eq!(w.column(3 + (i + k) % 12), w0.column(3 + i));
        }
    }
}
