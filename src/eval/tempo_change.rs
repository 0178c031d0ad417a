//! The tempo-change section of `choreo eval`: a song that speeds up in the middle.
//!
//! Each extra song of at least 90 s is played at 0.8× for its first 45 s and at 1.25× for the
//! next 45 s (`sox … tempo`, pitch kept) and joined: the music speeds up [`MUSIC_FACTOR`]× at
//! 56.25 s. Its true beats are the analysis' beats of the unaltered song, moved by the stretch.
//! The section reports, for the analysis, beat F (70 ms) on each side of the change against
//! those true beats; and for each model and seed, the step rate of the ankles
//! ([`crate::metrics::musicality::tempo_lock`]) after the change over before it, as served and
//! as the network made it, with [`CLEAR_S`] on each side of the change left out. A dancer who
//! follows the music steps 1.5625× faster after the change; a metronome, 1×.
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use super::as_served;
use super::EvalError;
use crate::audio::{self, Analysis, DecodedAudio};
use crate::metrics::beats::f_measure;
use crate::metrics::musicality::tempo_lock;
use crate::models::{DanceModel, GenerateRequest};
use crate::motion::Motion;

/// Tempo of the first part.
pub const SLOW: f64 = 0.8;
/// Tempo of the second part.
pub const FAST: f64 = 1.25;
/// Seconds of the unaltered song in each part.
pub const PART_S: f64 = 45.0;
/// How much faster the music goes after the change.
pub const MUSIC_FACTOR: f64 = FAST / SLOW;
/// Seconds kept clear of the change on each side when step rates are measured (the tracker's
/// 8 s window and a dancer's reaction both straddle it).
pub const CLEAR_S: f64 = 3.0;
/// A dance follows the change when its step-rate ratio lies within this share of the music's.
pub const FOLLOW_TOLERANCE: f64 = 0.1;
/// The short windows (s) whose step rate tells when a dance's pace has settled after the
/// change: four cycles of a 1 Hz step, the least a spectral peak resolves to a few per cent.
pub const SETTLE_WINDOW_S: f64 = 4.0;
/// Seconds between the short windows' starts, and how far after the change they are looked at.
pub const SETTLE_HOP_S: f64 = 0.5;
pub const SETTLE_HORIZON_S: f64 = 10.0;

/// When the music speeds up in the joined song (s).
pub fn change_s() -> f64 {
    PART_S / SLOW
}

/// The analysis of one joined song.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct ChangedSong {
    pub song: String,
    /// Beat F (70 ms) before and after the change against the moved true beats.
    pub beat_f_before: f64,
    pub beat_f_after: f64,
    /// The tempo curve 15 s before and after the change (BPM), and the unaltered song's tempo.
    pub curve_bpm_before: f64,
    pub curve_bpm_after: f64,
    pub original_bpm: f64,
}

/// One dance of a [`TempoChangeRow`].
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct TempoChangeDance {
    pub song: String,
    pub seed: u64,
    /// Step rate after over before the change, as served and as the network made it (none
    /// where a side has no measurable step rate).
    pub ratio: Option<f64>,
    pub ratio_own: Option<f64>,
    /// Seconds after the change from which every short window of the served dance steps nearer
    /// its new pace than its old ([`settle_s`]); none where it does not follow the change or
    /// does not settle within [`SETTLE_HORIZON_S`].
    #[serde(default)]
    pub settle_s: Option<f64>,
}

/// One model on the joined songs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct TempoChangeRow {
    pub model: String,
    pub dances: Vec<TempoChangeDance>,
    /// Dances whose served ratio lies within [`FOLLOW_TOLERANCE`] of [`MUSIC_FACTOR`], and the
    /// same for the network's own motion.
    pub followed: usize,
    pub followed_own: usize,
}

/// The section: the songs as analysed and every model's row.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct TempoChange {
    pub songs: Vec<ChangedSong>,
    pub rows: Vec<TempoChangeRow>,
}

/// A joined song ready to dance: its audio and analysis.
pub struct Joined {
    pub name: String,
    pub audio: DecodedAudio,
    pub analysis: Analysis,
    pub song: ChangedSong,
}

