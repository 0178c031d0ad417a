//! Beat alignment: the served stage that moves a dance's steps onto the song's beats (issue 25,
//! item 4), after the network and before [`super::finish`] plants the feet.
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
use ndarray::{Array3, ArrayView3, Axis};
use realfft::RealFftPlanner;

use super::skeleton::ANKLES;
use super::Motion;

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
    let planted = finish.as_ref().map(|f| f(motion.clone()));
    let mut views = vec![(RhythmFrom::Network, &motion)];
    views.extend(planted.as_ref().map(|p| (RhythmFrom::Planted, p)));
    // (served motion, summary, cost)
    let mut candidates: Vec<(Motion, BeatAlignSummary, f64)> = Vec::new();
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
            candidates.push((served, summary, cost));
        }
    }
    let from = if planted.is_some() {
        RhythmFrom::Planted
    } else {
        RhythmFrom::Network
    };
    let as_it_came = planted.unwrap_or(motion);
    let why_unwarped = if candidates.is_empty() {
        skipped.unwrap_or("nothing to align")
    } else {
        "it steps on the beat as it came, and no warp of it does"
    };
    match unwarped(&as_it_came, beat_times_s, from, why_unwarped) {
        Some(kept) => candidates.push((as_it_came, kept, f64::INFINITY)),
        None if candidates.is_empty() => {
            let mut summary = BeatAlignSummary::skipped(why_unwarped);
            summary.rhythm_from = from;
            return (as_it_came, summary);
        }
        None => {}
    }
    // Those that step on the beat first, each group by cost (the unwarped last of its group).
    candidates.sort_by(|a, b| {
        (!a.1.steps_on_beat)
            .cmp(&!b.1.steps_on_beat)
            .then(a.2.total_cmp(&b.2))
    });
    let mut chosen = 0;
    if let Some(judge) = &judge {
        for (i, (served, summary, _)) in candidates.iter_mut().take(MAX_JUDGED).enumerate() {
            if !summary.steps_on_beat {
                break;
            }
            summary.steps_on_beat = judge(served).is_some_and(|m| steps_on_beat(&m, beat_times_s));
            if summary.steps_on_beat {
                chosen = i;
                break;
            }
        }
    }
    let (served, summary, _) = candidates.swap_remove(chosen);
    (served, summary)
}

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

/// The warps [`align_served`] chooses from, one per grid fraction within reach (the least cost
/// of its phases and, where no fixed time lies after the first frame, of [`PACES`], a pace's
/// dropped tail counted), with their costs; the rhythm read from `view` (the same frames as
/// `motion`, e.g. with the feet planted), the warps applying to `motion`. `Err`: why there is
/// none.
fn plan_from(
    motion: &Motion,
    view: &Motion,
    beat_times_s: &[f64],
    fixed_times_s: &[f64],
) -> Result<Vec<(Warp, f64)>, &'static str> {
    let frames = motion.num_frames();
    let held = fixed_times_s
        .iter()
        .any(|t| t.is_finite() && *t * motion.fps >= 0.5);
    // The dance's mean joint speed, as the plausibility verdict takes it.
    let steps = super::skeleton::mean_speed(motion.positions.view(), motion.fps);
    let speed = steps.iter().sum::<f64>() / steps.len().max(1) as f64;
    let paces: Vec<f64> = PACES
        .into_iter()
        .filter(|&p| p == 1.0 || (!held && p * speed >= LIVELY_M_S))
        .collect();
    let end_s = frames.saturating_sub(1) as f64 / motion.fps;
    // Per grid fraction: (q, cost, warp).
    let mut best: Vec<(f64, f64, Warp)> = Vec::new();
    let mut why = None;
    for pace in paces {
        let paced;
        let m = if pace == 1.0 {
            view
        } else {
            let at: Vec<f64> = (0..frames).map(|f| f as f64 * pace).collect();
            paced = resample(view, &at);
            &paced
        };
        // A pace that warps nothing would only drop the tail: it has no candidates.
        let candidates = match plan_at(m, beat_times_s, fixed_times_s, pace) {
            Ok(c) => c,
            Err(w) => {
                why.get_or_insert(w);
                continue;
            }
        };
        for (q, mut warp, cost) in candidates {
            let cost = cost + DROPPED_PER_S * (1.0 - pace) * end_s;
            warp.source_frames.iter_mut().for_each(|s| *s *= pace);
            warp.summary.step_hz /= pace;
            warp.summary.pace = pace;
            match best.iter_mut().find(|b| b.0 == q) {
                Some(b) if cost < b.1 => *b = (q, cost, warp),
                Some(_) => {}
                None => best.push((q, cost, warp)),
            }
        }
    }
    if best.is_empty() {
        return Err(why.unwrap_or("no grid of the beat is within the warp's reach"));
    }
    let fps = motion.fps;
    Ok(best
        .into_iter()
        .map(|(_, cost, mut warp)| {
            let slopes: Vec<f64> = warp.source_frames.windows(2).map(|w| w[1] - w[0]).collect();
            let shifts: Vec<f64> = warp
                .source_frames
                .iter()
                .enumerate()
                .map(|(f, &s)| (s - f as f64).abs() / fps)
                .collect();
            let s = &mut warp.summary;
            s.mean_shift_s = shifts.iter().sum::<f64>() / shifts.len() as f64;
            s.max_shift_s = shifts.iter().copied().fold(0.0, f64::max);
            s.slope_min = slopes.iter().copied().fold(f64::INFINITY, f64::min);
            s.slope_max = slopes.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (warp, cost)
        })
        .collect())
}

