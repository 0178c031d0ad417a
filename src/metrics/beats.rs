//! Rhythm: kinematic beats, Beat Align Score in both published conventions, beat coverage and
//! hit rate, rhythm hit, and the `mir_eval` beat-list metrics.
//!
//! Times are seconds from the first motion frame; motion frame `i` is at `i / fps`. Music beats
//! come from [`crate::audio::analyze`] (never computed here) and must be on the same clock.
use ndarray::ArrayView3;

/// FACT (Li et al., ICCV 2021, `mint/tools/calculate_beat_scores.py`): minima of order 10 at 60 fps.
pub const FACT_MINIMA_ORDER_60FPS: f64 = 10.0;
/// Bailando (Li et al., CVPR 2022, `utils/metrics_new.py`): Gaussian σ = 5 frames at 60 fps.
pub const BAILANDO_SMOOTH_SIGMA_60FPS: f64 = 5.0;
/// Both BAS conventions: σ = 3 frames at 60 fps (Bailando writes it as `/ 2 / 9`), i.e. 0.05 s.
pub const BAS_SIGMA_S: f64 = 3.0 / 60.0;
/// DanceRevolution (Huang et al., ICLR 2021) gives no tolerance for "aligned"; choreo uses ±0.1 s.
pub const ALIGN_TOLERANCE_S: f64 = 0.1;
/// DanceNet (Zhuang et al., 2020): a music beat is hit when a kinematic beat lies within 0.25 s.
pub const RHYTHM_HIT_TOLERANCE_S: f64 = 0.25;
/// `mir_eval.beat.f_measure` default window.
pub const F_MEASURE_WINDOW_S: f64 = 0.07;
/// `mir_eval.beat.cemgil` default σ.
pub const CEMGIL_SIGMA_S: f64 = 0.04;
/// `mir_eval.beat.p_score` default threshold (a share of the median reference interval).
pub const P_SCORE_THRESHOLD: f64 = 0.2;

/// Per-frame joint speed in metres per frame: `speed[t][j] = |p[t+1, j] − p[t, j]|`, `[T−1][J]`.
fn frame_speeds(positions: ArrayView3<'_, f32>) -> Vec<Vec<f64>> {
    let (t, j, _) = positions.dim();
    (1..t)
        .map(|f| {
            (0..j)
                .map(|k| {
                    let mut s = 0.0f64;
                    for c in 0..3 {
                        let d = positions[[f, k, c]] as f64 - positions[[f - 1, k, c]] as f64;
                        s += d * d;
                    }
                    s.sqrt()
                })
                .collect()
        })
        .collect()
}

/// Indices `i` with `x[i] < x[i±k]` for every `k` in `1..=order`, indices clipped to the ends:
/// `scipy.signal.argrelextrema(x, np.less, order=order)` (mode `clip`, so the ends never qualify).
pub fn argrelmin(x: &[f64], order: usize) -> Vec<usize> {
    let n = x.len();
    if n == 0 {
        return Vec::new();
    }
    (0..n)
        .filter(|&i| {
            (1..=order.max(1)).all(|k| {
                let lo = i.saturating_sub(k);
                let hi = (i + k).min(n - 1);
                x[i] < x[lo] && x[i] < x[hi]
            })
        })
        .collect()
}

/// `scipy.ndimage.gaussian_filter1d(x, sigma)`: mode `reflect`, truncate 4.0, radius `⌊4σ + 0.5⌋`.
pub fn gaussian_filter1d(x: &[f64], sigma: f64) -> Vec<f64> {
    let n = x.len() as isize;
    if n == 0 || sigma <= 0.0 {
        return x.to_vec();
    }
    let radius = (4.0 * sigma + 0.5) as isize;
    let mut w: Vec<f64> = (-radius..=radius)
        .map(|i| (-0.5 / (sigma * sigma) * (i * i) as f64).exp())
        .collect();
    let sum: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= sum);
    // scipy's `reflect` repeats the edge sample: (d c b a | a b c d | d c b a).
    let reflect = |mut i: isize| -> usize {
        let period = 2 * n;
        i = i.rem_euclid(period);
        if i >= n {
            i = period - 1 - i;
        }
        i as usize
    };
    (0..n)
        .map(|i| {
            w.iter()
                .enumerate()
                .map(|(k, wk)| wk * x[reflect(i + k as isize - radius)])
                .sum()
        })
        .collect()
}

