//! TSMT's served opening check (not in the paper): a candidate clip whose opening,
//! drawn by the network, freezes, holds one pose, holds its arms or bends its knees backwards
//! (as served) is passed over for the next
//! candidate the song chose (`Served::generate_features`), and a freeze or a hold later in the
//! song is found where it starts.
use ndarray::{Array2, ArrayBase, Ix2};

use super::Bins;
use crate::models::{smooth_columns, ModelError};
use crate::motion::hold::{longest_slow_s, slow_spans, HOLD_NOTED_S, HOLD_SPEED_M_S};
use crate::motion::repr::{self, RootStart};

/// Frames of the opening drawn to see whether a candidate clip freezes (20 s at 25 fps; a hold
/// the reach sees sooner stops it there).
pub(super) const OPENING_CHECK_FRAMES: usize = 500;
/// A freeze holds this long (frames, 10 s): lively dances dip under the reach for a few
/// seconds and come back (the card's calibration: at most 6 windows in a row, 7 s), frozen ones
/// stay under it to the end of the song.
pub(super) const FREEZE_FRAMES: usize = 250;
/// Windows of the reach measured every this many frames.
pub(super) const REACH_STRIDE: usize = 25;

/// An opening holds one pose this long (frames, 3 s: two 2-s windows a second apart) and
/// another candidate clip is tried. A hold is what a viewer sees first: tsmt opened
/// sweet_waltz, seed 3, in one lunge from 1.8 to 6.5 s (0.17 m/s) and the dance ended under the
/// verdict's 0.5 m/s; choice_drum_bass, seed 1, held from 1.2 to 7.6 s. Later in the song only a
/// freeze (FREEZE_FRAMES) is drawn again: lively dances dip for up to 7 s and come back.
pub(super) const OPENING_HOLD_FRAMES: usize = 75;

/// What the opening check reads of a drawn opening besides its reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct OpeningMeasures {
    /// The arms' speed against the spine (m/s, `metrics::musicality::arm_speed_m_s`).
    arms_m_s: f64,
    /// The longest stretch (s) whose every one-second mean joint speed is under
    /// [`OPENING_SLOW_M_S`]: a pose held while it drifts, which the reach can miss.
    slow_s: f64,
    /// The share of knee-frames bent backwards once the served knee step and the feet have run
    /// (`motion::finish`), as `metrics::musicality` counts them.
    knee_backward_share: f64,
    /// The mean joint speed (m/s) with the served knee step and feet, as the verdict reads it.
    speed_m_s: f64,
    /// The frames' rate (network frames a second of the song).
    fps: f64,
}

impl OpeningMeasures {
    /// The opening holds its arms or one pose, or bends its knees backwards more often than
    /// real dancers do, or, where it is the `whole` song, moves slower than
    /// [`SHORT_SONG_MIN_SPEED_M_S`] (its speed is then the verdict's), and another candidate is
    /// tried.
    pub(super) fn passed_over(&self, whole: bool) -> bool {
        self.arms_m_s < OPENING_MIN_ARMS_M_S
            || self.slow_s >= OPENING_HOLD_FRAMES as f64 / self.fps
            || self.knee_backward_share > OPENING_MAX_KNEE_BACKWARD
            || (whole && self.speed_m_s < SHORT_SONG_MIN_SPEED_M_S)
    }
}

/// On a song no longer than the check's window (its opening is the whole dance) an opening that
/// moves slower than this (m/s, mean joint speed with the served knee step and feet) is passed
/// over: the verdict's floor (0.5) and what the served stages after the check took off (the
/// beat-align stage may play a dance a little slower): on the trumpet loop at 0.85×, seed 1,
/// 0.81 here and 0.72 downloaded; seed 5 at 1.2× measured 0.49 here and failed the verdict at 0.49.
const SHORT_SONG_MIN_SPEED_M_S: f64 = 0.6;