/// The warps of `motion` (the network's played at `pace`), one per grid fraction within reach
/// (its phase of least cost), as (fraction, warp, cost); their slopes are kept within
/// [`SLOPE_RANGE`] once `pace` is applied. `Err`: why there is none.
fn plan_at(
    motion: &Motion,
    beat_times_s: &[f64],
    fixed_times_s: &[f64],
    pace: f64,
) -> Result<Vec<(f64, Warp, f64)>, &'static str> {
    let frames = motion.num_frames();
    let fps = motion.fps;
    if frames < MIN_FRAMES || fps <= 0.0 || !fps.is_finite() {
        return Err("the dance is too short");
    }
    let end_s = (frames - 1) as f64 / fps;
    let Some(clock) = BeatClock::new(beat_times_s, frames as f64 / fps) else {
        return Err("fewer than 4 beats within the dance");
    };
    let speed = ankle_speed(motion.positions.view(), fps);
    let Some((step_hz, filtered)) = rhythm(&speed, fps) else {
        return Err("no step rate: the ankles do not move");
    };
    let kin = kinematic_beats(&filtered, fps, step_hz);
    // Fixed frames: the start, the end, and each key pose's frame (as `serve` anchors them).
    let mut fixed: Vec<usize> = fixed_times_s
        .iter()
        .filter(|t| t.is_finite())
        .map(|t| ((t * fps).round().max(0.0) as usize).min(frames - 1))
        .collect();
    fixed.extend([0, frames - 1]);
    fixed.sort_unstable();
    fixed.dedup();
    let anchors: Vec<f64> = fixed.iter().map(|&f| f as f64 / fps).collect();

    // Every grid within reach: its spacing over the motion's cycle is the slope of a lock.
    let mut out = Vec::new();
    for &q in &GRID_FRACTIONS {
        let slope = pace * q * clock.rate_hz / step_hz;
        // A grid outside the band the step rate is read in (with the lock's tolerance) cannot be
        // the served dance's step rate: a waltz at 87 bpm stepped every 6 beats (0.24 Hz) reads
        // as 0.25 Hz, 4 % off (eval 2026-11-25: dancenet's four waltz test dances).
        let grid_hz = q * clock.rate_hz;
        let in_band = grid_hz >= STEP_BAND_HZ.0 * (1.0 + LOCK_TOLERANCE)
            && grid_hz <= STEP_BAND_HZ.1 / (1.0 + LOCK_TOLERANCE);
        if !in_band || !(SLOPE_RANGE.0..=SLOPE_RANGE.1).contains(&slope) {
            continue;
        }
        let mut best: Option<(f64, Vec<Pair>, f64)> = None; // (cost, pairs, locked s)
        for start in grid_phases(q) {
            let grid = clock.grid(q, start, end_s);
            let (mut cost, mut pairs, mut locked) = (0.0, Vec::new(), 0.0);
            for span in anchors.windows(2) {
                let (a, b) = (span[0], span[1]);
                let k: Vec<f64> = kin.iter().copied().filter(|&t| t > a && t < b).collect();
                let g: Vec<f64> = grid.iter().copied().filter(|&t| t > a && t < b).collect();
                let p = match_span(a, b, &k, &g, pace);
                cost += p.cost;
                locked += p.locked_s;
                pairs.extend(p.pairs);
            }
            if best.as_ref().is_none_or(|b| cost < b.0) {
                best = Some((cost, pairs, locked));
            }
        }
        let Some((cost, pairs, locked_s)) = best else {
            continue;
        };
        // Knots (served s, source s): the fixed frames and the matched beats, in time order.
        let mut knots: Vec<Pair> = anchors
            .iter()
            .map(|&a| Pair { out: a, src: a })
            .chain(pairs.iter().copied())
            .collect();
        knots.sort_by(|x, y| x.out.total_cmp(&y.out));
        let source_frames = smooth_warp(&knots, &fixed, frames, fps);
        // Shifts and slopes are measured by `plan_from`, on the warp of the network's own frames.
        let summary = BeatAlignSummary {
            applied: true,
            skipped: None,
            step_hz,
            beat_hz: clock.rate_hz,
            grid_fraction: q,
            grid_spacing_s: 1.0 / (q * clock.rate_hz),
            kinematic_beats: kin.len(),
            matched_beats: pairs.len(),
            locked_share: locked_s / end_s,
            pace: 1.0,
            ..BeatAlignSummary::default()
        };
        out.push((
            q,
            Warp {
                source_frames,
                summary,
            },
            cost,
        ));
    }
    if out.is_empty() {
        return Err("no grid of the beat is within the warp's reach of the motion's step rate");
    }
    Ok(out)
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

