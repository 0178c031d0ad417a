//! Beat alignment: the served stage that moves a dance's steps onto the song's beats, after
//! the network and before [`super::finish`] plants the feet.
//!
//! Real dancers step at a fixed fraction of the beat ([`crate::metrics::musicality`]: the peak of
//! the ankles' summed-speed spectrum is 1/2 of the beat rate for rumba and cha-cha, 1/3 for
//! waltz). A network that drifts, or steps at its own fixed rate, is brought onto the song by a
//! *time warp*: output frame `f` shows the network's motion at source time `w(f)`, with `w`
//! monotone, its slope within [`SLOPE_RANGE`] and smooth, so no pose is invented and none is
//! repeated; only the timing changes. It is a last step, never the only one: the networks
//! themselves must move with the music, and `choreo eval` keeps their own tempo lock beside the
//! served one.
//!
//! # How
//! 1. **The motion's rhythm.** The ankles' summed speed (the series the metric reads), its
//!    dominant rate `f_m` (the spectral peak within [`STEP_BAND_HZ`]), and that series
//!    band-passed around `f_m` (a Gaussian in log-frequency, ±[`BAND_WIDTH_LN`]): its minima are
//!    the kinematic beats, one per cycle of the rhythm the metric sees (FACT's kinematic beats are
//!    minima of speed; unfiltered, a noisy speed curve has several minima per step).
//! 2. **The grid.** The song's beats, grouped or subdivided to `q` × the beat rate for each `q`
//!    of [`GRID_FRACTIONS`] (the fractions the metric knows), at every phase (which beat of the
//!    group the grid starts on). Only grids whose spacing is within [`SLOPE_RANGE`] of the
//!    motion's own cycle are tried: the warp stays small.
//! 3. **The match.** Per span between fixed frames (start, end, the key poses: they map to
//!    themselves, so key poses stay where the user put them), a dynamic programme pairs kinematic
//!    beats with grid points monotonically. A run of `a` motion cycles over `b` grid intervals
//!    with `a = b` is *locked* (every step lands on the grid); `a ≠ b` is a catch-up, where the
//!    motion's cycle count and the grid's part (a span between fixed frames has mean slope 1, so a
//!    motion slower or faster than its grid must lose or gain a cycle somewhere). The cost is the
//!    time not locked, plus the warp's distortion `(ln slope)²`, plus skipped beats; the grid
//!    and phase of least cost over the whole dance win. A catch-up slips exactly whole cycles,
//!    so the locked runs on either side stay in phase with one grid and the spectrum's peak is
//!    the grid's rate.
//! 4. **The warp.** Piecewise linear through the pairs, its per-frame slope smoothed by a Gaussian
//!    ([`SLOPE_SMOOTH_S`]; a mean of slopes within the range stays within it, and the motion's
//!    speed changes over a quarter second instead of jumping, so the acceleration does not
//!    spike), then scaled per span so the fixed frames map exactly to themselves.
//! 5. **The resample.** Positions at the warped times by Catmull-Rom (C¹, and exact at whole
//!    frames, so a fixed frame's pose is the network's to the bit).
//!
//! When the song has fewer than four beats in the dance, the dance is shorter than 2 s, or no
//! grid is within reach of the motion's rhythm, the motion is left as it came and the summary
//! says why. Cost: a few FFTs of one series and small dynamic programmes, milliseconds for a
//! 3-minute song.
use ndarray::Array3;

use super::hang::{hang_s, HANG_REAL_MAX_S};
use super::hold::{longest_hold_s, HOLD_NOTED_S};
use super::Motion;

mod plan;
mod rhythm;
pub mod tempo_follow;

use plan::{plan_from, BeatClock};
use rhythm::{ankle_speed, step_rate, CHECK_ZERO_PAD};