/// An opening whose knees bend backwards on more of its knee-frames than this, with the served
/// knee step and feet, is passed over: half of the knee line (6 %; real dances at most 5.8 %),
/// since the stages after the check (the beat-align warp, the export's rigid skeleton) add to
/// it. The knee step turns most of tsmt's backward knees forward, but not over a foot pointed
/// along the shin: on the trumpet loop at 1.2× (4.4 s, all of it the opening), seed 1's first
/// candidate measured 9.0 % here and 9.9 % downloaded, its second 4.1 % here and 7.2 %
/// downloaded (a right knee behind the line over a foot pointed 55–65° from the shin).
pub(super) const OPENING_MAX_KNEE_BACKWARD: f64 = 0.03;

/// Reads tokens drawn on the network's clock as served: their bin centres smoothed over `sigma`
/// frames, the root's height over `sigma_height` ([`super::served::heights_as_served`]), and
/// rebuilt into poses at `fps` (network frames a second of the song). What the served dance
/// measures, before the beat-align stage and the feet: read on the clearance instead, its
/// hopping root (0.31–0.35 m/s) hid a 6-s stand the dance made at 0.22–0.28 (tsmt, sweet_waltz,
/// seed 2, 25–32 s).
pub(super) struct PoseReader<'a> {
    pub bins: &'a Bins,
    pub sigma: f64,
    pub sigma_height: f64,
    pub fps: f64,
}

impl PoseReader<'_> {
    /// The poses of feature `values` (bin centres, or joins of them).
    fn poses(&self, values: &Array2<f32>) -> Result<crate::motion::Motion, ModelError> {
        let mut f = values.clone();
        smooth_columns(&mut f, 0, self.sigma);
        super::served::heights_as_served(&mut f, 0, self.sigma_height);
        Ok(repr::from_features(f.view(), RootStart::default(), self.fps)?.0)
    }

    /// [`OpeningMeasures`] of `tokens`.
    pub(super) fn opening_measures<S: ndarray::Data<Elem = i64>>(
        &self,
        tokens: &ArrayBase<S, Ix2>,
    ) -> Result<OpeningMeasures, ModelError> {
        let fps = self.fps;
        let motion = self.poses(&self.bins.values(tokens))?;
        let p = motion.positions.view();
        let speed = crate::motion::skeleton::mean_speed(p, fps);
        let finished = crate::motion::finish(motion.clone(), true);
        Ok(OpeningMeasures {
            speed_m_s: crate::motion::skeleton::average_speed(finished.positions.view(), fps),
            arms_m_s: crate::metrics::musicality::arm_speed_m_s(p, fps),
            slow_s: longest_slow_s(&speed, fps, OPENING_SLOW_M_S),
            knee_backward_share: crate::metrics::musicality::knee_backward_share(
                finished.positions.view(),
            ),
            fps,
        })
    }

    /// Where the poses of feature `values` hold one pose for [`MIDSONG_HOLD_S`] from frame
    /// `after` on: the frames of the first such hold ([`crate::motion::hold`]'s measure) that
    /// lasts past `after`, from `after` where it began before.
    pub(super) fn midsong_hold(
        &self,
        values: &Array2<f32>,
        after: usize,
    ) -> Result<Option<std::ops::Range<usize>>, ModelError> {
        // With its feet planted, as jobs serve it: a planted foot no longer skates, and two
        // stands that skating had parted become one (lets_go_fishin at 1.2×, seed 1: the
        // poses held 3.0 and 4.6 s around a 0.4-m/s skate, the download 8.2 s).
        let motion = crate::motion::finish(self.poses(values)?, true);
        let speed = crate::motion::skeleton::mean_speed(motion.positions.view(), self.fps);
        let hold = (MIDSONG_HOLD_S * self.fps).ceil() as usize;
        // `mean_speed`'s value k is the step from frame k to k + 1.
        Ok(slow_spans(&speed, self.fps, HOLD_SPEED_M_S)
            .into_iter()
            .find(|r| r.len() >= hold && r.end > after)
            .map(|r| r.start.max(after)..r.end))
    }
}