/// The ankles' summed speed (m/s) between consecutive frames: sample `i` lies at `(i + ½)/fps`.
fn ankle_speed(p: ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let frames = p.len_of(Axis(0));
    (1..frames)
        .map(|f| {
            ANKLES
                .iter()
                .map(|&j| {
                    (0..3)
                        .map(|c| (f64::from(p[[f, j, c]]) - f64::from(p[[f - 1, j, c]])).powi(2))
                        .sum::<f64>()
                        .sqrt()
                        * fps
                })
                .sum()
        })
        .collect()
}

/// The zero-padding of the spectrum whose peak the warp is planned on: 8× its length.
const PLAN_ZERO_PAD: usize = 8;
/// The zero-padding of the spectrum whose peak says whether a dance steps on the beat: the
/// metric's ([`crate::metrics::musicality::ZERO_PAD`], a unit test checks), so the stage reads
/// the peak where the report will. At 8× a 4.4-s dance's peak fell on bins 2.3 % apart, and the
/// stage called a dance on the beat that the metric read 4.1 % off (dancenet on the trumpet loop
/// at 1.2×, seed 2; eval 2026-11-28).
const CHECK_ZERO_PAD: usize = 16;

/// The step rate (Hz: the peak within [`STEP_BAND_HZ`] of the Hann-windowed spectrum
/// zero-padded to `zero_pad` × its length, as the metric finds it), with the speed centred on
/// its mean; `None` where the speed does not change.
fn step_rate(speed: &[f64], fps: f64, zero_pad: usize) -> Option<(f64, Vec<f64>)> {
    let n = speed.len();
    let mean = speed.iter().sum::<f64>() / n.max(1) as f64;
    let centred: Vec<f64> = speed.iter().map(|v| v - mean).collect();
    if n < 2 || centred.iter().all(|v| v.abs() < 1e-9) {
        return None;
    }
    // Hann window (symmetric, numpy's), zero-padded to interpolate between bins.
    let padded = zero_pad * n;
    let mut input = vec![0.0; padded];
    for (i, v) in centred.iter().enumerate() {
        input[i] = v * (0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / (n - 1) as f64).cos());
    }
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(padded);
    let mut spectrum = fft.make_output_vec();
    fft.process(&mut input, &mut spectrum).ok()?;
    let bin_hz = fps / padded as f64;
    let step_hz = spectrum
        .iter()
        .enumerate()
        .map(|(k, c)| (k as f64 * bin_hz, c.norm()))
        .filter(|(f, _)| (STEP_BAND_HZ.0..=STEP_BAND_HZ.1).contains(f))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(f, _)| f)?;
    Some((step_hz, centred))
}

/// The step rate ([`step_rate`] at [`PLAN_ZERO_PAD`]) and the speed band-passed around it.
fn rhythm(speed: &[f64], fps: f64) -> Option<(f64, Vec<f64>)> {
    let (step_hz, centred) = step_rate(speed, fps, PLAN_ZERO_PAD)?;
    let n = centred.len();
    let mut planner = RealFftPlanner::<f64>::new();
    // The band-pass: no window (the whole series keeps its weight), padded 2× so the circular
    // convolution's wrap falls in the padding.
    let padded = 2 * n;
    let mut input = vec![0.0; padded];
    input[..n].copy_from_slice(&centred);
    let fft = planner.plan_fft_forward(padded);
    let mut spectrum = fft.make_output_vec();
    fft.process(&mut input, &mut spectrum).ok()?;
    let bin_hz = fps / padded as f64;
    for (k, c) in spectrum.iter_mut().enumerate() {
        let f = k as f64 * bin_hz;
        let gain = if k == 0 {
            0.0
        } else {
            (-0.5 * ((f / step_hz).ln() / BAND_WIDTH_LN).powi(2)).exp()
        };
        *c *= gain / padded as f64;
    }
    let ifft = planner.plan_fft_inverse(padded);
    let mut out = ifft.make_output_vec();
    ifft.process(&mut spectrum, &mut out).ok()?;
    out.truncate(n);
    Some((step_hz, out))
}