/// The fractions of the beat rate a grid may step at: the same as
/// [`crate::metrics::musicality::TEMPO_FRACTIONS`] (a unit test checks), repeated here because
/// the metric reads motion and motion must not read the metric.
pub const GRID_FRACTIONS: [f64; 6] = [1.0 / 6.0, 1.0 / 4.0, 1.0 / 3.0, 1.0 / 2.0, 2.0 / 3.0, 1.0];
/// The warp's slope (source seconds per served second) stays within this: a motion played at
/// most 30 % slower or 40 % faster (faster is rarer, and accelerations grow with its square).
pub const SLOPE_RANGE: (f64, f64) = (0.7, 1.4);
/// The band searched for the motion's step rate (Hz), the metric's.
pub const STEP_BAND_HZ: (f64, f64) = (0.25, 3.0);
/// The metric's tempo-lock tolerance (3 %): a grid this close to the band's edge is left out.
const LOCK_TOLERANCE: f64 = 0.03;
/// Half-width of the band-pass around the step rate, in natural log of frequency (±28 %): narrow
/// enough for one minimum per cycle, wide enough to follow a rhythm that wanders.
pub const BAND_WIDTH_LN: f64 = 0.25;
/// The Gaussian (σ, seconds) that smooths the warp's slope.
pub const SLOPE_SMOOTH_S: f64 = 0.25;
/// The fewest frames and beats inside the dance the stage works on (the metric's minimum).
const MIN_FRAMES: usize = 50;
const MIN_BEATS: usize = 4;
/// Most motion cycles or grid intervals one matched segment spans (3 over 2 is a catch-up).
const MAX_RUN: usize = 3;
/// Most kinematic beats or grid points left out before the first match of a span, or after its last.
const MAX_EDGE_SKIP: usize = 6;
/// Cost of a second not locked to the grid.
const UNLOCKED_PER_S: f64 = 1.0;
/// Cost per second of the warp's distortion at the range's steepest slope: half a second not
/// locked, so locking a stretch always beats leaving it alone, and among locks the least warp wins.
const DISTORTION_AT_LIMIT_PER_S: f64 = 0.5;
/// Cost of a kinematic beat or a grid point left unmatched.
const SKIP: f64 = 0.2;
/// Paces the whole motion may be played at before the warp, when no key pose holds the dance's
/// end: a motion a few per cent faster than its grid locks along its whole length at a pace
/// below 1, where at 1 (both ends fixed) it must lose a cycle in catch-ups, and those unlocked
/// stretches pull the spectrum's peak off the grid (eval 2026-11-26: tsmt on sugar_plum_fairy
/// read 3.2 % off 1/6 with 60 % of it locked). The motion's last `1 − pace` is then not shown.
/// A pace above 1 would need motion past the network's last frame, so there is none.
pub const PACES: [f64; 5] = [1.0, 0.97, 0.94, 0.91, 0.88];
/// Cost per second of the network's motion left unshown at a pace below 1: half an unlocked
/// second, so a pace is taken only where it locks more than twice what it drops.
const DROPPED_PER_S: f64 = 0.5;
/// A pace never slows a dance below this mean joint speed (m/s): the slowest real train dance's
/// (`metrics/reference_train.json`, `physical.mean_speed_range_m_s`; repeated here because motion
/// must not read the metric). Without it dance-revolution's slowest whole-song dance (0.53 m/s)
/// was played at 0.88 and fell under the plausibility verdict's 0.5 floor.
pub const LIVELY_M_S: f64 = 0.63;