/// A hold later in the song this long (s) or longer is drawn again from the next candidate clip:
/// longer than 41 of the 43 real dances' longest (all but two rumba poses of 8.6 and 9.5 s;
/// [`crate::motion::hold`]). The served dances' previews held 5–19 s mid-song (the tsmt
/// card: hungarian_dance_5 31–36 s, vibe_ace 26–45 s), which the freeze check,
/// reading the reach over 10 s, let pass.
pub(super) const MIDSONG_HOLD_S: f64 = HOLD_NOTED_S;

/// An opening that moves slower than this (m/s, mean joint speed over each second) for
/// OPENING_HOLD_FRAMES holds one pose, though it drifts: the network's own dance on
/// hungarian_dance_5, seed 7, stood from 2 to 7 s at 0.13–0.16 m/s and reached more than the
/// reopen reach (the card).
pub(super) const OPENING_SLOW_M_S: f64 = HOLD_SPEED_M_S;

/// An opening whose arms move slower than this against the spine (m/s; the slowest real
/// dance's, the musicality line) is passed over for the next candidate clip. On a 5-s loop the
/// opening is the whole dance: a clip continued in a ballroom hold kept its arms at 0.34 m/s
/// and, beat-aligned, under the line (the card).
pub(super) const OPENING_MIN_ARMS_M_S: f64 = 0.43;

/// Where the tokens freeze, from frame `after` on ([`holds_from`] for [`FREEZE_FRAMES`]).
pub(super) fn frozen_from<S: ndarray::Data<Elem = i64>>(
    tokens: &ArrayBase<S, Ix2>,
    window: usize,
    widths: &[f32],
    reach: f32,
    after: usize,
) -> Option<usize> {
    holds_from(tokens, window, widths, reach, after, FREEZE_FRAMES)
}