/// `path`'s `[start, start + dur)` seconds at `factor`× its tempo, written by sox to `out`
/// (-D: no dither, the same file on every run). Debian's sox reads ogg, flac and wav itself (as
/// the tempo section's songs are made, and the tests' songs); an mp3 or m4a reaches it as raw
/// mono floats from choreo's own decoder, cut here (sox's `trim` stops reading its input early).
fn sox_part(
    path: &Path,
    a: &DecodedAudio,
    start: f64,
    dur: f64,
    factor: f64,
    out: &Path,
) -> Result<(), EvalError> {
    let io = |source| EvalError::Io {
        path: "sox (Debian's sox package; scripts/setup.sh --test installs it)".into(),
        source,
    };
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let raw = !matches!(ext.as_deref(), Some("ogg" | "oga" | "flac" | "wav"));
    let mut sox = Command::new("sox");
    sox.arg("-D");
    if raw {
        let rate = a.sample_rate.to_string();
        sox.args(["-t", "f32", "-L", "-c", "1", "-r", &rate, "-"])
            .arg(out)
            .stdin(Stdio::piped());
    } else {
        sox.arg(path)
            .arg(out)
            .args(["trim", &start.to_string(), &dur.to_string()]);
    }
    let mut child = sox
        .args(["tempo", &factor.to_string()])
        .spawn()
        .map_err(io)?;
    if let (true, Some(mut stdin)) = (raw, child.stdin.take()) {
        use std::io::Write;
        let sr = a.sample_rate as f64;
        let first = ((start * sr).round() as usize).min(a.samples.len());
        let last = (((start + dur) * sr).round() as usize).min(a.samples.len());
        let bytes: Vec<u8> = a.samples[first..last]
            .iter()
            .flat_map(|s| s.to_le_bytes())
            .collect();
        stdin.write_all(&bytes).map_err(io)?;
    }
    let status = child.wait().map_err(io)?;
    if !status.success() {
        return Err(EvalError::Io {
            path: out.to_path_buf(),
            source: std::io::Error::other(format!("sox exited with {status}")),
        });
    }
    Ok(())
}

/// The tempo at `t` on `curve` (the last point at or before it).
fn curve_at(curve: &[audio::TempoPoint], t: f64) -> f64 {
    curve
        .iter()
        .rev()
        .find(|p| p.time_s <= t)
        .or(curve.first())
        .map_or(f64::NAN, |p| p.bpm)
}

/// `path` (called `name`) slowed then sped up and joined in `dir`, analysed; `None` for a song
/// shorter than two parts.
pub fn joined(path: &Path, name: &str, dir: &Path) -> Result<Option<Joined>, EvalError> {
    let original = audio::decode_path(path)?;
    if original.duration_s < 2.0 * PART_S {
        return Ok(None);
    }
    let truth_of = audio::analyze(&original)?;
    let stem = Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let parts = [
        (0.0, SLOW, dir.join(format!("{stem}_slow.wav"))),
        (PART_S, FAST, dir.join(format!("{stem}_fast.wav"))),
    ];
    for (start, factor, out) in &parts {
        sox_part(path, &original, *start, PART_S, *factor, out)?;
    }
    let out: PathBuf = dir.join(format!("{stem}@{SLOW}x-{FAST}x.wav"));
    let status = Command::new("sox")
        .arg("-D")
        .args(parts.iter().map(|p| &p.2))
        .arg(&out)
        .status()
        .map_err(|source| EvalError::Io {
            path: out.clone(),
            source,
        })?;
    if !status.success() {
        return Err(EvalError::Io {
            path: out,
            source: std::io::Error::other(format!("sox exited with {status}")),
        });
    }
    let joined = audio::decode_path(&out)?;
    let analysis = audio::analyze(&joined)?;
    let change = change_s();
    let truth: Vec<f64> = truth_of
        .beat_times
        .iter()
        .filter(|&&t| t < 2.0 * PART_S)
        .map(|&t| {
            if t < PART_S {
                t / SLOW
            } else {
                change + (t - PART_S) / FAST
            }
        })
        .collect();
    let side = |v: &[f64], after: bool| -> Vec<f64> {
        v.iter()
            .copied()
            .filter(|&t| (t >= change) == after)
            .collect()
    };
    let song = ChangedSong {
        song: name.into(),
        beat_f_before: f_measure(&side(&truth, false), &side(&analysis.beat_times, false)),
        beat_f_after: f_measure(&side(&truth, true), &side(&analysis.beat_times, true)),
        curve_bpm_before: curve_at(&analysis.tempo_curve, change - 15.0),
        curve_bpm_after: curve_at(&analysis.tempo_curve, change + 15.0),
        original_bpm: truth_of.tempo_bpm,
    };
    Ok(Some(Joined {
        name: name.into(),
        audio: joined,
        analysis,
        song,
    }))
}