/// What the stage did to one dance (report.json's `beat_align`, and each eval dance's).
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct BeatAlignSummary {
    /// Whether the motion was warped.
    pub applied: bool,
    /// Why not, when it was not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
    /// The motion's own step rate (Hz) before: the ankles' speed spectrum's peak.
    pub step_hz: f64,
    /// The song's beat rate over the dance (Hz).
    pub beat_hz: f64,
    /// The grid's rate as a fraction of the beat rate (0.5: a step every two beats).
    pub grid_fraction: f64,
    /// The grid's mean spacing (s).
    pub grid_spacing_s: f64,
    /// Kinematic beats (one per cycle of the motion's rhythm) and how many landed on grid points.
    pub kinematic_beats: usize,
    pub matched_beats: usize,
    /// Share of the dance's time in locked runs (motion cycles one-to-one on grid intervals).
    pub locked_share: f64,
    /// Mean and largest `|w(t) − t|` (s): how far the motion moved in time.
    pub mean_shift_s: f64,
    pub max_shift_s: f64,
    /// Smallest and largest slope of the warp (source frames per served frame).
    pub slope_min: f64,
    pub slope_max: f64,
    /// The pace the whole motion was played at under the warp ([`PACES`]): 1, or less where the
    /// motion's own steps were a little faster than the grid; its last `1 − pace` is not shown.
    #[serde(default = "one")]
    pub pace: f64,
    /// Which motion the warp's rhythm was read from: the network's, or the same motion with its
    /// feet planted ([`align_served`] plans on both).
    #[serde(default)]
    pub rhythm_from: RhythmFrom,
    /// Whether the served dance (warped, then its feet planted, and where [`align_served`] judged
    /// it, fitted to the rigid skeleton as downloaded) steps at a fraction of the beat: the
    /// ankles' spectral peak within 3 % of one of [`GRID_FRACTIONS`] × the beat rate.
    #[serde(default)]
    pub steps_on_beat: bool,
}

/// The motion a warp's rhythm (step rate and kinematic beats) was read from.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    utoipa::ToSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum RhythmFrom {
    /// The network's motion as it came.
    #[default]
    Network,
    /// The network's motion after the feet are planted (what is served, untimed).
    Planted,
}

fn one() -> f64 {
    1.0
}

impl BeatAlignSummary {
    fn skipped(why: &str) -> Self {
        Self {
            skipped: Some(why.to_string()),
            slope_min: 1.0,
            slope_max: 1.0,
            pace: 1.0,
            ..Self::default()
        }
    }
}

/// A time warp: for each served frame, the source frame (fractional) it shows.
#[derive(Clone, Debug)]
pub struct Warp {
    pub source_frames: Vec<f64>,
    pub summary: BeatAlignSummary,
}

/// The stage without a stage after it: `motion` warped onto the grid of `beat_times_s` (on the
/// dance's clock), with `fixed_times_s` (the key poses' times) mapped to themselves, and what was
/// done; [`align_served`] with the feet kept as they came.
pub fn align(
    motion: &Motion,
    beat_times_s: &[f64],
    fixed_times_s: &[f64],
) -> (Motion, BeatAlignSummary) {
    align_served(
        motion.clone(),
        beat_times_s,
        fixed_times_s,
        None::<fn(Motion) -> Motion>,
        None::<fn(&Motion) -> Option<Motion>>,
    )
}

/// The stage as jobs serve it, with the stage after it (`finish`: the feet planted; `None` where
/// the caller keeps the feet as they came) applied to what it returns, and `judge` (what a
/// finished motion becomes when it is served: the rigid skeleton fitted to it, as the user
/// downloads it and the report measures it; `None` where the finished motion is what is judged)
/// reading whether it steps on the beat.
///
/// Planting changes the rhythm the ankles show: it holds a foot still through a contact and so
/// sharpens some steps and drops others, and a slow sway of the network's can give way to the
/// steps (dancenet on hungarian_dance_5, seed 1: 0.26 Hz before planting, 0.61 after; eval
/// 2026-11-27). A warp planned on the network's rhythm alone then locks a rhythm the served
/// dance does not show, and one planned on the planted rhythm alone misses where planting hides
/// the rhythm that would have locked (keypose-transformer on the same song, seed 2). So the
/// warps are planned on both (without `finish`, on the network's only), one per grid fraction
/// within reach of each rhythm, and each warped dance is finished and checked (its ankles'
/// spectral peak within 3 % of a fraction of the beat rate: it steps on the beat; on a dance of
/// a few cycles the peak can land on a grid other than the one planned, or on none).
///
/// The finished dance as it came, unwarped, is a candidate too where it steps on the beat, after
/// every warp that does: a warp can take a dance that already steps on the beat off it (dancenet
/// on hungarian_dance_5 at 1.2×, seed 1: 0.507 of the beat rate as it came, 0.087 warped onto
/// every other beat; eval 2026-11-28).
///
/// Of the candidates that step on the beat, in order of cost, the first whose served dance
/// (`judge`) steps on it too is served: the rigid fit moves the ankles a little, and where a
/// spectrum's two peaks are near it can move the peak off the grid (dancenet on
/// sugar_plum_fairy at 0.85×, seed 1: 1/6 of the beat finished, 0.346 served, 3.7 % off 1/3).
/// A warp whose served dance holds one pose for 5 s or longer, and longer than the dance as it
/// came, is passed over for the next ([`lengthens_hold`]) that hangs no longer ([`choose`]).
/// When none is judged to, the first of them is served still; when none steps on the beat, the
/// warp of least cost. Without a warp the finished motion is served as it came. Cost: `finish`
/// once per warp, at most 13 times (15–78 ms on a 133-s song), and `judge` once per candidate
/// tried, at most [`MAX_JUDGED`] times (usually once).
pub fn align_served(
    motion: Motion,
    beat_times_s: &[f64],
    fixed_times_s: &[f64],
    finish: Option<impl Fn(Motion) -> Motion>,
    judge: Option<impl Fn(&Motion) -> Option<Motion>>,
) -> (Motion, BeatAlignSummary) {
    let aligned = align_served_parts(motion, beat_times_s, fixed_times_s, finish, judge);
    (aligned.served, aligned.summary)
}