/// FACT's kinematic beats (seconds): local minima of the summed joint speed, order 10 at 60 fps
/// scaled to `fps` (4 at 25 fps), speed at frame `t` being `|p[t] − p[t−1]|` with `speed[0] = 0`.
pub fn kinematic_beats_fact(positions: ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let speeds = frame_speeds(positions);
    if speeds.is_empty() {
        return Vec::new();
    }
    // FACT pads velocity[0] = 0, so frame t's speed is the step into t.
    let mut envelope = vec![0.0f64];
    envelope.extend(speeds.iter().map(|row| row.iter().sum::<f64>()));
    let order = fact_order(fps);
    argrelmin(&envelope, order)
        .into_iter()
        .map(|i| i as f64 / fps)
        .collect()
}

/// The FACT minima order at `fps`: `round(10 · fps / 60)`, at least 1.
pub fn fact_order(fps: f64) -> usize {
    ((FACT_MINIMA_ORDER_60FPS * fps / 60.0).round() as usize).max(1)
}

/// Bailando's Gaussian σ in frames at `fps`: `5 · fps / 60`.
pub fn bailando_sigma(fps: f64) -> f64 {
    BAILANDO_SMOOTH_SIGMA_60FPS * fps / 60.0
}

/// Bailando's kinematic beats (seconds): minima (order 1) of the mean joint speed smoothed by a
/// Gaussian of σ = 5 frames at 60 fps scaled to `fps`. Bailando's speed has no padding, so speed
/// `t` is the step from frame `t` to `t+1`, and a minimum at `t` is reported at time `t / fps`.
pub fn kinematic_beats_bailando(positions: ArrayView3<'_, f32>, fps: f64) -> Vec<f64> {
    let speeds = frame_speeds(positions);
    if speeds.is_empty() {
        return Vec::new();
    }
    let mean: Vec<f64> = speeds
        .iter()
        .map(|row| row.iter().sum::<f64>() / row.len() as f64)
        .collect();
    let smooth = gaussian_filter1d(&mean, bailando_sigma(fps));
    argrelmin(&smooth, 1)
        .into_iter()
        .map(|i| i as f64 / fps)
        .collect()
}

/// `exp(−d² / 2σ²)` for the distance from `t` to the nearest of `others`; 0 when `others` is empty.
fn nearest_gauss(t: f64, others: &[f64], sigma: f64) -> f64 {
    let d = others
        .iter()
        .map(|o| (o - t).abs())
        .fold(f64::INFINITY, f64::min);
    if d.is_finite() {
        (-(d * d) / (2.0 * sigma * sigma)).exp()
    } else {
        0.0
    }
}

/// Beat Align Score, **FACT convention**: mean over *motion* beats of `exp(−d²/2σ²)`, `d` the
/// distance to the nearest music beat, σ = 0.05 s. 0 when there are no motion beats.
pub fn bas_fact(music_beats: &[f64], motion_beats: &[f64]) -> f64 {
    if motion_beats.is_empty() {
        return 0.0;
    }
    motion_beats
        .iter()
        .map(|&b| nearest_gauss(b, music_beats, BAS_SIGMA_S))
        .sum::<f64>()
        / motion_beats.len() as f64
}

/// Beat Align Score, **Bailando convention**: mean over *music* beats of `exp(−d²/2σ²)`, `d` the
/// distance to the nearest motion beat, σ = 0.05 s. 0 when there are no music beats.
pub fn bas_bailando(music_beats: &[f64], motion_beats: &[f64]) -> f64 {
    if music_beats.is_empty() {
        return 0.0;
    }
    music_beats
        .iter()
        .map(|&b| nearest_gauss(b, motion_beats, BAS_SIGMA_S))
        .sum::<f64>()
        / music_beats.len() as f64
}