/// Minima below zero of the band-passed speed (sub-frame, by a parabola through three samples),
/// at least half a cycle apart (of two closer, the deeper), as times in seconds.
fn kinematic_beats(x: &[f64], fps: f64, step_hz: f64) -> Vec<f64> {
    let min_gap_s = 0.5 / step_hz;
    let mut out: Vec<(f64, f64)> = Vec::new();
    for i in 1..x.len().saturating_sub(1) {
        if !(x[i] < x[i - 1] && x[i] <= x[i + 1] && x[i] < 0.0) {
            continue;
        }
        let curvature = x[i - 1] - 2.0 * x[i] + x[i + 1];
        let offset = if curvature > 0.0 {
            (0.5 * (x[i - 1] - x[i + 1]) / curvature).clamp(-0.5, 0.5)
        } else {
            0.0
        };
        let t = (i as f64 + offset + 0.5) / fps;
        match out.last_mut() {
            Some(last) if t - last.0 < min_gap_s => {
                if x[i] < last.1 {
                    *last = (t, x[i]);
                }
            }
            _ => out.push((t, x[i])),
        }
    }
    out.into_iter().map(|(t, _)| t).collect()
}

/// The song's beats as a clock: beat index as a function of time, linear between beats and
/// extrapolated at the mean spacing before the first and after the last.
struct BeatClock {
    times: Vec<f64>,
    period: f64,
    /// The beat rate over the dance, as the metric takes it: `(n − 1) / (last − first)` of the
    /// beats within it.
    rate_hz: f64,
}

impl BeatClock {
    fn new(beat_times_s: &[f64], duration_s: f64) -> Option<Self> {
        let mut times: Vec<f64> = beat_times_s
            .iter()
            .copied()
            .filter(|t| t.is_finite())
            .collect();
        times.sort_by(f64::total_cmp);
        times.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        let inside: Vec<f64> = times
            .iter()
            .copied()
            .filter(|t| (0.0..=duration_s).contains(t))
            .collect();
        let (first, last) = (*inside.first()?, *inside.last()?);
        if inside.len() < MIN_BEATS || last <= first {
            return None;
        }
        let rate_hz = (inside.len() - 1) as f64 / (last - first);
        let period = (times[times.len() - 1] - times[0]) / (times.len() - 1) as f64;
        Some(Self {
            times,
            period,
            rate_hz,
        })
    }

    /// Beat index (fractional) at time `t`.
    fn phase(&self, t: f64) -> f64 {
        let n = self.times.len();
        if t <= self.times[0] {
            return (t - self.times[0]) / self.period;
        }
        if t >= self.times[n - 1] {
            return (n - 1) as f64 + (t - self.times[n - 1]) / self.period;
        }
        let i = self.times.partition_point(|&b| b <= t) - 1;
        i as f64 + (t - self.times[i]) / (self.times[i + 1] - self.times[i])
    }

    /// Time at beat index `phase`.
    fn time_at(&self, phase: f64) -> f64 {
        let n = self.times.len();
        if phase <= 0.0 {
            return self.times[0] + phase * self.period;
        }
        if phase >= (n - 1) as f64 {
            return self.times[n - 1] + (phase - (n - 1) as f64) * self.period;
        }
        let i = phase.floor() as usize;
        self.times[i] + (phase - i as f64) * (self.times[i + 1] - self.times[i])
    }

    /// Grid points in `(0, end_s)`: beat indices `start + n / q`.
    fn grid(&self, q: f64, start: f64, end_s: f64) -> Vec<f64> {
        let spacing = 1.0 / q;
        let (p0, p1) = (self.phase(0.0), self.phase(end_s));
        let first = ((p0 - start) / spacing).ceil() as i64;
        let last = ((p1 - start) / spacing).floor() as i64;
        (first..=last)
            .map(|n| self.time_at(start + n as f64 * spacing))
            .filter(|&t| t > 0.0 && t < end_s)
            .collect()
    }
}

/// Where a grid of `q` × the beat rate may start, in beats: each beat of a group (2/3: each half
/// beat of its 1½).
fn grid_phases(q: f64) -> Vec<f64> {
    let spacing = 1.0 / q;
    let step = if (spacing - spacing.round()).abs() < 1e-9 {
        1.0
    } else {
        0.5
    };
    (0..(spacing / step).round() as usize)
        .map(|m| m as f64 * step)
        .collect()
}

/// A knot of the warp: served time `out` shows source time `src` (s).
#[derive(Clone, Copy, Debug)]
struct Pair {
    out: f64,
    src: f64,
}

/// The best monotone matching of one span between fixed times.
struct SpanPlan {
    cost: f64,
    pairs: Vec<Pair>,
    locked_s: f64,
}

/// Cost of a segment lasting `d_out` served seconds over `d_src` seconds of the motion played at
/// `pace`, locked or not, skipping `skips` beats; `None` when the slope (of the network's motion:
/// `pace · d_src / d_out`) is out of range.
fn segment_cost(d_out: f64, d_src: f64, locked: bool, skips: usize, pace: f64) -> Option<f64> {
    if d_out <= 0.0 || d_src <= 0.0 {
        return None;
    }
    let slope = pace * d_src / d_out;
    if !(SLOPE_RANGE.0..=SLOPE_RANGE.1).contains(&slope) {
        return None;
    }
    let limit = SLOPE_RANGE.0.ln().abs().max(SLOPE_RANGE.1.ln().abs());
    let distortion = DISTORTION_AT_LIMIT_PER_S * (slope.ln() / limit).powi(2);
    Some(d_out * (distortion + if locked { 0.0 } else { UNLOCKED_PER_S }) + SKIP * skips as f64)
}

