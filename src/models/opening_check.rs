//! A served check of a sampled dance's opening (not in any of the papers): where a model's draw
//! (dance-revolution's `h_0`, DanceNet's sampling stream and context clip) sets the dance's
//! character for the whole song, the draw first dances the song's opening, and one that shuffles
//! or flails is passed over for the next draw derived from the job's seed. Each model's serving
//! decides what a draw is; this module holds the rule and the measure. The draw rule itself
//! ([`first_inside`]) also chooses keypose-transformer's draw of a short song, by its own measure
//! (`keypose_transformer::served::SHORT_SONG_FRAMES`).
use serde::{Deserialize, Serialize};

use crate::models::beat_time::BeatTime;
use crate::motion::Motion;

/// `model.json`'s check. The draw dances the song's first `frames` frames (after any warm-up;
/// [`OpeningCheck::window`]), and the second half of them is measured, where the draw has settled
/// (dance-revolution's seed 3 on DANCE_C_8 opens at 0.5–1 m/s and steps a 2-m/s metronome from
/// 5 s on). Where its mean joint speed or its arms' speed against the spine falls outside the
/// ranges (m/s), the next of `draws` draws is tried; where none passes, the draw nearest the
/// ranges is danced. The check costs at most `draws × frames` frames (and each draw's warm-up):
/// dance-revolution's kept draw goes on from the end of its opening
/// (`dance_revolution::Decoding`), dancenet's is danced again in the full run (its sampler
/// cannot go on). A job's seed motion skips it.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct OpeningCheck {
    pub frames: usize,
    pub draws: usize,
    pub speed_m_s: [f64; 2],
    pub arms_m_s: [f64; 2],
}

impl OpeningCheck {
    /// The settled half of `opening`: its mean joint speed and its arms' speed against the
    /// spine (m/s).
    pub fn measure(opening: &Motion) -> (f64, f64) {
        let settled = opening
            .positions
            .slice(ndarray::s![opening.num_frames() / 2.., .., ..]);
        let speed = crate::motion::skeleton::average_speed(settled, opening.fps);
        let arms = crate::metrics::musicality::arm_speed_m_s(settled, opening.fps);
        (speed, arms)
    }

    /// How far the settled half of `opening` lies outside the ranges (summed log ratios of its
    /// mean joint speed and its arms' speed against the spine); 0 inside both.
    pub fn miss(&self, opening: &Motion) -> f64 {
        let (speed, arms) = Self::measure(opening);
        self.miss_of(speed, arms)
    }

    /// How far (summed log ratios) `speed` and `arms` lie outside the ranges; 0 inside both.
    fn miss_of(&self, speed: f64, arms: f64) -> f64 {
        let out = |v: f64, [lo, hi]: [f64; 2]| {
            let v = v.max(1e-6);
            (lo / v).ln().max(0.0) + (v / hi).ln().max(0.0)
        };
        out(speed, self.speed_m_s) + out(arms, self.arms_m_s)
    }

    /// The span the check dances for a song on `clock`: its first [`Self::frames`] song frames
    /// (or the whole song when shorter), and how many network frames make them. The ranges are
    /// the served dance's, so a network in beat time is judged at the song's pace: on a fast song
    /// heard slower (dance-revolution heard vibe_ace at 0.67×) 500 network frames are 13 s of the
    /// song and its motion plays back 1.5× as fast.
    pub fn window(&self, clock: &BeatTime) -> BeatTime {
        BeatTime::with_factor(clock.factor, self.frames.min(clock.song_frames))
    }

    /// The draw `seed` dances: each of [`Self::draws`] in turn ([`draw_seed`], the seed's own
    /// first) dances `window.net_frames` network frames through `opening`, played back at the
    /// song's pace ([`Self::window`]), until one lies inside the ranges; else the nearest. Returns
    /// that draw's seed and what the check saw (for report.json); `model` names the model in the
    /// log line. `None` where `opening` is stopped (the job was cancelled).
    pub fn choose<E>(
        &self,
        model: &str,
        seed: u64,
        window: &BeatTime,
        mut opening: impl FnMut(u64) -> Result<Option<Motion>, E>,
    ) -> Result<Option<(u64, OpeningChosen)>, E> {
        let measured = first_inside(
            seed,
            self.draws,
            |s| {
                Ok(opening(s)?.map(|motion| {
                    let (speed, arms) = Self::measure(&window.back(motion));
                    (speed, arms, self.miss_of(speed, arms))
                }))
            },
            |m| m.2,
        )?;
        Ok(measured.map(|d| {
            let (speed_m_s, arms_m_s, miss) = d.kept;
            tracing::info!(
                model,
                seed,
                tried = d.tried,
                kept = d.index,
                miss,
                "opening check"
            );
            (
                d.seed,
                OpeningChosen {
                    tried: d.tried,
                    kept: d.index,
                    speed_m_s,
                    arms_m_s,
                    inside: miss == 0.0,
                },
            )
        }))
    }
}

/// The draw a [`first_inside`] search keeps.
pub struct Drawn<T> {
    /// Its seed ([`draw_seed`]) and index (0: the job's seed itself).
    pub seed: u64,
    pub index: usize,
    /// Draws made, this one among them.
    pub tried: usize,
    pub kept: T,
}