/// The FACT-convention BAS that motion beats placed uniformly at random over `[0, duration_s]`
/// would score on average: the mean of `exp(−d²/2σ²)` over the span, `d` the distance to the
/// nearest music beat (a 1-ms grid). About `σ√(2π)/P` for beat period `P`: 0.18 at 86 bpm, so
/// a BAS near this says the kinematic beats ignore the music. 0 without music beats.
pub fn bas_fact_chance(music_beats: &[f64], duration_s: f64) -> f64 {
    if music_beats.is_empty() || duration_s <= 0.0 {
        return 0.0;
    }
    let mut sorted = music_beats.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = (duration_s / 1e-3).round().max(1.0) as usize;
    let mut sum = 0.0;
    for i in 0..n {
        let t = (i as f64 + 0.5) * duration_s / n as f64;
        let k = sorted.partition_point(|&b| b < t);
        let mut d = f64::INFINITY;
        if k < sorted.len() {
            d = d.min(sorted[k] - t);
        }
        if k > 0 {
            d = d.min(t - sorted[k - 1]);
        }
        sum += (-(d * d) / (2.0 * BAS_SIGMA_S * BAS_SIGMA_S)).exp();
    }
    sum / n as f64
}

/// Whether some element of `others` lies within `tol` seconds of `t`.
fn has_within(t: f64, others: &[f64], tol: f64) -> bool {
    others.iter().any(|o| (o - t).abs() <= tol)
}

/// DanceRevolution's beat coverage `B_k / B_m`: kinematic beats per music beat. 0 without music beats.
pub fn beat_coverage(music_beats: &[f64], motion_beats: &[f64]) -> f64 {
    if music_beats.is_empty() {
        return 0.0;
    }
    motion_beats.len() as f64 / music_beats.len() as f64
}

/// DanceRevolution's beat hit rate `B_a / B_k`: the share of kinematic beats within
/// [`ALIGN_TOLERANCE_S`] of a music beat. 0 without kinematic beats.
pub fn beat_hit_rate(music_beats: &[f64], motion_beats: &[f64]) -> f64 {
    if motion_beats.is_empty() {
        return 0.0;
    }
    let aligned = motion_beats
        .iter()
        .filter(|&&b| has_within(b, music_beats, ALIGN_TOLERANCE_S))
        .count();
    aligned as f64 / motion_beats.len() as f64
}

/// DanceNet's rhythm hit: the share of music beats with a kinematic beat within 0.25 s.
pub fn rhythm_hit(music_beats: &[f64], motion_beats: &[f64]) -> f64 {
    if music_beats.is_empty() {
        return 0.0;
    }
    let hit = music_beats
        .iter()
        .filter(|&&b| has_within(b, motion_beats, RHYTHM_HIT_TOLERANCE_S))
        .count();
    hit as f64 / music_beats.len() as f64
}

/// Size of a maximum matching of `reference` and `estimated` events with `|r − e| ≤ window`,
/// as `mir_eval.util.match_events` finds it. Both lists sorted ascending.
///
/// The hit test copies `mir_eval`'s float arithmetic (`est − window ≤ ref ≤ est + window`). On a
/// line, windows form a convex bipartite graph, where the greedy earliest-partner matching is
/// maximum, so it equals `mir_eval`'s Hopcroft–Karp count.
pub fn match_events(reference: &[f64], estimated: &[f64], window: f64) -> usize {
    let mut used = vec![false; estimated.len()];
    let mut count = 0;
    for &r in reference {
        if let Some(j) = (0..estimated.len())
            .find(|&j| !used[j] && r >= estimated[j] - window && r <= estimated[j] + window)
        {
            used[j] = true;
            count += 1;
        }
    }
    count
}

/// `mir_eval.beat.f_measure(reference, estimated, 0.07)` (no trimming: we call it untrimmed).
pub fn f_measure(reference: &[f64], estimated: &[f64]) -> f64 {
    if reference.is_empty() || estimated.is_empty() {
        return 0.0;
    }
    let m = match_events(reference, estimated, F_MEASURE_WINDOW_S) as f64;
    let precision = m / estimated.len() as f64;
    let recall = m / reference.len() as f64;
    if precision == 0.0 && recall == 0.0 {
        return 0.0;
    }
    2.0 * precision * recall / (precision + recall)
}