/// Where the tokens hold one pose, from frame `after` on: the start of the first `hold` frames
/// in a row over which every `window`-frame window, one every [`REACH_STRIDE`] frames, has
/// reached less than `reach` m ([`super::sampling::reach_m`]).
pub(super) fn holds_from<S: ndarray::Data<Elem = i64>>(
    tokens: &ArrayBase<S, Ix2>,
    window: usize,
    widths: &[f32],
    reach: f32,
    after: usize,
    hold: usize,
) -> Option<usize> {
    let need = 1 + hold.saturating_sub(window) / REACH_STRIDE;
    let mut run = 0;
    let mut end = after + window;
    while end <= tokens.nrows() {
        let frames: std::collections::VecDeque<Vec<i64>> = tokens
            .outer_iter()
            .skip(end - window)
            .take(window)
            .map(|r| r.to_vec())
            .collect();
        run = if super::sampling::reach_m(&frames, widths) < reach {
            run + 1
        } else {
            0
        };
        if run >= need {
            return Some(end - window - (need - 1) * REACH_STRIDE);
        }
        end += REACH_STRIDE;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::repr::FEATURE_DIM;
    use ndarray::s;

    /// Tokens of 2 joints (6 coordinates, 1 cm a bin) over `frames` frames: moving `step` bins a
    /// frame back and forth over 40 frames, plus a bin of jitter.
    fn tokens(frames: usize, step: impl Fn(usize) -> i64) -> Array2<i64> {
        Array2::from_shape_fn((frames, 6), |(t, c)| {
            let phase = (t % 80) as i64;
            let swing = if phase < 40 { phase } else { 80 - phase };
            100 + swing * step(t) + ((t * 7 + c) % 2) as i64
        })
    }

    /// 101 bins over [-1, 1]: bin 50's centre is 0 (no root velocity, no turn).
    fn centred_bins() -> Bins {
        Bins {
            n: 101,
            lo: vec![-1.0; FEATURE_DIM],
            hi: vec![1.0; FEATURE_DIM],
        }
    }

    /// Reads `bins` at 25 fps, smoothed over a frame.
    fn reader(bins: &Bins) -> PoseReader<'_> {
        PoseReader {
            bins,
            sigma: 1.0,
            sigma_height: 1.0,
            fps: 25.0,
        }
    }

    /// Pose tokens over `frames` frames: the first coordinate of every joint that `moves` swings
    /// 2 bins a frame back and forth over 20 frames, outside the frames `still`; every other
    /// coordinate stays at bin 50.
    fn swinging(
        frames: usize,
        moves: impl Fn(usize) -> bool,
        still: std::ops::Range<usize>,
    ) -> Array2<i64> {
        Array2::from_shape_fn((frames, FEATURE_DIM), |(t, c)| {
            let swing = (t % 20) as i64;
            let swing = if swing < 10 { swing } else { 20 - swing };
            if c < repr::POSE_DIM && c % 3 == 0 && moves(c / 3) && !still.contains(&t) {
                40 + 2 * swing
            } else {
                50
            }
        })
    }

    /// A freeze is 10 s under the reach; a lively dance that holds still for 6 s and moves on is
    /// not one (the card's calibration: lively openings dipped for at most 7 s), but its opening
    /// holds (3 s); a 2-s pause does not.
    #[test]
    fn an_opening_freezes_after_ten_seconds_still_and_holds_after_three() {
        let widths = [0.01f32; 6];
        let frozen = |t: &Array2<i64>| frozen_from(t, 50, &widths, 0.1, 0).is_some();
        let held = |t: &Array2<i64>| holds_from(t, 50, &widths, 0.1, 0, OPENING_HOLD_FRAMES);
        let moving = tokens(500, |_| 2);
        assert!(!frozen(&moving));
        assert_eq!(held(&moving), None);
        let still = tokens(500, |t| i64::from(t < 150));
        assert!(frozen(&still));
        let dip = tokens(500, |t| i64::from(!(150..300).contains(&t)) * 2);
        assert!(!frozen(&dip));
        let from = held(&dip).expect("a 6-s hold");
        assert!((140..=180).contains(&from), "held from {from}");
        let pause = tokens(500, |t| i64::from(!(150..200).contains(&t)) * 2);
        assert_eq!(held(&pause), None);
        // Too short to tell.
        assert!(!frozen(&tokens(200, |_| 0)));
    }

    /// The opening check's measures: a held pose moves nothing and is slow throughout (its 99
    /// steps, 3.96 s); an elbow and a wrist swinging 2 bins (4 cm) a frame at 25 fps move about 1 m/s,
    /// half the arm joints' mean; the legs swinging move the arms not at all.
    #[test]
    fn an_opening_that_holds_its_arms_or_drifts_slowly_is_still() {
        let bins = centred_bins();
        let reader = reader(&bins);
        let swinging = |joints: &'static [usize]| swinging(100, |j| joints.contains(&j), 0..0);
        let [elbow, wrist, _, _] = crate::metrics::musicality::ARM_JOINTS;
        let held = Array2::from_elem((100, FEATURE_DIM), 50i64);
        let measure = |t: &Array2<i64>| reader.opening_measures(t).unwrap();
        let still = measure(&held);
        assert!(still.arms_m_s < 1e-6, "held arms move {still:?}");
        assert!(
            (still.slow_s - 3.96).abs() < 1e-9 && still.passed_over(false),
            "{still:?}"
        );
        assert_eq!([elbow, wrist], [4, 6]);
        let arms = measure(&swinging(&[4, 6]));
        assert!(
            (0.35..=0.52).contains(&arms.arms_m_s),
            "swinging arms: {arms:?}"
        );
        let legs = measure(&swinging(&[9, 10]));
        assert!(
            legs.arms_m_s < 1e-6 && legs.passed_over(false),
            "swinging legs: {legs:?}"
        );
        // Most joints swinging (not the spine) move about 1 m/s: never slow, arms lively.
        let all: &'static [usize] = &[0, 1, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16];
        let lively = measure(&swinging(all));
        assert!(
            lively.slow_s == 0.0 && !lively.passed_over(false),
            "{lively:?}"
        );
    }

    /// A lively opening is passed over where its knees, as served, bend backwards on more than
    /// OPENING_MAX_KNEE_BACKWARD of its knee-frames, and kept at or under it.
    #[test]
    fn an_opening_that_bends_its_knees_backwards_is_passed_over() {
        let lively = |knee_backward_share| OpeningMeasures {
            arms_m_s: 0.9,
            speed_m_s: 0.8,
            slow_s: 0.0,
            knee_backward_share,
            fps: 25.0,
        };
        assert!(!lively(0.0).passed_over(false));
        assert!(!lively(OPENING_MAX_KNEE_BACKWARD).passed_over(false));
        assert!(lively(0.041).passed_over(false));
    }

    /// An opening slower than SHORT_SONG_MIN_SPEED_M_S is passed over only where it is the whole
    /// song (the trumpet loop at 1.2×, seed 5: 0.49 m/s); a faster one is kept there too.
    #[test]
    fn a_slow_opening_is_passed_over_where_it_is_the_whole_song() {
        let opening = |speed_m_s| OpeningMeasures {
            arms_m_s: 0.9,
            speed_m_s,
            slow_s: 0.0,
            knee_backward_share: 0.0,
            fps: 25.0,
        };
        assert!(!opening(0.55).passed_over(false) && opening(0.55).passed_over(true));
        assert!(!opening(0.8).passed_over(true));
    }

    /// A stand of 8 s mid-song is found where it starts and ends (with the few frames of its
    /// one-second windows around it), also where it began before `after`; a stand of 3 s, as long
    /// as a real waltz's closing pose, is not one. Two stands parted by a skate (every joint,
    /// feet included, gliding one way and back for a second: no step) are one stand, as the
    /// download plants the feet and shows it.
    #[test]
    fn a_hold_later_in_the_song_is_found_where_it_starts() {
        let bins = centred_bins();
        let reader = reader(&bins);
        // The upper body swinging (about 0.5 m/s over all joints) over feet that stay, standing
        // over `still`.
        let upper = |j: usize| ![2, 7, 8, 9, 10, 11, 16, 17, 18, 19, 20].contains(&j);
        let dance = |still| swinging(1000, upper, still);
        let found = |t: &Array2<i64>, after| reader.midsong_hold(&bins.values(t), after).unwrap();
        let eight = dance(400..600);
        let held = found(&eight, 0).expect("an 8-s hold");
        assert!((385..=400).contains(&held.start), "found at {held:?}");
        assert!((600..=615).contains(&held.end), "found at {held:?}");
        assert_eq!(found(&eight, 500), Some(500..held.end));
        assert_eq!(found(&eight, 700), None);
        assert_eq!(found(&dance(400..475), 0), None);
        assert_eq!(found(&dance(0..0), 0), None);
        // 4 s, a one-second skate, 4 s.
        let mut skated = dance(400..725);
        let glide = swinging(1000, |_| true, 0..0);
        skated
            .slice_mut(s![500..525, ..])
            .assign(&glide.slice(s![500..525, ..]));
        let held = found(&skated, 0).expect("one 13-s hold");
        assert!(
            (385..=400).contains(&held.start) && (725..=750).contains(&held.end),
            "found at {held:?}"
        );
    }

    /// A dance that freezes mid-song is found where its freeze starts, and only after `after`.
    #[test]
    fn a_freeze_later_in_the_song_is_found_where_it_starts() {
        let widths = [0.01f32; 6];
        // Lively for 700 frames, then still to the end (1,200 frames).
        let late = tokens(1200, |t| i64::from(t < 700) * 2);
        let from = frozen_from(&late, 50, &widths, 0.1, 500).expect("a freeze");
        assert!((650..=760).contains(&from), "found at {from}");
        assert_eq!(frozen_from(&late, 50, &widths, 0.1, 0), Some(from));
        // Nothing after the end of the freeze's search.
        assert_eq!(frozen_from(&late, 50, &widths, 0.1, 1000), None);
        assert_eq!(frozen_from(&tokens(1200, |_| 2), 50, &widths, 0.1, 0), None);
    }
}