/// What [`align_served`] chose, with the chosen dance before `finish`, so a caller can tell
/// what the warp and the stage after it each did.
pub struct Aligned {
    /// The dance served: `warped`, finished.
    pub served: Motion,
    pub summary: BeatAlignSummary,
    /// The network's motion under the chosen warp (as it came where none was chosen).
    pub warped: Motion,
    /// Frames `warped` shows from another moment of the network's motion (its source frame
    /// more than [`RETIMED_FRAMES`] of a frame from its own).
    pub frames_retimed: usize,
}

/// How far (frames) a served frame's source may lie from its own and the frame still count as
/// shown at its own time: a float's rounding, not a warp.
pub const RETIMED_FRAMES: f64 = 1e-3;

/// [`align_served`], with the chosen dance before `finish` ([`Aligned`]).
pub fn align_served_parts(
    motion: Motion,
    beat_times_s: &[f64],
    fixed_times_s: &[f64],
    finish: Option<impl Fn(Motion) -> Motion>,
    judge: Option<impl Fn(&Motion) -> Option<Motion>>,
) -> Aligned {
    let planted = finish.as_ref().map(|f| f(motion.clone()));
    let mut views = vec![(RhythmFrom::Network, &motion)];
    views.extend(planted.as_ref().map(|p| (RhythmFrom::Planted, p)));
    // (served motion, summary, cost, the warp's source frames: none for the dance as it came)
    let mut candidates: Vec<Candidate> = Vec::new();
    let mut skipped = None;
    for (from, view) in views {
        let warps = match plan_from(&motion, view, beat_times_s, fixed_times_s) {
            Ok(c) => c,
            Err(why) => {
                skipped.get_or_insert(why);
                continue;
            }
        };
        for (warp, cost) in warps {
            let warped = resample(&motion, &warp.source_frames);
            let served = match &finish {
                Some(f) => f(warped),
                None => warped,
            };
            let mut summary = warp.summary;
            summary.rhythm_from = from;
            summary.steps_on_beat = steps_on_beat(&served, beat_times_s);
            candidates.push((served, summary, cost, Some(warp.source_frames)));
        }
    }
    let from = if planted.is_some() {
        RhythmFrom::Planted
    } else {
        RhythmFrom::Network
    };
    let as_it_came = planted.unwrap_or_else(|| motion.clone());
    let came_hold_s = longest_hold_s(as_it_came.positions.view(), as_it_came.fps);
    let why_unwarped = if candidates.is_empty() {
        skipped.unwrap_or("nothing to align")
    } else {
        "it steps on the beat as it came, and no warp of it does"
    };
    match unwarped(&as_it_came, beat_times_s, from, why_unwarped) {
        Some(kept) => candidates.push((as_it_came, kept, f64::INFINITY, None)),
        None if candidates.is_empty() => {
            let mut summary = BeatAlignSummary::skipped(why_unwarped);
            summary.rhythm_from = from;
            return Aligned {
                served: as_it_came,
                summary,
                warped: motion,
                frames_retimed: 0,
            };
        }
        None => {}
    }
    // Those that step on the beat first, each group by cost (the unwarped last of its group).
    candidates.sort_by(|a, b| {
        (!a.1.steps_on_beat)
            .cmp(&!b.1.steps_on_beat)
            .then(a.2.total_cmp(&b.2))
    });
    let chosen = choose(&mut candidates, beat_times_s, judge.as_ref(), came_hold_s);
    let (served, summary, _, source_frames) = candidates.swap_remove(chosen);
    let (warped, frames_retimed) = match source_frames {
        Some(frames) => {
            let retimed = frames
                .iter()
                .enumerate()
                .filter(|&(f, &s)| (s - f as f64).abs() > RETIMED_FRAMES)
                .count();
            (resample(&motion, &frames), retimed)
        }
        None => (motion, 0),
    };
    Aligned {
        served,
        summary,
        warped,
        frames_retimed,
    }
}

