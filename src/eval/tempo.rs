//! The tempo section of `choreo eval`: does a model follow the music's tempo?
//!
//! The data cannot tell: every waltz in it is near 87 bpm, every cha-cha 115–127, so a model
//! that steps at one fixed rate looks tempo-locked on its own genre. So every extra song is also
//! danced slower and faster, the same music with its pitch kept (`sox … tempo F`, Debian's
//! `sox`; a time-stretch in Rust would be a second, hand-written implementation of what sox does
//! well), and each model's dances are measured there: the share tempo-locked
//! ([`crate::metrics::musicality`]), and, per song and seed, the ratio of the step rates at the
//! fastest and the slowest tempo, which is `fast / slow` (1.41 for 1.2 / 0.85) for a dancer who
//! follows the tempo and 1 for a metronome.
//!
//! That holds only where the song's analysis hears both copies at one metrical level. Its tempo
//! is librosa's (a prior centred on 120 BPM, one octave wide), and at 0.85× and 1.2× it counts
//! about half of the songs measured so far at another level at one tempo than at the other
//! (lets_go_fishin: 152 BPM at 0.85×, 108 at 1.2×; librosa 0.11 itself gives the same), so a
//! dance that keeps its fraction of the beat it is given steps *slower* on the faster copy. The
//! row therefore names how each song was heard ([`HeardTempo`]) and gives the ratio of step
//! rates again over the songs heard at one level only, where 1.41 is a follower's and 1 a
//! metronome's without that confusion.
use std::path::Path;
use std::process::Command;

use super::as_served;
use super::songs::{whole_song, Song};
use super::{EvalError, EvalOptions};
use crate::metrics::musicality::{tempo_lock, Musicality};
use crate::metrics::reference::ReferenceStats;
use crate::models::{DanceModel, GenerateRequest};

/// The tempi every extra song is also danced at (`Default` of [`EvalOptions::tempi`]).
pub const TEMPI: [f64; 2] = [0.85, 1.2];

/// One model's dances of the stretched songs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct TempoRow {
    pub model: String,
    /// The tempo factors danced (besides the original).
    pub tempi: Vec<f64>,
    /// Dances (songs × tempi × seeds).
    pub dances: usize,
    /// Of those with a measurable step rate, how many are tempo-locked.
    pub measured: usize,
    pub tempo_locked: usize,
    /// Per song and seed: step rate at the fastest tempo over the step rate at the slowest.
    pub step_rate_ratios: Vec<f64>,
    /// Median of `step_rate_ratios` (NaN without any).
    pub step_rate_ratio_median: f64,
    /// The same for the network's own motion, before the beat-align stage (and the feet): how much
    /// of the lock and the tempo-following is the network's.
    #[serde(default)]
    pub measured_raw: usize,
    #[serde(default)]
    pub tempo_locked_raw: usize,
    #[serde(default)]
    pub step_rate_ratios_raw: Vec<f64>,
    #[serde(default)]
    pub step_rate_ratio_median_raw: f64,
    /// What a dancer who follows the tempo gives: fastest / slowest factor.
    pub followed_ratio: f64,
    /// The reference tempo (BPM) when the network runs in beat time ([`crate::models::beat_time`]):
    /// its "own" motion is then made on that clock and played back at each song's tempo.
    #[serde(default)]
    pub beat_time_bpm: Option<f64>,
    /// Each stretched dance's tempo lock, served and the network's own: which songs, tempi and
    /// seeds a count or a ratio above comes from (the tracker can hear one song's two tempi at
    /// two metrical levels, and a network can step at one pace on both).
    #[serde(default)]
    pub per_dance: Vec<TempoDance>,
    /// Every served musicality line is asked of the stretched songs too, not only the tempo
    /// lock: the row's worst served dance by each ([`TempoDance::served_lines`]). Absent in eval
    /// files written before they were measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub served_lines: Option<WorstLines>,
    /// How the analysis heard each song at the row's tempi (absent in files written before).
    #[serde(default)]
    pub heard: Vec<HeardTempo>,
    /// `step_rate_ratios` (served) and `step_rate_ratios_raw` (the network's own) of the songs
    /// heard at one metrical level only ([`HeardTempo::one_level`]), and their medians (none
    /// without such a song).
    #[serde(default)]
    pub step_rate_ratios_one_level: Vec<f64>,
    #[serde(default)]
    pub step_rate_ratios_one_level_raw: Vec<f64>,
    #[serde(default)]
    pub step_rate_ratio_median_one_level: Option<f64>,
    #[serde(default)]
    pub step_rate_ratio_median_one_level_raw: Option<f64>,
}