/// The ankles' step rate (Hz) of `m` between `from_s` and `to_s`, with the song's beats there.
fn step_hz(m: &Motion, beats: &[f64], from_s: f64, to_s: f64) -> Option<f64> {
    let n = m.positions.len_of(ndarray::Axis(0));
    let a = ((from_s * m.fps).ceil().max(0.0) as usize).min(n);
    let b = ((to_s * m.fps).floor().max(0.0) as usize).min(n);
    if b <= a {
        return None;
    }
    let part = m.positions.slice(ndarray::s![a..b, .., ..]);
    let shifted: Vec<f64> = beats
        .iter()
        .filter(|&&t| t >= from_s && t <= to_s)
        .map(|t| t - a as f64 / m.fps)
        .collect();
    tempo_lock(part, m.fps, &shifted).map(|l| l.step_hz)
}

/// The ankles' step rates (Hz) of `m` before and after the change, [`CLEAR_S`] kept clear of
/// it; `beats` are the joined song's.
fn paces(m: &Motion, beats: &[f64]) -> Option<(f64, f64)> {
    let change = change_s();
    let before = step_hz(m, beats, 0.0, change - CLEAR_S)?;
    let after = step_hz(m, beats, change + CLEAR_S, m.duration_s())?;
    Some((before, after))
}

/// The step rate after over before the change ([`paces`]).
fn step_ratio(m: &Motion, beats: &[f64]) -> Option<f64> {
    paces(m, beats).map(|(before, after)| after / before)
}

/// When the pace of `m` settles after the change: the first start `s` (every [`SETTLE_HOP_S`]
/// up to [`SETTLE_HORIZON_S`]) from which every short window `[change + s', change + s' + 4 s]`
/// steps nearer (as a ratio) to the dance's pace after the change than to its pace before
/// (`paces`, from [`paces`]). Short windows are noisy (a peak may jump to a harmonic), so a
/// window is held against the old pace rather than a tolerance; the windows start at the change,
/// so no frame before it is measured. `None` where the dance does not follow the change (its two
/// paces are within [`FOLLOW_TOLERANCE`] of the music's factor apart) or has not settled by the
/// horizon.
fn settle_s(m: &Motion, beats: &[f64], (before, after): (f64, f64)) -> Option<f64> {
    let change = change_s();
    if ((after / before) / MUSIC_FACTOR - 1.0).abs() > FOLLOW_TOLERANCE {
        return None;
    }
    let starts = (SETTLE_HORIZON_S / SETTLE_HOP_S).round() as usize;
    let settled: Vec<bool> = (0..=starts)
        .map(|k| {
            let from = change + k as f64 * SETTLE_HOP_S;
            step_hz(m, beats, from, from + SETTLE_WINDOW_S)
                .is_some_and(|hz| (hz / after).ln().abs() < (hz / before).ln().abs())
        })
        .collect();
    (0..=starts)
        .find(|&k| settled[k..].iter().all(|&ok| ok))
        .map(|k| k as f64 * SETTLE_HOP_S)
}

/// `model` on every joined song with the eval's seeds.
pub fn row(
    model: &dyn DanceModel,
    id: &str,
    songs: &[Joined],
    first_seed: u64,
    seeds: u64,
) -> Result<TempoChangeRow, EvalError> {
    let mut dances = Vec::new();
    for s in songs {
        let beats = &s.analysis.beat_times;
        for seed in first_seed..first_seed + seeds.max(1) {
            let req = GenerateRequest::plain(&s.audio, seed);
            let (raw, composed) =
                super::generate(model, id, &s.name, &req, &mut super::rows::Quiet)?;
            let ratio_own = step_ratio(&raw, beats);
            let (served, _) =
                as_served(raw, composed, &[], beats).map_err(|source| EvalError::Export {
                    model: id.into(),
                    song: s.name.clone(),
                    source,
                })?;
            let served_paces = paces(&served, beats);
            dances.push(TempoChangeDance {
                song: s.name.clone(),
                seed,
                ratio: served_paces.map(|(before, after)| after / before),
                ratio_own,
                settle_s: served_paces.and_then(|p| settle_s(&served, beats, p)),
            });
        }
    }
    let follows =
        |r: Option<f64>| r.is_some_and(|r| (r / MUSIC_FACTOR - 1.0).abs() <= FOLLOW_TOLERANCE);
    Ok(TempoChangeRow {
        model: id.into(),
        followed: dances.iter().filter(|d| follows(d.ratio)).count(),
        followed_own: dances.iter().filter(|d| follows(d.ratio_own)).count(),
        dances,
    })
}