/// The first value of `mir_eval.beat.cemgil(reference, estimated, 0.04)` (the plain metric,
/// not the best over metrical variations).
pub fn cemgil(reference: &[f64], estimated: &[f64]) -> f64 {
    if reference.is_empty() || estimated.is_empty() {
        return 0.0;
    }
    let mut acc = 0.0;
    for &r in reference {
        let d = estimated
            .iter()
            .map(|e| (r - e).abs())
            .fold(f64::INFINITY, f64::min);
        acc += (-(d * d) / (2.0 * CEMGIL_SIGMA_S * CEMGIL_SIGMA_S)).exp();
    }
    acc / (0.5 * (estimated.len() + reference.len()) as f64)
}

/// `mir_eval.beat.p_score(reference, estimated, 0.2)`: both lists become 100 Hz impulse trains
/// (index `⌈100 (t − offset)⌉`), and the cross-correlation within ±20 % of the median reference
/// interval is summed and divided by the larger beat count.
pub fn p_score(reference: &[f64], estimated: &[f64]) -> f64 {
    if reference.len() <= 1 || estimated.len() <= 1 {
        return 0.0;
    }
    let sampling_rate = 100.0f64;
    let offset = reference
        .iter()
        .chain(estimated)
        .copied()
        .fold(f64::INFINITY, f64::min);
    let train = |b: &[f64]| -> Vec<i64> {
        let mut idx: Vec<i64> = b
            .iter()
            .map(|t| ((t - offset) * sampling_rate).ceil() as i64)
            .collect();
        idx.sort_unstable();
        idx.dedup();
        idx
    };
    let r = train(reference);
    let e = train(estimated);
    let mut intervals: Vec<f64> = r.windows(2).map(|w| (w[1] - w[0]) as f64).collect();
    if intervals.is_empty() {
        // numpy's median of an empty array is NaN, and int(round(NaN)) raises in mir_eval.
        return 0.0;
    }
    intervals.sort_by(f64::total_cmp);
    let k = intervals.len();
    let median = if k % 2 == 1 {
        intervals[k / 2]
    } else {
        0.5 * (intervals[k / 2 - 1] + intervals[k / 2])
    };
    // np.round rounds half to even.
    let win = (P_SCORE_THRESHOLD * median).round_ties_even() as i64;
    let mut hits = 0usize;
    for &ri in &r {
        for &ei in &e {
            if (ri - ei).abs() <= win {
                hits += 1;
            }
        }
    }
    hits as f64 / reference.len().max(estimated.len()) as f64
}

/// TSMT (Li et al. 2020) scores beats as a detection: a motion beat is right when it matches a
/// music beat within this tolerance (one-to-one, as [`match_events`]); ±0.1 s is ±2.5 frames at
/// 25 fps ([`ALIGN_TOLERANCE_S`]; `mir_eval`'s 0.07 s is less than two frames here).
pub const BEAT_PRF_WINDOW_S: f64 = ALIGN_TOLERANCE_S;

/// Beat precision, recall and F of motion beats against music beats.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct BeatPrf {
    /// Matched motion beats over all motion beats: how many of the dance's accents fall on a beat.
    pub precision: f64,
    /// Matched music beats over all music beats: how many beats the dance marks.
    pub recall: f64,
    /// Their harmonic mean (0 when both are 0).
    pub f: f64,
}

/// [`BeatPrf`] of `motion_beats` against `music_beats` (both sorted, seconds) within `window`,
/// each beat matched at most once. Empty lists give 0.
pub fn beat_prf(music_beats: &[f64], motion_beats: &[f64], window: f64) -> BeatPrf {
    if music_beats.is_empty() || motion_beats.is_empty() {
        return BeatPrf::default();
    }
    let m = match_events(music_beats, motion_beats, window) as f64;
    let precision = m / motion_beats.len() as f64;
    let recall = m / music_beats.len() as f64;
    let f = if precision + recall > 0.0 {
        2.0 * precision * recall / (precision + recall)
    } else {
        0.0
    };
    BeatPrf {
        precision,
        recall,
        f,
    }
}