/// How far (relative) the analysis' ratio of beat rates may lie from the ratio of the tempi for
/// a song to count as heard at one metrical level. Another level is at least a factor 1.5 away
/// (2 for double time, 1.5 between twos and threes), and the tracker's rates of one level agree
/// within 3 % on the songs measured (hungarian_dance_5 1.38 for 1.41).
pub const ONE_LEVEL_TOLERANCE: f64 = 0.1;

/// One song of a [`TempoRow`] as the song's analysis heard it at each tempo.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct HeardTempo {
    pub song: String,
    /// The beat rate (Hz, [`crate::metrics::musicality::beat_rate_hz`]) at each of the row's
    /// `tempi`; none with under the tempo lock's beats.
    pub beat_hz: Vec<Option<f64>>,
    /// The fastest tempo's beat rate over the slowest's.
    pub beat_rate_ratio: Option<f64>,
    /// `beat_rate_ratio` within [`ONE_LEVEL_TOLERANCE`] of the ratio of the tempi: both copies
    /// heard at one metrical level, where following the beat is following the tempo.
    pub one_level: bool,
}

impl HeardTempo {
    fn of(song: &str, beat_hz: Vec<Option<f64>>, followed: f64) -> Self {
        let beat_rate_ratio = match (beat_hz.first(), beat_hz.last()) {
            (Some(Some(slow)), Some(Some(fast))) if beat_hz.len() >= 2 => Some(fast / slow),
            _ => None,
        };
        Self {
            song: song.into(),
            one_level: beat_rate_ratio
                .is_some_and(|r| (r / followed - 1.0).abs() <= ONE_LEVEL_TOLERANCE),
            beat_hz,
            beat_rate_ratio,
        }
    }
}

/// The served lines of one stretched dance (as a user downloads it), or the worst of a row's.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct ServedLines {
    /// Elbows and wrists against the spine (m/s; the bar: ≥ 0.43 in every dance).
    pub arms_m_s: f64,
    /// Share of knee-frames bent backwards (the bar: ≤ 6 %).
    pub knee_backward_share: f64,
    /// The longest span held in one pose (s; [`crate::motion::hold`]).
    pub longest_hold_s: f64,
    /// The plausibility verdict (`metrics::physical`), and the criteria it fails.
    pub verdict_pass: bool,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub verdict_failed: Vec<String>,
}

/// A row's worst stretched dances, each line on its own (they need not be one dance).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct WorstLines {
    /// Dances measured.
    pub dances: usize,
    pub arms_min_m_s: f64,
    pub knee_backward_max: f64,
    pub longest_hold_max_s: f64,
    /// Dances whose verdict passes.
    pub verdict_passed: usize,
}

impl WorstLines {
    /// The worst of `lines` by each line; `None` without any.
    fn of<'a>(lines: impl IntoIterator<Item = &'a ServedLines>) -> Option<Self> {
        lines.into_iter().fold(None, |worst, l| {
            Some(match worst {
                None => Self {
                    dances: 1,
                    arms_min_m_s: l.arms_m_s,
                    knee_backward_max: l.knee_backward_share,
                    longest_hold_max_s: l.longest_hold_s,
                    verdict_passed: usize::from(l.verdict_pass),
                },
                Some(w) => Self {
                    dances: w.dances + 1,
                    arms_min_m_s: w.arms_min_m_s.min(l.arms_m_s),
                    knee_backward_max: w.knee_backward_max.max(l.knee_backward_share),
                    longest_hold_max_s: w.longest_hold_max_s.max(l.longest_hold_s),
                    verdict_passed: w.verdict_passed + usize::from(l.verdict_pass),
                },
            })
        })
    }
}