/// A dance [`align_served`] may serve: finished, what its warp did, its cost, and the warp's
/// source frames (none for the dance as it came).
type Candidate = (Motion, BeatAlignSummary, f64, Option<Vec<f64>>);

/// Which of the sorted `candidates` [`align_served`] serves: of the first [`MAX_JUDGED`] that
/// step on the beat, the first whose served dance (`judge`'s; the candidate itself without one)
/// steps on it too and does not hold one pose longer than the dance as it came did
/// (`came_hold_s`, [`lengthens_hold`]); one after a candidate passed over for a hold only where
/// its served dance hangs (both feet up, [`hang_s`]) no longer than that one's or than real
/// dancers do ([`HANG_REAL_MAX_S`]): a warp slows a hop as it slows a pose, and the first
/// alternative to a hold found was served with a 1.04-s hang, over the verdict's 1.0 (tsmt,
/// DANCE_R_9 seed 4; the tsmt card). Else the first of them whose served
/// dance steps on the beat; else the first. Each judged candidate's `steps_on_beat` is set to
/// what its served dance does.
fn choose(
    candidates: &mut [Candidate],
    beat_times_s: &[f64],
    judge: Option<&impl Fn(&Motion) -> Option<Motion>>,
    came_hold_s: f64,
) -> usize {
    // The first on the beat, passed over for a hold, and its hang.
    let mut on_beat: Option<(usize, f64)> = None;
    for (i, (candidate, summary, _, _)) in candidates.iter_mut().take(MAX_JUDGED).enumerate() {
        if !summary.steps_on_beat {
            break;
        }
        let judged = judge.map(|j| j(candidate));
        let served = match &judged {
            Some(Some(m)) => m,
            Some(None) => {
                summary.steps_on_beat = false;
                continue;
            }
            None => &*candidate,
        };
        if judged.is_some() {
            summary.steps_on_beat = steps_on_beat(served, beat_times_s);
            if !summary.steps_on_beat {
                continue;
            }
        }
        let holds = lengthens_hold(served, came_hold_s);
        match on_beat {
            None if !holds => return i,
            None => on_beat = Some((i, hang_s(served.positions.view(), served.fps))),
            Some((_, first_hang_s)) => {
                if !holds
                    && hang_s(served.positions.view(), served.fps)
                        <= first_hang_s.max(HANG_REAL_MAX_S)
                {
                    return i;
                }
            }
        }
        tracing::debug!(candidate = i, holds, "beat-align: a warp passed over");
    }
    on_beat.map_or(0, |(i, _)| i)
}

/// `served` holds one pose ([`longest_hold_s`]) for [`HOLD_NOTED_S`] or longer, and longer
/// than the dance as it came (`came_hold_s`, plus [`HOLD_SLACK_S`]). A warp slows what it
/// stretches, and a slow stretch slowed reads as a hold: tsmt's own 2.6–5.0-s holds were served
/// as 5.0–6.4-s stands (16 of 120 dances at seeds 1–6 held 5 s or longer; the tsmt
/// card), longer than 41 of the 43 real dances ever hold.
fn lengthens_hold(served: &Motion, came_hold_s: f64) -> bool {
    let held = longest_hold_s(served.positions.view(), served.fps);
    held >= HOLD_NOTED_S && held > came_hold_s + HOLD_SLACK_S
}