/// Matches kinematic beats `k` to grid points `g` (both sorted, inside `(a, b)`), monotonically,
/// with the span's ends fixed (`a → a`, `b → b`), for the motion played at `pace`.
fn match_span(a: f64, b: f64, k: &[f64], g: &[f64], pace: f64) -> SpanPlan {
    let (m, n) = (k.len(), g.len());
    // Leaving the span as it is: slope 1, nothing locked.
    let mut best = SpanPlan {
        cost: UNLOCKED_PER_S * (b - a) + SKIP * (m + n) as f64,
        pairs: Vec::new(),
        locked_s: 0.0,
    };
    if m == 0 || n == 0 {
        return best;
    }
    // cost, previous node (None: the span's start), locked seconds so far.
    let mut table: Vec<Option<(f64, Option<usize>, f64)>> = vec![None; m * n];
    for i in 0..m {
        for j in 0..n {
            let mut cell: Option<(f64, Option<usize>, f64)> = None;
            let mut offer = |c: f64, prev: Option<usize>, locked: f64| {
                if cell.is_none_or(|x| c < x.0) {
                    cell = Some((c, prev, locked));
                }
            };
            if i < MAX_EDGE_SKIP && j < MAX_EDGE_SKIP {
                if let Some(c) = segment_cost(g[j] - a, k[i] - a, false, i + j, pace) {
                    offer(c, None, 0.0);
                }
            }
            for da in 1..=MAX_RUN.min(i) {
                for db in 1..=MAX_RUN.min(j) {
                    let p = (i - da) * n + (j - db);
                    let Some((pc, _, pl)) = table[p] else {
                        continue;
                    };
                    let locked = da == db;
                    if let Some(c) = segment_cost(
                        g[j] - g[j - db],
                        k[i] - k[i - da],
                        locked,
                        da + db - 2,
                        pace,
                    ) {
                        offer(
                            pc + c,
                            Some(p),
                            pl + if locked { g[j] - g[j - db] } else { 0.0 },
                        );
                    }
                }
            }
            table[i * n + j] = cell;
        }
    }
    let mut end: Option<(f64, usize, f64)> = None;
    for i in m.saturating_sub(MAX_EDGE_SKIP)..m {
        for j in n.saturating_sub(MAX_EDGE_SKIP)..n {
            let Some((c, _, l)) = table[i * n + j] else {
                continue;
            };
            if let Some(e) =
                segment_cost(b - g[j], b - k[i], false, (m - 1 - i) + (n - 1 - j), pace)
            {
                if end.is_none_or(|x| c + e < x.0) {
                    end = Some((c + e, i * n + j, l));
                }
            }
        }
    }
    if let Some((cost, last, locked_s)) = end.filter(|e| e.0 < best.cost) {
        let mut pairs = Vec::new();
        let mut at = Some(last);
        while let Some(node) = at {
            let prev = table[node].and_then(|(_, prev, _)| prev);
            pairs.push(Pair {
                out: g[node % n],
                src: k[node / n],
            });
            at = prev;
        }
        pairs.reverse();
        best = SpanPlan {
            cost,
            pairs,
            locked_s,
        };
    }
    best
}