/// One stretched dance of a [`TempoRow`].
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct TempoDance {
    /// The song's name in the eval (the original's, without the factor).
    pub song: String,
    pub factor: f64,
    pub seed: u64,
    /// As served (beat-aligned, feet planted); none without a measurable step rate.
    pub served: Option<crate::metrics::musicality::TempoLock>,
    /// The network's own motion.
    pub own: Option<crate::metrics::musicality::TempoLock>,
    /// The other lines of "Done when" as served (absent in files written before they were
    /// measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub served_lines: Option<ServedLines>,
}

impl ServedLines {
    /// The lines of `motion` (a dance as downloaded), its musicality `served` measured already;
    /// `reference` gives the verdict's speed floor, as in every row.
    fn of(served: &Musicality, motion: &crate::motion::Motion, reference: &ReferenceStats) -> Self {
        let physical = crate::metrics::physical::physical_series(motion, &[])
            .scores(reference.physical.pooled.mean_speed_m_s);
        let verdict = crate::metrics::physical::verdict(&physical, &[], None);
        Self {
            arms_m_s: served.arm_speed_m_s,
            knee_backward_share: served.knee_backward_share,
            longest_hold_s: served.longest_hold_s,
            verdict_pass: verdict.pass,
            verdict_failed: verdict
                .criteria
                .iter()
                .filter(|c| c.pass == Some(false))
                .map(|c| c.name.clone())
                .collect(),
        }
    }
}

/// `song` (called `name` in the eval) at `factor` × its tempo (pitch kept), written by sox into
/// `dir` and decoded.
fn stretched(song: &Path, name: &str, factor: f64, dir: &Path) -> Result<Song, EvalError> {
    let stem = Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let out = dir.join(format!("{stem}@{factor}x.wav"));
    // -D: no dither. sox dithers by default when it writes 16 bits, with fresh noise on each
    // run, so the same command gave dances a beat or two apart from run to run.
    let mut sox = Command::new("sox");
    sox.arg("-D");
    // Debian's sox reads ogg, flac and wav but has no mp3 or m4a handler: those are decoded by
    // choreo's own decoder (the one jobs use) and reach sox as raw mono 32-bit floats on stdin.
    let ext = song
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let raw = match ext.as_deref() {
        Some("mp3" | "m4a" | "mp4" | "aac") => Some(crate::audio::decode_path(song)?),
        _ => None,
    };
    match &raw {
        Some(a) => sox
            .args([
                "-t",
                "f32",
                "-L",
                "-c",
                "1",
                "-r",
                &a.sample_rate.to_string(),
                "-",
            ])
            .stdin(std::process::Stdio::piped()),
        None => sox.arg(song),
    };
    sox.arg(&out).args(["tempo", &factor.to_string()]);
    let sox_io = |source| EvalError::Io {
        path: "sox (Debian's sox package; scripts/setup.sh --test installs it)".into(),
        source,
    };
    let mut child = sox.spawn().map_err(sox_io)?;
    if let (Some(a), Some(mut stdin)) = (&raw, child.stdin.take()) {
        use std::io::Write;
        let bytes: Vec<u8> = a.samples.iter().flat_map(|s| s.to_le_bytes()).collect();
        stdin.write_all(&bytes).map_err(sox_io)?;
    }
    let status = child.wait().map_err(sox_io)?;
    if !status.success() {
        return Err(EvalError::Io {
            path: out,
            source: std::io::Error::other(format!("sox exited with {status}")),
        });
    }
    whole_song(&out)
}