/// How much longer (s) than the dance as it came a served hold may read without the warp being
/// blamed: planting and the rigid fit move a hold's edges by a few frames.
const HOLD_SLACK_S: f64 = 0.2;

/// Most candidates [`align_served`] has judged as served (each a rigid fit of the whole dance,
/// about as long as the export's: 0.1–0.3 s for a 3-minute song) before it gives up on finding
/// one whose served dance steps on the beat.
const MAX_JUDGED: usize = 4;

/// The summary of `motion` served as it came where it steps on the beat (`why`: why it is not
/// warped); `None` where it does not.
fn unwarped(
    motion: &Motion,
    beat_times_s: &[f64],
    from: RhythmFrom,
    why: &str,
) -> Option<BeatAlignSummary> {
    let beat = on_beat(motion, beat_times_s)?;
    Some(BeatAlignSummary {
        step_hz: beat.step_hz,
        beat_hz: beat.beat_hz,
        grid_fraction: beat.fraction,
        grid_spacing_s: 1.0 / (beat.fraction * beat.beat_hz),
        rhythm_from: from,
        steps_on_beat: true,
        ..BeatAlignSummary::skipped(why)
    })
}

/// Where a motion steps on the beat: its step rate, the song's beat rate over it, and the
/// fraction of that its steps are at.
struct OnBeat {
    step_hz: f64,
    beat_hz: f64,
    fraction: f64,
}

/// Whether `motion` steps at a fraction of the song's beat rate: the ankles' spectral peak (as
/// [`step_rate`] reads it at [`CHECK_ZERO_PAD`], the metric's) within the lock tolerance of one of [`GRID_FRACTIONS`] × it.
fn on_beat(motion: &Motion, beat_times_s: &[f64]) -> Option<OnBeat> {
    let fps = motion.fps;
    let clock = BeatClock::new(beat_times_s, motion.num_frames() as f64 / fps)?;
    let (step_hz, _) = step_rate(
        &ankle_speed(motion.positions.view(), fps),
        fps,
        CHECK_ZERO_PAD,
    )?;
    let fraction = GRID_FRACTIONS
        .into_iter()
        .find(|q| (step_hz / (q * clock.rate_hz) - 1.0).abs() <= LOCK_TOLERANCE)?;
    Some(OnBeat {
        step_hz,
        beat_hz: clock.rate_hz,
        fraction,
    })
}

fn steps_on_beat(motion: &Motion, beat_times_s: &[f64]) -> bool {
    on_beat(motion, beat_times_s).is_some()
}

/// The motion shown at the warp's source frames: Catmull-Rom between frames, exact on them.
pub fn resample(motion: &Motion, source_frames: &[f64]) -> Motion {
    let p = motion.positions.view();
    let (frames, joints, dims) = p.dim();
    let last = frames.saturating_sub(1) as isize;
    let at = |i: isize| i.clamp(0, last) as usize;
    let mut out = Array3::<f32>::zeros((source_frames.len(), joints, dims));
    for (f, &x) in source_frames.iter().enumerate() {
        let x = x.clamp(0.0, last as f64);
        let i = x.floor() as isize;
        let u = x - i as f64;
        let [i0, i1, i2, i3] = [at(i - 1), at(i), at(i + 1), at(i + 2)];
        for j in 0..joints {
            for c in 0..dims {
                let [p0, p1, p2, p3] = [i0, i1, i2, i3].map(|k| f64::from(p[[k, j, c]]));
                let v = if u == 0.0 {
                    p1
                } else {
                    0.5 * (2.0 * p1
                        + (p2 - p0) * u
                        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * u * u
                        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * u * u * u)
                };
                out[[f, j, c]] = v as f32;
            }
        }
    }
    Motion {
        fps: motion.fps,
        positions: out,
    }
}

#[cfg(test)]
mod tests;