/// The draw rule every served check shares: up to `draws` draws of `seed` ([`draw_seed`], the
/// seed's own first) are made by `draw` and judged by `miss` (0 inside the check's limits, more
/// the farther outside), stopping at the first inside; the kept draw is that one, else the one
/// that missed least (the first of equals). `None` where `draw` is stopped (the job was
/// cancelled). Used by [`OpeningCheck::choose`] and keypose-transformer's short songs, which
/// judge a draw by different measures.
pub fn first_inside<T, E>(
    seed: u64,
    draws: usize,
    mut draw: impl FnMut(u64) -> Result<Option<T>, E>,
    miss: impl Fn(&T) -> f64,
) -> Result<Option<Drawn<T>>, E> {
    let mut best: Option<(f64, Drawn<T>)> = None;
    for k in 0..draws.max(1) {
        let s = draw_seed(seed, k);
        let Some(made) = draw(s)? else {
            return Ok(None);
        };
        let m = miss(&made);
        if best.as_ref().is_none_or(|b| m < b.0) {
            best = Some((
                m,
                Drawn {
                    seed: s,
                    index: k,
                    tried: 0,
                    kept: made,
                },
            ));
        }
        if let Some(b) = best.as_mut() {
            b.1.tried = k + 1;
        }
        if m == 0.0 {
            break;
        }
    }
    Ok(best.map(|(_, d)| d))
}

/// What a model's opening check did for one job ([`OpeningCheck::choose`]), in report.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct OpeningChosen {
    /// Draws danced through their opening, the seed's own first.
    pub tried: usize,
    /// The draw danced: 0 is the seed's own; another where the seed's own opening shuffled or
    /// flailed.
    pub kept: usize,
    /// The kept draw's opening, its settled second half: mean joint speed (m/s).
    pub speed_m_s: f64,
    /// The same, the arms' speed against the spine (m/s).
    pub arms_m_s: f64,
    /// Whether both lie inside the check's ranges; where no draw did, the nearest was danced.
    pub inside: bool,
}

/// The `k`-th draw a job's seed may dance from: the seed itself first.
pub fn draw_seed(seed: u64, k: usize) -> u64 {
    seed.wrapping_add((k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

#[cfg(test)]
mod tests {
    use super::*;

    const CHECK: OpeningCheck = OpeningCheck {
        frames: 500,
        draws: 6,
        speed_m_s: [0.6, 1.6],
        arms_m_s: [0.5, 1.3],
    };

    #[test]
    fn a_draw_inside_both_ranges_misses_nothing_and_a_further_one_misses_more() {
        assert_eq!(CHECK.miss_of(0.8, 0.7), 0.0);
        assert!(CHECK.miss_of(0.5, 0.7) > 0.0);
        assert!(CHECK.miss_of(0.8, 2.5) > CHECK.miss_of(0.8, 1.5));
        assert!(CHECK.miss_of(0.4, 0.7) > CHECK.miss_of(0.5, 0.7));
        assert_eq!(draw_seed(7, 0), 7);
        assert_ne!(draw_seed(7, 1), draw_seed(8, 1));
    }

    /// The shared draw rule: it stops at the first draw inside, else keeps the first of the
    /// nearest, and stops with the job.
    #[test]
    fn draws_stop_at_the_first_inside_else_the_nearest_is_kept() {
        let misses = |m: Vec<f64>| {
            move |s: u64| -> Result<Option<(u64, f64)>, ()> {
                let k = (0..6)
                    .position(|k| draw_seed(7, k) == s)
                    .expect("a draw of seed 7");
                Ok(Some((s, m[k])))
            }
        };
        let d = first_inside(7, 6, misses(vec![0.3, 0.0, 0.0, 0.0, 0.0, 0.0]), |m| m.1)
            .unwrap()
            .unwrap();
        assert_eq!((d.index, d.tried, d.seed), (1, 2, draw_seed(7, 1)));
        let d = first_inside(7, 6, misses(vec![0.3, 0.1, 0.2, 0.1, 0.4, 0.5]), |m| m.1)
            .unwrap()
            .unwrap();
        assert_eq!((d.index, d.tried, d.kept.1), (1, 6, 0.1));
        let mut made = 0;
        let stopped = first_inside(
            7,
            6,
            |_| -> Result<Option<()>, ()> {
                made += 1;
                Ok((made < 3).then_some(()))
            },
            |_| 1.0,
        );
        assert!(matches!(stopped, Ok(None)) && made == 3);
    }

    #[test]
    fn the_window_is_the_songs_first_frames_on_the_networks_clock() {
        let seconds = CHECK.window(&BeatTime::seconds(4000));
        assert_eq!((seconds.song_frames, seconds.net_frames), (500, 500));
        // A fast song heard at 0.67×: 500 song frames take 745 network frames.
        let fast = CHECK.window(&BeatTime::with_factor(0.67, 4000));
        assert_eq!((fast.song_frames, fast.net_frames), (500, 745));
        // A song shorter than the window: all of it.
        let short = CHECK.window(&BeatTime::with_factor(1.2, 133));
        assert_eq!((short.song_frames, short.net_frames), (133, 111));
    }

    #[test]
    fn only_the_settled_half_is_measured() {
        // Still for the first half, then every joint moving 1 m/s along x: the settled half
        // measures 1 m/s, inside the speed range (arms still against the spine: below it).
        let (frames, fps) = (100, 25.0);
        let mut p = ndarray::Array3::<f32>::zeros((frames, crate::motion::NUM_JOINTS, 3));
        for f in frames / 2..frames {
            p.slice_mut(ndarray::s![f, .., 0])
                .fill((f - frames / 2) as f32 / fps as f32);
        }
        let motion = Motion { fps, positions: p };
        let arms_only = (0.5f64 / 1e-6).ln();
        assert!((CHECK.miss(&motion) - arms_only).abs() < 1e-6);
    }
}