/// Every song of `paths` (called `names`) at every factor of `args.tempi`, danced by `model`
/// with the eval's seeds, as served and as the network made it; `reference` gives the verdict's
/// speed floor.
pub(super) fn tempo_row(
    model: &dyn DanceModel,
    id: &str,
    paths: &[std::path::PathBuf],
    names: &[String],
    args: &EvalOptions,
    reference: &ReferenceStats,
) -> Result<TempoRow, EvalError> {
    let dir = tempfile::tempdir().map_err(|source| EvalError::Io {
        path: std::env::temp_dir(),
        source,
    })?;
    let mut tempi = args.tempi.clone();
    tempi.sort_by(f64::total_cmp);
    // [served, the network's own] for each count.
    let followed = match (tempi.first(), tempi.last()) {
        (Some(a), Some(b)) if tempi.len() >= 2 => b / a,
        _ => f64::NAN,
    };
    let (mut dances, mut measured, mut locked, mut ratios) =
        (0, [0; 2], [0; 2], [Vec::new(), Vec::new()]);
    // [served, the network's own] of the songs heard at one metrical level
    let mut one_level = [Vec::new(), Vec::new()];
    let (mut per_dance, mut heard) = (Vec::new(), Vec::new());
    for (path, name) in paths.iter().zip(names) {
        // step rate per (tempo, seed), served and the network's own
        let mut steps: Vec<Vec<[Option<f64>; 2]>> = Vec::new();
        let mut beat_hz = Vec::new();
        for &factor in &tempi {
            let song = stretched(path, name, factor, dir.path())?;
            beat_hz.push(crate::metrics::musicality::beat_rate_hz(
                &song.beats,
                song.audio.duration_s,
            ));
            let mut per_seed = Vec::new();
            for seed in args.seed..args.seed + args.seeds.max(1) {
                let req = GenerateRequest::plain(&song.audio, seed);
                let (raw, composed) =
                    super::generate(model, id, &song.name, &req, &mut super::rows::Quiet)?;
                let own = tempo_lock(raw.positions.view(), raw.fps, &song.beats);
                let (served, _) = as_served(raw, composed, &[], &song.beats).map_err(|source| {
                    EvalError::Export {
                        model: id.into(),
                        song: song.name.clone(),
                        source,
                    }
                })?;
                let as_served = Musicality::of(&served, &song.beats);
                let lock = as_served.tempo_lock;
                let lines = ServedLines::of(&as_served, &served, reference);
                // The same contact sheet as the whole songs': how the stepping changes with the
                // tempo is what this section is read for.
                if let Some(dir) = &args.previews {
                    super::rows::write_preview(dir, id, &song, seed, &served, &[], &as_served)?;
                }
                dances += 1;
                for (n, lock) in [lock, own].into_iter().enumerate() {
                    if let Some(lock) = lock {
                        measured[n] += 1;
                        locked[n] += usize::from(lock.locked);
                    }
                }
                per_seed.push([lock, own].map(|l| l.map(|l| l.step_hz)));
                per_dance.push(TempoDance {
                    song: name.clone(),
                    factor,
                    seed,
                    served: lock,
                    own,
                    served_lines: Some(lines),
                });
            }
            steps.push(per_seed);
        }
        let song = HeardTempo::of(name, beat_hz, followed);
        if let (Some(slow), Some(fast)) = (steps.first(), steps.last()) {
            if tempi.len() >= 2 {
                for n in 0..2 {
                    let pairs: Vec<f64> = slow
                        .iter()
                        .zip(fast)
                        .filter_map(|(s, f)| Some(f[n].as_ref()? / s[n].as_ref()?))
                        .collect();
                    if song.one_level {
                        one_level[n].extend(&pairs);
                    }
                    ratios[n].extend(pairs);
                }
            }
        }
        heard.push(song);
    }
    let median = |r: &[f64]| {
        let mut sorted = r.to_vec();
        sorted.sort_by(f64::total_cmp);
        if sorted.is_empty() {
            f64::NAN
        } else {
            sorted[sorted.len() / 2]
        }
    };
    let [ratios, ratios_raw] = ratios;
    let [one_level, one_level_raw] = one_level;
    let median_of = |r: &[f64]| (!r.is_empty()).then(|| median(r));
    Ok(TempoRow {
        model: id.into(),
        tempi,
        dances,
        measured: measured[0],
        tempo_locked: locked[0],
        step_rate_ratio_median: median(&ratios),
        step_rate_ratios: ratios,
        measured_raw: measured[1],
        tempo_locked_raw: locked[1],
        step_rate_ratio_median_raw: median(&ratios_raw),
        step_rate_ratios_raw: ratios_raw,
        followed_ratio: followed,
        beat_time_bpm: model.info().beat_time.map(|b| b.bpm),
        served_lines: WorstLines::of(per_dance.iter().filter_map(|d| d.served_lines.as_ref())),
        per_dance,
        heard,
        step_rate_ratio_median_one_level: median_of(&one_level),
        step_rate_ratio_median_one_level_raw: median_of(&one_level_raw),
        step_rate_ratios_one_level: one_level,
        step_rate_ratios_one_level_raw: one_level_raw,
    })
}