/// Music beats that fall within `[0, duration_s]`, the span a dance covers.
pub fn beats_within(beats: &[f64], duration_s: f64) -> Vec<f64> {
    beats
        .iter()
        .copied()
        .filter(|&b| b >= 0.0 && b <= duration_s)
        .collect()
}

/// Every rhythm number for one dance against one song's beats.
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct RhythmScores {
    /// BAS, FACT convention (mean over motion beats; FACT kinematic beats).
    pub bas_fact: f64,
    /// BAS, Bailando convention (mean over music beats; Bailando kinematic beats).
    pub bas_bailando: f64,
    /// What `bas_fact` would be for kinematic beats at random times (see [`bas_fact_chance`]).
    pub bas_fact_chance: f64,
    /// DanceRevolution beat coverage B_k / B_m (FACT kinematic beats).
    pub beat_coverage: f64,
    /// DanceRevolution beat hit rate B_a / B_k, ±0.1 s (FACT kinematic beats).
    pub beat_hit_rate: f64,
    /// DanceNet rhythm hit: share of music beats with a kinematic beat within 0.25 s (FACT beats).
    pub rhythm_hit: f64,
    /// mir_eval F-measure (0.07 s), music beats as reference, FACT kinematic beats as estimate.
    pub f_measure: f64,
    /// mir_eval Cemgil accuracy (σ = 0.04 s), same lists.
    pub cemgil: f64,
    /// mir_eval P-score, same lists.
    pub p_score: f64,
    /// TSMT's beat precision, recall and F (±[`BEAT_PRF_WINDOW_S`], FACT kinematic beats).
    #[serde(default)]
    pub beat_prf: BeatPrf,
}

/// Scores a dance's kinematic beats against music beats already clipped to the dance's span.
/// `duration_s` is the dance's span (for the chance level).
pub fn rhythm_scores(
    music_beats: &[f64],
    fact_beats: &[f64],
    bailando_beats: &[f64],
    duration_s: f64,
) -> RhythmScores {
    RhythmScores {
        bas_fact: bas_fact(music_beats, fact_beats),
        bas_bailando: bas_bailando(music_beats, bailando_beats),
        bas_fact_chance: bas_fact_chance(music_beats, duration_s),
        beat_coverage: beat_coverage(music_beats, fact_beats),
        beat_hit_rate: beat_hit_rate(music_beats, fact_beats),
        rhythm_hit: rhythm_hit(music_beats, fact_beats),
        f_measure: f_measure(music_beats, fact_beats),
        cemgil: cemgil(music_beats, fact_beats),
        p_score: p_score(music_beats, fact_beats),
        beat_prf: beat_prf(music_beats, fact_beats, BEAT_PRF_WINDOW_S),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beat_prf_counts_one_to_one_matches_within_the_window() {
        // Music beats every 0.5 s; the dance marks the first three (one 0.08 s late), adds one
        // accent off the beat and a second accent near the first beat (matched only once).
        let music = [0.5, 1.0, 1.5, 2.0];
        let motion = [0.47, 0.52, 1.08, 1.5, 1.75];
        let p = beat_prf(&music, &motion, BEAT_PRF_WINDOW_S);
        assert!((p.precision - 3.0 / 5.0).abs() < 1e-12, "{p:?}");
        assert!((p.recall - 3.0 / 4.0).abs() < 1e-12, "{p:?}");
        let f = 2.0 * 0.6 * 0.75 / (0.6 + 0.75);
        assert!((p.f - f).abs() < 1e-12, "{p:?}");
    }

    #[test]
    fn beat_prf_of_a_perfect_and_an_empty_dance() {
        let music = [0.4, 0.8, 1.2];
        assert_eq!(
            beat_prf(&music, &music, BEAT_PRF_WINDOW_S),
            BeatPrf {
                precision: 1.0,
                recall: 1.0,
                f: 1.0
            }
        );
        assert_eq!(beat_prf(&music, &[], BEAT_PRF_WINDOW_S), BeatPrf::default());
        // Everything off by more than the window: nothing matches.
        let late: Vec<f64> = music.iter().map(|b| b + 0.15).collect();
        assert_eq!(beat_prf(&music, &late, BEAT_PRF_WINDOW_S).f, 0.0);
    }
}