/// The warp through `knots` (seconds) as source frames per served frame: piecewise linear, its
/// per-frame slope Gaussian-smoothed, then scaled per span between `fixed` frames so each maps to
/// itself.
fn smooth_warp(knots: &[Pair], fixed: &[usize], frames: usize, fps: f64) -> Vec<f64> {
    let (outs, srcs): (Vec<f64>, Vec<f64>) =
        knots.iter().map(|p| (p.out * fps, p.src * fps)).unzip();
    let linear = |f: f64| -> f64 {
        let i = outs.partition_point(|&o| o <= f).clamp(1, outs.len() - 1);
        let (o0, o1, s0, s1) = (outs[i - 1], outs[i], srcs[i - 1], srcs[i]);
        if o1 > o0 {
            s0 + (f - o0) * (s1 - s0) / (o1 - o0)
        } else {
            s0
        }
    };
    let slope: Vec<f64> = (0..frames - 1)
        .map(|f| linear(f as f64 + 1.0) - linear(f as f64))
        .collect();
    let sigma = SLOPE_SMOOTH_S * fps;
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|d| (-0.5 * (d as f64 / sigma).powi(2)).exp())
        .collect();
    let total: f64 = kernel.iter().sum();
    let last = slope.len() as isize - 1;
    let smoothed: Vec<f64> = (0..slope.len() as isize)
        .map(|f| {
            kernel
                .iter()
                .zip(-radius..=radius)
                .map(|(w, d)| w * slope[(f + d).clamp(0, last) as usize])
                .sum::<f64>()
                / total
        })
        .collect();
    let mut out = vec![0.0; frames];
    for span in fixed.windows(2) {
        let (a, b) = (span[0], span[1]);
        let sum: f64 = smoothed[a..b].iter().sum();
        let scale = if sum > 0.0 { (b - a) as f64 / sum } else { 1.0 };
        out[a] = a as f64;
        let mut acc = a as f64;
        for f in a..b {
            acc += smoothed[f] * scale;
            out[f + 1] = acc;
        }
        out[b] = b as f64;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::musicality::{tempo_lock, TEMPO_FRACTIONS};
    use crate::motion::NUM_JOINTS;

    const FPS: f64 = 25.0;

    /// A dance whose ankles travel with speed `1 + 0.8 cos(2π f t)` (so the step rate is `f`), the
    /// rest of the body still; the ankles swing up and down too, so no two frames are equal.
    fn periodic(seconds: f64, f: f64) -> Motion {
        let frames = (seconds * FPS) as usize;
        let mut p = Array3::<f32>::zeros((frames, NUM_JOINTS, 3));
        for t in 0..frames {
            let s = t as f64 / FPS;
            let x = s + 0.8 * (std::f64::consts::TAU * f * s).sin() / (std::f64::consts::TAU * f);
            for (side, &j) in ANKLES.iter().enumerate() {
                p[[t, j, 0]] = x as f32;
                p[[t, j, 1]] =
                    (0.1 + 0.05 * (std::f64::consts::TAU * f * s + side as f64).cos()) as f32;
                p[[t, j, 2]] = side as f32 * 0.3;
            }
        }
        Motion {
            fps: FPS,
            positions: p,
        }
    }

    /// Beats every `period` s from `first` to past `seconds`.
    fn beats(seconds: f64, period: f64, first: f64) -> Vec<f64> {
        (0..)
            .map(|i| first + i as f64 * period)
            .take_while(|&t| t < seconds + period)
            .collect()
    }

    #[test]
    fn the_grid_fractions_and_the_checks_padding_are_the_metrics() {
        assert_eq!(GRID_FRACTIONS, TEMPO_FRACTIONS);
        assert_eq!(CHECK_ZERO_PAD, crate::metrics::musicality::ZERO_PAD);
    }

    #[test]
    fn a_periodic_motion_off_the_grid_becomes_locked() {
        // 120 bpm; steps at 0.93 Hz, 7 % off half the beat rate: not locked as it comes.
        let (motion, beats) = (periodic(60.0, 0.93), beats(60.0, 0.5, 0.21));
        let before = tempo_lock(motion.positions.view(), FPS, &beats).expect("measured");
        assert!(!before.locked, "{before:?}");
        let (aligned, summary) = align(&motion, &beats, &[]);
        assert!(summary.applied, "{summary:?}");
        assert_eq!(summary.grid_fraction, 0.5);
        let after = tempo_lock(aligned.positions.view(), FPS, &beats).expect("measured");
        assert!(
            after.locked && (after.fraction - 0.5).abs() < 1e-9,
            "{after:?} {summary:?}"
        );
        assert!(summary.locked_share > 0.6, "{summary:?}");
        // Tempo changes: the same dance to a song 15 % faster locks too.
        let faster = beats_for(60.0, 0.5 / 1.15);
        let (aligned, summary) = align(&motion, &faster, &[]);
        let after = tempo_lock(aligned.positions.view(), FPS, &faster).expect("measured");
        assert!(after.locked, "{after:?} {summary:?}");
    }

    #[test]
    fn a_rhythm_only_the_planted_dance_shows_is_the_one_locked() {
        // Steps at 0.93 Hz under a wide sway (sideways, in z) that the stage after it removes,
        // as planting removes a slow drift of a network's feet. The sway's speed peaks twice a
        // cycle, at 0.28 Hz: at 180 bpm out of every grid's reach (1/6 of the beat is 0.5 Hz).
        let beats = beats_for(60.0, 1.0 / 3.0);
        let mut motion = periodic(60.0, 0.93);
        for t in 0..motion.num_frames() {
            let s = t as f64 / FPS;
            for &j in &ANKLES {
                motion.positions[[t, j, 2]] +=
                    3.0 * (std::f64::consts::TAU * 0.14 * s).sin() as f32;
            }
        }
        let unsway = |mut m: Motion| {
            for t in 0..m.num_frames() {
                for (side, &j) in ANKLES.iter().enumerate() {
                    m.positions[[t, j, 2]] = side as f32 * 0.3;
                }
            }
            m
        };
        let (_, network_only) = align(&motion, &beats, &[]);
        assert!(!network_only.applied, "{network_only:?}");
        let (served, summary) = align_served(
            motion.clone(),
            &beats,
            &[],
            Some(unsway),
            None::<fn(&Motion) -> Option<Motion>>,
        );
        assert!(summary.applied, "{summary:?}");
        assert_eq!(summary.rhythm_from, RhythmFrom::Planted);
        assert!(summary.steps_on_beat, "{summary:?}");
        let after = tempo_lock(served.positions.view(), FPS, &beats).expect("measured");
        assert!(after.locked, "{after:?} {summary:?}");
        // What is served went through the stage after it: no sway left.
        assert!(served.positions.iter().all(|v| v.is_finite()));
        assert!((0..served.num_frames()).all(|t| served.positions[[t, ANKLES[0], 2]] == 0.0));
    }

    /// No stage after it, and no judge.
    const UNFINISHED: Option<fn(Motion) -> Motion> = None;

    #[test]
    fn a_warp_whose_served_dance_is_off_the_beat_gives_way_to_the_next() {
        // Steps 4.5 % fast for half the beat rate, the body travelling: warps onto 1/2 and 2/3
        // of the beat rate, and paces, all step on the beat.
        let beats = beats(60.0, 0.5, 0.21);
        let mut motion = periodic(60.0, 1.045);
        for t in 0..motion.num_frames() {
            for j in (0..NUM_JOINTS).filter(|j| !ANKLES.contains(j)) {
                motion.positions[[t, j, 0]] = (t as f64 / FPS) as f32;
            }
        }
        let no_judge = None::<fn(&Motion) -> Option<Motion>>;
        let (first, s) = align_served(motion.clone(), &beats, &[], UNFINISHED, no_judge);
        assert!(s.applied && s.steps_on_beat, "{s:?}");
        // Served, the first choice stands still (no step rate at all); the next is served.
        let still = Motion {
            fps: FPS,
            positions: Array3::zeros(motion.positions.dim()),
        };
        let judge = |m: &Motion| {
            Some(if m.positions == first.positions {
                still.clone()
            } else {
                m.clone()
            })
        };
        let (next, s) = align_served(motion.clone(), &beats, &[], UNFINISHED, Some(judge));
        assert!(s.applied && s.steps_on_beat, "{s:?}");
        assert_ne!(next.positions, first.positions);
        let after = tempo_lock(next.positions.view(), FPS, &beats).expect("measured");
        assert!(after.locked, "{after:?} {s:?}");
        // Served, none steps on the beat: the first choice still, and the summary says so.
        let (kept, s) = align_served(motion, &beats, &[], UNFINISHED, Some(|_: &Motion| None));
        assert!(s.applied && !s.steps_on_beat, "{s:?}");
        assert_eq!(kept.positions, first.positions);
    }

    #[test]
    fn a_dance_on_the_beat_as_it_came_is_served_as_it_came_where_no_warp_is() {
        // Steps at exactly half the beat rate: on the beat as it comes.
        let (motion, beats) = (periodic(60.0, 1.0), beats(60.0, 0.5, 0.21));
        // Served, every warp of it is off the beat (here: anything but the dance as it came).
        let judge = |m: &Motion| (m.positions == motion.positions).then(|| m.clone());
        let (served, s) = align_served(motion.clone(), &beats, &[], UNFINISHED, Some(judge));
        assert_eq!(served.positions, motion.positions);
        assert!(!s.applied && s.steps_on_beat, "{s:?}");
        assert!(
            s.skipped
                .as_deref()
                .is_some_and(|w| w.contains("as it came")),
            "{s:?}"
        );
        assert_eq!(s.grid_fraction, 0.5);
        assert!((s.step_hz - 1.0).abs() < 0.01, "{s:?}");
        assert_eq!((s.slope_min, s.slope_max, s.pace), (1.0, 1.0, 1.0));
    }

    fn beats_for(seconds: f64, period: f64) -> Vec<f64> {
        beats(seconds, period, 0.1)
    }

    #[test]
    fn a_grid_below_the_step_band_is_not_chosen() {
        // 87 bpm: every 6 beats is 0.24 Hz, under the metric's 0.25 Hz floor. Steps at 0.25 Hz
        // would need almost no warp onto it, and are left alone (every 4 beats is out of reach);
        // steps at 0.33 Hz go to every 4 beats (0.36 Hz).
        let beats = beats(90.0, 60.0 / 87.0, 0.2);
        let (_, s) = align(&periodic(90.0, 0.25), &beats, &[]);
        assert!(!s.applied, "{s:?}");
        let motion = periodic(90.0, 0.33);
        let (aligned, s) = align(&motion, &beats, &[]);
        assert!(s.applied && s.grid_fraction == 0.25, "{s:?}");
        let after = tempo_lock(aligned.positions.view(), FPS, &beats).expect("measured");
        assert!(after.locked, "{after:?} {s:?}");
    }

    #[test]
    fn fixed_times_start_and_end_map_to_themselves() {
        let (motion, beats) = (periodic(40.0, 1.07), beats(40.0, 0.5, 0.3));
        let keys = [7.0, 19.52, 31.0];
        let last = motion.num_frames() - 1;
        for (warp, _) in plan_from(&motion, &motion, &beats, &keys).expect("a warp") {
            assert!(warp.summary.applied, "{:?}", warp.summary);
            for f in [0, 175, 488, 775, last] {
                assert_eq!(warp.source_frames[f], f as f64, "frame {f}");
            }
        }
        let (aligned, _) = align(&motion, &beats, &keys);
        for f in [0, 175, 488, 775, last] {
            assert_eq!(
                aligned.positions.index_axis(Axis(0), f),
                motion.positions.index_axis(Axis(0), f),
                "frame {f}"
            );
        }
    }

    #[test]
    fn the_warp_is_monotone_with_a_bounded_slope() {
        for (f, period) in [(0.93, 0.5), (1.2, 0.5), (0.55, 0.41), (1.9, 0.6)] {
            let (motion, beats) = (periodic(45.0, f), beats(45.0, period, 0.05));
            // With a key pose (pace 1) and without (the paces: the slope counts the pace's).
            for keys in [&[20.0][..], &[]] {
                // No warp within reach: the motion is served as it came (slope 1).
                let warps = plan_from(&motion, &motion, &beats, keys).unwrap_or_default();
                for (warp, _) in warps {
                    for w in warp.source_frames.windows(2) {
                        let s = w[1] - w[0];
                        assert!(
                            s >= SLOPE_RANGE.0 * 0.97 && s <= SLOPE_RANGE.1 * 1.03,
                            "slope {s} ({f} Hz, {period} s): {:?}",
                            warp.summary
                        );
                    }
                    let s = &warp.summary;
                    assert!(
                        s.slope_min >= SLOPE_RANGE.0 * 0.97 && s.slope_max <= SLOPE_RANGE.1 * 1.03,
                        "{s:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_motion_a_little_faster_than_its_grid_is_played_slower_and_locks() {
        // 120 bpm; steps at 1.045 Hz, 4.5 % fast for half the beat rate.
        let (still, beats) = (periodic(60.0, 1.045), beats(60.0, 0.5, 0.21));
        // A dance that slow (the body still, 0.09 m/s) is not slowed further.
        assert_eq!(align(&still, &beats, &[]).1.pace, 1.0);
        // The body travelling with the ankles at 1 m/s: lively enough to be slowed a little.
        let mut motion = still.clone();
        for t in 0..motion.num_frames() {
            for j in (0..NUM_JOINTS).filter(|j| !ANKLES.contains(j)) {
                motion.positions[[t, j, 0]] = (t as f64 / FPS) as f32;
            }
        }
        let (aligned, s) = align(&motion, &beats, &[]);
        assert!(s.applied && s.pace < 1.0, "{s:?}");
        // Locked along (nearly) all of it: at pace 1, 88 % (two cycles lost in catch-ups).
        assert!(s.locked_share > 0.95, "{s:?}");
        assert!(
            (s.step_hz - 1.045).abs() < 0.02,
            "the motion's own rate: {s:?}"
        );
        let after = tempo_lock(aligned.positions.view(), FPS, &beats).expect("measured");
        assert!(
            after.locked && (after.ratio - 0.5).abs() < 0.005,
            "{after:?}"
        );
        // The dance still covers the song, and its first frame is the network's.
        assert_eq!(aligned.num_frames(), motion.num_frames());
        assert_eq!(
            aligned.positions.index_axis(Axis(0), 0),
            motion.positions.index_axis(Axis(0), 0)
        );
        // With a key pose the end is held: pace 1.
        let (_, with_key) = align(&motion, &beats, &[30.0]);
        assert_eq!(with_key.pace, 1.0, "{with_key:?}");
        // The first frame fixed, as every job fixes it, changes nothing.
        let (_, first) = align(&motion, &beats, &[0.0]);
        assert_eq!(first, s);
    }

    #[test]
    fn too_short_too_few_beats_or_out_of_reach_is_left_alone() {
        let (out, s) = align(&periodic(1.0, 1.0), &beats(1.0, 0.1, 0.0), &[]);
        assert!(!s.applied && out.positions.dim().0 == 25, "{s:?}");
        let m = periodic(40.0, 1.0);
        let (out, s) = align(&m, &[1.0, 2.0], &[]);
        assert!(
            !s.applied && s.skipped.as_deref().is_some_and(|w| w.contains("beats")),
            "{s:?}"
        );
        assert_eq!(out.positions, m.positions);
        // Steps at 2.9 Hz against a 60-bpm song: the fastest grid (1 Hz) is out of reach.
        let m = periodic(40.0, 2.9);
        let (out, s) = align(&m, &beats(40.0, 1.0, 0.0), &[]);
        assert!(!s.applied && s.skipped.is_some(), "{s:?}");
        assert_eq!(out.positions, m.positions);
    }
}