/// The section's Markdown table: served (beat-aligned) and the network's own, side by side.
pub fn markdown(rows: &[TempoRow]) -> String {
    let mut out = String::from("| Model | network's clock | tempi | n | tempo-locked ↑ served | network's own | step-rate ratio fast/slow (median) served | network's own | a dancer who follows | songs heard at one level | their step-rate ratio, served | network's own | arms min (m/s) ↑ | knees backwards max ↓ | longest hold (s) ↓ | verdict passed |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let share = |locked: usize, measured: usize| {
        if measured == 0 {
            "–".into()
        } else {
            format!(
                "{locked}/{measured} ({:.0} %)",
                100.0 * locked as f64 / measured as f64
            )
        }
    };
    for r in rows {
        let tempi: Vec<String> = r.tempi.iter().map(|t| format!("{t}×")).collect();
        let lines = r.served_lines.as_ref().map_or_else(
            || "– | – | – | –".to_string(),
            |w| {
                format!(
                    "{:.2} | {:.1} % | {:.1} | {}/{}",
                    w.arms_min_m_s,
                    100.0 * w.knee_backward_max,
                    w.longest_hold_max_s,
                    w.verdict_passed,
                    w.dances
                )
            },
        );
        let one_level = r.heard.iter().filter(|h| h.one_level).count();
        let ratio = |m: Option<f64>| m.map_or("–".into(), |m| format!("{m:.2}"));
        out += &format!(
            "| {} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.2} | {one_level}/{} | {} | {} | {lines} |\n",
            r.model,
            r.beat_time_bpm
                .map_or("seconds".into(), |b| format!("beats at {b:.0} BPM")),
            tempi.join(", "),
            r.dances,
            share(r.tempo_locked, r.measured),
            share(r.tempo_locked_raw, r.measured_raw),
            r.step_rate_ratio_median,
            r.step_rate_ratio_median_raw,
            r.followed_ratio,
            r.heard.len(),
            ratio(r.step_rate_ratio_median_one_level),
            ratio(r.step_rate_ratio_median_one_level_raw),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A song heard in double time at one tempo only (lets_go_fishin: 152 BPM at 0.85×, 108 at
    /// 1.2×) is not at one level; one heard 1.38× faster at 1.2×/0.85× is.
    #[test]
    fn a_song_heard_at_another_metrical_level_is_named() {
        let followed = 1.2 / 0.85;
        let hz = |bpm: f64| Some(bpm / 60.0);
        let flipped = HeardTempo::of("fishin", vec![hz(152.0), hz(107.7)], followed);
        assert!(!flipped.one_level, "{flipped:?}");
        assert!((flipped.beat_rate_ratio.unwrap() - 107.7 / 152.0).abs() < 1e-12);
        let heard = HeardTempo::of("hungarian", vec![hz(125.0), hz(172.3)], followed);
        assert!(heard.one_level, "{heard:?}");
        let short = HeardTempo::of("loop", vec![None, hz(120.0)], followed);
        assert!(!short.one_level && short.beat_rate_ratio.is_none());
    }

    /// Debian's sox cannot read an mp3: the eval decodes it itself and hands sox the samples.
    #[test]
    fn an_mp3_is_stretched_through_choreos_own_decoder() {
        let song =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/audio/trumpet_loop_90bpm.ogg");
        assert!(song.is_file(), "{} is missing", song.display());
        let dir = tempfile::tempdir().expect("tempdir");
        let mp3 = dir.path().join("trumpet.mp3");
        let made = Command::new("ffmpeg")
            .args(["-loglevel", "error", "-i"])
            .arg(&song)
            .args(["-t", "5"])
            .arg(&mp3)
            .status()
            .expect("ffmpeg (scripts/setup.sh --test installs it) runs");
        assert!(made.success(), "ffmpeg: {made}");
        let plain = crate::audio::decode_path(&mp3).expect("decodes").duration_s;
        let fast = stretched(&mp3, "trumpet.mp3", 1.25, dir.path()).expect("sox stretches the mp3");
        assert!(
            (fast.audio.duration_s - plain / 1.25).abs() < 0.1,
            "{plain} s at 1.25× gave {} s",
            fast.audio.duration_s
        );
    }
}