/// The section's Markdown: the analysis per song, then each model's step-rate ratios.
pub fn markdown(section: &TempoChange) -> String {
    let mut out = format!(
        "The music speeds up {MUSIC_FACTOR}× at {:.2} s (0.8× then 1.25×).\n\n| Song | beat F before ↑ | beat F after ↑ | curve before (BPM) | curve after | the song's tempo × 0.8 / × 1.25 |\n|---|---|---|---|---|---|\n",
        change_s()
    );
    for s in &section.songs {
        out += &format!(
            "| {} | {:.3} | {:.3} | {:.1} | {:.1} | {:.1} / {:.1} |\n",
            s.song,
            s.beat_f_before,
            s.beat_f_after,
            s.curve_bpm_before,
            s.curve_bpm_after,
            s.original_bpm * SLOW,
            s.original_bpm * FAST
        );
    }
    out += "\n| Model | step-rate ratio after/before, served (per dance) | within 10 % of 1.5625 | network's own | within 10 % | served pace settled after (s), – where it does not follow |\n|---|---|---|---|---|---|\n";
    let list = |v: Vec<Option<f64>>| {
        v.iter()
            .map(|r| r.map_or("–".to_string(), |r| format!("{r:.2}")))
            .collect::<Vec<_>>()
            .join(", ")
    };
    for r in &section.rows {
        let settles: Vec<String> = r
            .dances
            .iter()
            .map(|d| d.settle_s.map_or("–".to_string(), |s| format!("{s:.1}")))
            .collect();
        out += &format!(
            "| {} | {} | {}/{} | {} | {}/{} | {} |\n",
            r.model,
            list(r.dances.iter().map(|d| d.ratio).collect()),
            r.followed,
            r.dances.len(),
            list(r.dances.iter().map(|d| d.ratio_own).collect()),
            r.followed_own,
            r.dances.len(),
            settles.join(", ")
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The section for the served models on ../shared's long songs, seeds 0 and 1, without the
    /// rest of `choreo eval` (minutes per dance on a CPU):
    /// `cargo test --release --lib eval::tempo_change -- --ignored --nocapture`.
    #[test]
    #[ignore = "dances 16 songs of 92 s: minutes each on a CPU"]
    fn served_models_on_a_song_that_speeds_up() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let dir = tempfile::tempdir().expect("tempdir");
        let mut section = TempoChange::default();
        let mut songs = Vec::new();
        for name in ["lets_go_fishin.ogg", "sugar_plum_fairy.ogg"] {
            let path = root.join("../shared/audio").join(name);
            let j = joined(&path, name, dir.path())
                .expect("joined")
                .expect("90 s or more");
            section.songs.push(j.song.clone());
            songs.push(j);
        }
        eprintln!("{}", markdown(&section));
        let registry = crate::models::Registry::load(&root.join("models")).expect("models");
        let only = std::env::var("CHOREO_TEMPO_CHANGE_MODELS").unwrap_or_default();
        for id in [
            "dance-revolution",
            "dancenet",
            "keypose-transformer",
            "tsmt",
            "beat-graph",
        ] {
            if !only.is_empty() && !only.split(',').any(|m| m == id) {
                continue;
            }
            let model = registry
                .get(&crate::models::ModelId(id.into()))
                .expect("served model");
            let r = row(model.as_ref(), id, &songs, 0, 2).expect("row");
            eprintln!("{id}: {:?}", r.dances);
            section.rows.push(r);
            eprintln!("{}", markdown(&section));
        }
    }
}
